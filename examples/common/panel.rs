//! The tuning panel of the windowed examples: every camera and material setting, edited live
//! through bevy-inspector-egui (field docs as tooltips, sliders over the documented ranges),
//! the frame time and the GPU time of each pass, and keys for the effects.

use bevy::{
    diagnostic::{DiagnosticPath, DiagnosticsStore, FrameTimeDiagnosticsPlugin},
    prelude::*,
    reflect::{TypeInfo, Typed},
};
use bevy_egui::{EguiContext, EguiPlugin, EguiPrimaryContextPass, PrimaryEguiContext, egui};
use bevy_inspector_egui::{
    DefaultInspectorConfigPlugin,
    inspector_options::{
        InspectorOptions, ReflectInspectorOptions, Target,
        std_options::{NumberDisplay, NumberOptions},
    },
};
use bevy_mesostructure::prelude::*;

/// The passes whose GPU time the panel shows, in frame order.
pub const PASSES: [&str; 7] = [
    "height",
    "gradient",
    "apex",
    "occlusion",
    "lighting",
    "bleeding",
    "bleeding_composite",
];

/// Adds egui, the inspector's type support, the slider ranges, the panel and the keys.
pub fn add(app: &mut App) {
    app.add_plugins((EguiPlugin::default(), DefaultInspectorConfigPlugin))
        .add_systems(EguiPrimaryContextPass, panel)
        .add_systems(Update, keys);
    register_ranges(app);
}

/// Slider ranges from `Mesostructure::RANGES` and `MesostructureCost::RANGES` (the same ranges
/// the plugin clamps to) and for the material's scale.
fn register_ranges(app: &mut App) {
    let registry = app.world().resource::<AppTypeRegistry>().clone();
    let mut registry = registry.write();
    let field_index = |info: &TypeInfo, name: &str| match info {
        TypeInfo::Struct(s) => s.index_of(name),
        _ => None,
    };
    let mut camera = InspectorOptions::new();
    for (name, lo, hi) in Mesostructure::RANGES {
        if let Some(i) = field_index(Mesostructure::type_info(), name) {
            camera.insert(Target::Field(i), slider(lo, hi));
        }
    }
    if let Some(registration) = registry.get_mut(std::any::TypeId::of::<Mesostructure>()) {
        registration.insert(ReflectInspectorOptions(camera));
    }
    // The `Custom` quality's values (all counts).
    let mut cost = InspectorOptions::new();
    for (name, lo, hi) in MesostructureCost::RANGES {
        if let Some(i) = field_index(MesostructureCost::type_info(), name) {
            cost.insert(Target::Field(i), slider(lo as u32, hi as u32));
        }
    }
    if let Some(registration) = registry.get_mut(std::any::TypeId::of::<MesostructureCost>()) {
        registration.insert(ReflectInspectorOptions(cost));
    }
    let mut material = InspectorOptions::new();
    if let Some(i) = field_index(MesostructureMaterial::type_info(), "scale") {
        material.insert(Target::Field(i), slider(0.0, 1.0));
    }
    if let Some(registration) = registry.get_mut(std::any::TypeId::of::<MesostructureMaterial>()) {
        registration.insert(ReflectInspectorOptions(material));
    }
}

fn slider<T>(lo: T, hi: T) -> NumberOptions<T> {
    let mut options = NumberOptions::between(lo, hi);
    options.display = NumberDisplay::Slider;
    options
}

/// Average GPU (or, where the driver has no timestamps, CPU) milliseconds of a pass.
pub fn pass_time(store: &DiagnosticsStore, pass: &str) -> Option<f64> {
    span_time(store, &format!("mesostructure/{pass}"))
}

/// The same for any span (`volumetric/spots_compute`).
pub fn span_time(store: &DiagnosticsStore, span: &str) -> Option<f64> {
    let path = |kind| DiagnosticPath::new(format!("render/{span}/elapsed_{kind}"));
    store
        .get(&path("gpu"))
        .and_then(|d| d.average())
        .or_else(|| store.get(&path("cpu")).and_then(|d| d.average()))
}

fn panel(world: &mut World) {
    let Ok(mut context) = world
        .query_filtered::<&mut EguiContext, With<PrimaryEguiContext>>()
        .single_mut(world)
        .map(|c| c.clone())
    else {
        return;
    };
    egui::Window::new("Mesostructure")
        .default_width(320.0)
        .show(context.get_mut(), |ui| {
            ui.label(
                "O occlusion · M micro-shadows · B bleeding · N bump mapping · V view · \
                 Space pause · F12 screenshot",
            );
            let store = world.resource::<DiagnosticsStore>();
            let frame = store
                .get(&FrameTimeDiagnosticsPlugin::FRAME_TIME)
                .and_then(|d| d.smoothed());
            ui.label(format!("frame {:.2} ms", frame.unwrap_or(0.0)));
            let mut total = 0.0;
            for pass in PASSES {
                if let Some(ms) = pass_time(store, pass) {
                    total += ms;
                    ui.label(format!("  {pass}: {ms:.3} ms"));
                }
            }
            ui.label(format!("  all passes: {total:.3} ms"));
            for (span, name) in [
                ("volumetric/spots_compute", "volumetric spots (compute)"),
                ("volumetric/spots", "volumetric spots (fragment)"),
            ] {
                if let Some(ms) = span_time(store, span) {
                    ui.label(format!("  {name}: {ms:.3} ms"));
                }
            }
            for span in [
                "translucency/injection",
                "translucency/iteration",
                "translucency/gather",
            ] {
                if let Some(ms) = span_time(store, span) {
                    ui.label(format!("  {span}: {ms:.3} ms"));
                }
            }
            if let Some(status) =
                world.get_resource::<bevy_mesostructure::translucency::TranslucencyStatus>()
            {
                ui.label(format!("translucency: {}", translucency_status(status)));
            }
            egui::ScrollArea::vertical().show(ui, |ui| {
                let cameras: Vec<Entity> = world
                    .query_filtered::<Entity, With<Mesostructure>>()
                    .iter(world)
                    .collect();
                for camera in cameras {
                    egui::CollapsingHeader::new(format!("camera {camera}: Mesostructure"))
                        .default_open(true)
                        .show(ui, |ui| {
                            let mut settings = world.get::<Mesostructure>(camera).unwrap().clone();
                            // The presets set the cost/accuracy fields together.
                            let mut changed = false;
                            ui.horizontal(|ui| {
                                ui.label("quality preset:");
                                for q in MesostructureQuality::ALL {
                                    let current = settings.quality == q;
                                    if ui.selectable_label(current, q.name()).clicked() {
                                        settings.quality = q;
                                        changed = true;
                                    }
                                }
                            });
                            changed |= bevy_inspector_egui::bevy_inspector::ui_for_value(
                                &mut settings,
                                ui,
                                world,
                            );
                            if changed {
                                world.entity_mut(camera).insert(settings);
                            }
                        });
                }
                edit_all::<bevy_mesostructure::volumetric::VolumetricMedium>(ui, world, "camera");
                edit_all::<bevy_mesostructure::volumetric::VolumetricSpot>(ui, world, "spot");
                edit_all::<bevy_mesostructure::translucency::Translucent>(ui, world, "mesh");
                if world
                    .contains_resource::<bevy_mesostructure::translucency::TranslucencySettings>()
                {
                    ui.collapsing("TranslucencySettings (a change precomputes again)", |ui| {
                        bevy_inspector_egui::bevy_inspector::ui_for_resource::<
                            bevy_mesostructure::translucency::TranslucencySettings,
                        >(world, ui);
                    });
                }
                let meshes: Vec<Entity> = world
                    .query_filtered::<Entity, With<MesostructureMaterial>>()
                    .iter(world)
                    .collect();
                for mesh in meshes {
                    ui.collapsing(format!("mesh {mesh}: MesostructureMaterial"), |ui| {
                        let mut material =
                            world.get::<MesostructureMaterial>(mesh).unwrap().clone();
                        if bevy_inspector_egui::bevy_inspector::ui_for_value(
                            &mut material,
                            ui,
                            world,
                        ) {
                            world.entity_mut(mesh).insert(material);
                        }
                    });
                }
            });
        });
}

fn translucency_status(status: &bevy_mesostructure::translucency::TranslucencyStatus) -> String {
    use bevy_mesostructure::translucency::{TranslucencyStatus, precompute_elapsed};
    match status {
        TranslucencyStatus::Idle => "nothing takes part".into(),
        TranslucencyStatus::Loading => "waiting for meshes (or for them to stay still)".into(),
        TranslucencyStatus::Precomputing { .. } => format!(
            "precomputing ({:.1} s)",
            precompute_elapsed(status).unwrap_or_default().as_secs_f32()
        ),
        TranslucencyStatus::Ready { patches, report, from_cache } => {
            let entries = format!(
                "{patches} patches, {} + {} entries",
                report.form_factor_entries, report.scattering_entries
            );
            if *from_cache {
                format!("{entries}, loaded from the cache (precomputed in {:.2} s)", report.seconds)
            } else {
                format!("{entries}, precomputed in {:.2} s", report.seconds)
            }
        }
    }
}

/// A collapsible inspector for component `C` of every entity that has it.
fn edit_all<C: Component<Mutability = bevy::ecs::component::Mutable> + Reflect + Clone>(
    ui: &mut egui::Ui,
    world: &mut World,
    what: &str,
) {
    let entities: Vec<Entity> = world.query_filtered::<Entity, With<C>>().iter(world).collect();
    let name = std::any::type_name::<C>().rsplit("::").next().unwrap_or("");
    for entity in entities {
        ui.collapsing(format!("{what} {entity}: {name}"), |ui| {
            let mut value = world.get::<C>(entity).unwrap().clone();
            if bevy_inspector_egui::bevy_inspector::ui_for_value(&mut value, ui, world) {
                world.entity_mut(entity).insert(value);
            }
        });
    }
}

fn keys(
    mut commands: Commands,
    input: Res<ButtonInput<KeyCode>>,
    mut cameras: Query<(Entity, &mut Mesostructure, Option<&MesostructureDebugView>)>,
    mut clock: ResMut<super::Clock>,
    script: Res<super::Script>,
    mut taken: Local<u32>,
) {
    if input.just_pressed(KeyCode::Space) {
        clock.paused = !clock.paused;
    }
    if input.just_pressed(KeyCode::F12) {
        *taken += 1;
        let path = script.out.join(format!("screenshot-{}.png", *taken));
        println!("F12: writing {}", path.display());
        commands
            .spawn(bevy::render::view::screenshot::Screenshot::primary_window())
            .observe(bevy::render::view::screenshot::save_to_disk(path));
    }
    for (camera, mut m, view) in &mut cameras {
        if input.just_pressed(KeyCode::KeyO) {
            m.occlusion = !m.occlusion;
        }
        if input.just_pressed(KeyCode::KeyM) {
            m.micro_shadows = !m.micro_shadows;
        }
        if input.just_pressed(KeyCode::KeyB) {
            m.bleeding = !m.bleeding;
        }
        if input.just_pressed(KeyCode::KeyN) {
            m.bump_mapping = !m.bump_mapping;
        }
        if input.just_pressed(KeyCode::KeyV) {
            let next = view.copied().unwrap_or_default().next();
            commands.entity(camera).insert(next);
        }
    }
}

/// Prints the average time of each pass (headless runs: the software driver's figures are
/// relative only).
pub fn print_timings(world: &World) {
    let Some(store) = world.get_resource::<DiagnosticsStore>() else {
        return;
    };
    let times: Vec<String> = PASSES
        .iter()
        .filter_map(|p| pass_time(store, p).map(|ms| format!("{p} {ms:.2} ms")))
        .chain(
            [
                "volumetric/spots_compute",
                "volumetric/spots",
                "translucency/injection",
                "translucency/iteration",
                "translucency/gather",
            ]
                .into_iter()
                .filter_map(|span| span_time(store, span).map(|ms| format!("{span} {ms:.2} ms"))),
        )
        .collect();
    if !times.is_empty() {
        println!("average time per pass: {}", times.join(", "));
    }
    // Every span the GPU timed (Bevy's passes, the plugins' and their parts), averaged over
    // the frames that ran it.
    let spans: Vec<(String, f64)> = store
        .iter()
        .filter_map(|d| {
            let span = d.path().as_str().strip_prefix("render/")?.strip_suffix("/elapsed_gpu")?;
            Some((span.to_string(), d.average()?))
        })
        .collect();
    let nested = |span: &str| {
        spans
            .iter()
            .any(|(other, _)| span.strip_prefix(other.as_str()).is_some_and(|rest| rest.starts_with('/')))
    };
    // The translucency passes' parts (their nested spans).
    let mut parts: Vec<String> = spans
        .iter()
        .filter(|(span, _)| span.starts_with("translucency/") && nested(span))
        .map(|(span, ms)| format!("{span} {ms:.3} ms"))
        .collect();
    parts.sort();
    if !parts.is_empty() {
        println!("average time per part: {}", parts.join(", "));
    }
    // The outermost spans, and their sum: what a frame costs the GPU where each ran, to
    // compare with a plugin off.
    let top: Vec<&(String, f64)> = spans.iter().filter(|(span, _)| !nested(span)).collect();
    if !top.is_empty() {
        let total: f64 = top.iter().map(|(_, ms)| ms).sum();
        let each: Vec<String> = top.iter().map(|(span, ms)| format!("{span} {ms:.3}")).collect();
        println!("GPU time of all timed spans: {total:.3} ms ({})", each.join(", "));
    }
}

/// The translucency precompute's outcome, once it is ready.
pub fn translucency_ready(world: &World) -> Option<String> {
    use bevy_mesostructure::translucency::TranslucencyStatus;
    match world.get_resource::<TranslucencyStatus>()? {
        status @ TranslucencyStatus::Ready { .. } => Some(translucency_status(status)),
        _ => None,
    }
}
