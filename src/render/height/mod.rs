//! Height pass (paper §2.1), in two halves. The raster half draws only the meshes with a
//! mesostructure material, with the mesh pipeline's own vertex stage (so skinned, morphed and
//! CPU-deformed meshes line up with the prepass depth), depth-tested against the prepass depth
//! and never writing it; it stores each pixel's UV, depth, object id, core normal and
//! parameter set and reads no texture. The compute half samples the height maps there into the
//! screen-space height map (MHM), the Blinn bump normals and the texture-space terms: all the
//! per-pixel texture work in compute, which some GPUs run far faster than fragment work (on an
//! H100 at 1080p the one-pass version's fragment shader took 15.2 ms on a 40k-triangle sphere,
//! the two halves 0.8 ms: docs/bench.md).

use std::ops::Range;

use bevy::{
    camera::{MainPassResolutionOverride, Viewport},
    core_pipeline::core_3d::TransparentSortingInfo3d,
    ecs::{
        entity::EntityHash,
        query::ROQueryItem,
        system::{SystemParamItem, lifetimeless::SRes},
    },
    math::FloatOrd,
    mesh::MeshVertexBufferLayoutRef,
    pbr::{
        DrawMesh, MeshPipeline, MeshPipelineKey, RenderMeshInstances, SetMeshBindGroup,
        SetMeshViewBindGroup, SetMeshViewBindingArrayBindGroup, ViewKeyCache,
    },
    platform::collections::{HashMap, HashSet},
    prelude::*,
    render::{
        batching::{
            GetBatchData, GetFullBatchData,
            gpu_preprocessing::UntypedPhaseIndirectParametersBuffers,
        },
        camera::ExtractedCamera,
        diagnostic::RecordDiagnostics,
        mesh::RenderMesh,
        render_asset::RenderAssets,
        render_phase::{
            CachedRenderPipelinePhaseItem, DrawFunctionId, DrawFunctions, PhaseItem,
            PhaseItemExtraIndex, RenderCommand, RenderCommandResult, SetItemPipeline,
            SortedPhaseItem, TrackedRenderPass, ViewSortedRenderPhases,
        },
        render_resource::{binding_types::*, *},
        renderer::{RenderContext, RenderDevice, RenderQueue, ViewQuery},
        sync_world::MainEntity,
        texture::{CachedTexture, GpuImage, TextureCache},
        view::{ExtractedView, RenderVisibleEntities, ViewDepthTexture},
    },
};
use nonmax::NonMaxU32;

use super::{STORAGE_IMAGE, view_texture, working_size};

mod compute;
pub use compute::{
    HeightComputePipeline, HeightParameterSet, HeightParametersUniform, height_compute_pass,
    init_height_compute_pipeline, prepare_height_bind_group,
};
use crate::{
    material::PreparedMesostructure, render::view_settings::ExtractedMesostructure,
    warn_once::WarnedOnce,
};

/// Embeds the pass's shaders (their asset paths follow this folder).
pub(super) fn embed_shaders(app: &mut App) {
    bevy::asset::embedded_asset!(app, "height_raster.wgsl");
    bevy::asset::embedded_asset!(app, "height.wgsl");
}

/// The raster half's surface image: (u, v, NDC depth, object id). Never cleared: a texel is
/// this frame's where Bevy's prepass left a mesostructure material at its depth (`height.wgsl`).
pub const SURFACE_FORMAT: TextureFormat = TextureFormat::Rgba32Float;
/// MHM: (height·k, NDC depth, object id, dis).
pub const MHM_FORMAT: TextureFormat = TextureFormat::Rgba32Float;
/// Core normal n0 (world space); `w` the parameter set of the pixel's material. 32-bit: the
/// compute half takes the core's curvature from neighbouring normals' differences, which half
/// floats would drown.
pub const CORE_NORMAL_FORMAT: TextureFormat = TextureFormat::Rgba32Float;
/// Shading normal by Blinn bump mapping (world space; 0 where the material has a normal map);
/// `w` the texture-space occlusion (−1: none).
pub const BUMP_NORMAL_FORMAT: TextureFormat = TextureFormat::Rgba16Float;
/// Texture-space terms of the first directional light: its visibility and its one bounce
/// relative to E0 (each −1: none).
pub const TEXTURE_VISIBILITY_FORMAT: TextureFormat = TextureFormat::Rg32Float;

/// The height pass's images of one view, which every later pass reads.
#[derive(Component)]
pub struct ViewHeightTextures {
    /// The raster half's UV, depth and object id.
    pub surface: CachedTexture,
    /// Screen-space height map.
    pub mhm: CachedTexture,
    /// Core normals.
    pub core_normal: CachedTexture,
    /// Bump-mapped shading normals.
    pub bump_normal: CachedTexture,
    /// Texture-space visibility and one bounce of the first directional light.
    pub texture_visibility: CachedTexture,
    /// Size in pixels (the render target's), that of every working image of the view.
    pub size: UVec2,
}

/// Creates the height pass's images of each view with the effect (render `PrepareResources`).
pub fn prepare_height_textures(
    mut commands: Commands,
    mut texture_cache: ResMut<TextureCache>,
    device: Res<RenderDevice>,
    views: Query<(Entity, &ExtractedCamera), With<ExtractedMesostructure>>,
) {
    let raster =
        TextureUsages::RENDER_ATTACHMENT | TextureUsages::TEXTURE_BINDING | TextureUsages::COPY_SRC;
    for (entity, camera) in &views {
        let Some(size) = working_size(camera) else {
            commands.entity(entity).remove::<ViewHeightTextures>();
            continue;
        };
        let mut texture = |label, format, usage| {
            view_texture(&mut texture_cache, &device, label, format, usage, size)
        };
        let textures = ViewHeightTextures {
            surface: texture("mesostructure_surface", SURFACE_FORMAT, raster),
            mhm: texture("mesostructure_mhm", MHM_FORMAT, STORAGE_IMAGE),
            core_normal: texture("mesostructure_core_normal", CORE_NORMAL_FORMAT, raster),
            bump_normal: texture("mesostructure_bump_normal", BUMP_NORMAL_FORMAT, STORAGE_IMAGE),
            texture_visibility: texture(
                "mesostructure_texture_visibility",
                TEXTURE_VISIBILITY_FORMAT,
                STORAGE_IMAGE,
            ),
            size,
        };
        commands.entity(entity).insert(textures);
    }
}

/// One mesostructure mesh to draw into the height map of one view.
pub struct HeightPhaseItem {
    sorting_info: TransparentSortingInfo3d,
    distance: FloatOrd,
    entity: (Entity, MainEntity),
    pipeline: CachedRenderPipelineId,
    draw_function: DrawFunctionId,
    batch_range: Range<u32>,
    extra_index: PhaseItemExtraIndex,
    indexed: bool,
}

impl PhaseItem for HeightPhaseItem {
    fn entity(&self) -> Entity {
        self.entity.0
    }
    fn main_entity(&self) -> MainEntity {
        self.entity.1
    }
    fn draw_function(&self) -> DrawFunctionId {
        self.draw_function
    }
    fn batch_range(&self) -> &Range<u32> {
        &self.batch_range
    }
    fn batch_range_mut(&mut self) -> &mut Range<u32> {
        &mut self.batch_range
    }
    fn extra_index(&self) -> PhaseItemExtraIndex {
        self.extra_index.clone()
    }
    fn batch_range_and_extra_index_mut(&mut self) -> (&mut Range<u32>, &mut PhaseItemExtraIndex) {
        (&mut self.batch_range, &mut self.extra_index)
    }
}

impl SortedPhaseItem for HeightPhaseItem {
    type SortKey = FloatOrd;
    fn sort_key(&self) -> FloatOrd {
        self.distance
    }
    fn sort(items: &mut indexmap::IndexMap<(Entity, MainEntity), Self, EntityHash>) {
        // Front to back: the depth test then rejects hidden fragments early.
        items.sort_by_key(|_, item| std::cmp::Reverse(item.distance));
    }
    fn recalculate_sort_keys(
        items: &mut indexmap::IndexMap<(Entity, MainEntity), Self, EntityHash>,
        view: &ExtractedView,
    ) {
        let rangefinder = view.rangefinder3d();
        for item in items.values_mut() {
            item.distance = FloatOrd(item.sorting_info.sort_distance(&rangefinder));
        }
    }
    fn indexed(&self) -> bool {
        self.indexed
    }
}

impl CachedRenderPipelinePhaseItem for HeightPhaseItem {
    fn cached_pipeline(&self) -> CachedRenderPipelineId {
        self.pipeline
    }
}

/// The height pass's raster pipeline: Bevy's mesh pipeline with our fragment stage and targets.
#[derive(Resource, Clone)]
pub struct HeightPassPipeline {
    mesh_pipeline: MeshPipeline,
    fragment_shader: Handle<Shader>,
    /// Group 3: the per-mesh uniform (UV transform, object id, parameter set).
    pub material_layout: BindGroupLayoutDescriptor,
}

/// Per-mesh parameters of the raster half (`HeightMaterial` in `height_raster.wgsl`).
#[derive(Clone, Copy, ShaderType)]
pub struct HeightMaterialUniform {
    /// Rows of the UV transform: `uv' = (x_axis·u + y_axis·v) + translation`.
    pub uv_x_axis_y_axis: Vec4,
    /// Translation of the UV transform.
    pub uv_translation: Vec2,
    /// Object id written to the MHM (> 0).
    pub object_id: f32,
    /// Index of the mesh's [`HeightParameterSet`].
    pub parameter_set: f32,
}

/// Builds the height-pass pipeline from Bevy's mesh pipeline (render startup).
pub fn init_height_pass_pipeline(
    mut commands: Commands,
    mesh_pipeline: Res<MeshPipeline>,
    asset_server: Res<AssetServer>,
) {
    let material_layout = BindGroupLayoutDescriptor::new(
        "mesostructure_height_material_layout",
        &BindGroupLayoutEntries::single(
            ShaderStages::FRAGMENT,
            uniform_buffer::<HeightMaterialUniform>(true),
        ),
    );
    commands.insert_resource(HeightPassPipeline {
        mesh_pipeline: mesh_pipeline.clone(),
        fragment_shader: bevy::asset::load_embedded_asset!(
            asset_server.as_ref(),
            "height_raster.wgsl"
        ),
        material_layout,
    });
}

/// The raster half's key: Bevy's mesh key (vertex layout, view).
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct HeightPipelineKey {
    /// Bevy's mesh pipeline key.
    pub mesh: MeshPipelineKey,
}

impl SpecializedMeshPipeline for HeightPassPipeline {
    type Key = HeightPipelineKey;

    fn specialize(
        &self,
        key: HeightPipelineKey,
        layout: &MeshVertexBufferLayoutRef,
    ) -> Result<RenderPipelineDescriptor, SpecializedMeshPipelineError> {
        let HeightPipelineKey { mesh: key } = key;
        // Bevy's own mesh pipeline gives the vertex stage (skinning, morph targets, the same
        // position math as the prepass), the vertex buffers and groups 0–2.
        let mut descriptor = self.mesh_pipeline.specialize(key, layout)?;
        descriptor.label = Some("mesostructure_height_raster_pipeline".into());
        descriptor.layout.push(self.material_layout.clone());
        let shader_defs = descriptor.vertex.shader_defs.clone();
        descriptor.fragment = Some(FragmentState {
            shader: self.fragment_shader.clone(),
            shader_defs,
            entry_point: Some("fragment".into()),
            targets: vec![
                Some(ColorTargetState {
                    format: SURFACE_FORMAT,
                    blend: None,
                    write_mask: ColorWrites::ALL,
                }),
                Some(ColorTargetState {
                    format: CORE_NORMAL_FORMAT,
                    blend: None,
                    write_mask: ColorWrites::ALL,
                }),
            ],
        });
        if let Some(depth) = descriptor.depth_stencil.as_mut() {
            depth.depth_write_enabled = Some(false);
            depth.depth_compare = Some(CompareFunction::GreaterEqual);
        }
        descriptor.multisample = MultisampleState::default();
        Ok(descriptor)
    }
}

// Per-item data comes from Bevy's mesh pipeline, but items are never batched: each may bind
// another height map at group 3.
impl GetBatchData for HeightPassPipeline {
    type Param = <MeshPipeline as GetBatchData>::Param;
    type BatchSetCompareData = ();
    type BatchCompareData = ();
    type BufferData = <MeshPipeline as GetBatchData>::BufferData;

    fn get_batch_data(
        param: &SystemParamItem<Self::Param>,
        entity: (Entity, MainEntity),
    ) -> Option<(Self::BufferData, Option<((), ())>)> {
        MeshPipeline::get_batch_data(param, entity).map(|(data, _)| (data, None))
    }
}

impl GetFullBatchData for HeightPassPipeline {
    type BufferInputData = <MeshPipeline as GetFullBatchData>::BufferInputData;

    fn get_index_and_compare_data(
        param: &SystemParamItem<Self::Param>,
        main_entity: MainEntity,
    ) -> Option<(NonMaxU32, Option<((), ())>)> {
        MeshPipeline::get_index_and_compare_data(param, main_entity).map(|(i, _)| (i, None))
    }

    fn get_binned_batch_data(
        param: &SystemParamItem<Self::Param>,
        main_entity: MainEntity,
    ) -> Option<Self::BufferData> {
        MeshPipeline::get_binned_batch_data(param, main_entity)
    }

    fn write_batch_indirect_parameters_metadata(
        indexed: bool,
        base_output_index: u32,
        batch_set_index: Option<NonMaxU32>,
        buffers: &mut UntypedPhaseIndirectParametersBuffers,
        offset: u32,
    ) {
        MeshPipeline::write_batch_indirect_parameters_metadata(
            indexed,
            base_output_index,
            batch_set_index,
            buffers,
            offset,
        );
    }

    fn get_binned_index(
        param: &SystemParamItem<Self::Param>,
        main_entity: MainEntity,
    ) -> Option<NonMaxU32> {
        MeshPipeline::get_binned_index(param, main_entity)
    }
}

/// Draws one mesostructure mesh into the height map.
pub type DrawHeight = (
    SetItemPipeline,
    SetMeshViewBindGroup<0>,
    SetMeshViewBindingArrayBindGroup<1>,
    SetMeshBindGroup<2>,
    SetHeightMaterialBindGroup<3>,
    DrawMesh,
);

/// Per-mesh bind groups of the raster half and the compute half's parameter sets, rebuilt
/// every frame.
#[derive(Resource, Default)]
pub struct HeightMaterialBindGroups {
    uniforms: DynamicUniformBuffer<HeightMaterialUniform>,
    groups: HashMap<MainEntity, (BindGroup, u32)>,
    /// The compute half's dispatches, in index order (set 0 also writes "none" to the MHM).
    pub parameter_sets: Vec<HeightParameterSet>,
}

/// Binds the mesh's height-map bind group.
pub struct SetHeightMaterialBindGroup<const I: usize>;

impl<P: PhaseItem, const I: usize> RenderCommand<P> for SetHeightMaterialBindGroup<I> {
    type Param = SRes<HeightMaterialBindGroups>;
    type ViewQuery = ();
    type ItemQuery = ();

    fn render<'w>(
        item: &P,
        _view: ROQueryItem<'w, '_, ()>,
        _entity: Option<ROQueryItem<'w, '_, ()>>,
        groups: SystemParamItem<'w, '_, Self::Param>,
        pass: &mut TrackedRenderPass<'w>,
    ) -> RenderCommandResult {
        let Some((group, offset)) = groups.into_inner().groups.get(&item.main_entity()) else {
            return RenderCommandResult::Skip;
        };
        pass.set_bind_group(I, group, &[*offset]);
        RenderCommandResult::Success
    }
}

/// Builds the raster half's per-mesh uniforms and bind groups and the compute half's parameter
/// sets (height-map mip chain, horizon map, k, bump flag).
#[allow(clippy::too_many_arguments)]
pub fn prepare_height_material_bind_groups(
    mut groups: ResMut<HeightMaterialBindGroups>,
    materials: Query<(&MainEntity, &PreparedMesostructure)>,
    images: Res<RenderAssets<GpuImage>>,
    pipeline: Res<HeightPassPipeline>,
    compute: Res<HeightComputePipeline>,
    pipeline_cache: Res<PipelineCache>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
) {
    let groups = groups.as_mut();
    groups.groups.clear();
    groups.uniforms.clear();
    groups.parameter_sets.clear();
    let mut entries = Vec::new();
    // Parameter sets by (height mips, horizon map, distances, k, bump): meshes sharing all of
    // these share a dispatch.
    let mut set_of: HashMap<_, usize> = HashMap::default();
    let parameter_layout = pipeline_cache.get_bind_group_layout(&compute.parameter_layout);
    for (main_entity, prepared) in &materials {
        let (Some(image), Some(horizons), Some(distances)) = (
            images.get(prepared.height_mips),
            images.get(prepared.horizons),
            images.get(prepared.horizon_distances),
        ) else {
            continue;
        };
        let key = (
            prepared.height_mips,
            prepared.horizons,
            prepared.horizon_distances,
            prepared.scale.to_bits(),
            prepared.bump,
        );
        let parameter_set = *set_of.entry(key).or_insert_with(|| {
            let index = groups.parameter_sets.len();
            let set = HeightParameterSet::new(
                &device,
                &queue,
                &parameter_layout,
                [image, horizons, distances],
                HeightParametersUniform {
                    scale: prepared.scale,
                    bump: prepared.bump as u32 as f32,
                    index: index as f32,
                    spare: 0.0,
                },
            );
            groups.parameter_sets.push(set);
            index
        });
        let t = prepared.uv_transform;
        let offset = groups.uniforms.push(&HeightMaterialUniform {
            uv_x_axis_y_axis: Vec4::new(
                t.matrix2.x_axis.x,
                t.matrix2.x_axis.y,
                t.matrix2.y_axis.x,
                t.matrix2.y_axis.y,
            ),
            uv_translation: t.translation,
            object_id: object_id(*main_entity),
            parameter_set: parameter_set as f32,
        });
        entries.push((*main_entity, offset));
    }
    if entries.is_empty() {
        return;
    }
    groups.uniforms.write_buffer(&device, &queue);
    let Some(binding) = groups.uniforms.binding() else {
        return;
    };
    let layout = pipeline_cache.get_bind_group_layout(&pipeline.material_layout);
    for (main_entity, offset) in entries {
        let group = device.create_bind_group(
            "mesostructure_height_material_bind_group",
            &layout,
            &BindGroupEntries::single(binding.clone()),
        );
        groups.groups.insert(main_entity, (group, offset));
    }
}

/// The id that the MHM carries for a mesh: its entity index + 1 (0 = no mesostructure).
/// Stored as `f32`, exact below 2^24.
pub fn object_id(entity: MainEntity) -> f32 {
    (entity.id().index_u32() + 1) as f32
}

/// Adds every visible, prepared mesostructure mesh of each view to the height phase.
#[allow(clippy::too_many_arguments)]
pub fn queue_height_phase(
    draw_functions: Res<DrawFunctions<HeightPhaseItem>>,
    mut pipelines: ResMut<SpecializedMeshPipelines<HeightPassPipeline>>,
    pipeline_cache: Res<PipelineCache>,
    pipeline: Res<HeightPassPipeline>,
    render_meshes: Res<RenderAssets<RenderMesh>>,
    render_mesh_instances: Res<RenderMeshInstances>,
    mut phases: ResMut<ViewSortedRenderPhases<HeightPhaseItem>>,
    views: Query<(&ExtractedView, &RenderVisibleEntities), With<ExtractedMesostructure>>,
    view_key_cache: Res<ViewKeyCache>,
    materials: Query<(Entity, &MainEntity), With<PreparedMesostructure>>,
    groups: Res<HeightMaterialBindGroups>,
    mut warned: ResMut<WarnedOnce>,
) {
    if materials.is_empty() {
        return;
    }
    let draw_function = draw_functions.read().id::<DrawHeight>();
    for (view, visible) in &views {
        let Some(phase) = phases.get_mut(&view.retained_view_entity) else {
            continue;
        };
        let Some(&view_key) = view_key_cache.get(&view.retained_view_entity) else {
            continue;
        };
        let Some(visible) = visible.get::<Mesh3d>() else {
            continue;
        };
        let visible_set: HashSet<MainEntity> = visible
            .entities_cpu_culling
            .iter()
            .map(|(_, m)| *m)
            .chain(visible.entities_gpu_culling.keys().copied())
            .collect();
        for (render_entity, main_entity) in &materials {
            if !visible_set.contains(main_entity) || !groups.groups.contains_key(main_entity) {
                continue;
            }
            let Some(instance) = render_mesh_instances.render_mesh_queue_data(*main_entity) else {
                continue;
            };
            let Some(mesh) = render_meshes.get(instance.mesh_asset_id()) else {
                continue;
            };
            let missing: Vec<&str> = [
                (Mesh::ATTRIBUTE_UV_0, "UV_0"),
                (Mesh::ATTRIBUTE_NORMAL, "NORMAL"),
            ]
            .into_iter()
            .filter(|(a, _)| !mesh.layout.0.contains(*a))
            .map(|(_, name)| name)
            .collect();
            if !missing.is_empty() {
                warned.warn(format!("attributes {:?}", instance.mesh_asset_id()), || {
                    format!(
                        "mesh {:?} of entity {} has no {}; it is drawn without mesostructure",
                        instance.mesh_asset_id(),
                        main_entity.id(),
                        missing.join(" or ")
                    )
                });
                continue;
            }
            let key = HeightPipelineKey {
                mesh: view_key
                    | MeshPipelineKey::from_bits_retain(mesh.key_bits.bits())
                    | MeshPipelineKey::from_primitive_topology_and_strip_index(
                        mesh.primitive_topology(),
                        mesh.index_format(),
                    ),
            };
            let pipeline_id =
                match pipelines.specialize(&pipeline_cache, &pipeline, key, &mesh.layout) {
                    Ok(id) => id,
                    Err(err) => {
                        warned.warn(format!("specialize {:?}", instance.mesh_asset_id()), || {
                            format!(
                                "cannot draw mesh {:?} into the height map: {err}",
                                instance.mesh_asset_id()
                            )
                        });
                        continue;
                    }
                };
            phase.add_transient(HeightPhaseItem {
                // Order does not matter: only the fragment at the prepass depth passes.
                sorting_info: TransparentSortingInfo3d::AlwaysOnTop,
                distance: FloatOrd(0.0),
                entity: (render_entity, *main_entity),
                pipeline: pipeline_id,
                draw_function,
                batch_range: 0..1,
                extra_index: PhaseItemExtraIndex::None,
                indexed: mesh.indexed(),
            });
        }
    }
}

/// The height pass's raster half: draws the phase into the surface and core-normal images
/// (clearing neither).
pub fn height_pass(
    world: &World,
    view: ViewQuery<(
        &ExtractedCamera,
        &ExtractedView,
        &ViewDepthTexture,
        &ViewHeightTextures,
        Option<&MainPassResolutionOverride>,
        &crate::render::view_settings::ExtractedMesostructure,
    )>,
    phases: Res<ViewSortedRenderPhases<HeightPhaseItem>>,
    mut ctx: RenderContext,
) {
    let view_entity = view.entity();
    let (camera, extracted_view, depth, textures, resolution_override, settings) =
        view.into_inner();
    let Some(phase) = phases.get(&extracted_view.retained_view_entity) else {
        return;
    };
    if phase.items.is_empty() || !settings.0.needs_height_map() {
        // No mesostructure surface in view: no pass at all (the later passes skip too).
        return;
    }
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    ctx.command_encoder()
        .push_debug_group("mesostructure/height_raster");
    {
        let attachment = |view, load| {
            Some(RenderPassColorAttachment {
                view,
                depth_slice: None,
                resolve_target: None,
                ops: Operations {
                    load,
                    store: StoreOp::Store,
                },
            })
        };
        // Nothing is cleared (clears were ~1.2 ms of a 1080p frame on an H100, issue 11): the
        // compute half takes a texel as this frame's only where Bevy's prepass left a
        // mesostructure material at the texel's depth, and this pass writes both targets
        // wherever it writes at all.
        let mut pass = ctx.begin_tracked_render_pass(RenderPassDescriptor {
            label: Some("mesostructure_height_raster_pass"),
            color_attachments: &[
                attachment(&textures.surface.default_view, LoadOp::Load),
                attachment(&textures.core_normal.default_view, LoadOp::Load),
            ],
            depth_stencil_attachment: Some(RenderPassDepthStencilAttachment {
                view: depth.view(),
                depth_ops: Some(Operations {
                    load: LoadOp::Load,
                    store: StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        // A pass span: inside the pass, so that pipeline statistics (fragment invocations)
        // are recorded where the backend has them.
        let span = diagnostics.pass_span(&mut pass, "mesostructure/height_raster");
        if let Some(viewport) =
            Viewport::from_viewport_and_override(camera.viewport.as_ref(), resolution_override)
        {
            pass.set_camera_viewport(&viewport);
        }
        if let Err(err) = phase.render(&mut pass, world, view_entity) {
            error!("bevy_mesostructure: height pass failed: {err:?}");
        }
        span.end(&mut pass);
    }
    ctx.command_encoder().pop_debug_group();
}
