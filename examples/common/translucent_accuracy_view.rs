//! What the accuracy scenes' camera sees: the objects (`Shape`), where the camera stands, its
//! rays, and each pixel's hit on the object (`ShapeView`) — the geometry the plugin's picture
//! (`translucent_accuracy_scene.rs`), the references and the mesh light tracer all take.

use bevy::prelude::*;
use bevy_mesostructure::translucency::{PatchObject, SceneRays, patches::world_triangles};

/// The ball's radius, metres.
pub const RADIUS: f32 = 0.01;
/// Where the camera looking at the ball stands.
pub const EYE: Vec3 = Vec3::new(0.0, 0.0, 0.04);
/// Where the camera looking at the bunny stands: above it, to one side.
pub const BUNNY_EYE: Vec3 = Vec3::new(0.025, 0.03, 0.055);
/// The bunny's longest side, metres.
pub const BUNNY_LENGTH: f32 = 0.04;
/// The torus's ring and tube radii, metres: a tube 6 mm thick, thinner than skin's red
/// light travels, curved both ways.
pub const TORUS_RADII: (f32, f32) = (0.01, 0.003);
/// Where the camera looking at the torus stands: above it, to one side.
pub const TORUS_EYE: Vec3 = Vec3::new(0.01, 0.022, 0.036);
/// The default light: from the right, slightly above and in front.
pub const FRONT_LIGHT: Vec3 = Vec3::new(-1.0, -0.2, -0.3);
/// Lit from behind, a little from the left and above.
pub const BACK_LIGHT: Vec3 = Vec3::new(0.4, -0.2, 1.0);
pub const FOV_Y: f32 = std::f32::consts::FRAC_PI_4;

/// The object of an accuracy scene, centred on the origin; the camera looks at the origin.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Shape {
    /// A ball of radius 1 cm (Bevy's ico sphere of 5 subdivisions: 720 triangles), seen from
    /// 4 cm.
    Ball,
    /// The Stanford bunny (`assets/meshes/bunny.obj`, 3 674 triangles) 4 cm long: thin ears,
    /// concave creases and flat flanks, seen from above and aside.
    Bunny,
    /// A torus lying flat, ring radius 1 cm, tube radius 3 mm (Bevy's torus mesh, 48 × 24
    /// segments): a thin, doubly curved part, with a hole, seen from above and aside.
    Torus,
}

impl Shape {
    /// The object's world-space triangles, metres.
    pub fn triangles(self) -> (Vec<Vec3>, Vec<u32>) {
        match self {
            Shape::Ball => world_triangles(
                &Sphere::new(RADIUS).mesh().ico(5).expect("a valid subdivision"),
                &GlobalTransform::IDENTITY,
            )
            .expect("a triangle list"),
            Shape::Bunny => {
                let (positions, indices) =
                    crate::meshes::read_obj(&crate::meshes::asset_path("meshes/bunny.obj"));
                // The file's longest side is 1.6, centred (assets/meshes/README.md).
                let scale = BUNNY_LENGTH / 1.6;
                (positions.into_iter().map(|v| v * scale).collect(), indices)
            }
            Shape::Torus => world_triangles(&torus_mesh(), &GlobalTransform::IDENTITY)
                .expect("a triangle list"),
        }
    }

    /// The normals the GPU's prepass interpolates over the shape's triangles (`positions`,
    /// `indices` of [`triangles`](Self::triangles)), per vertex: the bunny's smooth normals
    /// as the examples give its mesh (`Mesh::compute_smooth_normals`), the torus's own; none
    /// for the ball (its pixels take the sphere's).
    pub fn vertex_normals(self, positions: &[Vec3], indices: &[u32]) -> Option<Vec<Vec3>> {
        use bevy::mesh::{Indices, PrimitiveTopology, VertexAttributeValues};
        let mesh = match self {
            Shape::Ball => return None,
            Shape::Bunny => {
                // In the file's units, as the examples load it: Bevy weighs each corner by its
                // angle only where its two edges' squared lengths multiply past f32's epsilon,
                // which no corner of a 4 cm bunny in metres does.
                let unit = 1.6 / BUNNY_LENGTH;
                let mut mesh = Mesh::new(PrimitiveTopology::TriangleList, bevy::asset::RenderAssetUsages::default())
                    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions.iter().map(|p| (*p * unit).to_array()).collect::<Vec<_>>())
                    .with_inserted_indices(Indices::U32(indices.to_vec()));
                mesh.compute_smooth_normals();
                mesh
            }
            Shape::Torus => torus_mesh(),
        };
        match mesh.attribute(Mesh::ATTRIBUTE_NORMAL) {
            Some(VertexAttributeValues::Float32x3(n)) if n.len() == positions.len() => {
                Some(n.iter().map(|&v| Vec3::from(v)).collect())
            }
            _ => None,
        }
    }

    /// Where the camera stands.
    pub fn eye(self) -> Vec3 {
        match self {
            Shape::Ball => EYE,
            Shape::Bunny => BUNNY_EYE,
            Shape::Torus => TORUS_EYE,
        }
    }

    /// The scene's name in `docs/translucent.csv`.
    pub fn scene_name(self) -> &'static str {
        match self {
            Shape::Ball => "ball",
            Shape::Bunny => "bunny",
            Shape::Torus => "torus",
        }
    }

    /// The object's size in a scene name (`ball_skin1_r10mm_front`).
    pub fn size_name(self) -> &'static str {
        match self {
            Shape::Ball => "r10mm",
            Shape::Bunny => "4cm",
            Shape::Torus => "R10r3mm",
        }
    }
}

/// The torus's mesh (Bevy's, 48 × 24 segments), for the patches and for Bevy's fit alike.
pub fn torus_mesh() -> Mesh {
    Torus { minor_radius: TORUS_RADII.1, major_radius: TORUS_RADII.0 }
        .mesh()
        .minor_resolution(24)
        .major_resolution(48)
        .build()
}

/// The camera's frame at `eye`, looking at the origin with +Y up: (forward, right, up).
pub fn camera_frame(eye: Vec3) -> (Vec3, Vec3, Vec3) {
    let forward = (-eye).normalize();
    let right = forward.cross(Vec3::Y).normalize();
    (forward, right, right.cross(forward))
}

/// The camera ray through the centre of pixel `(x, y)` of `size`²: unit direction.
pub fn camera_ray(eye: Vec3, x: u32, y: u32, size: u32) -> Vec3 {
    let tan = (FOV_Y / 2.0).tan();
    let (forward, right, up) = camera_frame(eye);
    let sx = (2.0 * (x as f32 + 0.5) / size as f32 - 1.0) * tan;
    let sy = (1.0 - 2.0 * (y as f32 + 0.5) / size as f32) * tan;
    (forward + right * sx + up * sy).normalize()
}

/// Where a pixel's camera ray meets the object.
#[derive(Clone, Copy, Debug)]
pub struct PixelHit {
    /// The ray's unit direction.
    pub direction: Vec3,
    /// The point met.
    pub point: Vec3,
    /// The surface's unit normal there, facing the camera.
    pub normal: Vec3,
    /// The distance from the eye.
    pub distance: f32,
}

/// What the camera sees of a shape at `size`² pixels, and which pixels are scored.
pub struct ShapeView {
    pub shape: Shape,
    pub size: u32,
    /// The object's world-space triangles (`Shape::triangles`), read once for the view, the
    /// plugin's patches and the reference's OBJ.
    pub positions: Vec<Vec3>,
    pub indices: Vec<u32>,
    /// Per pixel, row by row.
    pub hits: Vec<Option<PixelHit>>,
    /// Per pixel: on the object, facing the camera at a cosine of 0.3 or more, and (the
    /// bunny) with its four neighbours on the same surface (within 3 mm of its distance): the
    /// reference integrates each pixel's area and the plugin's picture takes its centre, so
    /// pixels astride a silhouette are left out.
    pub scored: Vec<bool>,
}

impl ShapeView {
    /// The view of `shape`: the ball's hits in closed form, the others' by rays.
    pub fn new(shape: Shape, size: u32) -> Self {
        Self::with_hits(shape, size, false)
    }

    /// The view of `shape` with every hit on its triangles, as the GPU's depth prepass puts
    /// its pixels (the ball's normals still the sphere's, as its interpolated normals are).
    /// The ball's references are of the sphere, so its silhouette and rim differ from them.
    pub fn on_mesh(shape: Shape, size: u32) -> Self {
        Self::with_hits(shape, size, true)
    }

    fn with_hits(shape: Shape, size: u32, on_mesh: bool) -> Self {
        let eye = shape.eye();
        let (positions, indices) = shape.triangles();
        let hits: Vec<Option<PixelHit>> = match shape {
            Shape::Ball if !on_mesh => (0..size * size)
                .map(|i| {
                    let d = camera_ray(eye, i % size, i / size, size);
                    let b = eye.dot(d);
                    let disc = b * b - (eye.length_squared() - RADIUS * RADIUS);
                    (disc > 0.0).then(|| {
                        let distance = -b - disc.sqrt();
                        let point = eye + d * distance;
                        PixelHit {
                            direction: d,
                            point,
                            normal: point.normalize(),
                            distance,
                        }
                    })
                })
                .collect(),
            Shape::Ball | Shape::Bunny | Shape::Torus => {
                let rays = SceneRays::new(&[PatchObject {
                    positions: &positions,
                    indices: &indices,
                }]);
                (0..size * size)
                    .map(|i| {
                        let d = camera_ray(eye, i % size, i / size, size);
                        rays.first_hit(eye, d).map(|(distance, n)| PixelHit {
                            direction: d,
                            point: eye + d * distance,
                            normal: match shape {
                                Shape::Ball => (eye + d * distance).normalize(),
                                _ if n.dot(d) > 0.0 => -n,
                                _ => n,
                            },
                            distance,
                        })
                    })
                    .collect()
            }
        };
        let at = |x: i64, y: i64| -> Option<PixelHit> {
            if x < 0 || y < 0 || x >= size as i64 || y >= size as i64 {
                return None;
            }
            hits[(y * size as i64 + x) as usize]
        };
        let scored = (0..size * size)
            .map(|i| {
                let (x, y) = ((i % size) as i64, (i / size) as i64);
                let Some(hit) = hits[i as usize] else {
                    return false;
                };
                if hit.normal.dot(-hit.direction) < 0.3 {
                    return false;
                }
                shape == Shape::Ball
                    || [(1, 0), (-1, 0), (0, 1), (0, -1)].iter().all(|&(dx, dy)| {
                        at(x + dx, y + dy).is_some_and(|n| (n.distance - hit.distance).abs() < 0.003)
                    })
            })
            .collect();
        // Scored by the faces the references are of; shaded by the normals the GPU's prepass
        // gives its pixels, the mesh's own interpolated across each triangle.
        let hits = match shape.vertex_normals(&positions, &indices) {
            Some(normals) => interpolated_normals(hits, &positions, &indices, &normals),
            None => hits,
        };
        Self {
            shape,
            size,
            positions,
            indices,
            hits,
            scored,
        }
    }
}

/// Each hit's normal interpolated from `normals` (per vertex) over the triangle of
/// `positions`, `indices` it lies on, facing the camera as the face's did.
fn interpolated_normals(hits: Vec<Option<PixelHit>>, positions: &[Vec3], indices: &[u32], normals: &[Vec3]) -> Vec<Option<PixelHit>> {
    let corners = |t: &[u32]| [0, 1, 2].map(|k| positions[t[k] as usize]);
    hits.into_iter()
        .map(|hit| {
            hit.map(|mut hit| {
                // The triangle the hit lies on: the nearest in its plane of those containing it.
                let found = indices
                    .chunks_exact(3)
                    .filter_map(|t| {
                        let [a, b, c] = corners(t);
                        let n = (b - a).cross(c - a);
                        let area2 = n.length_squared();
                        if !(area2 > 0.0) {
                            return None;
                        }
                        let off = (hit.point - a).dot(n).abs() / area2.sqrt();
                        let w = [(c - b).cross(hit.point - b).dot(n), (a - c).cross(hit.point - c).dot(n)].map(|x| x / area2);
                        let w = [w[0], w[1], 1.0 - w[0] - w[1]];
                        (w.iter().all(|&x| x > -1e-4) && off < 1e-6).then(|| (off, t, w))
                    })
                    .min_by(|a, b| a.0.total_cmp(&b.0));
                if let Some((_, t, w)) = found {
                    let n = (0..3).map(|k| normals[t[k] as usize] * w[k]).sum::<Vec3>().normalize_or_zero();
                    if n != Vec3::ZERO {
                        hit.normal = if n.dot(hit.normal) < 0.0 { -n } else { n };
                    }
                }
                hit
            })
        })
        .collect()
}
