//! Lighting pass: Bevy's deferred lighting for the pixels of mesostructure materials, with the
//! mesostructure ambient occlusion applied to ambient and environment light and the
//! micro-shadows to each light's direct light (paper eq. 2).
//!
//! Mesostructure materials get their own deferred lighting pass id
//! ([`MESOSTRUCTURE_LIGHTING_PASS_ID`], see [`crate::material`]), so Bevy's lighting pass skips
//! their pixels and this one lights exactly those. The pipeline is Bevy's own deferred lighting
//! pipeline for the view (same shader defs: shadows, SSAO, environment maps, tonemapping) with
//! our shader and our group 2. Where the view's main image takes storage writes it runs in its
//! [`compute`] form instead, after Bevy's deferred lighting.

pub mod compute;

use bevy::{
    core_pipeline::{
        deferred::copy_lighting_id::DeferredLightingIdDepthTexture, prepass::ViewPrepassTextures,
    },
    pbr::{MeshViewBindGroup, ViewKeyCache, deferred::DeferredLightingLayout},
    platform::collections::HashMap,
    prelude::*,
    render::{
        diagnostic::RecordDiagnostics,
        render_phase::ViewSortedRenderPhases,
        render_resource::{binding_types::*, *},
        renderer::{RenderContext, RenderDevice, RenderQueue, ViewQuery},
        texture::{CachedTexture, TextureCache},
        view::{ExtractedView, ViewTarget},
    },
    shader::ShaderDefVal,
};

use super::{
    STORAGE_IMAGE,
    height::{HeightPhaseItem, ViewHeightTextures},
    occlusion::{ViewOcclusionBindGroup, ViewOcclusionTextures},
    view_has_mesostructure, view_texture, working_size,
};
use crate::render::view_settings::ExtractedMesostructure;

/// Micro-shadow visibility, the lowest over the lights (1 = lit), for the debug view and
/// captures; and the first directional light's shadow-map visibility (1: no shadow map),
/// which the bleeding pass needs for that light's texture-space bounce.
pub const MICRO_SHADOW_FORMAT: TextureFormat = TextureFormat::Rg32Float;

/// The lighting pass's micro-shadow image of one view.
#[derive(Component)]
pub struct ViewMicroShadowTexture(pub CachedTexture);

/// Creates each view's micro-shadow image (render `PrepareResources`).
pub fn prepare_micro_shadow_texture(
    mut commands: Commands,
    mut texture_cache: ResMut<TextureCache>,
    device: Res<RenderDevice>,
    views: Query<(Entity, &bevy::render::camera::ExtractedCamera), With<ExtractedMesostructure>>,
) {
    for (entity, camera) in &views {
        let Some(size) = working_size(camera) else {
            commands.entity(entity).remove::<ViewMicroShadowTexture>();
            continue;
        };
        let texture = view_texture(
            &mut texture_cache,
            &device,
            "mesostructure_micro_shadow",
            MICRO_SHADOW_FORMAT,
            STORAGE_IMAGE,
            size,
        );
        commands.entity(entity).insert(ViewMicroShadowTexture(texture));
    }
}

/// Embeds the pass's shaders (their asset paths follow this folder).
pub(super) fn embed_shaders(app: &mut App) {
    bevy::asset::embedded_asset!(app, "lighting.wgsl");
}

/// The deferred lighting pass id of mesostructure materials (Bevy's own is 1; 0 = no geometry).
pub const MESOSTRUCTURE_LIGHTING_PASS_ID: u8 = 2;

/// Our group 2, the shader, 1×1 stand-ins for frames without the plugin's images ("open"
/// occlusion and sector records, "no mesostructure here", a micro-shadow image to write to), and
/// the pipelines made so far, by view key.
#[derive(Resource)]
pub struct LightingPipeline {
    /// Group 2: occlusion, MHM, core normals, sector records, settings, bump normals,
    /// micro-shadow visibility (written).
    pub layout: BindGroupLayoutDescriptor,
    shader: Handle<Shader>,
    open: TextureView,
    open_horizons: TextureView,
    empty: TextureView,
    no_micro_shadow: TextureView,
    /// The compute form's layouts and pipelines.
    pub compute: compute::ComputeLighting,
    pipelines: HashMap<bevy::pbr::MeshPipelineKey, ViewLightingPipeline>,
}

/// Creates the lighting pipeline resource (render startup).
pub fn init_lighting_pipeline(
    mut commands: Commands,
    asset_server: Res<AssetServer>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
) {
    let entries = BindGroupLayoutEntries::sequential(
        ShaderStages::FRAGMENT,
        (
            texture_2d(TextureSampleType::Float { filterable: false }),
            texture_2d(TextureSampleType::Float { filterable: false }),
            texture_2d(TextureSampleType::Float { filterable: false }),
            texture_2d(TextureSampleType::Uint),
            uniform_buffer::<crate::render::view_settings::MesostructureUniform>(true),
            texture_2d(TextureSampleType::Float { filterable: false }),
            texture_storage_2d(MICRO_SHADOW_FORMAT, StorageTextureAccess::WriteOnly),
            texture_2d(TextureSampleType::Float { filterable: false }),
        ),
    );
    let compute = compute::ComputeLighting::new(&device, &entries);
    let layout = BindGroupLayoutDescriptor::new("mesostructure_lighting_layout", &entries);
    let texel = |label, format, usage, data: &[u8]| {
        super::one_texel(&device, &queue, label, format, usage, data)
    };
    // For frames without a height pass: "no mesostructure here" (an MHM texel with object id
    // 0; all zeros also reads as no bump normal) and "open" occlusion.
    let sampled = TextureUsages::TEXTURE_BINDING;
    let empty = texel("mesostructure_empty_mhm", super::height::MHM_FORMAT, sampled, &[0u8; 16]);
    let open = texel(
        "mesostructure_open_occlusion",
        super::occlusion::OCCLUSION_FORMAT,
        sampled,
        &1.0f32.to_le_bytes(),
    );
    // Written where the view has no micro-shadow image of its own (stores outside it are
    // dropped).
    let no_micro_shadow = texel(
        "mesostructure_no_micro_shadow",
        MICRO_SHADOW_FORMAT,
        TextureUsages::STORAGE_BINDING,
        bytemuck::cast_slice(&[1.0f32, 1.0]),
    );
    // Every sector's horizon at 0: no micro-shadow.
    let open_horizons = texel(
        "mesostructure_open_sector_horizons",
        super::occlusion::SECTOR_HORIZONS_FORMAT,
        sampled,
        &[0u8; 16],
    );
    commands.insert_resource(LightingPipeline {
        layout,
        shader: bevy::asset::load_embedded_asset!(asset_server.as_ref(), "lighting.wgsl"),
        open,
        open_horizons,
        empty,
        no_micro_shadow,
        compute,
        pipelines: HashMap::default(),
    });
}

/// The lighting pipelines of a view: the raster form, and the compute form where the view's
/// lighting allows it.
#[derive(Component, Clone)]
pub struct ViewLightingPipeline {
    pub raster: CachedRenderPipelineId,
    pub compute: Option<compute::ComputeLightingPipeline>,
}

/// Specializes Bevy's deferred lighting pipeline for each view and swaps in our shader and
/// group 2.
pub fn prepare_lighting_pipelines(
    mut commands: Commands,
    pipeline_cache: Res<PipelineCache>,
    view_key_cache: Res<ViewKeyCache>,
    deferred: Option<Res<DeferredLightingLayout>>,
    mut lighting: ResMut<LightingPipeline>,
    views: Query<(Entity, &ExtractedView), With<ExtractedMesostructure>>,
    device: Res<RenderDevice>,
) {
    let Some(deferred) = deferred else {
        return;
    };
    // Vulkan and GLES have it; elsewhere the shader runs on every pixel (correct, slower).
    let early_depth_test = device
        .features()
        .contains(WgpuFeatures::SHADER_EARLY_DEPTH_TEST);
    let LightingPipeline {
        layout,
        shader,
        compute,
        pipelines,
        ..
    } = lighting.as_mut();
    for (entity, view) in &views {
        let Some(&key) = view_key_cache.get(&view.retained_view_entity) else {
            continue;
        };
        let view_pipelines = pipelines.entry(key).or_insert_with(|| {
            let mut descriptor = deferred.specialize(key);
            descriptor.label = Some("mesostructure_lighting_pipeline".into());
            descriptor.layout[2] = layout.clone();
            let id_def = ShaderDefVal::UInt(
                "MESOSTRUCTURE_LIGHTING_PASS_ID".into(),
                MESOSTRUCTURE_LIGHTING_PASS_ID as u32,
            );
            descriptor.vertex.shader = shader.clone();
            descriptor.vertex.shader_defs.push(id_def.clone());
            if let Some(fragment) = descriptor.fragment.as_mut() {
                fragment.shader = shader.clone();
                fragment.shader_defs.push(id_def);
                // The fragment stage stores the micro-shadow visibility, and a storage write
                // turns implicit early depth testing off: without `@early_depth_test(force)`
                // every pixel of the screen runs the whole shader before the id-depth test
                // rejects the foreign ones (issue 11: 1.6 ms of a 1080p frame on an H100).
                if early_depth_test {
                    fragment.shader_defs.push("EARLY_DEPTH_TEST".into());
                }
            }
            ViewLightingPipeline {
                compute: compute.pipeline(&pipeline_cache, &descriptor),
                raster: pipeline_cache.queue_render_pipeline(descriptor),
            }
        });
        commands.entity(entity).insert(view_pipelines.clone());
    }
}

/// What both forms of the pass read of a view: its settings, its passes' images and what says
/// whether those passes ran this frame.
type LightingViewInputs<'a> = (
    &'a ExtractedView,
    &'a ExtractedMesostructure,
    &'a super::ViewMesostructureUniformOffset,
    Option<&'a ViewHeightTextures>,
    Option<(&'a ViewOcclusionTextures, &'a ViewOcclusionBindGroup)>,
    Option<&'a ViewMicroShadowTexture>,
    Option<&'a super::occlusion::ViewOcclusionPipeline>,
);

/// The render-world resources both forms of the pass read.
#[derive(bevy::ecs::system::SystemParam)]
pub struct LightingPassResources<'w> {
    phases: Res<'w, ViewSortedRenderPhases<HeightPhaseItem>>,
    lighting: Res<'w, LightingPipeline>,
    uniforms: Res<'w, super::MesostructureUniforms>,
    pipeline_cache: Res<'w, PipelineCache>,
    gradient: Res<'w, super::gradient::GradientPipeline>,
    apex: Res<'w, super::apex::ApexPipeline>,
    height_compute: Res<'w, super::height::HeightComputePipeline>,
}

/// Group 2's first eight bindings, in order.
type Group2Inputs<'a> = (
    &'a TextureView,
    &'a TextureView,
    &'a TextureView,
    &'a TextureView,
    BindingResource<'a>,
    &'a TextureView,
    &'a TextureView,
    &'a TextureView,
);

/// Group 2's first eight bindings for a view (both forms): this frame's images of the passes
/// before, or the stand-ins where a pass did not run ("open", "no mesostructure here").
fn group_2_inputs<'a>(
    r: &'a LightingPassResources,
    (extracted_view, settings, _, height, occlusion_outputs, micro_shadow, occlusion_pipeline): LightingViewInputs<'a>,
) -> Option<Group2Inputs<'a>> {
    let lighting = &r.lighting;
    let settings_binding = r.uniforms.0.binding()?;
    // The images are only current when their passes ran this frame; otherwise "open" and
    // "no mesostructure here".
    let height = height.filter(|_| {
        view_has_mesostructure(&r.phases, extracted_view) && settings.0.needs_height_map()
    });
    // The occlusion image is this frame's only once its pass and the passes it reads have
    // compiled (in the background, over the first frames); until then "open", never the
    // zero-initialised image (a dark flash at start-up).
    let compiled = |id| r.pipeline_cache.get_compute_pipeline(id).is_some();
    // (A view without apex sets — too large for the GPU — has no occlusion bind group.)
    let occlusion_ran = occlusion_pipeline.is_some_and(|p| compiled(p.0))
        && compiled(r.gradient.pipeline)
        && (!settings.0.needs_apex_sets() || compiled(r.apex.pipeline));
    let outputs = occlusion_outputs
        .filter(|_| height.is_some() && occlusion_ran)
        .map(|(textures, _)| textures);
    let occlusion = match outputs {
        Some(o) if settings.0.occlusion => &o.occlusion.default_view,
        _ => &lighting.open,
    };
    let sector_horizons = match outputs {
        Some(o) if settings.0.needs_sector_horizons() => &o.sector_horizons.default_view,
        _ => &lighting.open_horizons,
    };
    // The height pass's compute half (texture-space visibility) compiles in the background
    // too: until it has, "visible".
    let height_computed = compiled(r.height_compute.for_settings(&settings.0));
    let (mhm, core_normal, bump_normal, texture_visibility) = match height {
        Some(h) if height_computed => (
            &h.mhm.default_view,
            &h.core_normal.default_view,
            &h.bump_normal.default_view,
            &h.texture_visibility.default_view,
        ),
        _ => (&lighting.empty, &lighting.empty, &lighting.empty, &lighting.open),
    };
    let micro_shadow = micro_shadow.map_or(&lighting.no_micro_shadow, |t| &t.0.default_view);
    Some((
        occlusion,
        mhm,
        core_normal,
        sector_horizons,
        settings_binding,
        bump_normal,
        micro_shadow,
        texture_visibility,
    ))
}

/// Core3d system, before Bevy's deferred lighting (which discards the id-depth texture): the
/// raster form, for views whose lighting does not run as compute this frame; lights the
/// mesostructure pixels, timed as `mesostructure/lighting`.
pub fn lighting_pass(
    view: ViewQuery<
        (
            LightingViewInputs<'static>,
            &MeshViewBindGroup,
            &ViewTarget,
            &DeferredLightingIdDepthTexture,
            &ViewLightingPipeline,
        ),
        Without<compute::ViewComputeLighting>,
    >,
    resources: LightingPassResources,
    mut ctx: RenderContext,
) {
    let (inputs, mesh_view, target, id_depth, pipelines) = view.into_inner();
    let offset = inputs.2.0;
    let (Some(pipeline), Some(group_2_entries)) = (
        resources.pipeline_cache.get_render_pipeline(pipelines.raster),
        group_2_inputs(&resources, inputs),
    ) else {
        return;
    };
    let group_2 = ctx.render_device().create_bind_group(
        "mesostructure_lighting_bind_group",
        &resources.pipeline_cache.get_bind_group_layout(&resources.lighting.layout),
        &BindGroupEntries::sequential(group_2_entries),
    );
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    ctx.command_encoder()
        .push_debug_group("mesostructure/lighting");
    {
        let mut pass = ctx.begin_tracked_render_pass(RenderPassDescriptor {
            label: Some("mesostructure_lighting_pass"),
            color_attachments: &[Some(target.get_color_attachment())],
            depth_stencil_attachment: Some(RenderPassDepthStencilAttachment {
                view: &id_depth.texture.default_view,
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
        let span = diagnostics.pass_span(&mut pass, "mesostructure/lighting");
        pass.set_render_pipeline(pipeline);
        pass.set_bind_group(0, &mesh_view.main, &mesh_view.main_offsets);
        pass.set_bind_group(1, &mesh_view.binding_array, &[]);
        pass.set_bind_group(2, &group_2, &[offset]);
        pass.draw(0..3, 0..1);
        span.end(&mut pass);
    }
    ctx.command_encoder().pop_debug_group();
}

/// Core3d system, after Bevy's deferred lighting (which leaves the pixels of our lighting pass
/// id as it cleared them): the compute form, for the views that have it this frame; writes the
/// lit mesostructure pixels into the view's main image, timed as `mesostructure/lighting`.
pub fn lighting_compute_pass(
    view: ViewQuery<(
        LightingViewInputs<'static>,
        &MeshViewBindGroup,
        &ViewTarget,
        &ViewPrepassTextures,
        &ViewLightingPipeline,
        &compute::ViewComputeLighting,
    )>,
    resources: LightingPassResources,
    mut ctx: RenderContext,
) {
    let (inputs, mesh_view, target, prepass, pipelines, groups) = view.into_inner();
    let offset = inputs.2.0;
    let (Some(pipeline), Some(pass_ids), Some(group_2_entries)) = (
        pipelines
            .compute
            .as_ref()
            .and_then(|c| resources.pipeline_cache.get_compute_pipeline(c.id)),
        prepass.deferred_lighting_pass_id.as_ref(),
        group_2_inputs(&resources, inputs),
    ) else {
        return;
    };
    let (a, b, c, d, e, f, g, h) = group_2_entries;
    let group_2 = ctx.render_device().create_bind_group(
        "mesostructure_lighting_compute_bind_group",
        &resources
            .pipeline_cache
            .get_bind_group_layout(&resources.lighting.compute.layout),
        &BindGroupEntries::sequential((
            a,
            b,
            c,
            d,
            e,
            f,
            g,
            h,
            target.main_texture_view(),
            &pass_ids.texture.default_view,
        )),
    );
    super::dispatch_per_pixel_with(
        &mut ctx,
        "mesostructure/lighting",
        pipeline,
        &[
            (&groups.view, &mesh_view.main_offsets),
            (&groups.empty, &[]),
            (&group_2, &[offset]),
        ],
        {
            let size = pass_ids.texture.texture.size();
            UVec2::new(size.width, size.height)
        },
        |_| {},
    );
}
