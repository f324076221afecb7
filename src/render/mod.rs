//! The render-world side: per-view working images, the passes and their ordering.
//!
//! Per camera with [`Mesostructure`], each frame, between Bevy's prepass and main pass:
//! [`height`] (a raster half in a custom phase, then a compute half) → [`gradient`] (compute) →
//! [`apex`] (compute) →
//! [`occlusion`] (compute); in the main pass, [`lighting`] (compute after Bevy's deferred
//! lighting where the view's main image takes storage writes, else raster before it) and
//! [`bleeding`] (compute; it writes the view's next main image) between the opaque and
//! transparent passes; the [`debug_view`] pass draws over
//! the output after tonemapping when a debug view is chosen.
//!
//! Each pass's folder owns its pipeline, the images it writes (a component per view, e.g.
//! [`height::ViewHeightTextures`], [`occlusion::ViewOcclusionTextures`]), its bind group and its
//! system; this module keeps what they share: the settings uniform, the per-pixel dispatch, the
//! image helper and the order of the passes.

pub mod apex;
pub mod bleeding;
#[cfg(feature = "oracle")]
pub mod capture;

/// The render-world components a capture adds to a view (none without the `oracle` feature).
#[cfg(feature = "oracle")]
pub(crate) type CaptureComponents = capture::ExtractedCapture;
#[cfg(not(feature = "oracle"))]
pub(crate) type CaptureComponents = ();
pub mod debug_view;
pub mod gradient;
pub mod height;
pub mod lighting;
pub mod occlusion;
pub mod view_settings;

use bevy::{
    camera::Camera3d,
    core_pipeline::{
        Core3dSystems,
        core_3d::{main_opaque_pass_3d, main_transparent_pass_3d},
        prepass::DepthPrepass,
        schedule::Core3d,
        tonemapping::tonemapping,
    },
    image::ToExtents,
    pbr::MeshPipelineSystems,
    platform::collections::HashSet,
    prelude::*,
    render::{
        Extract, ExtractSchedule, Render, RenderApp, RenderDebugFlags, RenderStartup,
        RenderSystems,
        camera::ExtractedCamera,
        render_phase::{
            AddRenderCommand, DrawFunctions, SortedRenderPhasePlugin, ViewSortedRenderPhases,
            sort_phase_system,
        },
        render_resource::*,
        renderer::{RenderDevice, RenderQueue},
        sync_world::RenderEntity,
        texture::{CachedTexture, TextureCache},
        view::{Msaa, RetainedViewEntity},
    },
    shader::load_shader_library,
};

use crate::{
    render::view_settings::{ExtractedMesostructure, MesostructureUniform, ViewSettings},
    settings::Mesostructure,
    warn_once::WarnedOnce,
};

/// Size of a view's working images (its render target's); `None` where it has none.
pub(crate) fn working_size(camera: &ExtractedCamera) -> Option<UVec2> {
    camera.physical_target_size.filter(|s| s.x > 0 && s.y > 0)
}

/// One of a view's per-pixel working images (each pass creates its own outputs).
pub(crate) fn view_texture(
    cache: &mut TextureCache,
    device: &RenderDevice,
    label: &'static str,
    format: TextureFormat,
    usage: TextureUsages,
    size: UVec2,
) -> CachedTexture {
    cache.get(
        device,
        TextureDescriptor {
            label: Some(label),
            size: size.to_extents(),
            mip_level_count: 1,
            sample_count: 1,
            dimension: TextureDimension::D2,
            format,
            usage,
            view_formats: &[],
        },
    )
}

/// A 1×1 image holding `data`: what a pass binds where a view has no image of its own (an
/// "open" occlusion, "no mesostructure here", a write-only sink).
pub(crate) fn one_texel(
    device: &RenderDevice,
    queue: &RenderQueue,
    label: &'static str,
    format: TextureFormat,
    usage: TextureUsages,
    data: &[u8],
) -> TextureView {
    device
        .create_texture_with_data(
            queue,
            &TextureDescriptor {
                label: Some(label),
                size: UVec2::ONE.to_extents(),
                mip_level_count: 1,
                sample_count: 1,
                dimension: TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            },
            TextureDataOrder::default(),
            data,
        )
        .create_view(&TextureViewDescriptor::default())
}

/// Usage of an image a compute pass writes and later passes (and captures) read.
pub(crate) const STORAGE_IMAGE: TextureUsages = TextureUsages::STORAGE_BINDING
    .union(TextureUsages::TEXTURE_BINDING)
    .union(TextureUsages::COPY_SRC);

/// Offset of this view's [`MesostructureUniform`] in [`MesostructureUniforms`].
#[derive(Component, Clone, Copy)]
pub struct ViewMesostructureUniformOffset(pub u32);

/// A fullscreen pass whose fragment `entry` of `shader` is added to a view target of `format`
/// (alpha kept): the bleeding composite and the translucency gather.
pub(crate) fn additive_fullscreen_pipeline(
    label: &'static str,
    layout: BindGroupLayoutDescriptor,
    fullscreen: &bevy::core_pipeline::FullscreenShader,
    shader: Handle<Shader>,
    entry: &'static str,
    format: TextureFormat,
) -> RenderPipelineDescriptor {
    RenderPipelineDescriptor {
        label: Some(label.into()),
        layout: vec![layout],
        vertex: fullscreen.to_vertex_state(),
        fragment: Some(FragmentState {
            shader,
            entry_point: Some(entry.into()),
            targets: vec![Some(ColorTargetState {
                format,
                blend: Some(BlendState {
                    color: BlendComponent {
                        src_factor: BlendFactor::One,
                        dst_factor: BlendFactor::One,
                        operation: BlendOperation::Add,
                    },
                    alpha: BlendComponent {
                        src_factor: BlendFactor::Zero,
                        dst_factor: BlendFactor::One,
                        operation: BlendOperation::Add,
                    },
                }),
                write_mask: ColorWrites::ALL,
            })],
            ..default()
        }),
        ..default()
    }
}

/// Whether any mesostructure mesh was queued into the height phase of `view` this frame; the
/// passes do nothing (and cost nothing) for views without one.
pub fn view_has_mesostructure(
    phases: &ViewSortedRenderPhases<height::HeightPhaseItem>,
    view: &bevy::render::view::ExtractedView,
) -> bool {
    phases
        .get(&view.retained_view_entity)
        .is_some_and(|phase| !phase.items.is_empty())
}

/// The format of a view's main image that compute passes write themselves (Bevy's HDR format).
pub(crate) const VIEW_TARGET_FORMAT: TextureFormat = TextureFormat::Rgba16Float;

/// Whether compute passes can write the view's main images themselves (through Bevy's
/// post-process ping-pong) rather than a fullscreen draw blending into them: where the main
/// images are HDR and allow storage writes (the plugins ask for that on their cameras:
/// [`request_storage_main_textures`]). The bleeding gather and the volumetric spots use it.
pub(crate) fn composites_in_compute(target: &bevy::render::view::ViewTarget) -> bool {
    target.main_texture_format() == VIEW_TARGET_FORMAT
        && target.main_texture().usage().contains(TextureUsages::STORAGE_BINDING)
        && target.main_texture_other().usage().contains(TextureUsages::STORAGE_BINDING)
}

/// Main world, for each HDR camera with the component `C` (`Mesostructure`,
/// `VolumetricMedium`): lets its main images be written by compute passes. Once, when the
/// component or `Hdr` is added: a camera whose usages are set afterwards without
/// `STORAGE_BINDING` keeps the fullscreen (raster) passes. Only HDR cameras: an LDR camera's
/// main images take the output's format, often sRGB, which storage writes do not allow (wgpu
/// would reject the textures).
pub(crate) fn request_storage_main_textures<C: Component>(
    mut cameras: Query<
        &mut bevy::camera::CameraMainTextureUsages,
        (
            Or<(Added<C>, Added<bevy::camera::Hdr>)>,
            With<C>,
            With<bevy::camera::Hdr>,
        ),
    >,
) {
    for mut usages in &mut cameras {
        usages.0 |= TextureUsages::STORAGE_BINDING;
    }
}

/// Records one per-pixel compute pass over a view (8×8 workgroups), labelled with a debug
/// group and timed with a GPU span named `label`; `before` records commands ahead of it.
pub(crate) fn dispatch_per_pixel(
    ctx: &mut bevy::render::renderer::RenderContext,
    label: &'static str,
    pipeline: &ComputePipeline,
    bind_group: &BindGroup,
    dynamic_offsets: &[u32],
    size: UVec2,
    before: impl FnOnce(&mut CommandEncoder),
) {
    dispatch_per_pixel_with(ctx, label, pipeline, &[(bind_group, dynamic_offsets)], size, before);
}

/// [`dispatch_per_pixel`] with several bind groups (group i: `bind_groups[i]` and its dynamic
/// offsets).
pub(crate) fn dispatch_per_pixel_with(
    ctx: &mut bevy::render::renderer::RenderContext,
    label: &'static str,
    pipeline: &ComputePipeline,
    bind_groups: &[(&BindGroup, &[u32])],
    size: UVec2,
    before: impl FnOnce(&mut CommandEncoder),
) {
    use bevy::render::diagnostic::RecordDiagnostics;
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    let span = diagnostics.time_span(ctx.command_encoder(), label);
    let encoder = ctx.command_encoder();
    encoder.push_debug_group(label);
    before(encoder);
    {
        let mut pass = encoder.begin_compute_pass(&ComputePassDescriptor {
            label: Some(label),
            timestamp_writes: None,
        });
        pass.set_pipeline(pipeline);
        for (i, (group, offsets)) in bind_groups.iter().enumerate() {
            pass.set_bind_group(i as u32, *group, offsets);
        }
        pass.dispatch_workgroups(size.x.div_ceil(8), size.y.div_ceil(8), 1);
    }
    encoder.pop_debug_group();
    span.end(ctx.command_encoder());
}

/// The plugin's systems in the `Core3d` schedule that other code may order against.
#[derive(bevy::ecs::schedule::SystemSet, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MesostructureSystems {
    /// The lighting pass, which lights the mesostructure pixels in place of Bevy's deferred
    /// lighting (in `Core3dSystems::MainPass`): both of its forms, so a system after this set
    /// sees those pixels lit. The set spans Bevy's `deferred_lighting`; to order against that,
    /// use the two below.
    Lighting,
    /// The lighting pass's raster form (a fullscreen fragment pass, before Bevy's
    /// `deferred_lighting`), for views whose main images take no storage writes.
    RasterLighting,
    /// The lighting pass's compute form (after Bevy's `deferred_lighting`, before its
    /// screen-space reflections and the opaque pass), for views whose main images take storage
    /// writes.
    ComputeLighting,
    /// The colour bleeding's gather and composite (after the opaque pass), which add the
    /// bounced light to the view's surfaces, through Bevy's post-process ping-pong where the
    /// view allows it.
    Bleeding,
    /// The translucency plugin's gather (after the opaque pass and the bleeding), which adds
    /// the patches' light to the view's surfaces.
    TranslucencyGather,
}

/// The settings of all views, one dynamic uniform buffer.
#[derive(Resource, Default)]
pub struct MesostructureUniforms(pub DynamicUniformBuffer<MesostructureUniform>);

pub(crate) fn build(app: &mut App) {
    load_shader_library!(app, "common.wgsl");
    load_shader_library!(app, "surface.wgsl");
    // Each pass's folder embeds its own shaders.
    height::embed_shaders(app);
    gradient::embed_shaders(app);
    apex::embed_shaders(app);
    occlusion::embed_shaders(app);
    lighting::embed_shaders(app);
    bleeding::embed_shaders(app);
    debug_view::embed_shaders(app);

    // The phase plugin adds the batching systems; with our pipeline type as their batch data,
    // items are never merged (each may bind another height map).
    app.add_plugins(SortedRenderPhasePlugin::<
        height::HeightPhaseItem,
        height::HeightPassPipeline,
    >::new(RenderDebugFlags::default()));
    #[cfg(feature = "oracle")]
    capture::build(app);
    let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
        return;
    };
    render_app
        .init_resource::<MesostructureUniforms>()
        .init_resource::<height::HeightMaterialBindGroups>()
        .init_resource::<SpecializedMeshPipelines<height::HeightPassPipeline>>()
        .init_resource::<SpecializedRenderPipelines<debug_view::DebugViewPipeline>>()
        .init_resource::<SpecializedRenderPipelines<bleeding::BleedingPipeline>>()
        .init_resource::<SpecializedComputePipelines<occlusion::OcclusionPipeline>>()
        .init_resource::<DrawFunctions<height::HeightPhaseItem>>()
        .init_resource::<ViewSortedRenderPhases<height::HeightPhaseItem>>()
        .add_render_command::<height::HeightPhaseItem, height::DrawHeight>()
        .add_systems(
            RenderStartup,
            (
                height::init_height_pass_pipeline.after(MeshPipelineSystems),
                height::init_height_compute_pipeline,
                gradient::init_gradient_pipeline,
                apex::init_apex_pipeline,
                occlusion::init_occlusion_pipeline,
                lighting::init_lighting_pipeline,
                bleeding::init_bleeding_pipeline,
                debug_view::init_debug_view_pipeline,
            ),
        )
        .add_systems(
            ExtractSchedule,
            (
                extract_mesostructure_cameras,
                extract_height_phases,
            ),
        )
        .add_systems(
            Render,
            (
                height::queue_height_phase.in_set(RenderSystems::QueueMeshes),
                sort_phase_system::<height::HeightPhaseItem>.in_set(RenderSystems::PhaseSort),
                debug_view::prepare_debug_view_pipelines.in_set(RenderSystems::Prepare),
                lighting::prepare_lighting_pipelines.in_set(RenderSystems::Prepare),
                bleeding::prepare_bleeding_pipelines.in_set(RenderSystems::Prepare),
                occlusion::prepare_occlusion_pipelines.in_set(RenderSystems::Prepare),
                (
                    prepare_view_uniforms,
                    height::prepare_height_textures,
                    gradient::prepare_gradient_map,
                    apex::prepare_apex_sets,
                    occlusion::prepare_occlusion_textures,
                    lighting::prepare_micro_shadow_texture,
                    bleeding::prepare_bleeding_texture,
                )
                    .in_set(RenderSystems::PrepareResources),
                height::prepare_height_material_bind_groups
                    .in_set(RenderSystems::Queue)
                    .before(height::queue_height_phase),
                (
                    gradient::prepare_gradient_bind_group,
                    apex::prepare_apex_bind_group,
                    occlusion::prepare_occlusion_bind_group,
                    debug_view::prepare_debug_view_bind_group,
                    height::prepare_height_bind_group,
                    lighting::compute::prepare_compute_lighting_bind_groups,
                )
                    .in_set(RenderSystems::PrepareBindGroups),
            ),
        )
        .add_systems(
            Core3d,
            (
                height::height_pass,
                height::height_compute_pass,
                gradient::gradient_pass,
                apex::apex_pass,
                occlusion::occlusion_pass,
            )
                .chain()
                .after(Core3dSystems::Prepass)
                .before(Core3dSystems::MainPass)
                .before(main_opaque_pass_3d),
        )
        .add_systems(
            Core3d,
            lighting::lighting_pass
                .in_set(Core3dSystems::MainPass)
                .in_set(MesostructureSystems::Lighting)
                .in_set(MesostructureSystems::RasterLighting)
                .before(bevy::pbr::deferred::deferred_lighting)
                .before(main_opaque_pass_3d),
        )
        .add_systems(
            Core3d,
            lighting::lighting_compute_pass
                .in_set(Core3dSystems::MainPass)
                .in_set(MesostructureSystems::Lighting)
                .in_set(MesostructureSystems::ComputeLighting)
                .after(bevy::pbr::deferred::deferred_lighting)
                // Screen-space reflections reflect the lit image: ours included.
                .before(bevy::pbr::screen_space_reflections)
                .before(main_opaque_pass_3d),
        )
        .add_systems(
            Core3d,
            (bleeding::bleeding_pass, bleeding::bleeding_composite_pass)
                .chain()
                .in_set(Core3dSystems::MainPass)
                .in_set(MesostructureSystems::Bleeding)
                .after(main_opaque_pass_3d)
                .before(main_transparent_pass_3d),
        )
        .add_systems(
            Core3d,
            debug_view::debug_view_pass
                .after(tonemapping)
                .in_set(Core3dSystems::PostProcess),
        );
}

/// Copies each camera's settings into the render world after checking what the effect needs;
/// a camera that cannot have it (MSAA on, zero-sized viewport) loses it with a one-time warning
/// and renders as without the plugin.
pub fn extract_mesostructure_cameras(
    mut commands: Commands,
    cameras: Extract<
        Query<
            (
                RenderEntity,
                Entity,
                &Camera,
                &Mesostructure,
                Option<&Msaa>,
                Has<DepthPrepass>,
                Option<&crate::MesostructureDebugView>,
                Option<&crate::settings::HorizonSearchBaseline>,
            ),
            With<Camera3d>,
        >,
    >,
    mut warned: ResMut<WarnedOnce>,
) {
    for (render_entity, entity, camera, settings, msaa, has_depth_prepass, debug_view, baseline) in
        &cameras
    {
        let Ok(mut target) = commands.get_entity(render_entity) else {
            continue;
        };
        let size = camera.physical_viewport_size();
        let usable = if !camera.is_active {
            false
        } else if msaa.is_some_and(|m| *m != Msaa::Off) {
            warned.warn(format!("msaa {entity}"), || {
                format!(
                    "camera {entity} has Mesostructure but MSAA is on ({:?}); the effect needs \
                     Msaa::Off on the camera and is off until then",
                    msaa.unwrap()
                )
            });
            false
        } else if !has_depth_prepass {
            warned.warn(format!("prepass {entity}"), || {
                format!("camera {entity} has Mesostructure but its DepthPrepass was removed; the effect is off")
            });
            false
        } else if size.is_none_or(|s| s.x == 0 || s.y == 0) {
            warned.warn(format!("size {entity}"), || {
                format!(
                    "camera {entity} has a zero-sized viewport; the mesostructure effect skips it"
                )
            });
            false
        } else {
            true
        };
        if !usable {
            target
                .remove::<<Mesostructure as bevy::render::sync_component::SyncComponent>::Target>();
            continue;
        }
        warned.forget(&format!("msaa {entity}"));
        warned.forget(&format!("size {entity}"));
        let (sanitized, changed) =
            ViewSettings::resolve(settings, debug_view.copied().unwrap_or_default(), baseline.copied());
        if !changed.is_empty() {
            warned.warn(format!("settings {entity} {changed:?}"), || {
                format!(
                    "camera {entity}: Mesostructure fields {changed:?} were out of range or not \
                     finite; clamped or reset to their defaults"
                )
            });
        }
        target.insert(ExtractedMesostructure(sanitized));
    }
}

/// Per-view phases for cameras with the effect.
pub fn extract_height_phases(
    mut phases: ResMut<ViewSortedRenderPhases<height::HeightPhaseItem>>,
    cameras: Extract<Query<(Entity, &Camera), (With<Camera3d>, With<Mesostructure>)>>,
    mut live: Local<HashSet<RetainedViewEntity>>,
) {
    live.clear();
    for (entity, camera) in &cameras {
        if !camera.is_active {
            continue;
        }
        let retained = RetainedViewEntity::new(entity.into(), None, 0);
        phases.prepare_for_new_frame(retained);
        live.insert(retained);
    }
    phases.retain(|view, _| live.contains(view));
}

fn prepare_view_uniforms(
    mut commands: Commands,
    mut uniforms: ResMut<MesostructureUniforms>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    views: Query<(Entity, &ExtractedMesostructure)>,
) {
    let Some(mut writer) = uniforms.0.get_writer(views.iter().len(), &device, &queue) else {
        return;
    };
    for (entity, settings) in &views {
        let offset = writer.write(&MesostructureUniform::from(&settings.0));
        commands
            .entity(entity)
            .insert(ViewMesostructureUniformOffset(offset));
    }
}
