//! Apex pass (compute): MHGM → local apex set f(P) per pixel (paper §2.2).

use bevy::{
    prelude::*,
    render::{
        diagnostic::RecordDiagnostics,
        render_resource::{binding_types::*, *},
        renderer::{RenderContext, ViewQuery},
    },
};

use super::{ViewMesostructureBindGroups, ViewMesostructureTextures, ViewMesostructureUniformOffset};
use crate::settings::MesostructureUniform;

/// Pipeline and layout of the apex pass.
#[derive(Resource)]
pub struct ApexPipeline {
    /// MHM, MHGM, apex buffer, statistics, settings.
    pub layout: BindGroupLayoutDescriptor,
    /// The compute pipeline.
    pub pipeline: CachedComputePipelineId,
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
    let pipeline = pipeline_cache.queue_compute_pipeline(ComputePipelineDescriptor {
        label: Some("mesostructure_apex_pipeline".into()),
        layout: vec![layout.clone()],
        shader: bevy::asset::load_embedded_asset!(asset_server.as_ref(), "apex.wgsl"),
        entry_point: Some("apex".into()),
        ..default()
    });
    commands.insert_resource(ApexPipeline { layout, pipeline });
}

/// Core3d system: dispatches the apex search for the current view, timed as `mesostructure/apex`.
pub fn apex_pass(
    view: ViewQuery<(
        &ViewMesostructureTextures,
        &ViewMesostructureBindGroups,
        &ViewMesostructureUniformOffset,
    )>,
    pipeline: Res<ApexPipeline>,
    pipeline_cache: Res<PipelineCache>,
    mut ctx: RenderContext,
) {
    let (textures, bind_groups, offset) = view.into_inner();
    let Some(compute) = pipeline_cache.get_compute_pipeline(pipeline.pipeline) else {
        return;
    };
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    let span = diagnostics.time_span(ctx.command_encoder(), "mesostructure/apex");
    let encoder = ctx.command_encoder();
    encoder.push_debug_group("mesostructure/apex");
    encoder.clear_buffer(&textures.apex_stats, 0, None);
    {
        let mut pass = encoder.begin_compute_pass(&ComputePassDescriptor {
            label: Some("mesostructure_apex_pass"),
            timestamp_writes: None,
        });
        pass.set_pipeline(compute);
        pass.set_bind_group(0, &bind_groups.apex, &[offset.0]);
        pass.dispatch_workgroups(textures.size.x.div_ceil(8), textures.size.y.div_ceil(8), 1);
    }
    encoder.pop_debug_group();
    span.end(ctx.command_encoder());
}
