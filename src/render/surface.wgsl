// The mesostructure surface seen from the screen, shared by the occlusion and lighting passes:
// surface points (eq. 7), the surface normal N' and the azimuth sectors of the horizons.
// Mirrors `reference::{surface_point, mesostructure_normal, sector_of}`. The images and the
// view are parameters, so each pass binds them where its layout has them.
#define_import_path bevy_mesostructure::surface

#import bevy_mesostructure::common::is_connected

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
    let uv = (vec2<f32>(p) + 0.5 - viewport.xy) / viewport.zw;
    let world = world_from_clip * vec4<f32>(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, m.y, 1.0);
    return world.xyz / world.w + textureLoad(core_normal, p, 0).xyz * m.x;
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
    mhgm: texture_2d<f32>,
    world_from_clip: mat4x4<f32>,
    viewport: vec4<f32>,
    p: vec2<i32>,
    sp: vec3<f32>,
    n0: vec3<f32>,
) -> vec3<f32> {
    let flags = u32(textureLoad(mhgm, p, 0).w);
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
