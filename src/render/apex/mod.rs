//! Apex pass (compute): MHGM → local apex set f(P) per pixel (paper §2.2).

use bevy::{
    prelude::*,
    shader::ShaderDefVal,
    render::{
        render_phase::ViewSortedRenderPhases,
        render_resource::{binding_types::*, *},
        renderer::{RenderContext, ViewQuery},
        view::ExtractedView,
    },
};

use super::{
    ViewMesostructureBindGroups, ViewMesostructureTextures, ViewMesostructureUniformOffset,
    dispatch_per_pixel, height::HeightPhaseItem, view_has_mesostructure,
};
use crate::render::view_settings::MesostructureUniform;

/// Embeds the pass's shaders (their asset paths follow this folder).
pub(super) fn embed_shaders(app: &mut App) {
    bevy::asset::embedded_asset!(app, "apex.wgsl");
}

/// Pipeline and layout of the apex pass.
#[derive(Resource)]
pub struct ApexPipeline {
    /// MHM, MHGM, apex buffer, statistics, settings.
    pub layout: BindGroupLayoutDescriptor,
    /// The compute pipeline.
    pub pipeline: CachedComputePipelineId,
    /// The same with the search statistics counted (shader def `STATISTICS`), for views whose
    /// frames are captured ([`super::capture::CapturedFrame::apex_stats`]).
    pub pipeline_with_statistics: CachedComputePipelineId,
}

/// Queues the apex pipeline (render startup).
pub fn init_apex_pipeline(
    mut commands: Commands,
    pipeline_cache: Res<PipelineCache>,
    asset_server: Res<AssetServer>,
) {
    let layout = BindGroupLayoutDescriptor::new(
        "mesostructure_apex_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::COMPUTE,
            (
                texture_2d(TextureSampleType::Float { filterable: false }),
                texture_2d(TextureSampleType::Float { filterable: false }),
                storage_buffer_sized(false, None),
                storage_buffer_sized(false, None),
                uniform_buffer::<MesostructureUniform>(true),
            ),
        ),
    );
    let shader = bevy::asset::load_embedded_asset!(asset_server.as_ref(), "apex.wgsl");
    let descriptor = |label: &'static str, shader_defs: Vec<ShaderDefVal>| ComputePipelineDescriptor {
        label: Some(label.into()),
        layout: vec![layout.clone()],
        shader: shader.clone(),
        shader_defs,
        entry_point: Some("apex".into()),
        ..default()
    };
    let pipeline = pipeline_cache.queue_compute_pipeline(descriptor("mesostructure_apex_pipeline", vec![]));
    let pipeline_with_statistics = pipeline_cache.queue_compute_pipeline(descriptor(
        "mesostructure_apex_statistics_pipeline",
        vec!["STATISTICS".into()],
    ));
    commands.insert_resource(ApexPipeline {
        layout,
        pipeline,
        pipeline_with_statistics,
    });
}

/// Core3d system: dispatches the apex pass for the current view, timed as `mesostructure/apex`.
pub fn apex_pass(
    view: ViewQuery<(
        &ExtractedView,
        &ViewMesostructureTextures,
        &ViewMesostructureBindGroups,
        &ViewMesostructureUniformOffset,
        &crate::render::view_settings::ExtractedMesostructure,
        Has<super::capture::ExtractedCapture>,
    )>,
    phases: Res<ViewSortedRenderPhases<HeightPhaseItem>>,
    pipeline: Res<ApexPipeline>,
    pipeline_cache: Res<PipelineCache>,
    mut ctx: RenderContext,
) {
    let (extracted_view, textures, bind_groups, offset, settings, captured) = view.into_inner();
    if !settings.0.needs_apex_sets() || !view_has_mesostructure(&phases, extracted_view) {
        return;
    }
    // Captured views count the search statistics (until that variant has compiled, the plain
    // one runs and they read zero).
    let counted = captured
        .then(|| pipeline_cache.get_compute_pipeline(pipeline.pipeline_with_statistics))
        .flatten();
    let Some(compute) = counted.or_else(|| pipeline_cache.get_compute_pipeline(pipeline.pipeline))
    else {
        return;
    };
    dispatch_per_pixel(
        &mut ctx,
        "mesostructure/apex",
        compute,
        &bind_groups.apex,
        &[offset.0],
        // One invocation per block of pixels that shares an apex set.
        (textures.size + textures.apex_block - 1) / textures.apex_block,
        |encoder| encoder.clear_buffer(&textures.apex_stats, 0, None),
    );
}
