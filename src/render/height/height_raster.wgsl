// Height pass, raster half (paper §2.1): per visible pixel of a mesostructure mesh, what the
// compute half needs to sample the height map there: the UV (the material's transform
// applied), the NDC depth, the object id, the core normal n0 and the material's parameter set.
// The vertex stage is Bevy's mesh vertex shader, so skinned, morphed and CPU-deformed meshes
// land exactly on their prepass depth. No texture is read here: fragment work is the scarce
// kind on some GPUs (height.wgsl).

#import bevy_pbr::forward_io::VertexOutput

struct HeightMaterial {
    // Columns of the 2×2 UV matrix: (x_axis.x, x_axis.y, y_axis.x, y_axis.y).
    uv_axes: vec4<f32>,
    uv_translation: vec2<f32>,
    object_id: f32,
    // Index of the material's parameter set (height map, horizon map, k, bump) in the compute
    // half's dispatches.
    parameter_set: f32,
}

@group(3) @binding(0) var<uniform> material: HeightMaterial;

struct HeightRasterOutput {
    // (u, v, NDC depth, object id)
    @location(0) surface: vec4<f32>,
    // (n0 in world space, parameter set)
    @location(1) core_normal: vec4<f32>,
}

@fragment
fn fragment(in: VertexOutput) -> HeightRasterOutput {
#ifdef VERTEX_UVS_A
    let uv = mat2x2<f32>(material.uv_axes.xy, material.uv_axes.zw) * in.uv + material.uv_translation;
#else
    let uv = vec2<f32>(0.0);
#endif
    var out: HeightRasterOutput;
    out.surface = vec4<f32>(uv, in.position.z, material.object_id);
#ifdef VERTEX_NORMALS
    out.core_normal = vec4<f32>(normalize(in.world_normal), material.parameter_set);
#else
    out.core_normal = vec4<f32>(0.0, 0.0, 0.0, material.parameter_set);
#endif
    return out;
}
