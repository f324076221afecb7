//! The main-world side of [`TranslucencyPlugin`](super::TranslucencyPlugin): its components,
//! settings, status and the scene the render world takes; the lights' direct irradiance per
//! patch when they change, and the translucent objects' materials. The precompute is in
//! `precompute.rs`.

use std::{
    sync::Arc,
    time::{Duration, Instant},
};

use bevy::{
    prelude::*,
    render::extract_resource::ExtractResource,
};

use super::{
    medium::TranslucentMedium,
    precompute::{Precompute, hash_f32s},
    patches::Patches,
    translucent_shadow_map::MarchedMedium,
    lights::{light_numbers, lights_reaching},
    transport::{
        DirectLight, EnergyTransport, PatchLight, PatchSurface, SceneRays, TransportReport,
        TransportSettings, direct_light,
    },
};
use crate::warn_once::WarnedOnce;

/// A static mesh whose light diffuses through it (seed 001's subsurface patches). Needs a
/// `Mesh3d` with a `MeshMaterial3d<StandardMaterial>`; while its transport is ready the
/// plugin shades its diffuse part (the material's base colour is set aside; specular stays).
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Default)]
pub struct Translucent {
    /// What it is made of (coefficients in mm⁻¹).
    pub medium: TranslucentMedium,
    /// World units per millimetre (> 0): 0.001 for a scene in metres (Bevy's default scale).
    pub world_units_per_mm: f32,
    /// Take the diffusion dipole's flux between two patches along the exit patch's own normal,
    /// from sources placed along the entry patch's normal, instead of the flat profile at their
    /// distance ([`DiffusionProfile::orientation_factor`](super::diffusion::DiffusionProfile::orientation_factor)):
    /// the same on a plane; across the object, the light that crosses its bulk meets the far
    /// side head-on. Off by default. Turn it on for skin-like media in parts two to a few
    /// diffusion lengths across (`1/σtr`; ears, fingers, a hand lit from behind): a 1 cm ball
    /// of skin lit from behind goes from 0.61 to 0.31 relative L1 against a light-traced
    /// reference. Leave it off for objects not much larger than their diffusion length (a
    /// 1 cm ball of marble or apple comes out 1.6× too bright with it; `docs/translucent.md`).
    /// It matters only where the object keeps the flat profile
    /// ([`TransportSettings::shape_diffusion`](super::transport::TransportSettings::shape_diffusion)
    /// off): solved in its shape, an object takes the oriented flux anyway, with a correction
    /// for the light its surface lets out on the way (back-lit, skin 0.42 and marble 0.15).
    pub oriented_dipole: bool,
}

impl Default for Translucent {
    /// Marble in a scene in metres.
    fn default() -> Self {
        Self {
            medium: TranslucentMedium::default(),
            world_units_per_mm: 0.001,
            oriented_dipole: false,
        }
    }
}

/// A static opaque mesh that takes part in the radiosity: it receives light from the
/// translucent objects and the other patches and bounces it (Lambertian, with its
/// `StandardMaterial`'s base colour as albedo). Its direct light stays Bevy's; the plugin adds
/// the bounced light.
#[derive(Component, Reflect, Clone, Copy, Debug, Default, PartialEq)]
#[reflect(Component, Default)]
pub struct RadiosityReceiver;

/// The scene-wide settings of the translucency transport.
#[derive(Resource, Reflect, Clone, Debug, PartialEq)]
#[reflect(Resource, Default)]
pub struct TranslucencySettings {
    /// Patches over every participating mesh (16 – 200 000; more is capped with a warning).
    pub patch_budget: u32,
    /// The iteration stops once the energy still moving is below this share of the first
    /// bounce's (1e-6 – 0.5); the geometric tail of the increments is then added.
    pub iteration_threshold: f32,
    /// And after at most this many bounces (1 – 256).
    pub max_iterations: u32,
    /// Whether each light change starts the iteration from the last solution rather than
    /// from zero (`EnergyTransport::solve_from`): a spot turning 0.75° a frame then takes
    /// 2.3 – 2.6 products instead of 10 in the room of `docs/translucent.md`, within 6.6e-4
    /// of the converged exitance against a cold start's 2.8e-4 (it stops at a tenth of
    /// `iteration_threshold`). A warm start takes at most
    /// [`WARM_MAX_ITERATIONS`](super::transport::WARM_MAX_ITERATIONS) products a frame (on
    /// the GPU it records one more than the last solve took, read back without waiting) and
    /// goes on warm for [`settle_frames`](super::transport::settle_frames) frames after the
    /// lights stop: a quarter turn at once comes within 7.6e-4, 5.1e-4 after settling. On an
    /// H100 (1080p, 17.9 k patches) a moving spot's iteration takes 0.32–0.36 ms warm against
    /// 0.70–0.71 cold (changing it rebuilds nothing).
    pub warm_start: bool,
    /// How the transport is built.
    pub transport: TransportSettings,
    /// A folder to keep precomputed transports in (created if missing), one file per scene
    /// keyed by everything the transport depends on; `None` (the default) keeps nothing on
    /// disk.
    pub cache_dir: Option<std::path::PathBuf>,
    /// How the patches' light reaches the pixels (changing it rebuilds nothing).
    pub gather: GatherMethod,
    /// At how many pixels the gather runs (changing it rebuilds nothing).
    pub gather_resolution: GatherResolution,
    /// How the lights' direct light reaches the patches (changing it rebuilds nothing).
    pub light_injection: LightInjection,
}

/// How the lights' direct light reaches the patches whenever a light changes (seed 001's
/// injection). Both give the same fall-off, range window and incidence weights; they differ
/// in where they run and how they see shadows (measured against each other in
/// `docs/translucent.md`).
#[derive(Reflect, Clone, Copy, Debug, PartialEq)]
pub enum LightInjection {
    /// One shadow ray per patch and light from its centre through the precompute's BVH, on
    /// the CPU (main world, every core): exact visibility at the patch centre, whatever the
    /// lights, at main-thread time on every frame a light moves. No maps for single
    /// scattering to be marched on: the beam table keeps it (switching to or from this
    /// rebuilds the table).
    ShadowRays,
    /// The seed's way, on the GPU (`injection/`): each light's depth map splatted from the
    /// patches' samples in compute (`resolution` texels a side per face: one face for a
    /// directional light over the whole scene, six for a point or spot light), and each
    /// patch's light with the share of 3×3 texels about it that the light reaches. Costs the
    /// CPU nothing when lights move; shadow edges soften over a texel. Of more than
    /// [`MAX_INJECTED_LIGHTS`](super::injection::MAX_INJECTED_LIGHTS) lights that reach the
    /// patches, that many are taken, the brightest at them (with a warning saying how much
    /// light the rest could have given); lights that cannot reach them (range, cone) are
    /// left out with either injection.
    LightViewMaps {
        /// Texels a side of each map face (32 – 2048).
        resolution: u32,
    },
}

impl Default for LightInjection {
    /// On the GPU, 512 texels a side: within a few per cent of the shadow rays on the
    /// patches away from shadow edges (`docs/translucent.md`), 6 MB of maps per light.
    fn default() -> Self {
        Self::LightViewMaps { resolution: 512 }
    }
}

/// How each pixel takes the light of the patches about it (seed 001's last step); both look
/// at the patches within 1.5 of their own object's patch sizes whose normals agree with the
/// pixel's (`smoothstep(0.3, 0.9, n·nᵢ)`). Measured against each other in
/// `docs/translucent.md`.
#[derive(Reflect, Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum GatherMethod {
    /// Interpolates the patches' outgoing radiance `Lᵢ = (Bᵢ − ρᵢE⁰ᵢ)/π`:
    /// `Σ wᵢ Lᵢ / Σ wᵢ`, `wᵢ = (1 − d²/R²)²` times the normal agreement. Keeps a uniformly lit
    /// surface uniform at any patch spacing.
    #[default]
    Interpolation,
    /// The seed's photons: each patch's outgoing power `Φᵢ = (Bᵢ − ρᵢE⁰ᵢ) Aᵢ` at its centre,
    /// gathered by a kernel of unit integral over the surface, `M(x) = Σ Φᵢ K(dᵢ)`,
    /// `K(d) = 3/(πR²) (1 − d²/R²)²` (times the normal agreement), and `L = M/π`: density
    /// estimation, which conserves the power the patches give off but ripples with their
    /// spacing and darkens where the patches end.
    PhotonDensity,
}

/// At how many pixels the gather walks the patches. The light it adds changes on the scale
/// of a patch's reach, which at the sizes games show is several pixels.
#[derive(Reflect, Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum GatherResolution {
    /// Every pixel walks the patches about it.
    Full,
    /// One pixel in 2×2 walks them; every pixel then takes the light of the four such pixels
    /// about it that show its own surface (normals within ~25°, off its tangent plane by at
    /// most a quarter of their distance, within the reach of the patches they took), weighted
    /// bilinearly, and a pixel none of them serves (at a depth edge or a crease) walks the
    /// patches itself. Only where the view's main images take storage writes (the compute
    /// form of the gather; a view without them gathers every pixel). Measured against `Full`
    /// in `docs/translucent.md`.
    #[default]
    Half,
}

impl Default for TranslucencySettings {
    /// 4000 patches: a precompute of ~0.4 s on two CPU cores for a small room
    /// (`docs/translucent.md`); a threshold of 1e-2 (10 iterations in that room, within
    /// 0.03 % of the converged exitance with the geometric tail added; 1e-3 took 15 to come
    /// within 0.05–0.07 % without it); at most 16 (every iteration is recorded, and those
    /// after the stop still cost their empty dispatches; with the tail a bright box of albedo
    /// 0.9 capped at 16 comes within 2e-6); warm starts (a spot turning 0.75° a frame takes
    /// 2.3 – 2.6 products instead of 10 in that room).
    fn default() -> Self {
        Self {
            patch_budget: 4000,
            iteration_threshold: 1e-2,
            max_iterations: 16,
            warm_start: true,
            transport: TransportSettings::default(),
            cache_dir: None,
            gather: GatherMethod::default(),
            gather_resolution: GatherResolution::default(),
            light_injection: LightInjection::default(),
        }
    }
}

/// Frames a changed scene must stay the same before its transport is rebuilt (after the
/// first): moving or deforming participants are shaded by Bevy meanwhile instead of
/// precomputing every frame.
pub const SETTLE_FRAMES: u32 = 10;

/// The most patches the budget may ask for.
pub const MAX_PATCH_BUDGET: u32 = 200_000;

/// Where the precompute stands.
#[derive(Resource, Clone, Debug, Default)]
pub enum TranslucencyStatus {
    /// Nothing takes part.
    #[default]
    Idle,
    /// Waiting for meshes or materials to load.
    Loading,
    /// The precompute is running on a background task, started this long ago.
    Precomputing {
        /// When it started.
        since: Instant,
    },
    /// Ready.
    Ready {
        /// Patches.
        patches: usize,
        /// What the transport kept and cost (its precompute's, where it came from the cache).
        report: TransportReport,
        /// Whether it was loaded from [`TranslucencySettings::cache_dir`] rather than built.
        from_cache: bool,
    },
}

impl TranslucencyStatus {
    /// Whether `world` (an app's main world) is still loading or precomputing its transport:
    /// frames meant to show or time the transport — a loading screen's last, a test's or a
    /// benchmark's — wait for it. (A mesh that never stays still keeps it loading: bound the
    /// wait.)
    pub fn building(world: &World) -> bool {
        matches!(
            world.get_resource::<Self>(),
            Some(Self::Loading | Self::Precomputing { .. })
        )
    }
}

/// One precomputed static scene: its patches, transport and visibility, and what the gather
/// needs.
#[derive(Clone)]
pub struct TranslucencyScene {
    /// The patches.
    pub patches: Patches,
    /// `K` and `F`.
    pub transport: EnergyTransport,
    /// Visibility for the lights' injection.
    pub rays: SceneRays,
    /// Albedo per patch (zero on translucent patches: all their light is the transport's).
    pub albedo: Vec<Vec3>,
    /// How each patch's light leaves it ([`ExitLaw`](super::transport::ExitLaw)).
    pub exit_laws: Vec<super::transport::ExitLaw>,
    /// Per patch, where light entering it acts as a source
    /// ([`EnergyTransport::source_depths`]): what the beam table's light flow is measured from.
    pub source_depths: Vec<Vec3>,
    /// The entity of each object (`Patch::object` indexes it).
    pub entities: Vec<Entity>,
    /// Per object, the medium whose single scattering is marched per pixel (where the beam
    /// table leaves it to the pixels, [`BeamTableSettings::single_scattering_to_pixels`]); empty
    /// where none is.
    ///
    /// [`BeamTableSettings::single_scattering_to_pixels`]: super::beam_table::BeamTableSettings::single_scattering_to_pixels
    pub marched: Vec<Option<MarchedMedium>>,
    /// A sphere about every patch ([`Patches::bounding_sphere`]): the lights that cannot reach
    /// it are left out of the injection.
    pub bounds: (Vec3, f32),
    /// Per object, its surface (`Patch::object` indexes it).
    pub surfaces: Vec<PatchSurface>,
    /// The settings the transport was built with and its exit laws and incidence weights
    /// derived with ([`TransportSettings::derived`]).
    pub settings: TransportSettings,
}

/// What the render world takes each frame.
#[derive(Resource, Clone, Default, ExtractResource)]
pub struct TranslucencyFrame {
    /// The scene and its generation (changes when it is rebuilt).
    pub scene: Option<(u64, Arc<TranslucencyScene>)>,
    /// This frame's direct light per patch, and its generation (changes when a light
    /// does), where the CPU injects it ([`LightInjection::ShadowRays`]).
    pub direct: Option<(u64, Arc<DirectLight>)>,
    /// The lights for the GPU to inject, and their generation (changes when a light does),
    /// where the GPU injects them ([`LightInjection::LightViewMaps`]).
    pub lights: Option<(u64, Arc<InjectedLights>)>,
    /// The settings.
    pub settings: TranslucencySettings,
}

/// The lights for the GPU's injection ([`LightInjection::LightViewMaps`]).
#[derive(Clone, Debug, PartialEq)]
pub struct InjectedLights {
    /// The lights, at most [`MAX_INJECTED_LIGHTS`](super::injection::MAX_INJECTED_LIGHTS).
    pub lights: Vec<PatchLight>,
    /// Bevy's ambient irradiance, taken by translucent patches.
    pub ambient: Vec3,
    /// Texels a side of each map face.
    pub resolution: u32,
}

/// The original material of a translucent mesh and the copy without diffuse shown while its
/// transport is ready.
#[derive(Component, Clone, Debug)]
pub struct TranslucentMaterials {
    /// The material as the user gave it.
    pub original: Handle<StandardMaterial>,
    /// Its copy with a black base colour (the diffuse comes from the patches).
    pub without_diffuse: Handle<StandardMaterial>,
}

/// Gives each new translucent mesh its material without diffuse.
pub(crate) fn prepare_translucent_materials(
    mut commands: Commands,
    new: Query<
        (Entity, &MeshMaterial3d<StandardMaterial>),
        (With<Translucent>, Without<TranslucentMaterials>),
    >,
    mut materials: ResMut<Assets<StandardMaterial>>,
) {
    for (entity, material) in &new {
        let Some(original) = materials.get(&material.0).cloned() else {
            continue;
        };
        let without_diffuse = materials.add(StandardMaterial {
            base_color: Color::BLACK,
            base_color_texture: None,
            diffuse_transmission: 0.0,
            ..original
        });
        commands.entity(entity).insert(TranslucentMaterials {
            original: material.0.clone(),
            without_diffuse,
        });
    }
}

/// The lights as the transport injects them, when they change.
pub(crate) fn inject_direct_light(
    directional: Query<(&DirectionalLight, &GlobalTransform)>,
    points: Query<(&PointLight, &GlobalTransform)>,
    spots: Query<(&SpotLight, &GlobalTransform)>,
    ambient: Option<Res<bevy::light::GlobalAmbientLight>>,
    mut state: ResMut<Precompute>,
    mut frame: ResMut<TranslucencyFrame>,
    mut warned: ResMut<WarnedOnce>,
) {
    let Some((_, scene)) = frame.scene.clone() else {
        return;
    };
    let colour = |c: Color, scale: f32| {
        let c = c.to_linear();
        Vec3::new(c.red, c.green, c.blue) * scale
    };
    let candela = 1.0 / (4.0 * std::f32::consts::PI);
    let mut lights = Vec::new();
    for (light, transform) in &directional {
        lights.push(PatchLight::Directional {
            direction: transform.forward().as_vec3(),
            illuminance: colour(light.color, light.illuminance),
        });
    }
    for (light, transform) in &points {
        lights.push(PatchLight::Point {
            position: transform.translation(),
            intensity: colour(light.color, light.intensity * candela),
            range: light.range,
        });
    }
    for (light, transform) in &spots {
        lights.push(PatchLight::Spot {
            position: transform.translation(),
            direction: transform.forward().as_vec3(),
            intensity: colour(light.color, light.intensity * candela),
            inner_angle: light.inner_angle,
            outer_angle: light.outer_angle,
            range: light.range,
        });
    }
    // Bevy's ambient light: uniform radiance `brightness × colour`, irradiance π times it.
    // Bevy lights opaque surfaces with it itself; the translucent ones show no diffuse of their
    // own, so it enters them here (unoccluded, as Bevy's is without SSAO).
    let ambient = ambient.map_or(Vec3::ZERO, |a| {
        colour(a.color, a.brightness * std::f32::consts::PI)
    });
    // Only the lights whose light can reach the patches (lossless: the rest give none), and
    // for the GPU's injection at most as many as it takes, the brightest at the scene.
    let most = match frame.settings.light_injection {
        LightInjection::LightViewMaps { .. } => super::injection::MAX_INJECTED_LIGHTS,
        LightInjection::ShadowRays => usize::MAX,
    };
    let reaching = lights_reaching(&lights, scene.bounds.0, scene.bounds.1, most);
    if reaching.left_out > 0 {
        warned.warn("translucency-injection-lights", || {
            format!(
                "translucency: {} lights reach the translucent scene, more than the GPU injection's {}; \
                 the {} brightest there are taken and {} left out of the transport (at most {:.0} % \
                 of the light there; LightInjection::ShadowRays takes every light, on the CPU)",
                reaching.lights.len() + reaching.left_out,
                super::injection::MAX_INJECTED_LIGHTS,
                reaching.lights.len(),
                reaching.left_out,
                100.0 * reaching.left_out_share
            )
        });
    }
    let lights = reaching.lights;
    let mut signature: Vec<u64> = lights.iter().map(|l| hash_f32s(light_numbers(l))).collect();
    signature.push(hash_f32s(ambient.to_array()));
    let on_gpu = match frame.settings.light_injection {
        LightInjection::LightViewMaps { resolution } => {
            let range = super::injection::LIGHT_VIEW_RESOLUTIONS;
            if !range.contains(&resolution) {
                warned.warn("translucency-injection-resolution", || {
                    format!(
                        "translucency: a light-view resolution of {resolution} is outside {} – {}; clamped",
                        range.start(),
                        range.end()
                    )
                });
            }
            Some(resolution.clamp(*range.start(), *range.end()))
        }
        LightInjection::ShadowRays => None,
    };
    signature.push(on_gpu.map_or(0, |r| r as u64 + 1));
    if signature == state.direct_signature && (frame.direct.is_some() || frame.lights.is_some()) {
        return;
    }
    state.direct_signature = signature;
    state.direct_generation += 1;
    if let Some(resolution) = on_gpu {
        frame.direct = None;
        frame.lights = Some((
            state.direct_generation,
            Arc::new(InjectedLights {
                lights,
                ambient,
                resolution,
            }),
        ));
        return;
    }
    frame.lights = None;
    let mut direct = direct_light(&scene.patches, Some(&scene.transport), &lights, &scene.rays);
    if ambient != Vec3::ZERO {
        for (e, albedo) in direct.irradiance.iter_mut().zip(&scene.albedo) {
            if *albedo == Vec3::ZERO {
                *e += ambient;
            }
        }
    }
    frame.direct = Some((state.direct_generation, Arc::new(direct)));
}

/// Shows each translucent mesh without its diffuse while its transport is ready, and with
/// its own material otherwise (loading, precomputing, or taking no part).
pub(crate) fn swap_translucent_materials(
    mut meshes: Query<(
        Entity,
        &mut MeshMaterial3d<StandardMaterial>,
        &TranslucentMaterials,
        Has<Translucent>,
    )>,
    frame: Res<TranslucencyFrame>,
    status: Res<TranslucencyStatus>,
) {
    let ready = matches!(*status, TranslucencyStatus::Ready { .. });
    let scene = frame.scene.as_ref().filter(|_| ready).map(|(_, s)| s);
    for (entity, mut material, materials, translucent) in &mut meshes {
        let takes_part = translucent && scene.is_some_and(|s| s.entities.contains(&entity));
        let wanted = if takes_part {
            &materials.without_diffuse
        } else {
            &materials.original
        };
        if material.0 != *wanted {
            material.0 = wanted.clone();
        }
    }
}

/// How long ago the precompute started, if it runs.
pub fn precompute_elapsed(status: &TranslucencyStatus) -> Option<Duration> {
    match status {
        TranslucencyStatus::Precomputing { since } => Some(since.elapsed()),
        _ => None,
    }
}
