//! The render side of the volumetric spots: extraction with validation, the per-view uniform,
//! the fullscreen pipeline and its pass.

use bevy::{
    camera::Camera3d,
    pbr::{
        GlobalClusterableObjectMeta, MeshViewBindGroup, ViewKeyCache,
        deferred::DeferredLightingLayout,
    },
    platform::collections::HashMap,
    prelude::*,
    render::{
        Extract,
        diagnostic::RecordDiagnostics,
        render_resource::{binding_types::*, *},
        renderer::{RenderContext, RenderDevice, RenderQueue, ViewQuery},
        sync_component::SyncComponent,
        sync_world::RenderEntity,
        view::{ExtractedView, Msaa, ViewTarget},
    },
};

use super::{MAX_VOLUMETRIC_SPOTS, VolumetricMedium, VolumetricSpot};
use crate::warn_once::WarnedOnce;

/// The render world's copy of a camera's medium, sanitized, and the camera's frustum (to cull
/// the spots whose cones it does not see).
#[derive(Component, Clone, Copy, Debug)]
pub struct ExtractedVolumetricMedium {
    /// The medium.
    pub medium: VolumetricMedium,
    /// The camera's view frustum.
    pub frustum: bevy::camera::primitives::Frustum,
    /// The camera's view-projection.
    pub clip_from_world: Mat4,
}

impl SyncComponent for VolumetricMedium {
    type Target = (
        ExtractedVolumetricMedium,
        ViewVolumetricPipeline,
        ViewVolumetricUniformOffset,
    );
}

/// One spot as the shader reads it.
#[derive(Clone, Copy, Debug, Default, ShaderType)]
pub struct GpuVolumetricSpot {
    /// Position, range.
    pub position_range: Vec4,
    /// Unit axis, samples.
    pub direction_samples: Vec4,
    /// Linear colour × intensity (candela) × `intensity_scale`.
    pub color: Vec4,
    /// cos(outer angle), Bevy's spot scale and offset, the light's index in Bevy's clustered
    /// lights where its shadow map is sampled (−1: no shadow map).
    pub cone: Vec4,
    /// The part of the view the cone can cover, in NDC: (min x, min y, max x, max y) — its
    /// bounding sphere's projection; pixels outside skip the spot.
    pub screen_rect: Vec4,
    /// A sphere around the cone out to its range (centre, radius): where the slicing planes
    /// go.
    pub bounds: Vec4,
}

/// One spot of this frame.
#[derive(Clone, Copy, Debug)]
pub struct ExtractedVolumetricSpot {
    /// What the shader reads (its shadow-map index still to be filled in).
    pub gpu: GpuVolumetricSpot,
    /// Its render-world entity.
    pub entity: Entity,
    /// Whether it casts shadows.
    pub shadows: bool,
    /// A sphere bounding its cone out to its range: views whose frustum misses it skip it.
    pub bounds: bevy::camera::primitives::Sphere,
}

/// The spots of this frame.
#[derive(Resource, Default)]
pub struct ExtractedVolumetricSpots(pub Vec<ExtractedVolumetricSpot>);

/// The NDC rectangle (min x, min y, max x, max y) that a sphere can cover in a view with
/// `clip_from_world`: the projections of its bounding box's corners; the whole view where a
/// corner lies behind the camera's plane.
pub fn screen_rect(sphere: &bevy::camera::primitives::Sphere, clip_from_world: Mat4) -> Vec4 {
    let whole = Vec4::new(-1.0, -1.0, 1.0, 1.0);
    let (mut lo, mut hi) = (Vec2::splat(f32::INFINITY), Vec2::splat(f32::NEG_INFINITY));
    let center = Vec3::from(sphere.center);
    for i in 0..8 {
        let corner = center
            + Vec3::new(
                if i & 1 == 0 { -1.0 } else { 1.0 },
                if i & 2 == 0 { -1.0 } else { 1.0 },
                if i & 4 == 0 { -1.0 } else { 1.0 },
            ) * sphere.radius;
        let clip = clip_from_world * corner.extend(1.0);
        if !(clip.w > 1e-6) {
            return whole;
        }
        let ndc = clip.truncate().truncate() / clip.w;
        lo = lo.min(ndc);
        hi = hi.max(ndc);
    }
    Vec4::new(lo.x.max(-1.0), lo.y.max(-1.0), hi.x.min(1.0), hi.y.min(1.0))
}

/// The smallest sphere around a cone of half-angle `angle` and length `length` from `apex`
/// along the unit `axis`: about the far disc's centre for wide cones, else through the apex and
/// the far rim.
pub fn cone_bounds(apex: Vec3, axis: Vec3, angle: f32, length: f32) -> bevy::camera::primitives::Sphere {
    let (center, radius) = if angle > std::f32::consts::FRAC_PI_4 {
        (apex + axis * length * angle.cos(), length * angle.sin())
    } else {
        let r = length / (2.0 * angle.cos() * angle.cos());
        (apex + axis * r, r)
    };
    bevy::camera::primitives::Sphere {
        center: center.into(),
        radius,
    }
}

/// What the shader reads for one view: the medium and the spots.
#[derive(Clone, Copy, ShaderType)]
pub struct VolumetricUniform {
    /// σs, σa, g, number of spots.
    pub medium: Vec4,
    /// The spots (the first `medium.w` are used).
    pub spots: [GpuVolumetricSpot; MAX_VOLUMETRIC_SPOTS],
}

/// The views' uniforms.
#[derive(Resource, Default)]
pub struct VolumetricUniforms(pub DynamicUniformBuffer<VolumetricUniform>);

/// Offset of a view's [`VolumetricUniform`], and how many spots the view sees.
#[derive(Component, Clone, Copy)]
pub struct ViewVolumetricUniformOffset {
    /// Dynamic offset.
    pub offset: u32,
    /// Spots whose cones are in the view's frustum.
    pub spots: u32,
    /// Whether the medium dims what lies behind it (σt > 0): then the pass runs even with no
    /// cone in view, so that surfaces do not brighten when the last spot leaves the view.
    pub dims: bool,
}

fn finite_at_least(v: f32, min: f32, default: f32) -> (f32, bool) {
    if v.is_finite() {
        (v.max(min), v < min)
    } else {
        (default, true)
    }
}

/// Copies each camera's medium after checking it; bad values get one warning and a sane
/// fallback (their defaults or the nearest valid value); MSAA turns the effect off for that
/// camera, with a warning.
pub fn extract_volumetric_cameras(
    mut commands: Commands,
    cameras: Extract<
        Query<
            (
                RenderEntity,
                Entity,
                &Camera,
                &VolumetricMedium,
                Option<&Msaa>,
                &bevy::camera::primitives::Frustum,
                &GlobalTransform,
            ),
            With<Camera3d>,
        >,
    >,
    mut warned: ResMut<WarnedOnce>,
) {
    for (render_entity, entity, camera, medium, msaa, frustum, transform) in &cameras {
        let Ok(mut target) = commands.get_entity(render_entity) else {
            continue;
        };
        let size = camera.physical_viewport_size();
        if !camera.is_active || size.is_none_or(|s| s.x == 0 || s.y == 0) {
            target.remove::<ExtractedVolumetricMedium>();
            continue;
        }
        if msaa.is_some_and(|m| *m != Msaa::Off) {
            warned.warn(format!("volumetric msaa {entity}"), || {
                format!("camera {entity} has VolumetricMedium but MSAA is on; the volumetric spots need Msaa::Off and are off until then")
            });
            target.remove::<ExtractedVolumetricMedium>();
            continue;
        }
        warned.forget(&format!("volumetric msaa {entity}"));
        let d = VolumetricMedium::default();
        let (scattering, bad_s) = finite_at_least(medium.scattering, 0.0, d.scattering);
        let (absorption, bad_a) = finite_at_least(medium.absorption, 0.0, d.absorption);
        let asymmetry = if medium.asymmetry.is_finite() {
            medium.asymmetry.clamp(-0.95, 0.95)
        } else {
            d.asymmetry
        };
        if bad_s || bad_a || asymmetry != medium.asymmetry {
            warned.warn(format!("volumetric medium {entity}"), || {
                format!(
                    "camera {entity}: VolumetricMedium {medium:?} has negative or non-finite \
                     coefficients or |g| > 0.95; using σs {scattering}, σa {absorption}, g {asymmetry}"
                )
            });
        }
        target.insert(ExtractedVolumetricMedium {
            medium: VolumetricMedium {
                scattering,
                absorption,
                asymmetry,
                resolution: medium.resolution,
                method: medium.method,
            },
            frustum: *frustum,
            clip_from_world: camera.clip_from_view() * transform.to_matrix().inverse(),
        });
    }
}

/// Collects the visible spots with [`VolumetricSpot`]; a cone angle of 0 (or NaN) drops the
/// spot, one of 90° or more is narrowed to 89°, other bad values fall back to the defaults —
/// each with one warning.
pub fn extract_volumetric_spots(
    lights: Extract<
        Query<(
            Entity,
            RenderEntity,
            &SpotLight,
            &GlobalTransform,
            &VolumetricSpot,
            Option<&ViewVisibility>,
        )>,
    >,
    mut spots: ResMut<ExtractedVolumetricSpots>,
    mut warned: ResMut<WarnedOnce>,
) {
    spots.0.clear();
    for (entity, render_entity, light, transform, volumetric, visibility) in &lights {
        if visibility.is_some_and(|v| !v.get()) || light.intensity <= 0.0 {
            continue;
        }
        let max_outer = 89f32.to_radians();
        let outer = light.outer_angle;
        if !(outer > 0.0) || !light.intensity.is_finite() || !light.range.is_finite() {
            warned.warn(format!("volumetric spot {entity}"), || {
                format!(
                    "spot light {entity}: outer angle {outer}, intensity {} or range {} cannot \
                     light a medium; its volumetric light is off",
                    light.intensity, light.range
                )
            });
            continue;
        }
        let outer = if outer >= max_outer {
            warned.warn(format!("volumetric spot angle {entity}"), || {
                format!(
                    "spot light {entity}: an outer angle of {:.1}° is not a cone; its \
                     volumetric light uses 89°",
                    outer.to_degrees()
                )
            });
            max_outer
        } else {
            outer
        };
        let inner = if light.inner_angle.is_finite() {
            light.inner_angle.clamp(0.0, outer)
        } else {
            0.0
        };
        let (scale, bad_scale) = finite_at_least(volumetric.intensity_scale, 0.0, 1.0);
        let samples = volumetric.samples.clamp(1, super::MAX_VOLUMETRIC_SAMPLES);
        if bad_scale || samples != volumetric.samples {
            warned.warn(format!("volumetric spot settings {entity}"), || {
                format!(
                    "spot light {entity}: VolumetricSpot {volumetric:?} out of range; using \
                     intensity_scale {scale}, samples {samples}"
                )
            });
        }
        if spots.0.len() == MAX_VOLUMETRIC_SPOTS {
            warned.warn("volumetric spot count", || {
                format!("more than {MAX_VOLUMETRIC_SPOTS} spots have VolumetricSpot; the rest are skipped")
            });
            break;
        }
        // As Bevy lights surfaces (`render/light.rs`): candela = lumens / 4π, and the spot
        // fall-off saturate(cos ψ · scale + offset)².
        let candela = light.intensity / (4.0 * std::f32::consts::PI) * scale;
        let color = light.color.to_linear().to_vec3() * candela;
        let cos_outer = outer.cos();
        let spot_scale = 1.0 / (inner.cos() - cos_outer).max(1e-4);
        let spot = GpuVolumetricSpot {
            position_range: transform.translation().extend(light.range.max(0.0)),
            direction_samples: transform.forward().as_vec3().extend(samples as f32),
            color: color.extend(0.0),
            cone: Vec4::new(cos_outer, spot_scale, -cos_outer * spot_scale, -1.0),
            // Per view, in `prepare_volumetric_uniforms`.
            screen_rect: Vec4::new(-1.0, -1.0, 1.0, 1.0),
            bounds: Vec4::ZERO,
        };
        let axis = transform.forward().as_vec3();
        spots.0.push(ExtractedVolumetricSpot {
            gpu: spot,
            entity: render_entity,
            shadows: light.shadow_maps_enabled,
            bounds: cone_bounds(transform.translation(), axis, outer, light.range.max(0.0)),
        });
    }
}

/// Writes each view's uniform, with each shadowed spot's index in Bevy's clustered lights (known
/// once Bevy has prepared its lights) for its shadow map.
pub fn prepare_volumetric_uniforms(
    mut commands: Commands,
    mut uniforms: ResMut<VolumetricUniforms>,
    spots: Res<ExtractedVolumetricSpots>,
    clusterables: Option<Res<GlobalClusterableObjectMeta>>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    views: Query<(Entity, &ExtractedVolumetricMedium)>,
) {
    let Some(mut writer) = uniforms.0.get_writer(views.iter().len(), &device, &queue) else {
        return;
    };
    for (entity, view) in &views {
        // The spots whose cones this camera sees (a bounding sphere against its frustum).
        let mut gpu_spots = [GpuVolumetricSpot::default(); MAX_VOLUMETRIC_SPOTS];
        let mut count = 0;
        for spot in &spots.0 {
            if !view.frustum.intersects_sphere(&spot.bounds, false) {
                continue;
            }
            let mut gpu = spot.gpu;
            gpu.screen_rect = screen_rect(&spot.bounds, view.clip_from_world);
            gpu.bounds = Vec3::from(spot.bounds.center).extend(spot.bounds.radius);
            if let Some(index) = clusterables
                .as_ref()
                .filter(|_| spot.shadows)
                .and_then(|c| c.entity_to_index.get(&spot.entity))
            {
                gpu.cone.w = *index as f32;
            }
            gpu_spots[count] = gpu;
            count += 1;
        }
        let m = view.medium;
        let offset = writer.write(&VolumetricUniform {
            medium: Vec4::new(m.scattering, m.absorption, m.asymmetry, count as f32),
            spots: gpu_spots,
        });
        commands.entity(entity).insert(ViewVolumetricUniformOffset {
            offset,
            spots: count as u32,
            dims: m.scattering + m.absorption > 0.0,
        });
    }
}

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_screen_rect_holds_the_sphere_and_falls_back_to_the_whole_view() {
        let clip_from_view = Mat4::perspective_infinite_reverse_rh(0.8, 1.5, 0.1);
        let view_from_world =
            Transform::from_xyz(0.0, 1.0, 6.0).looking_at(Vec3::ZERO, Vec3::Y).to_matrix().inverse();
        let clip_from_world = clip_from_view * view_from_world;
        let sphere = bevy::camera::primitives::Sphere {
            center: Vec3::new(0.5, 0.2, 0.0).into(),
            radius: 0.3,
        };
        let rect = screen_rect(&sphere, clip_from_world);
        assert!(rect.x < rect.z && rect.y < rect.w && rect.z - rect.x < 0.5, "{rect}");
        // Points of the sphere's surface project inside the rectangle.
        for i in 0..64 {
            let (a, b) = (i as f32 * 0.7, i as f32 * 1.3);
            let p = Vec3::from(sphere.center)
                + Vec3::new(a.cos() * b.sin(), a.sin() * b.sin(), b.cos()) * sphere.radius;
            let c = clip_from_world * p.extend(1.0);
            let ndc = c.truncate().truncate() / c.w;
            assert!(ndc.x >= rect.x && ndc.x <= rect.z && ndc.y >= rect.y && ndc.y <= rect.w);
        }
        // A sphere around the camera covers the whole view.
        let around = bevy::camera::primitives::Sphere {
            center: Vec3::new(0.0, 1.0, 6.0).into(),
            radius: 1.0,
        };
        assert_eq!(screen_rect(&around, clip_from_world), Vec4::new(-1.0, -1.0, 1.0, 1.0));
    }

    #[test]
    fn the_cone_bounds_hold_every_point_of_the_cone() {
        for angle_deg in [1.0f32, 20.0, 44.0, 46.0, 70.0, 89.0] {
            let angle = angle_deg.to_radians();
            let (apex, axis, length) = (Vec3::new(1.0, 2.0, 3.0), Vec3::new(0.0, -0.6, 0.8), 5.0);
            let bounds = cone_bounds(apex, axis, angle, length);
            let side = axis.any_orthonormal_vector();
            let other = axis.cross(side);
            for i in 0..=20 {
                for j in 0..16 {
                    // Points of the cone's surface (within the range sphere) and of its axis.
                    let t = length * i as f32 / 20.0;
                    let phi = j as f32 * std::f32::consts::TAU / 16.0;
                    let dir = (axis * angle.cos()
                        + (side * phi.cos() + other * phi.sin()) * angle.sin())
                    .normalize();
                    for p in [apex + dir * t, apex + axis * t] {
                        let d = (p - Vec3::from(bounds.center)).length();
                        assert!(d <= bounds.radius * 1.0001 + 1e-5, "{angle_deg}°: {d} > {}", bounds.radius);
                    }
                }
            }
        }
    }
}
