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
// view's other main image (`gather_compute`).

#import bevy_core_pipeline::fullscreen_vertex_shader::FullscreenVertexOutput
#import bevy_render::view::View
#import bevy_mesostructure::translucency::boundary::{
    deep_exit_shape, deep_exit_shape_about, fresnel_reflectance,
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

// The grid cell's bucket: `PatchGrid::bucket` in gather/mod.rs.
fn bucket(cell: vec3<i32>, mask: u32) -> u32 {
    let c = bitcast<vec3<u32>>(cell);
    return ((c.x * 73856093u) ^ (c.y * 19349663u) ^ (c.z * 83492791u)) & mask;
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
// the channel's `flow` where it has one (axis, 1/N), else about the normal at the exit
// cosine mu.
fn exit_factor(law: vec4<f32>, flow: vec4<f32>, lobe: vec4<f32>, lobe_norm: f32, lobe_exitance: f32,
               local_albedo: f32, eta: f32, b: f32, e0: f32, n: vec3<f32>, towards: vec3<f32>,
               mu: f32) -> f32 {
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
    var shape = deep_exit_shape(law, eta, mu);
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

// The light the patches give the pixel `p` (centre `position`), times the exposure; `w` = 0
// where no patch reaches it (or nothing was drawn there).
fn gathered(p: vec2<i32>, position: vec2<f32>) -> vec4<f32> {
    let depth = textureLoad(depth_prepass, p, 0);
    if depth <= 0.0 {
        return vec4(0.0);
    }
    let uv = (position - view.viewport.xy) / view.viewport.zw;
    let ndc = vec4(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, depth, 1.0);
    let world = view.world_from_clip * ndc;
    let x = world.xyz / world.w;
    let n = normalize(textureLoad(normal_prepass, p, 0).xyz * 2.0 - 1.0);
    // The exit direction and cosine towards the camera.
    let towards = normalize(view.world_position - x);
    let mu = clamp(dot(n, towards), 0.0, 1.0);

    var sum = vec3(0.0);
    var weights = 0.0;
    for (var level = 0u; level < params.levels; level += 1u) {
        let cell_size = bitcast<f32>(grid[4u * level]);
        let mask = grid[4u * level + 1u];
        let table = grid[4u * level + 2u];
        let members = grid[4u * level + 3u];
        let centre_cell = vec3<i32>(floor(x / cell_size));
        for (var dz = -1; dz <= 1; dz += 1) {
            for (var dy = -1; dy <= 1; dy += 1) {
                for (var dx = -1; dx <= 1; dx += 1) {
                    let cell = centre_cell + vec3(dx, dy, dz);
                    let b = bucket(cell, mask);
                    let start = grid[table + b];
                    let end = grid[table + b + 1u];
                    for (var k = start; k < end; k += 1u) {
                        // Only the members of this very cell: a bucket that two of the 27
                        // cells hash to would give its patches twice (photons: twice the
                        // light); a member of another of them is taken when that one is walked.
                        let member = members + 4u * k;
                        let own_cell = bitcast<vec3<i32>>(
                            vec3(grid[member + 1u], grid[member + 2u], grid[member + 3u]),
                        );
                        if any(own_cell != cell) {
                            continue;
                        }
                        let i = grid[member];
                        let record = patches[i];
                        let d = record.centre.xyz - x;
                        let d2 = dot(d, d);
                        // Each patch reaches 1.5 of its own object's patch sizes (centre.w).
                        let r2 = record.centre.w * record.centre.w;
                        if d2 >= r2 {
                            continue;
                        }
                        let agree = smoothstep(0.3, 0.9, dot(n, record.normal.xyz));
                        let falloff = 1.0 - d2 / r2;
#ifdef PHOTON_DENSITY
                        // The seed's photons: power Φ = M·A under a kernel of unit integral,
                        // K(d) = 3/(πR²)(1 − d²/R²)² (`GatherMethod::PhotonDensity`).
                        let w = falloff * falloff * agree * 3.0 / (3.14159265358979 * r2) * record.normal.w;
#else
                        let w = falloff * falloff * agree;
#endif
                        if w <= 0.0 {
                            continue;
                        }
                        let b_i = vectors[params.exitance + i].rgb;
                        let e0 = vectors[params.direct + i].rgb;
                        let eta = record.local_albedo.w;
                        let norms = patch_lobes(i, 3u);
                        let afar = patch_lobes(i, 4u);
                        let law = vec3(
                            exit_factor(record.law_r, patch_flow(i, 0u), patch_lobes(i, 0u), norms.r,
                                        afar.r, record.local_albedo.r, eta, b_i.r, e0.r, n, towards, mu),
                            exit_factor(record.law_g, patch_flow(i, 1u), patch_lobes(i, 1u), norms.g,
                                        afar.g, record.local_albedo.g, eta, b_i.g, e0.g, n, towards, mu),
                            exit_factor(record.law_b, patch_flow(i, 2u), patch_lobes(i, 2u), norms.b,
                                        afar.b, record.local_albedo.b, eta, b_i.b, e0.b, n, towards, mu),
                        );
                        sum += w * max(b_i - record.albedo.rgb * e0, vec3(0.0)) * law / 3.14159265358979;
                        // Single scattering by the lit face (`BeamSingleScattering::radiance`):
                        // the patch's beams at this pixel's own incidence.
                        let travel = vectors[params.beam_direction + i].xyz;
                        if any(record.single.rgb > vec3(0.0)) && dot(travel, travel) > 0.0 {
                            let mu0 = dot(n, -normalize(travel));
                            let e = vectors[params.beam_irradiance + i].rgb * max(mu0, 0.0);
                            sum += w * single_scattering_radiance(record.single.rgb, record.single.w, e, mu0, mu);
                        }
                        weights += w;
                    }
                }
            }
        }
    }
    if weights <= 0.0 {
        return vec4(0.0);
    }
#ifdef PHOTON_DENSITY
    return vec4(sum * view.exposure, 1.0);
#else
    return vec4(sum / weights * view.exposure, 1.0);
#endif
}

#ifdef COMPUTE_GATHER
// The lit image and the image written (Bevy's post-process ping-pong): every pixel is copied,
// with the gathered light added where there is some; alpha kept.
@group(0) @binding(7) var lit: texture_2d<f32>;
@group(0) @binding(8) var lit_out: texture_storage_2d<rgba16float, write>;

@compute @workgroup_size(8, 8, 1)
fn gather_compute(@builtin(global_invocation_id) id: vec3<u32>) {
    if any(id.xy >= textureDimensions(lit)) {
        return;
    }
    let p = vec2<i32>(id.xy);
    let colour = textureLoad(lit, p, 0);
    let added = gathered(p, vec2<f32>(id.xy) + 0.5);
    textureStore(lit_out, p, vec4(colour.rgb + added.rgb, colour.a));
}
#else
@fragment
fn gather(in: FullscreenVertexOutput) -> @location(0) vec4<f32> {
    let added = gathered(vec2<i32>(floor(in.position.xy)), in.position.xy);
    if added.w == 0.0 {
        discard;
    }
    return vec4(added.rgb, 0.0);
}
#endif
