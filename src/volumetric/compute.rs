//! The compute form of the volumetric spots' full-resolution pass (`compute_spots` in
//! `spots.wgsl`): where a view's main images take storage writes, it reads the lit image and
//! writes in-scatter + transmittance × lit into the other one (Bevy's post-process ping-pong),
//! culling spots per 8 × 8 tile. Bevy's mesh view bindings are visible to fragment shaders only,
//! so it binds the part of them that Bevy's spot-shadow lookup reads, at Bevy's binding
//! numbers, in a layout of its own.

use bevy::{
    pbr::{GlobalClusterableObjectMeta, MeshPipelineKey, deferred::DeferredLightingLayout},
    platform::collections::HashMap,
    prelude::*,
    render::{
        render_resource::{binding_types::*, *},
        renderer::{RenderContext, RenderDevice},
        view::ViewTarget,
    },
    shader::ShaderDefVal,
};

use super::extract::{VolumetricUniform, VolumetricUniforms};

/// The compute form's layouts and its pipelines by view key.
pub struct ComputeForm {
    /// Group 0: the part of Bevy's mesh view bindings that its spot-shadow lookup reads (view,
    /// lights, the spot shadow maps and their comparison sampler, the clustered lights,
    /// globals), at Bevy's binding numbers and visible to compute.
    light_layout: BindGroupLayoutDescriptor,
    /// Group 1: empty (the fragment form's binding arrays).
    empty_layout: BindGroupLayoutDescriptor,
    /// Group 2: the volumetric uniform, the depth buffer, the lit image and the image written.
    spots_layout: BindGroupLayoutDescriptor,
    pipelines: HashMap<MeshPipelineKey, CachedComputePipelineId>,
    /// Whether the device gives Bevy's clustered lights a storage buffer (the layout assumes
    /// it; otherwise the fragment form runs).
    supported: bool,
}

impl ComputeForm {
    pub fn new(device: &RenderDevice) -> Self {
        let light_layout = BindGroupLayoutDescriptor::new(
            "volumetric_spots_light_layout",
            &BindGroupLayoutEntries::with_indices(
                ShaderStages::COMPUTE,
                (
                    (0, uniform_buffer::<bevy::render::view::ViewUniform>(true)),
                    (1, uniform_buffer::<bevy::pbr::GpuLights>(true)),
                    (5, texture_2d_array(TextureSampleType::Depth)),
                    (6, sampler(SamplerBindingType::Comparison)),
                    (8, storage_buffer_read_only_sized(false, None)),
                    (11, uniform_buffer::<bevy::render::globals::GlobalsUniform>(false)),
                ),
            ),
        );
        let spots_layout = BindGroupLayoutDescriptor::new(
            "volumetric_spots_compute_layout",
            &BindGroupLayoutEntries::with_indices(
                ShaderStages::COMPUTE,
                (
                    (0, uniform_buffer::<VolumetricUniform>(true)),
                    (2, texture_depth_2d()),
                    (3, texture_2d(TextureSampleType::Float { filterable: false })),
                    (
                        4,
                        texture_storage_2d(
                            crate::render::VIEW_TARGET_FORMAT,
                            StorageTextureAccess::WriteOnly,
                        ),
                    ),
                ),
            ),
        );
        Self {
            light_layout,
            empty_layout: BindGroupLayoutDescriptor::new("volumetric_spots_empty_layout", &[]),
            spots_layout,
            pipelines: HashMap::default(),
            supported: matches!(
                device.get_supported_read_only_binding_type(3),
                BufferBindingType::Storage { .. }
            ),
        }
    }

    /// The pipeline for views of `key` (queued the first time), where the device allows the
    /// compute form: Bevy's shader defs for the view (its shadow filtering, light limits), as
    /// the fragment form gets them from Bevy's deferred lighting pipeline, less the PCSS
    /// samplers this layout does not bind.
    pub fn pipeline(
        &mut self,
        pipeline_cache: &PipelineCache,
        deferred: &DeferredLightingLayout,
        shader: Handle<Shader>,
        key: MeshPipelineKey,
    ) -> Option<CachedComputePipelineId> {
        if !self.supported {
            return None;
        }
        if let Some(&id) = self.pipelines.get(&key) {
            return Some(id);
        }
        let mut shader_defs = deferred
            .specialize(key)
            .fragment
            .map(|f| f.shader_defs)
            .unwrap_or_default();
        shader_defs.retain(
            |d| !matches!(d, ShaderDefVal::Bool(name, _) if name == "PCSS_SAMPLERS_AVAILABLE"),
        );
        shader_defs.push("COMPUTE_PASS".into());
        let id = pipeline_cache.queue_compute_pipeline(ComputePipelineDescriptor {
            label: Some("volumetric_spots_compute_pipeline".into()),
            layout: vec![
                self.light_layout.clone(),
                self.empty_layout.clone(),
                self.spots_layout.clone(),
            ],
            shader,
            shader_defs,
            entry_point: Some("compute_spots".into()),
            ..default()
        });
        self.pipelines.insert(key, id);
        Some(id)
    }

    /// Records the compute form for a view, timed as `volumetric/spots_compute`; false (nothing
    /// recorded, the main images not flipped) where it cannot run this frame — main images
    /// without storage writes, the pipeline not compiled yet, a resource not ready — and the
    /// fragment form runs instead.
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        ctx: &mut RenderContext,
        pipeline_cache: &PipelineCache,
        id: CachedComputePipelineId,
        uniforms: &VolumetricUniforms,
        lights: &LightResources,
        (view_offset, lights_offset, shadows, prepass): (
            &bevy::render::view::ViewUniformOffset,
            &bevy::pbr::ViewLightsUniformOffset,
            &bevy::pbr::ViewShadowBindings,
            &bevy::core_pipeline::prepass::ViewPrepassTextures,
        ),
        volumetric_offset: u32,
        target: &ViewTarget,
    ) -> bool {
        if !crate::render::composites_in_compute(target) {
            return false;
        }
        let Some(pipeline) = pipeline_cache.get_compute_pipeline(id) else {
            return false;
        };
        let (
            Some(view),
            Some(lights_binding),
            Some(clustered),
            Some(globals),
            Some(volumetric),
            Some(depth),
        ) = (
            lights.view_uniforms.uniforms.binding(),
            lights.light_meta.view_gpu_lights.binding(),
            lights.clusterables.as_ref().and_then(|c| c.gpu_clustered_lights.binding()),
            lights.globals.buffer.binding(),
            uniforms.0.binding(),
            prepass.depth_view(),
        )
        else {
            return false;
        };
        let device = ctx.render_device().clone();
        let light_group = device.create_bind_group(
            "volumetric_spots_light_bind_group",
            &pipeline_cache.get_bind_group_layout(&self.light_layout),
            &BindGroupEntries::with_indices((
                (0, view),
                (1, lights_binding),
                (5, &shadows.directional_light_depth_texture_view),
                (6, &lights.shadow_samplers.directional_light_comparison_sampler),
                (8, clustered),
                (11, globals),
            )),
        );
        let empty = device.create_bind_group(
            "volumetric_spots_empty_bind_group",
            &pipeline_cache.get_bind_group_layout(&self.empty_layout),
            &[],
        );
        let post = target.post_process_write();
        let spots_group = device.create_bind_group(
            "volumetric_spots_compute_bind_group",
            &pipeline_cache.get_bind_group_layout(&self.spots_layout),
            &BindGroupEntries::with_indices((
                (0, volumetric),
                (2, depth),
                (3, post.source),
                (4, post.destination),
            )),
        );
        // Every pixel of the main image, inside the viewport or not (it is a new image).
        let size = target.main_texture().size();
        crate::render::dispatch_per_pixel_with(
            ctx,
            "volumetric/spots_compute",
            pipeline,
            &[
                (&light_group, &[view_offset.offset, lights_offset.offset]),
                (&empty, &[]),
                (&spots_group, &[volumetric_offset]),
            ],
            UVec2::new(size.width, size.height),
            |_| {},
        );
        true
    }
}

/// What the compute form reads of a view beyond the fragment form's: its view and lights
/// offsets, its shadow maps and its depth.
pub type ComputeViewBindings = (
    &'static bevy::render::view::ViewUniformOffset,
    &'static bevy::pbr::ViewLightsUniformOffset,
    &'static bevy::pbr::ViewShadowBindings,
    &'static bevy::core_pipeline::prepass::ViewPrepassTextures,
);

/// Bevy's light and view resources that the compute form binds itself.
#[derive(bevy::ecs::system::SystemParam)]
pub struct LightResources<'w> {
    view_uniforms: Res<'w, bevy::render::view::ViewUniforms>,
    light_meta: Res<'w, bevy::pbr::LightMeta>,
    clusterables: Option<Res<'w, GlobalClusterableObjectMeta>>,
    shadow_samplers: Res<'w, bevy::pbr::ShadowSamplers>,
    globals: Res<'w, bevy::render::globals::GlobalsBuffer>,
}
