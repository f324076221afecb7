//! Translucent objects lit globally: seed 001's radiosity with dipole subsurface transport
//! (Wang, Shi, Wang and Zhao, patent CN102819860, 2012).
//!
//! The method, in three steps:
//! 1. **Precompute**, once per static scene: resample every object into near-uniform patches
//!    ([`patches`]); build a sparse energy-transport operator — the dipole diffusion profile
//!    between patches of one translucent object ([`diffusion`]) and radiosity form factors
//!    between patches that see each other ([`transport`]).
//! 2. **Per frame**: inject the lights' direct irradiance into the patches, then iterate
//!    `B ← K E⁰ + K F B` (the seed's `L = (S F)^N S L`) until the energy still moving falls
//!    below a threshold.
//! 3. Turn each patch's exitance into the picture.
//!
//! [`TranslucencyPlugin`] runs it in an app: meshes with [`Translucent`] (and opaque ones with
//! [`RadiosityReceiver`]) are resampled and their transport precomputed on a background task
//! ([`TranslucencyStatus`]); when a light changes, the direct light of each patch is injected
//! on the GPU from each light's view (`injection/`; or on the CPU by one shadow ray per patch
//! and light, [`LightInjection::ShadowRays`]) and the iteration runs on the GPU
//! (`iteration/`); cameras with [`TranslucencyCamera`] gather the patches' light per pixel
//! (`gather/`).
//! `docs/translucent.md` says what is measured and what is not built yet.

pub mod beam_table;
pub mod cache;
pub mod diffusion;
pub mod exit_lobe;
mod far_field;
pub mod gather;
pub mod injection;
pub mod iteration;
mod lights;
pub mod medium;
pub mod patches;
mod plugin;
mod precompute;
pub mod random_walk;
mod rays;
pub mod shape_diffusion;
mod sparse;
pub mod transport;
pub mod translucent_shadow_map;

use bevy::{
    core_pipeline::{
        Core3dSystems,
        core_3d::{main_opaque_pass_3d, main_transparent_pass_3d},
        schedule::Core3d,
    },
    prelude::*,
    render::{
        Render, RenderApp, RenderStartup, RenderSystems, extract_component::ExtractComponentPlugin,
        extract_resource::ExtractResourcePlugin, render_resource::SpecializedRenderPipelines,
    },
};

pub use gather::TranslucencyCamera;
pub use plugin::{
    GatherMethod, GatherResolution, InjectedLights, LightInjection, MAX_PATCH_BUDGET, RadiosityReceiver,
    TranslucencyFrame, TranslucencyScene,
    TranslucencySettings, TranslucencyStatus, Translucent, TranslucentMaterials,
    precompute_elapsed,
};
pub use precompute::{MAX_MARCHED_OBJECTS, translucent_patch_cap};

/// Translucent objects lit globally (seed 001): [`Translucent`] on static meshes,
/// [`RadiosityReceiver`] on the opaque ones that bounce light, [`TranslucencyCamera`] on the
/// cameras that show it, [`TranslucencySettings`] for the scene.
#[derive(Default)]
pub struct TranslucencyPlugin;

impl Plugin for TranslucencyPlugin {
    fn build(&self, app: &mut App) {
        crate::warn_once::install(app);
        bevy::shader::load_shader_library!(app, "boundary.wgsl");
        bevy::shader::load_shader_library!(app, "gather/marched.wgsl");
        bevy::shader::load_shader_library!(app, "gather/gathered.wgsl");
        bevy::asset::embedded_asset!(app, "gather/gather.wgsl");
        bevy::asset::embedded_asset!(app, "gather/gather_compute.wgsl");
        app.register_type::<Translucent>()
            .register_type::<RadiosityReceiver>()
            .register_type::<TranslucencyCamera>()
            .register_type::<TranslucencySettings>()
            .init_resource::<TranslucencySettings>()
            .init_resource::<TranslucencyStatus>()
            .init_resource::<TranslucencyFrame>()
            .init_resource::<precompute::Precompute>()
            .add_plugins((
                ExtractComponentPlugin::<TranslucencyCamera>::default(),
                ExtractResourcePlugin::<TranslucencyFrame>::default(),
            ))
            .add_systems(
                PostUpdate,
                (
                    plugin::prepare_translucent_materials,
                    precompute::run_precompute,
                    plugin::inject_direct_light,
                    plugin::swap_translucent_materials,
                )
                    .chain()
                    .after(TransformSystems::Propagate),
            )
            // The gather's compute form writes the main images itself.
            .add_systems(
                PostUpdate,
                crate::render::request_storage_main_textures::<TranslucencyCamera>,
            );
        let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
            return;
        };
        render_app
            .init_resource::<gather::TranslucencyGpu>()
            .init_resource::<SpecializedRenderPipelines<gather::GatherPipeline>>()
            .add_systems(RenderStartup, gather::init_gather_pipeline)
            .add_systems(
                Render,
                (
                    gather::prepare_gather_pipelines.in_set(RenderSystems::Prepare),
                    gather::prepare_translucency.in_set(RenderSystems::PrepareResources),
                    iteration::map_products_readback.in_set(RenderSystems::Cleanup),
                ),
            )
            .add_systems(
                Core3d,
                (
                    injection::translucency_injection_pass
                        .in_set(Core3dSystems::MainPass)
                        .before(iteration::translucency_iteration_pass),
                    iteration::translucency_iteration_pass
                        .in_set(Core3dSystems::MainPass)
                        .before(main_opaque_pass_3d),
                    // After the bleeding, which may flip the view's main images (its compute
                    // form writes the other one): the gather must draw into the current one.
                    gather::translucency_gather_pass
                        .in_set(Core3dSystems::MainPass)
                        .in_set(crate::MesostructureSystems::TranslucencyGather)
                        .after(crate::MesostructureSystems::Bleeding)
                        .after(main_opaque_pass_3d)
                        .before(main_transparent_pass_3d),
                ),
            );
    }
}

#[cfg(test)]
mod tests;

pub use diffusion::{DiffusionKernel, DiffusionProfile};
pub use medium::{TranslucentMedium, TranslucentPreset};
pub use patches::{
    Patch, PatchObject, Patches, resample_into_patches, resample_into_patches_with_caps,
};
pub use transport::{
    DirectLight, EnergyTransport, ExitLaw, MAX_SHAPE_ENERGY_DROPPED, PatchLight, PatchSurface, SceneRays, SparseMatrix,
    TransportReport, TransportSettings, TransportSolution, direct_irradiance, direct_light,
    patch_albedos,
};

/// `boundary.wgsl` (the translucency's shared boundary functions: Fresnel's reflectance, the
/// deep field's exit law) appended to a raw wgpu shader's `source`, its naga_oil import path line taken out: the
/// injection's and the iteration's shaders are not Bevy assets and cannot `#import` it as the
/// gather does.
pub(crate) fn with_boundary(source: &str) -> String {
    let boundary: String = include_str!("boundary.wgsl")
        .lines()
        .filter(|line| !line.starts_with("#define_import_path"))
        .map(|line| format!("{line}\n"))
        .collect();
    format!("{source}\n{boundary}")
}
