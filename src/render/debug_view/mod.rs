//! Debug views: the MHM, MHGM, apex sets and the lighting terms drawn into the camera's output.

use bevy::{
    core_pipeline::FullscreenShader,
    prelude::*,
    render::{
        diagnostic::RecordDiagnostics,
        render_resource::{binding_types::*, *},
        renderer::{RenderContext, RenderDevice, ViewQuery},
        view::ViewTarget,
    },
};

use super::{
    MesostructureUniforms, ViewMesostructureUniformOffset, apex::ViewApexSets,
    bleeding::ViewBleedingTexture, gradient::ViewGradientMap, height::ViewHeightTextures,
    lighting::ViewMicroShadowTexture, occlusion::ViewOcclusionTextures,
};
use super::view_settings::{ExtractedMesostructure, MesostructureUniform};
use crate::settings::MesostructureDebugView;

/// Embeds the pass's shaders (their asset paths follow this folder).
pub(super) fn embed_shaders(app: &mut App) {
    bevy::asset::embedded_asset!(app, "debug_view.wgsl");
}

/// Layout, shaders and per-format pipelines of the debug views.
#[derive(Resource)]
pub struct DebugViewPipeline {
    /// MHM, MHGM, apex buffer (read), settings, occlusion, micro-shadow, bleeding.
    pub layout: BindGroupLayoutDescriptor,
    fullscreen: FullscreenShader,
    shader: Handle<Shader>,
}

/// The debug view's bind group of one view.
#[derive(Component)]
pub struct ViewDebugViewBindGroup(pub BindGroup);

/// Binds the images each view's debug view draws from (render `PrepareBindGroups`).
pub fn prepare_debug_view_bind_group(
    mut commands: Commands,
    device: Res<RenderDevice>,
    pipeline_cache: Res<PipelineCache>,
    pipeline: Res<DebugViewPipeline>,
    uniforms: Res<MesostructureUniforms>,
    views: Query<
        (
            Entity,
            &ViewHeightTextures,
            &ViewGradientMap,
            &ViewApexSets,
            &ViewOcclusionTextures,
            &ViewMicroShadowTexture,
            &ViewBleedingTexture,
        ),
        With<ViewDebugViewPipeline>,
    >,
) {
    let Some(settings) = uniforms.0.binding() else {
        return;
    };
    for (entity, height, mhgm, apex, occlusion, micro_shadow, bleeding) in &views {
        let bind_group = device.create_bind_group(
            "mesostructure_debug_view_bind_group",
            &pipeline_cache.get_bind_group_layout(&pipeline.layout),
            &BindGroupEntries::sequential((
                &height.mhm.default_view,
                &mhgm.0.default_view,
                apex.sets.as_entire_binding(),
                settings.clone(),
                &occlusion.occlusion.default_view,
                &micro_shadow.0.default_view,
                &bleeding.0.default_view,
            )),
        );
        commands.entity(entity).insert(ViewDebugViewBindGroup(bind_group));
    }
}

/// Creates the debug-view layout (render startup).
pub fn init_debug_view_pipeline(
    mut commands: Commands,
    fullscreen: Res<FullscreenShader>,
    asset_server: Res<AssetServer>,
) {
    let layout = BindGroupLayoutDescriptor::new(
        "mesostructure_debug_view_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::FRAGMENT,
            (
                texture_2d(TextureSampleType::Float { filterable: false }),
                texture_2d(TextureSampleType::Uint),
                storage_buffer_read_only_sized(false, None),
                uniform_buffer::<MesostructureUniform>(true),
                texture_2d(TextureSampleType::Float { filterable: false }),
                texture_2d(TextureSampleType::Float { filterable: false }),
                texture_2d(TextureSampleType::Float { filterable: false }),
            ),
        ),
    );
    commands.insert_resource(DebugViewPipeline {
        layout,
        fullscreen: fullscreen.clone(),
        shader: bevy::asset::load_embedded_asset!(asset_server.as_ref(), "debug_view.wgsl"),
    });
}

impl SpecializedRenderPipeline for DebugViewPipeline {
    type Key = TextureFormat;

    fn specialize(&self, format: TextureFormat) -> RenderPipelineDescriptor {
        RenderPipelineDescriptor {
            label: Some("mesostructure_debug_view_pipeline".into()),
            layout: vec![self.layout.clone()],
            vertex: self.fullscreen.to_vertex_state(),
            fragment: Some(FragmentState {
                shader: self.shader.clone(),
                entry_point: Some("fragment".into()),
                targets: vec![Some(ColorTargetState {
                    format,
                    blend: None,
                    write_mask: ColorWrites::ALL,
                })],
                ..default()
            }),
            ..default()
        }
    }
}

/// The debug-view pipeline of a view, specialized for its output format.
#[derive(Component)]
pub struct ViewDebugViewPipeline(pub CachedRenderPipelineId);

/// Specializes the debug-view pipeline for each view that shows one.
pub fn prepare_debug_view_pipelines(
    mut commands: Commands,
    pipeline_cache: Res<PipelineCache>,
    mut pipelines: ResMut<SpecializedRenderPipelines<DebugViewPipeline>>,
    pipeline: Res<DebugViewPipeline>,
    views: Query<(Entity, &ViewTarget, &ExtractedMesostructure)>,
) {
    for (entity, target, settings) in &views {
        if settings.0.debug_view == MesostructureDebugView::None {
            commands.entity(entity).remove::<ViewDebugViewPipeline>();
            continue;
        }
        let id = pipelines.specialize(&pipeline_cache, &pipeline, target.main_texture_format());
        commands.entity(entity).insert(ViewDebugViewPipeline(id));
    }
}

/// Core3d system: draws the chosen debug view over the output, after tonemapping.
pub fn debug_view_pass(
    view: ViewQuery<(
        &ViewTarget,
        &ViewDebugViewPipeline,
        &ViewDebugViewBindGroup,
        &ViewMesostructureUniformOffset,
        &bevy::render::camera::ExtractedCamera,
        &bevy::render::view::ExtractedView,
    )>,
    phases: Res<bevy::render::render_phase::ViewSortedRenderPhases<super::height::HeightPhaseItem>>,
    pipeline_cache: Res<PipelineCache>,
    mut ctx: RenderContext,
) {
    let (target, pipeline_id, bind_group, offset, camera, extracted_view) = view.into_inner();
    if !super::view_has_mesostructure(&phases, extracted_view) {
        return;
    }
    let Some(pipeline) = pipeline_cache.get_render_pipeline(pipeline_id.0) else {
        return;
    };
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    ctx.command_encoder()
        .push_debug_group("mesostructure/debug_view");
    {
        let mut pass = ctx.begin_tracked_render_pass(RenderPassDescriptor {
            label: Some("mesostructure_debug_view_pass"),
            color_attachments: &[Some(target.get_color_attachment())],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        // A pass span: inside the pass, so that pipeline statistics (fragment invocations)
        // are recorded where the backend has them.
        let span = diagnostics.pass_span(&mut pass, "mesostructure/debug_view");
        if let Some(viewport) = camera.viewport.as_ref() {
            pass.set_camera_viewport(viewport);
        }
        pass.set_render_pipeline(pipeline);
        pass.set_bind_group(0, &bind_group.0, &[offset.0]);
        pass.draw(0..3, 0..1);
        span.end(&mut pass);
    }
    ctx.command_encoder().pop_debug_group();
}
