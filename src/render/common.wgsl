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
    texture_space_horizons: u32,
    // The first directional light's bounce from texture space (`texture_bounce`, height pass).
    texture_space_bounce: u32,
    // Side of the pixel block that shares one apex set (1, 2 or 4: the working resolution).
    apex_block: u32,
    // λa, λs, λd of eq. (2), spare.
    weights: vec4<f32>,
    // (cos θ_i, sin θ_i) of the indirect sample directions, two per vector.
    directions: array<vec4<f32>, 8>,
}

// P0 of pixel p: the core point (no height), its NDC depth back to the world.
fn core_point(world_from_clip: mat4x4<f32>, viewport: vec4<f32>, p: vec2<i32>, depth: f32) -> vec3<f32> {
    let uv = (vec2<f32>(p) + 0.5 - viewport.xy) / viewport.zw;
    let world = world_from_clip * vec4<f32>(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, depth, 1.0);
    return world.xyz / world.w;
}

const FLAG_VALID: u32 = 1u;
const FLAG_SCREEN_EDGE: u32 = 2u;
const FLAG_OBJECT_EDGE: u32 = 4u;
const FLAG_DEPTH_EDGE: u32 = 8u;
const FLAG_BOUNDARY: u32 = 14u;
const CONNECTIVITY_SHIFT: u32 = 8u;

// The MHGM texel (`Rg32Uint`): x the height's f32 bits; y the flags above (bits 0–15) and the
// gradient's direction quantised to a neighbour index (bits 16–19; 8: zero gradient), which is
// all the apex search takes from the gradient. Mirrors `reference::gradient`.
const ASCENT_SHIFT: u32 = 16u;
const NO_ASCENT: u32 = 8u;

fn mhgm_height(texel: vec4<u32>) -> f32 {
    return bitcast<f32>(texel.x);
}

fn mhgm_flags(texel: vec4<u32>) -> u32 {
    return texel.y & 0xffffu;
}

fn mhgm_ascent(texel: vec4<u32>) -> u32 {
    return texel.y >> ASCENT_SHIFT;
}

const APEX_COUNT_MASK: u32 = 0x3fu;
const APEX_DIRECT_PRESENT: u32 = 64u;
const APEX_TRUNCATED: u32 = 128u;
const APEX_BOUNDARY_SHIFT: u32 = 8u;
const APEX_MIN_RISE: f32 = 1.0e-6;
// Position of the searched pixel inside its block (x in bits 25–26, y in 27–28).
const APEX_ORIGIN_SHIFT: u32 = 25u;

// The 8 neighbours in the order of the connectivity bits (y down): (1, 0), (1, 1), (0, 1),
// (−1, 1), (−1, 0), (−1, −1), (0, −1), (1, −1). By arithmetic, not a table: a variable index
// into a private array costs local memory on some GPUs, in the apex search's hot loops.
fn neighbour_offset(dir: u32) -> vec2<i32> {
    return vec2<i32>(
        i32(dir == 0u || dir == 1u || dir == 7u) - i32(dir >= 3u && dir <= 5u),
        i32(dir >= 1u && dir <= 3u) - i32(dir >= 5u && dir <= 7u),
    );
}

// The inverse, by the step's place (y + 1) · 3 + x + 1 in the 3×3 block: its neighbour index,
// a nibble each for places 0–7 (place 8, the step (1, 1), is neighbour 1); 8 for (0, 0) and for
// steps that are not a neighbour's.
const NEIGHBOUR_OF_PLACE: u32 = 0x23084765u;

fn neighbour_index(step: vec2<i32>) -> u32 {
    if any(abs(step) > vec2(1)) {
        return 8u;
    }
    let place = u32((step.y + 1) * 3 + step.x + 1);
    if place == 8u {
        return 1u;
    }
    return extractBits(NEIGHBOUR_OF_PLACE, place * 4u, 4u);
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

// Apex sets are searched once per `apex_block`² block of pixels (the working resolution): from
// the block's first mesostructure pixel, its origin. Every pixel of the block shares that set,
// whose offsets are relative to the origin. Index of the set that covers pixel p.
fn apex_base(settings: MesostructureUniform, p: vec2<i32>, size: vec2<i32>) -> u32 {
    let b = settings.apex_block;
    let blocks_x = (u32(size.x) + b - 1u) / b;
    let q = vec2<u32>(p) / b;
    return (q.y * blocks_x + q.x) * settings.apex_stride;
}

// The pixel the set covering p was searched from, given the set's header.
fn apex_origin(settings: MesostructureUniform, p: vec2<i32>, header: u32) -> vec2<i32> {
    let b = i32(settings.apex_block);
    let inside = vec2<i32>(
        i32((header >> APEX_ORIGIN_SHIFT) & 3u),
        i32((header >> (APEX_ORIGIN_SHIFT + 2u)) & 3u),
    );
    return (p / b) * b + inside;
}

// Whether pixel p may use the apex set searched from `origin`: the same object, no depth jump
// between them (the threshold of one pixel step, scaled by the block's side).
fn shares_apex_set(
    mhm: texture_2d<f32>,
    settings: MesostructureUniform,
    p: vec2<i32>,
    origin: vec2<i32>,
) -> bool {
    if all(p == origin) {
        return true;
    }
    let a = textureLoad(mhm, p, 0);
    let o = textureLoad(mhm, origin, 0);
    return a.z == o.z
        && abs(a.y - o.y) <= settings.depth_relative * f32(settings.apex_block) * max(a.y, o.y);
}

// Pixel p's apex set: where its offsets start in the buffer, how many there are (0 where p may
// not share its block's set), and what to add to an unpacked offset to make it relative to p.
struct ApexSetOf {
    first: u32,
    count: u32,
    shift: vec2<i32>,
}

fn apex_set_of(
    mhm: texture_2d<f32>,
    settings: MesostructureUniform,
    p: vec2<i32>,
    header: u32,
    base: u32,
) -> ApexSetOf {
    let origin = apex_origin(settings, p, header);
    let count = select(0u, header & APEX_COUNT_MASK, shares_apex_set(mhm, settings, p, origin));
    return ApexSetOf(base + 1u, count, origin - p);
}
