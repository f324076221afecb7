// Height pass, compute half (paper §2.1, eq. 7; seed 003): per mesostructure pixel, the height
// `dis · k` fetched through the UVs the raster half stored, the Blinn bump normal N', and the
// texture-space occlusion and light visibility from the material's horizon map. All the
// texture work runs here, not in the raster half's fragment shader: on GPUs with few pixel-
// shader units (an H100 runs fragment work ~30x slower than compute) it had cost 15-43 ms a
// 1080p frame (docs/bench.md). The screen derivatives the fragment stage had from its quads are
// taken here from neighbouring pixels of the same object (the quad partner, as hardware coarse
// derivatives do; the other side where the partner is another object or across a UV seam).
// One dispatch per parameter set (height map, horizon map, k, bump flag); the first also
// writes "none" into the MHM of pixels without a mesostructure surface. Nothing is cleared:
// a texel of the raster half is this frame's where Bevy's prepass left a mesostructure
// material (its deferred lighting pass id) at that texel's depth.

#import bevy_render::view::View
#import bevy_pbr::mesh_view_types::Lights
#import bevy_mesostructure::common::core_point

// (u, v, NDC depth, object id) from the raster half; id 0: no mesostructure.
@group(0) @binding(0) var surface: texture_2d<f32>;
// (n0 in world space, parameter set index) from the raster half.
@group(0) @binding(1) var core_normal: texture_2d<f32>;
// MHM: (dis · k in world units, NDC depth, object id, dis).
@group(0) @binding(2) var mhm_out: texture_storage_2d<rgba32float, write>;
// (N' by Blinn bump mapping in world space, or 0 where the material has a normal map;
// texture-space occlusion, or −1 where none).
@group(0) @binding(3) var bump_out: texture_storage_2d<rgba16float, write>;
// Texture-space terms of the first directional light: its visibility and its one bounce
// relative to E0 (`texture_bounce`), each −1 where none.
@group(0) @binding(4) var visibility_out: texture_storage_2d<rg32float, write>;
@group(0) @binding(5) var<uniform> view: View;
@group(0) @binding(6) var<uniform> lights: Lights;
// Bevy's prepass depth and deferred lighting pass ids: which raster texels are this frame's.
@group(0) @binding(7) var prepass_depth: texture_depth_2d;
@group(0) @binding(8) var lighting_pass_id: texture_2d<u32>;

struct HeightParameters {
    // k, world units.
    scale: f32,
    // 1: write the Blinn bump normal; 0: the material has its own normal map.
    bump: f32,
    // The index the raster half writes into the core normal's w for this set.
    index: f32,
    spare: f32,
}

@group(1) @binding(0) var height_mips: texture_2d<f32>;
// Texture-space horizon map (`HorizonMap` in height_map_import.rs), HORIZON_BLOCKS blocks wide:
// the highest slope towards azimuths 4b … 4b + 3 in block b (i · 360° / HORIZON_AZIMUTHS in
// texel space; height per UV unit of distance), per distance band (see `HorizonMap::to_image`),
// then the height gradient per UV unit.
@group(1) @binding(1) var horizons: texture_2d<f32>;
// The texel steps (1 … 32) at which those slopes are reached, one byte each, laid out as the
// slopes but without the gradient block (`HorizonMap::distance_image`).
@group(1) @binding(2) var horizon_distances: texture_2d<u32>;
@group(1) @binding(3) var<uniform> material: HeightParameters;

const PI: f32 = 3.141592653589793;
// Azimuths of the horizon map (`height_map_import::HORIZON_AZIMUTHS`, a multiple of 4): per
// distance band their slopes four a block; then the gradient block.
const HORIZON_AZIMUTHS: u32 = #{HORIZON_AZIMUTHS}u;
const AZIMUTH_BLOCKS: i32 = i32(HORIZON_AZIMUTHS / 4u);
// Distance bands (`height_map_import::HORIZON_BANDS`).
const HORIZON_BANDS: i32 = #{HORIZON_BANDS};
const HORIZON_BLOCKS: i32 = HORIZON_BANDS * AZIMUTH_BLOCKS + 1;
// The most light a shadowed pixel keeps at a shadow edge (`height_map_import::EDGE_SHADOWED_PERCENT`).
const EDGE_SHADOWED: f32 = f32(#{EDGE_SHADOWED_PERCENT}u) / 100.0;
#ifdef TEXTURE_SPACE_BOUNCE
// Points per azimuth of the texture-space bounce (`height_map_import::TEXTURE_BOUNCE_SAMPLES`).
const TEXTURE_BOUNCE_SAMPLES: u32 = #{TEXTURE_BOUNCE_SAMPLES}u;
#endif

fn height_texel(p: vec2<i32>, level: i32, size: vec2<i32>) -> f32 {
    // Repeat addressing: height maps tile. The UVs come in wrapped to [0, 1), so a tap is at
    // most two texels outside the level; one select per side instead of integer remainders
    // (two divisions per tap, 24 taps a pixel, were much of this pass's cost).
    var wrapped = select(p, p + size, p < vec2(0));
    wrapped = select(wrapped, wrapped - size, wrapped >= size);
    return textureLoad(height_mips, clamp(wrapped, vec2(0), size - 1), level).r;
}

// The texel below-left of `uv` on `level`, the bilinear weights, and the level's size.
struct Footprint {
    i: vec2<i32>,
    f: vec2<f32>,
    size: vec2<i32>,
}

fn footprint(uv: vec2<f32>, level: i32) -> Footprint {
    // Level sizes from level 0: a per-pixel (non-uniform) level in textureDimensions reads the
    // wrong level on some drivers (seen on lavapipe), which then loads out of bounds.
    let size = max(vec2<i32>(textureDimensions(height_mips)) >> vec2<u32>(u32(level)), vec2(1));
    let p = uv * vec2<f32>(size) - 0.5;
    let base = floor(p);
    return Footprint(vec2<i32>(base), p - base, size);
}

// Bilinear filtering by hand: the mip chain is R32Float, which need not be filterable.
fn height_bilinear(uv: vec2<f32>, level: i32) -> f32 {
    let fp = footprint(uv, level);
    let i = fp.i;
    let f = fp.f;
    let size = fp.size;
    let h00 = height_texel(i, level, size);
    let h10 = height_texel(i + vec2(1, 0), level, size);
    let h01 = height_texel(i + vec2(0, 1), level, size);
    let h11 = height_texel(i + vec2(1, 1), level, size);
    return mix(mix(h00, h10, f.x), mix(h01, h11, f.x), f.y);
}

// The bilinear height at `uv` on `level` and the differences of the bilinear heights one texel
// to either side along x and along y (same weights, shifted texels): the value and the central
// differences of the Blinn bump from 12 texel loads instead of 20.
struct HeightTaps {
    center: f32,
    // B(uv + x̂) − B(uv − x̂) and B(uv + ŷ) − B(uv − ŷ), one texel of the level each way
    across: vec2<f32>,
    // Texels of the level per UV unit.
    size: vec2<f32>,
}

fn height_taps(uv: vec2<f32>, level: i32) -> HeightTaps {
    let fp = footprint(uv, level);
    let i = fp.i;
    let f = fp.f;
    let size = fp.size;
    // Rows i.y and i.y + 1, columns i.x − 1 … i.x + 2.
    let a0 = height_texel(i + vec2(-1, 0), level, size);
    let b0 = height_texel(i, level, size);
    let c0 = height_texel(i + vec2(1, 0), level, size);
    let d0 = height_texel(i + vec2(2, 0), level, size);
    let a1 = height_texel(i + vec2(-1, 1), level, size);
    let b1 = height_texel(i + vec2(0, 1), level, size);
    let c1 = height_texel(i + vec2(1, 1), level, size);
    let d1 = height_texel(i + vec2(2, 1), level, size);
    // Columns i.x and i.x + 1, rows i.y − 1 and i.y + 2.
    let bm = height_texel(i + vec2(0, -1), level, size);
    let cm = height_texel(i + vec2(1, -1), level, size);
    let bp = height_texel(i + vec2(0, 2), level, size);
    let cp = height_texel(i + vec2(1, 2), level, size);
    let row0 = mix(b0, c0, f.x);
    let row1 = mix(b1, c1, f.x);
    let right = mix(mix(c0, d0, f.x), mix(c1, d1, f.x), f.y);
    let left = mix(mix(a0, b0, f.x), mix(a1, b1, f.x), f.y);
    let below = mix(row1, mix(bp, cp, f.x), f.y);
    let above = mix(mix(bm, cm, f.x), row0, f.y);
    return HeightTaps(mix(row0, row1, f.y), vec2(right - left, below - above), vec2<f32>(size));
}

// Blinn bump mapping (seed 003), unnormalised: N' = Pu × Pv + Fu (n × Pv) − Fv (n × Pu),
// oriented like n; `pu`, `pv` the surface's derivatives along the texture axes, `fu`, `fv`
// those of the displacement F = k · dis.
fn blinn_normal(n: vec3<f32>, pu: vec3<f32>, pv: vec3<f32>, fu: f32, fv: f32) -> vec3<f32> {
    let base = cross(pu, pv);
    let orientation = select(-1.0, 1.0, dot(base, n) >= 0.0);
    return orientation * (base + fu * cross(n, pv) - fv * cross(n, pu));
}

// ∫ cos(φ − γ) sin φ dφ (antiderivative): the cosine-weighted solid angle of a slice through
// the core normal, φ measured from it, γ the angle of the true normal projected into the slice.
fn slice_antiderivative(phi: f32, gamma: f32) -> f32 {
    return -0.25 * cos(2.0 * phi - gamma) + 0.5 * phi * sin(gamma);
}

// The core around a pixel, as the texture-space horizons need it: the core normal `n`, the
// world vectors per UV unit `pu`, `pv`, the normal's change per UV unit `nu`, `nv` (from which
// the core's curvature along any azimuth), and the material's scale `k`.
struct CoreFrame {
    n: vec3<f32>,
    pu: vec3<f32>,
    pv: vec3<f32>,
    nu: vec3<f32>,
    nv: vec3<f32>,
    k: f32,
}

// The world vector per UV unit along texel-space direction `d`, and the core's normal
// curvature along it (1/world units, positive where convex: dN · dP / |dP|²).
struct Along {
    along: vec3<f32>,
    curvature: f32,
}

fn along_direction(core: CoreFrame, d: vec2<f32>) -> Along {
    let along = core.pu * d.x + core.pv * d.y;
    let bend = core.nu * d.x + core.nv * d.y;
    let reach2 = dot(along, along);
    return Along(along, select(0.0, dot(bend, along) / reach2, reach2 > 0.0));
}

// The tangent of the horizon's elevation above the core's tangent plane from a horizon-map
// `slope` reached at UV `distance` (`height_map_import::horizon_tangent`): the map's slope in
// world units, less the core's fall κ D² / 2 below its tangent plane at D = distance · reach.
fn horizon_tangent(slope: f32, distance: f32, k: f32, reach: f32, curvature: f32) -> f32 {
    return k * slope / reach - 0.5 * curvature * distance * reach;
}

// UV length of one texel step along horizon azimuth `i` on a level `level` texels in size
// (`height_map_import::horizon_step`); the same for the opposite azimuth.
fn horizon_step(i: u32, level: vec2<i32>) -> f32 {
    let a = f32(i) * 2.0 * PI / f32(HORIZON_AZIMUTHS);
    return length(vec2(cos(a), sin(a)) / vec2<f32>(level));
}

// The highest horizon tangent of azimuth `i` at `texel` over the distance bands, each band's
// slope lowered by the core's fall where it is reached (exact on a flat core; a lower bound on
// a curved one, tight at both bands' distances). `level`: the horizon map level's size (one
// block); `step`: `horizon_step(i, level)`.
fn texel_horizon_tangent(texel: vec2<i32>, level: vec2<i32>, i: u32, step: f32, k: f32, reach: f32, curvature: f32) -> f32 {
    var best = -3.0e38;
    for (var band = 0; band < HORIZON_BANDS; band++) {
        let offset = vec2((band * AZIMUTH_BLOCKS + i32(i / 4u)) * level.x, 0);
        let slope = textureLoad(horizons, texel + offset, 0)[i % 4u];
        let distance = f32(textureLoad(horizon_distances, texel + offset, 0)[i % 4u]) * step;
        best = max(best, horizon_tangent(slope, distance, k, reach, curvature));
    }
    return best;
}

// Cosine-weighted ambient occlusion of the true surface at texel `texel` of the horizon map,
// about its true normal, from the horizons of its HORIZON_AZIMUTHS azimuths (half as many
// slices through the core normal), each lowered by the core's curvature along it: per slice,
// the directions above both horizons and in the normal's hemisphere, integrated in closed form
// (the slice form of Jimenez et al. 2016, here about n).
fn texel_occlusion(texel: vec2<i32>, level: vec2<i32>, core: CoreFrame) -> f32 {
    let n = core.n;
    let gradient = textureLoad(horizons, texel + vec2((HORIZON_BLOCKS - 1) * level.x, 0), 0).xy;
    // The true normal by Blinn's formula with the map's own gradient (as the bump normal).
    let true_normal = normalize(blinn_normal(n, core.pu, core.pv, core.k * gradient.x, core.k * gradient.y));
    var sum = 0.0;
    for (var i = 0u; i < HORIZON_AZIMUTHS / 2u; i++) {
        let a = f32(i) * 2.0 * PI / f32(HORIZON_AZIMUTHS);
        let along = along_direction(core, vec2(cos(a), sin(a)));
        let reach = length(along.along);
        let t = along.along - n * dot(along.along, n);
        if reach <= 0.0 || dot(t, t) <= 0.0 {
            sum += 1.0;
            continue;
        }
        let tangent = normalize(t);
        // Horizon elevations from the core plane on both sides of the slice (the curvature
        // and the texel step along the opposite azimuth are the same).
        let step = horizon_step(i, level);
        let up = atan(texel_horizon_tangent(texel, level, i, step, core.k, reach, along.curvature));
        let down = atan(texel_horizon_tangent(texel, level, i + HORIZON_AZIMUTHS / 2u, step, core.k, reach, along.curvature));
        let projected = vec2(dot(true_normal, tangent), dot(true_normal, n));
        let gamma = atan2(projected.x, projected.y);
        let hi = max(min(0.5 * PI - up, gamma + 0.5 * PI), 0.0);
        let lo = min(max(-(0.5 * PI - down), gamma - 0.5 * PI), 0.0);
        let f0 = slice_antiderivative(0.0, gamma);
        sum += length(projected)
            * (slice_antiderivative(hi, gamma) - f0 + slice_antiderivative(lo, gamma) - f0);
    }
    return clamp(sum / f32(HORIZON_AZIMUTHS / 2u), 0.0, 1.0);
}

// The first directional light as the texture-space shadow test sees it over one core frame:
// the tangent of its elevation above the core plane, its direction in UV space (unit), the
// world length per UV unit and the core's normal curvature along it, and the two horizon
// azimuths around it with the weight of the second. `valid` false: the light is below the
// core plane (n·l's and Bevy's shadow maps' job) or at the zenith, and reaches every point.
struct LightInUv {
    valid: bool,
    tan_l: f32,
    uv_direction: vec2<f32>,
    reach: f32,
    curvature: f32,
    i0: u32,
    i1: u32,
    blend: f32,
}

fn no_light() -> LightInUv {
    return LightInUv(false, 0.0, vec2(1.0, 0.0), 0.0, 0.0, 0u, 0u, 0.0);
}

fn light_in_uv(core: CoreFrame, to_light: vec3<f32>) -> LightInUv {
    let n = core.n;
    let pu = core.pu;
    let pv = core.pv;
    let sin_l = dot(to_light, n);
    let tangential = to_light - n * sin_l;
    let t2 = dot(tangential, tangential);
    if sin_l <= 0.0 || t2 <= 1e-12 {
        return no_light();
    }
    // The light's azimuth in UV space: tangential = pu a + pv b (least squares in the plane).
    let g = mat2x2<f32>(dot(pu, pu), dot(pu, pv), dot(pu, pv), dot(pv, pv));
    let det = g[0][0] * g[1][1] - g[0][1] * g[1][0];
    if abs(det) <= 1e-20 {
        return no_light();
    }
    let r = vec2(dot(tangential, pu), dot(tangential, pv));
    let ab = vec2(g[1][1] * r.x - g[0][1] * r.y, g[0][0] * r.y - g[1][0] * r.x) / det;
    let uv_length = length(ab);
    if uv_length <= 0.0 {
        return no_light();
    }
    let along = along_direction(core, ab / uv_length);
    let position = atan2(ab.y, ab.x) / (2.0 * PI) * f32(HORIZON_AZIMUTHS);
    let lower = floor(position);
    let count = i32(HORIZON_AZIMUTHS);
    let i0 = u32((i32(lower) % count + count) % count);
    return LightInUv(true, sin_l / sqrt(t2), ab / uv_length, length(along.along), along.curvature, i0, (i0 + 1u) % HORIZON_AZIMUTHS, position - lower);
}

// The horizon tangent at `texel` towards the light's azimuth, the two nearest azimuths
// interpolated, each lowered by the core's fall with `curvature`.
fn light_horizon(texel: vec2<i32>, level: vec2<i32>, core: CoreFrame, light: LightInUv, curvature: f32) -> f32 {
    return mix(
        texel_horizon_tangent(texel, level, light.i0, horizon_step(light.i0, level), core.k, light.reach, curvature),
        texel_horizon_tangent(texel, level, light.i1, horizon_step(light.i1, level), core.k, light.reach, curvature),
        light.blend);
}

// The farther of the two light azimuths' highest occluders at `texel`, in texel steps: beyond
// it nothing rises above the flat horizon, and a convex core's fall only lowers it further.
fn light_occluder_steps(texel: vec2<i32>, level: vec2<i32>, light: LightInUv) -> u32 {
    let d0 = textureLoad(horizon_distances, texel + vec2(i32(light.i0 / 4u) * level.x, 0), 0)[light.i0 % 4u];
    let d1 = textureLoad(horizon_distances, texel + vec2(i32(light.i1 / 4u) * level.x, 0), 0)[light.i1 % 4u];
    return max(d0, d1);
}

// Whether `light` reaches the true surface at `texel` (1) or not (0): its elevation above the
// core plane against the texel's horizon towards its azimuth — horizon mapping (Max 1988) on
// the texture-space horizon map. On a convex core the horizon lowered by the core's curvature
// is a lower bound (the highest occluder's fall at its distance; a nearer, lower one may fall
// less) and the flat map's an upper one; a light between the two is decided by a march of the
// heights towards it (`light_march`). Mirrors `reference::texture_space::texel_light_visibility`.
fn texel_light_visibility(texel: vec2<i32>, level: vec2<i32>, core: CoreFrame, light: LightInUv) -> f32 {
    if !light.valid {
        return 1.0;
    }
    if light.tan_l < light_horizon(texel, level, core, light, light.curvature) {
        return 0.0;
    }
    if light.curvature <= 0.0 || light.tan_l >= light_horizon(texel, level, core, light, 0.0) {
        return 1.0;
    }
    return light_march(vec2<f32>(texel), level, core, light, 1.0, light_occluder_steps(texel, level, light));
}

// Whether `light` reaches the true surface at texel coordinates `p` (texel centres at
// integers): the bilinear heights marched towards it `step` texels at a time for `steps`
// steps, each lowered by the core's fall κ D² / 2 at its world distance D.
fn light_march(p: vec2<f32>, level: vec2<i32>, core: CoreFrame, light: LightInUv, step: f32, steps: u32) -> f32 {
    let mip = horizon_mip(level);
    let texel_direction = normalize(light.uv_direction * vec2<f32>(level));
    let uv_step = length(texel_direction / vec2<f32>(level)) * step;
    let h0 = level_height(p, mip, level);
    for (var t = 1u; t <= steps; t++) {
        let d = f32(t) * uv_step * light.reach;
        let rise = core.k * (level_height(p + f32(t) * step * texel_direction, mip, level) - h0) - 0.5 * light.curvature * d * d;
        if rise > light.tan_l * d {
            return 0.0;
        }
    }
    return 1.0;
}

// Whether `light` reaches the true surface at `uv` itself, as a ray cast at the pixel's centre
// would find (like Bevy's shadow maps, one point per pixel): the four texels around it decide
// where they agree; where they do not, a shadow edge crosses them, and a march from `uv` in
// half-texel steps, as far as their highest occluders plus a texel, places it (interpolating
// the texels' 0s and 1s alone put every edge halfway between texel centres). At such an edge
// the march decides the side of one half (lit ≥ 0.5, shadowed below) and the texels' mix
// shapes the edge's soft profile about a texel wide, so that an edge sweeping over a deforming
// surface fades instead of switching pixels from 1 to 0. Mirrors
// `reference::texture_space::point_light_visibility`.
fn point_light_visibility(uv: vec2<f32>, level: vec2<i32>, core: CoreFrame, light: LightInUv) -> f32 {
    if !light.valid {
        return 1.0;
    }
    let p = fract(uv) * vec2<f32>(level) - 0.5;
    let base = vec2<i32>(floor(p));
    let f = p - floor(p);
    var corners: array<f32, 4>;
    for (var corner = 0; corner < 4; corner++) {
        let texel = horizon_texel(base, vec2<i32>(corner & 1, corner >> 1u), level);
        corners[corner] = texel_light_visibility(texel, level, core, light);
    }
    let soft = mix(mix(corners[0], corners[1], f.x), mix(corners[2], corners[3], f.x), f.y);
    let lit = corners[0] + corners[1] + corners[2] + corners[3];
    if lit == 0.0 || lit == 4.0 {
        return soft;
    }
    // Only at an edge (few pixels): how far the march goes, the corners' farthest occluder.
    var steps = 0u;
    for (var corner = 0; corner < 4; corner++) {
        let texel = horizon_texel(base, vec2<i32>(corner & 1, corner >> 1u), level);
        steps = max(steps, light_occluder_steps(texel, level, light));
    }
    if light_march(p, level, core, light, 0.5, 2u * (steps + 1u)) > 0.5 {
        return max(soft, 0.5);
    }
    return min(soft, EDGE_SHADOWED);
}

// The height chain's mip level as wide as the horizon map's level (built from it, a power of
// two apart).
fn horizon_mip(level: vec2<i32>) -> i32 {
    return i32(countTrailingZeros(u32(textureDimensions(height_mips, 0).x) / u32(level.x)));
}

// The bilinear height at texel coordinates `p` (texel centres at integers) of the height
// chain's level `mip`, the horizon map's level (`level` texels), wrapped however far.
fn level_height(p: vec2<f32>, mip: i32, level: vec2<i32>) -> f32 {
    let base = vec2<i32>(floor(p));
    let f = p - floor(p);
    let h00 = textureLoad(height_mips, horizon_texel(base, vec2(0, 0), level), mip).r;
    let h10 = textureLoad(height_mips, horizon_texel(base, vec2(1, 0), level), mip).r;
    let h01 = textureLoad(height_mips, horizon_texel(base, vec2(0, 1), level), mip).r;
    let h11 = textureLoad(height_mips, horizon_texel(base, vec2(1, 1), level), mip).r;
    return mix(mix(h00, h10, f.x), mix(h01, h11, f.x), f.y);
}

// The size of the horizon map's level: one block of its image.
fn horizon_level() -> vec2<i32> {
    let size = vec2<i32>(textureDimensions(horizons));
    return vec2<i32>(size.x / HORIZON_BLOCKS, size.y);
}

// The texture-space occlusion at `uv`: the four texels around it mixed bilinearly, so that
// texels do not show as blocks. Mirrors `reference::texture_space::magnified_occlusion`.
fn magnified_occlusion(uv: vec2<f32>, level: vec2<i32>, core: CoreFrame) -> f32 {
    let p = fract(uv) * vec2<f32>(level) - 0.5;
    let base = vec2<i32>(floor(p));
    let f = p - floor(p);
    var corners: array<f32, 4>;
    for (var corner = 0; corner < 4; corner++) {
        let texel = horizon_texel(base, vec2<i32>(corner & 1, corner >> 1u), level);
        corners[corner] = texel_occlusion(texel, level, core);
    }
    // Nested mixes: four equal corners give exactly their value (an open flat map stays
    // exactly 1).
    return mix(mix(corners[0], corners[1], f.x), mix(corners[2], corners[3], f.x), f.y);
}

// The texel of the horizon map `i` texels from `base`, wrapped (height maps tile).
fn horizon_texel(base: vec2<i32>, i: vec2<i32>, level: vec2<i32>) -> vec2<i32> {
    return ((base + i) % level + level) % level;
}

// The fine occlusion a pixel shows, from the texture-space horizon map, and the visibility of
// `light` (the camera's first directional light) at its centre (`point_light_visibility`).
// The occlusion magnified (less than a texel per pixel): the texels' values interpolated
// bilinearly; minified: the mean over the pixel's footprint, not the occlusion of the filtered
// heights that the screen-space passes see (which flattens the relief): 2 × 2 taps spread over
// the footprint (UV derivatives `duv1`, `duv2`). Between 0.75 and 1.5 texels per pixel, a
// blend of the two.
fn footprint_terms(uv: vec2<f32>, duv1: vec2<f32>, duv2: vec2<f32>, texels_per_pixel: f32, core: CoreFrame, light: LightInUv) -> vec2<f32> {
    let level = horizon_level();
    // Texels per pixel of the horizon map's level (it may be coarser than level 0).
    let horizon_texels = texels_per_pixel * f32(level.x) / f32(textureDimensions(height_mips, 0).x);
    let minified = smoothstep(0.75, 1.5, horizon_texels);
    var magnified = 0.0;
    if minified < 1.0 {
        magnified = magnified_occlusion(uv, level, core);
    }
    var footprint_mean = 0.0;
    if minified > 0.0 {
        for (var tap = 0; tap < 4; tap++) {
            let offset = vec2<f32>(f32(tap & 1), f32(tap >> 1u)) * 0.5 - 0.25;
            let tap_uv = fract(uv + offset.x * duv1 + offset.y * duv2);
            let texel = horizon_texel(vec2<i32>(tap_uv * vec2<f32>(level)), vec2(0), level);
            footprint_mean += 0.25 * texel_occlusion(texel, level, core);
        }
    }
    return vec2(mix(magnified, footprint_mean, minified), point_light_visibility(uv, level, core, light));
}

#ifdef TEXTURE_SPACE_BOUNCE
// The true normal at texel coordinates `p` (texel centres at integers) of the horizon map, by
// Blinn's formula with the map's gradient mixed bilinearly between the four texels around it.
fn true_normal_at(p: vec2<f32>, level: vec2<i32>, core: CoreFrame) -> vec3<f32> {
    let base = vec2<i32>(floor(p));
    let f = p - floor(p);
    let offset = vec2((HORIZON_BLOCKS - 1) * level.x, 0);
    let g00 = textureLoad(horizons, horizon_texel(base, vec2(0, 0), level) + offset, 0).xy;
    let g10 = textureLoad(horizons, horizon_texel(base, vec2(1, 0), level) + offset, 0).xy;
    let g01 = textureLoad(horizons, horizon_texel(base, vec2(0, 1), level) + offset, 0).xy;
    let g11 = textureLoad(horizons, horizon_texel(base, vec2(1, 1), level) + offset, 0).xy;
    let gradient = mix(mix(g00, g10, f.x), mix(g01, g11, f.x), f.y);
    return normalize(blinn_normal(core.n, core.pu, core.pv, core.k * gradient.x, core.k * gradient.y));
}


// One bounce of the light from `to_light` at `uv`, relative to E0 (the irradiance of a surface
// facing the light), every surface white — what a ray tracer finds by following the rays that
// hit the surface to their lit points, here from the horizon map, in texture space (so it does
// not flatten where the view is minified or oblique, as the screen-space gather does). Along
// each azimuth, TEXTURE_BOUNCE_SAMPLES points S between the point and the distance where its
// horizon is reached (beyond, the rays escape), lowered by the core's fall κ D² / 2; those seen
// at rising elevations above the true tangent plane each stand for the band of cosine-weighted
// solid angle below them, (sin² e_j − sin² e_{j−1}) / 2 · Δθ (paper eq. 8 with the band's area),
// and send max(0, N_S · l) V(S) if they face the point (N_S from the gradient at S, V of S's
// nearest texel, both about S's own core normal, which the curvature has turned). The
// sum is rescaled to the blocked part of the hemisphere by the texture-space occlusion
// `occlusion`: the samples give the mean radiance of what the point sees instead of the sky,
// the occlusion how much of it. Mirrors `reference::texture_space::texture_bounce`.
fn texture_bounce(uv: vec2<f32>, level: vec2<i32>, core: CoreFrame, to_light: vec3<f32>, occlusion: f32) -> f32 {
    let mip = horizon_mip(level);
    let p = fract(uv) * vec2<f32>(level) - 0.5;
    let normal = true_normal_at(p, level, core);
    let h0 = level_height(p, mip, level);
    let nearest = horizon_texel(vec2<i32>(round(p)), vec2(0), level);
    var irradiance = 0.0;
    var covered = 0.0;
    for (var i = 0u; i < HORIZON_AZIMUTHS; i++) {
        let a = f32(i) * 2.0 * PI / f32(HORIZON_AZIMUTHS);
        let direction = vec2(cos(a), sin(a));
        let curvature = along_direction(core, direction).curvature;
        let block = vec2(i32(i / 4u) * level.x, 0);
        let distance = f32(textureLoad(horizon_distances, nearest + block, 0)[i % 4u]);
        var seen = 0.0;
        for (var j = 1u; j <= TEXTURE_BOUNCE_SAMPLES; j++) {
            let t = distance * f32(j) / f32(TEXTURE_BOUNCE_SAMPLES);
            let s = p + t * direction;
            let along = core.pu * (t * direction.x / f32(level.x)) + core.pv * (t * direction.y / f32(level.y));
            // The core falls κ D² / 2 below its tangent plane at world distance D.
            let fall = 0.5 * curvature * dot(along, along);
            let d = along + core.n * (core.k * (level_height(s, mip, level) - h0) - fall);
            let len = length(d);
            if len <= 0.0 {
                continue;
            }
            let sine = dot(d, normal) / len;
            if sine <= seen {
                continue;
            }
            let band = 0.5 * (sine * sine - seen * seen);
            let q = horizon_texel(vec2<i32>(round(s)), vec2(0), level);
            // S's own core frame: on a curved core the normal has turned by dN = Nu du + Nv dv
            // on the way, which changes S's light elevation (to below its horizon, and past
            // its terminator, where no shadow map of ours helps: unlit).
            var core_s = core;
            core_s.n = normalize(core.n + core.nu * (t * direction.x / f32(level.x)) + core.nv * (t * direction.y / f32(level.y)));
            let n_s = true_normal_at(s, level, core_s);
            let cos_l = dot(n_s, to_light);
            if dot(n_s, -d) > 0.0 && cos_l > 0.0 && dot(core_s.n, to_light) > 0.0 {
                irradiance += cos_l * band * texel_light_visibility(q, level, core_s, light_in_uv(core_s, to_light));
            }
            covered += band;
            seen = sine;
        }
    }
    // Both sums times Δθ / π; their ratio needs none.
    let scale = 2.0 / f32(HORIZON_AZIMUTHS);
    let gathered = covered * scale;
    if gathered > 1e-4 {
        return irradiance * scale * max(1.0 - occlusion, 0.0) / gathered;
    }
    return irradiance * scale;
}
#endif

// Whether the raster half drew texel `s` of pixel `q` this frame (it is never cleared): Bevy's
// prepass left a mesostructure material there, at this depth (the raster half passes only
// where its depth is the prepass's; a hair of slack for vertex shaders compiled apart).
fn drawn_this_frame(q: vec2<i32>, s: vec4<f32>) -> bool {
    if s.w == 0.0 || textureLoad(lighting_pass_id, q, 0).r != #{MESOSTRUCTURE_LIGHTING_PASS_ID}u {
        return false;
    }
    let d = textureLoad(prepass_depth, q, 0);
    return s.z >= d && s.z - d <= d * 1.0e-5 + 1.0e-12;
}

// What the fragment stage's dpdx/dpdy gave: the change of the UV, the core point and the core
// normal from pixel `p` to the next along screen axis `axis`.
struct Difference {
    uv: vec2<f32>,
    position: vec3<f32>,
    normal: vec3<f32>,
    valid: bool,
}

// The difference towards neighbour `q` (forward when `sign` is 1, backward when −1), valid
// where `q` is on screen and of the same object.
fn difference_to(p: vec2<i32>, q: vec2<i32>, sign: f32, here: vec4<f32>, n: vec3<f32>, sp: vec3<f32>) -> Difference {
    var d: Difference;
    let size = vec2<i32>(textureDimensions(surface));
    if any(q < vec2(0)) || any(q >= size) {
        return d;
    }
    let there = textureLoad(surface, q, 0);
    if there.w != here.w || !drawn_this_frame(q, there) {
        return d;
    }
    d.uv = (there.xy - here.xy) * sign;
    d.position = (core_point(view.world_from_clip, view.viewport, q, there.z) - sp) * sign;
    d.normal = (textureLoad(core_normal, q, 0).xyz - n) * sign;
    d.valid = true;
    return d;
}

// The screen derivative along `axis` ((1, 0) or (0, 1)): towards the quad partner, as hardware
// coarse derivatives are taken, unless the partner is another object or lies across a UV seam
// (a UV step over 4× the other side's); then towards the other side.
fn screen_derivative(p: vec2<i32>, axis: vec2<i32>, here: vec4<f32>, n: vec3<f32>, sp: vec3<f32>) -> Difference {
    // Even pixels' partner is the next one, odd pixels' the previous one.
    let odd = (dot(p, axis) & 1) == 1;
    let partner_sign = select(1.0, -1.0, odd);
    let partner = difference_to(p, p + axis * i32(partner_sign), partner_sign, here, n, sp);
    let other = difference_to(p, p - axis * i32(partner_sign), -partner_sign, here, n, sp);
    if partner.valid && (!other.valid || dot(partner.uv, partner.uv) <= 16.0 * dot(other.uv, other.uv)) {
        return partner;
    }
    return other;
}

@compute @workgroup_size(8, 8, 1)
fn height(@builtin(global_invocation_id) id: vec3<u32>) {
    let p = vec2<i32>(id.xy);
    let size = vec2<i32>(textureDimensions(surface));
    if any(p >= size) {
        return;
    }
    let here = textureLoad(surface, p, 0);
    if !drawn_this_frame(p, here) {
        // No mesostructure: the MHM needs no clear of its own, the first set's dispatch writes
        // "none" (id 0) here.
        if material.index == 0.0 {
            textureStore(mhm_out, p, vec4(0.0));
        }
        return;
    }
    let normal = textureLoad(core_normal, p, 0);
    if normal.w != material.index {
        return;
    }
    let uv = here.xy;
    let n = normal.xyz;
    let has_normal = dot(n, n) > 0.5;
    let sp = core_point(view.world_from_clip, view.viewport, p, here.z);
    let x = screen_derivative(p, vec2(1, 0), here, n, sp);
    let y = screen_derivative(p, vec2(0, 1), here, n, sp);
    let duv1 = x.uv;
    let duv2 = y.uv;

    // Mip selection from the pixel footprint in texels (trilinear), as the hardware would.
    let size0 = vec2<f32>(textureDimensions(height_mips, 0));
    let dx = duv1 * size0;
    let dy = duv2 * size0;
    let rho2 = max(dot(dx, dx), dot(dy, dy));
    let last = f32(textureNumLevels(height_mips) - 1u);
    let lod = clamp(0.5 * log2(max(rho2, 1e-12)), 0.0, last);
    let l0 = floor(lod);
    let l1 = min(l0 + 1.0, last);
    // The taps wrap by one period at most (see `height_texel`). With bump mapping the finer
    // level also gives the central differences.
    let tap_uv = fract(uv);
    var taps: HeightTaps;
    if material.bump > 0.0 {
        taps = height_taps(tap_uv, i32(l0));
    } else {
        taps.center = height_bilinear(tap_uv, i32(l0));
    }
    let dis = mix(taps.center, height_bilinear(tap_uv, i32(l1)), lod - l0);

    // Blinn bump mapping (seed 003): P' = P + F n with F = k · dis; N' = Pu × Pv + Fu (n × Pv)
    // − Fv (n × Pu), oriented like n. Pu and Pv, the surface's derivatives along the texture
    // axes, come from the screen derivatives of the position and the UVs (no tangents needed);
    // Fu and Fv from central differences of neighbouring texels at the level sampled.
    var bump = vec3<f32>(0.0);
    // The texture-space occlusion and first directional light's visibility; −1 where they
    // could not be computed (no UV derivatives), which the later passes read as "none".
    var texture_occlusion = -1.0;
    var texture_visibility = -1.0;
    var texture_bounce_value = -1.0;
    let det = duv1.x * duv2.y - duv1.y * duv2.x;
    if has_normal && x.valid && y.valid && abs(det) > 1e-12 {
        let dp1 = x.position;
        let dp2 = y.position;
        // The surface's derivatives along the texture axes (world per UV unit), for the bump
        // and the texture-space horizons alike.
        // Kept in the core's tangent plane: positions rebuilt from depth carry rounding that
        // would tilt Pu × Pv off n (most at grazing views), which the fragment stage's exact
        // interpolants did not.
        let pu_raw = (dp1 * duv2.y - dp2 * duv1.y) / det;
        let pv_raw = (dp2 * duv1.x - dp1 * duv2.x) / det;
        let pu = pu_raw - n * dot(pu_raw, n);
        let pv = pv_raw - n * dot(pv_raw, n);
#ifdef TEXTURE_SPACE_HORIZONS
        // The normal's change per UV unit: the core's curvature, which lowers (convex) or
        // raises (concave) the texture-space horizons.
        let dn1 = x.normal;
        let dn2 = y.normal;
        let has_light = lights.n_directional_lights > 0u;
        let to_light = select(vec3(0.0, 0.0, 1.0), lights.directional_lights[0].direction_to_light, has_light);
        let nu = (dn1 * duv2.y - dn2 * duv1.y) / det;
        let nv = (dn2 * duv1.x - dn1 * duv2.x) / det;
        let core = CoreFrame(n, pu, pv, nu, nv, material.scale);
        // Texels of level 0 per pixel along the footprint's longer axis.
        let texels_per_pixel = sqrt(rho2);
        var light = no_light();
        if has_light {
            light = light_in_uv(core, to_light);
        }
        let terms = footprint_terms(uv, duv1, duv2, texels_per_pixel, core, light);
        texture_occlusion = terms.x;
        texture_visibility = select(-1.0, terms.y, has_light);
#ifdef TEXTURE_SPACE_BOUNCE
        if has_light {
            // At the pixel's own UV, not averaged over its footprint like the occlusion: 16
            // azimuths × TEXTURE_BOUNCE_SAMPLES points cost too much to take four times. So
            // rescaled with the occlusion at that UV too (the texels' bilinear mix, which the
            // footprint's value is where the surface is magnified): the mean over a minified
            // footprint paired with one point's bounce was off by the difference.
            let level = horizon_level();
            var occlusion_here = texture_occlusion;
            if texels_per_pixel * f32(level.x) / size0.x > 0.75 {
                occlusion_here = magnified_occlusion(uv, level, core);
            }
            texture_bounce_value = texture_bounce(uv, level, core, to_light, occlusion_here);
        }
#endif
#endif
        if material.bump > 0.0 {
            // Central differences over two texels of level l0, per UV unit.
            let fu = material.scale * taps.across.x * taps.size.x * 0.5;
            let fv = material.scale * taps.across.y * taps.size.y * 0.5;
            let bumped = blinn_normal(n, pu, pv, fu, fv);
            let len = length(bumped);
            if len > 0.0 {
                bump = bumped / len;
            }
        }
    }
    textureStore(mhm_out, p, vec4<f32>(dis * material.scale, here.z, here.w, dis));
    textureStore(bump_out, p, vec4<f32>(bump, texture_occlusion));
    textureStore(visibility_out, p, vec4<f32>(texture_visibility, texture_bounce_value, 0.0, 0.0));
}
