// Bleeding gather (paper §3.3, eq. 8). For each sector of the pixel's apex set, the path from P
// to the apex that bounds that sector's horizon is the part of the surface that P sees there
// instead of the sky; `bleeding_samples` points S along it, seen from P at rising elevations,
// each stand for the band of elevation between the previous visible sample and themselves:
// dω·cos = (sin² e_j − sin² e_{j−1}) / 2 · Δθ, which is eq. (8)'s cos_P · cos_S · ΔA / |PS|²
// with ΔA the area the sample stands for [beyond: area-weighted, as SSDO does]. Samples that
// face away from P, or that nearer samples hide, give nothing. S's radiance is its lit colour in
// the opaque image (one bounce: direct, ambient and emitted light of S). Written:
// λd · ρ_P / π · E_P, the radiance added to P. Only blocked directions are gathered, which is
// eq. (2)'s (1 − V). With WRITE_VIEW_TARGET the pass also writes the view's next main image:
// the lit image plus the bleeding, every pixel (Bevy's post-process ping-pong), so no
// fullscreen fragment pass composites it (fragment work is the scarce kind on some GPUs).

#import bevy_render::view::View
#import bevy_pbr::pbr_deferred_types::{unpack_unorm4x8_, unpack_flags, DEFERRED_FLAGS_UNLIT_BIT}
#import bevy_mesostructure::common::{
    MesostructureUniform, on_screen, unpack_offset, apex_base, apex_set_of,
}
#import bevy_mesostructure::surface
#import bevy_mesostructure::surface::{SECTORS, TAU, sector_sine, sector_apex, sector_normal}

@group(0) @binding(0) var lit: texture_2d<f32>;
@group(0) @binding(1) var mhm: texture_2d<f32>;
@group(0) @binding(2) var core_normal: texture_2d<f32>;
@group(0) @binding(3) var bump_normal: texture_2d<f32>;
@group(0) @binding(4) var<storage, read> apex_sets: array<u32>;
@group(0) @binding(5) var gbuffer: texture_2d<u32>;
@group(0) @binding(6) var bleeding_out: texture_storage_2d<rgba16float, write>;
@group(0) @binding(7) var<uniform> settings: MesostructureUniform;
@group(0) @binding(8) var<uniform> view: View;
// The occlusion pass's sector record of each pixel (`surface.wgsl`): N', each sector's horizon
// and the apex that sets it.
@group(0) @binding(9) var sector_horizons: texture_2d<u32>;
#ifdef WRITE_VIEW_TARGET
// The view's other main image, which becomes its main image after this pass.
@group(0) @binding(10) var view_out: texture_storage_2d<rgba16float, write>;
#endif

const PI: f32 = 3.141592653589793;

fn surface_point(p: vec2<i32>) -> vec3<f32> {
    return surface::surface_point(mhm, core_normal, view.world_from_clip, view.viewport, p);
}

// The diffuse albedo ρ of P from Bevy's G-buffer (layout of `pbr_input_from_deferred_gbuffer`:
// sRGB-ish base colour as pow 2.2 in .r, metallic in the second byte of .b); 0 for unlit.
fn diffuse_albedo(p: vec2<i32>) -> vec3<f32> {
    let g = textureLoad(gbuffer, p, 0);
    if (unpack_flags(g.a) & DEFERRED_FLAGS_UNLIT_BIT) != 0u {
        return vec3(0.0);
    }
    let base = pow(unpack_unorm4x8_(g.r).rgb, vec3(2.2));
    let metallic = unpack_unorm4x8_(g.b).g;
    return base * (1.0 - metallic);
}

// The normal a sample S faces with: its bump-mapped normal, or n0 where it has none.
fn sample_normal(q: vec2<i32>) -> vec3<f32> {
    let b = textureLoad(bump_normal, q, 0).xyz;
    if dot(b, b) > 0.5 {
        return normalize(b);
    }
    return textureLoad(core_normal, q, 0).xyz;
}

@compute @workgroup_size(8, 8, 1)
fn bleeding(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = vec2<i32>(textureDimensions(mhm));
    let p = vec2<i32>(id.xy);
    if !on_screen(p, size) {
        return;
    }
    var added = vec3(0.0);
    if textureLoad(mhm, p, 0).z == 0.0 {
        textureStore(bleeding_out, p, vec4(0.0));
    } else {
        added = gather(p, size);
        textureStore(bleeding_out, p, vec4(added, 1.0));
    }
#ifdef WRITE_VIEW_TARGET
    let here = textureLoad(lit, p, 0);
    textureStore(view_out, p, vec4(here.rgb + added, here.a));
#endif
}

// The bleeding radiance added to mesostructure pixel `p`.
fn gather(p: vec2<i32>, size: vec2<i32>) -> vec3<f32> {
    let albedo = diffuse_albedo(p);
    let base = apex_base(settings, p, size);
    let apexes = apex_set_of(mhm, settings, p, apex_sets[base], base);
    let sp = surface_point(p);
    // Per sector, the apex with the highest horizon (as the occlusion pass found it).
    let record = textureLoad(sector_horizons, p, 0);
    let n = sector_normal(record);
    var irradiance = vec3(0.0);
    // Σ (sin² e_j − sin² e_{j−1}) / 2 over the visible samples: the cosine-weighted solid angle
    // the gather covered, per unit of Δθ.
    var covered = 0.0;
    let samples = max(settings.bleeding_samples, 1u);
    for (var sector = 0u; sector < SECTORS; sector++) {
        if sector_sine(record, sector) <= 0.0 || all(albedo == vec3(0.0)) {
            continue;
        }
        let index = sector_apex(record, sector);
        let o = vec2<f32>(unpack_offset(apex_sets[apexes.first + index]) + apexes.shift);
        var seen = 0.0; // sine of the highest elevation so far: what lies below is hidden
        var last = vec2(0);
        for (var j = 1u; j <= samples; j++) {
            let q_offset = vec2<i32>(round(o * f32(j) / f32(samples)));
            if all(q_offset == last) {
                continue;
            }
            last = q_offset;
            let q = p + q_offset;
            if !on_screen(q, size) || textureLoad(mhm, q, 0).z == 0.0 {
                break;
            }
            let d = surface_point(q) - sp;
            let len = length(d);
            if len <= 0.0 {
                continue;
            }
            let s = dot(d, n) / len;
            if s <= seen {
                continue;
            }
            // S must face P (eq. 8's max(0, SP · N_S)); a sample seen from behind still hides
            // what lies beyond it but sends nothing.
            if dot(sample_normal(q), -d) > 0.0 {
                let radiance = textureLoad(lit, q, 0).rgb;
                irradiance += radiance * (s * s - seen * seen) * 0.5;
            }
            covered += (s * s - seen * seen) * 0.5;
            seen = s;
        }
    }
    irradiance *= TAU / f32(SECTORS);
    // Area-correct bounce: the screen-space horizons see too little of the surface around P
    // (the occlusion they give is too open, docs/accuracy.md), so the gather stands for the
    // mean radiance of what P sees instead of the sky, and the texture-space occlusion says how
    // much that is: irradiance = mean radiance · π (1 − AO) (cosine-weighted blocked solid
    // angle), with the gather's own blocked fraction `covered · Δθ / π` in the denominator.
    // No cap: irradiance / gathered is a weighted mean of the samples' radiance, so the result
    // never exceeds the brightest sample's radiance times π (1 − AO), however little the gather
    // covered. (A cap of 4 had kept minified and oblique views' bounce at 0.38–0.55 of the
    // truth: there the screen-space gather covers a sliver; docs/accuracy.md.)
    let texture_space = textureLoad(bump_normal, p, 0).w;
    let gathered = covered * TAU / f32(SECTORS) / PI;
    if settings.texture_space_horizons != 0u && texture_space >= 0.0 && gathered > 1e-4 {
        irradiance *= max(1.0 - texture_space, 0.0) / gathered;
    }
    return settings.weights.z * albedo / PI * irradiance;
}
