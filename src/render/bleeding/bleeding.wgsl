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
// The first directional light's bounce comes from texture space instead (`texture_bounce` in
// height.wgsl: the screen-space gather sees too little of the surface where the view is
// minified or oblique, docs/accuracy.md): its direct diffuse light is taken out of every
// gathered colour and its texture-space bounce added, times the mean albedo of what P sees.

#import bevy_render::view::View
#import bevy_pbr::mesh_view_types::Lights
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
// The height pass's texture-space terms of the first directional light: (visibility, one
// bounce relative to E0), each −1 where none.
@group(0) @binding(10) var texture_terms: texture_2d<f32>;
// The lighting pass's (micro-shadow visibility, first directional light's shadow-map
// visibility).
@group(0) @binding(11) var light_visibility: texture_2d<f32>;
@group(0) @binding(12) var<uniform> lights: Lights;
#ifdef WRITE_VIEW_TARGET
// The view's other main image, which becomes its main image after this pass.
@group(0) @binding(13) var view_out: texture_storage_2d<rgba16float, write>;
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

// The direct diffuse radiance the first directional light (irradiance `e0` facing it, from
// `to_light`) gives sample `q` of the lit image, as the lighting pass shaded it: Bevy's Burley
// diffuse (`Fd_Burley` in bevy_pbr's lighting.wgsl) with q's albedo, roughness and normal,
// times the light's texture-space visibility there (where micro-shadows are on), its shadow
// map and λs. What the texture-space bounce already counts, to take out of q's colour.
fn first_directional_diffuse(q: vec2<i32>, sq: vec3<f32>, e0: vec3<f32>, to_light: vec3<f32>) -> vec3<f32> {
    let n = sample_normal(q);
    let n_dot_l = dot(n, to_light);
    if n_dot_l <= 0.0 {
        return vec3(0.0);
    }
    let v = normalize(view.world_position - sq);
    let n_dot_v = max(dot(n, v), 1e-4);
    let l_dot_h = dot(to_light, normalize(to_light + v));
    let perceptual = clamp(unpack_unorm4x8_(textureLoad(gbuffer, q, 0).r).a, 0.089, 1.0);
    let f90 = 0.5 + 2.0 * perceptual * perceptual * l_dot_h * l_dot_h;
    let burley = (1.0 + (f90 - 1.0) * pow(1.0 - n_dot_l, 5.0))
        * (1.0 + (f90 - 1.0) * pow(1.0 - n_dot_v, 5.0)) / PI;
    var visible = textureLoad(light_visibility, q, 0).g;
    let micro = textureLoad(texture_terms, q, 0).r;
    if settings.micro_shadows != 0u && micro >= 0.0 {
        visible *= micro;
    }
    return diffuse_albedo(q) * burley * e0 * n_dot_l * visible * settings.weights.y;
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
    // The first directional light's texture-space bounce at P (−1: none), its irradiance E0
    // (exposure applied) and direction.
    var sun_bounce = -1.0;
    var sun = vec3(0.0);
    var to_sun = vec3(0.0, 0.0, 1.0);
    if settings.texture_space_bounce != 0u && lights.n_directional_lights > 0u {
        sun_bounce = textureLoad(texture_terms, p, 0).g;
        sun = lights.directional_lights[0].color.rgb * view.exposure;
        to_sun = lights.directional_lights[0].direction_to_light;
    }
    // Σ ρ_S · band over the visible samples: the mean albedo of what P sees.
    var seen_albedo = vec3(0.0);
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
            let band = (s * s - seen * seen) * 0.5;
            if dot(sample_normal(q), -d) > 0.0 {
                var radiance = textureLoad(lit, q, 0).rgb;
                if sun_bounce >= 0.0 {
                    radiance = max(radiance - first_directional_diffuse(q, sp + d, sun, to_sun), vec3(0.0));
                }
                irradiance += radiance * band;
            }
            seen_albedo += diffuse_albedo(q) * band;
            covered += band;
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
    if sun_bounce >= 0.0 {
        // E1 = ρ_S E0 · bounce, in the light's shadow map at P (where the light does not reach
        // P, it does not reach the bumps around it either); ρ_S the mean albedo of what the
        // gather saw, P's own where it saw nothing.
        var surround = albedo;
        if covered > 0.0 {
            surround = seen_albedo / covered;
        }
        let shadow = textureLoad(light_visibility, p, 0).g;
        irradiance += surround * sun * sun_bounce * shadow;
    }
    return settings.weights.z * albedo / PI * irradiance;
}
