//! The compute form of the lighting pass (`light_compute` in `lighting.wgsl`): on GPUs where
//! few units run pixel shaders, a fullscreen fragment pass is the costliest way to light a few
//! pixels (issue 11), so where the view's main image takes storage writes the pass runs as a
//! compute dispatch after Bevy's deferred lighting and writes the pixels of its lighting pass id
//! itself. The raster form stays for every other view.
//!
//! Bevy's mesh view bindings are visible to fragment shaders only, and wgpu matches a bind
//! group to a layout by identity, so the compute form binds the same resources, at Bevy's
//! binding numbers, in a compute-visible copy of the view's own layout (taken from Bevy's
//! deferred lighting pipeline for the view's key, so Bevy's feature flags shape both alike).
//! It runs Bevy's unchanged lighting code: `apply_pbr_lighting`, the clustered light loop and
//! the shadow lookups. Views whose lighting reads what this copy does not bind — environment
//! maps and irradiance volumes (group 1 binding arrays), light textures, PCSS samplers, the
//! atmosphere, tonemapping in the shader, order-independent transparency — keep the raster form.

use bevy::{
    core_pipeline::prepass::ViewPrepassTextures,
    pbr::{
        AreaLightLuts, Bluenoise, ContactShadowsBuffer, DfgLut, FogMeta,
        GlobalClusterableObjectMeta, LightMeta, LightProbesBuffer,
        ScreenSpaceAmbientOcclusionResources, ScreenSpaceReflectionsBuffer, ShadowSamplers,
        ViewClusterBindings, ViewShadowBindings, ViewTransmissionTexture,
    },
    prelude::*,
    render::{
        globals::GlobalsBuffer,
        render_asset::RenderAssets,
        render_resource::*,
        renderer::RenderDevice,
        texture::{FallbackImage, FallbackImageZero, GpuImage},
        view::{ViewTarget, ViewUniforms},
    },
    shader::ShaderDefVal,
};

/// Shader defs of Bevy's deferred lighting under which the view's lighting reads bindings the
/// compute form does not provide (see the module docs); such views keep the raster form.
const RASTER_ONLY_DEFS: [&str; 6] = [
    "ENVIRONMENT_MAP",
    "IRRADIANCE_VOLUME",
    "LIGHT_TEXTURES",
    "PCSS_SAMPLERS_AVAILABLE",
    "ATMOSPHERE",
    "TONEMAP_IN_SHADER",
];

/// The bindings of Bevy's mesh view layout (group 0) that the compute form can provide: view,
/// lights, shadow maps and comparison samplers, clustered lights, globals, light probes, fog,
/// screen-space reflection and contact-shadow settings, SSAO, the prepass images, the
/// transmission image, blue noise and the area-light and DFG tables.
const PROVIDED_BINDINGS: [u32; 26] = [
    0, 1, 2, 3, 5, 6, 8, 9, 10, 11, 12, 13, 15, 16, 17, 20, 21, 22, 23, 24, 25, 34, 35, 36, 37, 38,
];

/// A view's compute lighting pipeline and the compute-visible copy of its view layout.
#[derive(Clone)]
pub struct ComputeLightingPipeline {
    pub id: CachedComputePipelineId,
    view_layout: BindGroupLayoutDescriptor,
}

/// The compute form's layouts.
pub struct ComputeLighting {
    /// Group 1: empty (the raster form's binding arrays, which the compute form never reads).
    empty_layout: BindGroupLayoutDescriptor,
    /// Group 2: the raster form's group 2, plus the main image written and the pass ids.
    pub layout: BindGroupLayoutDescriptor,
    /// Whether the device gives Bevy's clustered lights storage buffers (as on every
    /// compute-capable desktop GPU); otherwise the raster form runs.
    supported: bool,
}

impl ComputeLighting {
    /// `raster_entries`: the raster form's group 2 entries, made visible to compute here.
    pub fn new(device: &RenderDevice, raster_entries: &[BindGroupLayoutEntry]) -> Self {
        use binding_types::*;
        let mut entries: Vec<_> = raster_entries
            .iter()
            .map(|e| BindGroupLayoutEntry {
                visibility: ShaderStages::COMPUTE,
                ..*e
            })
            .collect();
        let next = entries.len() as u32;
        for (binding, builder) in [
            (
                next,
                texture_storage_2d(
                    crate::render::VIEW_TARGET_FORMAT,
                    StorageTextureAccess::WriteOnly,
                ),
            ),
            (next + 1, texture_2d(TextureSampleType::Uint)),
        ] {
            entries.push(builder.build(binding, ShaderStages::COMPUTE));
        }
        Self {
            empty_layout: BindGroupLayoutDescriptor::new("mesostructure_lighting_empty_layout", &[]),
            layout: BindGroupLayoutDescriptor::new("mesostructure_lighting_compute_layout", &entries),
            supported: matches!(
                device.get_supported_read_only_binding_type(3),
                BufferBindingType::Storage { .. }
            ),
        }
    }

    /// Queues the compute pipeline for a view key from the raster form's descriptor for the
    /// same key (Bevy's deferred lighting's, with our shader and group 2); `None` where the
    /// view's lighting needs the raster form.
    pub fn pipeline(
        &self,
        pipeline_cache: &PipelineCache,
        raster: &RenderPipelineDescriptor,
    ) -> Option<ComputeLightingPipeline> {
        if !self.supported {
            return None;
        }
        let fragment = raster.fragment.as_ref()?;
        let defined = |name: &str| {
            fragment.shader_defs.iter().any(|d| match d {
                ShaderDefVal::Bool(n, on) => n == name && *on,
                _ => false,
            })
        };
        if RASTER_ONLY_DEFS.into_iter().any(defined) {
            return None;
        }
        // Bevy's view layout for the key, visible to compute; its vertex-only bindings
        // (visibility ranges) are left out.
        let view_entries: Vec<_> = raster.layout[0]
            .entries
            .iter()
            .filter(|e| e.visibility.contains(ShaderStages::FRAGMENT))
            .map(|e| BindGroupLayoutEntry {
                visibility: ShaderStages::COMPUTE,
                ..*e
            })
            .collect();
        if view_entries.iter().any(|e| !PROVIDED_BINDINGS.contains(&e.binding)) {
            return None;
        }
        let view_layout =
            BindGroupLayoutDescriptor::new("mesostructure_lighting_view_layout", &view_entries);
        let mut shader_defs = fragment.shader_defs.clone();
        shader_defs.retain(|d| !matches!(d, ShaderDefVal::Bool(name, _) if name == "EARLY_DEPTH_TEST"));
        shader_defs.push("COMPUTE_LIGHTING".into());
        let id = pipeline_cache.queue_compute_pipeline(ComputePipelineDescriptor {
            label: Some("mesostructure_lighting_compute_pipeline".into()),
            layout: vec![
                view_layout.clone(),
                self.empty_layout.clone(),
                self.layout.clone(),
            ],
            shader: fragment.shader.clone(),
            shader_defs,
            entry_point: Some("light_compute".into()),
            ..default()
        });
        Some(ComputeLightingPipeline { id, view_layout })
    }
}

/// A view's bind groups 0 and 1 for the compute form; present exactly on the views whose
/// lighting runs as compute this frame (the raster form skips them).
#[derive(Component)]
pub struct ViewComputeLighting {
    pub view: BindGroup,
    pub empty: BindGroup,
}

/// Bevy's resources behind its mesh view bind group, which the compute form binds itself.
#[derive(bevy::ecs::system::SystemParam)]
pub struct MeshViewResources<'w> {
    view_uniforms: Res<'w, ViewUniforms>,
    light_meta: Res<'w, LightMeta>,
    clusterables: Option<Res<'w, GlobalClusterableObjectMeta>>,
    shadow_samplers: Res<'w, ShadowSamplers>,
    globals: Res<'w, GlobalsBuffer>,
    light_probes: Res<'w, LightProbesBuffer>,
    fog: Res<'w, FogMeta>,
    ssr: Option<Res<'w, ScreenSpaceReflectionsBuffer>>,
    contact_shadows: Option<Res<'w, ContactShadowsBuffer>>,
    images: Res<'w, RenderAssets<GpuImage>>,
    fallback: Res<'w, FallbackImage>,
    fallback_zero: Res<'w, FallbackImageZero>,
    blue_noise: Option<Res<'w, Bluenoise>>,
    area_light_luts: Option<Res<'w, AreaLightLuts>>,
    dfg_lut: Option<Res<'w, DfgLut>>,
}

/// What the compute form binds of a view beyond Bevy's global resources.
type ViewResources<'a> = (
    &'a ViewShadowBindings,
    &'a ViewClusterBindings,
    Option<&'a ScreenSpaceAmbientOcclusionResources>,
    Option<&'a ViewPrepassTextures>,
    Option<&'a ViewTransmissionTexture>,
);

/// Creates the compute form's view bind groups (render `PrepareBindGroups`) for the views
/// whose lighting can run as compute this frame — a compute pipeline for their key, compiled,
/// main images that take storage writes, every binding at hand — and removes them elsewhere,
/// so the raster form lights those views.
pub fn prepare_compute_lighting_bind_groups(
    mut commands: Commands,
    device: Res<RenderDevice>,
    pipeline_cache: Res<PipelineCache>,
    lighting: Res<super::LightingPipeline>,
    resources: MeshViewResources,
    views: Query<(
        Entity,
        &super::ViewLightingPipeline,
        &ViewTarget,
        ViewResources,
    )>,
) {
    for (entity, pipeline, target, view) in &views {
        let groups = pipeline
            .compute
            .as_ref()
            .filter(|c| pipeline_cache.get_compute_pipeline(c.id).is_some())
            .filter(|_| crate::render::composites_in_compute(target))
            .and_then(|c| view_bind_groups(&device, &pipeline_cache, &lighting.compute, c, &resources, view));
        match groups {
            Some(groups) => commands.entity(entity).insert(groups),
            None => commands.entity(entity).remove::<ViewComputeLighting>(),
        };
    }
}

/// Group 0 as `prepare_mesh_view_bind_groups` fills Bevy's, for the bindings of the view's
/// layout; `None` where one of them is not at hand.
fn view_bind_groups(
    device: &RenderDevice,
    pipeline_cache: &PipelineCache,
    compute: &ComputeLighting,
    pipeline: &ComputeLightingPipeline,
    r: &MeshViewResources,
    (shadows, clusters, ssao, prepass, transmission): ViewResources,
) -> Option<ViewComputeLighting> {
    let prepass_views = bevy::pbr::get_bindings(prepass);
    let image = |handle: &Handle<Image>| r.images.get(handle);
    // The LUTs as Bevy binds them: the loaded image, else the fallback of its dimension.
    fn lut<'a>(image: Option<&'a GpuImage>, fallback: &'a GpuImage) -> (&'a TextureView, &'a Sampler) {
        let i = image.unwrap_or(fallback);
        (&i.texture_view, &i.sampler)
    }
    let area = lut(
        r.area_light_luts.as_ref().and_then(|l| image(&l.image)),
        &r.fallback.d2_array,
    );
    let dfg = lut(r.dfg_lut.as_ref().and_then(|l| image(&l.texture)), &r.fallback.d2);
    let (transmission_view, transmission_sampler) = transmission.map_or(
        (&r.fallback_zero.texture_view, &r.fallback_zero.sampler),
        |t| (&t.view, &t.sampler),
    );
    let mut entries = Vec::new();
    for entry in &pipeline.view_layout.entries {
        let resource = match entry.binding {
            0 => r.view_uniforms.uniforms.binding(),
            1 => r.light_meta.view_gpu_lights.binding(),
            2 => Some(BindingResource::TextureView(&shadows.point_light_depth_texture_view)),
            3 => Some(BindingResource::Sampler(&r.shadow_samplers.point_light_comparison_sampler)),
            5 => Some(BindingResource::TextureView(&shadows.directional_light_depth_texture_view)),
            6 => Some(BindingResource::Sampler(
                &r.shadow_samplers.directional_light_comparison_sampler,
            )),
            8 => r.clusterables.as_ref().and_then(|c| c.gpu_clustered_lights.binding()),
            9 => clusters.clusterable_object_index_lists_binding(),
            10 => clusters.offsets_and_counts_binding(),
            11 => r.globals.buffer.binding(),
            12 => r.light_probes.binding(),
            13 => r.fog.gpu_fogs.binding(),
            15 => r.ssr.as_ref().and_then(|b| b.binding()),
            16 => r.contact_shadows.as_ref().and_then(|b| b.0.binding()),
            17 => ssao.map(|s| {
                BindingResource::TextureView(&s.screen_space_ambient_occlusion_texture.default_view)
            }),
            i @ 20..=23 => prepass_views[i as usize - 20].as_ref().map(|v| BindingResource::TextureView(v)),
            24 => Some(BindingResource::TextureView(transmission_view)),
            25 => Some(BindingResource::Sampler(transmission_sampler)),
            34 => r
                .blue_noise
                .as_ref()
                .and_then(|b| image(&b.texture))
                .map(|i| BindingResource::TextureView(&i.texture_view)),
            35 => Some(BindingResource::TextureView(area.0)),
            36 => Some(BindingResource::Sampler(area.1)),
            37 => Some(BindingResource::TextureView(dfg.0)),
            38 => Some(BindingResource::Sampler(dfg.1)),
            _ => None,
        }?;
        entries.push(BindGroupEntry {
            binding: entry.binding,
            resource,
        });
    }
    Some(ViewComputeLighting {
        view: device.create_bind_group(
            "mesostructure_lighting_view_bind_group",
            &pipeline_cache.get_bind_group_layout(&pipeline.view_layout),
            &entries,
        ),
        empty: device.create_bind_group(
            "mesostructure_lighting_empty_bind_group",
            &pipeline_cache.get_bind_group_layout(&compute.empty_layout),
            &[],
        ),
    })
}
