#define_import_path bevy_mesostructure::translucency::gathered

// Seed 001's last step, what every form of the gather shares: each pixel (world position from
// the depth prepass, normal from the normal prepass) gathers the patches within their reach R
// (1.5 of their object's patch size) about it through a hashed grid, weighted by distance,
// (1 − d²/R²)², and by how far their normals agree with its own — interpolating their
// outgoing radiance (the default), or, with PHOTON_DENSITY, summing their power as photons
// under a kernel of unit integral (`GatherMethod`). Translucent patches give their whole
// exitance B/π (their mesh's material has no diffuse), the part that came from elsewhere in
// the deep field's limb-darkened law (`ExitLaw`), opaque patches the light they bounce,
// (B − ρE⁰)/π = ρ(E − E⁰)/π (their direct light is Bevy's); a translucent pixel adds its
// object's single scattering marched per pixel (`marched.wgsl`). The forms that import this:
// the fullscreen fragment pass (`gather.wgsl`) and the compute passes (`gather_compute.wgsl`).

#import bevy_render::view::View
#import bevy_mesostructure::translucency::boundary::{
    deep_exit_shape, deep_exit_shape_about, fresnel_reflectance, single_scattering_radiance,
    tangential_flux_factor,
}
#import bevy_mesostructure::translucency::marched::marched_single_scattering

struct GatherParams {
    // Grids by reach (`PatchGrid::levels`): per grid four words at the start of `grid` (cell
    // size, bucket mask, where its bucket offsets and its members start; a member is four
    // words: patch index and its cell).
    levels: u32,
    patches: u32,
    // Offsets in `vectors` (vec4s).
    direct: u32,
    exitance: u32,
    // The beams' normal irradiance and weighted direction, per patch (a beam table's).
    beam_irradiance: u32,
    beam_direction: u32,
    // Per patch and channel, the way its light from elsewhere flows (`ExitLaw::flow`: axis,
    // 1/N), three vec4s a patch; `has_flow` 0: none, the normal's law.
    flow: u32,
    has_flow: u32,
    // Per patch its exit lobes (`ExitLaw::lobes`, five vec4s a patch: per channel axis and κ,
    // the norms, the light from afar that leaves by them); `has_lobes` 0: none.
    lobes: u32,
    has_lobes: u32,
    // Per patch, its irradiance direct and bounced (the iteration's E): the exit law's own light.
    irradiance: u32,
    padding_y: u32,
}

struct GatherPatch {
    // (surface point, reach R)
    centre: vec4<f32>,
    // (normal, area)
    normal: vec4<f32>,
    albedo: vec4<f32>,
    // `ExitLaw` (transport.rs): what a unit irradiance on the patch gives back in all and the
    // boundary's η, and per channel the deep field's law (α, ν, 1/N, g); g = 0: Lambert's.
    local_albedo: vec4<f32>,
    law_r: vec4<f32>,
    law_g: vec4<f32>,
    law_b: vec4<f32>,
    // Where a beam table carries the patch's beams: its medium's single-scattering albedo and
    // η, for single scattering by the lit face (zero elsewhere).
    single: vec4<f32>,
    // `ExitLaw::tangential`: per channel the weight of the flux along the surface (zero: none).
    tangential: vec4<f32>,
}

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var depth_prepass: texture_depth_2d;
@group(0) @binding(2) var normal_prepass: texture_2d<f32>;
@group(0) @binding(3) var<uniform> params: GatherParams;
@group(0) @binding(4) var<storage, read> patches: array<GatherPatch>;
@group(0) @binding(5) var<storage, read> vectors: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read> grid: array<u32>;

// The grid cell's bucket: `PatchGrid::bucket` in gather/mod.rs.
fn bucket(cell: vec3<i32>, mask: u32) -> u32 {
    let c = bitcast<vec3<u32>>(cell);
    return ((c.x * 73856093u) ^ (c.y * 19349663u) ^ (c.z * 83492791u)) & mask;
}

// Grid `level`'s four words at the start of `grid` (`GatherParams::levels`).
struct GridLevel {
    cell_size: f32,
    mask: u32,
    // Where its bucket offsets and its members start.
    table: u32,
    members: u32,
}

fn grid_level(level: u32) -> GridLevel {
    return GridLevel(bitcast<f32>(grid[4u * level]), grid[4u * level + 1u], grid[4u * level + 2u],
                     grid[4u * level + 3u]);
}

// The patch of member `k` of grid `g` where it lies in `cell`, else none (-1): a bucket that
// two walked cells hash to would give its patches twice (photons: twice the light), so only
// the members of the very cell walked are taken.
fn member_in_cell(g: GridLevel, k: u32, cell: vec3<i32>) -> i32 {
    let member = g.members + 4u * k;
    let own_cell = bitcast<vec3<i32>>(vec3(grid[member + 1u], grid[member + 2u], grid[member + 3u]));
    return select(-1, i32(grid[member]), all(own_cell == cell));
}

// `ExitLaw::factor_towards` (transport.rs) in one channel: the share `lobe_exitance / B`
// leaves by the channel's exit lobe (`lobe`: axis and κ; `ExitLobe::factor`), the rest
// `B' = B − lobe_exitance` by 1 + D (s − 1), D = g·clamp(1 − A E/B'), E the patch's
// irradiance direct and bounced (light bounced onto it enters as its direct light does), s the deep law about
// the channel's `flow` where it has one (axis, 1/N), else about the normal
// (`shape_about_normal`, `deep_exit_shape` at the pixel's exit cosine). Returns the factor
// and of it the part that leaves by the law, not the lobe (`ExitLaw::factor_towards_parts`).
fn exit_factor(law: vec4<f32>, flow: vec4<f32>, lobe: vec4<f32>, lobe_norm: f32, lobe_exitance: f32,
               local_albedo: f32, eta: f32, b: f32, e: f32, n: vec3<f32>, towards: vec3<f32>,
               shape_about_normal: f32) -> vec2<f32> {
    var share = 0.0;
    if lobe_norm > 0.0 && b > 0.0 {
        share = clamp(lobe_exitance / b, 0.0, 1.0);
    }
    let lobed = share * lobe_norm * exp(lobe.w * (dot(towards, lobe.xyz) - 1.0));
    let rest = b * (1.0 - share);
    if law.w <= 0.0 || rest <= 0.0 {
        return vec2(lobed + (1.0 - share), 1.0 - share);
    }
    let deep = law.w * clamp(1.0 - local_albedo * e / rest, 0.0, 1.0);
    var shape = shape_about_normal;
    if any(flow != vec4(0.0)) {
        shape = deep_exit_shape_about(law, eta, n, flow.xyz, towards) * flow.w;
    }
    let own = (1.0 - share) * (1.0 + deep * (shape - 1.0));
    return vec2(lobed + own, own);
}

// Patch `i`'s exit lobes: `k` 0 – 2 a channel's axis and κ, 3 the norms, 4 the light from
// afar (zero without them).
fn patch_lobes(i: u32, k: u32) -> vec4<f32> {
    if params.has_lobes == 0u {
        return vec4(0.0);
    }
    return vectors[params.lobes + 5u * i + k];
}

// Patch `i`'s flow in `channel` (zero without one).
fn patch_flow(i: u32, channel: u32) -> vec4<f32> {
    if params.has_flow == 0u {
        return vec4(0.0);
    }
    return vectors[params.flow + 3u * i + channel];
}

// What a pixel shows of the surface: its world point, unit normal, the unit direction and
// exit cosine towards the camera; `valid` false where nothing was drawn.
struct Surface {
    valid: bool,
    x: vec3<f32>,
    n: vec3<f32>,
    towards: vec3<f32>,
    mu: f32,
    // A tangent frame about `n` (`tangent_frame`), for the exitance's gradient.
    frame: mat2x3<f32>,
}

fn no_surface() -> Surface {
    return Surface(false, vec3(0.0), vec3(0.0), vec3(0.0), 0.0, mat2x3<f32>(vec3(0.0), vec3(0.0)));
}

fn pixel_surface(p: vec2<i32>, position: vec2<f32>) -> Surface {
    let depth = textureLoad(depth_prepass, p, 0);
    if depth <= 0.0 {
        return no_surface();
    }
    let uv = (position - view.viewport.xy) / view.viewport.zw;
    let ndc = vec4(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, depth, 1.0);
    let world = view.world_from_clip * ndc;
    let x = world.xyz / world.w;
    let n = normalize(textureLoad(normal_prepass, p, 0).xyz * 2.0 - 1.0);
    let towards = normalize(view.world_position - x);
    return Surface(true, x, n, towards, clamp(dot(n, towards), 0.0, 1.0), tangent_frame(n));
}

// A pixel's sums over the patches that reach it, and the deep law's shape at its exit cosine
// for the last medium met (`shape_key`: that medium's per-channel laws and η; the law about
// the normal depends on the pixel and the medium only, so one evaluation serves all of that
// medium's patches about it).
struct Gathered {
    sum: vec3<f32>,
    weights: f32,
    shape_key_r: vec4<f32>,
    shape_key_g: vec4<f32>,
    shape_key_b: vec4<f32>,
    shape_key_eta: f32,
    shape: vec3<f32>,
    // The smallest reach among the patches that reached the pixel (the half-resolution
    // gather's upsample takes a sample only within it).
    reach: f32,
    // The pixel's translucent object (-1: none), its patch that weighs most there, and its
    // weight.
    object: i32,
    object_weight: f32,
    // The flux along the surface (`AlongSurface` in twin.rs), over the patches with a weight
    // for it: their light that leaves by the laws, their weights, Σ w·weight, Σ w B, and for
    // a plane fitted to their exitance Σ w d, Σ w (dx², dx dy, dy²) and per channel Σ w d B
    // (`d` a patch's offset in the pixel's tangent frame), and their η.
    along_leaving: vec3<f32>,
    along_weights: f32,
    along_weight: vec3<f32>,
    along_exitance: vec3<f32>,
    along_offset: vec2<f32>,
    along_second: vec3<f32>,
    along_times_r: vec2<f32>,
    along_times_g: vec2<f32>,
    along_times_b: vec2<f32>,
    along_eta: f32,
}

fn no_light() -> Gathered {
    return Gathered(vec3(0.0), 0.0, vec4(-1.0), vec4(-1.0), vec4(-1.0), -1.0, vec3(1.0), 3.0e38, -1, 0.0,
                    vec3(0.0), 0.0, vec3(0.0), vec3(0.0), vec2(0.0), vec3(0.0), vec2(0.0), vec2(0.0), vec2(0.0),
                    1.0);
}

// Patch `i`'s light at the pixel `s`, if it reaches it.
fn add_patch(i: u32, s: Surface, acc: ptr<function, Gathered>) {
    let record = patches[i];
    let d = record.centre.xyz - s.x;
    let d2 = dot(d, d);
    // Each patch reaches 1.5 of its own object's patch sizes (centre.w).
    let r2 = record.centre.w * record.centre.w;
    if d2 >= r2 {
        return;
    }
    let agree = smoothstep(0.3, 0.9, dot(s.n, record.normal.xyz));
    let falloff = 1.0 - d2 / r2;
#ifdef PHOTON_DENSITY
    // The seed's photons: power Φ = M·A under a kernel of unit integral,
    // K(d) = 3/(πR²)(1 − d²/R²)² (`GatherMethod::PhotonDensity`).
    let w = falloff * falloff * agree * 3.0 / (3.14159265358979 * r2) * record.normal.w;
#else
    let w = falloff * falloff * agree;
#endif
    if w <= 0.0 {
        return;
    }
    let b_i = vectors[params.exitance + i].rgb;
    let e0 = vectors[params.direct + i].rgb;
    let received = vectors[params.irradiance + i].rgb;
    let eta = record.local_albedo.w;
    if any(vec3(record.law_r.w, record.law_g.w, record.law_b.w) > vec3(0.0))
        && !(all(record.law_r == (*acc).shape_key_r) && all(record.law_g == (*acc).shape_key_g)
             && all(record.law_b == (*acc).shape_key_b) && eta == (*acc).shape_key_eta) {
        (*acc).shape_key_r = record.law_r;
        (*acc).shape_key_g = record.law_g;
        (*acc).shape_key_b = record.law_b;
        (*acc).shape_key_eta = eta;
        (*acc).shape = vec3(
            deep_exit_shape(record.law_r, eta, s.mu),
            deep_exit_shape(record.law_g, eta, s.mu),
            deep_exit_shape(record.law_b, eta, s.mu),
        );
    }
    let shape = (*acc).shape;
    let norms = patch_lobes(i, 3u);
    let afar = patch_lobes(i, 4u);
    let factor_r = exit_factor(record.law_r, patch_flow(i, 0u), patch_lobes(i, 0u), norms.r, afar.r,
                    record.local_albedo.r, eta, b_i.r, received.r, s.n, s.towards, shape.r);
    let factor_g = exit_factor(record.law_g, patch_flow(i, 1u), patch_lobes(i, 1u), norms.g, afar.g,
                    record.local_albedo.g, eta, b_i.g, received.g, s.n, s.towards, shape.g);
    let factor_b = exit_factor(record.law_b, patch_flow(i, 2u), patch_lobes(i, 2u), norms.b, afar.b,
                    record.local_albedo.b, eta, b_i.b, received.b, s.n, s.towards, shape.b);
    let own = max(b_i - record.albedo.rgb * e0, vec3(0.0)) / 3.14159265358979;
    (*acc).sum += w * own * vec3(factor_r.x, factor_g.x, factor_b.x);
#ifndef PHOTON_DENSITY
    if any(record.tangential.rgb > vec3(0.0)) {
        let o = vec2(dot(d, s.frame[0]), dot(d, s.frame[1]));
        (*acc).along_leaving += w * own * vec3(factor_r.y, factor_g.y, factor_b.y);
        (*acc).along_weights += w;
        (*acc).along_weight += w * record.tangential.rgb;
        (*acc).along_exitance += w * b_i;
        (*acc).along_offset += w * o;
        (*acc).along_second += w * vec3(o.x * o.x, o.x * o.y, o.y * o.y);
        (*acc).along_times_r += w * o * b_i.r;
        (*acc).along_times_g += w * o * b_i.g;
        (*acc).along_times_b += w * o * b_i.b;
        (*acc).along_eta = eta;
    }
#endif
    // Single scattering by the lit face (`BeamSingleScattering::radiance`): the patch's beams
    // at this pixel's own incidence.
    if any(record.single.rgb > vec3(0.0)) {
        let travel = vectors[params.beam_direction + i].xyz;
        if dot(travel, travel) > 0.0 {
            let mu0 = dot(s.n, -normalize(travel));
            let e = vectors[params.beam_irradiance + i].rgb * max(mu0, 0.0);
            (*acc).sum += w * single_scattering_radiance(record.single.rgb, record.single.w, e, mu0, s.mu);
        }
    }
    if all(record.albedo.rgb == vec3(0.0)) && w > (*acc).object_weight {
        (*acc).object = i32(record.albedo.w);
        (*acc).object_weight = w;
    }
    (*acc).weights += w;
    (*acc).reach = min((*acc).reach, record.centre.w);
}

// The light gathered at the pixel `s`, with its object's single scattering marched, times
// the exposure; `w` = 0 where no patch reaches the pixel.
fn finish(acc: Gathered, s: Surface) -> vec4<f32> {
    if acc.weights <= 0.0 {
        return vec4(0.0);
    }
    let marched = marched_single_scattering(acc.object, s.x, s.n, s.towards, s.mu);
#ifdef PHOTON_DENSITY
    return vec4((acc.sum + marched) * view.exposure, 1.0);
#else
    return vec4(((acc.sum + along_surface(acc, s)) / acc.weights + marched) * view.exposure, 1.0);
#endif
}

// The pixel's tangent frame about its unit normal (`tangent_frame` in twin.rs).
fn tangent_frame(n: vec3<f32>) -> mat2x3<f32> {
    var helper = vec3(0.0, 1.0, 0.0);
    if abs(n.x) < 0.9 {
        helper = vec3(1.0, 0.0, 0.0);
    }
    let t = normalize(cross(n, helper));
    return mat2x3<f32>(t, cross(n, t));
}

// A plane's gradient fitted to one channel's exitance about the pixel: the offsets'
// covariance (xx, xy, yy, its determinant) solved against Σ w d B / Σ w − mean · B̄.
fn fitted_gradient(times: vec2<f32>, total: f32, mean: vec2<f32>, b: f32, cov: vec4<f32>) -> vec2<f32> {
    let cross_term = times / total - mean * b;
    return vec2(cov.z * cross_term.x - cov.y * cross_term.y, cov.x * cross_term.y - cov.y * cross_term.x) / cov.w;
}

// What the flux along the surface adds to the pixel's weighted sum (`AlongSurface::lean` in
// twin.rs): the light that left by the laws times `tangential_flux_factor − 1`, the exitance's
// gradient a weighted least-squares plane's (none where the patches do not span the plane).
fn along_surface(acc: Gathered, s: Surface) -> vec3<f32> {
    if acc.along_weights <= 0.0 {
        return vec3(0.0);
    }
    let total = acc.along_weights;
    let mean = acc.along_offset / total;
    let b = acc.along_exitance / total;
    let xx = acc.along_second.x / total - mean.x * mean.x;
    let xy = acc.along_second.y / total - mean.x * mean.y;
    let yy = acc.along_second.z / total - mean.y * mean.y;
    let det = xx * yy - xy * xy;
    if !(det > 1e-6 * (xx + yy) * (xx + yy)) {
        return vec3(0.0);
    }
    let cov = vec4(xx, xy, yy, det);
    let view = vec2(dot(s.towards, s.frame[0]), dot(s.towards, s.frame[1]));
    let along = vec3(
        dot(fitted_gradient(acc.along_times_r, total, mean, b.r, cov), view),
        dot(fitted_gradient(acc.along_times_g, total, mean, b.g, cov), view),
        dot(fitted_gradient(acc.along_times_b, total, mean, b.b, cov), view),
    ) / max(b, vec3(1e-30));
    let factor = tangential_flux_factor(
        select(vec3(0.0), acc.along_weight / total, b > vec3(0.0)), acc.along_eta, s.mu, along);
    return acc.along_leaving * (factor - 1.0);
}

// The light the patches give the pixel `s` by its own walk of the grids: the 27 cells about
// it in each.
fn gathered(s: Surface) -> vec4<f32> {
    return finish(walked(s), s);
}

// `gathered`'s sums.
fn walked(s: Surface) -> Gathered {
    var acc = no_light();
    if !s.valid {
        return acc;
    }
    for (var level = 0u; level < params.levels; level += 1u) {
        let g = grid_level(level);
        let centre_cell = vec3<i32>(floor(s.x / g.cell_size));
        for (var dz = -1; dz <= 1; dz += 1) {
            for (var dy = -1; dy <= 1; dy += 1) {
                for (var dx = -1; dx <= 1; dx += 1) {
                    let cell = centre_cell + vec3(dx, dy, dz);
                    let b = bucket(cell, g.mask);
                    for (var k = grid[g.table + b]; k < grid[g.table + b + 1u]; k += 1u) {
                        let i = member_in_cell(g, k, cell);
                        if i >= 0 {
                            add_patch(u32(i), s, &acc);
                        }
                    }
                }
            }
        }
    }
    return acc;
}

