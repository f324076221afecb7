//! The translucency's render-world state ([`TranslucencyGpu`]: the scene's transport, light
//! injection and gather buffers, uploaded in `prepare_translucency`; the injection's and the
//! iteration's passes are in `injection/` and `iteration/`) and the gather that puts the
//! patches' light into each view (`gather_compute.wgsl`: a compute pass culling the patches
//! per 8×8 tile where the view's main images take storage writes — at one pixel in 2×2 and
//! upsampled by surface, by default ([`GatherResolution`]); else `gather.wgsl`, a fullscreen
//! pass added to the lit image). What they share is `gathered.wgsl`, and single scattering
//! marched per pixel `marched.wgsl`, both imported. Its CPU twin is `twin.rs`.

use std::sync::Arc;

use bevy::{
    core_pipeline::{FullscreenShader, prepass::ViewPrepassTextures},
    prelude::*,
    render::{
        diagnostic::RecordDiagnostics,
        render_resource::{binding_types::*, *},
        renderer::{RenderAdapterInfo, RenderContext, RenderDevice, RenderQueue, ViewQuery},
        texture::{CachedTexture, TextureCache},
        view::{ViewTarget, ViewUniform, ViewUniformOffset, ViewUniforms},
    },
};
use bytemuck::{Pod, Zeroable};

use super::{
    injection::GpuInjection,
    iteration::{FlowFrame, GpuTransport, IterationLimits, ProductsReadback, RowLanes},
    plugin::{GatherMethod, GatherResolution, TranslucencyFrame, TranslucencyScene},
};

mod twin;

pub use twin::{BeamSingleScattering, PatchGrid, gathered_radiance};

/// `GatherParams` in `gathered.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable, ShaderType)]
struct GatherParams {
    levels: u32,
    patches: u32,
    direct: u32,
    exitance: u32,
    beam_irradiance: u32,
    beam_direction: u32,
    flow: u32,
    has_flow: u32,
    lobes: u32,
    has_lobes: u32,
    irradiance: u32,
    // A uniform's size is a multiple of 16 bytes.
    padding_y: u32,
}

/// The gather radius in patch sizes: about two rings of neighbours.
pub const GATHER_RADIUS_IN_PATCHES: f32 = 1.5;

/// The render world's copy of the scene: the transport on the GPU and the gather's buffers.
#[derive(Resource, Default)]
pub struct TranslucencyGpu {
    // The injection's and the iteration's passes (`injection/`, `iteration/`) read and
    // clear their flags.
    scene_generation: u64,
    direct_generation: u64,
    lights_generation: u64,
    /// The lights changed since the last iteration ran.
    pub(super) iteration_pending: bool,
    /// And the GPU injects them ([`LightInjection::LightViewMaps`](super::LightInjection)).
    pub(super) injection_pending: bool,
    /// An iteration of this transport was recorded: the next may start from its exitance.
    pub(super) solved: bool,
    /// Warm solves still to record with the lights still: a warm start stops at
    /// [`WARM_MAX_ITERATIONS`](super::transport::WARM_MAX_ITERATIONS) products, and these go
    /// on from where it stopped ([`settle_frames`](super::transport::settle_frames)).
    pub(super) settle_frames: u32,
    pub(super) transport: Option<GpuTransport>,
    /// The products the last solve took, read back: what the next warm solve records.
    pub(super) products: Option<ProductsReadback>,
    pub(super) injection: Option<GpuInjection>,
    gather: Option<(Buffer, Buffer, Buffer)>,
    /// What the gather binds for the translucent maps where the GPU injects no light: a
    /// header of no objects, and one word.
    no_translucent_maps: Option<(Buffer, Buffer)>,
    /// The injection's translucent maps are this frame's lights' (the CPU injected the last
    /// change: none).
    maps_current: bool,
}

impl TranslucencyGpu {
    /// The scene's transport on the GPU, once uploaded: its vectors hold this frame's `E⁰`
    /// and `B` ([`GpuTransport::direct_offsets`], [`GpuTransport::exitance`]).
    pub fn transport(&self) -> Option<&GpuTransport> {
        self.transport.as_ref()
    }
}

/// Uploads a new scene and each frame's new direct light (render `PrepareResources`).
pub(crate) fn prepare_translucency(
    frame: Res<TranslucencyFrame>,
    mut gpu: ResMut<TranslucencyGpu>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    adapter: Res<RenderAdapterInfo>,
    mut warned: ResMut<crate::warn_once::WarnedOnce>,
) {
    let row_lanes = RowLanes::for_adapter(&adapter);
    let Some((generation, scene)) = &frame.scene else {
        *gpu = TranslucencyGpu::default();
        return;
    };
    if gpu.scene_generation != *generation || gpu.transport.is_none() {
        let limits = IterationLimits {
            threshold: frame.settings.iteration_threshold.clamp(1e-6, 0.5),
            max_iterations: frame.settings.max_iterations.clamp(1, 256),
        };
        // With a beam table, the deep law's axis follows the table's light each frame.
        let frames = match scene.transport.beam_table {
            Some(_) => FlowFrame::of(&scene.patches, &scene.exit_laws, &scene.source_depths),
            None => Vec::new(),
        };
        let transport = GpuTransport::with_flow(&device, &scene.transport, limits, row_lanes, &frames);
        gpu.gather = Some(gather_buffers(&device, scene, &transport));
        gpu.no_translucent_maps = Some((
            device.create_buffer_with_data(&BufferInitDescriptor {
                label: Some("translucency_no_translucent_maps"),
                // The header's two vec4s (`translucent_maps_of`): no objects, no maps.
                contents: bytemuck::cast_slice(&[0.0f32; 8]),
                usage: BufferUsages::STORAGE,
            }),
            device.create_buffer_with_data(&BufferInitDescriptor {
                label: Some("translucency_no_translucent_depths"),
                contents: bytemuck::cast_slice(&[0u32; 4]),
                usage: BufferUsages::STORAGE,
            }),
        ));
        gpu.transport = Some(transport);
        gpu.products = Some(ProductsReadback::new(&device));
        gpu.solved = false;
        gpu.settle_frames = 0;
        gpu.injection = None;
        gpu.scene_generation = *generation;
        gpu.direct_generation = 0;
        gpu.lights_generation = 0;
    }
    let gpu = &mut *gpu;
    let Some(transport) = &gpu.transport else {
        return;
    };
    if let Some((direct_generation, direct)) = &frame.direct
        && *direct_generation != gpu.direct_generation
    {
        transport.write_direct(&queue, direct);
        gpu.direct_generation = *direct_generation;
        gpu.maps_current = false;
        gpu.iteration_pending = true;
        gpu.injection_pending = false;
    }
    if let Some((lights_generation, lights)) = &frame.lights
        && *lights_generation != gpu.lights_generation
    {
        // `inject_direct_light` clamped the resolution to what `GpuInjection` takes.
        let wanted = lights.resolution;
        let injection = match &mut gpu.injection {
            Some(injection) if injection.resolution() == wanted => injection,
            slot => slot.insert(GpuInjection::new(
                &device,
                &scene.patches,
                &scene.transport,
                &scene.albedo,
                transport,
                wanted,
                &scene.marched,
            )),
        };
        injection.write_lights(&device, &queue, &lights.lights, lights.ambient);
        let (cubes, beyond) = injection.cube_maps();
        if beyond > 0 {
            warned.warn("translucency-cube-maps", || {
                format!(
                    "translucency: {} lights lie inside translucent objects' bounds, more than the {} that take a \
                     cube of maps; the other {} march single scattering against one map along the line to \
                     the object's centre (less accurate)",
                    cubes + beyond,
                    cubes,
                    beyond
                )
            });
        }
        gpu.lights_generation = *lights_generation;
        gpu.maps_current = true;
        gpu.injection_pending = true;
        gpu.iteration_pending = true;
    }
}

fn gather_buffers(
    device: &RenderDevice,
    scene: &Arc<TranslucencyScene>,
    transport: &GpuTransport,
) -> (Buffer, Buffer, Buffer) {
    let patches = &scene.patches;
    // Each patch reaches 1.5 of its own patch sizes.
    let reaches: Vec<f32> = (0..patches.patches.len())
        .map(|i| GATHER_RADIUS_IN_PATCHES * patches.size_of(i))
        .collect();
    let centres: Vec<Vec3> = patches.patches.iter().map(|p| p.surface_point).collect();
    let grids = PatchGrid::levels(&centres, &reaches);
    // `GatherPatch` in gathered.wgsl: (surface point, reach), (normal, area), (albedo, object),
    // (the exit law's local albedo, η), its law per channel, (α, η) of its medium where a
    // beam table carries its beams (single scattering's law; zero elsewhere), the weight of
    // the flux along its surface per channel.
    // Where an object's single scattering is marched per pixel, the lit face's law is not
    // given as well.
    let marches = |object: u32| scene.marched.get(object as usize).is_some_and(Option::is_some);
    let media: Vec<Vec4> = scene
        .transport
        .beam_table
        .as_ref()
        .map(|t| {
            t.patch_media()
                .into_iter()
                .zip(&patches.patches)
                .map(|(m, p)| if marches(p.object) { Vec4::ZERO } else { m })
                .collect()
        })
        .unwrap_or_default();
    let records: Vec<[f32; 36]> = patches
        .patches
        .iter()
        .enumerate()
        .zip(&scene.albedo)
        .zip(&reaches)
        .map(|(((i, p), a), reach)| {
            let law = scene.exit_laws.get(i).copied().unwrap_or_default();
            let mut record = [0.0; 36];
            record[..12].copy_from_slice(&[
                p.surface_point.x,
                p.surface_point.y,
                p.surface_point.z,
                *reach,
                p.normal.x,
                p.normal.y,
                p.normal.z,
                p.area,
                a.x,
                a.y,
                a.z,
                // Its object (exact as a float below 2²⁴): the pixel's, for its marched single
                // scattering.
                p.object as f32,
            ]);
            record[12..15].copy_from_slice(&law.local_albedo.to_array());
            record[15] = law.eta;
            for (c, channel) in law.channels.iter().enumerate() {
                record[16 + 4 * c..20 + 4 * c].copy_from_slice(&channel.to_array());
            }
            record[28..32].copy_from_slice(&media.get(i).copied().unwrap_or(Vec4::ZERO).to_array());
            record[32..35].copy_from_slice(&law.tangential.to_array());
            record
        })
        .collect();
    // Per grid: cell size, bucket mask, where its offsets and its members start; then the
    // arrays themselves, each member as four words (patch index, its cell).
    let mut words = vec![0u32; 4 * grids.len()];
    for (l, grid) in grids.iter().enumerate() {
        words[4 * l] = grid.cell_size.to_bits();
        words[4 * l + 1] = (grid.offsets.len() - 2) as u32;
        words[4 * l + 2] = words.len() as u32;
        words.extend(&grid.offsets);
        words[4 * l + 3] = words.len() as u32;
        for (&i, cell) in grid.members.iter().zip(&grid.cells) {
            words.extend([i, cell.x as u32, cell.y as u32, cell.z as u32]);
        }
    }
    words.push(0);
    let (direct, exitance) = transport.vector_offsets();
    let beams = transport.beam_offsets();
    let params = GatherParams {
        levels: grids.len() as u32,
        patches: patches.patches.len() as u32,
        direct,
        exitance,
        beam_irradiance: beams.irradiance,
        beam_direction: beams.direction,
        flow: transport.flow_offset().unwrap_or(0),
        has_flow: u32::from(transport.flow_offset().is_some()),
        lobes: transport.lobes_offset().unwrap_or(0),
        has_lobes: u32::from(transport.lobes_offset().is_some()),
        irradiance: transport.irradiance_offset(),
        padding_y: 0,
    };
    let patch_buffer = device.create_buffer_with_data(&BufferInitDescriptor {
        label: Some("translucency_gather_patches"),
        contents: bytemuck::cast_slice(&records),
        usage: BufferUsages::STORAGE,
    });
    let grid_buffer = device.create_buffer_with_data(&BufferInitDescriptor {
        label: Some("translucency_gather_grid"),
        contents: bytemuck::cast_slice(&words),
        usage: BufferUsages::STORAGE,
    });
    let params_buffer = device.create_buffer_with_data(&BufferInitDescriptor {
        label: Some("translucency_gather_params"),
        contents: bytemuck::bytes_of(&params),
        usage: BufferUsages::UNIFORM,
    });
    (patch_buffer, grid_buffer, params_buffer)
}

/// A camera that shows the translucency: put on a `Camera3d` (with `Msaa::Off`). Brings the
/// depth and normal prepasses the gather reads.
#[derive(
    Component,
    Reflect,
    Clone,
    Copy,
    Debug,
    Default,
    bevy::render::extract_component::ExtractComponent,
)]
#[reflect(Component, Default)]
#[require(
    bevy::core_pipeline::prepass::DepthPrepass,
    bevy::core_pipeline::prepass::NormalPrepass
)]
pub struct TranslucencyCamera;

/// The gather's bind group layouts and shader: the fragment form specialised per view target
/// format; the compute form, for views whose main images take storage writes.
#[derive(Resource)]
pub struct GatherPipeline {
    layout: BindGroupLayoutDescriptor,
    /// The fragment form's bindings visible to compute, then the lit image and the image
    /// written.
    compute_layout: BindGroupLayoutDescriptor,
    /// The compute form, by gather method ([`GatherMethod`] as index).
    compute: [CachedComputePipelineId; 2],
    /// [`GatherResolution::Half`]'s three passes' layouts: the inputs and the samples
    /// written; the compute layout's bindings, the samples read and the tiles' flags written;
    /// the same with the flags read.
    half_layout: BindGroupLayoutDescriptor,
    upsample_layout: BindGroupLayoutDescriptor,
    unserved_layout: BindGroupLayoutDescriptor,
    /// Its gather at one pixel in 2×2, its upsample and its gather of the pixels no sample
    /// serves, by gather method.
    half: [CachedComputePipelineId; 2],
    upsample: [CachedComputePipelineId; 2],
    unserved: [CachedComputePipelineId; 2],
    fullscreen: FullscreenShader,
    shader: Handle<Shader>,
}

/// Render startup.
pub fn init_gather_pipeline(
    mut commands: Commands,
    asset_server: Res<AssetServer>,
    fullscreen: Res<FullscreenShader>,
    pipeline_cache: Res<PipelineCache>,
) {
    let inputs = |stages| {
        BindGroupLayoutEntries::sequential(
            stages,
            (
                uniform_buffer::<ViewUniform>(true),
                texture_depth_2d(),
                texture_2d(TextureSampleType::Float { filterable: false }),
                uniform_buffer::<GatherParams>(false),
                storage_buffer_read_only_sized(false, None),
                storage_buffer_read_only_sized(false, None),
                storage_buffer_read_only_sized(false, None),
            ),
        )
        .iter()
        .copied()
        // The translucent maps (13, 14).
        .chain(
            BindGroupLayoutEntries::with_indices(
                stages,
                (
                    (13, storage_buffer_read_only_sized(false, None)),
                    (14, storage_buffer_read_only_sized(false, None)),
                ),
            )
            .iter()
            .copied(),
        )
        .collect::<Vec<_>>()
    };
    let layout = BindGroupLayoutDescriptor::new(
        "translucency_gather_layout",
        &inputs(ShaderStages::FRAGMENT),
    );
    let mut compute_entries = inputs(ShaderStages::COMPUTE).to_vec();
    compute_entries.extend(BindGroupLayoutEntries::with_indices(
        ShaderStages::COMPUTE,
        (
            (7, texture_2d(TextureSampleType::Float { filterable: false })),
            (
                8,
                texture_storage_2d(
                    crate::render::VIEW_TARGET_FORMAT,
                    StorageTextureAccess::WriteOnly,
                ),
            ),
        ),
    ).iter());
    let mut half_entries = inputs(ShaderStages::COMPUTE).to_vec();
    half_entries.extend(BindGroupLayoutEntries::with_indices(
        ShaderStages::COMPUTE,
        ((9, texture_storage_2d(HALF_LIGHT_FORMAT, StorageTextureAccess::WriteOnly)),),
    ).iter());
    let mut upsample_entries = compute_entries.clone();
    upsample_entries.extend(BindGroupLayoutEntries::with_indices(
        ShaderStages::COMPUTE,
        (
            (10, texture_2d(TextureSampleType::Float { filterable: false })),
            (11, texture_storage_2d(UNSERVED_TILES_FORMAT, StorageTextureAccess::WriteOnly)),
        ),
    ).iter());
    let mut unserved_entries = compute_entries.clone();
    unserved_entries.extend(BindGroupLayoutEntries::with_indices(
        ShaderStages::COMPUTE,
        (
            (10, texture_2d(TextureSampleType::Float { filterable: false })),
            (12, texture_2d(TextureSampleType::Uint)),
        ),
    ).iter());
    let compute_layout =
        BindGroupLayoutDescriptor::new("translucency_gather_compute_layout", &compute_entries);
    let half_layout =
        BindGroupLayoutDescriptor::new("translucency_gather_half_layout", &half_entries);
    let upsample_layout =
        BindGroupLayoutDescriptor::new("translucency_gather_upsample_layout", &upsample_entries);
    let unserved_layout =
        BindGroupLayoutDescriptor::new("translucency_gather_unserved_layout", &unserved_entries);
    let shader = bevy::asset::load_embedded_asset!(asset_server.as_ref(), "gather.wgsl");
    let compute_shader = bevy::asset::load_embedded_asset!(asset_server.as_ref(), "gather_compute.wgsl");
    let queue = |label: &'static str, layout: &BindGroupLayoutDescriptor, entry: &'static str, half: bool| {
        [GatherMethod::Interpolation, GatherMethod::PhotonDensity].map(|method| {
            let mut shader_defs = Vec::new();
            if half {
                shader_defs.push("HALF_RESOLUTION".into());
            }
            shader_defs.extend(method_def(method));
            pipeline_cache.queue_compute_pipeline(ComputePipelineDescriptor {
                label: Some(label.into()),
                layout: vec![layout.clone()],
                shader: compute_shader.clone(),
                shader_defs,
                entry_point: Some(entry.into()),
                ..default()
            })
        })
    };
    let compute = queue("translucency_gather_compute_pipeline", &compute_layout, "gather_compute", false);
    let half = queue("translucency_gather_half_pipeline", &half_layout, "gather_half", true);
    let upsample =
        queue("translucency_gather_upsample_pipeline", &upsample_layout, "gather_upsample", true);
    let unserved =
        queue("translucency_gather_unserved_pipeline", &unserved_layout, "gather_unserved", true);
    commands.insert_resource(GatherPipeline {
        layout,
        compute_layout,
        compute,
        half_layout,
        upsample_layout,
        unserved_layout,
        half,
        upsample,
        unserved,
        fullscreen: fullscreen.clone(),
        shader,
    });
}

/// The shader def of a gather method (none: interpolation).
fn method_def(method: GatherMethod) -> Option<bevy::shader::ShaderDefVal> {
    (method == GatherMethod::PhotonDensity).then(|| "PHOTON_DENSITY".into())
}

impl SpecializedRenderPipeline for GatherPipeline {
    type Key = (TextureFormat, GatherMethod);

    fn specialize(&self, (format, method): Self::Key) -> RenderPipelineDescriptor {
        // Added to the lit colour; alpha kept.
        let mut descriptor = crate::render::additive_fullscreen_pipeline(
            "translucency_gather_pipeline",
            self.layout.clone(),
            &self.fullscreen,
            self.shader.clone(),
            "gather",
            format,
        );
        if let Some(fragment) = descriptor.fragment.as_mut() {
            fragment.shader_defs.extend(method_def(method));
        }
        descriptor
    }
}

/// The gather pipeline of a view.
#[derive(Component)]
pub struct ViewGatherPipeline(CachedRenderPipelineId);

/// The format of [`GatherResolution::Half`]'s samples: the light (HDR, times the exposure) and
/// the reach the upsample takes a sample within, which may be far below a half float's
/// precision in a small scene.
const HALF_LIGHT_FORMAT: TextureFormat = TextureFormat::Rgba32Float;

/// The format of [`GatherResolution::Half`]'s flags, one per 8×8 tile: whether a pixel of it
/// is served by no sample.
const UNSERVED_TILES_FORMAT: TextureFormat = TextureFormat::R32Uint;

/// A view's [`GatherResolution::Half`] samples, one per 2×2 pixels, and its tiles' flags.
#[derive(Component)]
pub struct ViewHalfGatherTextures {
    half_light: CachedTexture,
    unserved_tiles: CachedTexture,
}

/// Specialises the gather for each translucency camera's target format (render `Prepare`);
/// a camera with MSAA on gets one warning and no gather (its prepass images are multisampled).
pub(crate) fn prepare_gather_pipelines(
    mut commands: Commands,
    pipeline_cache: Res<PipelineCache>,
    mut pipelines: ResMut<SpecializedRenderPipelines<GatherPipeline>>,
    pipeline: Res<GatherPipeline>,
    views: Query<
        (Entity, &ViewTarget, Option<&bevy::render::view::Msaa>),
        With<TranslucencyCamera>,
    >,
    mut warned: ResMut<crate::warn_once::WarnedOnce>,
    frame: Res<TranslucencyFrame>,
    mut texture_cache: ResMut<TextureCache>,
    device: Res<RenderDevice>,
) {
    for (entity, target, msaa) in &views {
        if msaa.is_some_and(|m| *m != bevy::render::view::Msaa::Off) {
            warned.warn("translucency-msaa", || {
                "translucency: a TranslucencyCamera has MSAA on; the translucency needs Msaa::Off \
                 and is not shown by that camera"
                    .to_string()
            });
            commands.entity(entity).remove::<ViewGatherPipeline>();
            continue;
        }
        let key = (target.main_texture_format(), frame.settings.gather);
        let id = pipelines.specialize(&pipeline_cache, &pipeline, key);
        commands.entity(entity).insert(ViewGatherPipeline(id));
        // The half-resolution samples, where the gather runs as compute at half resolution.
        if frame.settings.gather_resolution == GatherResolution::Half
            && crate::render::composites_in_compute(target)
        {
            let size = target.main_texture().size();
            let mut texture = |label, divisor: u32, format| {
                texture_cache.get(
                    &device,
                    TextureDescriptor {
                        label: Some(label),
                        size: Extent3d {
                            width: size.width.div_ceil(divisor),
                            height: size.height.div_ceil(divisor),
                            depth_or_array_layers: 1,
                        },
                        mip_level_count: 1,
                        sample_count: 1,
                        dimension: TextureDimension::D2,
                        format,
                        usage: TextureUsages::STORAGE_BINDING | TextureUsages::TEXTURE_BINDING,
                        view_formats: &[],
                    },
                )
            };
            commands.entity(entity).insert(ViewHalfGatherTextures {
                half_light: texture("translucency_gather_half_light", 2, HALF_LIGHT_FORMAT),
                unserved_tiles: texture("translucency_gather_unserved_tiles", 8, UNSERVED_TILES_FORMAT),
            });
        } else {
            commands.entity(entity).remove::<ViewHalfGatherTextures>();
        }
    }
}

/// Core3d system between the opaque and transparent passes: adds the patches' light to the
/// view, timed as `translucency/gather` — as compute where the view's main images take
/// storage writes (and its pipeline has compiled), else as a fullscreen fragment pass.
pub fn translucency_gather_pass(
    view: ViewQuery<(
        &ViewTarget,
        &ViewPrepassTextures,
        &ViewUniformOffset,
        &ViewGatherPipeline,
        Option<&ViewHalfGatherTextures>,
    )>,
    gpu: Res<TranslucencyGpu>,
    frame: Res<TranslucencyFrame>,
    pipeline: Res<GatherPipeline>,
    pipeline_cache: Res<PipelineCache>,
    view_uniforms: Res<ViewUniforms>,
    mut ctx: RenderContext,
) {
    let (target, prepass, view_offset, gather, half_texture) = view.into_inner();
    let (Some(transport), Some((patches, grid, params)), Some(no_maps)) =
        (&gpu.transport, &gpu.gather, &gpu.no_translucent_maps)
    else {
        return;
    };
    let (maps, depths) = gpu
        .injection
        .as_ref()
        .filter(|_| gpu.maps_current)
        .map_or((&no_maps.0, &no_maps.1), GpuInjection::translucent_maps);
    // Nothing lit yet.
    if gpu.direct_generation == 0 && gpu.lights_generation == 0 {
        return;
    }
    let (Some(view_binding), Some(depth), Some(normal)) = (
        view_uniforms.uniforms.binding(),
        prepass.depth_view(),
        prepass.normal_view(),
    ) else {
        return;
    };
    let device = ctx.render_device().clone();
    let (vectors, _) = transport.exitance();
    // The seven inputs every form of the gather reads (bindings 0 – 6); each form's bind
    // group adds its own images at the bindings its layout gives them.
    let inputs = [
        view_binding,
        depth.into_binding(),
        normal.into_binding(),
        params.as_entire_binding(),
        patches.as_entire_binding(),
        vectors.as_entire_binding(),
        grid.as_entire_binding(),
    ];
    let bind_group = |label, layout: &BindGroupLayoutDescriptor, own: &[(u32, &TextureView)]| {
        let entries: Vec<BindGroupEntry> = (0u32..)
            .zip(inputs.iter().cloned())
            .chain([(13, maps.as_entire_binding()), (14, depths.as_entire_binding())])
            .chain(own.iter().map(|&(binding, view)| (binding, view.into_binding())))
            .map(|(binding, resource)| BindGroupEntry { binding, resource })
            .collect();
        device.create_bind_group(label, &pipeline_cache.get_bind_group_layout(layout), &entries)
    };
    let method = frame.settings.gather as usize;
    // At half resolution: the samples, every pixel from them, then the pixels they do not
    // serve, in one timed span.
    if crate::render::composites_in_compute(target)
        && let Some(ViewHalfGatherTextures { half_light, unserved_tiles }) = half_texture
        && let (Some(half), Some(upsample), Some(unserved)) = (
            pipeline_cache.get_compute_pipeline(pipeline.half[method]),
            pipeline_cache.get_compute_pipeline(pipeline.upsample[method]),
            pipeline_cache.get_compute_pipeline(pipeline.unserved[method]),
        )
    {
        let post = target.post_process_write();
        let (samples, flags) = (&half_light.default_view, &unserved_tiles.default_view);
        let half_group = bind_group(
            "translucency_gather_half_bind_group",
            &pipeline.half_layout,
            &[(9, samples)],
        );
        // The tiles' flags written at binding 11, read at 12.
        let upsample_group = bind_group(
            "translucency_gather_upsample_bind_group",
            &pipeline.upsample_layout,
            &[(7, post.source), (8, post.destination), (10, samples), (11, flags)],
        );
        let unserved_group = bind_group(
            "translucency_gather_unserved_bind_group",
            &pipeline.unserved_layout,
            &[(7, post.source), (8, post.destination), (10, samples), (12, flags)],
        );
        let size = target.main_texture().size();
        let (width, height) = (size.width, size.height);
        let diagnostics = ctx.diagnostic_recorder();
        let diagnostics = diagnostics.as_deref();
        let span = diagnostics.time_span(ctx.command_encoder(), "translucency/gather");
        let encoder = ctx.command_encoder();
        encoder.push_debug_group("translucency/gather");
        // Each stage its own compute pass and time span (`half`, `upsample`, `unserved`).
        let half_size = (width.div_ceil(2).div_ceil(8), height.div_ceil(2).div_ceil(8));
        let full_size = (width.div_ceil(8), height.div_ceil(8));
        for (name, label, stage, group, (x, y)) in [
            ("half", "translucency_gather_half", half, &half_group, half_size),
            ("upsample", "translucency_gather_upsample", upsample, &upsample_group, full_size),
            ("unserved", "translucency_gather_unserved", unserved, &unserved_group, full_size),
        ] {
            let stage_span = diagnostics.time_span(encoder, name);
            {
                let mut pass = encoder.begin_compute_pass(&ComputePassDescriptor {
                    label: Some(label),
                    timestamp_writes: None,
                });
                pass.set_pipeline(stage);
                pass.set_bind_group(0, group, &[view_offset.offset]);
                pass.dispatch_workgroups(x, y, 1);
            }
            stage_span.end(encoder);
        }
        encoder.pop_debug_group();
        span.end(ctx.command_encoder());
        return;
    }
    if crate::render::composites_in_compute(target)
        && let Some(compute) = pipeline_cache.get_compute_pipeline(pipeline.compute[method])
    {
        // Bevy's post-process ping-pong: read the lit image, write lit + gathered into the
        // other main image, which becomes the view's main image.
        let post = target.post_process_write();
        let bind_group = bind_group(
            "translucency_gather_compute_bind_group",
            &pipeline.compute_layout,
            &[(7, post.source), (8, post.destination)],
        );
        let size = target.main_texture().size();
        crate::render::dispatch_per_pixel(
            &mut ctx,
            "translucency/gather",
            compute,
            &bind_group,
            &[view_offset.offset],
            UVec2::new(size.width, size.height),
            |_| {},
        );
        return;
    }
    let Some(render_pipeline) = pipeline_cache.get_render_pipeline(gather.0) else {
        return;
    };
    let bind_group = bind_group("translucency_gather_bind_group", &pipeline.layout, &[]);
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    ctx.command_encoder()
        .push_debug_group("translucency/gather");
    {
        let mut pass = ctx.begin_tracked_render_pass(RenderPassDescriptor {
            label: Some("translucency_gather_pass"),
            color_attachments: &[Some(target.get_color_attachment())],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        let span = diagnostics.pass_span(&mut pass, "translucency/gather");
        pass.set_render_pipeline(render_pipeline);
        pass.set_bind_group(0, &bind_group, &[view_offset.offset]);
        pass.draw(0..3, 0..1);
        span.end(&mut pass);
    }
    ctx.command_encoder().pop_debug_group();
}
