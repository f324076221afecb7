// Volumetric spot lights (seed 004): per pixel, the view ray from the camera to the depth
// buffer, clipped to each spot's cone and range, and its single scattering integrated at equal
// angles around the light: t = t_c + h tan γ, for which dt / |x − p|² = dγ / h (no 1/d² spike).
// Output: the in-scattered radiance (added) and the transmittance to the surface (which
// multiplies what the surface sends). Mirrors `volumetric::reference::estimate` with
// `Sampling::EqualAngle` (and, under SLICING_PLANES, `Sampling::SlicingPlanes`).

#import bevy_pbr::{
    mesh_view_bindings::{view, clustered_lights},
    mesh_view_types::POINT_LIGHT_FLAGS_SHADOWS_ENABLED_BIT,
    prepass_utils,
    shadows,
}

struct Spot {
    position_range: vec4<f32>,
    direction_samples: vec4<f32>,
    color: vec4<f32>,
    // cos(outer), Bevy's spot scale and offset, the light's index in Bevy's clustered lights
    // (its shadow map; −1: none).
    cone: vec4<f32>,
    // The NDC rectangle the cone can cover (min x, min y, max x, max y).
    screen_rect: vec4<f32>,
    // A sphere around the cone out to its range: centre, radius.
    bounds: vec4<f32>,
}

struct Volumetric {
    // σs, σa, g, number of spots.
    medium: vec4<f32>,
    spots: array<Spot, 64>,
}

@group(2) @binding(0) var<uniform> volumetric: Volumetric;
// The low-resolution in-scatter, for the upsample.
@group(2) @binding(1) var in_scatter: texture_2d<f32>;

const PI: f32 = 3.141592653589793;
// Where a ray without a surface stops: the range sphere clips it first.
const NO_SURFACE: f32 = 1.0e30;

// Henyey–Greenstein phase of the angle between the light's travel and the scattered light's.
fn phase(cos_theta: f32, g: f32) -> f32 {
    return (1.0 - g * g) / (4.0 * PI * pow(max(1.0 + g * g - 2.0 * g * cos_theta, 1e-6), 1.5));
}

// Whether x lies inside the cone (its forward half) and the range of the spot.
fn inside(spot: Spot, x: vec3<f32>) -> bool {
    let w = x - spot.position_range.xyz;
    return dot(w, spot.direction_samples.xyz) >= spot.cone.x * length(w)
        && dot(w, w) < spot.position_range.w * spot.position_range.w;
}

// The part of [s_a, s_b] of the ray c + s·d inside the spot's cone and range (one interval:
// both are convex); x > y where it has none. `c` is the ray's point closest to the light: about
// it the quadratics below are well conditioned (about a camera metres away, a crossing of the
// cone a few millimetres from its apex is lost to cancellation in f32: rays grazing the light
// came out 6 % too dark).
fn clip_to_light(spot: Spot, c: vec3<f32>, d: vec3<f32>, s_a: f32, s_b: f32) -> vec2<f32> {
    let p = spot.position_range.xyz;
    let w0 = c - p;
    // Range sphere.
    let b = dot(d, w0);
    let disc_s = b * b - (dot(w0, w0) - spot.position_range.w * spot.position_range.w);
    if disc_s <= 0.0 {
        return vec2(1.0, 0.0);
    }
    let s = sqrt(disc_s);
    let a0 = max(s_a, -b - s);
    let b0 = min(s_b, -b + s);
    if b0 <= a0 {
        return vec2(1.0, 0.0);
    }
    // Cone: (w·u)² = cos² |w|², a quadratic in t; its roots split [a0, b0] into at most three
    // pieces, of which the inside ones are contiguous.
    let u = spot.direction_samples.xyz;
    let c2 = spot.cone.x * spot.cone.x;
    let du = dot(d, u);
    let wu = dot(w0, u);
    let qa = du * du - c2;
    let qb = 2.0 * (du * wu - c2 * dot(d, w0));
    let qc = wu * wu - c2 * dot(w0, w0);
    var r = vec2(a0, a0);
    if abs(qa) > 1e-7 {
        let disc = qb * qb - 4.0 * qa * qc;
        if disc >= 0.0 {
            let q = sqrt(disc);
            let r1 = (-qb - q) / (2.0 * qa);
            let r2 = (-qb + q) / (2.0 * qa);
            r = clamp(vec2(min(r1, r2), max(r1, r2)), vec2(a0), vec2(b0));
        }
    } else if abs(qb) > 1e-7 {
        r = vec2(clamp(-qc / qb, a0, b0));
    }
    let cuts = array<f32, 4>(a0, r.x, r.y, b0);
    var first = 1.0;
    var last = 0.0;
    var found = false;
    for (var i = 0u; i < 3u; i++) {
        let lo = cuts[i];
        let hi = cuts[i + 1u];
        if hi > lo && inside(spot, c + d * (0.5 * (lo + hi))) {
            if !found {
                first = lo;
                found = true;
            }
            last = hi;
        }
    }
    return vec2(first, last);
}

// Visibility of the spot from x through its shadow map (Bevy's own lookup and filtering, the
// direction to the light standing for the surface normal of its normal bias).
fn spot_visibility(spot: Spot, x: vec3<f32>, l: vec3<f32>, frag_coord: vec2<f32>) -> f32 {
    if spot.cone.w < 0.0 {
        return 1.0;
    }
    let id = u32(spot.cone.w);
    let light = &clustered_lights.data[id];
    if ((*light).flags & POINT_LIGHT_FLAGS_SHADOWS_ENABLED_BIT) == 0u {
        return 1.0;
    }
    // Nothing nearer the light than its shadow map's near plane is in the map, so the map
    // cannot shadow such a point; and Bevy's lookup would push it past the light by the depth
    // bias (2 cm), behind the map, reading it as shadowed: at 1080p the pixels whose rays pass
    // within 0.5° of the light came out 23 % too dark (0.023 of the whole picture's error).
    let near_z = (*light).shadow_map_near_z;
    if dot(x - spot.position_range.xyz, spot.direction_samples.xyz) < near_z {
        return 1.0;
    }
    return shadows::fetch_spot_shadow(id, vec4(x, 1.0), -l, near_z, frag_coord);
}

// In-scattered radiance of one spot along the ray over [t_a, t_b].
// The ray over [t_a, t_b] in the spot's equal-angle variable, t = t_c + h tan γ: the closest
// approach t_c, the distance h, and the angles of the part inside the cone and range (g_b ≤ g_a
// where there is none).
struct EqualAngleSpan {
    t_c: f32,
    h: f32,
    g_a: f32,
    g_b: f32,
}

fn equal_angle_span(spot: Spot, o: vec3<f32>, d: vec3<f32>, t_a: f32, t_b: f32) -> EqualAngleSpan {
    var e: EqualAngleSpan;
    let p = spot.position_range.xyz;
    e.t_c = dot(p - o, d);
    let c = o + d * e.t_c;
    let span = clip_to_light(spot, c, d, t_a - e.t_c, t_b - e.t_c);
    if span.y <= span.x {
        return e;
    }
    e.h = max(length(c - p), 1e-5);
    e.g_a = atan(span.x / e.h);
    e.g_b = atan(span.y / e.h);
    return e;
}

// The integrand in t times |x − p|² at ray parameter t, F · W · V · ρ · e^(−σt (t + |x − p|)),
// and |x − p|: Bevy's spot fall-off and range window (`pbr_lighting.wgsl`), the spot's shadow
// map, the phase, extinction along the ray and from the light.
fn scattered_at(spot: Spot, o: vec3<f32>, d: vec3<f32>, t: f32, frag_coord: vec2<f32>) -> vec2<f32> {
    let p = spot.position_range.xyz;
    // From the ray's point closest to the light, as in `clip_to_light`.
    let t_c = dot(p - o, d);
    let v = (o + d * t_c - p) + d * (t - t_c);
    let dist = length(v);
    let l = v / dist;
    let a = saturate(dot(l, spot.direction_samples.xyz) * spot.cone.y + spot.cone.z);
    let f = dist * dist / (spot.position_range.w * spot.position_range.w);
    let window = saturate(1.0 - f * f);
    let w = a * a * window * window;
    if w <= 0.0 {
        return vec2(0.0, dist);
    }
    let visible = spot_visibility(spot, p + v, l, frag_coord);
    let sigma_t = volumetric.medium.x + volumetric.medium.y;
    return vec2(w * visible * phase(-dot(l, d), volumetric.medium.z) * exp(-sigma_t * (t + dist)), dist);
}

fn in_scattered(
    spot: Spot,
    o: vec3<f32>,
    d: vec3<f32>,
    t_a: f32,
    t_b: f32,
    frag_coord: vec2<f32>,
) -> vec3<f32> {
    let e = equal_angle_span(spot, o, d, t_a, t_b);
    if e.g_b <= e.g_a {
        return vec3(0.0);
    }
    let n = max(u32(spot.direction_samples.w), 1u);
    let step = (e.g_b - e.g_a) / f32(n);
    var sum = 0.0;
    for (var i = 0u; i < n; i++) {
        let gamma = e.g_a + (f32(i) + 0.5) * step;
        sum += scattered_at(spot, o, d, e.t_c + e.h * tan(gamma), frag_coord).x;
    }
    return spot.color.rgb * (volumetric.medium.x / e.h * sum * step);
}

struct FullscreenVertexOutput {
    @builtin(position) position: vec4<f32>,
}

@vertex
fn vertex(@builtin(vertex_index) vertex_index: u32) -> FullscreenVertexOutput {
    let uv = vec2<f32>(f32(vertex_index >> 1u), f32(vertex_index & 1u)) * 2.0;
    return FullscreenVertexOutput(vec4(uv * vec2(2.0, -2.0) + vec2(-1.0, 1.0), 0.0, 1.0));
}

// The view ray of the pixel at `pixel` (render-target coordinates): origin, direction, where it
// meets the depth buffer's surface (NO_SURFACE for the sky), and that surface's NDC depth.
struct ViewRay {
    o: vec3<f32>,
    d: vec3<f32>,
    t_end: f32,
    ndc_depth: f32,
    ndc: vec2<f32>,
}

// Whether the pixel lies where the spot's cone can be seen (its screen rectangle).
fn may_cover(spot: Spot, r: ViewRay) -> bool {
    return all(r.ndc >= spot.screen_rect.xy) && all(r.ndc <= spot.screen_rect.zw);
}

fn view_ray(pixel: vec2<f32>) -> ViewRay {
    return view_ray_at(pixel, prepass_utils::prepass_depth(vec4(pixel, 0.0, 0.0), 0u));
}

// The view ray of the pixel at `pixel` whose depth buffer holds `ndc_depth`.
fn view_ray_at(pixel: vec2<f32>, ndc_depth: f32) -> ViewRay {
    var r: ViewRay;
    r.ndc_depth = ndc_depth;
    let ndc = (pixel - view.viewport.xy) / view.viewport.zw * vec2(2.0, -2.0) + vec2(-1.0, 1.0);
    r.ndc = ndc;
    // The near-plane point in view space, where the camera is the origin: taking the direction
    // as (near point − camera) in world space would lose ~1e-5 rad to cancellation (the near
    // plane is 0.1 m from a camera metres from the origin), a few per cent of the in-scatter
    // near the light at 1080p, where it goes as 1/h.
    let near = view.view_from_clip * vec4(ndc, 1.0, 1.0);
    let near_in_view = near.xyz / near.w;
    // Perspective: from the camera; orthographic: from the near plane.
    let orthographic = view.clip_from_view[3].w == 1.0;
    r.o = select(view.world_position, (view.world_from_view * vec4(near_in_view, 1.0)).xyz, orthographic);
    r.d = normalize((view.world_from_view * vec4(select(near_in_view, vec3(0.0, 0.0, -1.0), orthographic), 0.0)).xyz);
    r.t_end = NO_SURFACE;
    if r.ndc_depth > 0.0 {
        let surface = view.world_from_clip * vec4(ndc, r.ndc_depth, 1.0);
        r.t_end = dot(surface.xyz / surface.w - r.o, r.d);
    }
    return r;
}

// What the surface sends is dimmed by the medium in front of it; the sky is left as it is
// (the medium is taken to end before it).
fn transmittance(r: ViewRay) -> f32 {
    let sigma_t = volumetric.medium.x + volumetric.medium.y;
    return select(1.0, exp(-sigma_t * r.t_end), r.ndc_depth > 0.0);
}

// The in-scatter's smooth, unshadowed part for the reduced resolutions: per spot the closed
// form σs · I · (γ_b − γ_a) / (4π h) over the ray clipped to its cone and range (no fall-off,
// phase or extinction), summed with each spot's brightest channel. It holds the 1/h spike near
// each light and the cone's edges at full resolution; the low-resolution pass stores the
// in-scatter divided by it, which is smooth, and the upsample multiplies it back.
fn unshadowed_closed_form(r: ViewRay) -> f32 {
    var sum = 0.0;
    let count = u32(volumetric.medium.w);
    for (var i = 0u; i < count; i++) {
        let spot = volumetric.spots[i];
        if !may_cover(spot, r) {
            continue;
        }
        let e = equal_angle_span(spot, r.o, r.d, 0.0, r.t_end);
        if e.g_b <= e.g_a {
            continue;
        }
        let c = spot.color.rgb;
        sum += max(c.r, max(c.g, c.b)) * (e.g_b - e.g_a) / e.h;
    }
    return sum * volumetric.medium.x / (4.0 * PI) * view.exposure;
}

fn in_scattered_all(r: ViewRay, frag_coord: vec2<f32>) -> vec3<f32> {
    var radiance = vec3(0.0);
    let count = u32(volumetric.medium.w);
    for (var i = 0u; i < count; i++) {
        let spot = volumetric.spots[i];
        if may_cover(spot, r) {
            radiance += in_scattered(spot, r.o, r.d, 0.0, r.t_end, frag_coord);
        }
    }
    return radiance * view.exposure;
}

#ifdef COMPUTE_PASS
// The compute form of the full-resolution pass (where the view's main images are HDR and
// allow storage writes): Bevy's post-process ping-pong, reading the lit image and writing
// in-scatter + transmittance × lit into the other main image, every pixel of it. Spots are
// culled per 8×8 tile: a spot is kept where its screen rectangle overlaps the tile's and its
// bounding sphere begins in front of the tile's farthest surface (no ray of the tile reaches a
// cone behind every surface of it). The kept spots are a bit mask, walked in index order, so
// the sum is the raster pass's, in the same order.
@group(2) @binding(2) var depth_texture: texture_depth_2d;
@group(2) @binding(3) var lit: texture_2d<f32>;
@group(2) @binding(4) var view_out: texture_storage_2d<rgba16float, write>;

const TILE: u32 = 8u;
// `volumetric::MAX_VOLUMETRIC_SPOTS` bits.
var<workgroup> tile_spots: array<atomic<u32>, 2>;
// The tile's farthest surface: the least reversed-Z depth, as bits (depths are ≥ 0, so the
// bits order as the values do); 0 where a pixel sees the sky.
var<workgroup> tile_farthest: atomic<u32>;

// Distance along the view direction (view-space −z) of a world point.
fn view_z(x: vec3<f32>) -> f32 {
    return -(view.view_from_world * vec4(x, 1.0)).z;
}

// Whether a spot's cone may add light to some pixel of the tile covering NDC rectangle `rect`
// (min x, min y, max x, max y) whose farthest surface lies at NDC depth `farthest`.
fn tile_may_see(spot: Spot, rect: vec4<f32>, farthest: f32) -> bool {
    if any(rect.xy > spot.screen_rect.zw) || any(rect.zw < spot.screen_rect.xy) {
        return false;
    }
    if farthest <= 0.0 {
        return true;
    }
    let surface = view.view_from_clip * vec4(0.0, 0.0, farthest, 1.0);
    let farthest_z = -surface.z / surface.w;
    return view_z(spot.bounds.xyz) - spot.bounds.w <= farthest_z;
}

@compute @workgroup_size(8, 8, 1)
fn compute_spots(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(local_invocation_index) local: u32,
    @builtin(workgroup_id) group: vec3<u32>,
) {
    let size = textureDimensions(view_out);
    let pixel = vec2<f32>(id.xy) + 0.5;
    let in_target = all(id.xy < size);
    let in_viewport = in_target && all(pixel >= view.viewport.xy)
        && all(pixel < view.viewport.xy + view.viewport.zw);
    var ndc_depth = 0.0;
    if in_viewport {
        ndc_depth = textureLoad(depth_texture, vec2<i32>(id.xy), 0);
    }
    if local < 2u {
        atomicStore(&tile_spots[local], 0u);
    }
    if local == 0u {
        atomicStore(&tile_farthest, 0x7f7fffffu);
    }
    workgroupBarrier();
    if in_viewport {
        atomicMin(&tile_farthest, bitcast<u32>(max(ndc_depth, 0.0)));
    }
    workgroupBarrier();
    // One thread per spot (at most 64 spots, 64 threads).
    let count = u32(volumetric.medium.w);
    if local < count {
        let corner = vec2<f32>(group.xy * TILE);
        let lo = (corner - view.viewport.xy) / view.viewport.zw * vec2(2.0, -2.0) + vec2(-1.0, 1.0);
        let hi = (corner + f32(TILE) - view.viewport.xy) / view.viewport.zw * vec2(2.0, -2.0)
            + vec2(-1.0, 1.0);
        let rect = vec4(lo.x, hi.y, hi.x, lo.y);
        let farthest = bitcast<f32>(atomicLoad(&tile_farthest));
        if tile_may_see(volumetric.spots[local], rect, farthest) {
            atomicOr(&tile_spots[local / 32u], 1u << (local % 32u));
        }
    }
    workgroupBarrier();
    if !in_target {
        return;
    }
    let surface = textureLoad(lit, id.xy, 0);
    if !in_viewport {
        textureStore(view_out, id.xy, surface);
        return;
    }
    let r = view_ray_at(pixel, ndc_depth);
    var radiance = vec3(0.0);
    for (var word = 0u; word < 2u; word++) {
        var bits = atomicLoad(&tile_spots[word]);
        while bits != 0u {
            let i = word * 32u + firstTrailingBit(bits);
            bits &= bits - 1u;
            let spot = volumetric.spots[i];
            if may_cover(spot, r) {
                radiance += in_scattered(spot, r.o, r.d, 0.0, r.t_end, pixel);
            }
        }
    }
    textureStore(view_out, id.xy, vec4(radiance * view.exposure + surface.rgb * transmittance(r), surface.a));
}
#endif

// Full resolution: every pixel's in-scatter and transmittance, blended into the view. At a
// reduced resolution (LOW_RESOLUTION_PASS): one pixel in RESOLUTION_FACTOR², the block's
// first, into the in-scatter image.
@fragment
fn fragment(in: FullscreenVertexOutput) -> @location(0) vec4<f32> {
#ifdef LOW_RESOLUTION_PASS
    let pixel = view.viewport.xy + floor(in.position.xy) * f32(#{RESOLUTION_FACTOR}u) + 0.5;
    let r = view_ray(pixel);
    let closed_form = unshadowed_closed_form(r);
    if closed_form <= 0.0 {
        return vec4(0.0);
    }
    // The ratio to the closed form (alpha 1: this sample has one).
    return vec4(in_scattered_all(r, pixel) / closed_form, 1.0);
#else
    let r = view_ray(in.position.xy);
    return vec4(in_scattered_all(r, in.position.xy), transmittance(r));
#endif
}

#ifdef RESOLUTION_FACTOR
// Distance along the view direction of the surface at NDC depth `ndc_depth` (the sky far away).
fn view_depth(ndc_depth: f32) -> f32 {
    if ndc_depth <= 0.0 {
        return 1.0e9;
    }
    let p = view.view_from_clip * vec4(0.0, 0.0, ndc_depth, 1.0);
    return -p.z / p.w;
}

// The depth-aware upsample of the ratio to the closed form: the four low-resolution samples
// around the pixel, bilinear weights times how close each sample's surface is in depth to the
// pixel's (so that a beam's edge on a foreground object does not bleed onto the background),
// samples without a closed form (outside every cone) left out; times the pixel's own closed
// form; the transmittance per pixel.
@fragment
fn upsample(in: FullscreenVertexOutput) -> @location(0) vec4<f32> {
    let f = f32(#{RESOLUTION_FACTOR}u);
    let r = view_ray(in.position.xy);
    let closed_form = unshadowed_closed_form(r);
    if closed_form <= 0.0 {
        return vec4(0.0, 0.0, 0.0, transmittance(r));
    }
    let z = view_depth(r.ndc_depth);
    let size = vec2<i32>(textureDimensions(in_scatter));
    // Low-resolution sample i stands at the centre of full-resolution pixel i·f.
    let g = (in.position.xy - view.viewport.xy - 0.5) / f;
    let base = floor(g);
    let t = g - base;
    var sum = vec3(0.0);
    var weight = 0.0;
    for (var k = 0u; k < 4u; k++) {
        let c = vec2(f32(k & 1u), f32(k >> 1u));
        let q = clamp(vec2<i32>(base + c), vec2(0), size - 1);
        let sample_pixel = view.viewport.xy + vec2<f32>(q) * f + 0.5;
        let zq = view_depth(prepass_utils::prepass_depth(vec4(sample_pixel, 0.0, 0.0), 0u));
        let bilinear = mix(1.0 - t.x, t.x, c.x) * mix(1.0 - t.y, t.y, c.y);
        let similar = 1.0 / (1.0e-3 + abs(zq - z) / max(z, 1.0e-3));
        let ratio = textureLoad(in_scatter, q, 0);
        let w = max(bilinear, 1.0e-3) * similar * ratio.a;
        sum += w * ratio.rgb;
        weight += w;
    }
    return vec4(sum / max(weight, 1.0e-9) * closed_form, transmittance(r));
}
#endif

#ifdef SLICING_PLANES
// Seed 004's sampling planes as it rasterises them (`VolumetricMethod::SlicingPlanes`), for the
// comparison: per spot `samples` planes perpendicular to the view axis at view depths
// z_p + H tan γ_k, equal steps of γ around the light (z_p its view depth, H its distance from the
// view axis, at least 1 % of the span) over the depths of its cone's bounding sphere; each drawn
// over the cone's screen rectangle, each pixel in front of the depth buffer adding the
// integrand where its ray meets the plane times the ray length the plane stands for. Instance 0
// dims the surfaces; instance 1 + PLANES_PER_SPOT · i + k is plane k of spot i. Mirrors
// `reference::SlicingPlanes`.
// `volumetric::MAX_VOLUMETRIC_SAMPLES`.
const PLANES_PER_SPOT: u32 = #{PLANES_PER_SPOT}u;

struct PlaneVertexOutput {
    @builtin(position) position: vec4<f32>,
    // The plane's view depth, the view depth it stands for, its spot (−1: the dimming).
    @location(0) @interpolate(flat) plane: vec3<f32>,
}

fn view_forward() -> vec3<f32> {
    return normalize((view.world_from_view * vec4(0.0, 0.0, -1.0, 0.0)).xyz);
}

@vertex
fn plane_vertex(@builtin(vertex_index) vertex_index: u32, @builtin(instance_index) instance: u32) -> PlaneVertexOutput {
    var corners = array<vec2<f32>, 6>(vec2(0.0, 0.0), vec2(1.0, 0.0), vec2(0.0, 1.0), vec2(0.0, 1.0), vec2(1.0, 0.0), vec2(1.0, 1.0));
    let corner = corners[vertex_index];
    if instance == 0u {
        return PlaneVertexOutput(vec4(corner * 2.0 - 1.0, 0.0, 1.0), vec3(0.0, 0.0, -1.0));
    }
    // Planes a spot does not have collapse to a point: no fragments.
    let none = PlaneVertexOutput(vec4(0.0, 0.0, 0.0, 1.0), vec3(0.0, 0.0, -1.0));
    let i = (instance - 1u) / PLANES_PER_SPOT;
    let k = (instance - 1u) % PLANES_PER_SPOT;
    if i >= u32(volumetric.medium.w) {
        return none;
    }
    let spot = volumetric.spots[i];
    let n = max(u32(spot.direction_samples.w), 1u);
    if k >= n {
        return none;
    }
    let forward = view_forward();
    let w = spot.position_range.xyz - view.world_position;
    let z_p = dot(w, forward);
    let z_bounds = dot(spot.bounds.xyz - view.world_position, forward);
    // Bevy's perspective projections keep the near plane's distance in clip_from_view[3][2];
    // planes in front of an orthographic camera's near plane are clipped.
    let orthographic = view.clip_from_view[3].w == 1.0;
    let near = max(z_bounds - spot.bounds.w, select(view.clip_from_view[3][2], 0.0, orthographic));
    let far = z_bounds + spot.bounds.w;
    if far <= near {
        return none;
    }
    let h = max(length(w - forward * z_p), 0.01 * (far - near));
    let g_a = atan((near - z_p) / h);
    let step = (atan((far - z_p) / h) - g_a) / f32(n);
    let z = z_p + h * tan(g_a + (f32(k) + 0.5) * step);
    let dz = h * (tan(g_a + f32(k + 1u) * step) - tan(g_a + f32(k) * step));
    let clip = view.clip_from_view * vec4(0.0, 0.0, -z, 1.0);
    let ndc = mix(spot.screen_rect.xy, spot.screen_rect.zw, corner);
    return PlaneVertexOutput(vec4(ndc * clip.w, clip.z, clip.w), vec3(z, dz, f32(i)));
}

@fragment
fn plane_fragment(in: PlaneVertexOutput) -> @location(0) vec4<f32> {
    let r = view_ray(in.position.xy);
    if in.plane.z < 0.0 {
        return vec4(0.0, 0.0, 0.0, transmittance(r));
    }
    let spot = volumetric.spots[u32(in.plane.z)];
    let forward = view_forward();
    let along = dot(r.d, forward);
    let t = (in.plane.x - dot(r.o - view.world_position, forward)) / along;
    // The seed's depth test against the G-buffer, and nothing behind the camera.
    if along <= 0.0 || t <= 0.0 || t >= r.t_end {
        return vec4(0.0, 0.0, 0.0, 1.0);
    }
    let s = scattered_at(spot, r.o, r.d, t, in.position.xy);
    // σs · I · integrand / |x − p|² times the ray length the plane stands for.
    let dt = in.plane.y / along;
    return vec4(spot.color.rgb * (volumetric.medium.x * s.x / (s.y * s.y) * dt) * view.exposure, 1.0);
}
#endif
