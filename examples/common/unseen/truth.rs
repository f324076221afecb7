//! The ground truth of the unseen-content suite: a ray caster on the displaced core mesh (AO,
//! light visibility, one bounce at each scored pixel's UV).

use super::*;

pub(crate) fn a(v: Vec3) -> Vec3A {
    Vec3A::new(v.x, v.y, v.z)
}

/// A ray direction with no zero component: the BVH's traversal misses everything along an
/// exact axis whose other components are ±0 (seen with (−0, −1, −0)).
pub(crate) fn direction(d: Vec3) -> Vec3A {
    let nudge = |c: f32| if c.abs() < 1e-9 { 1e-9 } else { c };
    Vec3A::new(nudge(d.x), nudge(d.y), nudge(d.z))
}

pub(crate) fn b(v: Vec3A) -> Vec3 {
    Vec3::new(v.x, v.y, v.z)
}

/// A triangle mesh in a BVH.
pub(crate) struct Traced {
    pub(crate) bvh: CwBvh,
    pub(crate) triangles: Vec<Triangle>,
}

impl Traced {
    fn new(triangles: Vec<Triangle>) -> Self {
        let mut time = std::time::Duration::ZERO;
        let bvh = build_cwbvh_from_tris(&triangles, BvhBuildParams::fast_build(), &mut time);
        Self { bvh, triangles }
    }

    /// The nearest hit: (triangle index, distance).
    fn hit(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<(usize, f32)> {
        let ray = Ray::new(a(origin), direction(dir), 0.0, t_max);
        let mut hit = RayHit::none();
        self.bvh
            .ray_traverse(ray, &mut hit, |r, id| {
                self.triangles[self.bvh.primitive_indices[id] as usize].intersect(r)
            })
            .then(|| (self.bvh.primitive_indices[hit.primitive_id as usize] as usize, hit.t))
    }

    /// Whether anything lies along the ray.
    fn blocked(&self, origin: Vec3, dir: Vec3) -> bool {
        let ray = Ray::new(a(origin), direction(dir), 0.0, f32::INFINITY);
        !self.bvh.ray_traverse_miss(ray, |r, id| {
            self.triangles[self.bvh.primitive_indices[id] as usize].intersect(r)
        })
    }

    fn normal(&self, triangle: usize) -> Vec3 {
        b(self.triangles[triangle].compute_normal())
    }
}

/// A vertex of the core mesh, as the plugin sees it.
#[derive(Clone, Copy)]
pub(crate) struct Vertex {
    pub(crate) position: Vec3,
    pub(crate) normal: Vec3,
    pub(crate) uv: Vec2,
}

impl Vertex {
    fn blend(v: [Vertex; 3], w: [f32; 3]) -> Vertex {
        Vertex {
            position: v[0].position * w[0] + v[1].position * w[1] + v[2].position * w[2],
            normal: (v[0].normal * w[0] + v[1].normal * w[1] + v[2].normal * w[2]).normalize(),
            uv: v[0].uv * w[0] + v[1].uv * w[1] + v[2].uv * w[2],
        }
    }
}

pub(crate) fn core_triangles(mesh: &Mesh) -> Vec<[Vertex; 3]> {
    let Some(VertexAttributeValues::Float32x3(p)) = mesh.attribute(Mesh::ATTRIBUTE_POSITION) else {
        panic!("core mesh without positions")
    };
    let Some(VertexAttributeValues::Float32x3(n)) = mesh.attribute(Mesh::ATTRIBUTE_NORMAL) else {
        panic!("core mesh without normals")
    };
    let Some(VertexAttributeValues::Float32x2(t)) = mesh.attribute(Mesh::ATTRIBUTE_UV_0) else {
        panic!("core mesh without UVs")
    };
    let vertex = |i: usize| Vertex {
        position: Vec3::from(p[i]),
        normal: Vec3::from(n[i]),
        uv: Vec2::from(t[i]),
    };
    let indices: Vec<usize> = match mesh.indices() {
        Some(Indices::U16(i)) => i.iter().map(|&i| i as usize).collect(),
        Some(Indices::U32(i)) => i.iter().map(|&i| i as usize).collect(),
        None => (0..p.len()).collect(),
    };
    indices
        .chunks_exact(3)
        .map(|c| [vertex(c[0]), vertex(c[1]), vertex(c[2])])
        .collect()
}

/// A rendered mesh on the CPU: the point, interpolated normal and UV a camera ray meets (the
/// `render` example's `uv` view, and each scored pixel's UV here).
pub struct CoreMesh {
    vertices: Vec<[Vertex; 3]>,
    traced: Traced,
}

impl CoreMesh {
    /// `mesh` needs positions, normals and UVs.
    pub fn new(mesh: &Mesh) -> Self {
        let vertices = core_triangles(mesh);
        let traced = Traced::new(
            vertices
                .iter()
                .map(|t| Triangle {
                    v0: a(t[0].position),
                    v1: a(t[1].position),
                    v2: a(t[2].position),
                })
                .collect(),
        );
        Self { vertices, traced }
    }

    fn vertex_hit(&self, origin: Vec3, direction: Vec3) -> Option<Vertex> {
        let (id, t) = self.traced.hit(origin, direction, f32::INFINITY)?;
        let tri = self.vertices[id];
        let p = origin + direction * t;
        // Barycentric weights of p in the triangle.
        let (e1, e2, d) = (
            tri[1].position - tri[0].position,
            tri[2].position - tri[0].position,
            p - tri[0].position,
        );
        let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
        let (d31, d32) = (d.dot(e1), d.dot(e2));
        let den = d11 * d22 - d12 * d12;
        let w1 = (d22 * d31 - d12 * d32) / den;
        let w2 = (d11 * d32 - d12 * d31) / den;
        Some(Vertex::blend(tri, [1.0 - w1 - w2, w1, w2]))
    }

    /// Where the ray first meets the mesh: position, interpolated normal, UV.
    pub fn hit(&self, origin: Vec3, direction: Vec3) -> Option<(Vec3, Vec3, Vec2)> {
        self.vertex_hit(origin, direction)
            .map(|v| (v.position, v.normal, v.uv))
    }
}

/// Displaced-mesh vertices per height-map texel along each axis.
pub(crate) const SUBDIVISION: f32 = 2.0;

/// The ground truth of one scene: the core mesh (to find each pixel's UV) and the displaced
/// mesh (to ray-cast), both in BVHs.
pub struct GroundTruth {
    core: CoreMesh,
    displaced: Traced,
    map: HeightMap,
    scale: f32,
    tiles: Vec2,
    /// Ray offset off a surface (world units): a tenth of a texel on the plane.
    epsilon: f32,
}

/// What the ground truth says at one pixel.
#[derive(Clone, Copy, Debug, Default)]
pub struct Truth {
    /// The pixel's UV on the core (before the tiling).
    pub uv: Vec2,
    pub ao: f32,
    /// The light reaches the surface point.
    pub lit: bool,
    /// The true normal faces the light (N·l > 0.05).
    pub facing: bool,
    /// The core alone would shadow this point (Bevy's shadow maps' job).
    pub core_shadowed: bool,
    /// One-bounce irradiance relative to E0.
    pub bounce: f32,
}

impl GroundTruth {
    /// Builds both BVHs (a few seconds for the largest scenes).
    pub fn new(core: Core, map: HeightMap, scale: f32, tiles: Vec2) -> Self {
        let core = CoreMesh::new(&core.mesh());
        let texel = Vec2::new(map.width as f32, map.height as f32) * tiles;
        // Bilinear, wrapped heights in [0, 1] at texel coordinates (texel centres at i + ½, as
        // the GPU samples): the crate's height field at unit scale.
        let heights = HeightField::new(map.width, map.height, &map.values, 1.0, 1.0);
        let map_size = Vec2::new(map.width as f32, map.height as f32);
        let mut displaced = vec![];
        for tri in &core.vertices {
            // Subdivide so that each small triangle spans at most half a texel: with vertices a
            // texel apart the mesh would pass through texel corners, the box-filtered heights,
            // and be smoother (lower horizons) than the bilinear surface the map stands for.
            let extent = [(0, 1), (1, 2), (2, 0)]
                .iter()
                .map(|&(i, j)| ((tri[i].uv - tri[j].uv) * texel).abs().max_element())
                .fold(1.0f32, f32::max);
            let n = (SUBDIVISION * extent).ceil() as usize;
            let lifted = |i: usize, j: usize| {
                let (wi, wj) = (i as f32 / n as f32, j as f32 / n as f32);
                let v = Vertex::blend(*tri, [1.0 - wi - wj, wi, wj]);
                v.position + v.normal * scale * heights.sample(v.uv * tiles * map_size)
            };
            // Rows of vertices, (n + 1)(n + 2) / 2 of them, lifted once each.
            let rows: Vec<Vec<Vec3>> = (0..=n)
                .map(|j| (0..=n - j).map(|i| lifted(i, j)).collect())
                .collect();
            for j in 0..n {
                for i in 0..n - j {
                    displaced.push(Triangle {
                        v0: a(rows[j][i]),
                        v1: a(rows[j][i + 1]),
                        v2: a(rows[j + 1][i]),
                    });
                    if i + 1 < n - j {
                        displaced.push(Triangle {
                            v0: a(rows[j][i + 1]),
                            v1: a(rows[j + 1][i + 1]),
                            v2: a(rows[j + 1][i]),
                        });
                    }
                }
            }
        }
        let epsilon = 0.05 * 2.0 / texel.max_element().max(1.0);
        Self {
            core,
            displaced: Traced::new(displaced),
            map,
            scale,
            tiles,
            epsilon,
        }
    }

    /// Triangles in the displaced mesh.
    pub fn triangle_count(&self) -> usize {
        self.displaced.triangles.len()
    }

    /// The core point seen along a camera ray: position, interpolated normal, UV.
    pub(crate) fn core_hit(&self, origin: Vec3, direction: Vec3) -> Option<Vertex> {
        self.core.vertex_hit(origin, direction)
    }

    /// The core normal where the ray from `eye` towards `target` meets the core.
    pub fn normal_towards(&self, eye: Vec3, target: Vec3) -> Vec3 {
        self.core_hit(eye, (target - eye).normalize())
            .map_or(Vec3::Y, |v| v.normal)
    }

    /// The ground truth for the camera ray `origin + t · direction`; `None` where it misses the
    /// core. `to_light`: unit vector towards the directional light.
    pub fn at(&self, origin: Vec3, direction: Vec3, to_light: Vec3, rings: u32, sectors: u32) -> Option<Truth> {
        let core = self.core_hit(origin, direction)?;
        // The displaced point above the core point (along the displacement direction).
        let above = core.position + core.normal * (self.scale * 1.5 + self.epsilon);
        let (id, t) = self
            .displaced
            .hit(above, -core.normal, self.scale * 3.0 + 4.0 * self.epsilon)?;
        let p = above - core.normal * t;
        let mut n = self.displaced.normal(id);
        if n.dot(core.normal) < 0.0 {
            n = -n;
        }
        let origin = p + n * self.epsilon;
        let lit = !self.displaced.blocked(origin, to_light);
        let core_shadowed = self
            .core
            .traced
            .blocked(core.position + core.normal * self.epsilon, to_light);
        // Cosine-weighted stratified directions about n, rotated per pixel.
        let (t1, t2) = n.any_orthonormal_pair();
        let rotation = (core.uv.x * 12.9898 + core.uv.y * 78.233).sin().fract().abs();
        let (mut open, mut bounce) = (0.0, 0.0);
        for r in 0..rings {
            for s in 0..sectors {
                let u1 = (r as f32 + 0.5) / rings as f32;
                let phi = std::f32::consts::TAU * ((s as f32 + 0.5) / sectors as f32 + rotation);
                let (sin_t, cos_t) = (u1.sqrt(), (1.0 - u1).sqrt());
                let d = (t1 * phi.cos() + t2 * phi.sin()) * sin_t + n * cos_t;
                match self.displaced.hit(origin, d, f32::INFINITY) {
                    None => open += 1.0,
                    Some((hit, t)) => {
                        let mut ns = self.displaced.normal(hit);
                        if ns.dot(d) > 0.0 {
                            ns = -ns;
                        }
                        let cos_l = ns.dot(to_light);
                        if cos_l > 0.0 {
                            let s = origin + d * t + ns * self.epsilon;
                            if !self.displaced.blocked(s, to_light) {
                                bounce += cos_l;
                            }
                        }
                    }
                }
            }
        }
        let count = (rings * sectors) as f32;
        Some(Truth {
            uv: core.uv,
            ao: open / count,
            lit,
            facing: n.dot(to_light) > 0.05,
            core_shadowed,
            bounce: bounce / count,
        })
    }

    /// Height-map texels per pixel around `(x, y)`: the UV step to the next pixel, in texels.
    pub fn texels_per_pixel(&self, a: Vec2, b: Vec2) -> f32 {
        ((a - b) * self.tiles * Vec2::new(self.map.width as f32, self.map.height as f32)).length()
    }
}
