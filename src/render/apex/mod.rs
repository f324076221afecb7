//! Apex pass (compute): MHGM → local apex set f(P) per pixel (paper §2.2).

use bevy::{
    prelude::*,
    shader::ShaderDefVal,
    render::{
        render_phase::ViewSortedRenderPhases,
        render_resource::{binding_types::*, *},
        renderer::{RenderContext, RenderDevice, ViewQuery},
        view::ExtractedView,
    },
};

use super::{
    MesostructureUniforms, ViewMesostructureUniformOffset, dispatch_per_pixel,
    gradient::ViewGradientMap,
    height::{HeightPhaseItem, ViewHeightTextures},
    view_has_mesostructure,
};
use crate::{
    render::view_settings::{ExtractedMesostructure, MesostructureUniform},
    warn_once::WarnedOnce,
};

/// The apex sets of one view: `stride` words per `block`² block of pixels (see
/// `reference::packed`), and the search's counters.
#[derive(Component)]
pub struct ViewApexSets {
    /// The sets.
    pub sets: Buffer,
    /// Counters: mesostructure pixels, pixels that hit the step bound, ascent steps.
    pub stats: Buffer,
    /// Words per apex set.
    pub stride: u32,
    /// Side of the pixel block that shares one apex set (the working resolution).
    pub block: u32,
}

/// The apex pass's bind group of one view.
#[derive(Component)]
pub struct ViewApexBindGroup(pub BindGroup);

/// Sizes each view's apex buffer for its settings (render `PrepareResources`). A view whose
/// buffer would exceed what the GPU binds gets none, with a one-time warning: the passes that
/// need the apex sets skip it and its surfaces are lit without the mesostructure terms.
pub fn prepare_apex_sets(
    mut commands: Commands,
    device: Res<RenderDevice>,
    views: Query<(
        Entity,
        &ViewHeightTextures,
        &ExtractedMesostructure,
        Option<&ViewApexSets>,
    )>,
    mut warned: ResMut<WarnedOnce>,
) {
    for (entity, height, settings, previous) in &views {
        let size = height.size;
        let stride = crate::reference::packed::stride(settings.0.apex_directions);
        let block = settings.0.working_resolution.block();
        let blocks = (size + block - 1) / block;
        let bytes = blocks.x as u64 * blocks.y as u64 * stride as u64 * 4;
        if bytes > device.limits().max_storage_buffer_binding_size {
            warned.warn(format!("apex buffer {entity} {size}"), || {
                format!(
                    "camera {entity}: {size} with {} apex directions needs a {bytes}-byte apex \
                     buffer, more than this GPU binds; the mesostructure terms are off (use \
                     fewer directions or a lower working resolution)",
                    settings.0.apex_directions
                )
            });
            commands.entity(entity).remove::<ViewApexSets>();
            continue;
        }
        let (sets, stats) = match previous {
            Some(p) if p.sets.size() == bytes => (p.sets.clone(), p.stats.clone()),
            _ => (
                device.create_buffer(&BufferDescriptor {
                    label: Some("mesostructure_apex_sets"),
                    size: bytes,
                    usage: BufferUsages::STORAGE | BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                }),
                device.create_buffer(&BufferDescriptor {
                    label: Some("mesostructure_apex_stats"),
                    size: 16,
                    usage: BufferUsages::STORAGE | BufferUsages::COPY_SRC | BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                }),
            ),
        };
        commands.entity(entity).insert(ViewApexSets {
            sets,
            stats,
            stride,
            block,
        });
    }
}

/// Binds each view's MHM, gradient map and apex buffers (render `PrepareBindGroups`).
pub fn prepare_apex_bind_group(
    mut commands: Commands,
    device: Res<RenderDevice>,
    pipeline_cache: Res<PipelineCache>,
    pipeline: Res<ApexPipeline>,
    uniforms: Res<MesostructureUniforms>,
    views: Query<(Entity, &ViewHeightTextures, &ViewGradientMap, &ViewApexSets)>,
) {
    let Some(settings) = uniforms.0.binding() else {
        return;
    };
    for (entity, height, mhgm, apex) in &views {
        let bind_group = device.create_bind_group(
            "mesostructure_apex_bind_group",
            &pipeline_cache.get_bind_group_layout(&pipeline.layout),
            &BindGroupEntries::sequential((
                &height.mhm.default_view,
                &mhgm.0.default_view,
                apex.sets.as_entire_binding(),
                apex.stats.as_entire_binding(),
                settings.clone(),
            )),
        );
        commands.entity(entity).insert(ViewApexBindGroup(bind_group));
    }
}

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
                texture_2d(TextureSampleType::Uint),
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
        &ViewHeightTextures,
        &ViewApexSets,
        &ViewApexBindGroup,
        &ViewMesostructureUniformOffset,
        &ExtractedMesostructure,
    )>,
    #[cfg(feature = "oracle")] captured_views: Query<(), With<super::capture::ExtractedCapture>>,
    phases: Res<ViewSortedRenderPhases<HeightPhaseItem>>,
    pipeline: Res<ApexPipeline>,
    pipeline_cache: Res<PipelineCache>,
    mut ctx: RenderContext,
) {
    #[cfg(feature = "oracle")]
    let captured = captured_views.contains(view.entity());
    #[cfg(not(feature = "oracle"))]
    let captured = false;
    let (extracted_view, height, apex, bind_group, offset, settings) = view.into_inner();
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
        &bind_group.0,
        &[offset.0],
        // One invocation per block of pixels that shares an apex set.
        (height.size + apex.block - 1) / apex.block,
        |encoder| encoder.clear_buffer(&apex.stats, 0, None),
    );
}
