//! Volumetric spot lights by equal-angle sampling (seed 004, issue 12): single scattering of
//! Bevy's spot lights in a homogeneous medium, usable with or without the mesostructure plugin.
//!
//! ```no_run
//! # use bevy::prelude::*;
//! # use bevy_mesostructure::volumetric::*;
//! # let mut app = App::new();
//! app.add_plugins(VolumetricSpotsPlugin);
//! # let mut commands = app.world_mut().commands();
//! // The medium the camera looks through (per metre), and the spots that light it.
//! commands.spawn((Camera3d::default(), VolumetricMedium::default()));
//! commands.spawn((SpotLight::default(), VolumetricSpot::default()));
//! ```
//!
//! Per pixel, the view ray from the camera to the depth buffer is clipped to each spot's cone
//! and range, and its in-scatter integrated with `samples` points at **equal angles around the
//! light** — the change of variable `t = t_c + h tan γ` of [`reference`](mod@reference), which cancels the 1/d²
//! spike near the light — with extinction along the ray and from the light to each point,
//! Bevy's angular fall-off and range window, the spot's own shadow map (where it has one) at
//! every point, and a Henyey–Greenstein phase function; added to
//! the view between the opaque and transparent passes, whose surfaces it dims by the medium's
//! transmittance in front of them (the sky is left undimmed). At full resolution it is a
//! compute pass (timed as `volumetric/spots_compute`) writing the view's other main image
//! through Bevy's post-process ping-pong; the plugin asks for storage writes on the main images
//! of `Hdr` cameras with a [`VolumetricMedium`], and where they have none (a camera's own
//! `CameraMainTextureUsages`, an LDR camera) a fullscreen fragment pass does the same work
//! (timed as `volumetric/spots`). Both read Bevy's own lights and spot shadow maps (the compute
//! pass binds the part of Bevy's mesh view bindings it needs, at Bevy's binding numbers, so
//! Bevy's shadow lookup and filtering run unchanged). Culling: a spot whose cone is outside a
//! camera's frustum is skipped for it; the compute pass keeps, per 8 × 8 tile, the spots whose
//! projected bounding rectangle overlaps the tile and whose bounding sphere begins in front of
//! the tile's farthest surface; with no cone in view the pass only dims the surfaces (none at
//! all in a transparent medium).
//! Half and quarter resolutions ([`VolumetricResolution`]) upsample by depth; the seed's own
//! rasterised sampling planes are [`VolumetricMethod::SlicingPlanes`], for comparison (both
//! fragment passes). Use an `Hdr` camera: the in-scatter is added in linear light.
//! [`reference`](mod@reference) is the exact CPU ground truth.

mod compute;
mod extract;
pub mod reference;
mod render;

use bevy::{
    core_pipeline::{
        Core3dSystems,
        core_3d::{main_opaque_pass_3d, main_transparent_pass_3d},
        prepass::DepthPrepass,
        schedule::Core3d,
    },
    prelude::*,
    render::{
        ExtractSchedule, Render, RenderApp, RenderStartup, RenderSystems,
        sync_component::SyncComponentPlugin,
    },
};

use extract::*;
use render::*;

/// The most spots with [`VolumetricSpot`] drawn per frame (more are skipped, with a warning).
pub const MAX_VOLUMETRIC_SPOTS: usize = 64;
/// The most samples (or sampling planes) per spot ([`VolumetricSpot::samples`]).
pub const MAX_VOLUMETRIC_SAMPLES: u32 = 64;

/// The participating medium a camera sees its volumetric spots through: homogeneous, filling
/// the world. Coefficients per world unit (per metre at Bevy's scale). Requires the depth
/// prepass (the view ray stops at the depth buffer's surface) and `Msaa::Off`.
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Default)]
#[require(DepthPrepass)]
pub struct VolumetricMedium {
    /// Scattering coefficient σs (≥ 0, per world unit): how much light the medium sends
    /// towards the eye. Default 0.1: a haze in which a spot's beam is plainly visible and a
    /// 10 m room still clear (e^(−1.1) of the light crosses it).
    pub scattering: f32,
    /// Absorption coefficient σa (≥ 0, per world unit). Default 0.01.
    pub absorption: f32,
    /// Henyey–Greenstein asymmetry g (−0.95 to 0.95): > 0 scatters forward (a beam looks
    /// brighter looking into the light). Default 0 (isotropic).
    pub asymmetry: f32,
    /// Where the in-scatter is computed: every pixel, or one pixel in 2×2 or 4×4 with a
    /// depth-aware upsample (the surfaces' dimming stays per pixel). Default `Full`. The
    /// slicing planes are always drawn at full resolution.
    pub resolution: VolumetricResolution,
    /// How the in-scatter is sampled. Default [`VolumetricMethod::EqualAngleRays`].
    pub method: VolumetricMethod,
}

/// How the in-scatter along the view rays is sampled ([`VolumetricMedium::method`]).
#[derive(Reflect, Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[reflect(Default)]
pub enum VolumetricMethod {
    /// Per pixel, the view ray clipped to each cone and sampled at equal angles around the
    /// light (`samples` of them): seed 004's spacing as a change of variable along each ray,
    /// exact where the ray passes close to the light.
    #[default]
    EqualAngleRays,
    /// Seed 004 as it rasterises: `samples` planes per spot, perpendicular to the view axis
    /// and spaced at equal angles around the light, drawn over the cone's part of the screen
    /// and added where they lie in front of the depth buffer. Shared by every pixel, so a ray
    /// passing near the light may meet none of them inside the cone (docs/volumetric.md); for
    /// comparison.
    SlicingPlanes,
}

impl Default for VolumetricMedium {
    fn default() -> Self {
        Self {
            scattering: 0.1,
            absorption: 0.01,
            asymmetry: 0.0,
            resolution: VolumetricResolution::Full,
            method: VolumetricMethod::EqualAngleRays,
        }
    }
}

/// The resolution of the in-scatter ([`VolumetricMedium::resolution`]).
#[derive(Reflect, Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[reflect(Default)]
pub enum VolumetricResolution {
    /// Every pixel.
    #[default]
    Full,
    /// One pixel in 2×2 (a quarter of the work), upsampled by depth.
    Half,
    /// One pixel in 4×4 (a sixteenth), upsampled by depth.
    Quarter,
}

impl VolumetricResolution {
    /// Side of the block of pixels one computed pixel stands for.
    pub fn factor(self) -> u32 {
        match self {
            Self::Full => 1,
            Self::Half => 2,
            Self::Quarter => 4,
        }
    }
}

/// Put on a [`SpotLight`] entity to make its light visible in the cameras' [`VolumetricMedium`].
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Default)]
pub struct VolumetricSpot {
    /// Scale of the light's intensity in the medium (≥ 0; 1 = physical, as the surfaces see
    /// it).
    pub intensity_scale: f32,
    /// Points per pixel at equal angles around the light (1–64; with
    /// [`VolumetricMethod::SlicingPlanes`], planes for this spot). Default 16: within 1 % of
    /// the exact in-scatter on unshadowed rays, and 0.1 % on rays passing a few centimetres
    /// from the light (`reference` tests).
    pub samples: u32,
}

impl Default for VolumetricSpot {
    fn default() -> Self {
        Self {
            intensity_scale: 1.0,
            samples: 16,
        }
    }
}

/// Adds volumetric spot lights: [`VolumetricMedium`] on a camera, [`VolumetricSpot`] on spot
/// lights.
#[derive(Default)]
pub struct VolumetricSpotsPlugin;

impl Plugin for VolumetricSpotsPlugin {
    fn build(&self, app: &mut App) {
        crate::warn_once::install(app);
        bevy::asset::embedded_asset!(app, "spots.wgsl");
        app.register_type::<VolumetricMedium>()
            .register_type::<VolumetricResolution>()
            .register_type::<VolumetricMethod>()
            .register_type::<VolumetricSpot>()
            .add_plugins(SyncComponentPlugin::<VolumetricMedium>::default())
            .add_systems(
                PostUpdate,
                crate::render::request_storage_main_textures::<VolumetricMedium>,
            );
        let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
            return;
        };
        render_app
            .init_resource::<ExtractedVolumetricSpots>()
            .init_resource::<VolumetricUniforms>()
            .add_systems(
                RenderStartup,
                init_volumetric_pipeline.after(bevy::pbr::MeshPipelineSystems),
            )
            .add_systems(ExtractSchedule, (extract_volumetric_cameras, extract_volumetric_spots))
            .add_systems(
                Render,
                (
                    prepare_volumetric_pipelines.in_set(RenderSystems::Prepare),
                    prepare_volumetric_uniforms.in_set(RenderSystems::PrepareResources),
                ),
            )
            .add_systems(
                Core3d,
                // After every pass that adds light to the surfaces (the medium dims what they
                // send), and ordered against them because the compute form flips the view's
                // main images: unordered, two flips could reach the GPU in the other order.
                volumetric_spots_pass
                    .in_set(Core3dSystems::MainPass)
                    .after(crate::MesostructureSystems::Bleeding)
                    .after(crate::MesostructureSystems::TranslucencyGather)
                    .after(main_opaque_pass_3d)
                    .before(main_transparent_pass_3d),
            );
    }
}

