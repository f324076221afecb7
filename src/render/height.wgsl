// Height pass (paper §2.1, eq. 7): per visible pixel of a mesostructure mesh, the height
// `dis · k` fetched through the UVs, the NDC depth, the object id and the core normal n0.
// The vertex stage is Bevy's mesh vertex shader, so skinned, morphed and CPU-deformed meshes
// land exactly on their prepass depth.

#import bevy_pbr::forward_io::VertexOutput

struct HeightMaterial {
    // Columns of the 2×2 UV matrix: (x_axis.x, x_axis.y, y_axis.x, y_axis.y).
    uv_axes: vec4<f32>,
    uv_translation: vec2<f32>,
    scale: f32,
    object_id: f32,
    // 1: write the Blinn bump normal; 0: the material has its own normal map.
    bump: f32,
}

@group(3) @binding(0) var height_mips: texture_2d<f32>;
@group(3) @binding(1) var<uniform> material: HeightMaterial;

struct HeightOutput {
    // (dis · k in world units, NDC depth, object id, dis)
    @location(0) mhm: vec4<f32>,
    // (n0 in world space, 1)
    @location(1) core_normal: vec4<f32>,
    // (N' by Blinn bump mapping in world space, 1), or 0 where the material has a normal map
    @location(2) bump_normal: vec4<f32>,
}

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

@fragment
fn fragment(in: VertexOutput) -> HeightOutput {
#ifdef VERTEX_UVS_A
    let uv = mat2x2<f32>(material.uv_axes.xy, material.uv_axes.zw) * in.uv + material.uv_translation;
#else
    let uv = vec2<f32>(0.0);
#endif
    // Mip selection from the pixel footprint in texels (trilinear), as the hardware would.
    let size0 = vec2<f32>(textureDimensions(height_mips, 0));
    let dx = dpdx(uv) * size0;
    let dy = dpdy(uv) * size0;
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
    let dp1 = dpdx(in.world_position.xyz);
    let dp2 = dpdy(in.world_position.xyz);
    let duv1 = dpdx(uv);
    let duv2 = dpdy(uv);
    var bump = vec3<f32>(0.0);
#ifdef VERTEX_NORMALS
    let n = normalize(in.world_normal);
    let det = duv1.x * duv2.y - duv1.y * duv2.x;
    if material.bump > 0.0 && abs(det) > 1e-12 {
        let pu = (dp1 * duv2.y - dp2 * duv1.y) / det;
        let pv = (dp2 * duv1.x - dp1 * duv2.x) / det;
        // Central differences over two texels of level l0, per UV unit.
        let fu = material.scale * taps.across.x * taps.size.x * 0.5;
        let fv = material.scale * taps.across.y * taps.size.y * 0.5;
        let base = cross(pu, pv);
        let orientation = select(-1.0, 1.0, dot(base, n) >= 0.0);
        let bumped = orientation * (base + fu * cross(n, pv) - fv * cross(n, pu));
        let len = length(bumped);
        if len > 0.0 {
            bump = bumped / len;
        }
    }
#endif

    var out: HeightOutput;
    out.bump_normal = vec4<f32>(bump, 1.0);
    out.mhm = vec4<f32>(dis * material.scale, in.position.z, material.object_id, dis);
#ifdef VERTEX_NORMALS
    out.core_normal = vec4<f32>(normalize(in.world_normal), 1.0);
#else
    out.core_normal = vec4<f32>(0.0, 0.0, 0.0, 1.0);
#endif
    return out;
}
