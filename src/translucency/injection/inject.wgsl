// Seed 001's light injection (its step 2) on the GPU: each light's view of the scene as a depth
// map splatted from the patches' surface samples (`splat`), then each patch's direct
// irradiance E⁰ with the share of the light its neighbourhood sees in that map (`inject`),
// weighted by each beam's incidence. The GPU form of `lights::direct_light`, whose one shadow
// ray per patch is its oracle (the same fall-off, range window and incidence arithmetic).
//
// Maps: a directional light sees the scene's bounding sphere orthographically (one face); a
// point or spot light sees it through the six faces of a cube, the depth being the distance.
// Depths are stored as `~bitcast<u32>(depth)` with `atomicMax`: positive floats order as their
// bits, and a cleared (zero) texel is "nothing there".

const MAX_LIGHTS: u32 = 8u;
const DIRECTIONAL: u32 = 0u;
const POINT: u32 = 1u;
const SPOT: u32 = 2u;
// A splat's radius against its sample's disc (samples of ≤ h/2 sides do not tile as discs),
// and the widest splat in texels (a sample wider than this leaves gaps between its
// neighbours' splats: at 512², one of 5 mm radius nearer than 4 cm to a point light).
const SPLAT_COVER: f32 = 1.5;
const MAX_SPLAT_TEXELS: f32 = 32.0;
const PI: f32 = 3.14159265358979;

struct InjectedLight {
    // Directional: unused; point and spot: the light's position.
    position: vec3<f32>,
    kind: u32,
    // Directional: the way the light travels; spot: its axis.
    direction: vec3<f32>,
    range: f32,
    // Illuminance (directional) or luminous intensity (point, spot) per channel.
    intensity: vec3<f32>,
    cos_outer: f32,
    // Spot: 1 / (cos inner − cos outer), as Bevy.
    cone_scale: f32,
    // Spot: the outer angle, acos(cos_outer) (once on the CPU rather than per sample).
    outer: f32,
    pad1: f32,
    pad2: f32,
}

struct Injection {
    lights: array<InjectedLight, MAX_LIGHTS>,
    // Bevy's ambient irradiance, taken by translucent patches.
    ambient: vec3<f32>,
    light_count: u32,
    bounds_centre: vec3<f32>,
    bounds_radius: f32,
    resolution: u32,
    samples: u32,
    patches: u32,
    table_size: u32,
    // Offsets (in vec4s) of each array in `scene`.
    samples_at: u32,
    patches_at: u32,
    tables_at: u32,
    // Offsets (in vec4s) of E⁰ and S⁰ in the iteration's `vectors`.
    direct: u32,
    direct_exitance: u32,
    // The beam table's directions a patch (cosines × azimuths; 0 without one) and where its
    // vectors start in `vectors`: the beams' light by `slot · bins + bin`, the part of E⁰ it
    // carries, the beams' normal irradiance and weighted direction.
    cosines: u32,
    azimuths: u32,
    beam_light: u32,
    tabled: u32,
    beam_irradiance: u32,
    beam_direction: u32,
    // The lit faces' single-scattered exitance (`DirectLight::lit_face_exitance`).
    lit_face: u32,
}

const PATCH_RECORD: u32 = 5u;

@group(0) @binding(0) var<uniform> injection: Injection;
// Samples: (position, radius), (normal, 0). Patches (PATCH_RECORD vec4s each): (surface
// point, size), (normal, object), (single-scattering factor, 1 on translucent patches),
// (beam-table slot or −1, index of refraction, 0, 0), (the slot's single-scattering albedo, 0).
// Tables per object: (incidence weight, single-scattering shape − its diffuse mean) at
// cosines 0, 1/(n−1), …, 1.
@group(0) @binding(1) var<storage, read> scene: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> depth_maps: array<atomic<u32>>;
@group(0) @binding(3) var<storage, read_write> vectors: array<vec4<f32>>;

// A place in one face of a light's map.
struct MapPoint {
    // Texel coordinates (texel centres at .5).
    texel: vec2<f32>,
    depth: f32,
    // The world size of one texel there.
    texel_world: f32,
    // The way the light's ray runs there.
    ray: vec3<f32>,
    // The face's two world axes across the map (one texel = texel_world along them).
    across: vec3<f32>,
    up: vec3<f32>,
    face: u32,
    inside: bool,
}

fn orthonormal(d: vec3<f32>) -> mat3x3<f32> {
    let helper = select(vec3(0.0, 1.0, 0.0), vec3(1.0, 0.0, 0.0), abs(d.y) > 0.9);
    let across = normalize(cross(helper, d));
    return mat3x3(across, cross(d, across), d);
}

fn cube_axis(face: u32) -> mat3x3<f32> {
    // Face f looks along ±axis f/2; the two others run across it.
    let a = face / 2u;
    let s = select(-1.0, 1.0, face % 2u == 0u);
    var e = array(vec3(1.0, 0.0, 0.0), vec3(0.0, 1.0, 0.0), vec3(0.0, 0.0, 1.0));
    return mat3x3(e[(a + 1u) % 3u], e[(a + 2u) % 3u], s * e[a]);
}

fn map_point(light: InjectedLight, face: u32, p: vec3<f32>) -> MapPoint {
    let res = f32(injection.resolution);
    var m: MapPoint;
    m.face = face;
    if light.kind == DIRECTIONAL {
        let radius = injection.bounds_radius;
        let basis = orthonormal(normalize(light.direction));
        let local = p - injection.bounds_centre;
        let uv = vec2(dot(local, basis[0]), dot(local, basis[1])) / radius;
        m.texel = (uv * 0.5 + 0.5) * res;
        m.depth = dot(local, basis[2]) + radius;
        m.texel_world = 2.0 * radius / res;
        m.ray = basis[2];
        m.across = basis[0];
        m.up = basis[1];
        m.inside = all(abs(uv) <= vec2(1.0)) && m.depth >= 0.0;
        return m;
    }
    let basis = cube_axis(face);
    let local = p - light.position;
    let major = dot(local, basis[2]);
    let uv = vec2(dot(local, basis[0]), dot(local, basis[1])) / max(major, 1e-20);
    m.texel = (uv * 0.5 + 0.5) * res;
    m.depth = length(local);
    m.texel_world = 2.0 * major / res;
    m.ray = local / max(m.depth, 1e-20);
    m.across = basis[0];
    m.up = basis[1];
    m.inside = major > 0.0 && all(abs(uv) <= vec2(1.0));
    return m;
}

fn map_index(light: u32, face: u32, texel: vec2<i32>) -> u32 {
    let res = injection.resolution;
    return ((light * 6u + face) * res + u32(texel.y)) * res + u32(texel.x);
}

fn faces_of(light: InjectedLight) -> u32 {
    return select(6u, 1u, light.kind == DIRECTIONAL);
}

// Each sample's disc into each face of each light's map that it reaches, at the depth of the
// sample's own plane across the disc (so that a tilted surface does not shadow itself).
// Eight samples a workgroup, eight threads a sample over its texels (`SPLAT_LANES`): a
// thread a sample walked up to 65² texels a face alone, waiting on its atomics, and fewer,
// larger samples (a smaller budget) took longer (on an H100 at 1080p: 0.051 ms at 17.9 k
// patches, 0.113 at 3.8 k).
const SPLAT_LANES: u32 = 8u;

@compute @workgroup_size(64)
fn splat(
    @builtin(workgroup_id) group: vec3<u32>,
    @builtin(local_invocation_index) thread: u32,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let l = group.y;
    if l >= injection.light_count {
        return;
    }
    let per_group = 64u / SPLAT_LANES;
    // Strided: the dispatch is capped at the 65 535 groups a dimension may have.
    for (var s = group.x * per_group + thread / SPLAT_LANES; s < injection.samples; s += groups.x * per_group) {
        splat_sample(l, s, thread % SPLAT_LANES);
    }
}

// Whether a sample's disc (radius `cover` about `p`) may shadow anything `light` lights: the
// occluders of a lit point lie between it and the light, so within the light's range and, for
// a spot, within its cone (a cone is star-shaped about its apex), grown by the disc's angular
// radius and by four texels' angle for the 3×3 texels `seen_share` reads about a point. A
// sample that cannot is not splatted: the walls beside and behind a spot took most of the
// splat's time (up to 65 × 65 texels a sample close to the light).
fn may_shadow(light: InjectedLight, p: vec3<f32>, cover: f32) -> bool {
    if light.kind == DIRECTIONAL {
        return true;
    }
    let v = p - light.position;
    let dist = length(v);
    if dist <= cover {
        return true;
    }
    // Bevy's range window lights nothing at or beyond the range.
    if dist - cover >= light.range {
        return false;
    }
    if light.kind != SPOT {
        return true;
    }
    let margin = asin(cover / dist) + 8.0 / f32(injection.resolution);
    let outer = light.outer;
    if outer + margin >= PI {
        return true;
    }
    return dot(v / dist, normalize(light.direction)) >= cos(outer + margin);
}

// Sample s into light l's maps: this thread's share of its texels (`lane` of `SPLAT_LANES`).
fn splat_sample(l: u32, s: u32, lane: u32) {
    let light = injection.lights[l];
    let a = scene[injection.samples_at + 2u * s];
    let n = scene[injection.samples_at + 2u * s + 1u].xyz;
    let res = i32(injection.resolution);
    let cover = SPLAT_COVER * a.w;
    if !may_shadow(light, a.xyz, cover) {
        return;
    }
    for (var face = 0u; face < faces_of(light); face++) {
        let m = map_point(light, face, a.xyz);
        if m.texel_world <= 0.0 {
            continue;
        }
        // A disc may reach into a face whose centre it is outside of.
        let reach = min(cover / m.texel_world, MAX_SPLAT_TEXELS);
        let lo = vec2<i32>(floor(m.texel - reach));
        let hi = vec2<i32>(floor(m.texel + reach));
        if any(hi < vec2(0)) || any(lo >= vec2(res)) {
            continue;
        }
        let own = vec2<i32>(floor(m.texel));
        var basis = cube_axis(face);
        if light.kind == DIRECTIONAL {
            basis = orthonormal(normalize(light.direction));
        }
        let first = max(lo, vec2(0));
        let width = u32(min(hi.x, res - 1) - first.x + 1);
        let texels = width * u32(min(hi.y, res - 1) - first.y + 1);
        for (var t = lane; t < texels; t += SPLAT_LANES) {
            let x = first.x + i32(t % width);
            let y = first.y + i32(t / width);
            // Where this texel's ray meets the sample's plane: the disc's texels are those
            // within its (widened) radius there, so a surface seen edge-on covers few.
            let offset = vec2(f32(x), f32(y)) + 0.5 - m.texel;
            var depth = m.depth;
            var ray = m.ray;
            var q = a.xyz;
            if light.kind == DIRECTIONAL {
                let o = (offset.x * basis[0] + offset.y * basis[1]) * m.texel_world;
                let facing = dot(n, ray);
                let along = select(-dot(n, o) / facing, 0.0, abs(facing) < 1e-4);
                depth = m.depth + along;
                q = a.xyz + o + along * ray;
            } else {
                let uv = (vec2(f32(x), f32(y)) + 0.5) / f32(res) * 2.0 - 1.0;
                ray = normalize(uv.x * basis[0] + uv.y * basis[1] + basis[2]);
                let facing = dot(n, ray);
                depth = select(dot(n, a.xyz - light.position) / facing, m.depth, abs(facing) < 1e-4);
                q = light.position + depth * ray;
            }
            let is_own = all(vec2(x, y) == own);
            if !is_own && (depth <= 0.0 || distance(q, a.xyz) > cover) {
                continue;
            }
            if is_own {
                depth = m.depth;
            }
            atomicMax(&depth_maps[map_index(l, face, vec2(x, y))], ~bitcast<u32>(max(depth, 0.0)));
        }
    }
}

// The share of 3×3 texels about `p` where nothing lies nearer the light than `p` less `bias`.
fn seen_share(l: u32, m: MapPoint, bias: f32) -> f32 {
    let res = i32(injection.resolution);
    let centre = vec2<i32>(floor(m.texel));
    var seen = 0.0;
    for (var y = -1; y <= 1; y++) {
        for (var x = -1; x <= 1; x++) {
            let texel = clamp(centre + vec2(x, y), vec2(0), vec2(res - 1));
            let stored = atomicLoad(&depth_maps[map_index(l, m.face, texel)]);
            if stored == 0u || m.depth <= bitcast<f32>(~stored) + bias {
                seen += 1.0;
            }
        }
    }
    return seen / 9.0;
}

fn incidence_entry(object: u32, cos_i: f32) -> vec4<f32> {
    let last = f32(injection.table_size - 1u);
    let f = clamp(cos_i, 0.0, 1.0) * last;
    let i = min(u32(f), injection.table_size - 2u);
    let at = injection.tables_at + object * injection.table_size + i;
    return mix(scene[at], scene[at + 1u], f - f32(i));
}

// `direction_weights` (beam_table/directions.rs): the four table directions about a beam travelling
// along `travel` onto a surface of normal `n` (incidence cosine `mu` > 0) and their weights,
// bilinear in the incidence cosine between the bins' centres (held at the first and last)
// and in the azimuth round the circle, in the frame of `tangent_frame` (boundary.wgsl).
struct DirectionWeights {
    bins: vec4<u32>,
    weights: vec4<f32>,
}

fn direction_weights(travel: vec3<f32>, n: vec3<f32>, mu: f32) -> DirectionWeights {
    let frame = tangent_frame(n);
    let t = frame[0];
    let s = frame[1];
    let along = travel + mu * n;
    let count = f32(injection.azimuths);
    let raw = atan2(dot(along, s), dot(along, t)) / (6.283185307179586 / count);
    let turn = raw - floor(raw / count) * count;
    let m0 = min(u32(floor(turn)), injection.azimuths - 1u);
    let m1 = (m0 + 1u) % injection.azimuths;
    let g = clamp(turn - f32(m0), 0.0, 1.0);
    let place = clamp(min(mu, 1.0) * f32(injection.cosines) - 0.5, 0.0, f32(injection.cosines - 1u));
    let k0 = min(u32(floor(place)), injection.cosines - 1u);
    let k1 = min(k0 + 1u, injection.cosines - 1u);
    let f = place - f32(k0);
    let row0 = k0 * injection.azimuths;
    let row1 = k1 * injection.azimuths;
    return DirectionWeights(
        vec4(row0 + m0, row0 + m1, row1 + m0, row1 + m1),
        vec4((1.0 - f) * (1.0 - g), (1.0 - f) * g, f * (1.0 - g), f * g),
    );
}

// A point or spot light's irradiance across its ray per unit intensity at squared distance
// `dist2`, the ray leaving it along the unit `from_light`: Bevy's cone (spot) and range
// window over the distance squared (`PatchLight::irradiance_across`).
fn falloff_over_distance2(light: InjectedLight, from_light: vec3<f32>, dist2: f32) -> f32 {
    var falloff = 1.0;
    if light.kind == SPOT {
        let t = clamp((dot(from_light, normalize(light.direction)) - light.cos_outer) * light.cone_scale, 0.0, 1.0);
        falloff = t * t;
    }
    // Bevy's range window.
    let f = dist2 / (light.range * light.range);
    let s = clamp(1.0 - f * f, 0.0, 1.0);
    return falloff * s * s / dist2;
}

@compute @workgroup_size(64)
fn inject(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= injection.patches {
        return;
    }
    let a = scene[injection.patches_at + PATCH_RECORD * i];
    let b = scene[injection.patches_at + PATCH_RECORD * i + 1u];
    let c = scene[injection.patches_at + PATCH_RECORD * i + 2u];
    let table = scene[injection.patches_at + PATCH_RECORD * i + 3u];
    let alpha = scene[injection.patches_at + PATCH_RECORD * i + 4u].xyz;
    let n = b.xyz;
    let object = u32(b.w);
    // Where the oracle's shadow ray starts, and what its fall-off sees.
    let x = a.xyz + n * (0.05 * a.w);
    var irradiance = vec3(0.0);
    var exitance = vec3(0.0);
    // The beam table (`lights::direct_light`): a table patch's beams go into its directions'
    // light instead of E⁰'s part that K takes.
    let tabled_patch = table.x >= 0.0 && injection.cosines > 0u;
    let bins = injection.cosines * injection.azimuths;
    let first = u32(max(table.x, 0.0)) * bins;
    if tabled_patch {
        for (var k = 0u; k < bins; k++) {
            vectors[injection.beam_light + first + k] = vec4(0.0);
        }
    }
    var tabled = vec3(0.0);
    var normal_irradiance = vec3(0.0);
    var direction = vec3(0.0);
    var lit_face = vec3(0.0);
    for (var l = 0u; l < injection.light_count; l++) {
        let light = injection.lights[l];
        var e = vec3(0.0);
        var to_light: vec3<f32>;
        if light.kind == DIRECTIONAL {
            to_light = -normalize(light.direction);
            e = light.intensity * max(dot(n, to_light), 0.0);
        } else {
            let d = light.position - x;
            let dist2 = dot(d, d);
            // A light on the patch itself lights nothing (as the oracle's NaN cosine).
            if !(dist2 > 1e-20) {
                continue;
            }
            to_light = d * inverseSqrt(dist2);
            let cos_i = dot(n, to_light);
            e = light.intensity * max(falloff_over_distance2(light, -to_light, dist2) * cos_i, 0.0);
        }
        if all(e == vec3(0.0)) {
            continue;
        }
        // Visibility: the patch's point lifted off its surface by a texel, with a slope-scaled
        // depth bias (a texel's depth step across a surface at this incidence).
        let cos_i = dot(n, to_light);
        var face = 0u;
        if light.kind != DIRECTIONAL {
            face = cube_face(x - light.position);
        }
        let here = map_point(light, face, a.xyz);
        let m = map_point(light, face, a.xyz + n * max(0.05 * a.w, here.texel_world));
        let slope = min(sqrt(max(1.0 - cos_i * cos_i, 0.0)) / max(cos_i, 1e-3), 8.0);
        e *= seen_share(l, m, m.texel_world * (1.5 + slope));
        if tabled_patch && cos_i > 0.0 && any(e != vec3(0.0)) {
            // The table's column holds the beam's incidence and its scattering.
            let got_in = e * (1.0 - fresnel_reflectance(min(cos_i, 1.0), max(table.y, 1.0)));
            let about = direction_weights(-to_light, n, cos_i);
            for (var q = 0u; q < 4u; q++) {
                if about.weights[q] > 0.0 {
                    let at = injection.beam_light + first + about.bins[q];
                    vectors[at] += vec4(got_in * about.weights[q], 0.0);
                }
            }
            irradiance += got_in;
            tabled += got_in;
            normal_irradiance += e / cos_i;
            direction += -to_light * dot(e / cos_i, vec3(1.0));
            lit_face += lit_face_exitance(alpha, max(table.y, 1.0), e / cos_i, cos_i);
            continue;
        }
        // A beam takes in and gives back by its own incidence (`IncidenceWeight`).
        let entry = incidence_entry(object, cos_i);
        e *= entry.xyz;
        irradiance += e;
        exitance += c.xyz * e * entry.w;
    }
    irradiance += injection.ambient * c.w;
    vectors[injection.direct + i] = vec4(irradiance, 0.0);
    vectors[injection.direct_exitance + i] = vec4(exitance, 0.0);
    vectors[injection.tabled + i] = vec4(tabled, 0.0);
    vectors[injection.beam_irradiance + i] = vec4(normal_irradiance, 0.0);
    vectors[injection.beam_direction + i] = vec4(direction, 0.0);
    vectors[injection.lit_face + i] = vec4(lit_face, 0.0);
}

// Translucent shadow maps (`translucent_shadow_map.rs`, their CPU twin): per translucent
// object and light, where the light enters the object and where it first leaves it again,
// over the object's bounding sphere, 256², each texel's column one of the light's rays
// (`TranslucentFrame` in boundary.wgsl: across the travel of a directional light, in
// perspective from a point or spot) — the injection's maps are centimetres wide in a room,
// the light's path inside needs a fraction of a mean free path — and each texel's light
// inside (`entry_light`), for the gather's single scattering marched per pixel
// (`marched_single_scattering` in marched.wgsl).
//
// `translucent_maps`, in vec4s: a header (objects, object slots with maps, resolution,
// lights) and the maps; per object (σt per world unit, slot or −1), (α, η); per slot the
// first of its object's samples and how many there are (a range that may hold others:
// `splat_translucent` keeps its object's); per light and slot its first map and how many
// (none, one, or a cube's six faces about a light inside the object's bounds); per map and
// texel its light; then per map its frame (`MapFrame::to_vec4s`). `translucent_depths`: per
// map and texel its entry and exit depths along its ray (`translucent_place`,
// `translucent_map_depth`).
@group(1) @binding(0) var<storage, read_write> translucent_maps: array<vec4<f32>>;
@group(1) @binding(1) var<storage, read_write> translucent_depths: array<atomic<u32>>;

// The widest splat in texels (`MAX_SPLAT_TEXELS` in translucent_shadow_map.rs).
const TRANSLUCENT_SPLAT_TEXELS: f32 = 64.0;

fn translucent_maps_header() -> TranslucentMaps {
    return translucent_maps_of(translucent_maps[0], translucent_maps[1]);
}

fn translucent_frame(h: TranslucentMaps, m: u32) -> TranslucentFrame {
    let at = translucent_frame_at(h, m);
    return translucent_frame_of(translucent_maps[at], translucent_maps[at + 1u], translucent_maps[at + 2u],
                                translucent_maps[at + 3u]);
}

// The pass: the entries (true) or the exits, which need every entry splatted before.
override ENTERING: bool = true;

// Dispatched a map in y, a workgroup a sample of the map's object in x (strided), its 64
// threads over the texels of the sample's splat. A thread a sample, walking its up to 129²
// texels alone, left the GPU waiting on each thread's atomics: the objects have a few
// thousand samples (on an H100 at 1080p, 17.9 k patches: 0.043 ms for the entries, 0.052 for
// the exits).
@compute @workgroup_size(64)
fn splat_translucent_maps(
    @builtin(workgroup_id) group: vec3<u32>,
    @builtin(local_invocation_index) thread: u32,
    @builtin(num_workgroups) groups: vec3<u32>,
) {
    let h = translucent_maps_header();
    let m = group.y;
    if m >= h.maps {
        return;
    }
    let f = translucent_frame(h, m);
    if f.object >= h.objects {
        return;
    }
    let slot = translucent_maps[translucent_medium_at(f.object)].w;
    if slot < 0.0 {
        return;
    }
    let range = translucent_maps[translucent_slot_samples_at(h, u32(slot))];
    let first = u32(range.x);
    for (var s = group.x; s < u32(range.y); s += groups.x) {
        splat_translucent(h, m, f, first + s, ENTERING, thread);
    }
}

// `TranslucentShadowMap::splat_one`: a sample of a translucent object into its map `m`
// (frame `f`), facing the light (`entering`: the entry depths) or away from it (the exit
// depths, only deeper than the entry: the object's first stretch along each of the light's
// rays); this thread's share of its texels (`thread` of 64).
fn splat_translucent(h: TranslucentMaps, m: u32, f: TranslucentFrame, s: u32, entering: bool, thread: u32) {
    let a = scene[injection.samples_at + 2u * s];
    let b = scene[injection.samples_at + 2u * s + 1u];
    if u32(b.w) != f.object {
        return;
    }
    let n = b.xyz;
    let place = translucent_place(f, a.xyz, h.resolution);
    if !place.on || (dot(n, translucent_ray(f, place.at, h.resolution).towards) < 0.0) != entering {
        return;
    }
    let res = i32(h.resolution);
    let cover = SPLAT_COVER * a.w;
    let reach = min(cover / translucent_texel_width(f, place.depth, h.resolution), TRANSLUCENT_SPLAT_TEXELS);
    let own = vec2<i32>(floor(place.at));
    let lo = max(vec2<i32>(floor(place.at - reach)), vec2(0));
    let hi = min(vec2<i32>(floor(place.at + reach)), vec2(res - 1));
    if any(hi < lo) {
        return;
    }
    let width = u32(hi.x - lo.x + 1);
    let texels = width * u32(hi.y - lo.y + 1);
    for (var t = thread; t < texels; t += 64u) {
        let x = lo.x + i32(t % width);
        let y = lo.y + i32(t / width);
        // Where this texel's ray meets the sample's plane.
        let ray = translucent_ray(f, vec2(f32(x), f32(y)) + 0.5, h.resolution);
        let facing = dot(n, ray.towards);
        let d = select(dot(n, a.xyz - ray.origin) / facing, place.depth, abs(facing) < 1e-4);
        if any(vec2(x, y) != own) && distance(ray.origin + ray.towards * d, a.xyz) > cover {
            continue;
        }
        let k = u32(translucent_texel(h, m, x, y, true));
        if entering {
            atomicMax(&translucent_depths[2u * k], ~ordered_bits(d));
        } else if d > translucent_map_depth(atomicLoad(&translucent_depths[2u * k])) {
            atomicMax(&translucent_depths[2u * k + 1u], ~ordered_bits(d));
        }
    }
}

// Map m's entry depth at texel (x, y), +∞ outside the map or where the light does not enter.
fn translucent_entry_depth(h: TranslucentMaps, m: u32, x: i32, y: i32) -> f32 {
    let k = translucent_texel(h, m, x, y, false);
    if k < 0 {
        return bitcast<f32>(0x7f800000u);
    }
    return translucent_map_depth(atomicLoad(&translucent_depths[2u * u32(k)]));
}

fn is_finite(d: f32) -> bool {
    return d < 3.0e38 && d > -3.0e38;
}

// Where the light enters in texel (x, y)'s column, at depth `near` along its ray.
fn translucent_entry_point(f: TranslucentFrame, res: u32, x: i32, y: i32, near: f32) -> vec3<f32> {
    let ray = translucent_ray(f, vec2(f32(x), f32(y)) + 0.5, res);
    return ray.origin + ray.towards * near;
}

// The entry surface's tangent along one of the map's axes at a texel
// (`TranslucentShadowMap::entry`): between the entry points either side, one-sided beside an
// uncovered texel, `across` (the map's own axis) between two.
fn translucent_tangent(h: TranslucentMaps, m: u32, f: TranslucentFrame, x: i32, y: i32, step: vec2<i32>,
                       here: vec3<f32>, across: vec3<f32>) -> vec3<f32> {
    let before = translucent_entry_depth(h, m, x - step.x, y - step.y);
    let after = translucent_entry_depth(h, m, x + step.x, y + step.y);
    if !is_finite(before) && !is_finite(after) {
        return across;
    }
    // A neighbour off the object stands in by this texel's own point (a one-sided difference).
    var b = here;
    var a = here;
    if is_finite(before) {
        b = translucent_entry_point(f, h.resolution, x - step.x, y - step.y, before);
    }
    if is_finite(after) {
        a = translucent_entry_point(f, h.resolution, x + step.x, y + step.y, after);
    }
    return a - b;
}

// Each texel's light inside the object (`TranslucentShadowMap::light_texels` with
// `PatchLight::irradiance_across` and `entry_light`): the light's irradiance across its
// travel where it enters, Bevy's fall-off and range window for a point or spot, shadowed by
// the scene as the injection's map sees the entry point (lifted a texel along its normal,
// biased by the entry's slope, as `inject` a patch), times what gets through the boundary,
// and the path's scale for its refraction in w.
@compute @workgroup_size(64)
fn translucent_light(@builtin(global_invocation_id) id: vec3<u32>) {
    let h = translucent_maps_header();
    let m = id.y;
    let texels = h.resolution * h.resolution;
    if id.x >= texels || m >= h.maps {
        return;
    }
    let at = translucent_light_at(h, m) + id.x;
    let f = translucent_frame(h, m);
    let x = i32(id.x % h.resolution);
    let y = i32(id.x / h.resolution);
    let near = translucent_entry_depth(h, m, x, y);
    if f.light >= h.lights || !is_finite(near) {
        translucent_maps[at] = vec4(0.0);
        return;
    }
    let column = translucent_ray(f, vec2(f32(x), f32(y)) + 0.5, h.resolution);
    let entry = column.origin + column.towards * near;
    let towards = column.towards;
    var normal = cross(translucent_tangent(h, m, f, x, y, vec2(1, 0), entry, f.u),
                       translucent_tangent(h, m, f, x, y, vec2(0, 1), entry, f.v));
    var cos_entry = 1.0;
    if dot(normal, normal) > 0.0 {
        // Outward: against the light's ray.
        normal = normalize(normal) * -sign(dot(normal, towards));
        cos_entry = abs(dot(normal, towards));
    } else {
        normal = -towards;
    }
    let light = injection.lights[f.light];
    var e = light.intensity;
    var face = 0u;
    if light.kind != DIRECTIONAL {
        let d = entry - light.position;
        let dist2 = dot(d, d);
        if !(dist2 > 1e-20) {
            translucent_maps[at] = vec4(0.0);
            return;
        }
        e *= falloff_over_distance2(light, d * inverseSqrt(dist2), dist2);
        face = cube_face(d);
    }
    // Shadowed by what else the light meets on its way, as `inject` sees a patch: the entry
    // lifted off the surface by a texel along its normal (from the entry points' tangents),
    // with the slope-scaled bias.
    let here = map_point(light, face, entry);
    let lifted = map_point(light, face, entry + normal * here.texel_world);
    let slope = min(sqrt(max(1.0 - cos_entry * cos_entry, 0.0)) / max(cos_entry, 1e-3), 8.0);
    e *= seen_share(f.light, lifted, lifted.texel_world * (1.5 + slope));
    let eta = clamp(translucent_maps[translucent_medium_at(f.object) + 1u].w, 1.0, 3.0);
    translucent_maps[at] = entry_light(e, cos_entry, eta);
}

// `entry_light` (translucent_shadow_map.rs): E T(μ₀) μ₀/μ₀′, and the path's scale μ₀/μ₀′ at
// least `PATH_SCALE_FLOOR`.
const PATH_SCALE_FLOOR: f32 = 0.7;

fn entry_light(e: vec3<f32>, cos_entry: f32, eta: f32) -> vec4<f32> {
    let mu0 = clamp(cos_entry, 1e-3, 1.0);
    let inside = sqrt(max(1.0 - (1.0 - mu0 * mu0) / (eta * eta), 0.0));
    let scale = mu0 / max(inside, 1e-3);
    return vec4(e * (1.0 - fresnel_reflectance(mu0, eta)) * scale, max(scale, PATH_SCALE_FLOOR));
}
