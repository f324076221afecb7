//! The precompute of [`TranslucencyPlugin`](super::TranslucencyPlugin): what takes part and
//! its signature, and on a change (once it has stayed the same for
//! [`SETTLE_FRAMES`](super::plugin::SETTLE_FRAMES)) the patches, the transport, the beam table
//! and the exit laws on a background task, from the disk cache where it holds them.

use std::{sync::Arc, time::Instant};

use bevy::{
    prelude::*,
    tasks::{AsyncComputeTaskPool, Task, block_on, poll_once},
};

use super::{
    patches::{resample_into_patches_with_caps, world_triangles},
    plugin::{
        LightInjection, MAX_PATCH_BUDGET, RadiosityReceiver, SETTLE_FRAMES, TranslucencyFrame,
        TranslucencyScene, TranslucencySettings, TranslucencyStatus, Translucent,
        TranslucentMaterials,
    },
    translucent_shadow_map::MarchedMedium,
    transport::{EnergyTransport, MAX_SHAPE_ENERGY_DROPPED, PatchSurface, SceneRays, TransportSettings},
};
use crate::warn_once::WarnedOnce;

/// The signature of what takes part: when it changes, the precompute runs again.
#[derive(Resource, Default)]
pub(crate) struct Precompute {
    signature: Vec<u64>,
    /// Per participant of the transport built last, its entity, mesh and transform (hashed):
    /// what tells a mesh that moved from one added, removed or restyled.
    placements: Vec<(u64, u64, u64)>,
    /// How many times each mesh was modified in place (`AssetEvent::Modified`): a mesh
    /// deformed under the same handle changes its participant's signature too.
    mesh_revisions: bevy::platform::collections::HashMap<AssetId<Mesh>, u64>,
    /// A changed signature waiting to stay the same for [`SETTLE_FRAMES`] before a rebuild,
    /// and for how many frames it has.
    settling: Option<(Vec<u64>, u32)>,
    task: Option<Task<(TranslucencyScene, Vec<String>, bool)>>,
    generation: u64,
    /// The lights' signature and generation (`inject_direct_light`, which the scene's
    /// rebuild restarts).
    pub(super) direct_signature: Vec<u64>,
    pub(super) direct_generation: u64,
}

type Participant<'a> = (
    Entity,
    &'a Mesh3d,
    &'a MeshMaterial3d<StandardMaterial>,
    &'a GlobalTransform,
    Option<&'a Translucent>,
    Option<&'a TranslucentMaterials>,
    // Skinned or morphed: deformed on the GPU every frame, under an unchanged `Mesh`.
    Has<bevy::mesh::skinning::SkinnedMesh>,
    Has<bevy::mesh::morph::MeshMorphWeights>,
);

pub(super) fn hash_of(value: impl std::hash::Hash) -> u64 {
    use std::hash::Hasher;
    let mut hasher = std::collections::hash_map::DefaultHasher::new();
    value.hash(&mut hasher);
    hasher.finish()
}

pub(super) fn hash_f32s(values: impl IntoIterator<Item = f32>) -> u64 {
    super::cache::Hash::new().f32s(values).0
}

/// Whether the table leaves single scattering to the pixels' march: where it asks to and the
/// GPU injects the lights (the march reads the injection's maps; with shadow rays the table
/// keeps single scattering).
fn marches(settings: &TranslucencySettings, table: &super::beam_table::BeamTableSettings) -> bool {
    table.single_scattering_to_pixels && matches!(settings.light_injection, LightInjection::LightViewMaps { .. })
}

/// The most translucent objects whose single scattering is marched per pixel (a map a light
/// each, 1.5 MiB; 96 MiB at 8 lights).
pub const MAX_MARCHED_OBJECTS: usize = 8;

/// Starts the precompute when what takes part changes; collects it when done.
#[allow(clippy::too_many_arguments)]
pub(crate) fn run_precompute(
    participants: Query<Participant, Or<(With<Translucent>, With<RadiosityReceiver>)>>,
    meshes: Res<Assets<Mesh>>,
    materials: Res<Assets<StandardMaterial>>,
    mut settings: ResMut<TranslucencySettings>,
    mut state: ResMut<Precompute>,
    mut status: ResMut<TranslucencyStatus>,
    mut frame: ResMut<TranslucencyFrame>,
    mut warned: ResMut<WarnedOnce>,
    mut mesh_events: MessageReader<AssetEvent<Mesh>>,
) {
    for event in mesh_events.read() {
        if let AssetEvent::Modified { id } = event {
            *state.mesh_revisions.entry(*id).or_default() += 1;
        }
    }
    if settings.patch_budget > MAX_PATCH_BUDGET || settings.patch_budget < 16 {
        let capped = settings.patch_budget.clamp(16, MAX_PATCH_BUDGET);
        warned.warn("translucency-budget", || {
            format!(
                "translucency: a patch budget of {} is outside 16 – {MAX_PATCH_BUDGET}; using {capped}",
                settings.patch_budget
            )
        });
        settings.patch_budget = capped;
    }
    let dropped = settings.transport.shape_energy_dropped;
    if !(0.0..=MAX_SHAPE_ENERGY_DROPPED).contains(&dropped) {
        let fallback = if dropped.is_nan() {
            TransportSettings::default().shape_energy_dropped
        } else {
            dropped.clamp(0.0, MAX_SHAPE_ENERGY_DROPPED)
        };
        warned.warn("translucency-shape-energy-dropped", || {
            format!("translucency: a shape_energy_dropped of {dropped} is outside 0 – {MAX_SHAPE_ENERGY_DROPPED}; using {fallback}")
        });
        settings.transport.shape_energy_dropped = fallback;
    }
    if let Some(table) = settings.transport.beam_table.as_mut() {
        // The exit directions are the CPU oracle's (translucent_accuracy --exit-axis lobe): the
        // GPU gather does not take the lobes fitted to them, and each early entry would cost
        // 15 floats instead of 3 for nothing on screen.
        if std::mem::take(&mut table.exit_directions) {
            warned.warn("translucency-exit-directions", || {
                "translucency: BeamTableSettings::exit_directions is for the CPU oracle \
                 (translucent_accuracy --exit-axis lobe); the plugin's gather does not use it, so \
                 it is turned off"
                    .to_string()
            });
        }
    }
    let mut list: Vec<_> = participants.iter().collect();
    list.sort_by_key(|p| p.0);
    // The signature: entities, meshes, transforms, media, albedos and the settings the
    // transport is built with (not those only derived from it, `TransportSettings::derived`,
    // which `derive_again` takes on the scene already built).
    let mut signature = vec![
        settings.patch_budget as u64,
        hash_f32s([
            settings.transport.diffusion_energy_kept,
            settings.transport.form_factor_cutoff,
            settings.transport.far_field_ratio,
            settings.transport.cluster_size as f32,
            settings.transport.kernel as u32 as f32,
            settings.transport.object_exit_share as u32 as f32,
            settings.transport.shape_diffusion as u32 as f32,
            settings.transport.shape_energy_dropped,
        ]),
        // The beam table's settings (none: all zero).
        hash_f32s(settings.transport.beam_table.map_or([0.0; 10], |t| {
            [t.cosines, t.azimuths, t.walks, t.late_walks, t.last_order, t.seed, t.max_patches, marches(&settings, &t) as u32, t.far_splits, t.max_last_order]
                .map(|v| v as f32)
        })),
    ];
    let mut placements = Vec::with_capacity(list.len());
    for (entity, mesh, material, transform, translucent, _, skinned, morphed) in &list {
        signature.push(u64::from(*skinned) | u64::from(*morphed) << 1);
        let revision = state.mesh_revisions.get(&mesh.0.id()).copied().unwrap_or(0);
        let placement = (
            entity.to_bits(),
            hash_of((mesh.0.id(), revision)),
            hash_f32s(transform.to_matrix().to_cols_array()),
        );
        placements.push(placement);
        signature.extend([placement.0, placement.1, placement.2]);
        if translucent.is_none() {
            let albedo = materials
                .get(&material.0)
                .map(|m| m.base_color.to_linear().to_f32_array());
            signature.push(hash_f32s(albedo.unwrap_or([-1.0; 4])));
        }
        if let Some(t) = translucent {
            signature.push(hash_f32s(
                t.medium
                    .absorption
                    .to_array()
                    .into_iter()
                    .chain(t.medium.reduced_scattering.to_array())
                    .chain([
                        t.medium.index_of_refraction,
                        t.world_units_per_mm,
                        t.oriented_dipole as u32 as f32,
                    ]),
            ));
        }
    }
    if signature != state.signature {
        // After a first transport: static only. Back to Bevy's shading until the scene has
        // stayed the same for a few frames, then rebuilt.
        if state.generation > 0 {
            let frames = match &state.settling {
                Some((pending, frames)) if *pending == signature => frames + 1,
                _ => 0,
            };
            if frames == 0 {
                // A participant whose mesh or transform is not the one the transport was built
                // for is a warning (the transport is for static scenes); objects added or
                // removed, a medium, an albedo or the settings changed are the game's own
                // edits, and only say that the transport is rebuilt.
                let moved = placements.iter().any(|&(entity, mesh, transform)| {
                    state
                        .placements
                        .iter()
                        .any(|&(e, m, t)| e == entity && (m, t) != (mesh, transform))
                });
                if moved && (frame.scene.is_some() || state.task.is_some()) {
                    warned.warn("translucency-moved", || {
                        "translucency: a translucent or radiosity mesh moved or deformed; the \
                         transport is for static scenes: Bevy shades them until they stay still, \
                         then the transport is rebuilt"
                            .to_string()
                    });
                } else if !moved && state.settling.is_none() {
                    info!(
                        "translucency: translucent or radiosity objects were added, removed or \
                         changed, or the settings were; Bevy shades them until the transport is \
                         rebuilt"
                    );
                }
                state.task = None;
                frame.scene = None;
                frame.direct = None;
                frame.lights = None;
                *status = TranslucencyStatus::Loading;
            }
            if frames < SETTLE_FRAMES {
                state.settling = Some((signature, frames));
                frame.settings = settings.clone();
                return;
            }
        }
        state.settling = None;
        state.signature = signature;
        state.placements = placements;
        state.task = None;
        frame.scene = None;
        frame.direct = None;
        frame.lights = None;
        if list.iter().all(|p| p.4.is_none()) {
            *status = TranslucencyStatus::Idle;
            return;
        }
        // Every mesh loaded and a triangle list; translucent media valid.
        let mut objects = Vec::new();
        let mut entities = Vec::new();
        for (entity, mesh, material, transform, translucent, swapped, skinned, morphed) in &list {
            // The transport is for static meshes: a skinned or morphed one deforms every frame
            // without its `Mesh` changing, so it takes no part (Bevy shades it).
            if *skinned || *morphed {
                warned.warn(format!("translucency-animated-{entity}"), || {
                    format!(
                        "translucency: {entity} is {}; the transport is for static meshes, so it \
                         takes no part and is shaded by Bevy",
                        if *skinned { "skinned" } else { "morphed" }
                    )
                });
                continue;
            }
            // Translucent meshes may show their copy without diffuse: read the original.
            let material = swapped.map_or(&material.0, |m| &m.original);
            let (Some(mesh), Some(material)) = (meshes.get(&mesh.0), materials.get(material))
            else {
                *status = TranslucencyStatus::Loading;
                state.signature.clear();
                return;
            };
            let Some((positions, indices)) = world_triangles(mesh, transform) else {
                warned.warn(format!("translucency-mesh-{entity}"), || {
                    format!("translucency: the mesh of {entity} is not a triangle list with positions; it takes no part")
                });
                continue;
            };
            let surface = match translucent {
                Some(t) => {
                    if let Some(reason) = t.medium.invalid_reason() {
                        warned.warn(format!("translucency-medium-{entity}"), || {
                            format!("translucency: {entity}'s medium is unusable ({reason}); it is shaded by Bevy")
                        });
                        continue;
                    }
                    if !(t.world_units_per_mm.is_finite() && t.world_units_per_mm > 0.0) {
                        warned.warn(format!("translucency-units-{entity}"), || {
                            format!("translucency: {entity}'s world_units_per_mm {} must be positive; it is shaded by Bevy", t.world_units_per_mm)
                        });
                        continue;
                    }
                    PatchSurface::Translucent {
                        medium: t.medium,
                        world_units_per_mm: t.world_units_per_mm,
                        oriented_dipole: t.oriented_dipole,
                    }
                }
                None => {
                    let c = material.base_color.to_linear();
                    PatchSurface::Opaque {
                        albedo: Vec3::new(c.red, c.green, c.blue),
                    }
                }
            };
            objects.push((positions, indices, surface));
            entities.push(*entity);
        }
        let budget = settings.patch_budget as usize;
        let mut transport_settings = settings.transport;
        if let Some(table) = transport_settings.beam_table.as_mut() {
            table.single_scattering_to_pixels = marches(&settings, table);
        }
        // Each translucent object marching its single scattering takes a map a light
        // (1.5 MiB each); beyond `MAX_MARCHED_OBJECTS` the table keeps it for the smaller ones.
        let translucent_objects = objects.iter().filter(|o| matches!(o.2, PatchSurface::Translucent { .. })).count();
        if let Some(table) = transport_settings.beam_table.as_ref()
            && table.single_scattering_to_pixels
            && translucent_objects > MAX_MARCHED_OBJECTS
        {
            warned.warn("translucency-marched-objects", || {
                format!(
                    "translucency: {translucent_objects} translucent objects are more than the \
                     {MAX_MARCHED_OBJECTS} that march their single scattering per pixel; the \
                     {MAX_MARCHED_OBJECTS} largest march, the beam table keeps it for the others"
                )
            });
        }
        let cache_dir = settings.cache_dir.clone();
        state.task = Some(AsyncComputeTaskPool::get().spawn(async move {
            let views: Vec<_> = objects
                .iter()
                .map(|(p, i, _)| super::patches::PatchObject { positions: p, indices: i })
                .collect();
            let surfaces: Vec<PatchSurface> = objects.iter().map(|o| o.2).collect();
            let rays = SceneRays::new(&views);
            let mut notes = Vec::new();
            // From the cache where it holds this very scene; else built (and kept).
            let file = cache_dir.as_ref().map(|dir| {
                let keyed: Vec<_> = objects.iter().map(|(p, i, s)| (p.as_slice(), i.as_slice(), *s)).collect();
                let key = super::cache::scene_key(&keyed, budget, &transport_settings);
                dir.join(format!("{key:016x}.translucency"))
            });
            let cached = file.as_ref().and_then(|path| match super::cache::load(path) {
                Ok(loaded) => Some(loaded),
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
                Err(e) => {
                    notes.push(format!("translucency: the cached transport {} is unreadable ({e}); built again", path.display()));
                    None
                }
            });
            let from_cache = cached.is_some();
            let (patches, mut transport) = cached.unwrap_or_else(|| {
                let caps: Vec<Option<f32>> = surfaces
                    .iter()
                    .map(|s| translucent_patch_cap(s, &transport_settings))
                    .collect();
                let patches = resample_into_patches_with_caps(&views, &caps, budget);
                let transport = EnergyTransport::build(&patches, &surfaces, &rays, &transport_settings);
                if let Some(path) = &file {
                    let kept = path
                        .parent()
                        .map_or(Ok(()), std::fs::create_dir_all)
                        .and_then(|_| super::cache::save(path, &patches, &transport));
                    if let Err(e) = kept {
                        notes.push(format!("translucency: cannot keep the transport in {} ({e})", path.display()));
                    }
                }
                (patches, transport)
            });
            if let (Some(table), skipped @ 1..) = (transport_settings.beam_table, transport.report.beam_table_skipped) {
                notes.push(format!(
                    "translucency: {skipped} translucent patches are more than the beam table's max_patches ({}); \
                     their beams enter by the diffusion profile (raise BeamTableSettings::max_patches, or lower the patch budget)",
                    table.max_patches
                ));
            }
            let exit_laws = derived_from(&mut transport, &patches, &surfaces, &transport_settings);
            let albedo = super::transport::patch_albedos(&patches, &surfaces);
            let source_depths = EnergyTransport::source_depths(&patches, &surfaces);
            let marched = match transport.beam_table.as_ref() {
                Some(table) if table.settings.single_scattering_to_pixels => {
                    let marching = super::beam_table::marched_objects(&patches, &surfaces);
                    surfaces.iter().zip(marching).map(|(s, m)| if m { MarchedMedium::of(s) } else { None }).collect()
                }
                _ => Vec::new(),
            };
            let bounds = patches.bounding_sphere();
            let scene = TranslucencyScene {
                patches,
                transport,
                rays,
                albedo,
                exit_laws,
                source_depths,
                entities,
                marched,
                bounds,
                surfaces,
                settings: transport_settings,
            };
            (scene, notes, from_cache)
        }));
        *status = TranslucencyStatus::Precomputing {
            since: Instant::now(),
        };
    }
    if let Some(task) = state.task.as_mut()
        && let Some((scene, notes, from_cache)) = block_on(poll_once(task))
    {
        for note in notes {
            warned.warn(note.clone(), || note);
        }
        state.task = None;
        state.generation += 1;
        state.direct_signature.clear();
        *status = TranslucencyStatus::Ready {
            patches: scene.patches.patches.len(),
            report: scene.transport.report.clone(),
            from_cache,
        };
        frame.scene = Some((state.generation, Arc::new(scene)));
    }
    derive_again(&settings.transport, &mut state, &mut frame);
    frame.settings = settings.clone();
}

/// Sets `transport`'s incidence weights for `settings` and returns each patch's exit law: what
/// a scene derives from its transport, on a build, a load from the cache, or a change of
/// [`TransportSettings::derived`].
fn derived_from(
    transport: &mut EnergyTransport,
    patches: &super::patches::Patches,
    surfaces: &[PatchSurface],
    settings: &TransportSettings,
) -> Vec<super::transport::ExitLaw> {
    transport.incidence = EnergyTransport::incidence_weights(surfaces, settings);
    transport.exit_laws(patches, surfaces, settings)
}

/// Where [`TransportSettings::derived`] changed since the scene was derived, derives its exit
/// laws and incidence weights again on the transport already built, as a new generation of the
/// scene (a copy of it on the main thread, not timed; the GPU takes it whole and the lights
/// are injected again). Toggling one of these in a
/// tuning panel rebuilt the whole transport before (tens of seconds at a 20 k budget, the
/// meshes shaded by Bevy meanwhile), and `beam_incidence` was not seen at all until a rebuild.
fn derive_again(settings: &TransportSettings, state: &mut Precompute, frame: &mut TranslucencyFrame) {
    let Some((_, scene)) = &frame.scene else {
        return;
    };
    if scene.settings.derived() == settings.derived() {
        return;
    }
    let mut scene = TranslucencyScene::clone(scene);
    scene.settings = scene.settings.with_derived_from(settings);
    scene.exit_laws = derived_from(&mut scene.transport, &scene.patches, &scene.surfaces, &scene.settings);
    state.generation += 1;
    state.direct_signature.clear();
    frame.scene = Some((state.generation, Arc::new(scene)));
}

/// The widest patch a translucent object may have: a third of the radius within which its
/// profile gives off 99 % of its light, so that each patch has neighbours to pass light to
/// (with the room's uniform share, a 10 cm marble bunny got 68 patches of 21 mm and the
/// Burley profile, 99 % within ~9 mm, reached none of them).
pub fn translucent_patch_cap(surface: &PatchSurface, settings: &TransportSettings) -> Option<f32> {
    match *surface {
        PatchSurface::Translucent {
            medium,
            world_units_per_mm,
            ..
        } => {
            let profile = super::diffusion::DiffusionProfile::new(&medium, settings.kernel);
            Some((profile.radius_holding(0.99) / 3.0) as f32 * world_units_per_mm)
        }
        PatchSurface::Opaque { .. } => None,
    }
}

