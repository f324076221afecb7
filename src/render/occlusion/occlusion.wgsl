// Occlusion pass (paper §3.1, eqs. 3–7): per pixel, the horizon angle of each apex of its set,
// sin h = ((H − P) · n0) / |H − P| with P = P0 + n0 · dis · k for both points; the highest per
// azimuth sector; then 1/(2π) ∫ cos² h dθ (cosine-weighted) or ∫ (1 − sin h) (eq. 6).
// Mirrors `reference::occlusion`. Multiplied by a coarse horizon-based AO on the depth buffer
// (Bavoil et al. 2008) whose step is the adaptive (min + max) / 2 of the apex distances (§3.1):
// the depth buffer holds only the core geometry, so the two do not count the same occluder.
// Where micro-shadows or bleeding are on, it also stores each pixel's sector record (horizons
// about N', N', the apex setting each horizon; `surface.wgsl`), so that the lighting and
// bleeding passes read them instead of walking the apex set again.

#import bevy_render::view::View
#import bevy_mesostructure::common::{
    MesostructureUniform, on_screen, unpack_offset, sample_direction, apex_base, apex_set_of,
}
#import bevy_mesostructure::surface
#import bevy_mesostructure::surface::{SECTORS, sector_of}

@group(0) @binding(0) var mhm: texture_2d<f32>;
@group(0) @binding(1) var core_normal: texture_2d<f32>;
@group(0) @binding(2) var<storage, read> apex_sets: array<u32>;
@group(0) @binding(3) var occlusion_out: texture_storage_2d<r32float, write>;
@group(0) @binding(4) var<uniform> settings: MesostructureUniform;
@group(0) @binding(5) var<uniform> view: View;
@group(0) @binding(6) var mhgm: texture_2d<u32>;
@group(0) @binding(7) var depth: texture_depth_2d;
// w: the height pass's texture-space occlusion (−1 where it has none).
@group(0) @binding(8) var bump_normal: texture_2d<f32>;
// The sector record of each pixel (`surface.wgsl`) for the lighting and bleeding passes.
@group(0) @binding(9) var sector_horizons_out: texture_storage_2d<rgba32uint, write>;

const COARSE_DIRECTIONS: u32 = 8u;
const COARSE_STEPS: u32 = 8u;
// How far the march reaches, in the pixel's adaptive step (its apexes' mean distance): 32 of
// them, far enough for an object's own far parts (a torus's ring across its hole) — 4 with a
// falloff over the whole range had left the tori 0.03–0.05 too open on the unseen-content
// suite (docs/accuracy.md). The samples are spaced quadratically (0.5, 2, 4.5 … 32 steps), so
// that the foot of a wall next to the pixel is still seen.
const COARSE_REACH: f32 = 32.0;
// Sine of the elevation a depth sample must exceed to count (hides the facets of tessellated
// curved cores, as HBAO's angle bias does).
const COARSE_BIAS: f32 = 0.1;

fn surface_point(p: vec2<i32>) -> vec3<f32> {
    return surface::surface_point(mhm, core_normal, view.world_from_clip, view.viewport, p);
}

// The core point seen through pixel p at NDC depth `ndc_depth`.
fn core_point(p: vec2<f32>, ndc_depth: f32) -> vec3<f32> {
    let uv = (p + 0.5 - view.viewport.xy) / view.viewport.zw;
    let world = view.world_from_clip * vec4<f32>(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, ndc_depth, 1.0);
    return world.xyz / world.w;
}

// Coarse horizon-based AO of the core around P0 (normal n0), out to COARSE_REACH × `step`
// pixels: per direction the highest elevation of the depth buffer's points within the world
// radius the march covers, faded over its last quarter; cosine-weighted like the fine term.
fn coarse_occlusion(p: vec2<i32>, n0: vec3<f32>, step: f32) -> f32 {
    let size = vec2<i32>(textureDimensions(depth));
    let d0 = textureLoad(depth, p, 0);
    let p0 = core_point(vec2<f32>(p), d0);
    let reach = step * COARSE_REACH;
    let radius = length(core_point(vec2<f32>(p) + vec2(reach, 0.0), d0) - p0);
    if !(radius > 0.0) {
        return 1.0;
    }
    var visibility = 0.0;
    for (var i = 0u; i < COARSE_DIRECTIONS; i++) {
        let a = (f32(i) + 0.5) * surface::TAU / f32(COARSE_DIRECTIONS);
        let dir = vec2(cos(a), sin(a));
        var sin_h = 0.0;
        for (var j = 1u; j <= COARSE_STEPS; j++) {
            let along = f32(j) / f32(COARSE_STEPS);
            let q = p + vec2<i32>(round(dir * reach * along * along));
            if !on_screen(q, size) {
                break;
            }
            let dq = textureLoad(depth, q, 0);
            if dq == 0.0 {
                continue; // sky (reverse Z)
            }
            let v = core_point(vec2<f32>(q), dq) - p0;
            let dist = length(v);
            if dist <= 0.0 || dist > radius {
                continue;
            }
            // Full weight to three quarters of the range, then fading (no pop at its edge).
            let falloff = 1.0 - smoothstep(0.75 * radius, radius, dist);
            sin_h = max(sin_h, (dot(v, n0) / dist - COARSE_BIAS) * falloff);
        }
        visibility += 1.0 - sin_h * sin_h;
    }
    return visibility / f32(COARSE_DIRECTIONS);
}

// A baseline, not the paper's method (`horizon_search_steps` > 0): a brute-force horizon search
// with a fixed radius — along each of `apex_directions` directions, `horizon_search_steps`
// samples out to `max_walk` pixels on the same surface — and the same integral over the
// directions. Mirrors `reference::horizon_search_occlusion`.
fn horizon_search(p: vec2<i32>, size: vec2<i32>, sp: vec3<f32>, n: vec3<f32>) -> f32 {
    let object = textureLoad(mhm, p, 0).z;
    let directions = max(settings.apex_directions, 1u);
    let steps = settings.horizon_search_steps;
    var visibility = 0.0;
    for (var i = 0u; i < directions; i++) {
        let dir = sample_direction(settings, i);
        var sin_h = 0.0;
        for (var j = 1u; j <= steps; j++) {
            let q = p + vec2<i32>(round(dir * f32(settings.max_walk) * f32(j) / f32(steps)));
            if !on_screen(q, size) || textureLoad(mhm, q, 0).z != object {
                break;
            }
            let d = surface_point(q) - sp;
            let len = length(d);
            if len > 0.0 {
                sin_h = max(sin_h, clamp(dot(d, n) / len, 0.0, 1.0));
            }
        }
#ifdef OCCLUSION_FORM_PAPER
        visibility += 1.0 - sin_h;
#else
        visibility += 1.0 - sin_h * sin_h;
#endif
    }
    return visibility / f32(directions);
}

@compute @workgroup_size(8, 8, 1)
fn occlusion(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = vec2<i32>(textureDimensions(mhm));
    let p = vec2<i32>(id.xy);
    if !on_screen(p, size) {
        return;
    }
    if textureLoad(mhm, p, 0).z == 0.0 {
#ifdef AMBIENT_OCCLUSION
        textureStore(occlusion_out, p, vec4<f32>(1.0));
#endif
#ifdef SECTOR_HORIZONS
        textureStore(sector_horizons_out, p, vec4<u32>(0u));
#endif
        return;
    }
    let base = apex_base(settings, p, size);
    let apexes = apex_set_of(mhm, settings, p, apex_sets[base], base);
    let sp = surface_point(p);
    let n0 = textureLoad(core_normal, p, 0).xyz;
    // The texture-space occlusion of the true surface (the mean over the pixel's footprint
    // where the map is minified; see height.wgsl) takes over from the apex horizons where the
    // height pass computed it; then the AO needs only the apexes' distances (the coarse term's
    // step), not their horizons nor N' — unless the record for the lighting and bleeding
    // passes wants them.
    let texture_space = textureLoad(bump_normal, p, 0).w;
#ifdef TEXTURE_SPACE_HORIZONS
    let from_texture_space = texture_space >= 0.0;
#else
    let from_texture_space = false;
#endif
    // Which horizons this variant finds: about N' for the record (lighting and bleeding) and
    // the cosine-weighted AO, about n0 for eq. (6); none for the brute-force baseline alone
    // (the apex sets may not even exist then).
#ifdef SECTOR_HORIZONS
    let horizons_wanted = true;
#else
#ifdef HORIZON_SEARCH
    let horizons_wanted = false;
#else
    let horizons_wanted = !from_texture_space;
#endif
#endif
    var n = n0;
#ifdef OCCLUSION_FORM_PAPER
#ifdef SECTOR_HORIZONS
    n = surface::mesostructure_normal(
        mhm, core_normal, mhgm, view.world_from_clip, view.viewport, p, sp, n0);
#endif
    // Eq. (6) measures from the core plane.
    let n_form = n0;
#else
    if horizons_wanted || !from_texture_space {
        n = surface::mesostructure_normal(
            mhm, core_normal, mhgm, view.world_from_clip, view.viewport, p, sp, n0);
    }
    let n_form = n;
#endif
    var maxima: surface::SectorMaxima;
    // Eq. (6) with a record to store needs a second set of horizons, about n0; without one,
    // n is n0 and `maxima` already holds them.
#ifdef OCCLUSION_FORM_PAPER
#ifdef SECTOR_HORIZONS
    var sin_h_core: array<vec4<f32>, 2>;
#endif
#endif
#ifdef HORIZON_SEARCH
    // The baseline's AO needs no apex distances either.
    let apex_count = select(0u, apexes.count, horizons_wanted);
#else
    let apex_count = apexes.count;
#endif
    var nearest = 1.0e9;
    var farthest = 0.0;
    for (var i = 0u; i < apex_count; i++) {
        let o = unpack_offset(apex_sets[apexes.first + i]) + apexes.shift;
        let distance = length(vec2<f32>(o));
        if distance > 0.0 {
            nearest = min(nearest, distance);
            farthest = max(farthest, distance);
        }
        if !horizons_wanted {
            continue;
        }
        let d = surface_point(p + o) - sp;
        let len = length(d);
        if len <= 0.0 {
            continue;
        }
        let sector = sector_of(o);
        surface::raise_sector_horizon(&maxima, sector, clamp(dot(d, n) / len, 0.0, 1.0), i);
#ifdef OCCLUSION_FORM_PAPER
#ifdef SECTOR_HORIZONS
        surface::raise_sector_maximum(&sin_h_core, sector, clamp(dot(d, n0) / len, 0.0, 1.0));
#endif
#endif
    }
#ifdef SECTOR_HORIZONS
    textureStore(sector_horizons_out, p, surface::pack_sector_record(maxima, n));
#endif
#ifdef AMBIENT_OCCLUSION
#ifdef HORIZON_SEARCH
    textureStore(occlusion_out, p, vec4<f32>(horizon_search(p, size, sp, n_form)));
#else
#ifdef OCCLUSION_FORM_PAPER
#ifdef SECTOR_HORIZONS
    var visibility = surface::sectors_visibility(sin_h_core, true);
#else
    var visibility = surface::sectors_visibility(maxima.sin_h, true);
#endif
#else
    var visibility = surface::sectors_visibility(maxima.sin_h, false);
#endif
    if from_texture_space {
        visibility = texture_space;
    }
#ifdef COARSE_OCCLUSION
    // No apex, no scale for the coarse step: a flat height map stays neutral.
    if farthest > 0.0 {
        visibility *= coarse_occlusion(p, n0, max(0.5 * (nearest + farthest), 1.0));
    }
#endif
    textureStore(occlusion_out, p, vec4<f32>(visibility));
#endif
#endif
}
