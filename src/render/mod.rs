//! The render-world side: per-view working images, the passes and their ordering.
//!
//! Per camera with [`Mesostructure`], each frame, between Bevy's prepass and main pass:
//! [`height`] (raster, custom phase) → [`gradient`] (compute) → [`apex`] (compute) →
//! [`occlusion`] (compute); in the main pass, [`lighting`] before Bevy's deferred lighting and
//! [`bleeding`] between the opaque and transparent passes; the [`debug_view`] pass draws over
//! the output after tonemapping when a debug view is chosen.

pub mod apex;
pub mod bleeding;
pub mod capture;
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

/// MHM: (height·k, NDC depth, object id, dis).
pub const MHM_FORMAT: TextureFormat = TextureFormat::Rgba32Float;
/// Core normal n0 (world space).
pub const CORE_NORMAL_FORMAT: TextureFormat = TextureFormat::Rgba16Float;
/// Shading normal by Blinn bump mapping (world space; 0 where the material has a normal map).
pub const BUMP_NORMAL_FORMAT: TextureFormat = TextureFormat::Rgba16Float;
/// MHGM: (∂h/∂x, ∂h/∂y, h, flags).
pub const MHGM_FORMAT: TextureFormat = TextureFormat::Rgba32Float;
/// Mesostructure ambient occlusion (1 = open).
pub const OCCLUSION_FORMAT: TextureFormat = TextureFormat::R32Float;
/// Sector record per pixel: horizons about N', N' and the apexes that set the horizons
/// (`surface.wgsl`), stored by the occlusion pass for the lighting and bleeding passes.
pub const SECTOR_HORIZONS_FORMAT: TextureFormat = TextureFormat::Rgba32Uint;
/// Micro-shadow visibility, the lowest over the lights (1 = lit).
pub const MICRO_SHADOW_FORMAT: TextureFormat = TextureFormat::R32Float;
/// One-bounce bleeding radiance added to the view (λd · ρ / π · E).
pub const BLEEDING_FORMAT: TextureFormat = TextureFormat::Rgba16Float;

/// The working images of one view.
#[derive(Component)]
pub struct ViewMesostructureTextures {
    /// Screen-space height map.
    pub mhm: CachedTexture,
    /// Core normals.
    pub core_normal: CachedTexture,
    /// Bump-mapped shading normals.
    pub bump_normal: CachedTexture,
    /// Gradient map.
    pub mhgm: CachedTexture,
    /// Ambient occlusion.
    pub occlusion: CachedTexture,
    /// Sector records (written by the occlusion pass).
    pub sector_horizons: CachedTexture,
    /// Micro-shadow visibility (written by the lighting pass).
    pub micro_shadow: CachedTexture,
    /// Bleeding radiance.
    pub bleeding: CachedTexture,
    /// Apex sets, `apex_stride` words per `apex_block`² block of pixels (see `reference::packed`).
    pub apex_sets: Buffer,
    /// Apex-pass counters: mesostructure pixels, pixels that hit the step bound, ascent steps.
    pub apex_stats: Buffer,
    /// Size in pixels (the render target's).
    pub size: UVec2,
    /// Words per apex set in `apex_sets`.
    pub apex_stride: u32,
    /// Side of the pixel block that shares one apex set (the working resolution).
    pub apex_block: u32,
}

/// Bind groups of the compute passes and the debug view of one view.
#[derive(Component)]
pub struct ViewMesostructureBindGroups {
    /// Gradient pass.
    pub gradient: BindGroup,
    /// Apex pass.
    pub apex: BindGroup,
    /// Occlusion pass.
    pub occlusion: BindGroup,
    /// Debug view.
    pub debug_view: BindGroup,
}

/// Offset of this view's [`MesostructureUniform`] in [`MesostructureUniforms`].
#[derive(Component, Clone, Copy)]
pub struct ViewMesostructureUniformOffset(pub u32);

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
        pass.set_bind_group(0, bind_group, dynamic_offsets);
        pass.dispatch_workgroups(size.x.div_ceil(8), size.y.div_ceil(8), 1);
    }
    encoder.pop_debug_group();
    span.end(ctx.command_encoder());
}

/// The plugin's systems in the `Core3d` schedule that other code may order against.
#[derive(bevy::ecs::schedule::SystemSet, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MesostructureSystems {
    /// The lighting pass (in `Core3dSystems::MainPass`, before Bevy's deferred lighting), which
    /// lights the mesostructure pixels in place of Bevy's deferred lighting.
    Lighting,
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
    let captures = capture::MesostructureCaptures::default();
    app.insert_resource(captures.clone());
    let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
        return;
    };
    render_app
        .insert_resource(captures)
        .init_resource::<capture::PendingCaptures>()
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
                capture::extract_capture_requests,
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
                (prepare_view_textures, prepare_view_uniforms)
                    .in_set(RenderSystems::PrepareResources),
                height::prepare_height_material_bind_groups
                    .in_set(RenderSystems::Queue)
                    .before(height::queue_height_phase),
                prepare_view_bind_groups.in_set(RenderSystems::PrepareBindGroups),
                capture::map_captures
                    .after(RenderSystems::Render)
                    .before(RenderSystems::Cleanup),
            ),
        )
        .add_systems(
            Core3d,
            (
                height::height_pass,
                gradient::gradient_pass,
                apex::apex_pass,
                occlusion::occlusion_pass,
                capture::copy_capture,
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
                .before(bevy::pbr::deferred::deferred_lighting)
                .before(main_opaque_pass_3d),
        )
        .add_systems(
            Core3d,
            (
                capture::copy_lighting_capture,
                bleeding::bleeding_pass,
                bleeding::bleeding_composite_pass,
            )
                .chain()
                .in_set(Core3dSystems::MainPass)
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

fn prepare_view_textures(
    mut commands: Commands,
    mut texture_cache: ResMut<TextureCache>,
    device: Res<RenderDevice>,
    views: Query<(
        Entity,
        &ExtractedCamera,
        &ExtractedMesostructure,
        Option<&ViewMesostructureTextures>,
    )>,
    mut warned: ResMut<WarnedOnce>,
) {
    for (entity, camera, settings, previous) in &views {
        let Some(size) = camera.physical_target_size.filter(|s| s.x > 0 && s.y > 0) else {
            commands
                .entity(entity)
                .remove::<ViewMesostructureTextures>();
            continue;
        };
        let apex_stride = crate::reference::packed::stride(settings.0.apex_directions);
        let apex_block = settings.0.working_resolution.block();
        let blocks = (size + apex_block - 1) / apex_block;
        let apex_bytes = blocks.x as u64 * blocks.y as u64 * apex_stride as u64 * 4;
        if apex_bytes > device.limits().max_storage_buffer_binding_size as u64 {
            warned.warn(format!("apex buffer {entity} {size}"), || {
                format!(
                    "camera {entity}: {size} with {} apex directions needs a {apex_bytes}-byte apex \
                     buffer, more than this GPU binds; the effect is off (use fewer directions)",
                    settings.0.apex_directions
                )
            });
            commands
                .entity(entity)
                .remove::<ViewMesostructureTextures>();
            continue;
        }
        let texture = |cache: &mut TextureCache, label, format, usage| {
            cache.get(
                &device,
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
        };
        let attachment = TextureUsages::RENDER_ATTACHMENT
            | TextureUsages::TEXTURE_BINDING
            | TextureUsages::COPY_SRC;
        let mhm = texture(
            &mut texture_cache,
            "mesostructure_mhm",
            MHM_FORMAT,
            attachment,
        );
        let core_normal = texture(
            &mut texture_cache,
            "mesostructure_core_normal",
            CORE_NORMAL_FORMAT,
            attachment,
        );
        let bump_normal = texture(
            &mut texture_cache,
            "mesostructure_bump_normal",
            BUMP_NORMAL_FORMAT,
            attachment,
        );
        let mhgm = texture(
            &mut texture_cache,
            "mesostructure_mhgm",
            MHGM_FORMAT,
            TextureUsages::STORAGE_BINDING
                | TextureUsages::TEXTURE_BINDING
                | TextureUsages::COPY_SRC,
        );
        let occlusion = texture(
            &mut texture_cache,
            "mesostructure_occlusion",
            OCCLUSION_FORMAT,
            TextureUsages::STORAGE_BINDING
                | TextureUsages::TEXTURE_BINDING
                | TextureUsages::COPY_SRC,
        );
        let sector_horizons = texture(
            &mut texture_cache,
            "mesostructure_sector_horizons",
            SECTOR_HORIZONS_FORMAT,
            TextureUsages::STORAGE_BINDING
                | TextureUsages::TEXTURE_BINDING
                | TextureUsages::COPY_SRC,
        );
        let micro_shadow = texture(
            &mut texture_cache,
            "mesostructure_micro_shadow",
            MICRO_SHADOW_FORMAT,
            TextureUsages::STORAGE_BINDING
                | TextureUsages::TEXTURE_BINDING
                | TextureUsages::COPY_SRC,
        );
        let bleeding = texture(
            &mut texture_cache,
            "mesostructure_bleeding",
            BLEEDING_FORMAT,
            TextureUsages::STORAGE_BINDING
                | TextureUsages::TEXTURE_BINDING
                | TextureUsages::COPY_SRC,
        );
        let (apex_sets, apex_stats) = match previous {
            Some(p) if p.apex_sets.size() == apex_bytes => {
                (p.apex_sets.clone(), p.apex_stats.clone())
            }
            _ => (
                device.create_buffer(&BufferDescriptor {
                    label: Some("mesostructure_apex_sets"),
                    size: apex_bytes,
                    usage: BufferUsages::STORAGE | BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                }),
                device.create_buffer(&BufferDescriptor {
                    label: Some("mesostructure_apex_stats"),
                    size: 16,
                    usage: BufferUsages::STORAGE | BufferUsages::COPY_SRC | BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                }),
            ),
        };
        commands.entity(entity).insert(ViewMesostructureTextures {
            mhm,
            core_normal,
            bump_normal,
            mhgm,
            occlusion,
            sector_horizons,
            micro_shadow,
            bleeding,
            apex_sets,
            apex_stats,
            size,
            apex_stride,
            apex_block,
        });
    }
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

fn prepare_view_bind_groups(
    mut commands: Commands,
    device: Res<RenderDevice>,
    pipeline_cache: Res<PipelineCache>,
    uniforms: Res<MesostructureUniforms>,
    gradient: Res<gradient::GradientPipeline>,
    apex: Res<apex::ApexPipeline>,
    debug: Res<debug_view::DebugViewPipeline>,
    occlusion: Res<occlusion::OcclusionPipeline>,
    view_uniforms: Res<bevy::render::view::ViewUniforms>,
    views: Query<(
        Entity,
        &ViewMesostructureTextures,
        &bevy::core_pipeline::prepass::ViewPrepassTextures,
    )>,
) {
    let (Some(settings), Some(view_binding)) =
        (uniforms.0.binding(), view_uniforms.uniforms.binding())
    else {
        return;
    };
    for (entity, t, prepass) in &views {
        let Some(depth) = prepass.depth_view() else {
            continue;
        };
        let gradient = device.create_bind_group(
            "mesostructure_gradient_bind_group",
            &pipeline_cache.get_bind_group_layout(&gradient.layout),
            &BindGroupEntries::sequential((
                &t.mhm.default_view,
                &t.mhgm.default_view,
                settings.clone(),
            )),
        );
        let apex = device.create_bind_group(
            "mesostructure_apex_bind_group",
            &pipeline_cache.get_bind_group_layout(&apex.layout),
            &BindGroupEntries::sequential((
                &t.mhm.default_view,
                &t.mhgm.default_view,
                t.apex_sets.as_entire_binding(),
                t.apex_stats.as_entire_binding(),
                settings.clone(),
            )),
        );
        let occlusion = device.create_bind_group(
            "mesostructure_occlusion_bind_group",
            &pipeline_cache.get_bind_group_layout(&occlusion.layout),
            &BindGroupEntries::sequential((
                &t.mhm.default_view,
                &t.core_normal.default_view,
                t.apex_sets.as_entire_binding(),
                &t.occlusion.default_view,
                settings.clone(),
                view_binding.clone(),
                &t.mhgm.default_view,
                depth,
                &t.bump_normal.default_view,
                &t.sector_horizons.default_view,
            )),
        );
        let debug_view = device.create_bind_group(
            "mesostructure_debug_view_bind_group",
            &pipeline_cache.get_bind_group_layout(&debug.layout),
            &BindGroupEntries::sequential((
                &t.mhm.default_view,
                &t.mhgm.default_view,
                t.apex_sets.as_entire_binding(),
                settings.clone(),
                &t.occlusion.default_view,
                &t.micro_shadow.default_view,
                &t.bleeding.default_view,
            )),
        );
        commands.entity(entity).insert(ViewMesostructureBindGroups {
            gradient,
            apex,
            occlusion,
            debug_view,
        });
    }
}
