#define_import_path bevy_mesostructure::translucency::marched

#import bevy_mesostructure::translucency::boundary::{
    cube_face, fresnel_reflectance, translucent_map_depth, TranslucentMaps, translucent_maps_of,
    translucent_light_maps_at, translucent_medium_at, translucent_texel_light, translucent_frame_at,
    TranslucentFrame, translucent_frame_of, translucent_place, translucent_texel_width, translucent_texel,
}

// The translucent objects' maps towards each light and their light (`translucent_maps`,
// `translucent_depths` in inject.wgsl, where they are laid out).
@group(0) @binding(13) var<storage, read> translucent_maps: array<vec4<f32>>;
@group(0) @binding(14) var<storage, read> translucent_depths: array<u32>;

// Single scattering marched per pixel (`MarchedObject::radiance`, translucent_shadow_map.rs):
// at `MARCHED_DEPTHS` optical depths a channel (the midpoint quantiles of e^{−τ}) along the
// view ray refracted into the pixel's object, each against each light's map of the object —
// the light's path inside to it (scaled for its refraction) and its column's light — out
// through the boundary, T(μ)/η².
const MARCHED_DEPTHS: u32 = 16u;

// `TranslucentShadowMap::lit_path_inside_with`: the light's path inside to `p` in map `m`
// (negative in front of the entry) and its own texel's light (the path's scale in w);
// `inside` false more than `before_entry` texels in front of the entry or beyond the first
// exit by more than a texel, or off the object. An uncovered own texel takes the nearest
// covered of the four about `p`.
struct LitPath {
    inside: bool,
    path: f32,
    light: vec4<f32>,
}

fn map_entry(h: TranslucentMaps, m: u32, x: i32, y: i32) -> f32 {
    return translucent_map_depth(translucent_depths[2u * u32(translucent_texel(h, m, x, y, true))]);
}

fn lit_path_inside(h: TranslucentMaps, m: u32, f: TranslucentFrame, p: vec3<f32>, before_entry: f32) -> LitPath {
    var lit: LitPath;
    let place = translucent_place(f, p, h.resolution);
    if !place.on {
        lit.inside = false;
        return lit;
    }
    let texel = translucent_texel_width(f, place.depth, h.resolution);
    let c = vec2<i32>(floor(place.at - 0.5));
    let t = place.at - 0.5 - floor(place.at - 0.5);
    let corners = vec4(map_entry(h, m, c.x, c.y), map_entry(h, m, c.x + 1, c.y),
                       map_entry(h, m, c.x, c.y + 1), map_entry(h, m, c.x + 1, c.y + 1));
    let own = vec2<i32>(floor(place.at));
    var k = u32(translucent_texel(h, m, own.x, own.y, true));
    var near = translucent_map_depth(translucent_depths[2u * k]);
    if !(near < 3.0e38) {
        // The nearest covered corner, first of equals in the CPU twin's order.
        var best = 3.0e38;
        for (var j = 0; j < 4; j++) {
            let corner = c + vec2(j & 1, j >> 1u);
            let d = distance(vec2<f32>(corner) + 0.5, place.at);
            if corners[j] < 3.0e38 && d * d < best {
                best = d * d;
                k = u32(translucent_texel(h, m, corner.x, corner.y, true));
                near = corners[j];
            }
        }
    }
    let far = translucent_map_depth(translucent_depths[2u * k + 1u]);
    if all(corners < vec4(3.0e38)) {
        near = mix(mix(corners.x, corners.y, t.x), mix(corners.z, corners.w, t.x), t.y);
    }
    lit.inside = near < 3.0e38 && place.depth >= near - before_entry * texel && place.depth <= far + texel;
    lit.path = place.depth - near;
    lit.light = translucent_maps[translucent_texel_light(h, k)];
    // From a point, the light spreads on inside as outside (index-matched): its irradiance at
    // the entry times (entry distance / distance)².
    if f.perspective && place.depth > near {
        lit.light = vec4(lit.light.rgb * (near * near) / (place.depth * place.depth), lit.light.w);
    }
    return lit;
}

fn map_frame(h: TranslucentMaps, m: u32) -> TranslucentFrame {
    let at = translucent_frame_at(h, m);
    return translucent_frame_of(translucent_maps[at], translucent_maps[at + 1u], translucent_maps[at + 2u],
                                translucent_maps[at + 3u]);
}

// A light's map that sees `p`: its one, or the cube face `p` lies in from the light
// (`LightMaps::face_of`).
struct MapFace {
    m: u32,
    f: TranslucentFrame,
}

fn map_face(h: TranslucentMaps, first: u32, first_frame: TranslucentFrame, faces: u32, p: vec3<f32>) -> MapFace {
    if faces == 6u {
        let m = first + cube_face(p - first_frame.origin);
        return MapFace(m, map_frame(h, m));
    }
    return MapFace(first, first_frame);
}

// At the pixel's world point `x` of unit normal `n`, seen along the unit `towards` at exit
// cosine `mu`, in translucent object `object` (-1: none). Each light's maps of the object are
// one, or a cube's six faces about a light inside its bounds: each depth then looks in the
// face it lies in from the light (`LightMaps::lit_path_inside`).
fn marched_single_scattering(object: i32, x: vec3<f32>, n: vec3<f32>, towards: vec3<f32>, mu: f32) -> vec3<f32> {
    let h = translucent_maps_of(translucent_maps[0], translucent_maps[1]);
    if object < 0 || u32(object) >= h.objects || mu <= 0.0 {
        return vec3(0.0);
    }
    let medium = translucent_maps[translucent_medium_at(u32(object))];
    if medium.w < 0.0 {
        return vec3(0.0);
    }
    let sigma_t = medium.xyz;
    let albedo_eta = translucent_maps[translucent_medium_at(u32(object)) + 1u];
    let eta = clamp(albedo_eta.w, 1.0, 3.0);
    let inside = sqrt(max(1.0 - (1.0 - mu * mu) / (eta * eta), 0.0));
    // Snell's law: the ray's part along the surface shrinks by η.
    let into = (-towards + n * mu) / eta - n * inside;
    var total = vec3(0.0);
    for (var l = 0u; l < h.lights; l++) {
        let maps = translucent_maps[translucent_light_maps_at(h, l, u32(medium.w))];
        let first = u32(maps.x);
        let faces = u32(maps.y);
        if faces == 0u {
            continue;
        }
        let first_frame = map_frame(h, first);
        // `LightMaps::half_space_bound`: under a surface facing the light, the path per unit
        // length marched is at most μ/μ₀, the tangent plane's.
        let at_x = map_face(h, first, first_frame, faces, x);
        var travel = at_x.f.travel;
        if at_x.f.perspective {
            travel = normalize(x - at_x.f.origin);
        }
        let mu0 = dot(n, -travel);
        let mu_in = -dot(into, n);
        var bound = -1.0;
        if mu0 > 1e-3 && mu_in > 0.0 && lit_path_inside(h, at_x.m, at_x.f, x, 1.0e30).inside {
            bound = mu_in / mu0;
        }
        // Under a lit surface a point in front of the map's entry takes the tangent plane's
        // path; elsewhere it is outside.
        let before_entry = select(0.0, 1.0e30, bound >= 0.0);
        for (var c = 0u; c < 3u; c++) {
            if !(sigma_t[c] > 0.0) {
                continue;
            }
            var sum = 0.0;
            var entered = false;
            for (var k = 0u; k < MARCHED_DEPTHS; k++) {
                // `optical_depth_quantile`.
                let depth = -log(1.0 - (f32(k) + 0.5) / f32(MARCHED_DEPTHS)) / sigma_t[c];
                let p = x + into * depth;
                let at_p = map_face(h, first, first_frame, faces, p);
                let lit = lit_path_inside(h, at_p.m, at_p.f, p, before_entry);
                if lit.inside {
                    var path = max(lit.path, 0.0);
                    if bound >= 0.0 {
                        path = select(min(lit.path, depth * bound), depth * bound, lit.path < 0.0);
                    }
                    sum += lit.light[c] * exp(-sigma_t[c] * path * lit.light.w);
                    entered = true;
                } else if entered {
                    // Once the ray has left the object, what lies beyond may be air.
                    break;
                }
            }
            total[c] += sum / f32(MARCHED_DEPTHS);
        }
    }
    let exit = (1.0 - fresnel_reflectance(mu, eta)) / (eta * eta);
    return albedo_eta.rgb / (4.0 * 3.14159265358979) * total * exit;
}
