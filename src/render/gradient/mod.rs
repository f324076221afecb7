//! Gradient pass (compute): MHM → MHGM with boundary flags (paper §2.1).

use bevy::{
    prelude::*,
    render::{
        render_phase::ViewSortedRenderPhases,
        render_resource::{binding_types::*, *},
        renderer::{RenderContext, RenderDevice, ViewQuery},
        texture::{CachedTexture, TextureCache},
        view::ExtractedView,
    },
};

use super::{
    MesostructureUniforms, STORAGE_IMAGE, ViewMesostructureUniformOffset, dispatch_per_pixel,
    height::{HeightPhaseItem, ViewHeightTextures},
    view_has_mesostructure, view_texture,
};
use crate::render::view_settings::MesostructureUniform;

/// MHGM: (height as f32 bits, flags | the gradient's direction as a neighbour index << 16) —
/// what the apex search reads of a pixel, in 8 bytes (`common.wgsl`, `reference::gradient`).
pub const MHGM_FORMAT: TextureFormat = TextureFormat::Rg32Uint;

/// The gradient map of one view.
#[derive(Component)]
pub struct ViewGradientMap(pub CachedTexture);

/// The gradient pass's bind group of one view.
#[derive(Component)]
pub struct ViewGradientBindGroup(pub BindGroup);

/// Creates each view's gradient map (render `PrepareResources`).
pub fn prepare_gradient_map(
    mut commands: Commands,
    mut texture_cache: ResMut<TextureCache>,
    device: Res<RenderDevice>,
    views: Query<(Entity, &ViewHeightTextures)>,
) {
    for (entity, height) in &views {
        let mhgm = view_texture(
            &mut texture_cache,
            &device,
            "mesostructure_mhgm",
            MHGM_FORMAT,
            STORAGE_IMAGE,
            height.size,
        );
        commands.entity(entity).insert(ViewGradientMap(mhgm));
    }
}

/// Binds each view's MHM and gradient map (render `PrepareBindGroups`).
pub fn prepare_gradient_bind_group(
    mut commands: Commands,
    device: Res<RenderDevice>,
    pipeline_cache: Res<PipelineCache>,
    pipeline: Res<GradientPipeline>,
    uniforms: Res<MesostructureUniforms>,
    views: Query<(Entity, &ViewHeightTextures, &ViewGradientMap)>,
) {
    let Some(settings) = uniforms.0.binding() else {
        return;
    };
    for (entity, height, mhgm) in &views {
        let bind_group = device.create_bind_group(
            "mesostructure_gradient_bind_group",
            &pipeline_cache.get_bind_group_layout(&pipeline.layout),
            &BindGroupEntries::sequential((
                &height.mhm.default_view,
                &mhgm.0.default_view,
                settings.clone(),
            )),
        );
        commands.entity(entity).insert(ViewGradientBindGroup(bind_group));
    }
}

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
        &ViewHeightTextures,
        &ViewGradientBindGroup,
        &ViewMesostructureUniformOffset,
        &crate::render::view_settings::ExtractedMesostructure,
    )>,
    phases: Res<ViewSortedRenderPhases<HeightPhaseItem>>,
    pipeline: Res<GradientPipeline>,
    pipeline_cache: Res<PipelineCache>,
    mut ctx: RenderContext,
) {
    let (extracted_view, height, bind_group, offset, settings) = view.into_inner();
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
        &bind_group.0,
        &[offset.0],
        height.size,
        |_| {},
    );
}
