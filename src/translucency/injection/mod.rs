//! Seed 001's light injection on the GPU (`inject.wgsl`, beside this file): each light's view
//! of the scene as a depth map splatted from the patches' surface samples in compute, then
//! each patch's direct irradiance `E⁰` and single-scattering exitance `S⁰` written straight
//! into the iteration's vectors, so a moving light costs the CPU nothing.
//!
//! The seed counts each patch's pixels in a light-view raster of patch ids; here the light's
//! view is a depth map and each patch takes the share of 3×3 texels about its centre that
//! the light reaches — the same idea (the share of the light the patch's neighbourhood
//! receives) with no raster pipeline and no per-patch atomics. Its oracle is
//! [`direct_light`](super::lights::direct_light), one shadow ray per patch through the
//! precompute's BVH: the same fall-off, range window and incidence weights (the latter from
//! [`IncidenceWeight`] itself, tabulated), visibility to within a texel at shadow edges
//! (`translucency::the_gpu_light_injection_matches_the_shadow_rays`).

use bevy::{
    ecs::system::ResMut,
    math::Vec3,
    render::{
        diagnostic::{DiagnosticsRecorder, RecordDiagnostics},
        render_resource::{
            BindGroup, BindGroupEntries, BindGroupLayout, Buffer, BufferDescriptor,
            BufferInitDescriptor, BufferUsages, CommandEncoder, ComputePassDescriptor,
            ComputePipeline, PipelineLayoutDescriptor, ShaderModuleDescriptor, ShaderSource,
        },
        renderer::{RenderContext, RenderDevice, RenderQueue, ViewQuery},
    },
};
use bytemuck::{Pod, Zeroable};

use super::{
    diffusion::{IncidenceWeight, diffuse_single_scattering_shape, single_scattering_shape},
    translucent_shadow_map::{MapFit, MapFrame, MarchedMedium, PLUGIN_RESOLUTION, object_bounds},
    gather::{TranslucencyCamera, TranslucencyGpu},
    iteration::{GpuTransport, compute_pipeline, packed_buffers_layout, specialized_compute_pipeline},
    patches::Patches,
    transport::{EnergyTransport, PatchLight},
};

const WORKGROUP: u32 = 64;

/// The most lights one injection takes (`MAX_LIGHTS` in `inject.wgsl`); a scene with more is
/// injected on the CPU.
pub const MAX_INJECTED_LIGHTS: usize = 8;

/// Entries of each object's incidence table over cosines 0 – 1: `IncidenceWeight` and the
/// single-scattering shape vary smoothly there except the shape's `μ ln μ` at grazing
/// incidence, where the irradiance is nearly zero anyway.
pub const INCIDENCE_TABLE_SIZE: u32 = 128;

/// Light-view map resolutions (per face) the injection accepts.
pub const LIGHT_VIEW_RESOLUTIONS: std::ops::RangeInclusive<u32> = 32..=2048;

/// `InjectedLight` in `inject.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable, Debug, Default)]
struct InjectedLight {
    position: [f32; 3],
    kind: u32,
    direction: [f32; 3],
    range: f32,
    intensity: [f32; 3],
    cos_outer: f32,
    cone_scale: f32,
    /// Spot: the outer angle `acos(cos_outer)`, once here rather than per splatted sample.
    outer: f32,
    pad: [f32; 2],
}

/// `Injection` in `inject.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable, Debug)]
struct Injection {
    lights: [InjectedLight; MAX_INJECTED_LIGHTS],
    ambient: [f32; 3],
    light_count: u32,
    bounds_centre: [f32; 3],
    bounds_radius: f32,
    resolution: u32,
    samples: u32,
    patches: u32,
    table_size: u32,
    samples_at: u32,
    patches_at: u32,
    tables_at: u32,
    direct: u32,
    direct_exitance: u32,
    // The beam table's directions (0 without one) and its vectors (`BeamOffsets`).
    cosines: u32,
    azimuths: u32,
    beam_light: u32,
    tabled: u32,
    beam_irradiance: u32,
    beam_direction: u32,
    lit_face: u32,
}

impl InjectedLight {
    fn new(light: &PatchLight) -> Self {
        match *light {
            PatchLight::Directional {
                direction,
                illuminance,
            } => Self {
                kind: 0,
                direction: direction.to_array(),
                intensity: illuminance.to_array(),
                ..default_light()
            },
            PatchLight::Point {
                position,
                intensity,
                range,
            } => Self {
                kind: 1,
                position: position.to_array(),
                intensity: intensity.to_array(),
                range,
                ..default_light()
            },
            PatchLight::Spot {
                position,
                direction,
                intensity,
                inner_angle,
                outer_angle,
                range,
            } => {
                // Bevy's cone, as `SpotLight::falloff` of the oracle.
                let cos_outer = outer_angle.cos();
                Self {
                    kind: 2,
                    position: position.to_array(),
                    direction: direction.to_array(),
                    intensity: intensity.to_array(),
                    range,
                    cos_outer,
                    cone_scale: 1.0 / (inner_angle.cos() - cos_outer).max(1e-4),
                    outer: cos_outer.clamp(-1.0, 1.0).acos(),
                    ..default_light()
                }
            }
        }
    }
}

fn default_light() -> InjectedLight {
    InjectedLight {
        direction: [0.0, 0.0, -1.0],
        range: 1.0,
        ..Zeroable::zeroed()
    }
}

/// One object's incidence table (`INCIDENCE_TABLE_SIZE` entries at cosines `i/(n−1)`): the
/// weight of a beam at that incidence (1 without one) and the single-scattering shape less
/// its diffuse mean, as [`direct_light`](super::lights::direct_light) computes them.
pub fn incidence_table(weight: Option<&IncidenceWeight>) -> Vec<[f32; 4]> {
    let diffuse_shape = diffuse_single_scattering_shape() as f32;
    (0..INCIDENCE_TABLE_SIZE)
        .map(|i| {
            let cos = i as f64 / (INCIDENCE_TABLE_SIZE - 1) as f64;
            let w = weight.map_or([1.0; 3], |w| w.at(cos));
            let shape = single_scattering_shape(cos) as f32 - diffuse_shape;
            [w[0] as f32, w[1] as f32, w[2] as f32, shape]
        })
        .collect()
}

/// The translucent objects' maps towards each light (`translucent_maps`,
/// `translucent_depths` in `inject.wgsl`, where their layout is), for single scattering
/// marched per pixel in the gather.
struct TranslucentMaps {
    /// The header, the maps, per object its medium (σt, slot or −1), (α, η), and per slot
    /// the range of the scene's samples that holds its object's (first, count).
    head: Vec<[f32; 4]>,
    /// Per slot (object with maps), its object and the sphere its maps see.
    slots: Vec<(u32, Vec3, f32)>,
    /// Per slot, what its maps are fitted to ([`MapFrame::fitted_to`]).
    fits: Vec<MapFit>,
    /// The most samples a slot's range holds: the splats' workgroups.
    most_slot_samples: u32,
    /// The maps the lights written last have (one a light and slot, six for a cube).
    maps_written: u32,
    /// Of the lights written last and the objects, those that took a cube, and those that
    /// would have past [`MAX_CUBE_MAPS`].
    cubes: (usize, usize),
    /// The buffers' room: vec4s of `maps` and maps of `depths`.
    capacity: (u64, u32),
    maps: Buffer,
    depths: Buffer,
    bind_group: BindGroup,
    layout: BindGroupLayout,
}

/// At most this many lights and objects take a cube of six maps (a light inside an object's
/// bounds, [`MapFrame::frames_towards`]) in one frame; beyond, the map along the line to the
/// object's centre, as before cubes (`docs/translucent.md`: 0.325 against the cube's 0.091 –
/// 0.101 on the torus with a light in its hole). Bounds the maps' memory: 1.5 MB a map at
/// 256², so 8 lights and 8 objects take 96 MB with one map each and 156 MB at most with this.
pub const MAX_CUBE_MAPS: usize = 8;

impl TranslucentMaps {
    fn new(device: &RenderDevice, patches: &Patches, marched: &[Option<MarchedMedium>]) -> Self {
        let objects = marched.len();
        let mut head = vec![[0.0f32; 4]; 2 + 2 * objects];
        let mut slots = Vec::new();
        let mut fits = Vec::new();
        // Each marched object's samples, and the range of the scene's samples that holds them
        // (the patches are grouped by object: the range is theirs alone), in one pass.
        let mut samples = vec![Vec::new(); objects];
        let mut ranges = vec![(u32::MAX, 0u32); objects];
        for (i, patch) in patches.patches.iter().enumerate() {
            if let Some(Some(_)) = marched.get(patch.object as usize) {
                samples[patch.object as usize].extend_from_slice(patches.samples_of(i));
                let range = &mut ranges[patch.object as usize];
                range.0 = range.0.min(patches.sample_offsets[i]);
                range.1 = range.1.max(patches.sample_offsets[i + 1]);
            }
        }
        for (object, medium) in marched.iter().enumerate() {
            let (medium, bounds) = match (medium, object_bounds(&samples[object])) {
                (Some(m), Some(b)) => (m, b),
                _ => {
                    head[2 + 2 * object] = [0.0, 0.0, 0.0, -1.0];
                    continue;
                }
            };
            head[2 + 2 * object] = medium.sigma_t.extend(slots.len() as f32).to_array();
            head[3 + 2 * object] = medium.alpha.extend(medium.eta).to_array();
            slots.push((object as u32, bounds.0, bounds.1));
            fits.push(MapFit::of(&samples[object]));
        }
        head[0] = [objects as f32, slots.len() as f32, PLUGIN_RESOLUTION as f32, 0.0];
        // Sample indices as floats: exact below 2²⁴, and the budget's 200 000 patches have
        // some millions.
        let slot_ranges: Vec<(u32, u32)> =
            slots.iter().map(|&(object, ..)| ranges[object as usize]).map(|(first, end)| (first, end - first)).collect();
        head.extend(slot_ranges.iter().map(|&(first, count)| [first as f32, count as f32, 0.0, 0.0]));
        let most_slot_samples = slot_ranges.iter().map(|r| r.1).max().unwrap_or(0);
        let layout = device.create_bind_group_layout(
            Some("translucency_translucent_maps_layout"),
            &bevy::render::render_resource::BindGroupLayoutEntries::sequential(
                bevy::render::render_resource::ShaderStages::COMPUTE,
                (
                    bevy::render::render_resource::binding_types::storage_buffer_sized(false, None),
                    bevy::render::render_resource::binding_types::storage_buffer_sized(false, None),
                ),
            ),
        );
        let capacity = (head.len() as u64, 0);
        let (maps, depths) = Self::buffers(device, capacity);
        let bind_group = Self::bind_group(device, &layout, &maps, &depths);
        Self { head, slots, fits, most_slot_samples, maps_written: 0, cubes: (0, 0), capacity, maps, depths, bind_group, layout }
    }

    /// The maps' buffers for `vec4s` of `translucent_maps` and `maps` maps' depths.
    fn buffers(device: &RenderDevice, (vec4s, maps): (u64, u32)) -> (Buffer, Buffer) {
        let buffer = |label, size: u64| {
            device.create_buffer(&BufferDescriptor {
                label: Some(label),
                size: size.max(16),
                usage: BufferUsages::STORAGE | BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        let texels = maps as u64 * (PLUGIN_RESOLUTION as u64).pow(2);
        (buffer("translucency_translucent_maps", vec4s * 16), buffer("translucency_translucent_depths", texels * 8))
    }

    fn bind_group(device: &RenderDevice, layout: &BindGroupLayout, maps: &Buffer, depths: &Buffer) -> BindGroup {
        device.create_bind_group(
            Some("translucency_translucent_maps"),
            layout,
            &BindGroupEntries::sequential((maps.as_entire_binding(), depths.as_entire_binding())),
        )
    }

    /// The header, each light's maps of each slot, and their frames for `lights`, the buffers
    /// grown to hold their texels.
    fn write_lights(&mut self, device: &RenderDevice, queue: &RenderQueue, lights: &[PatchLight]) {
        let slots = self.slots.len();
        if slots == 0 {
            return;
        }
        let taken = lights.len().min(MAX_INJECTED_LIGHTS);
        // Each light's maps of each slot: (first map, how many), and every map's frame (light
        // major, as `translucent_light_maps_at` reads them).
        let mut light_maps: Vec<[f32; 4]> = Vec::with_capacity(taken * slots);
        let mut frames: Vec<[f32; 4]> = Vec::new();
        let (mut cubes, mut beyond) = (0, 0);
        for (l, light) in lights[..taken].iter().enumerate() {
            for (&(object, centre, radius), fit) in self.slots.iter().zip(&self.fits) {
                let mut faces = MapFrame::frames_fitted(light, centre, radius, fit);
                if faces.len() > 1 {
                    if cubes == MAX_CUBE_MAPS {
                        faces = MapFrame::towards(light, centre, radius).map(|f| f.fitted_to(fit)).into_iter().collect();
                        beyond += 1;
                    } else {
                        cubes += 1;
                    }
                }
                let first = frames.len() / 4;
                light_maps.push([first as f32, faces.len() as f32, 0.0, 0.0]);
                frames.extend(faces.iter().flat_map(|f| f.to_vec4s(object, l as u32)));
            }
        }
        let maps = (frames.len() / 4) as u32;
        let texels = maps as u64 * (PLUGIN_RESOLUTION as u64).pow(2);
        let vec4s = (self.head.len() + light_maps.len()) as u64 + texels + frames.len() as u64;
        if vec4s > self.capacity.0 || maps > self.capacity.1 {
            self.capacity = (vec4s.max(self.capacity.0), maps.max(self.capacity.1));
            (self.maps, self.depths) = Self::buffers(device, self.capacity);
            self.bind_group = Self::bind_group(device, &self.layout, &self.maps, &self.depths);
        }
        let mut head = self.head.clone();
        head[0][3] = taken as f32;
        head[1][0] = maps as f32;
        head.extend(light_maps);
        queue.write_buffer(&self.maps, 0, bytemuck::cast_slice(&head));
        // The frames after every map's texels (`translucent_frame_at`).
        queue.write_buffer(&self.maps, (head.len() as u64 + texels) * 16, bytemuck::cast_slice(&frames));
        self.maps_written = maps;
        self.cubes = (cubes, beyond);
    }

    /// Bytes of the depths of the maps written last.
    fn depth_bytes(&self) -> u64 {
        self.maps_written as u64 * (PLUGIN_RESOLUTION as u64).pow(2) * 8
    }
}

/// One static scene's light injection on the GPU, writing into a [`GpuTransport`]'s `E⁰`
/// and `S⁰`.
pub struct GpuInjection {
    injection: Injection,
    uniform: Buffer,
    /// Maps for this many lights (grown as lights come; six faces each).
    map_capacity: u32,
    depth_maps: Buffer,
    bind_group: BindGroup,
    bind_group_layout: BindGroupLayout,
    scene: Buffer,
    vectors: Buffer,
    splat: ComputePipeline,
    inject: ComputePipeline,
    translucent_maps: TranslucentMaps,
    splat_entries: ComputePipeline,
    splat_exits: ComputePipeline,
    translucent_light: ComputePipeline,
}

impl GpuInjection {
    /// Uploads the patches (their samples, centres, normals), each patch's single-scattering
    /// factor and each object's incidence table, and builds the pipelines. `albedo` is zero on
    /// translucent patches (these take Bevy's ambient light); `resolution` is each map face's
    /// (clamped to [`LIGHT_VIEW_RESOLUTIONS`]). The objects with a medium in `marched` (by
    /// object; empty: none) get a map a light for their single scattering marched per pixel
    /// ([`PLUGIN_RESOLUTION`]², 1.5 MiB a light and object).
    pub fn new(
        device: &RenderDevice,
        patches: &Patches,
        transport: &EnergyTransport,
        albedo: &[Vec3],
        target: &GpuTransport,
        resolution: u32,
        marched: &[Option<MarchedMedium>],
    ) -> Self {
        let resolution = resolution.clamp(
            *LIGHT_VIEW_RESOLUTIONS.start(),
            *LIGHT_VIEW_RESOLUTIONS.end(),
        );
        let mut scene: Vec<[f32; 4]> = Vec::new();
        let samples_at = scene.len() as u32;
        for (i, p) in patches.patches.iter().enumerate() {
            for s in patches.samples_of(i) {
                let radius = (s.area.max(0.0) / std::f32::consts::PI).sqrt();
                scene.push([s.position.x, s.position.y, s.position.z, radius]);
                // Its object (exact as a float below 2²⁴): its translucent maps.
                scene.push([s.normal.x, s.normal.y, s.normal.z, p.object as f32]);
            }
        }
        let patches_at = scene.len() as u32;
        let mut objects = 0;
        for (i, p) in patches.patches.iter().enumerate() {
            let single = transport
                .single_scattering
                .get(i)
                .copied()
                .unwrap_or(Vec3::ZERO);
            let translucent = albedo.get(i).is_some_and(|a| *a == Vec3::ZERO);
            objects = objects.max(p.object as usize + 1);
            scene.push([
                p.surface_point.x,
                p.surface_point.y,
                p.surface_point.z,
                patches.size_of(i),
            ]);
            // The object as a float (exact below 2²⁴): its bits as a float could be a denormal,
            // which a GPU may flush to zero.
            scene.push([p.normal.x, p.normal.y, p.normal.z, p.object as f32]);
            scene.push([single.x, single.y, single.z, translucent as u32 as f32]);
            // The patch's beam-table slot (−1: none; exact as a float below 2²⁴) and index of
            // refraction.
            let table = transport.beam_table.as_ref();
            let slot = table.and_then(|t| t.slot(i));
            let medium = table.and_then(|t| t.patch_medium(i));
            let eta = medium.map_or(1.0, |m| m.w);
            scene.push([slot.map_or(-1.0, |s| s as f32), eta, 0.0, 0.0]);
            // Its single-scattering albedo: the lit face's single scattering
            // (`lit_face_exitance`).
            let alpha = medium.map_or(Vec3::ZERO, |m| m.truncate());
            scene.push([alpha.x, alpha.y, alpha.z, 0.0]);
        }
        let tables_at = scene.len() as u32;
        for object in 0..objects {
            let weight = transport.incidence.get(object).and_then(Option::as_ref);
            scene.extend(incidence_table(weight));
        }
        scene.push([0.0; 4]);

        // The maps see the patches' bounding sphere (directional lights).
        let (centre, radius) = patches.bounding_sphere();
        let (direct, direct_exitance) = target.direct_offsets();
        let beams = target.beam_offsets();
        let table = transport.beam_table.as_ref().map(|t| t.settings);
        let injection = Injection {
            lights: [default_light(); MAX_INJECTED_LIGHTS],
            ambient: [0.0; 3],
            light_count: 0,
            bounds_centre: centre.to_array(),
            bounds_radius: radius,
            resolution,
            samples: patches.samples.len() as u32,
            patches: patches.patches.len() as u32,
            table_size: INCIDENCE_TABLE_SIZE,
            samples_at,
            patches_at,
            tables_at,
            direct,
            direct_exitance,
            cosines: table.map_or(0, |t| t.cosines),
            azimuths: table.map_or(0, |t| t.azimuths),
            beam_light: beams.light,
            tabled: beams.tabled,
            beam_irradiance: beams.irradiance,
            beam_direction: beams.direction,
            lit_face: beams.lit_face,
        };

        let uniform = device.create_buffer_with_data(&BufferInitDescriptor {
            label: Some("translucency_injection"),
            contents: bytemuck::bytes_of(&injection),
            usage: BufferUsages::UNIFORM | BufferUsages::COPY_DST,
        });
        let scene_buffer = device.create_buffer_with_data(&BufferInitDescriptor {
            label: Some("translucency_injection_scene"),
            contents: bytemuck::cast_slice(&scene),
            usage: BufferUsages::STORAGE,
        });
        let layout = packed_buffers_layout(device, "translucency_injection_layout");
        let (vectors, _) = target.exitance();
        let vectors = vectors.clone();
        let map_capacity = 1;
        let depth_maps = Self::create_maps(device, resolution, map_capacity);
        let bind_group = Self::create_bind_group(
            device,
            &layout,
            &uniform,
            &scene_buffer,
            &depth_maps,
            &vectors,
        );
        let module = device.create_and_validate_shader_module(ShaderModuleDescriptor {
            label: Some("translucency_inject"),
            source: ShaderSource::Wgsl(super::with_boundary(include_str!("inject.wgsl")).into()),
        });
        let translucent_maps = TranslucentMaps::new(device, patches, marched);
        let pipeline_layout = device.create_pipeline_layout(&PipelineLayoutDescriptor {
            label: Some("translucency_injection"),
            bind_group_layouts: &[Some(&layout), Some(&translucent_maps.layout)],
            immediate_size: 0,
        });
        let pipeline = |entry| compute_pipeline(device, &pipeline_layout, &module, entry);
        Self {
            injection,
            uniform,
            map_capacity,
            depth_maps,
            bind_group,
            bind_group_layout: layout,
            scene: scene_buffer,
            vectors,
            splat: pipeline("splat"),
            inject: pipeline("inject"),
            translucent_maps,
            splat_entries: specialized_compute_pipeline(device, &pipeline_layout, &module, "splat_translucent_maps", &[("ENTERING", 1.0)]),
            splat_exits: specialized_compute_pipeline(device, &pipeline_layout, &module, "splat_translucent_maps", &[("ENTERING", 0.0)]),
            translucent_light: pipeline("translucent_light"),
        }
    }

    /// The translucent objects' maps and their light, and their depths (`translucent_maps`,
    /// `translucent_depths` in `inject.wgsl`), for the gather's single scattering marched per
    /// pixel.
    pub fn translucent_maps(&self) -> (&Buffer, &Buffer) {
        (&self.translucent_maps.maps, &self.translucent_maps.depths)
    }

    fn create_maps(device: &RenderDevice, resolution: u32, lights: u32) -> Buffer {
        device.create_buffer(&BufferDescriptor {
            label: Some("translucency_light_view_maps"),
            size: Self::map_bytes(resolution, lights),
            usage: BufferUsages::STORAGE | BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    fn create_bind_group(
        device: &RenderDevice,
        layout: &BindGroupLayout,
        uniform: &Buffer,
        scene: &Buffer,
        depth_maps: &Buffer,
        vectors: &Buffer,
    ) -> BindGroup {
        device.create_bind_group(
            Some("translucency_injection"),
            layout,
            &BindGroupEntries::sequential((
                uniform.as_entire_binding(),
                scene.as_entire_binding(),
                depth_maps.as_entire_binding(),
                vectors.as_entire_binding(),
            )),
        )
    }

    /// Bytes of `lights` lights' maps, six faces each.
    fn map_bytes(resolution: u32, lights: u32) -> u64 {
        lights as u64 * 6 * (resolution as u64).pow(2) * 4
    }

    /// Each map face's resolution.
    pub fn resolution(&self) -> u32 {
        self.injection.resolution
    }

    /// Sets the lights (the first [`MAX_INJECTED_LIGHTS`]) and Bevy's ambient irradiance for
    /// the next [`record`](Self::record), growing the maps to hold them (`resolution`² × 24
    /// bytes a light); returns how many lights it took.
    pub fn write_lights(
        &mut self,
        device: &RenderDevice,
        queue: &RenderQueue,
        lights: &[PatchLight],
        ambient: Vec3,
    ) -> usize {
        let taken = lights.len().min(MAX_INJECTED_LIGHTS);
        if taken as u32 > self.map_capacity {
            self.map_capacity = taken as u32;
            self.depth_maps =
                Self::create_maps(device, self.injection.resolution, self.map_capacity);
            self.bind_group = Self::create_bind_group(
                device,
                &self.bind_group_layout,
                &self.uniform,
                &self.scene,
                &self.depth_maps,
                &self.vectors,
            );
        }
        for (slot, light) in self.injection.lights.iter_mut().zip(&lights[..taken]) {
            *slot = InjectedLight::new(light);
        }
        self.injection.light_count = taken as u32;
        self.injection.ambient = ambient.to_array();
        queue.write_buffer(&self.uniform, 0, bytemuck::bytes_of(&self.injection));
        self.translucent_maps.write_lights(device, queue, lights);
        taken
    }

    /// Of the lights written last and the translucent objects that march, the pairs that
    /// took a cube of maps (a light inside the object's bounds), and those past
    /// [`MAX_CUBE_MAPS`] that kept one map.
    pub fn cube_maps(&self) -> (usize, usize) {
        self.translucent_maps.cubes
    }

    /// Records the injection: the maps cleared and splatted, then every patch's `E⁰` and `S⁰`
    /// written into the transport's vectors (record the iteration after it).
    pub fn record(&self, encoder: &mut CommandEncoder) {
        self.record_timed(encoder, &None::<&DiagnosticsRecorder>);
    }

    /// [`record`](Self::record) with a GPU time span for each part, nested in the caller's:
    /// `splat` (the maps cleared and splatted) and `inject` (each patch's `E⁰` and `S⁰`, and
    /// the beam table's beams), each its own compute pass; between them, where translucent
    /// objects march their single scattering per pixel, `translucent_maps` (their maps
    /// cleared, splatted, and their light).
    pub fn record_timed(&self, encoder: &mut CommandEncoder, spans: &impl RecordDiagnostics) {
        let injection = &self.injection;
        if injection.patches == 0 {
            return;
        }
        encoder.push_debug_group("translucency_injection");
        let lights = injection.light_count;
        if lights > 0 {
            let span = spans.time_span(encoder, "splat");
            encoder.clear_buffer(
                &self.depth_maps,
                0,
                Some(Self::map_bytes(injection.resolution, lights)),
            );
            // No samples: the maps stay clear (nothing shadows).
            if injection.samples > 0 {
                let mut pass = encoder.begin_compute_pass(&ComputePassDescriptor {
                    label: Some("translucency_injection_splat"),
                    timestamp_writes: None,
                });
                pass.set_bind_group(0, &self.bind_group, &[]);
                pass.set_bind_group(1, &self.translucent_maps.bind_group, &[]);
                pass.set_pipeline(&self.splat);
                // Eight samples a workgroup (`SPLAT_LANES` in inject.wgsl).
                pass.dispatch_workgroups(injection.samples.div_ceil(WORKGROUP / 8).min(65_535), lights, 1);
            }
            span.end(encoder);
            self.record_translucent_maps(encoder, spans);
        }
        let span = spans.time_span(encoder, "inject");
        {
            let mut pass = encoder.begin_compute_pass(&ComputePassDescriptor {
                label: Some("translucency_injection_inject"),
                timestamp_writes: None,
            });
            pass.set_bind_group(0, &self.bind_group, &[]);
            pass.set_bind_group(1, &self.translucent_maps.bind_group, &[]);
            pass.set_pipeline(&self.inject);
            pass.dispatch_workgroups(injection.patches.div_ceil(WORKGROUP), 1, 1);
        }
        span.end(encoder);
        encoder.pop_debug_group();
    }
}

impl GpuInjection {
    /// The translucent objects' maps written last (one a light and object, six for a cube):
    /// cleared, their entries and then their exits splatted (each its own pass: the exits are
    /// those deeper than the entries; a workgroup per sample of each map's object and a row
    /// per map), then each texel's light,
    /// shadowed by the scene's maps splatted before. Each its own time span (`entries`,
    /// `exits`, `light`) in `translucent_maps`.
    fn record_translucent_maps(&self, encoder: &mut CommandEncoder, spans: &impl RecordDiagnostics) {
        let maps = &self.translucent_maps;
        let count = maps.maps_written;
        if count == 0 || maps.most_slot_samples == 0 {
            return;
        }
        let span = spans.time_span(encoder, "translucent_maps");
        encoder.clear_buffer(&maps.depths, 0, Some(maps.depth_bytes()));
        let texels = PLUGIN_RESOLUTION * PLUGIN_RESOLUTION;
        // A workgroup a sample (`splat_translucent_maps`), a map in y.
        let splats = (maps.most_slot_samples.min(65_535), count);
        for (name, label, pipeline, (x, y)) in [
            ("entries", "translucency_translucent_entries", &self.splat_entries, splats),
            ("exits", "translucency_translucent_exits", &self.splat_exits, splats),
            ("light", "translucency_translucent_light", &self.translucent_light, (texels.div_ceil(WORKGROUP), count)),
        ] {
            let part = spans.time_span(encoder, name);
            {
                let mut pass =
                    encoder.begin_compute_pass(&ComputePassDescriptor { label: Some(label), timestamp_writes: None });
                pass.set_bind_group(0, &self.bind_group, &[]);
                pass.set_bind_group(1, &maps.bind_group, &[]);
                pass.set_pipeline(pipeline);
                pass.dispatch_workgroups(x, y, 1);
            }
            part.end(encoder);
        }
        span.end(encoder);
    }
}

/// Core3d system before the iteration: where the GPU injects the lights
/// ([`LightInjection::LightViewMaps`](crate::translucency::LightInjection)) and they changed, writes each
/// patch's `E⁰` and `S⁰` (the first view of the frame does it), timed as
/// `translucency/injection`. Its own system, so its own command encoder.
pub fn translucency_injection_pass(
    _view: ViewQuery<&TranslucencyCamera>,
    mut gpu: ResMut<TranslucencyGpu>,
    mut ctx: RenderContext,
) {
    if !gpu.injection_pending {
        return;
    }
    let Some(injection) = &gpu.injection else {
        return;
    };
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    let span = diagnostics.time_span(ctx.command_encoder(), "translucency/injection");
    injection.record_timed(ctx.command_encoder(), &diagnostics);
    span.end(ctx.command_encoder());
    gpu.injection_pending = false;
}
