//! The height pass's compute half: one dispatch per parameter set (height map, horizon map, k,
//! bump flag) over the view samples the height maps at the raster half's UVs into the MHM, the
//! Blinn bump normals and the texture-space terms (`height.wgsl`).

use bevy::{
    core_pipeline::prepass::ViewPrepassTextures,
    pbr::{GpuLights, LightMeta, ViewLightsUniformOffset},
    prelude::*,
    render::{
        diagnostic::RecordDiagnostics,
        render_phase::ViewSortedRenderPhases,
        render_resource::{binding_types::*, *},
        renderer::{RenderContext, RenderDevice, RenderQueue, ViewQuery},
        texture::GpuImage,
        view::{ExtractedView, ViewUniform, ViewUniformOffset, ViewUniforms},
    },
};

use super::{
    BUMP_NORMAL_FORMAT, HeightMaterialBindGroups, HeightPhaseItem, MHM_FORMAT,
    TEXTURE_VISIBILITY_FORMAT, ViewHeightTextures,
};
use crate::render::view_settings::ExtractedMesostructure;

/// What the compute half samples for one group of meshes (`HeightParameters` in
/// `height.wgsl`): meshes sharing a height map, horizon map, `k` and bump flag share a set and
/// one dispatch.
#[derive(Clone, Copy, ShaderType)]
pub struct HeightParametersUniform {
    /// `k`, world units.
    pub scale: f32,
    /// 1: write the Blinn bump normal; 0: the material has a normal map of its own.
    pub bump: f32,
    /// The set's index, as the raster half writes it into the core normal's `w`.
    pub index: f32,
    /// Padding.
    pub spare: f32,
}

/// One parameter set of the compute half: its bind group (height mips, horizon map, distances,
/// parameters).
pub struct HeightParameterSet {
    bind_group: BindGroup,
}

impl HeightParameterSet {
    /// The set's bind group over `images` (height mips, horizon map, horizon distances) and its
    /// parameters, written to a buffer of its own.
    pub fn new(
        device: &RenderDevice,
        queue: &RenderQueue,
        layout: &BindGroupLayout,
        images: [&GpuImage; 3],
        parameters: HeightParametersUniform,
    ) -> Self {
        let mut parameters = UniformBuffer::from(parameters);
        parameters.write_buffer(device, queue);
        let [mips, horizons, distances] = images;
        let bind_group = device.create_bind_group(
            "mesostructure_height_parameter_bind_group",
            layout,
            &BindGroupEntries::sequential((
                &mips.texture_view,
                &horizons.texture_view,
                &distances.texture_view,
                parameters.binding().expect("written above"),
            )),
        );
        Self { bind_group }
    }
}

/// The height pass's compute pipelines and layouts.
#[derive(Resource)]
pub struct HeightComputePipeline {
    /// Without the texture-space horizons.
    pub screen_space_only: CachedComputePipelineId,
    /// With them (`Mesostructure::texture_space_horizons`).
    pub texture_space_horizons: CachedComputePipelineId,
    /// With them and the first directional light's texture-space bounce (where the bleeding
    /// runs).
    pub texture_space_bounce: CachedComputePipelineId,
    /// Group 0: surface, core normal, MHM, bump normal and visibility out, view, lights,
    /// prepass depth, deferred lighting pass ids.
    pub view_layout: BindGroupLayoutDescriptor,
    /// Group 1: one parameter set.
    pub parameter_layout: BindGroupLayoutDescriptor,
}

/// Queues the compute half's pipelines, one per key (render startup).
pub fn init_height_compute_pipeline(
    mut commands: Commands,
    pipeline_cache: Res<PipelineCache>,
    asset_server: Res<AssetServer>,
) {
    let view_layout = BindGroupLayoutDescriptor::new(
        "mesostructure_height_view_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::COMPUTE,
            (
                texture_2d(TextureSampleType::Float { filterable: false }),
                texture_2d(TextureSampleType::Float { filterable: false }),
                texture_storage_2d(MHM_FORMAT, StorageTextureAccess::WriteOnly),
                texture_storage_2d(BUMP_NORMAL_FORMAT, StorageTextureAccess::WriteOnly),
                texture_storage_2d(TEXTURE_VISIBILITY_FORMAT, StorageTextureAccess::WriteOnly),
                uniform_buffer::<ViewUniform>(true),
                uniform_buffer::<GpuLights>(true),
                texture_depth_2d(),
                texture_2d(TextureSampleType::Uint),
            ),
        ),
    );
    let parameter_layout = BindGroupLayoutDescriptor::new(
        "mesostructure_height_parameter_layout",
        &BindGroupLayoutEntries::sequential(
            ShaderStages::COMPUTE,
            (
                texture_2d(TextureSampleType::Float { filterable: false }),
                texture_2d(TextureSampleType::Float { filterable: false }),
                texture_2d(TextureSampleType::Uint),
                uniform_buffer::<HeightParametersUniform>(false),
            ),
        ),
    );
    let shader = bevy::asset::load_embedded_asset!(asset_server.as_ref(), "height.wgsl");
    // One pipeline per key (as Bevy keys its SSAO): the texture-space horizons compiled in or
    // out, and with them the texture-space bounce.
    let specialize = |texture_space_horizons: bool, texture_space_bounce: bool| {
        let mut shader_defs = vec![
            // The horizon map's layout, from the one definition in `height_map_import`.
            bevy::shader::ShaderDefVal::UInt(
                "HORIZON_AZIMUTHS".into(),
                crate::height_map_import::HORIZON_AZIMUTHS as u32,
            ),
            bevy::shader::ShaderDefVal::Int(
                "HORIZON_BANDS".into(),
                crate::height_map_import::HORIZON_BANDS as i32,
            ),
            bevy::shader::ShaderDefVal::UInt(
                "EDGE_SHADOWED_PERCENT".into(),
                crate::height_map_import::EDGE_SHADOWED_PERCENT,
            ),
            bevy::shader::ShaderDefVal::UInt(
                "MESOSTRUCTURE_LIGHTING_PASS_ID".into(),
                crate::render::lighting::MESOSTRUCTURE_LIGHTING_PASS_ID as u32,
            ),
        ];
        if texture_space_horizons {
            shader_defs.push("TEXTURE_SPACE_HORIZONS".into());
        }
        if texture_space_bounce {
            shader_defs.push("TEXTURE_SPACE_BOUNCE".into());
            shader_defs.push(bevy::shader::ShaderDefVal::UInt(
                "TEXTURE_BOUNCE_SAMPLES".into(),
                crate::height_map_import::TEXTURE_BOUNCE_SAMPLES,
            ));
        }
        pipeline_cache.queue_compute_pipeline(ComputePipelineDescriptor {
            label: Some("mesostructure_height_pipeline".into()),
            layout: vec![view_layout.clone(), parameter_layout.clone()],
            shader: shader.clone(),
            shader_defs,
            entry_point: Some("height".into()),
            ..default()
        })
    };
    commands.insert_resource(HeightComputePipeline {
        screen_space_only: specialize(false, false),
        texture_space_horizons: specialize(true, false),
        texture_space_bounce: specialize(true, true),
        view_layout,
        parameter_layout,
    });
}

impl HeightComputePipeline {
    /// The pipeline a view's settings key.
    pub fn for_settings(
        &self,
        settings: &crate::render::view_settings::ViewSettings,
    ) -> CachedComputePipelineId {
        match (settings.texture_space_horizons, settings.texture_space_bounce_runs()) {
            (false, _) => self.screen_space_only,
            (true, false) => self.texture_space_horizons,
            (true, true) => self.texture_space_bounce,
        }
    }
}

/// The compute half's per-view bind group (render `PrepareBindGroups`).
#[derive(Component)]
pub struct ViewHeightBindGroup(pub BindGroup);

/// Binds each view's surface, core normal and outputs, its view and lights uniforms.
pub fn prepare_height_bind_group(
    mut commands: Commands,
    device: Res<RenderDevice>,
    pipeline_cache: Res<PipelineCache>,
    pipeline: Res<HeightComputePipeline>,
    view_uniforms: Res<ViewUniforms>,
    light_meta: Res<LightMeta>,
    views: Query<(Entity, &ViewHeightTextures, &ViewPrepassTextures)>,
) {
    let (Some(view_binding), Some(lights_binding)) = (
        view_uniforms.uniforms.binding(),
        light_meta.view_gpu_lights.binding(),
    ) else {
        return;
    };
    for (entity, textures, prepass) in &views {
        let (Some(depth), Some(pass_ids)) = (
            prepass.depth_view(),
            prepass
                .deferred_lighting_pass_id
                .as_ref()
                .map(|t| &t.texture.default_view),
        ) else {
            commands.entity(entity).remove::<ViewHeightBindGroup>();
            continue;
        };
        let bind_group = device.create_bind_group(
            "mesostructure_height_view_bind_group",
            &pipeline_cache.get_bind_group_layout(&pipeline.view_layout),
            &BindGroupEntries::sequential((
                &textures.surface.default_view,
                &textures.core_normal.default_view,
                &textures.mhm.default_view,
                &textures.bump_normal.default_view,
                &textures.texture_visibility.default_view,
                view_binding.clone(),
                lights_binding.clone(),
                depth,
                pass_ids,
            )),
        );
        commands
            .entity(entity)
            .insert(ViewHeightBindGroup(bind_group));
    }
}

/// The height pass's compute half: one dispatch per parameter set over the view, timed as
/// `mesostructure/height`. (Its own system, so its own command encoder: lavapipe crashes on
/// debug groups around a render and a compute pass in one encoder.)
pub fn height_compute_pass(
    view: ViewQuery<(
        &ExtractedView,
        &ViewHeightTextures,
        &ViewHeightBindGroup,
        &ViewUniformOffset,
        &ViewLightsUniformOffset,
        &ExtractedMesostructure,
    )>,
    phases: Res<ViewSortedRenderPhases<HeightPhaseItem>>,
    groups: Res<HeightMaterialBindGroups>,
    pipeline: Res<HeightComputePipeline>,
    pipeline_cache: Res<PipelineCache>,
    mut ctx: RenderContext,
) {
    let (extracted_view, textures, bind_group, view_offset, lights_offset, settings) =
        view.into_inner();
    if !settings.0.needs_height_map()
        || !crate::render::view_has_mesostructure(&phases, extracted_view)
    {
        return;
    }
    let Some(compute) = pipeline_cache.get_compute_pipeline(pipeline.for_settings(&settings.0))
    else {
        return;
    };
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    let span = diagnostics.time_span(ctx.command_encoder(), "mesostructure/height");
    let encoder = ctx.command_encoder();
    encoder.push_debug_group("mesostructure/height");
    {
        let mut pass = encoder.begin_compute_pass(&ComputePassDescriptor {
            label: Some("mesostructure/height"),
            timestamp_writes: None,
        });
        pass.set_pipeline(compute);
        pass.set_bind_group(
            0,
            &bind_group.0,
            &[view_offset.offset, lights_offset.offset],
        );
        let size = textures.size;
        for set in &groups.parameter_sets {
            pass.set_bind_group(1, &set.bind_group, &[]);
            pass.dispatch_workgroups(size.x.div_ceil(8), size.y.div_ceil(8), 1);
        }
    }
    encoder.pop_debug_group();
    span.end(ctx.command_encoder());
}
