//! Gradient pass (compute): MHM → MHGM with boundary flags (paper §2.1).

use bevy::{
    prelude::*,
    render::{
        render_phase::ViewSortedRenderPhases,
        render_resource::{binding_types::*, *},
        renderer::{RenderContext, ViewQuery},
        view::ExtractedView,
    },
};

use super::{
    MHGM_FORMAT, ViewMesostructureBindGroups, ViewMesostructureTextures,
    ViewMesostructureUniformOffset, dispatch_per_pixel, height::HeightPhaseItem,
    view_has_mesostructure,
};
use crate::render::view_settings::MesostructureUniform;

/// Embeds the pass's shaders (their asset paths follow this folder).
pub(super) fn embed_shaders(app: &mut App) {
    bevy::asset::embedded_asset!(app, "gradient.wgsl");
}

/// Pipeline and layout of the gradient pass.
#[derive(Resource)]
pub struct GradientPipeline {
    /// MHM, MHGM (storage), settings.
    pub layout: BindGroupLayoutDescriptor,
    /// The compute pipeline.
    pub pipeline: CachedComputePipelineId,
}

/// Queues the gradient pipeline (render startup).
pub fn init_gradient_pipeline(
    mut commands: Commands,
    pipeline_cache: Res<PipelineCache>,
    asset_server: Res<AssetServer>,
) {
    let layout = BindGroupLayoutDescriptor::new(
        "mesostructure_gradient_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::COMPUTE,
            (
                texture_2d(TextureSampleType::Float { filterable: false }),
                texture_storage_2d(MHGM_FORMAT, StorageTextureAccess::WriteOnly),
                uniform_buffer::<MesostructureUniform>(true),
            ),
        ),
    );
    let pipeline = pipeline_cache.queue_compute_pipeline(ComputePipelineDescriptor {
        label: Some("mesostructure_gradient_pipeline".into()),
        layout: vec![layout.clone()],
        shader: bevy::asset::load_embedded_asset!(asset_server.as_ref(), "gradient.wgsl"),
        entry_point: Some("gradient".into()),
        ..default()
    });
    commands.insert_resource(GradientPipeline { layout, pipeline });
}

/// Core3d system: dispatches the gradient pass for the current view, timed as `mesostructure/gradient`.
pub fn gradient_pass(
    view: ViewQuery<(
        &ExtractedView,
        &ViewMesostructureTextures,
        &ViewMesostructureBindGroups,
        &ViewMesostructureUniformOffset,
        &crate::render::view_settings::ExtractedMesostructure,
    )>,
    phases: Res<ViewSortedRenderPhases<HeightPhaseItem>>,
    pipeline: Res<GradientPipeline>,
    pipeline_cache: Res<PipelineCache>,
    mut ctx: RenderContext,
) {
    let (extracted_view, textures, bind_groups, offset, settings) = view.into_inner();
    if !settings.0.needs_gradient_map() || !view_has_mesostructure(&phases, extracted_view) {
        return;
    }
    let Some(compute) = pipeline_cache.get_compute_pipeline(pipeline.pipeline) else {
        return;
    };
    dispatch_per_pixel(
        &mut ctx,
        "mesostructure/gradient",
        compute,
        &bind_groups.gradient,
        &[offset.0],
        textures.size,
        |_| {},
    );
}
