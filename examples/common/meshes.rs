//! The examples' meshes: OBJ files (vertices and triangles) under `assets/meshes/`, given smooth
//! normals and spherical UVs, since the published teapot and bunny have neither.

use std::path::Path;

use bevy::{
    asset::RenderAssetUsages,
    mesh::{Indices, PrimitiveTopology, VertexAttributeValues},
    prelude::*,
};

/// Reads the `v` and `f` lines of an OBJ file (triangles; polygons are fanned).
pub fn read_obj(path: &Path) -> (Vec<Vec3>, Vec<u32>) {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    let (mut positions, mut indices) = (vec![], vec![]);
    for line in text.lines() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                let v: Vec<f32> = words
                    .take(3)
                    .map(|w| w.parse().expect("a number"))
                    .collect();
                positions.push(Vec3::new(v[0], v[1], v[2]));
            }
            Some("f") => {
                // "i", "i/t" or "i/t/n", 1-based.
                let face: Vec<u32> = words
                    .map(|w| {
                        w.split('/')
                            .next()
                            .unwrap()
                            .parse::<u32>()
                            .expect("an index")
                            - 1
                    })
                    .collect();
                for k in 1..face.len().saturating_sub(1) {
                    indices.extend([face[0], face[k], face[k + 1]]);
                }
            }
            _ => {}
        }
    }
    (positions, indices)
}

/// A mesh from an OBJ file: smooth normals, and UVs by a spherical projection about the centre
/// (`u` around the vertical axis, `v` from the top), `tiles` repeats of the height map around
/// and half as many from top to bottom. Triangles across the `u` seam get their own vertices
/// (unwrapped), so the height map does not streak there.
pub fn obj_mesh(path: &Path, tiles: f32) -> Mesh {
    let (positions, indices) = read_obj(path);
    let mut indexed = Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::default(),
    )
    .with_inserted_attribute(
        Mesh::ATTRIBUTE_POSITION,
        positions.iter().map(|p| p.to_array()).collect::<Vec<_>>(),
    )
    .with_inserted_indices(Indices::U32(indices.clone()));
    indexed.compute_smooth_normals();
    let Some(VertexAttributeValues::Float32x3(normals)) = indexed.attribute(Mesh::ATTRIBUTE_NORMAL)
    else {
        unreachable!("normals were just computed")
    };
    let uv = |p: Vec3| {
        let r = p.length().max(1e-6);
        Vec2::new(
            0.5 + p.z.atan2(p.x) / std::f32::consts::TAU,
            (p.y / r).clamp(-1.0, 1.0).acos() / std::f32::consts::PI,
        )
    };
    let (mut out_p, mut out_n, mut out_uv) = (vec![], vec![], vec![]);
    for tri in indices.chunks_exact(3) {
        let mut uvs: Vec<Vec2> = tri.iter().map(|&i| uv(positions[i as usize])).collect();
        let (lo, hi) = uvs
            .iter()
            .fold((f32::MAX, f32::MIN), |(a, b), t| (a.min(t.x), b.max(t.x)));
        if hi - lo > 0.5 {
            for t in &mut uvs {
                if t.x < 0.5 {
                    t.x += 1.0;
                }
            }
        }
        for (&i, t) in tri.iter().zip(uvs) {
            out_p.push(positions[i as usize].to_array());
            out_n.push(normals[i as usize]);
            out_uv.push([t.x * tiles, t.y * tiles * 0.5]);
        }
    }
    Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::default(),
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, out_p)
    .with_inserted_attribute(Mesh::ATTRIBUTE_NORMAL, out_n)
    .with_inserted_attribute(Mesh::ATTRIBUTE_UV_0, out_uv)
}

/// The path of a file under the crate's `assets/` folder.
pub fn asset_path(relative: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("assets")
        .join(relative)
}
