// Seed 001's per-frame transport on the GPU: B = K E⁰ + S⁰ + K F B, iterated as
//   ΔB₀ = K E⁰ + S⁰;  repeat { ΔB_c = cluster means of ΔB;  ΔE = F [ΔB, ΔB_c];  E += ΔE;
//                         ΔB = K ΔE;  B += ΔB }  until flux(ΔB) ≤ threshold · flux(ΔB₀).
// The same arithmetic as `EnergyTransport::solve` (src/translucency/transport.rs). The loop is
// recorded max_iterations times; `decide` zeroes the indirect dispatch arguments once the
// energy still moving is below the threshold, so the rest of the recorded loop costs nothing.

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
}

struct State {
    // Indirect dispatch arguments (x, y, z; scalars, so the two sets pack without padding):
    // one thread per patch, one per cluster.
    patch_groups: u32,
    patch_groups_y: u32,
    patch_groups_z: u32,
    cluster_groups: u32,
    cluster_groups_y: u32,
    cluster_groups_z: u32,
    iterations: u32,
    first_flux: f32,
    energy_left: f32,
}

@group(0) @binding(0) var<uniform> packing: Layout;
@group(0) @binding(1) var<storage, read> matrices: array<u32>;
@group(0) @binding(2) var<storage, read_write> vectors: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> partials: array<f32>;
// Apart from the rest: the products read it as their indirect arguments, which may not be
// bound for writing in the same dispatch.
@group(1) @binding(0) var<storage, read_write> state: State;

const WORKGROUP: u32 = 64u;

fn groups(n: u32) -> u32 {
    return (n + WORKGROUP - 1u) / WORKGROUP;
}

// E = E⁰, ΔE = E⁰, B = 0; the loop's state reset.
@compute @workgroup_size(64)
fn seed(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i == 0u {
        state.patch_groups = groups(packing.patches);
        state.patch_groups_y = 1u;
        state.patch_groups_z = 1u;
        state.cluster_groups = groups(packing.clusters);
        state.cluster_groups_y = 1u;
        state.cluster_groups_z = 1u;
        state.iterations = 0u;
        state.first_flux = -1.0;
        state.energy_left = 1.0;
    }
    if i >= packing.patches {
        return;
    }
    let e = vectors[packing.direct + i];
    vectors[packing.irradiance + i] = e;
    vectors[packing.delta_irradiance + i] = e;
    vectors[packing.exitance + i] = vec4(0.0);
}

var<workgroup> flux: array<f32, 64>;

// ΔB = K ΔE (+ S⁰ on the first bounce); B += ΔB; each workgroup's share of
// flux(ΔB) = Σ A_i (ΔB.r + ΔB.g + ΔB.b).
fn scatter_rows(i: u32, local: u32, group: u32, first: bool) {
    var own = 0.0;
    if i < packing.patches {
        var sum = vec4(0.0);
        let start = matrices[packing.k_offsets + i];
        let end = matrices[packing.k_offsets + i + 1u];
        for (var e = start; e < end; e += 1u) {
            let j = matrices[packing.k_columns + e];
            let v = packing.k_values + 3u * e;
            let k = vec4(bitcast<f32>(matrices[v]), bitcast<f32>(matrices[v + 1u]),
                         bitcast<f32>(matrices[v + 2u]), 0.0);
            sum += k * vectors[packing.delta_irradiance + j];
        }
        if first {
            sum += vectors[packing.direct_exitance + i];
        }
        vectors[packing.delta_exitance + i] = sum;
        vectors[packing.exitance + i] += sum;
        own = bitcast<f32>(matrices[packing.areas + i]) * (sum.x + sum.y + sum.z);
    }
    flux[local] = own;
    workgroupBarrier();
    for (var stride = WORKGROUP / 2u; stride > 0u; stride /= 2u) {
        if local < stride {
            flux[local] += flux[local + stride];
        }
        workgroupBarrier();
    }
    if local == 0u {
        partials[group] = flux[0];
    }
}

@compute @workgroup_size(64)
fn scatter_first(@builtin(global_invocation_id) id: vec3<u32>,
                 @builtin(local_invocation_index) local: u32,
                 @builtin(workgroup_id) group: vec3<u32>) {
    scatter_rows(id.x, local, group.x, true);
}

@compute @workgroup_size(64)
fn scatter(@builtin(global_invocation_id) id: vec3<u32>,
           @builtin(local_invocation_index) local: u32,
           @builtin(workgroup_id) group: vec3<u32>) {
    scatter_rows(id.x, local, group.x, false);
}

// Sums the partial fluxes and decides whether the loop goes on.
@compute @workgroup_size(64)
fn decide(@builtin(local_invocation_index) local: u32) {
    let count = groups(packing.patches);
    var own = 0.0;
    for (var g = local; g < count; g += WORKGROUP) {
        own += partials[g];
    }
    flux[local] = own;
    workgroupBarrier();
    for (var stride = WORKGROUP / 2u; stride > 0u; stride /= 2u) {
        if local < stride {
            flux[local] += flux[local + stride];
        }
        workgroupBarrier();
    }
    // Once stopped, the recorded rest of the loop leaves everything as it is.
    if local != 0u || state.patch_groups == 0u {
        return;
    }
    let total = flux[0];
    var go_on: bool;
    if state.first_flux < 0.0 {
        state.first_flux = total;
        state.energy_left = select(0.0, 1.0, total > 0.0);
        go_on = total > 0.0 && packing.max_iterations > 0u;
    } else {
        state.iterations += 1u;
        state.energy_left = total / state.first_flux;
        go_on = state.energy_left > packing.threshold && state.iterations < packing.max_iterations;
    }
    if !go_on {
        state.patch_groups = 0u;
        state.cluster_groups = 0u;
    }
}

// Row `row` of a scalar CSR matrix (F or the cluster means) times ΔB (patches, then clusters).
fn scalar_row(offsets: u32, columns: u32, values: u32, row: u32) -> vec4<f32> {
    var sum = vec4(0.0);
    let start = matrices[offsets + row];
    let end = matrices[offsets + row + 1u];
    for (var e = start; e < end; e += 1u) {
        let j = matrices[columns + e];
        sum += bitcast<f32>(matrices[values + e]) * vectors[packing.delta_exitance + j];
    }
    return sum;
}

// ΔB of each far-field cluster: its members' area mean.
@compute @workgroup_size(64)
fn cluster_means(@builtin(global_invocation_id) id: vec3<u32>) {
    let c = id.x;
    if c >= packing.clusters {
        return;
    }
    vectors[packing.delta_exitance + packing.patches + c] =
        scalar_row(packing.c_offsets, packing.c_columns, packing.c_values, c);
}

// ΔE = F [ΔB, ΔB_clusters]; E += ΔE.
@compute @workgroup_size(64)
fn gather(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= packing.patches {
        return;
    }
    let sum = scalar_row(packing.f_offsets, packing.f_columns, packing.f_values, i);
    vectors[packing.delta_irradiance + i] = sum;
    vectors[packing.irradiance + i] += sum;
}
