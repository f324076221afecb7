#define_import_path bevy_mesostructure::translucency::boundary

// What the translucency's shaders share about a medium's boundary, its frame and the light
// leaving through it: imported by the gather (a Bevy shader), appended to the raw wgpu shaders of the
// injection and the iteration (`with_boundary` in translucency/mod.rs, this file's first line
// taken out).

// `tangent_frame` (beam_table/directions.rs): a tangent and bitangent of the unit normal `n` fixed by
// `n` alone (Duff et al. 2017, the sign taken as z ≥ 0; the bitangent is glam's
// `any_orthonormal_vector`): the frame a patch's table directions are measured in.
fn tangent_frame(n: vec3<f32>) -> mat2x3<f32> {
    let sign = select(-1.0, 1.0, n.z >= 0.0);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    return mat2x3(vec3(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x), vec3(b, sign + n.y * n.y * a, -n.y));
}

// `fresnel_reflectance` (diffusion.rs): unpolarised, light arriving at cos_i onto index eta.
fn fresnel_reflectance(cos_i: f32, eta: f32) -> f32 {
    let sin_t2 = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin_t2 >= 1.0 {
        return 1.0;
    }
    let cos_t = sqrt(1.0 - sin_t2);
    let rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    return 0.5 * (rs * rs + rp * rp);
}

// `jensen_internal_diffuse_reflectance` (diffusion.rs): F_dr for light inside a medium of
// index eta (Jensen et al. 2001's fit).
fn internal_diffuse_reflectance(eta: f32) -> f32 {
    return -1.440 / (eta * eta) + 0.710 / eta + 0.668 + 0.0636 * eta;
}

// `chandrasekhar_h` (diffusion.rs): Hapke's closed form of H(μ) for albedo `alpha`.
fn chandrasekhar_h(alpha: f32, mu_in: f32) -> f32 {
    let mu = clamp(mu_in, 1e-6, 1.0);
    let gamma = sqrt(1.0 - alpha);
    let r0 = (1.0 - gamma) / (1.0 + gamma);
    return 1.0 / (1.0 - alpha * mu * (r0 + 0.5 * (1.0 - 2.0 * r0 * mu) * log((1.0 + mu) / mu)));
}

// `deep_exit_shape` (diffusion.rs): the deep field's exit radiance over Lambert's at cosine mu
// behind a boundary of index eta: (1 − F(μ)) (1 + (H(μ_i)/(1 − ν μ_i) − 1)/A) / N.
fn deep_exit_shape(law: vec4<f32>, eta_in: f32, mu_in: f32) -> f32 {
    let eta = clamp(eta_in, 1.0, 3.0);
    let mu = clamp(mu_in, 0.0, 1.0);
    let inside = sqrt(max(1.0 - (1.0 - mu * mu) / (eta * eta), 0.0));
    let f_dr = internal_diffuse_reflectance(eta);
    let boundary = (1.0 + f_dr) / (1.0 - f_dr);
    let mode = chandrasekhar_h(law.x, inside) / (1.0 - law.y * inside);
    return (1.0 - fresnel_reflectance(mu, eta)) * (1.0 + (mode - 1.0) / boundary) * law.z;
}

// `tangential_flux_factor` (diffusion.rs): the diffusion field's flux along the surface (P1)
// in the exit radiance, 1 − clamp(w (1 − F(μ)) ∇_t ln B · ω, ±MAX_TANGENTIAL_LEAN), for the
// weight w (`tangential_flux_weight`), per channel.
const MAX_TANGENTIAL_LEAN: f32 = 0.5;
fn tangential_flux_factor(weight: vec3<f32>, eta_in: f32, mu: f32, along: vec3<f32>) -> vec3<f32> {
    let eta = clamp(eta_in, 1.0, 3.0);
    let out = 1.0 - fresnel_reflectance(clamp(mu, 0.0, 1.0), eta);
    let lean = clamp(weight * out * along, vec3(-MAX_TANGENTIAL_LEAN), vec3(MAX_TANGENTIAL_LEAN));
    return select(vec3(1.0), 1.0 - lean, weight > vec3(0.0));
}

// `deep_exit_shape_about` (diffusion.rs): the same law with the mode's axis along `axis` (the
// way the light flows, its length how much of it flows one way) instead of the normal `n`,
// towards the unit `towards`, unnormalised: (1 − F(μ)) (1 + (H(μ_i)/(1 − ν ω_i·a) − 1)/A).
fn deep_exit_shape_about(law: vec4<f32>, eta_in: f32, n: vec3<f32>, axis: vec3<f32>,
                         towards: vec3<f32>) -> f32 {
    let eta = clamp(eta_in, 1.0, 3.0);
    let mu = clamp(dot(n, towards), 0.0, 1.0);
    let tangent = towards - n * dot(n, towards);
    let inside_mu = sqrt(max(1.0 - dot(tangent, tangent) / (eta * eta), 0.0));
    let inside = tangent / eta + n * inside_mu;
    let f_dr = internal_diffuse_reflectance(eta);
    let boundary = (1.0 + f_dr) / (1.0 - f_dr);
    let flow = min(law.y * dot(inside, axis), 0.99);
    let mode = chandrasekhar_h(law.x, inside_mu) / (1.0 - flow);
    return (1.0 - fresnel_reflectance(mu, eta)) * (1.0 + (mode - 1.0) / boundary);
}

// `single_scattering_radiance` (beam_table/single_scattering.rs): a half-space's single scattering of a beam
// of irradiance `e` at incidence cosine mu0, seen at exit cosine mu, behind a boundary of
// index eta: α E T(μ₀) T(μ) / (4π η² (μ₀′ + μ′)).
fn single_scattering_radiance(alpha: vec3<f32>, eta_in: f32, e: vec3<f32>, mu0: f32, mu: f32) -> vec3<f32> {
    if !(mu0 > 0.0 && mu > 0.0) {
        return vec3(0.0);
    }
    let eta = clamp(eta_in, 1.0, 3.0);
    let inside0 = sqrt(max(1.0 - (1.0 - mu0 * mu0) / (eta * eta), 0.0));
    let inside = sqrt(max(1.0 - (1.0 - mu * mu) / (eta * eta), 0.0));
    let transmitted = (1.0 - fresnel_reflectance(min(mu0, 1.0), eta)) * (1.0 - fresnel_reflectance(min(mu, 1.0), eta));
    return alpha * e * transmitted / (4.0 * 3.14159265358979 * eta * eta * (inside0 + inside));
}

// `lit_face_exitance` (beam_table/single_scattering.rs): the exitance a lit face's single
// scattering gives out, 2π ∫ L μ dμ by LIT_FACE_NODES midpoints in μ, for a beam of normal
// irradiance `normal_e` at incidence cosine mu0. The gather gives this light per pixel; the
// iteration lets it light the other patches (the first bounce's source).
const LIT_FACE_NODES: u32 = 16u;

fn lit_face_exitance(alpha: vec3<f32>, eta: f32, normal_e: vec3<f32>, mu0: f32) -> vec3<f32> {
    if !(mu0 > 0.0) {
        return vec3(0.0);
    }
    let e = normal_e * min(mu0, 1.0);
    var sum = vec3(0.0);
    for (var k = 0u; k < LIT_FACE_NODES; k++) {
        let mu = (f32(k) + 0.5) / f32(LIT_FACE_NODES);
        sum += single_scattering_radiance(alpha, eta, e, mu0, mu) * mu;
    }
    return sum * (6.28318530717959 / f32(LIT_FACE_NODES));
}

// `deep_exit_norm_about` (diffusion.rs): 1/N of `deep_exit_shape_about` for an axis `along`
// the normal and `across` it is DEEP_EXIT_NORM_SAMPLES over the sum of these samples, the
// same 16 × 32 midpoint rule in μ² and φ (`cosine_weighted_directions`); sample `s` is ring
// s / 32, spoke s % 32. Summed by a workgroup (`table_flow_of` in iterate.wgsl).
const DEEP_EXIT_NORM_SAMPLES: u32 = 512u;

fn deep_exit_norm_sample(law: vec4<f32>, eta: f32, along: f32, across: f32, s: u32) -> f32 {
    let mu = sqrt((f32(s / 32u) + 0.5) / 16.0);
    let sine = sqrt(max(1.0 - mu * mu, 0.0));
    let phi = 6.28318530717959 * (f32(s % 32u) + 0.5) / 32.0;
    return deep_exit_shape_about(law, eta, vec3(0.0, 0.0, 1.0), vec3(across, 0.0, along),
                                 vec3(sine * cos(phi), sine * sin(phi), mu));
}

// f32 → u32 keeping the order (negatives flipped whole, positives' sign bit set): the
// gather's tile boxes and the translucent maps' depths take atomicMin / atomicMax on them.
fn ordered_bits(f: f32) -> u32 {
    let b = bitcast<u32>(f);
    return select(b | 0x80000000u, ~b, (b & 0x80000000u) != 0u);
}

fn from_ordered_bits(u: u32) -> f32 {
    return bitcast<f32>(select(~u, u & 0x7fffffffu, (u & 0x80000000u) != 0u));
}

// A translucent map's stored depth (`translucent_maps` in inject.wgsl): `~ordered_bits(d)`
// under atomicMax, so that the least depth wins and a cleared (zero) texel is +∞, nothing.
fn translucent_map_depth(stored: u32) -> f32 {
    return select(from_ordered_bits(~stored), bitcast<f32>(0x7f800000u), stored == 0u);
}

// The translucent maps' header and layout (`translucent_maps` in inject.wgsl, which writes
// them; the gather reads them): objects, object slots with maps, each map's resolution and
// the lights, in the first vec4, and the maps in the second; then per object two vec4s, per
// slot its samples, per light and slot its maps, per map and texel its light, per map its
// frame.
struct TranslucentMaps {
    objects: u32,
    slots: u32,
    resolution: u32,
    lights: u32,
    maps: u32,
}

fn translucent_maps_of(header: vec4<f32>, counts: vec4<f32>) -> TranslucentMaps {
    let h = vec4<u32>(header);
    return TranslucentMaps(h.x, h.y, h.z, h.w, u32(counts.x));
}

// Where object o's medium is: (σt per world unit, slot or −1), then (α, η).
fn translucent_medium_at(o: u32) -> u32 {
    return 2u + 2u * o;
}

// Where slot j's samples are: (first, count) in the scene's samples (its object's patches
// are consecutive, and so are their samples), as floats.
fn translucent_slot_samples_at(h: TranslucentMaps, j: u32) -> u32 {
    return translucent_medium_at(h.objects) + j;
}

// Where light l's maps of slot j are: (first map, how many: 0, 1, or 6 cube faces in
// `cube_face`'s order), as floats.
fn translucent_light_maps_at(h: TranslucentMaps, l: u32, j: u32) -> u32 {
    return translucent_slot_samples_at(h, h.slots) + l * h.slots + j;
}

// Where texel k's light is (k counted over every map, as `translucent_texel` gives it).
fn translucent_texel_light(h: TranslucentMaps, k: u32) -> u32 {
    return translucent_light_maps_at(h, h.lights, 0u) + k;
}

// Where map m's texels' light starts.
fn translucent_light_at(h: TranslucentMaps, m: u32) -> u32 {
    return translucent_texel_light(h, m * h.resolution * h.resolution);
}

// Where map m's frame starts (after every map's texels).
fn translucent_frame_at(h: TranslucentMaps, m: u32) -> u32 {
    return translucent_texel_light(h, h.maps * h.resolution * h.resolution) + 4u * m;
}

// The cube face (+x, −x, +y, −y, +z, −z) that `local` (from the light) points into: its
// largest axis (`translucent_shadow_map::cube_face`), for the injection's maps of a point
// light and the translucent maps' cube about a light inside an object's bounds.
fn cube_face(local: vec3<f32>) -> u32 {
    let a = abs(local);
    if a.x >= a.y && a.x >= a.z {
        return select(1u, 0u, local.x >= 0.0);
    }
    if a.y >= a.z {
        return select(3u, 2u, local.y >= 0.0);
    }
    return select(5u, 4u, local.z >= 0.0);
}

// `MapFrame` (translucent_shadow_map.rs): a map's frame from its four vec4s (origin, width),
// (u, object), (v, 1 if perspective), (travel, 1 + its light). Orthographic for a
// directional light (origin the object's centre, width in world units), perspective for a
// point or spot (origin the light, width the tangent of the half-angle).
struct TranslucentFrame {
    origin: vec3<f32>,
    width: f32,
    u: vec3<f32>,
    v: vec3<f32>,
    travel: vec3<f32>,
    perspective: bool,
    object: u32,
    light: u32,
}

fn translucent_frame_of(a: vec4<f32>, b: vec4<f32>, c: vec4<f32>, d: vec4<f32>) -> TranslucentFrame {
    return TranslucentFrame(a.xyz, a.w, b.xyz, c.xyz, d.xyz, c.w > 0.0, u32(b.w), u32(d.w) - 1u);
}

// `MapFrame::place`: a point's texel coordinates (centres at k + ½) and depth in a map of
// `res` texels a side; `on` false behind a perspective map's light.
struct MapPlace {
    at: vec2<f32>,
    depth: f32,
    on: bool,
}

fn translucent_place(f: TranslucentFrame, p: vec3<f32>, res: u32) -> MapPlace {
    let r = p - f.origin;
    let texel = 2.0 * f.width / f32(res);
    let across = vec2(dot(r, f.u), dot(r, f.v));
    if !f.perspective {
        return MapPlace((across + f.width) / texel, dot(r, f.travel), true);
    }
    let z = dot(r, f.travel);
    return MapPlace((across / max(z, 1e-30) + f.width) / texel, length(r), z > 0.0);
}

// `MapFrame::ray`: the ray at texel coordinates `at`, where depth 0 lies and the unit way
// depth grows.
struct MapRay {
    origin: vec3<f32>,
    towards: vec3<f32>,
}

fn translucent_ray(f: TranslucentFrame, at: vec2<f32>, res: u32) -> MapRay {
    let across = at * (2.0 * f.width / f32(res)) - f.width;
    if f.perspective {
        return MapRay(f.origin, normalize(f.travel + f.u * across.x + f.v * across.y));
    }
    return MapRay(f.origin + f.u * across.x + f.v * across.y, f.travel);
}

// A texel's width (world units) at `depth` (`TranslucentShadowMap::texel_width_at`).
fn translucent_texel_width(f: TranslucentFrame, depth: f32, res: u32) -> f32 {
    return 2.0 * f.width / f32(res) * select(1.0, depth, f.perspective);
}

// Texel (x, y) of map m in `translucent_depths` (two words a texel from 2 × this): clamped to
// the map's edge (`clamped`), or -1 outside it.
fn translucent_texel(h: TranslucentMaps, m: u32, x: i32, y: i32, clamped: bool) -> i32 {
    let res = i32(h.resolution);
    if !clamped && (x < 0 || y < 0 || x >= res || y >= res) {
        return -1;
    }
    return i32(m * h.resolution * h.resolution) + clamp(y, 0, res - 1) * res + clamp(x, 0, res - 1);
}
