//! Bleeding pass (paper §3.3, eq. 8): one-bounce light from the directly lit mesostructure onto
//! its neighbours, gathered in a compute pass from the lit opaque image along each pixel's
//! paths to its apexes, then added to the view by a fullscreen draw with additive blending
//! (weighted by λd of eq. 2), between Bevy's opaque and transparent passes.

use bevy::{
    core_pipeline::{FullscreenShader, prepass::ViewPrepassTextures},
    prelude::*,
    render::{
        diagnostic::RecordDiagnostics,
        render_phase::ViewSortedRenderPhases,
        render_resource::{binding_types::*, *},
        renderer::{RenderContext, RenderDevice, ViewQuery},
        texture::{CachedTexture, TextureCache},
        view::{ExtractedView, ViewTarget, ViewUniform, ViewUniformOffset, ViewUniforms},
    },
};

use super::{
    MesostructureUniforms, STORAGE_IMAGE, ViewMesostructureUniformOffset, apex::ViewApexSets,
    dispatch_per_pixel,
    height::{HeightPhaseItem, ViewHeightTextures},
    occlusion::{ViewOcclusionBindGroup, ViewOcclusionPipeline, ViewOcclusionTextures},
    lighting::ViewMicroShadowTexture,
    view_has_mesostructure, view_texture,
};
use bevy::pbr::{LightMeta, ViewLightsUniformOffset};

/// One-bounce bleeding radiance added to the view (λd · ρ / π · E).
pub const BLEEDING_FORMAT: TextureFormat = TextureFormat::Rgba16Float;

/// The bleeding gather's output image of one view.
#[derive(Component)]
pub struct ViewBleedingTexture(pub CachedTexture);

/// Creates each view's bleeding image (render `PrepareResources`).
pub fn prepare_bleeding_texture(
    mut commands: Commands,
    mut texture_cache: ResMut<TextureCache>,
    device: Res<RenderDevice>,
    views: Query<(Entity, &ViewHeightTextures)>,
) {
    for (entity, height) in &views {
        let texture = view_texture(
            &mut texture_cache,
            &device,
            "mesostructure_bleeding",
            BLEEDING_FORMAT,
            STORAGE_IMAGE,
            height.size,
        );
        commands.entity(entity).insert(ViewBleedingTexture(texture));
    }
}

/// Whether the occlusion pass stored this frame's sector records, which the gather reads (its
/// pipeline compiled; its bind group exists where the view has apex sets).
fn sector_records_stored(
    pipeline_cache: &PipelineCache,
    occlusion: Option<(&ViewOcclusionPipeline, &ViewOcclusionBindGroup)>,
) -> bool {
    occlusion.is_some_and(|(p, _)| pipeline_cache.get_compute_pipeline(p.0).is_some())
}
use super::view_settings::{ExtractedMesostructure, MesostructureUniform};

/// Embeds the pass's shaders (their asset paths follow this folder).
pub(super) fn embed_shaders(app: &mut App) {
    bevy::asset::embedded_asset!(app, "bleeding.wgsl");
    bevy::asset::embedded_asset!(app, "bleeding_composite.wgsl");
}

/// Layouts and pipelines of the gather (compute) and the composite (fullscreen draw).
#[derive(Resource)]
pub struct BleedingPipeline {
    /// Lit image, MHM, core normals, bump normals, apex sets, G-buffer, bleeding (storage),
    /// settings, view, sector records, texture-space terms, light visibility, lights.
    pub gather_layout: BindGroupLayoutDescriptor,
    /// The gather pipeline, for views composited by the fullscreen draw.
    pub gather: CachedComputePipelineId,
    /// `gather_layout` and the view's next main image (storage).
    pub gather_to_view_layout: BindGroupLayoutDescriptor,
    /// The gather that also writes the view's next main image (`WRITE_VIEW_TARGET`).
    pub gather_to_view: CachedComputePipelineId,
    /// Bleeding, MHM.
    pub composite_layout: BindGroupLayoutDescriptor,
    fullscreen: FullscreenShader,
    composite_shader: Handle<Shader>,
}

/// Queues the gather pipeline and keeps what the composite pipelines need (render startup).
pub fn init_bleeding_pipeline(
    mut commands: Commands,
    pipeline_cache: Res<PipelineCache>,
    asset_server: Res<AssetServer>,
    fullscreen: Res<FullscreenShader>,
) {
    let float = || texture_2d(TextureSampleType::Float { filterable: false });
    let entries = (
        float(),
        float(),
        float(),
        float(),
        storage_buffer_read_only_sized(false, None),
        texture_2d(TextureSampleType::Uint),
        texture_storage_2d(BLEEDING_FORMAT, StorageTextureAccess::WriteOnly),
        uniform_buffer::<MesostructureUniform>(true),
        uniform_buffer::<ViewUniform>(true),
        texture_2d(TextureSampleType::Uint),
        float(),
        float(),
        uniform_buffer::<bevy::pbr::GpuLights>(true),
    );
    let gather_layout = BindGroupLayoutDescriptor::new(
        "mesostructure_bleeding_gather_layout",
        &BindGroupLayoutEntries::sequential(ShaderStages::COMPUTE, entries),
    );
    let gather_to_view_layout = BindGroupLayoutDescriptor::new(
        "mesostructure_bleeding_gather_to_view_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::COMPUTE,
            {
                let (a, b, c, d, e, f, g, h, i, j, k, l, m) = entries;
                let view_out =
                    texture_storage_2d(super::VIEW_TARGET_FORMAT, StorageTextureAccess::WriteOnly);
                (a, b, c, d, e, f, g, h, i, j, k, l, m, view_out)
            },
        ),
    );
    let shader = bevy::asset::load_embedded_asset!(asset_server.as_ref(), "bleeding.wgsl");
    let gather = pipeline_cache.queue_compute_pipeline(ComputePipelineDescriptor {
        label: Some("mesostructure_bleeding_gather_pipeline".into()),
        layout: vec![gather_layout.clone()],
        shader: shader.clone(),
        entry_point: Some("bleeding".into()),
        ..default()
    });
    let gather_to_view = pipeline_cache.queue_compute_pipeline(ComputePipelineDescriptor {
        label: Some("mesostructure_bleeding_gather_to_view_pipeline".into()),
        layout: vec![gather_to_view_layout.clone()],
        shader,
        shader_defs: vec!["WRITE_VIEW_TARGET".into()],
        entry_point: Some("bleeding".into()),
        ..default()
    });
    let composite_layout = BindGroupLayoutDescriptor::new(
        "mesostructure_bleeding_composite_layout",
        &BindGroupLayoutEntries::sequential(ShaderStages::FRAGMENT, (float(), float())),
    );
    commands.insert_resource(BleedingPipeline {
        gather_layout,
        gather,
        gather_to_view_layout,
        gather_to_view,
        composite_layout,
        fullscreen: fullscreen.clone(),
        composite_shader: bevy::asset::load_embedded_asset!(
            asset_server.as_ref(),
            "bleeding_composite.wgsl"
        ),
    });
}

impl SpecializedRenderPipeline for BleedingPipeline {
    type Key = TextureFormat;

    fn specialize(&self, format: TextureFormat) -> RenderPipelineDescriptor {
        // Added to the lit colour; alpha kept.
        super::additive_fullscreen_pipeline(
            "mesostructure_bleeding_composite_pipeline",
            self.composite_layout.clone(),
            &self.fullscreen,
            self.composite_shader.clone(),
            "composite",
            format,
        )
    }
}

/// The composite pipeline of a view, specialized for its main texture format.
#[derive(Component)]
pub struct ViewBleedingPipeline(pub CachedRenderPipelineId);

/// Specializes the composite pipeline for each view with bleeding on.
pub fn prepare_bleeding_pipelines(
    mut commands: Commands,
    pipeline_cache: Res<PipelineCache>,
    mut pipelines: ResMut<SpecializedRenderPipelines<BleedingPipeline>>,
    pipeline: Res<BleedingPipeline>,
    views: Query<(Entity, &ViewTarget, &ExtractedMesostructure)>,
) {
    for (entity, target, settings) in &views {
        if !settings.0.bleeding_runs() {
            commands.entity(entity).remove::<ViewBleedingPipeline>();
            continue;
        }
        let id = pipelines.specialize(&pipeline_cache, &pipeline, target.main_texture_format());
        commands.entity(entity).insert(ViewBleedingPipeline(id));
    }
}

/// Core3d system between Bevy's opaque and transparent passes: gathers the bleeding of the
/// current view, timed as `mesostructure/bleeding`.
pub fn bleeding_pass(
    view: ViewQuery<(
        &ExtractedView,
        &ViewTarget,
        &ViewPrepassTextures,
        (
            &ViewHeightTextures,
            &ViewApexSets,
            &ViewOcclusionTextures,
            &ViewBleedingTexture,
            &ViewMicroShadowTexture,
        ),
        &ViewMesostructureUniformOffset,
        (&ViewUniformOffset, &ViewLightsUniformOffset),
        &ViewBleedingPipeline,
        Option<(&ViewOcclusionPipeline, &ViewOcclusionBindGroup)>,
    )>,
    phases: Res<ViewSortedRenderPhases<HeightPhaseItem>>,
    pipeline: Res<BleedingPipeline>,
    pipeline_cache: Res<PipelineCache>,
    uniforms: Res<MesostructureUniforms>,
    view_uniforms: Res<ViewUniforms>,
    light_meta: Res<LightMeta>,
    #[cfg(feature = "oracle")] captures: super::capture::BleedingCaptures,
    mut ctx: RenderContext,
) {
    #[cfg(feature = "oracle")]
    let view_entity = view.entity();
    let (extracted_view, target, prepass, images, offset, offsets, composite, occlusion) =
        view.into_inner();
    let (view_offset, lights_offset) = offsets;
    let (height, apex, occlusion_outputs, bleeding, light_visibility) = images;
    if !view_has_mesostructure(&phases, extracted_view)
        || !sector_records_stored(&pipeline_cache, occlusion)
    {
        return;
    }
    let to_view = super::composites_in_compute(target);
    let gather_id = if to_view {
        pipeline.gather_to_view
    } else {
        pipeline.gather
    };
    let (
        Some(gather),
        Some(_),
        Some(settings),
        Some(view_binding),
        Some(gbuffer),
        Some(lights_binding),
    ) = (
        pipeline_cache.get_compute_pipeline(gather_id),
        pipeline_cache.get_render_pipeline(composite.0),
        uniforms.0.binding(),
        view_uniforms.uniforms.binding(),
        prepass.deferred_view(),
        light_meta.view_gpu_lights.binding(),
    ) else {
        return;
    };
    let device = ctx.render_device().clone();
    let entries = |lit| {
        (
            lit,
            &height.mhm.default_view,
            &height.core_normal.default_view,
            &height.bump_normal.default_view,
            apex.sets.as_entire_binding(),
            gbuffer,
            &bleeding.0.default_view,
            settings.clone(),
            view_binding.clone(),
            &occlusion_outputs.sector_horizons.default_view,
            &height.texture_visibility.default_view,
            &light_visibility.0.default_view,
            lights_binding.clone(),
        )
    };
    let gather_group = if to_view {
        // Bevy's post-process ping-pong: read the lit image, write lit + bleeding into the
        // other main image, which becomes the view's main image.
        let post = target.post_process_write();
        device.create_bind_group(
            "mesostructure_bleeding_gather_to_view_bind_group",
            &pipeline_cache.get_bind_group_layout(&pipeline.gather_to_view_layout),
            &BindGroupEntries::sequential({
                let (a, b, c, d, e, f, g, h, i, j, k, l, m) = entries(post.source);
                (a, b, c, d, e, f, g, h, i, j, k, l, m, post.destination)
            }),
        )
    } else {
        device.create_bind_group(
            "mesostructure_bleeding_gather_bind_group",
            &pipeline_cache.get_bind_group_layout(&pipeline.gather_layout),
            &BindGroupEntries::sequential(entries(target.main_texture_view())),
        )
    };
    dispatch_per_pixel(
        &mut ctx,
        "mesostructure/bleeding",
        gather,
        &gather_group,
        &[offset.0, view_offset.offset, lights_offset.offset],
        height.size,
        |_| {},
    );
    #[cfg(feature = "oracle")]
    super::capture::copy_bleeding(&mut ctx, &captures, view_entity, height.size, &bleeding.0);
}

/// Core3d system after the gather: adds the bleeding to the view's lit colour, timed as
/// `mesostructure/bleeding_composite`. (Its own system, so its own command encoder: lavapipe
/// crashes on debug groups around a compute and a render pass in one encoder.)
pub fn bleeding_composite_pass(
    view: ViewQuery<(
        &ExtractedView,
        &ViewTarget,
        &ViewHeightTextures,
        &ViewBleedingTexture,
        &ViewBleedingPipeline,
        Option<(&ViewOcclusionPipeline, &ViewOcclusionBindGroup)>,
    )>,
    phases: Res<ViewSortedRenderPhases<HeightPhaseItem>>,
    pipeline: Res<BleedingPipeline>,
    pipeline_cache: Res<PipelineCache>,
    mut ctx: RenderContext,
) {
    let (extracted_view, target, height, bleeding, composite, occlusion) = view.into_inner();
    // As the gather: nothing to add before the sector records exist; nothing left to add
    // where the gather wrote the view's image itself.
    if !view_has_mesostructure(&phases, extracted_view)
        || !sector_records_stored(&pipeline_cache, occlusion)
        || super::composites_in_compute(target)
    {
        return;
    }
    let (Some(composite), Some(_)) = (
        pipeline_cache.get_render_pipeline(composite.0),
        pipeline_cache.get_compute_pipeline(pipeline.gather),
    ) else {
        return;
    };
    let device = ctx.render_device().clone();
    let composite_group = device.create_bind_group(
        "mesostructure_bleeding_composite_bind_group",
        &pipeline_cache.get_bind_group_layout(&pipeline.composite_layout),
        &BindGroupEntries::sequential((
            &bleeding.0.default_view,
            &height.mhm.default_view,
        )),
    );
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    ctx.command_encoder()
        .push_debug_group("mesostructure/bleeding_composite");
    {
        let mut pass = ctx.begin_tracked_render_pass(RenderPassDescriptor {
            label: Some("mesostructure_bleeding_composite_pass"),
            color_attachments: &[Some(target.get_color_attachment())],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        // A pass span: inside the pass, so that pipeline statistics (fragment invocations)
        // are recorded where the backend has them.
        let span = diagnostics.pass_span(&mut pass, "mesostructure/bleeding_composite");
        pass.set_render_pipeline(composite);
        pass.set_bind_group(0, &composite_group, &[]);
        pass.draw(0..3, 0..1);
        span.end(&mut pass);
    }
    ctx.command_encoder().pop_debug_group();
}
