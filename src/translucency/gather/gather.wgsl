// Seed 001's last step, by per-pixel interpolation of the patches' outgoing radiance: each
// pixel (world position from the depth prepass, normal from the normal prepass) gathers the
// patches within their reach R (1.5 of their object's patch size) about it through a hashed grid, weighted by distance,
// (1 − d²/R²)², and by how far their normals agree with its own; translucent patches give
// their whole exitance B/π (their mesh's material has no diffuse), opaque patches the light
// they bounce, (B − ρE⁰)/π = ρ(E − E⁰)/π (their direct light is Bevy's). Added to the lit
// view (additive blending), times the view's exposure as Bevy's lighting is.

#import bevy_core_pipeline::fullscreen_vertex_shader::FullscreenVertexOutput
#import bevy_render::view::View

struct GatherParams {
    // Grids by reach (`PatchGrid::levels`): per grid four words at the start of `grid` (cell
    // size, bucket mask, where its bucket offsets and its members start).
    levels: u32,
    patches: u32,
    // Offsets in `vectors` (vec4s).
    direct: u32,
    exitance: u32,
}

struct GatherPatch {
    centre: vec4<f32>,
    normal: vec4<f32>,
    albedo: vec4<f32>,
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

@fragment
fn gather(in: FullscreenVertexOutput) -> @location(0) vec4<f32> {
    let p = vec2<i32>(floor(in.position.xy));
    let depth = textureLoad(depth_prepass, p, 0);
    if depth <= 0.0 {
        discard;
    }
    let uv = (in.position.xy - view.viewport.xy) / view.viewport.zw;
    let ndc = vec4(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, depth, 1.0);
    let world = view.world_from_clip * ndc;
    let x = world.xyz / world.w;
    let n = normalize(textureLoad(normal_prepass, p, 0).xyz * 2.0 - 1.0);

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
                    let b = bucket(centre_cell + vec3(dx, dy, dz), mask);
                    let start = grid[table + b];
                    let end = grid[table + b + 1u];
                    for (var k = start; k < end; k += 1u) {
                        let i = grid[members + k];
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
                        let w = falloff * falloff * agree;
                        if w <= 0.0 {
                            continue;
                        }
                        let b_i = vectors[params.exitance + i].rgb;
                        let e0 = vectors[params.direct + i].rgb;
                        sum += w * max(b_i - record.albedo.rgb * e0, vec3(0.0)) / 3.14159265358979;
                        weights += w;
                    }
                }
            }
        }
    }
    if weights <= 0.0 {
        discard;
    }
    return vec4(sum / weights * view.exposure, 0.0);
}
