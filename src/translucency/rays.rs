//! Visibility between points of the scene: its triangles in a BVH (`obvhs`'s compressed wide
//! BVH), for the form factors' rays, the lights' shadow rays and the random walks.

use bevy::prelude::*;
use obvhs::{
    BvhBuildParams,
    cwbvh::{CwBvh, builder::build_cwbvh_from_tris},
    ray::{Ray, RayHit},
    triangle::Triangle,
};
use obvhs_glam::Vec3A;

use super::patches::PatchObject;

/// Visibility between points: the scene's triangles in a BVH.
#[derive(Clone)]
pub struct SceneRays {
    bvh: CwBvh,
    triangles: Vec<Triangle>,
    /// How far every query starts its BVH ray behind its origin (hits behind the origin left
    /// out): 1e-4 of the scene's bounding diagonal, and never under [`MIN_BACK_OFF`].
    back_off: f32,
}

/// The least [`SceneRays::back_off`], in world units. `obvhs`'s compressed wide BVH clamps
/// the distance at which a ray enters each box to at least 1e-4 world units
/// (`cwbvh::node::EPSILON`, an absolute figure), so a ray shorter than that meets nothing,
/// and a box it leaves within that distance of its start is skipped. In a scene in metres
/// that is 0.1 mm: in a scene under ~1 unit across (whose back-off of 1e-4 of its diagonal
/// fell short of the clamp), a random walk's free flight that short (a fifth of marble's
/// flights) went through the object's surface unseen, scattered on outside and came back as
/// late light or as an exit elsewhere. Starting every ray twice that far back keeps all it
/// is asked about past the clamp.
pub const MIN_BACK_OFF: f32 = 2e-4;

fn to_a(v: Vec3) -> Vec3A {
    Vec3A::new(v.x, v.y, v.z)
}

/// The BVH's ray from `origin` along `direction` over `[0, t_max]`.
fn ray(origin: Vec3, direction: Vec3, t_max: f32) -> Ray {
    // A zero component makes the traversal miss everything along the ray.
    let nudge = |c: f32| if c.abs() < 1e-9 { 1e-9 } else { c };
    let d = Vec3A::new(nudge(direction.x), nudge(direction.y), nudge(direction.z));
    Ray::new(to_a(origin), d, 0.0, t_max)
}

impl SceneRays {
    /// All objects' valid triangles.
    pub fn new(objects: &[PatchObject]) -> Self {
        let triangles: Vec<Triangle> = objects
            .iter()
            .flat_map(|o| {
                o.indices.chunks_exact(3).filter_map(|t| {
                    let v = |k: usize| o.positions.get(t[k] as usize).copied();
                    let (a, b, c) = (v(0)?, v(1)?, v(2)?);
                    (a.is_finite() && b.is_finite() && c.is_finite()).then(|| Triangle {
                        v0: to_a(a),
                        v1: to_a(b),
                        v2: to_a(c),
                    })
                })
            })
            .collect();
        let mut time = std::time::Duration::ZERO;
        let bvh = build_cwbvh_from_tris(&triangles, BvhBuildParams::fast_build(), &mut time);
        let (low, high) = triangles.iter().fold(
            (Vec3A::splat(f32::INFINITY), Vec3A::splat(f32::NEG_INFINITY)),
            |(low, high), t| {
                (low.min(t.v0.min(t.v1.min(t.v2))), high.max(t.v0.max(t.v1.max(t.v2))))
            },
        );
        let diagonal = (high - low).length();
        let back_off = if diagonal.is_finite() { (1e-4 * diagonal).max(MIN_BACK_OFF) } else { MIN_BACK_OFF };
        Self { bvh, triangles, back_off }
    }

    /// Whether the ray from `origin` along the unit `direction` is free over `[0, t_max]`.
    pub(super) fn free(&self, origin: Vec3, direction: Vec3, t_max: f32) -> bool {
        if self.triangles.is_empty() {
            return true;
        }
        let ray = self.backed_off(origin, direction, t_max);
        self.bvh.ray_traverse_miss(ray, |r, id| {
            self.triangles[self.bvh.primitive_indices[id] as usize].intersect(r)
        })
    }

    /// The nearest triangle along the unit `direction` from `origin`: its distance and unit
    /// normal (either side); `None` where the ray leaves the scene.
    pub fn first_hit(&self, origin: Vec3, direction: Vec3) -> Option<(f32, Vec3)> {
        if self.triangles.is_empty() {
            return None;
        }
        self.nearest(self.backed_off(origin, direction, f32::INFINITY))
    }

    /// [`first_hit`](Self::first_hit) over `[0, t_max]` only: `None` where nothing is that
    /// close (the traversal prunes everything further, which a random walk's short free
    /// flights make cheap). Like every query its ray starts [`back_off`](Self::back_off)
    /// behind `origin`: from a start within ~1e-4 world units of a face the BVH misses that
    /// face (a ray started at the origin from 1e-6 / 1e-5 / 1e-4 under a face of a 2-unit
    /// cube missed it 2000 / 1908 / 0 times in 2000), and a flight shorter than that meets
    /// nothing at all ([`MIN_BACK_OFF`]).
    pub fn first_hit_within(
        &self,
        origin: Vec3,
        direction: Vec3,
        t_max: f32,
    ) -> Option<(f32, Vec3)> {
        if self.triangles.is_empty() {
            return None;
        }
        self.nearest(self.backed_off(origin, direction, t_max))
    }

    /// The BVH's ray for `[0, t_max]` from `origin` along the unit `direction`: started
    /// [`back_off`](Self::back_off) behind `origin`, with hits behind `origin` left out (what
    /// [`nearest`](Self::nearest) takes off again).
    fn backed_off(&self, origin: Vec3, direction: Vec3, t_max: f32) -> Ray {
        let back = self.back_off;
        let mut ray = ray(origin - direction * back, direction, t_max + back);
        ray.tmin = back;
        ray
    }

    /// The nearest triangle along a [`backed_off`](Self::backed_off) ray: its distance from
    /// the query's origin (the ray's less the back-off) and unit normal (either side).
    fn nearest(&self, ray: Ray) -> Option<(f32, Vec3)> {
        let mut hit = RayHit::none();
        let found = self.bvh.ray_traverse(ray, &mut hit, |r, id| {
            self.triangles[self.bvh.primitive_indices[id] as usize].intersect(r)
        });
        found.then(|| {
            let t = &self.triangles[self.bvh.primitive_indices[hit.primitive_id as usize] as usize];
            let n = (t.v1 - t.v0).cross(t.v2 - t.v0).normalize_or_zero();
            (hit.t - self.back_off, Vec3::new(n.x, n.y, n.z))
        })
    }

    /// Whether `b` is visible from `a`.
    pub fn visible(&self, a: Vec3, b: Vec3) -> bool {
        let d = b - a;
        let length = d.length();
        length > 0.0 && self.free(a, d / length, length * (1.0 - 1e-4))
    }
}
