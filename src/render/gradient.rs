//! Gradient pass (compute): MHM → MHGM with boundary flags (paper §2.1).

use bevy::{
    prelude::*,
    render::{
        diagnostic::RecordDiagnostics,
        render_resource::{binding_types::*, *},
        renderer::{RenderContext, ViewQuery},
    },
};

use super::{ViewMesostructureBindGroups, ViewMesostructureTextures, ViewMesostructureUniformOffset, MHGM_FORMAT};
use crate::settings::MesostructureUniform;

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
        &ViewMesostructureTextures,
        &ViewMesostructureBindGroups,
        &ViewMesostructureUniformOffset,
    )>,
    pipeline: Res<GradientPipeline>,
    pipeline_cache: Res<PipelineCache>,
    mut ctx: RenderContext,
) {
    let (textures, bind_groups, offset) = view.into_inner();
    let Some(compute) = pipeline_cache.get_compute_pipeline(pipeline.pipeline) else {
        return;
    };
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    let span = diagnostics.time_span(ctx.command_encoder(), "mesostructure/gradient");
    let encoder = ctx.command_encoder();
    encoder.push_debug_group("mesostructure/gradient");
    {
        let mut pass = encoder.begin_compute_pass(&ComputePassDescriptor {
            label: Some("mesostructure_gradient_pass"),
            timestamp_writes: None,
        });
        pass.set_pipeline(compute);
        pass.set_bind_group(0, &bind_groups.gradient, &[offset.0]);
        pass.dispatch_workgroups(textures.size.x.div_ceil(8), textures.size.y.div_ceil(8), 1);
    }
    encoder.pop_debug_group();
    span.end(ctx.command_encoder());
}
