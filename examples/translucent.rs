//! Translucent objects lit globally (seed 001): a marble bunny and a skin-like sphere in a
//! small room with a red and a green wall, a spot light moving from in front of them to
//! behind them.
//!
//! Where there is a display it opens a window with the tuning panel (each object's
//! `Translucent`, the scene's `TranslucencySettings`, the precompute's status, the GPU time
//! of the iteration and the gather). Where there is none (or with `--headless`) it renders
//! headless and writes PNG screenshots: lit from the front, from behind, and the back-lit
//! frame as Bevy shades it without the plugin's transport.
//!
//! ```text
//! cargo run --example translucent -- [--frames N] [--out DIR] [--size WxH] [--headless]
//!     [--patches N] [--injection light-view|shadow-rays] [--shape-diffusion true|false]
//!     [--deep-exit-law true|false] [--max-iterations N] [--warm-start true|false] [--swing]
//!     [--gather-resolution full|half]
//! ```

#[path = "common/mod.rs"]
mod common;
// Only `obj_mesh` and `asset_path` are used here.
#[allow(dead_code)]
#[path = "common/meshes.rs"]
mod meshes;

use bevy::{camera::Exposure, camera::Hdr, prelude::*};
use bevy_mesostructure::translucency::{
    GatherResolution, LightInjection, RadiosityReceiver, TranslucencyCamera, TranslucencyPlugin, TranslucencySettings, Translucent,
    TranslucentPreset, TransportSettings,
};

/// A marble bunny and a skin sphere lit through; a window with the tuning panel, or headless
/// PNGs lit from the front, from behind, and from behind without the transport.
#[derive(clap::Parser)]
#[command(long_about = None)]
struct Cli {
    #[command(flatten)]
    common: common::CommonArgs,
    /// Patch budget of the scene (16 – 200000)
    #[arg(long, default_value_t = 4000, value_parser = clap::value_parser!(u32).range(16..=200_000))]
    patches: u32,
    /// How the lights reach the patches: the GPU's light-view maps or the CPU's shadow rays
    #[arg(long, value_enum, default_value_t = Injection::LightView)]
    injection: Injection,
    /// Solve each object's diffusion in its shape (`TransportSettings::shape_diffusion`)
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    shape_diffusion: bool,
    /// Light from deep inside leaves limb-darkened (`TransportSettings::deep_exit_law`)
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    deep_exit_law: bool,
    /// At most this many iterations a frame (`TranslucencySettings::max_iterations`)
    #[arg(long, default_value_t = TranslucencySettings::default().max_iterations,
          value_parser = clap::value_parser!(u32).range(1..=256))]
    max_iterations: u32,
    /// Start each light change's iteration from the last solution
    /// (`TranslucencySettings::warm_start`)
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    warm_start: bool,
    /// Carry the lights' beams into the translucent objects by a table of beam columns from
    /// random walks (`TransportSettings::beam_table`, on by default; ~0.05 s a translucent
    /// patch on one core in release to precompute); `false`: the diffusion profile alone
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    beam_table: bool,
    /// With the beam table, light from afar leaves by lobes leaning the way it travelled
    /// (`TransportSettings::exit_lobes`)
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    exit_lobes: bool,
    /// With the beam table, lean the light that crossed an object towards the camera about
    /// its silhouette: diffusion's flux along the surface (`TransportSettings::tangential_flux`,
    /// on by default; it leans marble-like media, never skin: `tangential_flux_mode_weight`)
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    tangential_flux: bool,
    /// Headless: swing the spot during the warm-up frames, as in a window, so that every frame
    /// injects and iterates anew (for timing; the shots still fix it in front and behind)
    #[arg(long)]
    swing: bool,
    /// At how many pixels the gather walks the patches (`TranslucencySettings::gather_resolution`;
    /// its default when not given)
    #[arg(long, value_enum)]
    gather_resolution: Option<Resolution>,
    /// Keep the precomputed transport in this folder and load it from there when the scene
    /// and settings are the same (`TranslucencySettings::cache_dir`)
    #[arg(long)]
    cache_dir: Option<std::path::PathBuf>,
    /// `false`: the same room with Bevy's shading alone (no `TranslucencyPlugin`, no
    /// `TranslucencyCamera` and so no prepass): the frame the plugin's cost is measured against
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    translucency: bool,
    /// With `--translucency false`: give the camera the depth and normal prepass that
    /// `TranslucencyCamera` asks for all the same (what the prepass alone costs)
    #[arg(long)]
    prepass: bool,
    /// Add a small lamp 1 mm off the skin sphere's face, inside its bounds: the sphere's
    /// single scattering from it is marched against a cube of six maps about it (what a cube
    /// costs)
    #[arg(long)]
    lamp: bool,
}

/// `--gather-resolution`: [`GatherResolution`]'s two.
#[derive(clap::ValueEnum, Clone, Copy)]
enum Resolution {
    Full,
    Half,
}

/// `--injection`: [`LightInjection`]'s two ways.
#[derive(clap::ValueEnum, Clone, Copy)]
enum Injection {
    LightView,
    ShadowRays,
}

/// Where the spot is: `0` in front of the objects, `1` behind them (headless shots set it;
/// in a window it swings between the two).
#[derive(Resource)]
struct SpotPlace {
    fixed: Option<f32>,
}

fn main() {
    use clap::Parser;
    let cli = Cli::parse();
    if cli.prepass && cli.translucency {
        common::fail("--prepass is for --translucency false (the plugin's camera has its prepass already)");
    }
    let args = common::ExampleArgs::from_cli("translucent", cli.common);
    let shots = vec![
        common::Shot {
            file: "translucent_front.png".into(),
            apply: Box::new(|world: &mut World| {
                world.resource_mut::<SpotPlace>().fixed = Some(0.0);
            }),
        },
        common::Shot {
            file: "translucent_back.png".into(),
            apply: Box::new(|world: &mut World| {
                world.resource_mut::<SpotPlace>().fixed = Some(1.0);
            }),
        },
        common::Shot {
            file: "translucent_back_bevy.png".into(),
            apply: Box::new(|world: &mut World| {
                let mut q = world.query_filtered::<Entity, With<Translucent>>();
                for e in q.iter(world).collect::<Vec<_>>() {
                    world.entity_mut(e).remove::<Translucent>();
                }
            }),
        },
    ];
    let windowed = args.windowed();
    let mut app = common::app(&args, "bevy_mesostructure: translucent", shots);
    if cli.translucency {
        app.add_plugins(TranslucencyPlugin);
    }
    app.insert_resource(ClearColor(Color::BLACK))
        .insert_resource(bevy::light::GlobalAmbientLight {
            brightness: 0.0,
            ..default()
        })
        .insert_resource(TranslucencySettings {
            patch_budget: cli.patches,
            light_injection: match cli.injection {
                Injection::LightView => LightInjection::default(),
                Injection::ShadowRays => LightInjection::ShadowRays,
            },
            transport: TransportSettings {
                shape_diffusion: cli.shape_diffusion,
                deep_exit_law: cli.deep_exit_law,
                beam_table: cli.beam_table.then(default),
                exit_lobes: cli.exit_lobes,
                tangential_flux: cli.tangential_flux,
                ..default()
            },
            max_iterations: cli.max_iterations,
            warm_start: cli.warm_start,
            gather_resolution: match cli.gather_resolution {
                Some(Resolution::Full) => GatherResolution::Full,
                Some(Resolution::Half) => GatherResolution::Half,
                None => GatherResolution::default(),
            },
            cache_dir: cli.cache_dir,
            ..default()
        })
        .insert_resource(SpotPlace {
            fixed: (!windowed && !cli.swing).then_some(0.0),
        })
        .add_systems(Update, move_spot);
    setup(app.world_mut(), cli.translucency, cli.prepass, cli.lamp);
    common::run(app);
}

fn setup(world: &mut World, translucency: bool, prepass: bool, lamp: bool) {
    let target = world.resource::<common::Output>().target();
    let mut camera = world.spawn((
        Camera3d::default(),
        target,
        Hdr,
        Msaa::Off,
        // A dim room lit by one small spot: exposed for it.
        Exposure { ev100: 7.0 },
        Transform::from_xyz(0.0, 0.12, 0.42).looking_at(Vec3::new(0.0, 0.05, 0.0), Vec3::Y),
    ));
    if translucency {
        camera.insert(TranslucencyCamera);
    } else if prepass {
        camera.insert((
            bevy::core_pipeline::prepass::DepthPrepass,
            bevy::core_pipeline::prepass::NormalPrepass,
        ));
    }
    let mut mesh = |m: Mesh| world.resource_mut::<Assets<Mesh>>().add(m);
    let bunny = mesh(meshes::obj_mesh(
        &meshes::asset_path("meshes/bunny.obj"),
        1.0,
    ));
    let sphere = mesh(
        Sphere::new(0.03)
            .mesh()
            .ico(5)
            .expect("a valid subdivision"),
    );
    let half = 0.3;
    let wall = mesh(Plane3d::new(Vec3::Y, Vec2::splat(half)).mesh().build());
    let mut material = |base_color: Color, roughness: f32| {
        world
            .resource_mut::<Assets<StandardMaterial>>()
            .add(StandardMaterial {
                base_color,
                perceptual_roughness: roughness,
                ..default()
            })
    };
    let white = material(Color::srgb(0.75, 0.75, 0.75), 0.9);
    let red = material(Color::srgb(0.75, 0.1, 0.1), 0.9);
    let green = material(Color::srgb(0.1, 0.75, 0.1), 0.9);
    let marble = material(Color::WHITE, 0.3);
    let skin = material(Color::srgb(0.9, 0.7, 0.6), 0.5);
    world.spawn((
        Mesh3d(bunny),
        MeshMaterial3d(marble),
        // Longest side 1.6 → 10 cm, resting on the floor.
        Transform::from_xyz(-0.06, 0.05, 0.0).with_scale(Vec3::splat(0.0625)),
        Translucent {
            medium: TranslucentPreset::Marble.medium(),
            world_units_per_mm: 0.001,
            ..default()
        },
    ));
    let sphere_at = Vec3::new(0.08, 0.03, 0.02);
    if lamp {
        // 1.033 radii from the centre, towards the camera and the room's middle.
        world.spawn((
            PointLight { intensity: 2.0, range: 1.0, ..default() },
            Transform::from_translation(sphere_at + Vec3::new(-0.5, 0.3, 0.8).normalize() * 0.031),
        ));
    }
    world.spawn((
        Mesh3d(sphere),
        MeshMaterial3d(skin),
        Transform::from_translation(sphere_at),
        Translucent {
            medium: TranslucentPreset::Skin1.medium(),
            world_units_per_mm: 0.001,
            ..default()
        },
    ));
    // The room, inside out: each plane's normal faces inwards.
    let quarter = std::f32::consts::FRAC_PI_2;
    for (material, transform) in [
        (white.clone(), Transform::IDENTITY),
        (
            white.clone(),
            Transform::from_xyz(0.0, 2.0 * half, 0.0)
                .with_rotation(Quat::from_rotation_x(2.0 * quarter)),
        ),
        (
            red,
            Transform::from_xyz(-half, half, 0.0).with_rotation(Quat::from_rotation_z(-quarter)),
        ),
        (
            green,
            Transform::from_xyz(half, half, 0.0).with_rotation(Quat::from_rotation_z(quarter)),
        ),
        (
            white.clone(),
            Transform::from_xyz(0.0, half, -half).with_rotation(Quat::from_rotation_x(quarter)),
        ),
    ] {
        world.spawn((
            Mesh3d(wall.clone()),
            MeshMaterial3d(material),
            transform,
            RadiosityReceiver,
        ));
    }
    world.spawn((
        SpotLight {
            intensity: 800.0,
            range: 5.0,
            inner_angle: 0.3,
            outer_angle: 0.5,
            shadow_maps_enabled: true,
            ..default()
        },
        Transform::from_xyz(0.0, 0.2, 0.25).looking_at(Vec3::new(0.0, 0.04, 0.0), Vec3::Y),
    ));
}

/// The spot circles the objects at a fixed height, from in front (`0`) to behind (`1`).
fn move_spot(
    clock: Res<common::Clock>,
    place: Res<SpotPlace>,
    mut spots: Query<&mut Transform, With<SpotLight>>,
) {
    let s = place
        .fixed
        .unwrap_or_else(|| 0.5 - 0.5 * (clock.t * 0.5).cos());
    let angle = s * std::f32::consts::PI;
    let position = Vec3::new(0.25 * angle.sin(), 0.2, 0.25 * angle.cos());
    for mut transform in &mut spots {
        *transform =
            Transform::from_translation(position).looking_at(Vec3::new(0.0, 0.04, 0.0), Vec3::Y);
    }
}
