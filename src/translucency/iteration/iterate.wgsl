// Seed 001's per-frame transport on the GPU: B = K E⁰ + S⁰ + K F (B + P), P the lit faces'
// single scattering (which the gather gives per pixel), iterated as
//   ΔB₀ = K E⁰ + S⁰, B = ΔB₀, ΔB₀ += P (the first F gathers it, B does not hold it);
//   repeat { ΔB_c = cluster means of ΔB;  ΔE = F [ΔB, ΔB_c];  E += ΔE;
//            ΔB = K ΔE;  B += ΔB }  until flux(ΔB) ≤ threshold · flux(ΔB₀);
//   then B += ΔB r/(1 − r), the geometric tail (r = flux(ΔB) / flux(the ΔB before)).
// The same arithmetic as `EnergyTransport::solve` (src/translucency/transport/solve.rs), each
// row's sum in another order (a few lanes' partial sums, then a tree). The loop is
// recorded max_iterations times; `decide` zeroes the indirect dispatch arguments once the
// energy still moving is below the threshold, so the rest of the recorded loop costs nothing.
// Warm-started from the last solution B' (`EnergyTransport::solve_from`): `seed_warm`,
// `cluster_means` and `gather_warm` give ΔE = E⁰ − E_t + F (B' + P), `scatter_first_warm`
// B = K ΔE + S⁰ + T x and ΔB = B − B' (counted as an iteration), and the loop goes on from
// that ΔB with its absolute flux, to `warm_threshold`, the first bounce's flux estimated as
// flux(B) (1 − r') with r' the last solution's tail ratio.

struct Layout {
    patches: u32,
    clusters: u32,
    threshold: f32,
    max_iterations: u32,
    // Offsets (in u32 words) of each CSR array in `matrices`.
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
    // Offsets (in vec4s) of each vector in `vectors`.
    direct: u32,
    exitance: u32,
    irradiance: u32,
    delta_exitance: u32,   // patches + clusters (the clusters' means after the patches)
    delta_irradiance: u32,
    // The direct light's exitance besides K E⁰ (single scattering at each beam's incidence).
    direct_exitance: u32,
    // `MAX_TAIL_RATIO` (transport/solve.rs): the most the tail ratio is trusted.
    max_tail_ratio: f32,
    // The beam table (`BeamTable` in beam_table/mod.rs): slots and directions a slot; its CSR
    // arrays (early columns over `beam_light`, late ones over `beam_late`, RGB values) and
    // each direction's late share (RGB), in `matrices`.
    slots: u32,
    bins: u32,
    early_offsets: u32,
    early_columns: u32,
    early_values: u32,
    late_offsets: u32,
    late_columns: u32,
    late_values: u32,
    late_shares: u32,
    // Its vectors (in vec4s): the beams' light by `slot · bins + bin`, its per-slot late
    // sums, the part of E⁰ it carries, the exitance it gives, and the beams' normal
    // irradiance and direction (the gather's single scattering).
    beam_light: u32,
    beam_late: u32,
    tabled: u32,
    table_exitance: u32,
    beam_irradiance: u32,
    beam_direction: u32,
    // The way the table's light flows into each patch (`BeamTable::flow`, `ExitLaw::set_flow`),
    // where `flow` is 1: each slot's patch (words in `matrices`), each patch's frame (32
    // words in `matrices`: surface point, normal and η, the diffusion source's depth per
    // channel and how far light from afar comes, the deep law per channel (α, ν, 1/N, g),
    // the lean along and across per channel), and the flow out (three vec4s a patch in
    // `vectors`: axis, 1/N).
    flow: u32,
    slot_patches: u32,
    frames: u32,
    table_flow: u32,
    // The exit lobes: their fits (`LobeFits`, 3 words a cell: κ, θ, norm) in `matrices`, and
    // each patch's (five vec4s: per channel axis and κ, the norms, the light from afar) in
    // `vectors`.
    lobe_fits: u32,
    table_lobes: u32,
    // `threshold` times `WARM_THRESHOLD_SHARE` (transport/solve.rs): where a warm start stops.
    warm_threshold: f32,
    // The beam table's rows that hold entries (words in `matrices`) and how many: `table_rows`
    // runs over those alone; the others' exitance, flow and lobes stay zero.
    table_rows: u32,
    table_row_count: u32,
    // The lit faces' single-scattered exitance P (in vec4s; `DirectLight::lit_face_exitance`):
    // the gather gives it per pixel, so it is not in B, but the first bounce gathers B + P.
    lit_face: u32,
}

struct State {
    // Indirect dispatch arguments (x, y, z; scalars, so the two sets pack without padding):
    // the products over the patches' rows and over the clusters' rows.
    patch_groups: u32,
    patch_groups_y: u32,
    patch_groups_z: u32,
    cluster_groups: u32,
    cluster_groups_y: u32,
    cluster_groups_z: u32,
    iterations: u32,
    first_flux: f32,
    energy_left: f32,
    // The K product's (its rows are shorter: fewer lanes a row, more rows a workgroup).
    scattering_groups: u32,
    scattering_groups_y: u32,
    scattering_groups_z: u32,
    // The flux of the last ΔB, and how much it shrank from the one before.
    previous_flux: f32,
    tail_ratio: f32,
    // 1 for a warm start, and the share of flux(B) its first bounce is taken to hold.
    warm: u32,
    reference_share: f32,
}

@group(0) @binding(0) var<uniform> packing: Layout;
@group(0) @binding(1) var<storage, read> matrices: array<u32>;
@group(0) @binding(2) var<storage, read_write> vectors: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> partials: array<f32>;
// Apart from the rest: the products read it as their indirect arguments, which may not be
// bound for writing in the same dispatch.
@group(1) @binding(0) var<storage, read_write> state: State;

const WORKGROUP: u32 = 64u;
// The products are CSR-vector: ROW_LANES neighbouring threads share a matrix row, each reading
// every ROW_LANES-th entry, so a row's columns and values are read in whole cache lines
// rather than one thread walking hundreds of entries alone (a form-factor row holds ~300).
// Powers of two up to WORKGROUP, set per pipeline (`RowLanes` in mod.rs): ROW_LANES for F
// and the cluster means, SCATTERING_LANES for K (hundreds of entries a translucent row, one or
// none an opaque one; the product waits for the longest).
override ROW_LANES: u32 = 32u;
override SCATTERING_LANES: u32 = 32u;
// Workgroups per dispatch dimension (WebGPU's least limit): more rows spill into y.
const MAX_GROUPS_X: u32 = 65535u;

fn groups(n: u32) -> u32 {
    return (n + WORKGROUP - 1u) / WORKGROUP;
}

// Workgroups of a product over `rows` rows, `lanes` threads a row.
fn row_groups(rows: u32, lanes: u32) -> u32 {
    let rows_per_group = WORKGROUP / lanes;
    return (rows + rows_per_group - 1u) / rows_per_group;
}

// A dispatch of `count` workgroups: x up to MAX_GROUPS_X, the rest in y.
fn dispatch_size(count: u32) -> vec2<u32> {
    return vec2(min(count, MAX_GROUPS_X), (count + MAX_GROUPS_X - 1u) / MAX_GROUPS_X);
}

// The product's workgroup, counted across both dispatch dimensions.
fn group_index(group: vec3<u32>, count: vec3<u32>) -> u32 {
    return group.y * count.x + group.x;
}

// The loop's state reset and the products' dispatch sizes; `tail_ratio` the ratio the tail
// starts from.
fn reset_state(warm: bool, tail_ratio: f32) {
    let patches = dispatch_size(row_groups(packing.patches, ROW_LANES));
    state.patch_groups = patches.x;
    state.patch_groups_y = patches.y;
    state.patch_groups_z = 1u;
    let clusters = dispatch_size(row_groups(packing.clusters, ROW_LANES));
    state.cluster_groups = clusters.x;
    state.cluster_groups_y = clusters.y;
    state.cluster_groups_z = 1u;
    let scattering = dispatch_size(row_groups(packing.patches, SCATTERING_LANES));
    state.scattering_groups = scattering.x;
    state.scattering_groups_y = scattering.y;
    state.scattering_groups_z = 1u;
    state.iterations = 0u;
    state.first_flux = -1.0;
    state.energy_left = 1.0;
    state.previous_flux = 0.0;
    state.tail_ratio = tail_ratio;
    state.warm = select(0u, 1u, warm);
    state.reference_share = 1.0 - tail_ratio;
}

// E = E⁰, ΔE = E⁰, B = 0; the loop's state reset; the products' dispatch sizes.
@compute @workgroup_size(64)
fn seed(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i == 0u {
        reset_state(false, 0.0);
    }
    if i >= packing.patches {
        return;
    }
    let e = vectors[packing.direct + i];
    vectors[packing.irradiance + i] = e;
    // K takes what the beam table does not carry (`DirectLight::tabled`).
    vectors[packing.delta_irradiance + i] = e - vectors[packing.tabled + i];
    vectors[packing.exitance + i] = vec4(0.0);
}

// A warm start: E = E⁰, ΔB = B' (the last solution, kept in B) for `cluster_means` and
// `gather_warm`; the tail starts from the last solution's ratio.
@compute @workgroup_size(64)
fn seed_warm(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i == 0u {
        reset_state(true, clamp(state.tail_ratio, 0.0, packing.max_tail_ratio));
    }
    if i >= packing.patches {
        return;
    }
    vectors[packing.irradiance + i] = vectors[packing.direct + i];
    vectors[packing.delta_exitance + i] = vectors[packing.exitance + i] + vectors[packing.lit_face + i];
}

fn rgb(at: u32) -> vec4<f32> {
    return vec4(bitcast<f32>(matrices[at]), bitcast<f32>(matrices[at + 1u]),
                bitcast<f32>(matrices[at + 2u]), 0.0);
}

// Each slot's late light: its directions' beams weighted by their late shares
// (`BeamTable::apply`).
@compute @workgroup_size(64)
fn table_late(@builtin(global_invocation_id) id: vec3<u32>) {
    let slot = id.x;
    if slot >= packing.slots {
        return;
    }
    var sum = vec4(0.0);
    for (var b = 0u; b < packing.bins; b++) {
        let c = slot * packing.bins + b;
        sum += rgb(packing.late_shares + 3u * c) * vectors[packing.beam_light + c];
    }
    vectors[packing.beam_late + slot] = sum;
}

// The exitance the beam table gives each patch: its early columns over the beams' light and
// its late columns over the slots' late light (`BeamTable::apply`), and with `flow` the way
// that light flows in and its exit lobes. Once a light change, before the iteration; a
// workgroup a row with entries (a translucent patch's rows hold ~900: a thread a row walked
// them alone, ~1.6 ms for the example's room on an H100); the rows without entries are left
// as the buffer started, zero (what they would give: no light, no flow, no lobes).
@compute @workgroup_size(64)
fn table_rows(
    @builtin(workgroup_id) group: vec3<u32>,
    @builtin(num_workgroups) count: vec3<u32>,
    @builtin(local_invocation_index) local: u32,
) {
    let k = group_index(group, count);
    if k >= packing.table_row_count {
        return;
    }
    let i = matrices[packing.table_rows + k];
    var exitance: vec4<f32>;
    if packing.flow == 1u {
        // One walk of the row gives both.
        exitance = table_flow_of(i, local);
    } else {
        let part = rgb_row_part(packing.early_offsets, packing.early_columns, packing.early_values,
                                packing.beam_light, i, local, WORKGROUP)
            + rgb_row_part(packing.late_offsets, packing.late_columns, packing.late_values,
                           packing.beam_late, i, local, WORKGROUP);
        exitance = row_total(local, part);
    }
    if local == 0u {
        vectors[packing.table_exitance + i] = exitance;
    }
}

// `row_sum` over the whole workgroup, after which `lanes` may be written again.
fn row_total(local: u32, part: vec4<f32>) -> vec4<f32> {
    let total = row_sum(local, part, WORKGROUP);
    workgroupBarrier();
    return total;
}

fn frame_vec4(i: u32, k: u32) -> vec4<f32> {
    let at = packing.frames + 32u * i + 4u * k;
    return vec4(bitcast<f32>(matrices[at]), bitcast<f32>(matrices[at + 1u]),
                bitcast<f32>(matrices[at + 2u]), bitcast<f32>(matrices[at + 3u]));
}

// What patch `j`'s beams give patch `i` (`given`, RGB), flowing from `j`'s diffusion source
// to `i`: into each channel's sum of directions (`BeamTable::flow`).
// The early light from afar (`from_afar`) is summed apart as well: what the exit lobes take.
struct FlowSums {
    r: vec3<f32>,
    g: vec3<f32>,
    b: vec3<f32>,
    total: vec3<f32>,
    far_r: vec3<f32>,
    far_g: vec3<f32>,
    far_b: vec3<f32>,
    far: vec3<f32>,
}

// `from_source` (beam_table/flow.rs): the unit direction from a diffusion source to `x`.
fn from_source(x: vec3<f32>, source: vec3<f32>) -> vec3<f32> {
    let d = x - source;
    return select(vec3(0.0), normalize(d), dot(d, d) > 0.0);
}

fn add_flow(sums: ptr<function, FlowSums>, x: vec3<f32>, afar: f32, i: u32, j: u32, given: vec3<f32>,
            early: bool) {
    if j == i || j >= packing.patches {
        return;
    }
    let point = frame_vec4(j, 0u).xyz;
    let normal = frame_vec4(j, 1u).xyz;
    let depth = frame_vec4(j, 2u).xyz;
    let u_r = from_source(x, point - normal * depth.x) * given.x;
    let u_g = from_source(x, point - normal * depth.y) * given.y;
    let u_b = from_source(x, point - normal * depth.z) * given.z;
    (*sums).r += u_r;
    (*sums).g += u_g;
    (*sums).b += u_b;
    (*sums).total += given;
    if early && distance(x, point) > afar {
        (*sums).far_r += u_r;
        (*sums).far_g += u_g;
        (*sums).far_b += u_b;
        (*sums).far += given;
    }
}

// `ExitLaw::set_flow` in one channel: the axis of the deep law about it (zero where the
// channel is Lambert's or no light comes from elsewhere), without its 1/N.
fn flow_out(sum: vec3<f32>, total: f32, law: vec4<f32>) -> vec4<f32> {
    if total <= 0.0 || law.w <= 0.0 {
        return vec4(0.0);
    }
    return vec4(sum / total, 0.0);
}

// Patch `i`'s flow from the table's early and late rows (`BeamTable::flow`), by the
// workgroup's threads (`local` of WORKGROUP; all must call it); returns the row's exitance
// (`BeamTable::apply`), in every thread.
fn table_flow_of(i: u32, local: u32) -> vec4<f32> {
    let x = frame_vec4(i, 0u).xyz;
    let afar = frame_vec4(i, 2u).w;
    let zero = vec3(0.0);
    var sums = FlowSums(zero, zero, zero, zero, zero, zero, zero, zero);
    // Everything the row gives, the patch's own beams too: its exitance.
    var given_all = vec4(0.0);
    let early_end = matrices[packing.early_offsets + i + 1u];
    for (var k = matrices[packing.early_offsets + i] + local; k < early_end; k += WORKGROUP) {
        let column = matrices[packing.early_columns + k];
        let given = rgb(packing.early_values + 3u * k) * vectors[packing.beam_light + column];
        given_all += given;
        add_flow(&sums, x, afar, i, matrices[packing.slot_patches + column / packing.bins], given.rgb, true);
    }
    let late_end = matrices[packing.late_offsets + i + 1u];
    for (var k = matrices[packing.late_offsets + i] + local; k < late_end; k += WORKGROUP) {
        let slot = matrices[packing.late_columns + k];
        let given = rgb(packing.late_values + 3u * k) * vectors[packing.beam_late + slot];
        given_all += given;
        add_flow(&sums, x, afar, i, matrices[packing.slot_patches + slot], given.rgb, false);
    }
    let exitance = row_total(local, given_all);
    // The row's sums, in every thread.
    let r = row_total(local, vec4(sums.r, sums.total.x));
    let g = row_total(local, vec4(sums.g, sums.total.y));
    let b = row_total(local, vec4(sums.b, sums.total.z));
    let far_r = row_total(local, vec4(sums.far_r, sums.far.x));
    let far_g = row_total(local, vec4(sums.far_g, sums.far.y));
    let far_b = row_total(local, vec4(sums.far_b, sums.far.z));
    sums = FlowSums(r.xyz, g.xyz, b.xyz, vec3(r.w, g.w, b.w),
                    far_r.xyz, far_g.xyz, far_b.xyz, vec3(far_r.w, far_g.w, far_b.w));
    // Each channel's 1/N about its axis (`deep_exit_norm_about`), the rule's samples shared
    // among the threads.
    let normal = frame_vec4(i, 1u);
    let flows = channel_flows(i, sums);
    let axis_r = flows[0].xyz;
    let axis_g = flows[1].xyz;
    let axis_b = flows[2].xyz;
    let along = vec3(dot(axis_r, normal.xyz), dot(axis_g, normal.xyz), dot(axis_b, normal.xyz));
    let across = vec3(
        length(axis_r - normal.xyz * along.x),
        length(axis_g - normal.xyz * along.y),
        length(axis_b - normal.xyz * along.z),
    );
    var samples = vec3(0.0);
    for (var s = local; s < DEEP_EXIT_NORM_SAMPLES; s += WORKGROUP) {
        samples += vec3(
            deep_exit_norm_sample(frame_vec4(i, 3u), normal.w, along.x, across.x, s),
            deep_exit_norm_sample(frame_vec4(i, 4u), normal.w, along.y, across.y, s),
            deep_exit_norm_sample(frame_vec4(i, 5u), normal.w, along.z, across.z, s),
        );
    }
    let norm = row_total(local, vec4(samples, 0.0)).xyz / f32(DEEP_EXIT_NORM_SAMPLES);
    if local == 0u {
        table_flow_out(i, sums, flows, select(vec3(1.0), 1.0 / norm, norm > vec3(0.0)));
    }
    return exitance;
}

// Each channel's `flow_out` from patch `i`'s row sums (its law per channel in its frame).
fn channel_flows(i: u32, sums: FlowSums) -> array<vec4<f32>, 3> {
    return array(
        flow_out(sums.r, sums.total.x, frame_vec4(i, 3u)),
        flow_out(sums.g, sums.total.y, frame_vec4(i, 4u)),
        flow_out(sums.b, sums.total.z, frame_vec4(i, 5u)),
    );
}

// A channel's flow with its 1/N (all zero where it has no axis).
fn with_norm(flow: vec4<f32>, inverse_norm: f32) -> vec4<f32> {
    return vec4(flow.xyz, select(0.0, inverse_norm, any(flow.xyz != vec3(0.0))));
}

// Patch `i`'s flow per channel (`channel_flows` and `inverse_norms`) and exit lobes from its
// row's sums.
fn table_flow_out(i: u32, sums: FlowSums, flows: array<vec4<f32>, 3>, inverse_norms: vec3<f32>) {
    let at = packing.table_flow + 3u * i;
    vectors[at] = with_norm(flows[0], inverse_norms.x);
    vectors[at + 1u] = with_norm(flows[1], inverse_norms.y);
    vectors[at + 2u] = with_norm(flows[2], inverse_norms.z);
    table_lobes_of(i, frame_vec4(i, 1u).xyz, sums);
}

// `ExitLaw::set_far_lobes`: each channel's light from afar by the lobe fitted to the mean
// its lean gives for the directions it came from (`ExitLean::mean`); none without a lean.
fn table_lobes_of(i: u32, normal: vec3<f32>, sums: FlowSums) {
    let along = frame_vec4(i, 6u).xyz;
    let across = frame_vec4(i, 7u).xyz;
    let at = packing.table_lobes + 5u * i;
    if all(along == vec3(0.0)) && all(across == vec3(0.0)) {
        for (var k = 0u; k < 5u; k += 1u) {
            vectors[at + k] = vec4(0.0);
        }
        return;
    }
    let far_r = select(vec3(0.0), sums.far_r / sums.far.x, sums.far.x > 0.0);
    let far_g = select(vec3(0.0), sums.far_g / sums.far.y, sums.far.y > 0.0);
    let far_b = select(vec3(0.0), sums.far_b / sums.far.z, sums.far.z > 0.0);
    let r = exit_lobe(normal, lean_mean(normal, far_r, along.x, across.x), sums.far.x);
    let g = exit_lobe(normal, lean_mean(normal, far_g, along.y, across.y), sums.far.y);
    let b = exit_lobe(normal, lean_mean(normal, far_b, along.z, across.z), sums.far.z);
    vectors[at] = r.axis_sharpness;
    vectors[at + 1u] = g.axis_sharpness;
    vectors[at + 2u] = b.axis_sharpness;
    vectors[at + 3u] = vec4(r.norm, g.norm, b.norm, 0.0);
    vectors[at + 4u] = vec4(sums.far, 0.0);
}

// `ExitLean::mean` in one channel.
fn lean_mean(normal: vec3<f32>, came: vec3<f32>, along: f32, across: f32) -> vec3<f32> {
    return normal * along + (came - normal * dot(came, normal)) * across;
}

struct Lobe {
    axis_sharpness: vec4<f32>,
    norm: f32,
}

// The fit table's side (`FIT_CELLS` in exit_lobe.rs).
const FIT_CELLS: u32 = 64u;

// `LobeFits::lobe` (exit_lobe.rs): the lobe whose exitance-weighted mean leaving direction is
// `mean`, from the table of fits; none (norm 0) without light from afar, Lambert's for a
// zero or non-finite mean.
fn exit_lobe(normal: vec3<f32>, mean: vec3<f32>, far: f32) -> Lobe {
    if !(far > 0.0) {
        return Lobe(vec4(0.0), 0.0);
    }
    // A non-finite mean fails both comparisons.
    if !(dot(mean, mean) > 0.0 && dot(mean, mean) < 1e30) {
        return Lobe(vec4(normal, 0.0), 1.0);
    }
    let along = dot(mean, normal);
    let tangent_part = mean - along * normal;
    let across = length(tangent_part);
    // glam's `any_orthonormal_vector` (the frame's bitangent) where the mean has no
    // tangential part.
    let tangent = select(tangent_frame(normal)[1], tangent_part / across, across > 1e-6);
    let row = min(u32(clamp(along, 0.0, 1.0) * f32(FIT_CELLS)), FIT_CELLS - 1u);
    let column = min(u32(clamp(across, 0.0, 1.0) * f32(FIT_CELLS)), FIT_CELLS - 1u);
    let cell = packing.lobe_fits + 3u * (row * FIT_CELLS + column);
    let kappa = bitcast<f32>(matrices[cell]);
    let theta = bitcast<f32>(matrices[cell + 1u]);
    let norm = bitcast<f32>(matrices[cell + 2u]);
    return Lobe(vec4(cos(theta) * normal + sin(theta) * tangent, kappa), norm);
}

var<workgroup> lanes: array<vec4<f32>, 64>;
var<workgroup> flux: array<f32, 64>;
// flux(B) of a warm start's first bounce.
var<workgroup> exitance_flux: array<f32, 64>;

// The sum of `part` over the `row_lanes` threads of `local`'s row, for every thread of the
// workgroup (all of whose threads must call it: it holds barriers).
fn row_sum(local: u32, part: vec4<f32>, row_lanes: u32) -> vec4<f32> {
    lanes[local] = part;
    workgroupBarrier();
    let lane = local % row_lanes;
    for (var stride = row_lanes / 2u; stride > 0u; stride /= 2u) {
        if lane < stride {
            lanes[local] += lanes[local + stride];
        }
        workgroupBarrier();
    }
    return lanes[local - lane];
}

// This lane's share of row `row` of a scalar CSR matrix (F or the cluster means) times ΔB
// (patches, then clusters).
fn scalar_row_part(offsets: u32, columns: u32, values: u32, row: u32, lane: u32) -> vec4<f32> {
    var sum = vec4(0.0);
    let start = matrices[offsets + row];
    let end = matrices[offsets + row + 1u];
    for (var e = start + lane; e < end; e += ROW_LANES) {
        let j = matrices[columns + e];
        sum += bitcast<f32>(matrices[values + e]) * vectors[packing.delta_exitance + j];
    }
    return sum;
}

// This lane's share (every `lanes`-th entry from `lane`) of row `row` of an RGB CSR matrix
// (K, the beam table's) times the vector at `vector`.
fn rgb_row_part(offsets: u32, columns: u32, values: u32, vector: u32,
                row: u32, lane: u32, lanes: u32) -> vec4<f32> {
    var sum = vec4(0.0);
    let end = matrices[offsets + row + 1u];
    for (var e = matrices[offsets + row] + lane; e < end; e += lanes) {
        sum += rgb(values + 3u * e) * vectors[vector + matrices[columns + e]];
    }
    return sum;
}

// This lane's share of row `row` of K times ΔE.
fn scattering_row_part(row: u32, lane: u32) -> vec4<f32> {
    return rgb_row_part(packing.k_offsets, packing.k_columns, packing.k_values,
                        packing.delta_irradiance, row, lane, SCATTERING_LANES);
}

// ΔB = K ΔE (+ S⁰ on the first bounce); B += ΔB; each workgroup's share of
// flux(ΔB) = Σ A_i (ΔB.r + ΔB.g + ΔB.b) in `partials`. Warm (`warm`): the absolute flux,
// Σ A_i (|ΔB.r| + |ΔB.g| + |ΔB.b|); its first bounce is the whole map, B = K ΔE + S⁰ + T x
// and ΔB = B − B', with flux(B) in `partials` after the increments'.
fn scatter_rows(local: u32, group: u32, first: bool, warm: bool) {
    let row = group * (WORKGROUP / SCATTERING_LANES) + local / SCATTERING_LANES;
    let lane = local % SCATTERING_LANES;
    var part = vec4(0.0);
    if row < packing.patches {
        part = scattering_row_part(row, lane);
    }
    var sum = row_sum(local, part, SCATTERING_LANES);
    var own = 0.0;
    var own_exitance = 0.0;
    if row < packing.patches && lane == 0u {
        if first {
            sum += vectors[packing.direct_exitance + row] + vectors[packing.table_exitance + row];
        }
        let area = bitcast<f32>(matrices[packing.areas + row]);
        if first && warm {
            own_exitance = area * (sum.x + sum.y + sum.z);
            sum -= vectors[packing.exitance + row];
        }
        vectors[packing.exitance + row] += sum;
        // A cold start's first bounce gathers the lit faces' single scattering with B.
        if first && !warm {
            sum += vectors[packing.lit_face + row];
        }
        vectors[packing.delta_exitance + row] = sum;
        if warm {
            let size = abs(sum);
            own = area * (size.x + size.y + size.z);
        } else {
            own = area * (sum.x + sum.y + sum.z);
        }
    }
    flux[local] = own;
    exitance_flux[local] = own_exitance;
    workgroupBarrier();
    for (var stride = WORKGROUP / 2u; stride > 0u; stride /= 2u) {
        if local < stride {
            flux[local] += flux[local + stride];
            exitance_flux[local] += exitance_flux[local + stride];
        }
        workgroupBarrier();
    }
    let groups = row_groups(packing.patches, SCATTERING_LANES);
    if local == 0u && group < groups {
        partials[group] = flux[0];
        partials[groups + group] = exitance_flux[0];
    }
}

@compute @workgroup_size(64)
fn scatter_first(@builtin(local_invocation_index) local: u32,
                 @builtin(workgroup_id) group: vec3<u32>,
                 @builtin(num_workgroups) count: vec3<u32>) {
    scatter_rows(local, group_index(group, count), true, false);
}

@compute @workgroup_size(64)
fn scatter(@builtin(local_invocation_index) local: u32,
           @builtin(workgroup_id) group: vec3<u32>,
           @builtin(num_workgroups) count: vec3<u32>) {
    scatter_rows(local, group_index(group, count), false, false);
}

@compute @workgroup_size(64)
fn scatter_first_warm(@builtin(local_invocation_index) local: u32,
                      @builtin(workgroup_id) group: vec3<u32>,
                      @builtin(num_workgroups) count: vec3<u32>) {
    scatter_rows(local, group_index(group, count), true, true);
}

@compute @workgroup_size(64)
fn scatter_warm(@builtin(local_invocation_index) local: u32,
                @builtin(workgroup_id) group: vec3<u32>,
                @builtin(num_workgroups) count: vec3<u32>) {
    scatter_rows(local, group_index(group, count), false, true);
}

const DECIDE_THREADS: u32 = 256u;
var<workgroup> totals: array<f32, DECIDE_THREADS>;
var<workgroup> exitance_totals: array<f32, DECIDE_THREADS>;

// Sums the partial fluxes and decides whether the loop goes on. (One workgroup, as wide as
// WebGPU allows: each thread's loads are a serial chain, once per iteration.)
@compute @workgroup_size(256)
fn decide(@builtin(local_invocation_index) local: u32) {
    let count = row_groups(packing.patches, SCATTERING_LANES);
    var own = 0.0;
    var own_exitance = 0.0;
    for (var g = local; g < count; g += DECIDE_THREADS) {
        own += partials[g];
        own_exitance += partials[count + g];
    }
    totals[local] = own;
    exitance_totals[local] = own_exitance;
    workgroupBarrier();
    for (var stride = DECIDE_THREADS / 2u; stride > 0u; stride /= 2u) {
        if local < stride {
            totals[local] += totals[local + stride];
            exitance_totals[local] += exitance_totals[local + stride];
        }
        workgroupBarrier();
    }
    // Once stopped, the recorded rest of the loop leaves everything as it is.
    if local != 0u || state.patch_groups == 0u {
        return;
    }
    let total = totals[0];
    let warm = state.warm == 1u;
    let threshold = select(packing.threshold, packing.warm_threshold, warm);
    var go_on: bool;
    if state.first_flux < 0.0 && !warm {
        state.first_flux = total;
        state.energy_left = select(0.0, 1.0, total > 0.0);
        go_on = total > 0.0 && packing.max_iterations > 0u;
    } else if state.first_flux < 0.0 {
        // A warm start's first bounce: the whole map, counted as an iteration.
        state.first_flux = exitance_totals[0] * state.reference_share;
        state.iterations = 1u;
        state.energy_left = select(0.0, total / state.first_flux, state.first_flux > 0.0);
        go_on = state.energy_left > threshold && state.iterations < packing.max_iterations;
    } else {
        state.iterations += 1u;
        state.energy_left = total / state.first_flux;
        state.tail_ratio = select(0.0, total / state.previous_flux, state.previous_flux > 0.0);
        go_on = state.energy_left > threshold && state.iterations < packing.max_iterations;
    }
    state.previous_flux = total;
    if !go_on {
        state.patch_groups = 0u;
        state.cluster_groups = 0u;
        state.scattering_groups = 0u;
    }
}

// Row `row` of a product of a scalar CSR matrix (F or the cluster means) over `rows` rows,
// this thread's workgroup (`group` of `count`) holding WORKGROUP / ROW_LANES of them: its sum
// for every lane of the row; `owner` for the one lane that writes it. All threads call it
// (barriers).
struct RowProduct {
    row: u32,
    owner: bool,
    sum: vec4<f32>,
}

fn scalar_rows(local: u32, group: vec3<u32>, count: vec3<u32>, rows: u32,
               offsets: u32, columns: u32, values: u32) -> RowProduct {
    let row = group_index(group, count) * (WORKGROUP / ROW_LANES) + local / ROW_LANES;
    let lane = local % ROW_LANES;
    var part = vec4(0.0);
    if row < rows {
        part = scalar_row_part(offsets, columns, values, row, lane);
    }
    let sum = row_sum(local, part, ROW_LANES);
    return RowProduct(row, row < rows && lane == 0u, sum);
}

// ΔB of each far-field cluster: its members' area mean.
@compute @workgroup_size(64)
fn cluster_means(@builtin(local_invocation_index) local: u32,
                 @builtin(workgroup_id) group: vec3<u32>,
                 @builtin(num_workgroups) count: vec3<u32>) {
    let c = scalar_rows(local, group, count, packing.clusters,
                        packing.c_offsets, packing.c_columns, packing.c_values);
    if c.owner {
        vectors[packing.delta_exitance + packing.patches + c.row] = c.sum;
    }
}

// ΔE = F [ΔB, ΔB_clusters]; E += ΔE.
@compute @workgroup_size(64)
fn gather(@builtin(local_invocation_index) local: u32,
          @builtin(workgroup_id) group: vec3<u32>,
          @builtin(num_workgroups) count: vec3<u32>) {
    let i = scalar_rows(local, group, count, packing.patches,
                        packing.f_offsets, packing.f_columns, packing.f_values);
    if i.owner {
        vectors[packing.delta_irradiance + i.row] = i.sum;
        vectors[packing.irradiance + i.row] += i.sum;
    }
}

// A warm start's: ΔE = E⁰ − E_t + F [B', B'_clusters] for `scatter_first_warm`; E += F B'.
@compute @workgroup_size(64)
fn gather_warm(@builtin(local_invocation_index) local: u32,
               @builtin(workgroup_id) group: vec3<u32>,
               @builtin(num_workgroups) count: vec3<u32>) {
    let i = scalar_rows(local, group, count, packing.patches,
                        packing.f_offsets, packing.f_columns, packing.f_values);
    if i.owner {
        let scattered = vectors[packing.direct + i.row] - vectors[packing.tabled + i.row];
        vectors[packing.delta_irradiance + i.row] = scattered + i.sum;
        vectors[packing.irradiance + i.row] += i.sum;
    }
}

// After the loop: B += the geometric tail of the last ΔB, ΔB r/(1 − r) (`geometric_tail` in
// transport/solve.rs), r the last shrink of the increments' flux.
@compute @workgroup_size(64)
fn extrapolate(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= packing.patches || state.iterations == 0u {
        return;
    }
    let r = clamp(state.tail_ratio, 0.0, packing.max_tail_ratio);
    vectors[packing.exitance + i] += vectors[packing.delta_exitance + i] * (r / (1.0 - r));
}
