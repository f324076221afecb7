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
        renderer::{RenderContext, RenderDevice, ViewQuery},
        texture::{CachedTexture, TextureCache},
        view::{ExtractedView, ViewUniform, ViewUniformOffset, ViewUniforms},
    },
};

use super::{
    MesostructureUniforms, STORAGE_IMAGE, ViewMesostructureUniformOffset, apex::ViewApexSets,
    dispatch_per_pixel,
    gradient::ViewGradientMap,
    height::{HeightPhaseItem, ViewHeightTextures},
    view_has_mesostructure, view_texture,
};
use crate::{
    reference::OcclusionForm,
    render::view_settings::{ExtractedMesostructure, MesostructureUniform},
};

/// Embeds the pass's shaders (their asset paths follow this folder).
pub(super) fn embed_shaders(app: &mut App) {
    bevy::asset::embedded_asset!(app, "occlusion.wgsl");
}

/// Mesostructure ambient occlusion (1 = open).
pub const OCCLUSION_FORMAT: TextureFormat = TextureFormat::R32Float;
/// Sector record per pixel: horizons about N', N' and the apexes that set the horizons
/// (`surface.wgsl`), for the lighting and bleeding passes.
pub const SECTOR_HORIZONS_FORMAT: TextureFormat = TextureFormat::Rgba32Uint;

/// The occlusion pass's images of one view.
#[derive(Component)]
pub struct ViewOcclusionTextures {
    /// Ambient occlusion.
    pub occlusion: CachedTexture,
    /// Sector records.
    pub sector_horizons: CachedTexture,
}

/// The occlusion pass's bind group of one view.
#[derive(Component)]
pub struct ViewOcclusionBindGroup(pub BindGroup);

/// Creates each view's occlusion and sector-record images (render `PrepareResources`).
pub fn prepare_occlusion_textures(
    mut commands: Commands,
    mut texture_cache: ResMut<TextureCache>,
    device: Res<RenderDevice>,
    views: Query<(Entity, &ViewHeightTextures)>,
) {
    for (entity, height) in &views {
        let mut texture = |label, format| {
            view_texture(&mut texture_cache, &device, label, format, STORAGE_IMAGE, height.size)
        };
        let textures = ViewOcclusionTextures {
            occlusion: texture("mesostructure_occlusion", OCCLUSION_FORMAT),
            sector_horizons: texture("mesostructure_sector_horizons", SECTOR_HORIZONS_FORMAT),
        };
        commands.entity(entity).insert(textures);
    }
}

/// Binds what each view's occlusion pass reads and writes (render `PrepareBindGroups`); views
/// without apex sets (too large for the GPU) get none, and the pass skips them.
pub fn prepare_occlusion_bind_group(
    mut commands: Commands,
    device: Res<RenderDevice>,
    pipeline_cache: Res<PipelineCache>,
    pipeline: Res<OcclusionPipeline>,
    uniforms: Res<MesostructureUniforms>,
    view_uniforms: Res<ViewUniforms>,
    views: Query<(
        Entity,
        &ViewHeightTextures,
        &ViewGradientMap,
        &ViewApexSets,
        &ViewOcclusionTextures,
        &bevy::core_pipeline::prepass::ViewPrepassTextures,
    )>,
) {
    let (Some(settings), Some(view_binding)) =
        (uniforms.0.binding(), view_uniforms.uniforms.binding())
    else {
        return;
    };
    for (entity, height, mhgm, apex, outputs, prepass) in &views {
        let Some(depth) = prepass.depth_view() else {
            commands.entity(entity).remove::<ViewOcclusionBindGroup>();
            continue;
        };
        let bind_group = device.create_bind_group(
            "mesostructure_occlusion_bind_group",
            &pipeline_cache.get_bind_group_layout(&pipeline.layout),
            &BindGroupEntries::sequential((
                &height.mhm.default_view,
                &height.core_normal.default_view,
                apex.sets.as_entire_binding(),
                &outputs.occlusion.default_view,
                settings.clone(),
                view_binding.clone(),
                &mhgm.0.default_view,
                depth,
                &height.bump_normal.default_view,
                &outputs.sector_horizons.default_view,
            )),
        );
        commands.entity(entity).insert(ViewOcclusionBindGroup(bind_group));
    }
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
                texture_2d(TextureSampleType::Uint),
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
        &ViewHeightTextures,
        &ViewOcclusionBindGroup,
        &ViewMesostructureUniformOffset,
        &ViewUniformOffset,
        &ViewOcclusionPipeline,
    )>,
    phases: Res<ViewSortedRenderPhases<HeightPhaseItem>>,
    pipeline_cache: Res<PipelineCache>,
    mut ctx: RenderContext,
) {
    let (extracted_view, settings, height, bind_group, offset, view_offset, pipeline) =
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
        &bind_group.0,
        &[offset.0, view_offset.offset],
        height.size,
        |_| {},
    );
}
