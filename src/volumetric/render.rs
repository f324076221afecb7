//! The render side of the volumetric spots: the fragment pipelines (full resolution, the
//! reduced resolutions and their upsample, the slicing planes), specialised per view, and the
//! pass that runs them or the compute form (`compute.rs`).

use bevy::{
    pbr::{MeshViewBindGroup, ViewKeyCache, deferred::DeferredLightingLayout},
    platform::collections::HashMap,
    prelude::*,
    render::{
        diagnostic::RecordDiagnostics,
        render_resource::{binding_types::*, *},
        renderer::{RenderContext, RenderDevice, RenderQueue, ViewQuery},
        view::{ExtractedView, ViewTarget},
    },
};

use super::extract::*;

/// Our group 2 (the volumetric uniform), the shader, and the pipelines made so far, by view
/// key: Bevy's deferred lighting pipeline for the view (its mesh view bindings — lights, shadow
/// maps, prepass depth — and shader defs) with our shader, group 2 and blending.
#[derive(Resource)]
pub struct VolumetricSpotsPipeline {
    /// Group 2: the volumetric uniform.
    pub layout: BindGroupLayoutDescriptor,
    shader: Handle<Shader>,
    pipelines: HashMap<(bevy::pbr::MeshPipelineKey, VolumetricPass), CachedRenderPipelineId>,
    /// Bound as the low-resolution in-scatter where a pass does not read it.
    no_in_scatter: TextureView,
    /// The compute form's layouts and pipelines.
    compute: super::compute::ComputeForm,
}

/// Which of the shader's passes a pipeline runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum VolumetricPass {
    /// Every pixel, blended into the view.
    Full,
    /// One pixel in `factor`², into the low-resolution in-scatter image.
    LowResolution(u32),
    /// The depth-aware upsample of that image, blended into the view.
    Upsample(u32),
    /// Seed 004's sampling planes, blended into the view.
    SlicingPlanes,
}

/// Format of the low-resolution in-scatter image.
pub const IN_SCATTER_FORMAT: TextureFormat = TextureFormat::Rgba16Float;

pub fn init_volumetric_pipeline(
    mut commands: Commands,
    asset_server: Res<AssetServer>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
) {
    let layout = BindGroupLayoutDescriptor::new(
        "volumetric_spots_layout",
        &BindGroupLayoutEntries::sequential(
            // The slicing planes' vertex stage places them from the spots' data.
            ShaderStages::VERTEX_FRAGMENT,
            (
                uniform_buffer::<VolumetricUniform>(true),
                texture_2d(TextureSampleType::Float { filterable: false }),
            ),
        ),
    );
    let no_in_scatter = crate::render::one_texel(
        &device,
        &queue,
        "volumetric_no_in_scatter",
        IN_SCATTER_FORMAT,
        TextureUsages::TEXTURE_BINDING,
        &[0u8; 8],
    );
    commands.insert_resource(VolumetricSpotsPipeline {
        layout,
        shader: bevy::asset::load_embedded_asset!(asset_server.as_ref(), "spots.wgsl"),
        pipelines: HashMap::default(),
        no_in_scatter,
        compute: super::compute::ComputeForm::new(&device),
    });
}

/// The volumetric pipelines of a view: the full-resolution one, or the low-resolution pass and
/// its upsample, or the slicing planes.
#[derive(Component)]
pub struct ViewVolumetricPipeline {
    /// The full-resolution pass in compute, where the device allows it; it runs in place of
    /// `blend` where the view's main images take storage writes.
    pub compute: Option<CachedComputePipelineId>,
    /// Full resolution, the upsample, or the slicing planes.
    pub blend: CachedRenderPipelineId,
    /// Whether `blend` draws the slicing planes (instanced) rather than one triangle.
    pub slicing_planes: bool,
    /// The low-resolution pass, where the view has one.
    pub low_resolution: Option<CachedRenderPipelineId>,
}

/// The low-resolution in-scatter image of a view.
#[derive(Component)]
pub struct ViewInScatterTexture {
    /// The image.
    pub texture: bevy::render::texture::CachedTexture,
}

fn specialize(
    deferred: &DeferredLightingLayout,
    volumetric: &VolumetricSpotsPipeline,
    key: bevy::pbr::MeshPipelineKey,
    pass: VolumetricPass,
) -> RenderPipelineDescriptor {
    let mut descriptor = deferred.specialize(key);
    descriptor.label = Some("volumetric_spots_pipeline".into());
    descriptor.layout[2] = volumetric.layout.clone();
    descriptor.vertex.shader = volumetric.shader.clone();
    descriptor.vertex.entry_point = Some("vertex".into());
    // Every pixel, whatever lies there: no id-depth test.
    descriptor.depth_stencil = None;
    let (entry, factor) = match pass {
        VolumetricPass::Full => ("fragment", None),
        VolumetricPass::LowResolution(f) => ("fragment", Some(f)),
        VolumetricPass::Upsample(f) => ("upsample", Some(f)),
        VolumetricPass::SlicingPlanes => ("plane_fragment", None),
    };
    if pass == VolumetricPass::SlicingPlanes {
        descriptor.vertex.entry_point = Some("plane_vertex".into());
        let defs = [
            "SLICING_PLANES".into(),
            bevy::shader::ShaderDefVal::UInt("PLANES_PER_SPOT".into(), super::MAX_VOLUMETRIC_SAMPLES),
        ];
        descriptor.vertex.shader_defs.extend(defs.clone());
        if let Some(fragment) = descriptor.fragment.as_mut() {
            fragment.shader_defs.extend(defs);
        }
    }
    if let Some(fragment) = descriptor.fragment.as_mut() {
        fragment.shader = volumetric.shader.clone();
        fragment.entry_point = Some(entry.into());
        if let Some(f) = factor {
            fragment
                .shader_defs
                .push(bevy::shader::ShaderDefVal::UInt("RESOLUTION_FACTOR".into(), f));
        }
        if let VolumetricPass::LowResolution(_) = pass {
            fragment.shader_defs.push("LOW_RESOLUTION_PASS".into());
            fragment.targets = vec![Some(ColorTargetState {
                format: IN_SCATTER_FORMAT,
                blend: None,
                write_mask: ColorWrites::ALL,
            })];
        } else {
            for target in fragment.targets.iter_mut().flatten() {
                // In-scatter + what the surface sends × its transmittance (the shader's
                // alpha): one blend, L + T · L_surface.
                target.blend = Some(BlendState {
                    color: BlendComponent {
                        src_factor: BlendFactor::One,
                        dst_factor: BlendFactor::SrcAlpha,
                        operation: BlendOperation::Add,
                    },
                    alpha: BlendComponent {
                        src_factor: BlendFactor::Zero,
                        dst_factor: BlendFactor::One,
                        operation: BlendOperation::Add,
                    },
                });
            }
        }
    }
    descriptor
}

/// The view's pipeline key with one hardware 2×2 PCF tap per shadow lookup, whatever the
/// view's `ShadowFilteringMethod`: the in-scatter integrates visibility along the ray over
/// `samples` points, which smooths a shaft's edge as the filter would, and Bevy's Gaussian
/// filter costs nine taps per sample (measured on the shadowed bench scene at 16 samples:
/// 0.0023 → 0.0025 against the exact shaft, 13.8 → 10.4 ms on llvmpipe).
fn fog_shadow_filtering(key: bevy::pbr::MeshPipelineKey) -> bevy::pbr::MeshPipelineKey {
    use bevy::pbr::MeshPipelineKey;
    (key & !MeshPipelineKey::SHADOW_FILTER_METHOD_RESERVED_BITS)
        | MeshPipelineKey::SHADOW_FILTER_METHOD_HARDWARE_2X2
}

pub fn prepare_volumetric_pipelines(
    mut commands: Commands,
    pipeline_cache: Res<PipelineCache>,
    view_key_cache: Res<ViewKeyCache>,
    deferred: Option<Res<DeferredLightingLayout>>,
    mut volumetric: ResMut<VolumetricSpotsPipeline>,
    mut texture_cache: ResMut<bevy::render::texture::TextureCache>,
    device: Res<RenderDevice>,
    views: Query<(
        Entity,
        &ExtractedView,
        &ExtractedVolumetricMedium,
        &bevy::render::camera::ExtractedCamera,
    )>,
) {
    let Some(deferred) = deferred else {
        return;
    };
    let volumetric = volumetric.as_mut();
    for (entity, view, medium, camera) in &views {
        let Some(&key) = view_key_cache.get(&view.retained_view_entity) else {
            continue;
        };
        let key = fog_shadow_filtering(key);
        let mut pipeline = |pass| {
            if let Some(&id) = volumetric.pipelines.get(&(key, pass)) {
                return id;
            }
            let id =
                pipeline_cache.queue_render_pipeline(specialize(&deferred, volumetric, key, pass));
            volumetric.pipelines.insert((key, pass), id);
            id
        };
        let factor = medium.medium.resolution.factor();
        let size = camera
            .physical_viewport_size
            .unwrap_or_default()
            .max(UVec2::ONE);
        let slicing_planes = medium.medium.method == super::VolumetricMethod::SlicingPlanes;
        if factor == 1 || slicing_planes {
            let blend = pipeline(if slicing_planes {
                VolumetricPass::SlicingPlanes
            } else {
                VolumetricPass::Full
            });
            let shader = volumetric.shader.clone();
            let compute = (!slicing_planes)
                .then(|| volumetric.compute.pipeline(&pipeline_cache, &deferred, shader, key))
                .flatten();
            commands
                .entity(entity)
                .insert(ViewVolumetricPipeline {
                    compute,
                    blend,
                    slicing_planes,
                    low_resolution: None,
                })
                .remove::<ViewInScatterTexture>();
            continue;
        }
        let low_resolution = Some(pipeline(VolumetricPass::LowResolution(factor)));
        let blend = pipeline(VolumetricPass::Upsample(factor));
        let low_size = (size + factor - 1) / factor;
        let texture = texture_cache.get(
            &device,
            TextureDescriptor {
                label: Some("volumetric_in_scatter"),
                size: Extent3d {
                    width: low_size.x,
                    height: low_size.y,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: TextureDimension::D2,
                format: IN_SCATTER_FORMAT,
                usage: TextureUsages::RENDER_ATTACHMENT | TextureUsages::TEXTURE_BINDING,
                view_formats: &[],
            },
        );
        commands.entity(entity).insert((
            ViewVolumetricPipeline {
                compute: None,
                blend,
                slicing_planes: false,
                low_resolution,
            },
            ViewInScatterTexture { texture },
        ));
    }
}

/// Core3d system between the opaque and transparent passes: adds the in-scattered light of
/// every volumetric spot to the view; nothing without spots. At full resolution with equal
/// angles, a compute pass where the view's main images take storage writes (timed as
/// `volumetric/spots_compute`); otherwise, and for the reduced resolutions and the slicing
/// planes, fullscreen fragment passes (timed as `volumetric/spots`).
pub fn volumetric_spots_pass(
    view: ViewQuery<(
        &ViewTarget,
        &MeshViewBindGroup,
        &ViewVolumetricPipeline,
        &ViewVolumetricUniformOffset,
        &bevy::render::camera::ExtractedCamera,
        Option<&ViewInScatterTexture>,
        super::compute::ComputeViewBindings,
    )>,
    spots: Res<ExtractedVolumetricSpots>,
    pipeline: Res<VolumetricSpotsPipeline>,
    pipeline_cache: Res<PipelineCache>,
    uniforms: Res<VolumetricUniforms>,
    lights: super::compute::LightResources,
    mut ctx: RenderContext,
) {
    let (target, mesh_view, pipelines, offset, camera, in_scatter, compute_view) =
        view.into_inner();
    // Nothing to add or dim: no cone in view and a transparent medium.
    if (spots.0.is_empty() || offset.spots == 0) && !offset.dims {
        return;
    }
    // The compute form where it can run this frame; otherwise the fragment passes below.
    if let Some(id) = pipelines.compute
        && pipeline.compute.record(
            &mut ctx,
            &pipeline_cache,
            id,
            &uniforms,
            &lights,
            compute_view,
            offset.offset,
            target,
        )
    {
        return;
    }
    let (Some(blend_pipeline), Some(volumetric)) = (
        pipeline_cache.get_render_pipeline(pipelines.blend),
        uniforms.0.binding(),
    ) else {
        return;
    };
    // At a reduced resolution: the low-resolution pass first, into its own image.
    let low = match (pipelines.low_resolution, in_scatter) {
        (Some(id), Some(image)) => match pipeline_cache.get_render_pipeline(id) {
            Some(p) => Some((p, image)),
            None => return,
        },
        (None, _) => None,
        (Some(_), None) => return,
    };
    let device = ctx.render_device().clone();
    let layout = pipeline_cache.get_bind_group_layout(&pipeline.layout);
    let group = |texture: &TextureView| {
        device.create_bind_group(
            "volumetric_spots_bind_group",
            &layout,
            &BindGroupEntries::sequential((volumetric.clone(), texture)),
        )
    };
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    ctx.command_encoder().push_debug_group("volumetric/spots");
    let span = diagnostics.time_span(ctx.command_encoder(), "volumetric/spots");
    if let Some((low_pipeline, image)) = low {
        let bind_group = group(&pipeline.no_in_scatter);
        let mut pass = ctx.begin_tracked_render_pass(RenderPassDescriptor {
            label: Some("volumetric_spots_low_resolution_pass"),
            color_attachments: &[Some(RenderPassColorAttachment {
                view: &image.texture.default_view,
                depth_slice: None,
                resolve_target: None,
                ops: Operations {
                    load: LoadOp::Clear(Default::default()),
                    store: StoreOp::Store,
                },
            })],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_render_pipeline(low_pipeline);
        pass.set_bind_group(0, &mesh_view.main, &mesh_view.main_offsets);
        pass.set_bind_group(1, &mesh_view.binding_array, &[]);
        pass.set_bind_group(2, &bind_group, &[offset.offset]);
        pass.draw(0..3, 0..1);
    }
    {
        let bind_group = match low {
            Some((_, image)) => group(&image.texture.default_view),
            None => group(&pipeline.no_in_scatter),
        };
        let mut pass = ctx.begin_tracked_render_pass(RenderPassDescriptor {
            label: Some("volumetric_spots_pass"),
            color_attachments: &[Some(target.get_color_attachment())],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        if let Some(viewport) = camera.viewport.as_ref() {
            pass.set_camera_viewport(viewport);
        }
        pass.set_render_pipeline(blend_pipeline);
        pass.set_bind_group(0, &mesh_view.main, &mesh_view.main_offsets);
        pass.set_bind_group(1, &mesh_view.binding_array, &[]);
        pass.set_bind_group(2, &bind_group, &[offset.offset]);
        if pipelines.slicing_planes {
            // Instance 0 dims the surfaces, then each spot's planes (a quad each; the ones a
            // spot does not have collapse in the vertex stage).
            pass.draw(0..6, 0..1 + offset.spots * super::MAX_VOLUMETRIC_SAMPLES);
        } else {
            pass.draw(0..3, 0..1);
        }
    }
    span.end(ctx.command_encoder());
    ctx.command_encoder().pop_debug_group();
}
