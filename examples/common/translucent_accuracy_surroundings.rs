//! What the accuracy scene can put beside its object: a floor that bounces the light
//! (`--floor`) and a plate that shades half of it (`--occluder`), for the plugin's patches
//! and the reference's Mitsuba scene alike.

use bevy::prelude::*;

/// The box about `positions`: its least and greatest corners.
fn bounds(positions: &[Vec3]) -> (Vec3, Vec3) {
    positions
        .iter()
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &p| (lo.min(p), hi.max(p)))
}

/// A square floor under an object (`--floor`): level, [`Floor::GAP`] below the object's
/// lowest point, centred under its box, twice its widest extent across.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Floor {
    /// Its centre (world units).
    pub centre: Vec3,
    /// Half its side.
    pub half: f32,
}

impl Floor {
    /// Between the object's lowest point and the floor: 2 mm, more than the gather's reach
    /// from a patch of the object, so that no pixel of the object takes the floor's light.
    pub const GAP: f32 = 0.002;

    /// The floor under the object of `positions`.
    pub fn under(positions: &[Vec3]) -> Self {
        let (lo, hi) = bounds(positions);
        let mid = (lo + hi) / 2.0;
        Self {
            centre: Vec3::new(mid.x, lo.y - Self::GAP, mid.z),
            half: (hi - lo).max_element(),
        }
    }

    /// Its two triangles, facing up.
    pub fn triangles(&self) -> (Vec<Vec3>, Vec<u32>) {
        let h = self.half;
        let corners = [(-h, -h), (h, -h), (h, h), (-h, h)];
        let positions = corners.iter().map(|&(x, z)| self.centre + Vec3::new(x, 0.0, z)).collect();
        (positions, vec![0, 2, 1, 0, 3, 2])
    }
}

/// A black square plate between a directional light and an object (`--occluder`), facing
/// the light, twice the object's bounding radius from its centre, one edge on the light's
/// line through that centre: the object's upper half (across the light) lies in its shadow,
/// and the shadow's edge crosses the object's middle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Occluder {
    /// Its centre (world units).
    pub centre: Vec3,
    /// Its half-axes: `u × v` faces the light.
    pub u: Vec3,
    pub v: Vec3,
}

impl Occluder {
    /// The plate shading the upper half of the object of `positions` from a light travelling
    /// along `travel`.
    pub fn shading(positions: &[Vec3], travel: Vec3) -> Self {
        let (lo, hi) = bounds(positions);
        let centre = (lo + hi) / 2.0;
        let radius = positions.iter().map(|p| p.distance(centre)).fold(0.0, f32::max);
        let t = travel.normalize();
        // Up across the light (x where the light falls straight down).
        let up = (Vec3::Y - t * t.y).try_normalize().unwrap_or(Vec3::X);
        let half = 2.0 * radius;
        Self {
            centre: centre - t * (2.0 * radius) + up * half,
            u: up.cross(-t) * half,
            v: up * half,
        }
    }

    /// Its two triangles, facing the light.
    pub fn triangles(&self) -> (Vec<Vec3>, Vec<u32>) {
        let (c, u, v) = (self.centre, self.u, self.v);
        (vec![c - u - v, c + u - v, c + u + v, c - u + v], vec![0, 1, 2, 0, 2, 3])
    }

    /// Where the ray from `origin` along the unit `direction` meets it, if it does.
    pub fn hit(&self, origin: Vec3, direction: Vec3) -> Option<f32> {
        let n = self.u.cross(self.v);
        let facing = n.dot(direction);
        if facing.abs() < 1e-12 {
            return None;
        }
        let t = n.dot(self.centre - origin) / facing;
        let d = origin + direction * t - self.centre;
        (t > 0.0 && d.dot(self.u).abs() <= self.u.length_squared() && d.dot(self.v).abs() <= self.v.length_squared())
            .then_some(t)
    }
}
