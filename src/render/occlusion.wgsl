// Occlusion pass (paper §3.1, eqs. 3–7): per pixel, the horizon angle of each apex of its set,
// sin h = ((H − P) · n0) / |H − P| with P = P0 + n0 · dis · k for both points; the highest per
// azimuth sector; then 1/(2π) ∫ cos² h dθ (cosine-weighted) or ∫ (1 − sin h) (eq. 6).
// Mirrors `reference::occlusion`.

#import bevy_render::view::View
#import bevy_mesostructure::common::{
    MesostructureUniform, APEX_COUNT_MASK, on_screen, unpack_offset,
}
#import bevy_mesostructure::surface
#import bevy_mesostructure::surface::{SECTORS, sector_of}

@group(0) @binding(0) var mhm: texture_2d<f32>;
@group(0) @binding(1) var core_normal: texture_2d<f32>;
@group(0) @binding(2) var<storage, read> apex_sets: array<u32>;
@group(0) @binding(3) var occlusion_out: texture_storage_2d<r32float, write>;
@group(0) @binding(4) var<uniform> settings: MesostructureUniform;
@group(0) @binding(5) var<uniform> view: View;
@group(0) @binding(6) var mhgm: texture_2d<f32>;

fn surface_point(p: vec2<i32>) -> vec3<f32> {
    return surface::surface_point(mhm, core_normal, view.world_from_clip, view.viewport, p);
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
        n = surface::mesostructure_normal(
            mhm, core_normal, mhgm, view.world_from_clip, view.viewport, p, sp, n0);
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
