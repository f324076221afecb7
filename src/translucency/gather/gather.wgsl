// Seed 001's last step: each pixel (world position from the depth prepass, normal from the
// normal prepass) gathers the patches within their reach R (1.5 of their object's patch size)
// about it through a hashed grid, weighted by distance, (1 − d²/R²)², and by how far their
// normals agree with its own — interpolating their outgoing radiance (the default), or, with
// PHOTON_DENSITY, summing their power as photons under a kernel of unit integral
// (`GatherMethod`). Translucent patches give their whole exitance B/π (their mesh's material
// has no diffuse), the part that came from elsewhere in the deep field's limb-darkened law
// (`ExitLaw`), opaque patches the light they bounce, (B − ρE⁰)/π = ρ(E − E⁰)/π (their
// direct light is Bevy's). Added to the lit view, times the view's exposure as Bevy's
// lighting is: by additive blending (`gather`, a fullscreen fragment pass), or, where the
// view's main images take storage writes, by a compute pass writing lit + gathered into the
// view's other main image (`gather_compute`), whose 8×8 tiles walk the grids once for their
// pixels (`collect_tile_patches`), or (HALF_RESOLUTION) the same at one pixel in 2×2 and the
// rest upsampled from the samples on their own surface (`gather_half`, `gather_upsample`,
// `gather_unserved`).

#import bevy_core_pipeline::fullscreen_vertex_shader::FullscreenVertexOutput
#import bevy_render::view::View
#import bevy_mesostructure::translucency::boundary::{
    deep_exit_shape, deep_exit_shape_about, fresnel_reflectance, from_ordered_bits, ordered_bits,
    translucent_map_depth, TranslucentMaps, translucent_maps_of, translucent_light_at,
    translucent_frame_at, TranslucentFrame, translucent_frame_of, translucent_place,
    translucent_texel_width, translucent_texel,
}

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
    padding_x: u32,
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
}

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var depth_prepass: texture_depth_2d;
@group(0) @binding(2) var normal_prepass: texture_2d<f32>;
@group(0) @binding(3) var<uniform> params: GatherParams;
@group(0) @binding(4) var<storage, read> patches: array<GatherPatch>;
@group(0) @binding(5) var<storage, read> vectors: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read> grid: array<u32>;
// The translucent objects' maps towards each light and their light (`translucent_maps`,
// `translucent_depths` in inject.wgsl, where they are laid out).
@group(0) @binding(13) var<storage, read> translucent_maps: array<vec4<f32>>;
@group(0) @binding(14) var<storage, read> translucent_depths: array<u32>;

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

// `ExitLaw::factor_towards` (transport.rs) in one channel: the share `lobe_exitance / B`
// leaves by the channel's exit lobe (`lobe`: axis and κ; `ExitLobe::factor`), the rest
// `B' = B − lobe_exitance` by 1 + D (s − 1), D = g·clamp(1 − A E⁰/B'), s the deep law about
// the channel's `flow` where it has one (axis, 1/N), else about the normal
// (`shape_about_normal`, `deep_exit_shape` at the pixel's exit cosine).
fn exit_factor(law: vec4<f32>, flow: vec4<f32>, lobe: vec4<f32>, lobe_norm: f32, lobe_exitance: f32,
               local_albedo: f32, eta: f32, b: f32, e0: f32, n: vec3<f32>, towards: vec3<f32>,
               shape_about_normal: f32) -> f32 {
    var share = 0.0;
    if lobe_norm > 0.0 && b > 0.0 {
        share = clamp(lobe_exitance / b, 0.0, 1.0);
    }
    let lobed = share * lobe_norm * exp(lobe.w * (dot(towards, lobe.xyz) - 1.0));
    let rest = b * (1.0 - share);
    if law.w <= 0.0 || rest <= 0.0 {
        return lobed + (1.0 - share);
    }
    let deep = law.w * clamp(1.0 - local_albedo * e0 / rest, 0.0, 1.0);
    var shape = shape_about_normal;
    if any(flow != vec4(0.0)) {
        shape = deep_exit_shape_about(law, eta, n, flow.xyz, towards) * flow.w;
    }
    return lobed + (1.0 - share) * (1.0 + deep * (shape - 1.0));
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
}

fn no_surface() -> Surface {
    return Surface(false, vec3(0.0), vec3(0.0), vec3(0.0), 0.0);
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
    return Surface(true, x, n, towards, clamp(dot(n, towards), 0.0, 1.0));
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
}

fn no_light() -> Gathered {
    return Gathered(vec3(0.0), 0.0, vec4(-1.0), vec4(-1.0), vec4(-1.0), -1.0, vec3(1.0), 3.0e38, -1, 0.0);
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
    let law = vec3(
        exit_factor(record.law_r, patch_flow(i, 0u), patch_lobes(i, 0u), norms.r, afar.r,
                    record.local_albedo.r, eta, b_i.r, e0.r, s.n, s.towards, shape.r),
        exit_factor(record.law_g, patch_flow(i, 1u), patch_lobes(i, 1u), norms.g, afar.g,
                    record.local_albedo.g, eta, b_i.g, e0.g, s.n, s.towards, shape.g),
        exit_factor(record.law_b, patch_flow(i, 2u), patch_lobes(i, 2u), norms.b, afar.b,
                    record.local_albedo.b, eta, b_i.b, e0.b, s.n, s.towards, shape.b),
    );
    (*acc).sum += w * max(b_i - record.albedo.rgb * e0, vec3(0.0)) * law / 3.14159265358979;
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

// Single scattering marched per pixel (`MarchedObject::radiance`, translucent_shadow_map.rs):
// at `MARCHED_DEPTHS` optical depths a channel (the midpoint quantiles of e^{−τ}) along the
// view ray refracted into the pixel's object, each against each light's map of the object —
// the light's path inside to it (scaled for its refraction) and its column's light — out
// through the boundary, T(μ)/η².
const MARCHED_DEPTHS: u32 = 16u;

// `TranslucentShadowMap::lit_path_inside`: the light's path inside to `p` in map `m` and
// its own texel's light (the path's scale in w); `inside` false before the entry or beyond
// the first exit by more than a texel, or off the object.
struct LitPath {
    inside: bool,
    path: f32,
    light: vec4<f32>,
}

fn map_entry(h: TranslucentMaps, m: u32, x: i32, y: i32) -> f32 {
    return translucent_map_depth(translucent_depths[2u * u32(translucent_texel(h, m, x, y, true))]);
}

fn lit_path_inside(h: TranslucentMaps, m: u32, f: TranslucentFrame, p: vec3<f32>) -> LitPath {
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
    let k = u32(translucent_texel(h, m, own.x, own.y, true));
    var near = translucent_map_depth(translucent_depths[2u * k]);
    let far = translucent_map_depth(translucent_depths[2u * k + 1u]);
    if all(corners < vec4(3.0e38)) {
        near = mix(mix(corners.x, corners.y, t.x), mix(corners.z, corners.w, t.x), t.y);
    }
    lit.inside = near < 3.0e38 && place.depth >= near - texel && place.depth <= far + texel;
    lit.path = max(place.depth - near, 0.0);
    lit.light = translucent_maps[translucent_light_at(h, m) + k - m * h.resolution * h.resolution];
    // From a point, the light spreads on inside as outside (index-matched): its irradiance at
    // the entry times (entry distance / distance)².
    if f.perspective && place.depth > near {
        lit.light = vec4(lit.light.rgb * (near * near) / (place.depth * place.depth), lit.light.w);
    }
    return lit;
}

fn marched_single_scattering(object: i32, s: Surface) -> vec3<f32> {
    let h = translucent_maps_of(translucent_maps[0]);
    if object < 0 || u32(object) >= h.objects || s.mu <= 0.0 {
        return vec3(0.0);
    }
    let medium = translucent_maps[1u + 2u * u32(object)];
    if medium.w < 0.0 {
        return vec3(0.0);
    }
    let sigma_t = medium.xyz;
    let albedo_eta = translucent_maps[2u + 2u * u32(object)];
    let eta = clamp(albedo_eta.w, 1.0, 3.0);
    let inside = sqrt(max(1.0 - (1.0 - s.mu * s.mu) / (eta * eta), 0.0));
    // Snell's law: the ray's part along the surface shrinks by η.
    let into = (-s.towards + s.n * s.mu) / eta - s.n * inside;
    var total = vec3(0.0);
    for (var l = 0u; l < h.lights; l++) {
        let m = l * h.slots + u32(medium.w);
        let frame_at = translucent_frame_at(h, m);
        let f = translucent_frame_of(translucent_maps[frame_at], translucent_maps[frame_at + 1u],
                                     translucent_maps[frame_at + 2u], translucent_maps[frame_at + 3u]);
        if !f.present {
            continue;
        }
        for (var c = 0u; c < 3u; c++) {
            if !(sigma_t[c] > 0.0) {
                continue;
            }
            var sum = 0.0;
            var entered = false;
            for (var k = 0u; k < MARCHED_DEPTHS; k++) {
                // `optical_depth_quantile`.
                let depth = -log(1.0 - (f32(k) + 0.5) / f32(MARCHED_DEPTHS)) / sigma_t[c];
                let lit = lit_path_inside(h, m, f, s.x + into * depth);
                if lit.inside {
                    sum += lit.light[c] * exp(-sigma_t[c] * lit.path * lit.light.w);
                    entered = true;
                } else if entered {
                    // Once the ray has left the object, what lies beyond may be air.
                    break;
                }
            }
            total[c] += sum / f32(MARCHED_DEPTHS);
        }
    }
    let exit = (1.0 - fresnel_reflectance(s.mu, eta)) / (eta * eta);
    return albedo_eta.rgb / (4.0 * 3.14159265358979) * total * exit;
}

// The light gathered at the pixel `s`, with its object's single scattering marched, times
// the exposure; `w` = 0 where no patch reaches the pixel.
fn finish(acc: Gathered, s: Surface) -> vec4<f32> {
    if acc.weights <= 0.0 {
        return vec4(0.0);
    }
    let marched = marched_single_scattering(acc.object, s);
#ifdef PHOTON_DENSITY
    return vec4((acc.sum + marched) * view.exposure, 1.0);
#else
    return vec4((acc.sum / acc.weights + marched) * view.exposure, 1.0);
#endif
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

#ifdef COMPUTE_GATHER
// The lit image and the image written (Bevy's post-process ping-pong): every pixel is copied,
// with the gathered light added where there is some; alpha kept.
@group(0) @binding(7) var lit: texture_2d<f32>;
@group(0) @binding(8) var lit_out: texture_storage_2d<rgba16float, write>;

// The surface the view's pixel `id` shows; none outside the view.
fn view_surface(id: vec2<u32>) -> Surface {
    if any(id >= textureDimensions(lit)) {
        return no_surface();
    }
    return pixel_surface(vec2<i32>(id), vec2<f32>(id) + 0.5);
}

// A workgroup's 8×8 pixels walk the grids once together (tiled culling, as Forward+ does for
// lights): the cells about the box of their world points give the patches that reach the
// box, and each pixel then takes its own from that list — instead of each pixel hashing its
// own 27 cells a grid and walking their buckets, out of step with its neighbours. A tile
// whose box spans more than `TILE_CELLS` cells of a grid or reaches more than `TILE_PATCHES`
// patches (an outline over what lies behind it) tries again as two: its pixels nearer and
// farther than the middle of their distances from the camera, a list each. Those still too
// large walk the grids pixel by pixel as the fragment form does (on an H100 at 1080p, half
// resolution, those walks were 40 % of the gather's first pass before the split).
const TILE_PATCHES: u32 = 256u;
const TILE_CELLS: u32 = 128u;

// The tile's box and its pixels' distances from the camera as order-preserving bits (least
// x y z distance, most x y z distance).
var<workgroup> tile_box: array<atomic<u32>, 8>;
var<workgroup> tile_count: atomic<u32>;
var<workgroup> tile_patches: array<u32, TILE_PATCHES>;
var<workgroup> tile_listed: u32;

// The cells of grid `g` about the box [lo, hi]: a grid's cells are as wide as its widest
// reach, so a patch reaching the box has its centre in the box grown by one cell (and a
// little, for rounding).
struct CellRange {
    first: vec3<i32>,
    extent: vec3<u32>,
}

fn cells_about(g: GridLevel, lo: vec3<f32>, hi: vec3<f32>) -> CellRange {
    let first = vec3<i32>(floor(lo / g.cell_size - 1.001));
    let last = vec3<i32>(floor(hi / g.cell_size + 1.001));
    return CellRange(first, vec3<u32>(last - first + 1));
}

// Whether the box [lo, hi] spans at most `TILE_CELLS` cells in every grid (each extent first:
// their product could wrap).
fn box_fits(lo: vec3<f32>, hi: vec3<f32>) -> bool {
    for (var level = 0u; level < params.levels; level += 1u) {
        let e = cells_about(grid_level(level), lo, hi).extent;
        if any(e > vec3(TILE_CELLS)) || e.x * e.y * e.z > TILE_CELLS {
            return false;
        }
    }
    return true;
}

// The patches of all grids that may reach the box [lo, hi] (which `box_fits`) into
// `tile_patches`, the cells shared among the workgroup's threads (`thread` of 64).
fn collect_tile_patches(thread: u32, lo: vec3<f32>, hi: vec3<f32>) {
    for (var level = 0u; level < params.levels; level += 1u) {
        let g = grid_level(level);
        let range = cells_about(g, lo, hi);
        let extent = range.extent;
        let cells = extent.x * extent.y * extent.z;
        for (var c = thread; c < cells; c += 64u) {
            let cell = range.first + vec3<i32>(vec3(c % extent.x, (c / extent.x) % extent.y, c / (extent.x * extent.y)));
            let b = bucket(cell, g.mask);
            for (var k = grid[g.table + b]; k < grid[g.table + b + 1u]; k += 1u) {
                let member = member_in_cell(g, k, cell);
                if member < 0 {
                    continue;
                }
                let i = u32(member);
                let centre = patches[i].centre;
                // The patch's distance from the box, against its reach (a little grown: the
                // pixels' own test decides).
                let out = max(max(lo - centre.xyz, centre.xyz - hi), vec3(0.0));
                if dot(out, out) >= centre.w * centre.w * 1.0001 {
                    continue;
                }
                let slot = atomicAdd(&tile_count, 1u);
                if slot < TILE_PATCHES {
                    tile_patches[slot] = i;
                }
            }
        }
    }
}

// A box of some of the tile's pixels, and their least and most distance from the camera.
struct TileBox {
    // Some pixel took part.
    any: bool,
    lo: vec3<f32>,
    hi: vec3<f32>,
    near: f32,
    far: f32,
}

// The box of the pixels whose `member` is true (`s` their surfaces, `d` their distances from
// the camera). Every thread of the workgroup calls it (it holds barriers); all get the same
// box.
fn tile_box_of(thread: u32, s: Surface, d: f32, member: bool) -> TileBox {
    if thread == 0u {
        for (var k = 0u; k < 4u; k += 1u) {
            atomicStore(&tile_box[k], 0xffffffffu);
            atomicStore(&tile_box[4u + k], 0u);
        }
    }
    workgroupBarrier();
    if member {
        atomicMin(&tile_box[0], ordered_bits(s.x.x));
        atomicMin(&tile_box[1], ordered_bits(s.x.y));
        atomicMin(&tile_box[2], ordered_bits(s.x.z));
        atomicMin(&tile_box[3], ordered_bits(d));
        atomicMax(&tile_box[4], ordered_bits(s.x.x));
        atomicMax(&tile_box[5], ordered_bits(s.x.y));
        atomicMax(&tile_box[6], ordered_bits(s.x.z));
        atomicMax(&tile_box[7], ordered_bits(d));
    }
    workgroupBarrier();
    let lo = vec3(atomicLoad(&tile_box[0]), atomicLoad(&tile_box[1]), atomicLoad(&tile_box[2]));
    let hi = vec3(atomicLoad(&tile_box[4]), atomicLoad(&tile_box[5]), atomicLoad(&tile_box[6]));
    let near = atomicLoad(&tile_box[3]);
    let far = atomicLoad(&tile_box[7]);
    // Every thread has read the box before it is reset again.
    workgroupBarrier();
    return TileBox(
        all(lo <= hi),
        vec3(from_ordered_bits(lo.x), from_ordered_bits(lo.y), from_ordered_bits(lo.z)),
        vec3(from_ordered_bits(hi.x), from_ordered_bits(hi.y), from_ordered_bits(hi.z)),
        from_ordered_bits(near),
        from_ordered_bits(far),
    );
}

// The list of the patches that may reach `box` into `tile_patches`: whether it holds them all
// (the box spans few enough cells and they are few enough), the same in every thread. Every
// thread of the workgroup calls it (it holds barriers).
fn tile_list(thread: u32, box: TileBox) -> bool {
    if thread == 0u {
        atomicStore(&tile_count, 0u);
    }
    workgroupBarrier();
    let fits = box.any && box_fits(box.lo, box.hi);
    if fits {
        collect_tile_patches(thread, box.lo, box.hi);
    }
    workgroupBarrier();
    if thread == 0u {
        tile_listed = select(0u, 1u, fits && atomicLoad(&tile_count) <= TILE_PATCHES);
    }
    return workgroupUniformLoad(&tile_listed) == 1u;
}

// The sums of a pixel (`s`) from the list, or where the list does not hold its patches
// (`listed` false) from its own walk of the grids.
fn listed_or_walked(s: Surface, listed: bool) -> Gathered {
    if !listed {
        return walked(s);
    }
    var acc = no_light();
    let count = atomicLoad(&tile_count);
    for (var k = 0u; k < count; k += 1u) {
        add_patch(tile_patches[k], s, &acc);
    }
    return acc;
}

// The sums for each thread's surface `s` (invalid: none wanted) by the tile's walk of the
// grids. Every thread of the workgroup calls it (it holds barriers).
fn tile_walked(thread: u32, s: Surface) -> Gathered {
    var acc = no_light();
    // Each pixel's distance from the camera, once for the tile's boxes and its side.
    let d = distance(s.x, view.world_position);
    let whole = tile_box_of(thread, s, d, s.valid);
    if tile_list(thread, whole) {
        if s.valid {
            acc = listed_or_walked(s, true);
        }
        return acc;
    }
    // Too large for one list: the pixels nearer than the middle of the tile's distances, then
    // the farther ones, a list each.
    let middle = 0.5 * (whole.near + whole.far);
    let far_side = s.valid && d > middle;
    for (var side = 0u; side < 2u; side += 1u) {
        let member = s.valid && far_side == (side == 1u);
        let listed = tile_list(thread, tile_box_of(thread, s, d, member));
        if member {
            acc = listed_or_walked(s, listed);
        }
        // Every pixel of this side is done with the list before the next side's.
        workgroupBarrier();
    }
    return acc;
}

#ifdef HALF_RESOLUTION
// `GatherResolution::Half`: the tiled gather at one pixel in 2×2 (`gather_half`, into
// `half_light`), then every pixel of the view from the four samples about it whose surface is
// its own (`gather_upsample`), and last the pixels none of them serves (at a depth edge or a
// crease), which gather themselves as the full-resolution gather does (`gather_unserved`, its
// own pass so that the upsample keeps the few registers it needs; only the tiles that hold such
// a pixel work).

// Per sample (the top-left pixel of its 2×2): the gathered light times the exposure, and in
// w the smallest reach of the patches that reached it, -1 where none reached its surface, 0
// where it shows none.
@group(0) @binding(9) var half_light_out: texture_storage_2d<rgba32float, write>;
@group(0) @binding(10) var half_light: texture_2d<f32>;
// Per 8×8 tile, 1 where some pixel of it is served by no sample.
@group(0) @binding(11) var unserved_tiles_out: texture_storage_2d<r32uint, write>;
@group(0) @binding(12) var unserved_tiles: texture_2d<u32>;

@compute @workgroup_size(8, 8, 1)
fn gather_half(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(local_invocation_index) thread: u32,
) {
    let inside = all(id.xy < textureDimensions(half_light_out));
    let p = vec2<i32>(2u * id.xy);
    var s = no_surface();
    if inside && all(vec2<u32>(p) < textureDimensions(depth_prepass)) {
        s = pixel_surface(p, vec2<f32>(p) + 0.5);
    }
    let acc = tile_walked(thread, s);
    if !inside {
        return;
    }
    var sample = vec4(0.0);
    if acc.weights > 0.0 {
        sample = vec4(finish(acc, s).rgb, acc.reach);
    } else if s.valid {
        sample = vec4(0.0, 0.0, 0.0, -1.0);
    }
    textureStore(half_light_out, id.xy, sample);
}

// Whether a sample's surface `r` (its light `sample`) is the pixel's surface `s`, seen alike:
// its normal within ~18° (0.95) and its exit cosine towards the camera within 0.05 (the exit
// law's limb darkening changes fast towards an outline), off the pixel's tangent plane by at
// most a quarter of their distance (a depth step is along the view ray, a curved surface's
// deviation second order), and, where patches reached it, within the smallest of their
// reaches (the light changes on that scale).
fn same_surface(s: Surface, r: Surface, sample: vec4<f32>) -> bool {
    if !r.valid || sample.w == 0.0 || dot(s.n, r.n) < 0.95 || abs(s.mu - r.mu) > 0.05 {
        return false;
    }
    let d = r.x - s.x;
    let d2 = dot(d, d);
    let off_plane = abs(dot(s.n, d));
    return off_plane * off_plane <= 0.0625 * d2 + 1.0e-12 && (sample.w < 0.0 || d2 <= sample.w * sample.w);
}

// The light of the samples about pixel `p` (surface `s`) that show its surface, weighted
// bilinearly; w: their weight, 0 where none serves it. The samples stand at the even pixels:
// an even coordinate is its own sample, an odd one halfway between two.
fn upsampled(p: vec2<i32>, s: Surface) -> vec4<f32> {
    var sum = vec3(0.0);
    var weight = 0.0;
    if s.valid {
        let base = p / 2;
        let t = vec2<f32>(p - 2 * base) * 0.5;
        let last = vec2<i32>(textureDimensions(half_light)) - 1;
        for (var k = 0u; k < 4u; k += 1u) {
            let c = vec2(i32(k & 1u), i32(k >> 1u));
            let bilinear = mix(1.0 - t.x, t.x, f32(c.x)) * mix(1.0 - t.y, t.y, f32(c.y));
            let q = base + c;
            if bilinear <= 0.0 || any(q > last) {
                continue;
            }
            let sample = textureLoad(half_light, q, 0);
            let r = pixel_surface(2 * q, vec2<f32>(2 * q) + 0.5);
            if same_surface(s, r, sample) {
                sum += bilinear * sample.rgb;
                weight += bilinear;
            }
        }
    }
    if weight <= 0.0 {
        return vec4(0.0);
    }
    return vec4(sum / weight, weight);
}

var<workgroup> tile_unserved: atomic<u32>;
var<workgroup> tile_unserved_uniform: u32;

@compute @workgroup_size(8, 8, 1)
fn gather_upsample(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(local_invocation_index) thread: u32,
    @builtin(workgroup_id) tile: vec3<u32>,
) {
    if thread == 0u {
        atomicStore(&tile_unserved, 0u);
    }
    workgroupBarrier();
    let inside = all(id.xy < textureDimensions(lit));
    let p = vec2<i32>(id.xy);
    let s = view_surface(id.xy);
    let added = upsampled(p, s);
    if s.valid && added.w <= 0.0 {
        atomicStore(&tile_unserved, 1u);
    }
    workgroupBarrier();
    if thread == 0u {
        textureStore(unserved_tiles_out, tile.xy, vec4(atomicLoad(&tile_unserved), 0u, 0u, 0u));
    }
    if !inside {
        return;
    }
    let colour = textureLoad(lit, p, 0);
    textureStore(lit_out, p, vec4(colour.rgb + added.rgb, colour.a));
}

@compute @workgroup_size(8, 8, 1)
fn gather_unserved(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(local_invocation_index) thread: u32,
    @builtin(workgroup_id) tile: vec3<u32>,
) {
    if thread == 0u {
        tile_unserved_uniform = textureLoad(unserved_tiles, tile.xy, 0).x;
    }
    if workgroupUniformLoad(&tile_unserved_uniform) == 0u {
        return;
    }
    let inside = all(id.xy < textureDimensions(lit));
    let p = vec2<i32>(id.xy);
    let s = view_surface(id.xy);
    let unserved = s.valid && upsampled(p, s).w <= 0.0;
    // The tile's box only about the pixels that gather themselves.
    var own = no_surface();
    if unserved {
        own = s;
    }
    let acc = tile_walked(thread, own);
    if unserved {
        let colour = textureLoad(lit, p, 0);
        textureStore(lit_out, p, vec4(colour.rgb + finish(acc, own).rgb, colour.a));
    }
}
#else
@compute @workgroup_size(8, 8, 1)
fn gather_compute(
    @builtin(global_invocation_id) id: vec3<u32>,
    @builtin(local_invocation_index) thread: u32,
) {
    let inside = all(id.xy < textureDimensions(lit));
    let p = vec2<i32>(id.xy);
    let s = view_surface(id.xy);
    let added = finish(tile_walked(thread, s), s);
    if !inside {
        return;
    }
    let colour = textureLoad(lit, p, 0);
    textureStore(lit_out, p, vec4(colour.rgb + added.rgb, colour.a));
}
#endif
#else
@fragment
fn gather(in: FullscreenVertexOutput) -> @location(0) vec4<f32> {
    let added = gathered(pixel_surface(vec2<i32>(floor(in.position.xy)), in.position.xy));
    if added.w == 0.0 {
        discard;
    }
    return vec4(added.rgb, 0.0);
}
#endif
