//! Occlusion pass (compute): apex sets → mesostructure ambient occlusion (paper §3.1), times a
//! coarse horizon-based AO of the depth buffer with the apex sets' adaptive step.

use bevy::{
    prelude::*,
    render::{
        render_phase::ViewSortedRenderPhases,
        render_resource::{binding_types::*, *},
        renderer::{RenderContext, ViewQuery},
        view::{ExtractedView, ViewUniform, ViewUniformOffset},
    },
};

use super::{
    OCCLUSION_FORMAT, ViewMesostructureBindGroups, ViewMesostructureTextures,
    ViewMesostructureUniformOffset, dispatch_per_pixel, height::HeightPhaseItem,
    view_has_mesostructure,
};
use crate::settings::{ExtractedMesostructure, MesostructureUniform};

/// Pipeline and layout of the occlusion pass.
#[derive(Resource)]
pub struct OcclusionPipeline {
    /// MHM, core normals, apex sets, occlusion (storage), settings, view, MHGM, prepass depth,
    /// bump normals (whose `w` carries the height pass's texture-space occlusion).
    pub layout: BindGroupLayoutDescriptor,
    /// The compute pipeline.
    pub pipeline: CachedComputePipelineId,
}

/// Queues the occlusion pipeline (render startup).
pub fn init_occlusion_pipeline(
    mut commands: Commands,
    pipeline_cache: Res<PipelineCache>,
    asset_server: Res<AssetServer>,
) {
    let layout = BindGroupLayoutDescriptor::new(
        "mesostructure_occlusion_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::COMPUTE,
            (
                texture_2d(TextureSampleType::Float { filterable: false }),
                texture_2d(TextureSampleType::Float { filterable: false }),
                storage_buffer_read_only_sized(false, None),
                texture_storage_2d(OCCLUSION_FORMAT, StorageTextureAccess::WriteOnly),
                uniform_buffer::<MesostructureUniform>(true),
                uniform_buffer::<ViewUniform>(true),
                texture_2d(TextureSampleType::Float { filterable: false }),
                texture_depth_2d(),
                texture_2d(TextureSampleType::Float { filterable: false }),
            ),
        ),
    );
    let pipeline = pipeline_cache.queue_compute_pipeline(ComputePipelineDescriptor {
        label: Some("mesostructure_occlusion_pipeline".into()),
        layout: vec![layout.clone()],
        shader: bevy::asset::load_embedded_asset!(asset_server.as_ref(), "occlusion.wgsl"),
        entry_point: Some("occlusion".into()),
        ..default()
    });
    commands.insert_resource(OcclusionPipeline { layout, pipeline });
}

/// Core3d system: computes the occlusion of the current view, timed as
/// `mesostructure/occlusion`; skipped when `Mesostructure::occlusion` is off.
pub fn occlusion_pass(
    view: ViewQuery<(
        &ExtractedView,
        &ExtractedMesostructure,
        &ViewMesostructureTextures,
        &ViewMesostructureBindGroups,
        &ViewMesostructureUniformOffset,
        &ViewUniformOffset,
    )>,
    phases: Res<ViewSortedRenderPhases<HeightPhaseItem>>,
    pipeline: Res<OcclusionPipeline>,
    pipeline_cache: Res<PipelineCache>,
    mut ctx: RenderContext,
) {
    let (extracted_view, settings, textures, bind_groups, offset, view_offset) = view.into_inner();
    if !settings.0.occlusion || !view_has_mesostructure(&phases, extracted_view) {
        return;
    }
    let Some(compute) = pipeline_cache.get_compute_pipeline(pipeline.pipeline) else {
        return;
    };
    dispatch_per_pixel(
        &mut ctx,
        "mesostructure/occlusion",
        compute,
        &bind_groups.occlusion,
        &[offset.0, view_offset.offset],
        textures.size,
        |_| {},
    );
}
