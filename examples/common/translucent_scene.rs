//! Issue 13's scene for the translucency precompute: a marble bunny (10 cm long) and a skin
//! sphere (radius 3 cm) on the floor of a closed 60 cm room with a red and a green wall, in
//! metres, as world-space triangle lists with their surfaces.

use std::path::Path;

use bevy::prelude::*;
use bevy_mesostructure::translucency::{
    PatchObject, PatchSurface, TranslucentPreset, patches::world_triangles,
};

/// World-space triangles of one object and what its surface does.
pub struct SceneObject {
    /// What it is.
    pub name: &'static str,
    /// Vertex positions, world space.
    pub positions: Vec<Vec3>,
    /// Triangle list.
    pub indices: Vec<u32>,
    /// Its surface.
    pub surface: PatchSurface,
}

impl SceneObject {
    /// The object as the patch resampler takes it.
    pub fn view(&self) -> PatchObject<'_> {
        PatchObject {
            positions: &self.positions,
            indices: &self.indices,
        }
    }
}

fn object(
    name: &'static str,
    mesh: Mesh,
    transform: Transform,
    surface: PatchSurface,
) -> SceneObject {
    let (positions, indices) =
        world_triangles(&mesh, &GlobalTransform::from(transform)).expect("a triangle list");
    SceneObject {
        name,
        positions,
        indices,
        surface,
    }
}

/// The scene; `bunny` is `assets/meshes/bunny.obj`.
pub fn translucent_room(bunny: &Path) -> Vec<SceneObject> {
    let mm = 0.001;
    let white = PatchSurface::Opaque {
        albedo: Vec3::splat(0.75),
    };
    let half = 0.3;
    let plane = |normal: Vec3| Plane3d::new(normal, Vec2::splat(half)).mesh().build();
    let (positions, mut indices) = crate::meshes::read_obj(bunny);
    // Patch normals follow the winding: make the closed bunny's face outwards (positive signed
    // volume).
    let volume: f32 = indices
        .chunks(3)
        .map(|t| {
            let p = |k: usize| positions[t[k] as usize];
            p(0).dot(p(1).cross(p(2)))
        })
        .sum();
    if volume < 0.0 {
        for t in indices.chunks_mut(3) {
            t.swap(1, 2);
        }
    }
    let mut bunny_mesh = Mesh::new(
        bevy::mesh::PrimitiveTopology::TriangleList,
        bevy::asset::RenderAssetUsages::default(),
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions);
    bunny_mesh.insert_indices(bevy::mesh::Indices::U32(indices));
    vec![
        object(
            "bunny (marble)",
            bunny_mesh,
            // Longest side 1.6 → 10 cm, resting on the floor.
            Transform::from_xyz(-0.06, 0.05, 0.0).with_scale(Vec3::splat(0.0625)),
            PatchSurface::Translucent {
                medium: TranslucentPreset::Marble.medium(),
                world_units_per_mm: mm,
                oriented_dipole: false,
            },
        ),
        object(
            "sphere (skin)",
            Sphere::new(0.03)
                .mesh()
                .ico(4)
                .expect("a valid subdivision"),
            Transform::from_xyz(0.08, 0.03, 0.02),
            PatchSurface::Translucent {
                medium: TranslucentPreset::Skin1.medium(),
                world_units_per_mm: mm,
                oriented_dipole: false,
            },
        ),
        object("floor", plane(Vec3::Y), Transform::IDENTITY, white),
        object(
            "ceiling",
            plane(Vec3::NEG_Y),
            Transform::from_xyz(0.0, 2.0 * half, 0.0),
            white,
        ),
        object(
            "wall (red)",
            plane(Vec3::X),
            Transform::from_xyz(-half, half, 0.0),
            PatchSurface::Opaque {
                albedo: Vec3::new(0.75, 0.1, 0.1),
            },
        ),
        object(
            "wall (green)",
            plane(Vec3::NEG_X),
            Transform::from_xyz(half, half, 0.0),
            PatchSurface::Opaque {
                albedo: Vec3::new(0.1, 0.75, 0.1),
            },
        ),
        object(
            "wall (back)",
            plane(Vec3::Z),
            Transform::from_xyz(0.0, half, -half),
            white,
        ),
        object(
            "wall (front)",
            plane(Vec3::NEG_Z),
            Transform::from_xyz(0.0, half, half),
            white,
        ),
    ]
}
