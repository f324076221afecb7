//! The per-frame transport on the GPU: [`EnergyTransport`]'s matrices uploaded once, the
//! iteration recorded into a command encoder each frame (`iterate.wgsl`, beside this file).
//!
//! All of `K`, `F` and the cluster means live in one `u32` storage buffer (values as bit
//! patterns) and all vectors in one `vec4<f32>` buffer, so the pass needs four storage
//! buffers whatever the device's per-stage limit. The loop is recorded `max_iterations` times
//! with indirect dispatches whose group counts the GPU zeroes once the energy still moving is
//! below the threshold: the CPU never waits for the GPU to know when to stop. (The plugin
//! records a warm solve's loop one product more often than the last solve took, read back a
//! frame or more later: [`ProductsReadback`].)

mod pass;

pub use pass::{ProductsReadback, map_products_readback, next_products, translucency_iteration_pass};

use bevy::{
    math::{Vec3, Vec4},
    render::{
        diagnostic::{DiagnosticsRecorder, RecordDiagnostics},
        render_resource::{
            BindGroup, BindGroupEntries, BindGroupLayout, BindGroupLayoutEntries, Buffer,
            BufferDescriptor, PipelineLayout, ShaderModule,
            BufferInitDescriptor, BufferUsages, CommandEncoder, ComputePass, ComputePassDescriptor,
            ComputePipeline, PipelineCompilationOptions, PipelineLayoutDescriptor,
            RawComputePipelineDescriptor, ShaderModuleDescriptor, ShaderSource, ShaderStages,
            binding_types::{
                storage_buffer_read_only_sized, storage_buffer_sized, uniform_buffer_sized,
            },
        },
        renderer::{RenderDevice, RenderQueue},
    },
};
use bytemuck::{Pod, Zeroable};

use super::transport::{EnergyTransport, warm_iterations};

const WORKGROUP: u32 = 64;

/// Offsets of every array in the two packed buffers; `Layout` in `iterate.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable, Debug)]
struct Layout {
    patches: u32,
    clusters: u32,
    threshold: f32,
    max_iterations: u32,
    f_offsets: u32,
    f_columns: u32,
    f_values: u32,
    k_offsets: u32,
    k_columns: u32,
    k_values: u32,
    c_offsets: u32,
    c_columns: u32,
    c_values: u32,
    areas: u32,
    direct: u32,
    exitance: u32,
    irradiance: u32,
    delta_exitance: u32,
    delta_irradiance: u32,
    direct_exitance: u32,
    max_tail_ratio: f32,
    // The beam table (`beam_table/`): its slots and directions a slot, its CSR arrays
    // (early: RGB values over `beam_light`; late: RGB over `beam_late`) and late shares.
    slots: u32,
    bins: u32,
    early_offsets: u32,
    early_columns: u32,
    early_values: u32,
    late_offsets: u32,
    late_columns: u32,
    late_values: u32,
    late_shares: u32,
    // Its vectors: the beams' light by table direction, its per-slot late sums, the part of
    // E⁰ it carries, the exitance it gives, and what single scattering needs in the gather.
    beam_light: u32,
    beam_late: u32,
    tabled: u32,
    table_exitance: u32,
    beam_irradiance: u32,
    beam_direction: u32,
    // The table's light flow (`BeamTable::flow`): on or not, each slot's patch and each
    // patch's frame (`FlowFrame`) in `matrices`, the flow out (3 vec4s a patch) in `vectors`.
    flow: u32,
    slot_patches: u32,
    frames: u32,
    table_flow: u32,
    // The exit lobes' fits (`LobeFits`: 3 words a cell) in `matrices`, and each patch's lobes
    // in `vectors` (5 vec4s a patch: per channel axis and κ, the norms, the light from afar).
    lobe_fits: u32,
    table_lobes: u32,
    // Where a warm start stops: `threshold` × `WARM_THRESHOLD_SHARE`.
    warm_threshold: f32,
    // The rows of the beam table that hold entries (words in `matrices`), and how many: the
    // others' exitance, flow and lobes stay zero, as the vectors buffer starts.
    table_rows: u32,
    table_row_count: u32,
    // The lit faces' single-scattered exitance (`DirectLight::lit_face_exitance`), in
    // `vectors`: gathered with `B` by the first bounce.
    lit_face: u32,
    // To a whole number of 16-byte rows, as the uniform's WGSL struct.
    pad: [u32; 2],
}

/// What the iteration needs of a patch to give the deep field's exit law its axis each frame
/// the light changes (`BeamTable::flow`, `ExitLaw::set_flow`): `frames` in `iterate.wgsl`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FlowFrame {
    /// The patch's surface point.
    pub point: Vec3,
    /// Its unit normal.
    pub normal: Vec3,
    /// Its boundary's index of refraction.
    pub eta: f32,
    /// Where light entering it acts as a source, per channel
    /// ([`EnergyTransport::source_depths`](super::transport::EnergyTransport::source_depths)).
    pub source_depth: Vec3,
    /// Its deep law per channel, `(α, ν, 1/N, g)` ([`ExitLaw::channels`](super::transport::ExitLaw::channels)).
    pub law: [Vec4; 3],
    /// How its light from afar leans as it leaves ([`ExitLaw::lean`](super::transport::ExitLaw::lean);
    /// zero: no exit lobes).
    pub lean: super::beam_table::ExitLean,
    /// How far light must come from to leave by the lobes
    /// ([`from_afar`](super::beam_table::from_afar)), world units.
    pub afar: f32,
}

impl FlowFrame {
    /// Each patch's frame: `patches`' points and normals, `exit_laws`' index and laws,
    /// `source_depths`.
    pub fn of(
        patches: &super::patches::Patches,
        exit_laws: &[super::transport::ExitLaw],
        source_depths: &[Vec3],
    ) -> Vec<Self> {
        patches
            .patches
            .iter()
            .enumerate()
            .map(|(i, q)| {
                let law = exit_laws.get(i).copied().unwrap_or_default();
                Self {
                    point: q.surface_point,
                    normal: q.normal,
                    eta: law.eta,
                    source_depth: source_depths.get(i).copied().unwrap_or(Vec3::ZERO),
                    law: law.channels,
                    lean: law.lean,
                    afar: super::beam_table::lobe_source_distance(patches, source_depths, i),
                }
            })
            .collect()
    }

    fn words(&self) -> [u32; 32] {
        let v = [
            self.point.extend(0.0),
            self.normal.extend(self.eta),
            self.source_depth.extend(self.afar),
            self.law[0],
            self.law[1],
            self.law[2],
            self.lean.along.extend(0.0),
            self.lean.across.extend(0.0),
        ];
        std::array::from_fn(|k| v[k / 4][k % 4].to_bits())
    }
}

/// Where the beam table's vectors start in the iteration's vectors buffer (in `vec4<f32>`s).
#[derive(Clone, Copy, Debug, Default)]
pub struct BeamOffsets {
    /// The beams' light that got in, by `slot · bins + bin`.
    pub light: u32,
    /// Per patch, the part of `E⁰` the table carries.
    pub tabled: u32,
    /// Per patch, the beams' irradiance at normal incidence.
    pub irradiance: u32,
    /// Per patch, the beams' travel directions weighted by it.
    pub direction: u32,
    /// Per patch, the lit face's single-scattered exitance.
    pub lit_face: u32,
}

/// `State` in `iterate.wgsl` (indirect arguments first, as dispatches read them).
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable, Debug, Default)]
struct State {
    patch_groups: [u32; 3],
    cluster_groups: [u32; 3],
    iterations: u32,
    first_flux: f32,
    energy_left: f32,
    scattering_groups: [u32; 3],
    previous_flux: f32,
    tail_ratio: f32,
    warm: u32,
    reference_share: f32,
}

/// How the GPU iteration stops.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IterationLimits {
    /// Stop once the flux of the last increment is at most this share of the first bounce's.
    pub threshold: f32,
    /// And at most this many iterations (each one `F` and one `K` product).
    pub max_iterations: u32,
}

/// One static scene's transport on the GPU.
pub struct GpuTransport {
    layout: Layout,
    vectors: Buffer,
    state: Buffer,
    bind_group: BindGroup,
    state_bind_group: BindGroup,
    seed: ComputePipeline,
    scatter_first: ComputePipeline,
    scatter: ComputePipeline,
    decide: ComputePipeline,
    extrapolate: ComputePipeline,
    restrict: ComputePipeline,
    gather: ComputePipeline,
    // A warm start's (`EnergyTransport::solve_from`).
    seed_warm: ComputePipeline,
    gather_warm: ComputePipeline,
    scatter_first_warm: ComputePipeline,
    scatter_warm: ComputePipeline,
    table_late: ComputePipeline,
    table_rows: ComputePipeline,
}

/// The bind group layout of the translucency's compute passes (the iteration's and the light
/// injection's): a uniform of sizes and offsets, one read-only storage buffer of packed
/// arrays, two read-write ones — few buffers whatever a device's per-stage limit.
pub(super) fn packed_buffers_layout(device: &RenderDevice, label: &'static str) -> BindGroupLayout {
    device.create_bind_group_layout(
        Some(label),
        &BindGroupLayoutEntries::sequential(
            ShaderStages::COMPUTE,
            (
                uniform_buffer_sized(false, None),
                storage_buffer_read_only_sized(false, None),
                storage_buffer_sized(false, None),
                storage_buffer_sized(false, None),
            ),
        ),
    )
}

/// One entry point of `module` as a compute pipeline of `layout`.
pub(super) fn compute_pipeline(
    device: &RenderDevice,
    layout: &PipelineLayout,
    module: &ShaderModule,
    entry: &str,
) -> ComputePipeline {
    specialized_compute_pipeline(device, layout, module, entry, &[])
}

/// The same with values for the module's `override` constants.
pub(super) fn specialized_compute_pipeline(
    device: &RenderDevice,
    layout: &PipelineLayout,
    module: &ShaderModule,
    entry: &str,
    constants: &[(&str, f64)],
) -> ComputePipeline {
    device.create_compute_pipeline(&RawComputePipelineDescriptor {
        label: Some(entry),
        layout: Some(layout),
        module,
        entry_point: Some(entry),
        compilation_options: PipelineCompilationOptions {
            constants,
            ..Default::default()
        },
        cache: None,
    })
}

/// How many threads share one matrix row in the iteration's products (`ROW_LANES` and
/// `SCATTERING_LANES` in `iterate.wgsl`): a form-factor row holds ~300 entries, read in whole
/// cache lines by 32 lanes on a GPU. A row of `K` holds ~45 in the mean, but an opaque
/// patch's one or none and a translucent patch's hundreds, and a product waits for its
/// longest rows: 32 lanes as well (on an H100, the example's 20 k room: the `K` product
/// 0.063 ms with 8, 0.034 with 32, 0.036 with 64; `F`'s 0.036 with 32, 0.041 with 16, 0.038
/// with 64; docs/translucent.md). A CPU driver (llvmpipe) runs a workgroup's threads in turn
/// and pays for every barrier the lanes' sum needs, so there each thread takes a row alone.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RowLanes {
    /// 32 lanes a row of `F` and of `K` (one NVIDIA warp).
    Gpu,
    /// One lane a row.
    Cpu,
}

impl RowLanes {
    /// For the adapter `info` describes.
    pub fn for_adapter(info: &bevy::render::render_resource::WgpuAdapterInfo) -> Self {
        if info.device_type == wgpu::DeviceType::Cpu {
            RowLanes::Cpu
        } else {
            RowLanes::Gpu
        }
    }

    /// Threads per row of `F` (and of the cluster means), and of `K`.
    pub fn lanes(self) -> (u32, u32) {
        match self {
            RowLanes::Gpu => (32, 32),
            RowLanes::Cpu => (1, 1),
        }
    }
}

/// Appends `values` to `words`, returning where they start.
fn push(words: &mut Vec<u32>, values: impl IntoIterator<Item = u32>) -> u32 {
    let at = words.len() as u32;
    words.extend(values);
    at
}

impl GpuTransport {
    /// Uploads `transport` and builds the pipelines.
    pub fn new(
        device: &RenderDevice,
        transport: &EnergyTransport,
        limits: IterationLimits,
        row_lanes: RowLanes,
    ) -> Self {
        Self::with_flow(device, transport, limits, row_lanes, &[])
    }

    /// The same, and where `transport` has a beam table and `frames` one [`FlowFrame`] a
    /// patch, each frame's flow of the table's light into each patch (the deep law's axes
    /// the gather reads: [`flow_offset`](Self::flow_offset)).
    pub fn with_flow(
        device: &RenderDevice,
        transport: &EnergyTransport,
        limits: IterationLimits,
        row_lanes: RowLanes,
        frames: &[FlowFrame],
    ) -> Self {
        let n = transport.areas.len() as u32;
        let clusters = transport.cluster_means.rows() as u32;
        let (f, k, c) = (
            &transport.form_factors,
            &transport.scattering,
            &transport.cluster_means,
        );
        let mut words = Vec::new();
        let mut layout = Layout {
            patches: n,
            clusters,
            threshold: limits.threshold,
            max_iterations: limits.max_iterations,
            max_tail_ratio: super::transport::MAX_TAIL_RATIO,
            warm_threshold: limits.threshold * super::transport::WARM_THRESHOLD_SHARE,
            f_offsets: push(&mut words, f.row_offsets.iter().copied()),
            f_columns: push(&mut words, f.columns.iter().copied()),
            f_values: push(&mut words, f.values.iter().map(|v| v.to_bits())),
            k_offsets: push(&mut words, k.row_offsets.iter().copied()),
            k_columns: push(&mut words, k.columns.iter().copied()),
            // Three words per RGB value.
            k_values: push(
                &mut words,
                k.values.iter().flat_map(|v| v.to_array().map(f32::to_bits)),
            ),
            ..Zeroable::zeroed()
        };
        // An empty cluster matrix still has one offset (0) for the shader to find.
        layout.c_offsets = if c.row_offsets.is_empty() {
            push(&mut words, [0])
        } else {
            push(&mut words, c.row_offsets.iter().copied())
        };
        layout.c_columns = push(&mut words, c.columns.iter().copied());
        layout.c_values = push(&mut words, c.values.iter().map(|v| v.to_bits()));
        layout.areas = push(&mut words, transport.areas.iter().map(|a| a.to_bits()));

        let rgb = |m: &super::transport::SparseMatrix<Vec3>| -> Vec<u32> {
            m.values.iter().flat_map(|v| v.to_array().map(f32::to_bits)).collect()
        };
        let offsets = |m: &super::transport::SparseMatrix<Vec3>| -> Vec<u32> {
            if m.row_offsets.is_empty() { vec![0; n as usize + 1] } else { m.row_offsets.clone() }
        };
        let empty = super::transport::SparseMatrix::<Vec3>::default();
        let table = transport.beam_table.as_ref();
        let (early, late) = table.map_or((&empty, &empty), |t| (&t.early, &t.late));
        layout.slots = table.map_or(0, |t| t.media.len() as u32);
        layout.bins = table.map_or(0, |t| t.bins());
        let (early_offsets, late_offsets) = (offsets(early), offsets(late));
        // The table's rows with entries: `table_rows` runs a workgroup for each of those alone.
        let rows_with_entries: Vec<u32> = (0..n as usize)
            .filter(|&i| {
                let entries = |o: &[u32]| o.get(i + 1).zip(o.get(i)).map_or(0, |(b, a)| b.saturating_sub(*a));
                entries(&early_offsets) + entries(&late_offsets) > 0
            })
            .map(|i| i as u32)
            .collect();
        layout.early_offsets = push(&mut words, early_offsets);
        layout.early_columns = push(&mut words, early.columns.iter().copied());
        layout.early_values = push(&mut words, rgb(early));
        layout.late_offsets = push(&mut words, late_offsets);
        layout.late_columns = push(&mut words, late.columns.iter().copied());
        layout.late_values = push(&mut words, rgb(late));
        layout.late_shares = push(
            &mut words,
            table.into_iter().flat_map(|t| t.late_share.iter().flat_map(|v| v.to_array().map(f32::to_bits))),
        );
        layout.table_row_count = rows_with_entries.len() as u32;
        layout.table_rows = push(&mut words, rows_with_entries);
        let flow = table.is_some() && frames.len() == n as usize && n > 0;
        if let Some(t) = table.filter(|_| flow) {
            layout.flow = 1;
            layout.slot_patches = push(&mut words, t.slot_patches());
            layout.frames = push(&mut words, frames.iter().flat_map(FlowFrame::words));
            layout.lobe_fits = push(
                &mut words,
                super::exit_lobe::LobeFits::get().cells().iter().flatten().map(|v| v.to_bits()),
            );
        }
        words.push(0);

        layout.direct = 0;
        layout.exitance = n;
        layout.irradiance = 2 * n;
        layout.delta_exitance = 3 * n;
        layout.delta_irradiance = 4 * n + clusters;
        layout.direct_exitance = 5 * n + clusters;
        layout.tabled = 6 * n + clusters;
        layout.table_exitance = 7 * n + clusters;
        layout.beam_irradiance = 8 * n + clusters;
        layout.beam_direction = 9 * n + clusters;
        layout.lit_face = 10 * n + clusters;
        layout.beam_light = 11 * n + clusters;
        layout.beam_late = layout.beam_light + layout.slots * layout.bins;
        layout.table_flow = layout.beam_late + layout.slots;
        let flows = if layout.flow == 1 { 3 * n } else { 0 };
        layout.table_lobes = layout.table_flow + flows;
        let lobes = if layout.flow == 1 { 5 * n } else { 0 };
        let vector_count = (layout.table_lobes + lobes).max(1) as u64;

        let matrices = device.create_buffer_with_data(&BufferInitDescriptor {
            label: Some("translucency_matrices"),
            contents: bytemuck::cast_slice(&words),
            usage: BufferUsages::STORAGE,
        });
        let vectors = device.create_buffer(&BufferDescriptor {
            label: Some("translucency_vectors"),
            size: vector_count * 16,
            usage: BufferUsages::STORAGE | BufferUsages::COPY_DST | BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let partials = device.create_buffer(&BufferDescriptor {
            label: Some("translucency_partial_fluxes"),
            // Two per workgroup of the K product (the increments' flux, and a warm start's
            // flux(B) after them): at most one workgroup per patch whatever its lanes a row
            // (`SCATTERING_LANES` in the shader).
            size: (n.max(1) as u64) * 8,
            usage: BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        let state = device.create_buffer(&BufferDescriptor {
            label: Some("translucency_iteration_state"),
            size: size_of::<State>() as u64,
            usage: BufferUsages::STORAGE | BufferUsages::INDIRECT | BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let uniform = device.create_buffer_with_data(&BufferInitDescriptor {
            label: Some("translucency_layout"),
            contents: bytemuck::bytes_of(&layout),
            usage: BufferUsages::UNIFORM,
        });

        let bind_group_layout = packed_buffers_layout(device, "translucency_iteration_layout");
        let state_layout = device.create_bind_group_layout(
            Some("translucency_state_layout"),
            &BindGroupLayoutEntries::single(ShaderStages::COMPUTE, storage_buffer_sized(false, None)),
        );
        let state_bind_group = device.create_bind_group(
            Some("translucency_state"),
            &state_layout,
            &BindGroupEntries::single(state.as_entire_binding()),
        );
        let bind_group = device.create_bind_group(
            Some("translucency_iteration"),
            &bind_group_layout,
            &BindGroupEntries::sequential((
                uniform.as_entire_binding(),
                matrices.as_entire_binding(),
                vectors.as_entire_binding(),
                partials.as_entire_binding(),
            )),
        );
        let module = device.create_and_validate_shader_module(ShaderModuleDescriptor {
            label: Some("translucency_iterate"),
            source: ShaderSource::Wgsl(super::with_boundary(include_str!("iterate.wgsl")).into()),
        });
        // The products see only group 0; `seed` and `decide` also the state.
        let products = device.create_pipeline_layout(&PipelineLayoutDescriptor {
            label: Some("translucency_products"),
            bind_group_layouts: &[Some(&bind_group_layout)],
            immediate_size: 0,
        });
        let control = device.create_pipeline_layout(&PipelineLayoutDescriptor {
            label: Some("translucency_control"),
            bind_group_layouts: &[Some(&bind_group_layout), Some(&state_layout)],
            immediate_size: 0,
        });
        let (form_factor_lanes, scattering_lanes) = row_lanes.lanes();
        let constants = [
            ("ROW_LANES", form_factor_lanes as f64),
            ("SCATTERING_LANES", scattering_lanes as f64),
        ];
        let pipeline =
            |entry, layout| specialized_compute_pipeline(device, layout, &module, entry, &constants);
        Self {
            layout,
            vectors,
            state,
            bind_group,
            state_bind_group,
            seed: pipeline("seed", &control),
            scatter_first: pipeline("scatter_first", &products),
            scatter: pipeline("scatter", &products),
            decide: pipeline("decide", &control),
            extrapolate: pipeline("extrapolate", &control),
            restrict: pipeline("cluster_means", &products),
            gather: pipeline("gather", &products),
            seed_warm: pipeline("seed_warm", &control),
            gather_warm: pipeline("gather_warm", &products),
            scatter_first_warm: pipeline("scatter_first_warm", &products),
            scatter_warm: pipeline("scatter_warm", &products),
            table_late: pipeline("table_late", &products),
            table_rows: pipeline("table_rows", &products),
        }
    }

    /// Number of patches.
    pub fn patches(&self) -> u32 {
        self.layout.patches
    }

    /// The most products a cold start records ([`IterationLimits::max_iterations`]).
    pub fn max_iterations(&self) -> u32 {
        self.layout.max_iterations
    }

    /// Writes this frame's direct light: irradiance `E⁰`, the exitance `S⁰` besides
    /// `K E⁰`, and the beam table's vectors (one per patch, the beams' light one per table
    /// direction; an empty vector is zero).
    pub fn write_direct(&self, queue: &RenderQueue, direct: &super::transport::DirectLight) {
        let n = self.layout.patches as usize;
        if n > 0 {
            let write = |at: u32, v: &[Vec3], count: usize| {
                let packed: Vec<[f32; 4]> = (0..count)
                    .map(|i| v.get(i).map_or([0.0; 4], |e| [e.x, e.y, e.z, 0.0]))
                    .collect();
                queue.write_buffer(&self.vectors, at as u64 * 16, bytemuck::cast_slice(&packed));
            };
            let l = &self.layout;
            write(l.direct, &direct.irradiance, n);
            write(l.direct_exitance, &direct.exitance, n);
            write(l.tabled, &direct.tabled, n);
            write(l.beam_irradiance, &direct.beam_irradiance, n);
            write(l.beam_direction, &direct.beam_direction, n);
            write(l.lit_face, &direct.lit_face_exitance, n);
            let lights = (l.slots * l.bins) as usize;
            if lights > 0 {
                write(l.beam_light, &direct.beam_light, lights);
            }
        }
    }

    /// Records one frame's iteration from the direct irradiance last written: from zero, or
    /// (`warm`) from the exitance the last recorded iteration left, as
    /// [`EnergyTransport::solve_from`] does (`warm` only after one was recorded; before, the
    /// exitance is not this transport's), with at most
    /// [`warm_iterations`]`(max_iterations)` products.
    pub fn record(&self, encoder: &mut CommandEncoder, warm: bool) {
        self.record_at_most(encoder, warm, u32::MAX);
    }

    /// [`record`](Self::record) with at most `products` products recorded (at least one; the
    /// transport's own caps still hold): the plugin records one more than the last solve took
    /// ([`ProductsReadback`]), since every recorded product costs its dispatches on the GPU
    /// even after the stop.
    pub fn record_at_most(&self, encoder: &mut CommandEncoder, warm: bool, products: u32) {
        self.record_timed(encoder, warm, products, &None::<&DiagnosticsRecorder>);
    }

    /// [`record_at_most`](Self::record_at_most) with a GPU time span for each of its parts,
    /// nested in the caller's: `table` (the beam table's exitance and flow, once a light
    /// change), `application` (the seed and the first product: a warm start's application of
    /// the last solution), `products` (the rest of the recorded loop and the geometric tail).
    /// Each is its own compute pass, so that the spans' timestamps fall between passes.
    pub fn record_timed(
        &self,
        encoder: &mut CommandEncoder,
        warm: bool,
        products: u32,
        spans: &impl RecordDiagnostics,
    ) {
        let n = self.layout.patches;
        if n == 0 {
            return;
        }
        encoder.push_debug_group("translucency_iteration");
        // `seed` is a thread per patch; it writes the products' dispatch sizes (rows per
        // workgroup are the shader's business).
        let patch_args = 0;
        let cluster_args = 12;
        let scattering_args = 36;
        if self.layout.slots > 0 {
            let span = spans.time_span(encoder, "table");
            {
                let mut pass = self.begin_pass(encoder, "translucency_iteration_table");
                // The beam table's exitance from the beams' light (`BeamTable::apply`).
                pass.set_pipeline(&self.table_late);
                pass.dispatch_workgroups(self.layout.slots.div_ceil(WORKGROUP), 1, 1);
                // A workgroup a row with entries, spilling into y past the per-dimension limit.
                let rows = self.layout.table_row_count;
                if rows > 0 {
                    pass.set_pipeline(&self.table_rows);
                    let x = rows.min(65_535);
                    pass.dispatch_workgroups(x, rows.div_ceil(x), 1);
                }
            }
            span.end(encoder);
        }
        let span = spans.time_span(encoder, "application");
        {
            let mut pass = self.begin_pass(encoder, "translucency_iteration_application");
            if warm {
                // E = E⁰ + F B', ΔE = E⁰ − E_t + F B', B = K ΔE + S⁰ + T x, ΔB = B − B'.
                pass.set_pipeline(&self.seed_warm);
                pass.dispatch_workgroups(n.div_ceil(WORKGROUP), 1, 1);
                if self.layout.clusters > 0 {
                    pass.set_pipeline(&self.restrict);
                    pass.dispatch_workgroups_indirect(&self.state, cluster_args);
                }
                pass.set_pipeline(&self.gather_warm);
                pass.dispatch_workgroups_indirect(&self.state, patch_args);
                pass.set_pipeline(&self.scatter_first_warm);
            } else {
                pass.set_pipeline(&self.seed);
                pass.dispatch_workgroups(n.div_ceil(WORKGROUP), 1, 1);
                pass.set_pipeline(&self.scatter_first);
            }
            pass.dispatch_workgroups_indirect(&self.state, scattering_args);
            pass.set_pipeline(&self.decide);
            pass.dispatch_workgroups(1, 1, 1);
        }
        span.end(encoder);
        let span = spans.time_span(encoder, "products");
        {
            let mut pass = self.begin_pass(encoder, "translucency_iteration_products");
            let scatter = if warm { &self.scatter_warm } else { &self.scatter };
            // A warm start's application was its first product.
            let loops = self.recorded_products(warm, products) - u32::from(warm);
            for _ in 0..loops {
                if self.layout.clusters > 0 {
                    pass.set_pipeline(&self.restrict);
                    pass.dispatch_workgroups_indirect(&self.state, cluster_args);
                }
                pass.set_pipeline(&self.gather);
                pass.dispatch_workgroups_indirect(&self.state, patch_args);
                pass.set_pipeline(scatter);
                pass.dispatch_workgroups_indirect(&self.state, scattering_args);
                pass.set_pipeline(&self.decide);
                pass.dispatch_workgroups(1, 1, 1);
            }
            pass.set_pipeline(&self.extrapolate);
            pass.dispatch_workgroups(n.div_ceil(WORKGROUP), 1, 1);
        }
        span.end(encoder);
        encoder.pop_debug_group();
    }

    /// A compute pass of the iteration with its bind groups set.
    fn begin_pass<'e>(&self, encoder: &'e mut CommandEncoder, label: &'static str) -> ComputePass<'e> {
        let mut pass = encoder.begin_compute_pass(&ComputePassDescriptor {
            label: Some(label),
            timestamp_writes: None,
        });
        pass.set_bind_group(0, &self.bind_group, &[]);
        pass.set_bind_group(1, &self.state_bind_group, &[]);
        pass
    }

    /// The products a solve records when asked for at most `products`: a warm one
    /// [`warm_iterations`] at most (its application one of them), a cold one `max_iterations`
    /// at most; at least one.
    pub fn recorded_products(&self, warm: bool, products: u32) -> u32 {
        let cap = if warm {
            warm_iterations(self.layout.max_iterations).max(1)
        } else {
            self.layout.max_iterations
        };
        products.clamp(1, cap.max(1))
    }

    /// The buffer holding every vector, and the byte range of the exitance `B` in it
    /// (`vec4<f32>` per patch, `w` unused): what the picture reads.
    pub fn exitance(&self) -> (&Buffer, std::ops::Range<u64>) {
        let start = self.layout.exitance as u64 * 16;
        (
            &self.vectors,
            start..start + self.layout.patches as u64 * 16,
        )
    }

    /// Where the direct irradiance `E⁰` and the exitance `B` start in the vectors buffer
    /// (in `vec4<f32>`s).
    pub fn vector_offsets(&self) -> (u32, u32) {
        (self.layout.direct, self.layout.exitance)
    }

    /// Where each patch's irradiance `E` (direct and bounced, as the iteration leaves it)
    /// starts in the vectors buffer (in `vec4<f32>`s): the gather's exit law takes it as the
    /// patch's own light.
    pub fn irradiance_offset(&self) -> u32 {
        self.layout.irradiance
    }

    /// Where the direct light's irradiance `E⁰` and exitance `S⁰` start in the vectors buffer
    /// (in `vec4<f32>`s): what the light injection writes.
    pub fn direct_offsets(&self) -> (u32, u32) {
        (self.layout.direct, self.layout.direct_exitance)
    }

    /// Where the beam table's vectors start in the vectors buffer (in `vec4<f32>`s): the
    /// beams' light by table direction, the part of `E⁰` the table carries, the beams'
    /// normal irradiance and weighted direction (what the injection writes and the gather's
    /// single scattering reads), and the lit faces' single-scattered exitance.
    pub fn beam_offsets(&self) -> BeamOffsets {
        let l = &self.layout;
        BeamOffsets {
            light: l.beam_light,
            tabled: l.tabled,
            irradiance: l.beam_irradiance,
            direction: l.beam_direction,
            lit_face: l.lit_face,
        }
    }

    /// Where each patch's flow starts in the vectors buffer (in `vec4<f32>`s, three a patch:
    /// per channel the deep law's axis and `1/N`, as [`ExitLaw::flow`](super::transport::ExitLaw::flow));
    /// `None` without a beam table or frames.
    pub fn flow_offset(&self) -> Option<u32> {
        (self.layout.flow == 1).then_some(self.layout.table_flow)
    }

    /// Where each patch's exit lobes start in the vectors buffer (in `vec4<f32>`s, five a
    /// patch: per channel the lobe's axis and κ, the three norms, and the light from afar
    /// that leaves by them, as [`ExitLaw::lobes`](super::transport::ExitLaw::lobes) and
    /// [`lobe_exitance`](super::transport::ExitLaw::lobe_exitance)); `None` as for
    /// [`flow_offset`](Self::flow_offset).
    pub fn lobes_offset(&self) -> Option<u32> {
        (self.layout.flow == 1).then_some(self.layout.table_lobes)
    }

    /// The buffer holding every vector (what a test reads back).
    pub fn vectors(&self) -> &Buffer {
        &self.vectors
    }

    /// The buffer holding the iteration's state (`iterations: u32` at byte 24,
    /// `energy_left: f32` at byte 32, `tail_ratio: f32` at byte 52, `warm: u32` at byte 56).
    pub fn state(&self) -> &Buffer {
        &self.state
    }
}

/// Byte offset of `State::iterations`, the products the last solve took.
pub(super) const ITERATIONS_OFFSET: u64 = std::mem::offset_of!(State, iterations) as u64;
