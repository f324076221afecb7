// Shared by the mesostructure passes: the camera settings, the MHGM flags and the apex-set
// layout. Mirrors `src/reference` (the CPU oracle) and `src/settings.rs`.
#define_import_path bevy_mesostructure::common

struct MesostructureUniform {
    apex_directions: u32,
    max_ascent_steps: u32,
    max_walk: u32,
    horizon_search_steps: u32,
    depth_relative: f32,
    depth_slope_factor: f32,
    debug_view: u32,
    apex_stride: u32,
    occlusion_form: u32,
    occlusion_enabled: u32,
    micro_shadows: u32,
    micro_shadow_softness: f32,
    bump_mapping: u32,
    bleeding_enabled: u32,
    bleeding_samples: u32,
    coarse_occlusion: u32,
    // λa, λs, λd of eq. (2), spare.
    weights: vec4<f32>,
    // (cos θ_i, sin θ_i) of the indirect sample directions, two per vector.
    directions: array<vec4<f32>, 8>,
}

const FLAG_VALID: u32 = 1u;
const FLAG_SCREEN_EDGE: u32 = 2u;
const FLAG_OBJECT_EDGE: u32 = 4u;
const FLAG_DEPTH_EDGE: u32 = 8u;
const FLAG_BOUNDARY: u32 = 14u;
const CONNECTIVITY_SHIFT: u32 = 8u;

const APEX_COUNT_MASK: u32 = 0x3fu;
const APEX_DIRECT_PRESENT: u32 = 64u;
const APEX_TRUNCATED: u32 = 128u;
const APEX_BOUNDARY_SHIFT: u32 = 8u;
const APEX_MIN_RISE: f32 = 1.0e-6;

// The 8 neighbours in the order of the connectivity bits (y down).
fn neighbour_offset(dir: u32) -> vec2<i32> {
    var offsets = array<vec2<i32>, 8>(
        vec2(1, 0), vec2(1, 1), vec2(0, 1), vec2(-1, 1),
        vec2(-1, 0), vec2(-1, -1), vec2(0, -1), vec2(1, -1),
    );
    return offsets[dir];
}

fn on_screen(p: vec2<i32>, size: vec2<i32>) -> bool {
    return all(p >= vec2(0)) && all(p < size);
}

fn is_connected(flags: u32, dir: u32) -> bool {
    return ((flags >> (CONNECTIVITY_SHIFT + dir)) & 1u) == 1u;
}

// An apex offset (dx, dy) as two i16 in one word.
fn pack_offset(o: vec2<i32>) -> u32 {
    return (u32(o.x) & 0xffffu) | (u32(o.y) << 16u);
}

fn unpack_offset(w: u32) -> vec2<i32> {
    return vec2<i32>(i32(w << 16u) >> 16u, i32(w) >> 16u);
}

fn sample_direction(settings: MesostructureUniform, i: u32) -> vec2<f32> {
    let v = settings.directions[i / 2u];
    return select(v.zw, v.xy, i % 2u == 0u);
}
