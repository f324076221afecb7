// The mesostructure surface seen from the screen, shared by the occlusion and lighting passes:
// surface points (eq. 7), the surface normal N' and the azimuth sectors of the horizons.
// Mirrors `reference::{surface_point, mesostructure_normal, sector_of}`. The images and the
// view are parameters, so each pass binds them where its layout has them.
#define_import_path bevy_mesostructure::surface

#import bevy_mesostructure::common::{is_connected, core_point, mhgm_flags}

// Azimuth sectors of the horizons (`reference::OCCLUSION_SECTORS`).
const SECTORS: u32 = 8u;
const TAU: f32 = 6.283185307;

// P = P0 + n0 · dis · k of pixel p: the core point from the NDC depth, lifted by the height.
fn surface_point(
    mhm: texture_2d<f32>,
    core_normal: texture_2d<f32>,
    world_from_clip: mat4x4<f32>,
    viewport: vec4<f32>,
    p: vec2<i32>,
) -> vec3<f32> {
    let m = textureLoad(mhm, p, 0);
    return core_point(world_from_clip, viewport, p, m.y) + textureLoad(core_normal, p, 0).xyz * m.x;
}

// Derivative of the surface point along one screen axis: central where both neighbours are
// connected, one-sided where one is; w = 0 where none is.
fn surface_derivative(
    mhm: texture_2d<f32>,
    core_normal: texture_2d<f32>,
    world_from_clip: mat4x4<f32>,
    viewport: vec4<f32>,
    p: vec2<i32>,
    sp: vec3<f32>,
    flags: u32,
    plus: u32,
    minus: u32,
    o: vec2<i32>,
) -> vec4<f32> {
    let cp = is_connected(flags, plus);
    let cm = is_connected(flags, minus);
    if cp && cm {
        let ahead = surface_point(mhm, core_normal, world_from_clip, viewport, p + o);
        let behind = surface_point(mhm, core_normal, world_from_clip, viewport, p - o);
        return vec4((ahead - behind) * 0.5, 1.0);
    } else if cp {
        return vec4(surface_point(mhm, core_normal, world_from_clip, viewport, p + o) - sp, 1.0);
    } else if cm {
        return vec4(sp - surface_point(mhm, core_normal, world_from_clip, viewport, p - o), 1.0);
    }
    return vec4(0.0);
}

// N' of the mesostructure surface at p (surface point sp, core normal n0): the cross product of
// the screen-space derivatives of the surface points, oriented like n0; n0 where an axis has no
// connected neighbour.
fn mesostructure_normal(
    mhm: texture_2d<f32>,
    core_normal: texture_2d<f32>,
    mhgm: texture_2d<u32>,
    world_from_clip: mat4x4<f32>,
    viewport: vec4<f32>,
    p: vec2<i32>,
    sp: vec3<f32>,
    n0: vec3<f32>,
) -> vec3<f32> {
    let flags = mhgm_flags(textureLoad(mhgm, p, 0));
    let dx = surface_derivative(mhm, core_normal, world_from_clip, viewport, p, sp, flags, 0u, 4u, vec2(1, 0));
    let dy = surface_derivative(mhm, core_normal, world_from_clip, viewport, p, sp, flags, 2u, 6u, vec2(0, 1));
    if dx.w == 0.0 || dy.w == 0.0 {
        return n0;
    }
    let n = cross(dx.xyz, dy.xyz);
    let len = length(n);
    if !(len > 0.0) {
        return n0;
    }
    return limit_tilt(select(n / len, -n / len, dot(n, n0) < 0.0), n0);
}

// Cosine of the largest angle N' may make with n0. Steeper walls (cliffs a pixel or two wide)
// have no reliable tangent plane on screen, and horizons sorted by screen azimuth stop
// describing a hemisphere about a near-horizontal normal; past this tilt N' is turned back to
// it. Mirrors `reference::MAX_NORMAL_TILT_COS`.
const MAX_NORMAL_TILT_COS: f32 = 0.5;

fn limit_tilt(n: vec3<f32>, n0: vec3<f32>) -> vec3<f32> {
    let c = dot(n, n0);
    if c >= MAX_NORMAL_TILT_COS {
        return n;
    }
    let side = n - n0 * c;
    let len = length(side);
    if !(len > 0.0) {
        return n0;
    }
    return n0 * MAX_NORMAL_TILT_COS + side / len * sqrt(1.0 - MAX_NORMAL_TILT_COS * MAX_NORMAL_TILT_COS);
}

// The azimuth of a screen-space direction, in sectors (sector i is centred on i).
fn sector_position(o: vec2<f32>) -> f32 {
    return atan2(o.y, o.x) / TAU * f32(SECTORS);
}

fn wrap_sector(s: i32) -> u32 {
    return u32(((s % i32(SECTORS)) + i32(SECTORS)) % i32(SECTORS));
}

// The sector a screen-space offset falls in: round(atan2(dy, dx) / 2π · N) mod N.
fn sector_of(o: vec2<i32>) -> u32 {
    return wrap_sector(i32(floor(sector_position(vec2<f32>(o)) + 0.5)));
}

// The sector record: what the occlusion pass stores per pixel so that the lighting and bleeding
// passes read a pixel's horizons and N' instead of rebuilding them from its apex set (each
// found once per pixel). One Rgba32Uint texel: x, y the sine of each sector's horizon above the
// tangent plane of N' as 8-bit unorm (sectors 0–3 and 4–7, byte i % 4); z bits 0–21 N' in
// octahedral form (two 11-bit unorm); z bits 22–31 and w bits 0–29 the index in the apex set of
// the apex that sets each sector's horizon (5 bits each: sectors 0–1 in z, 2–7 in w), which the
// bleeding gather walks to. Mirrors `reference::sector_record`.
const SINE_LEVELS: f32 = 255.0;
const NORMAL_BITS: u32 = 11u;
const APEX_INDEX_BITS: u32 = 5u;

fn quantize_unorm(v: f32, levels: f32) -> u32 {
    return u32(floor(0.5 + levels * clamp(v, 0.0, 1.0)));
}

// The unit vector n as a point of the octahedron unfolded onto [-1, 1]².
fn octahedral_encode(n: vec3<f32>) -> vec2<f32> {
    let p = n.xy / (abs(n.x) + abs(n.y) + abs(n.z));
    if n.z >= 0.0 {
        return p;
    }
    return (1.0 - abs(p.yx)) * select(vec2(-1.0), vec2(1.0), p >= vec2(0.0));
}

fn octahedral_decode(e: vec2<f32>) -> vec3<f32> {
    var n = vec3(e, 1.0 - abs(e.x) - abs(e.y));
    let fold = max(-n.z, 0.0);
    n.x += select(fold, -fold, n.x >= 0.0);
    n.y += select(fold, -fold, n.y >= 0.0);
    return normalize(n);
}

// The horizons of the 8 sectors (sines, sectors 0–3 then 4–7), kept in vectors rather than a
// private array (a variable index into one costs local memory on some GPUs): what the occlusion
// pass accumulates over a pixel's apexes, with the index of each sector's highest apex.
struct SectorMaxima {
    sin_h: array<vec4<f32>, 2>,
    apex: array<vec4<u32>, 2>,
}

// Raises the horizon of `sector` to `sin_h` (set by the apex at `index`) where that is higher,
// without a variable index: each half compares its four lanes with the sector.
fn raise_sector_horizon(m: ptr<function, SectorMaxima>, sector: u32, sin_h: f32, index: u32) {
    let lanes = vec4<u32>(0u, 1u, 2u, 3u);
    let lo = (lanes == vec4(sector)) & (vec4(sin_h) > (*m).sin_h[0]);
    let hi = (lanes + 4u == vec4(sector)) & (vec4(sin_h) > (*m).sin_h[1]);
    (*m).sin_h[0] = select((*m).sin_h[0], vec4(sin_h), lo);
    (*m).sin_h[1] = select((*m).sin_h[1], vec4(sin_h), hi);
    (*m).apex[0] = select((*m).apex[0], vec4(index), lo);
    (*m).apex[1] = select((*m).apex[1], vec4(index), hi);
}

// The same for horizons kept without their apexes (eq. (6)'s, about n0).
fn raise_sector_maximum(v: ptr<function, array<vec4<f32>, 2>>, sector: u32, sin_h: f32) {
    let lanes = vec4<u32>(0u, 1u, 2u, 3u);
    (*v)[0] = select((*v)[0], max((*v)[0], vec4(sin_h)), lanes == vec4(sector));
    (*v)[1] = select((*v)[1], max((*v)[1], vec4(sin_h)), lanes + 4u == vec4(sector));
}

// The visibility of each sector under the form's integral, averaged (eqs. 3–6).
fn sectors_visibility(sin_h: array<vec4<f32>, 2>, paper_form: bool) -> f32 {
    var v: vec4<f32>;
    if paper_form {
        v = 2.0 - sin_h[0] - sin_h[1];
    } else {
        v = 2.0 - sin_h[0] * sin_h[0] - sin_h[1] * sin_h[1];
    }
    return dot(v, vec4(1.0)) / f32(SECTORS);
}

fn pack_sector_record(m: SectorMaxima, n: vec3<f32>) -> vec4<u32> {
    let levels = f32((1u << NORMAL_BITS) - 1u);
    var r = vec4<u32>(0u);
    for (var s = 0u; s < 4u; s++) {
        r.x = insertBits(r.x, quantize_unorm(m.sin_h[0][s], SINE_LEVELS), s * 8u, 8u);
        r.y = insertBits(r.y, quantize_unorm(m.sin_h[1][s], SINE_LEVELS), s * 8u, 8u);
    }
    let e = octahedral_encode(n) * 0.5 + 0.5;
    r.z = quantize_unorm(e.x, levels) | (quantize_unorm(e.y, levels) << NORMAL_BITS);
    r.z = insertBits(r.z, m.apex[0].x, 2u * NORMAL_BITS, APEX_INDEX_BITS);
    r.z = insertBits(r.z, m.apex[0].y, 2u * NORMAL_BITS + APEX_INDEX_BITS, APEX_INDEX_BITS);
    r.w = m.apex[0].z | (m.apex[0].w << APEX_INDEX_BITS);
    for (var s = 0u; s < 4u; s++) {
        r.w = insertBits(r.w, m.apex[1][s], (2u + s) * APEX_INDEX_BITS, APEX_INDEX_BITS);
    }
    return r;
}

fn sector_normal(record: vec4<u32>) -> vec3<f32> {
    let levels = f32((1u << NORMAL_BITS) - 1u);
    let e = vec2(
        f32(extractBits(record.z, 0u, NORMAL_BITS)),
        f32(extractBits(record.z, NORMAL_BITS, NORMAL_BITS)),
    ) / levels;
    return octahedral_decode(e * 2.0 - 1.0);
}

// Sine of the horizon of `sector` (0 = open).
fn sector_sine(record: vec4<u32>, sector: u32) -> f32 {
    let word = select(record.x, record.y, sector >= 4u);
    return f32(extractBits(word, (sector & 3u) * 8u, 8u)) / SINE_LEVELS;
}

// Index in the apex set of the apex that sets the horizon of `sector` (meaningful where the
// sector's sine is above 0).
fn sector_apex(record: vec4<u32>, sector: u32) -> u32 {
    if sector < 2u {
        return extractBits(record.z, 2u * NORMAL_BITS + sector * APEX_INDEX_BITS, APEX_INDEX_BITS);
    }
    return extractBits(record.w, (sector - 2u) * APEX_INDEX_BITS, APEX_INDEX_BITS);
}
