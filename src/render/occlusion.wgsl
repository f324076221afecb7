// Occlusion pass (paper §3.1, eqs. 3–7): per pixel, the horizon angle of each apex of its set,
// sin h = ((H − P) · n0) / |H − P| with P = P0 + n0 · dis · k for both points; the highest per
// azimuth sector; then 1/(2π) ∫ cos² h dθ (cosine-weighted) or ∫ (1 − sin h) (eq. 6).
// Mirrors `reference::occlusion`.

#import bevy_render::view::View
#import bevy_mesostructure::common::{
    MesostructureUniform, APEX_COUNT_MASK, on_screen, unpack_offset, is_connected,
}

@group(0) @binding(0) var mhm: texture_2d<f32>;
@group(0) @binding(1) var core_normal: texture_2d<f32>;
@group(0) @binding(2) var<storage, read> apex_sets: array<u32>;
@group(0) @binding(3) var occlusion_out: texture_storage_2d<r32float, write>;
@group(0) @binding(4) var<uniform> settings: MesostructureUniform;
@group(0) @binding(5) var<uniform> view: View;
@group(0) @binding(6) var mhgm: texture_2d<f32>;

const SECTORS: u32 = 8u;
const TAU: f32 = 6.283185307;

fn surface_point(p: vec2<i32>) -> vec3<f32> {
    let m = textureLoad(mhm, p, 0);
    let uv = (vec2<f32>(p) + 0.5 - view.viewport.xy) / view.viewport.zw;
    let clip = vec4<f32>(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, m.y, 1.0);
    let world = view.world_from_clip * clip;
    let n0 = textureLoad(core_normal, p, 0).xyz;
    return world.xyz / world.w + n0 * m.x;
}

// Derivative of the surface point along one screen axis: central where both neighbours are
// connected, one-sided where one is; w = 0 where none is.
fn surface_derivative(p: vec2<i32>, sp: vec3<f32>, flags: u32, plus: u32, minus: u32, o: vec2<i32>) -> vec4<f32> {
    let cp = is_connected(flags, plus);
    let cm = is_connected(flags, minus);
    if cp && cm {
        return vec4((surface_point(p + o) - surface_point(p - o)) * 0.5, 1.0);
    } else if cp {
        return vec4(surface_point(p + o) - sp, 1.0);
    } else if cm {
        return vec4(sp - surface_point(p - o), 1.0);
    }
    return vec4(0.0);
}

// N' of the mesostructure surface (see `reference::mesostructure_normal`).
fn mesostructure_normal(p: vec2<i32>, sp: vec3<f32>, n0: vec3<f32>) -> vec3<f32> {
    let flags = u32(textureLoad(mhgm, p, 0).w);
    let dx = surface_derivative(p, sp, flags, 0u, 4u, vec2(1, 0));
    let dy = surface_derivative(p, sp, flags, 2u, 6u, vec2(0, 1));
    if dx.w == 0.0 || dy.w == 0.0 {
        return n0;
    }
    let n = cross(dx.xyz, dy.xyz);
    let len = length(n);
    if !(len > 0.0) {
        return n0;
    }
    return select(n / len, -n / len, dot(n, n0) < 0.0);
}

fn sector_of(o: vec2<i32>) -> u32 {
    let a = atan2(f32(o.y), f32(o.x)) / TAU * f32(SECTORS);
    let s = i32(floor(a + 0.5));
    return u32(((s % i32(SECTORS)) + i32(SECTORS)) % i32(SECTORS));
}

@compute @workgroup_size(8, 8, 1)
fn occlusion(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = vec2<i32>(textureDimensions(mhm));
    let p = vec2<i32>(id.xy);
    if !on_screen(p, size) {
        return;
    }
    if textureLoad(mhm, p, 0).z == 0.0 {
        textureStore(occlusion_out, p, vec4<f32>(1.0));
        return;
    }
    let base = (id.y * u32(size.x) + id.x) * settings.apex_stride;
    let count = apex_sets[base] & APEX_COUNT_MASK;
    let sp = surface_point(p);
    let n0 = textureLoad(core_normal, p, 0).xyz;
    // The paper's eq. (6) measures from the core plane; the cosine-weighted form from the
    // tangent plane of the mesostructure surface.
    var n = n0;
    if settings.occlusion_form == 0u {
        n = mesostructure_normal(p, sp, n0);
    }
    var sin_h = array<f32, 8>(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for (var i = 0u; i < count; i++) {
        let o = unpack_offset(apex_sets[base + 1u + i]);
        let d = surface_point(p + o) - sp;
        let len = length(d);
        if len <= 0.0 {
            continue;
        }
        let s = clamp(dot(d, n) / len, 0.0, 1.0);
        let sector = sector_of(o);
        sin_h[sector] = max(sin_h[sector], s);
    }
    var visibility = 0.0;
    for (var s = 0u; s < SECTORS; s++) {
        if settings.occlusion_form == 1u {
            visibility += 1.0 - sin_h[s];
        } else {
            visibility += 1.0 - sin_h[s] * sin_h[s];
        }
    }
    textureStore(occlusion_out, p, vec4<f32>(visibility / f32(SECTORS)));
}
