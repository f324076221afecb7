//! Occlusion pass (compute): apex sets → mesostructure ambient occlusion (paper §3.1), times a
//! coarse horizon-based AO of the depth buffer with the apex sets' adaptive step; and each
//! pixel's sector record (its horizons about N', N' and the apex setting each horizon,
//! `surface.wgsl`), which the lighting and bleeding passes read instead of rebuilding it.

use bevy::{
    prelude::*,
    shader::ShaderDefVal,
    render::{
        render_phase::ViewSortedRenderPhases,
        render_resource::{binding_types::*, *},
        renderer::{RenderContext, ViewQuery},
        view::{ExtractedView, ViewUniform, ViewUniformOffset},
    },
};

use super::{
    OCCLUSION_FORMAT, SECTOR_HORIZONS_FORMAT, ViewMesostructureBindGroups, ViewMesostructureTextures,
    ViewMesostructureUniformOffset, dispatch_per_pixel, height::HeightPhaseItem,
    view_has_mesostructure,
};
use crate::{
    reference::OcclusionForm,
    render::view_settings::{ExtractedMesostructure, MesostructureUniform},
};

/// Embeds the pass's shaders (their asset paths follow this folder).
pub(super) fn embed_shaders(app: &mut App) {
    bevy::asset::embedded_asset!(app, "occlusion.wgsl");
}

/// Layout and shader of the occlusion pass; its pipelines are specialised per
/// [`OcclusionPipelineKey`], as Bevy keys its SSAO pipeline.
#[derive(Resource)]
pub struct OcclusionPipeline {
    /// MHM, core normals, apex sets, occlusion (storage), settings, view, MHGM, prepass depth,
    /// bump normals (whose `w` carries the height pass's texture-space occlusion), sector
    /// records (storage).
    pub layout: BindGroupLayoutDescriptor,
    shader: Handle<Shader>,
}

/// What the occlusion shader is compiled for (shader defs instead of per-pixel branches on
/// uniforms).
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct OcclusionPipelineKey {
    /// The ambient occlusion is wanted (`AMBIENT_OCCLUSION`).
    pub ambient_occlusion: bool,
    /// The sector records are stored for the lighting and bleeding passes (`SECTOR_HORIZONS`).
    pub sector_horizons: bool,
    /// The integral (`OCCLUSION_FORM_PAPER` for eq. (6)).
    pub form: OcclusionForm,
    /// The coarse depth-buffer term multiplies (`COARSE_OCCLUSION`).
    pub coarse: bool,
    /// The height pass's texture-space occlusion replaces the apex horizons where it has one
    /// (`TEXTURE_SPACE_HORIZONS`).
    pub texture_space_horizons: bool,
    /// The brute-force horizon-search baseline instead of the apex sets (`HORIZON_SEARCH`).
    pub horizon_search: bool,
}

impl OcclusionPipelineKey {
    /// The key of a view's settings.
    pub fn of(settings: &crate::render::view_settings::ViewSettings) -> Self {
        Self {
            ambient_occlusion: settings.occlusion,
            sector_horizons: settings.needs_sector_horizons(),
            form: settings.occlusion_form,
            coarse: settings.coarse_occlusion,
            // The baseline stays the baseline: it never takes the texture-space occlusion.
            texture_space_horizons: settings.texture_space_horizons
                && settings.horizon_search_steps == 0,
            horizon_search: settings.horizon_search_steps > 0,
        }
    }
}

impl SpecializedComputePipeline for OcclusionPipeline {
    type Key = OcclusionPipelineKey;

    fn specialize(&self, key: OcclusionPipelineKey) -> ComputePipelineDescriptor {
        let mut shader_defs: Vec<ShaderDefVal> = vec![];
        for (on, def) in [
            (key.ambient_occlusion, "AMBIENT_OCCLUSION"),
            (key.sector_horizons, "SECTOR_HORIZONS"),
            (key.form == OcclusionForm::Paper, "OCCLUSION_FORM_PAPER"),
            (key.coarse, "COARSE_OCCLUSION"),
            (key.texture_space_horizons, "TEXTURE_SPACE_HORIZONS"),
            (key.horizon_search, "HORIZON_SEARCH"),
        ] {
            if on {
                shader_defs.push(def.into());
            }
        }
        ComputePipelineDescriptor {
            label: Some("mesostructure_occlusion_pipeline".into()),
            layout: vec![self.layout.clone()],
            shader: self.shader.clone(),
            shader_defs,
            entry_point: Some("occlusion".into()),
            ..default()
        }
    }
}

/// The occlusion pipeline of a view.
#[derive(Component)]
pub struct ViewOcclusionPipeline(pub CachedComputePipelineId);

/// Queues the occlusion pipeline (render startup).
pub fn init_occlusion_pipeline(mut commands: Commands, asset_server: Res<AssetServer>) {
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
                texture_storage_2d(SECTOR_HORIZONS_FORMAT, StorageTextureAccess::WriteOnly),
            ),
        ),
    );
    commands.insert_resource(OcclusionPipeline {
        layout,
        shader: bevy::asset::load_embedded_asset!(asset_server.as_ref(), "occlusion.wgsl"),
    });
}

/// Specialises each view's occlusion pipeline for its settings (render `Prepare`).
pub fn prepare_occlusion_pipelines(
    mut commands: Commands,
    pipeline_cache: Res<PipelineCache>,
    mut pipelines: ResMut<SpecializedComputePipelines<OcclusionPipeline>>,
    pipeline: Res<OcclusionPipeline>,
    views: Query<(Entity, &ExtractedMesostructure)>,
) {
    for (entity, settings) in &views {
        let id = pipelines.specialize(&pipeline_cache, &pipeline, OcclusionPipelineKey::of(&settings.0));
        commands.entity(entity).insert(ViewOcclusionPipeline(id));
    }
}

/// Core3d system: computes the occlusion and the sector records of the current view, timed as
/// `mesostructure/occlusion`; skipped when neither is wanted.
pub fn occlusion_pass(
    view: ViewQuery<(
        &ExtractedView,
        &ExtractedMesostructure,
        &ViewMesostructureTextures,
        &ViewMesostructureBindGroups,
        &ViewMesostructureUniformOffset,
        &ViewUniformOffset,
        &ViewOcclusionPipeline,
    )>,
    phases: Res<ViewSortedRenderPhases<HeightPhaseItem>>,
    pipeline_cache: Res<PipelineCache>,
    mut ctx: RenderContext,
) {
    let (extracted_view, settings, textures, bind_groups, offset, view_offset, pipeline) =
        view.into_inner();
    if !settings.0.occlusion_pass_runs() || !view_has_mesostructure(&phases, extracted_view) {
        return;
    }
    let Some(compute) = pipeline_cache.get_compute_pipeline(pipeline.0) else {
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
