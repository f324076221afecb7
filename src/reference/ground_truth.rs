//! Ground truth for a height field over a plane: ambient occlusion, the visibility of a
//! directional light and the one-bounce light of the directly lit surface, by ray marching the
//! height field itself (no screen space, no apexes).
//! Deterministic; the sample counts are arguments. The accuracy tests and tools compare the
//! screen-space method against these.

use bevy::math::{Vec2, Vec3};

/// A tiling height field `z = h(x, y)` over a plane, in world units.
#[derive(Clone, Debug, PartialEq)]
pub struct HeightField {
    /// Texels along x.
    pub width: u32,
    /// Texels along y.
    pub height: u32,
    /// World size of one texel.
    pub texel_size: f32,
    /// Heights in world units, row-major.
    pub heights: Vec<f32>,
}

impl HeightField {
    /// A height field from height-map values in `[0, 1]` (row-major, `width × height`), scaled by
    /// `k`, spread over a plane `plane_size` world units wide.
    pub fn new(width: u32, height: u32, values: &[f32], plane_size: f32, k: f32) -> Self {
        Self {
            width,
            height,
            texel_size: plane_size / width as f32,
            heights: values.iter().map(|v| v * k).collect(),
        }
    }

    /// Height at texel coordinates `p` (texel centres at `i + 0.5`), bilinear, tiling.
    pub fn sample(&self, p: Vec2) -> f32 {
        let q = p - 0.5;
        let (x0, y0) = (q.x.floor(), q.y.floor());
        let (fx, fy) = (q.x - x0, q.y - y0);
        let at = |x: i64, y: i64| {
            let (w, h) = (self.width as i64, self.height as i64);
            self.heights[(y.rem_euclid(h) * w + x.rem_euclid(w)) as usize]
        };
        let (x0, y0) = (x0 as i64, y0 as i64);
        let top = at(x0, y0) + (at(x0 + 1, y0) - at(x0, y0)) * fx;
        let bottom = at(x0, y0 + 1) + (at(x0 + 1, y0 + 1) - at(x0, y0 + 1)) * fx;
        top + (bottom - top) * fy
    }

    fn max_height(&self) -> f32 {
        self.heights.iter().cloned().fold(f32::MIN, f32::max)
    }

    /// The true surface normal at `p` (central differences), z up.
    pub fn normal(&self, p: Vec2) -> Vec3 {
        let dx = (self.sample(p + Vec2::X) - self.sample(p - Vec2::X)) / (2.0 * self.texel_size);
        let dy = (self.sample(p + Vec2::Y) - self.sample(p - Vec2::Y)) / (2.0 * self.texel_size);
        Vec3::new(-dx, -dy, 1.0).normalize()
    }

    /// Whether the ray from the surface point at `p` along the unit `direction` (world units,
    /// z up) leaves the height field without passing under it. Marches half a texel a step.
    pub fn ray_escapes(&self, p: Vec2, direction: Vec3) -> bool {
        self.ray_hit(p, direction).is_none()
    }

    /// Where the ray from the surface point at `p` along the unit `direction` first passes under
    /// the height field, in texel coordinates (refined by bisection), or `None` if it leaves it.
    /// Rays that go down stop after four tile widths, as hits.
    pub fn ray_hit(&self, p: Vec2, direction: Vec3) -> Option<Vec2> {
        let top = self.max_height();
        let start = Vec3::new(p.x * self.texel_size, p.y * self.texel_size, self.sample(p));
        let step = 0.5 * self.texel_size;
        let below = |q: Vec3| q.z < self.sample(Vec2::new(q.x, q.y) / self.texel_size);
        // Leave the surface by a hair, so that the start point does not occlude itself.
        let mut t = 0.25 * step;
        loop {
            let q = start + direction * t;
            if q.z >= top {
                return None;
            }
            if direction.z <= 0.0 && t > 4.0 * self.texel_size * self.width.max(self.height) as f32
            {
                return Some(Vec2::new(q.x, q.y) / self.texel_size);
            }
            if below(q) {
                let (mut lo, mut hi) = ((t - step).max(0.0), t);
                for _ in 0..8 {
                    let mid = 0.5 * (lo + hi);
                    if below(start + direction * mid) {
                        hi = mid;
                    } else {
                        lo = mid;
                    }
                }
                let q = start + direction * hi;
                return Some(Vec2::new(q.x, q.y) / self.texel_size);
            }
            t += step;
        }
    }

    /// Cosine-weighted ambient occlusion (1 = open sky) at texel coordinates `p`, about the
    /// true surface normal: what a path tracer computes under a white sky. Stratified over
    /// `rings × sectors` cosine-weighted directions.
    pub fn ambient_occlusion(&self, p: Vec2, rings: u32, sectors: u32) -> f32 {
        let n = self.normal(p);
        let (t, b) = orthonormal_basis(n);
        let mut visible = 0;
        for i in 0..rings {
            for j in 0..sectors {
                // Cosine-weighted: r = sqrt(u) on the unit disk, projected up onto the hemisphere.
                let u = (i as f32 + 0.5) / rings as f32;
                let phi = std::f32::consts::TAU * (j as f32 + 0.5 * (i % 2) as f32 + 0.5)
                    / sectors as f32;
                let r = u.sqrt();
                let local = Vec3::new(r * phi.cos(), r * phi.sin(), (1.0 - u).max(0.0).sqrt());
                let d = (t * local.x + b * local.y + n * local.z).normalize();
                // Directions under the core plane meet the (continuous) surface at once.
                if d.z > 0.0 && self.ray_escapes(p, d) {
                    visible += 1;
                }
            }
        }
        visible as f32 / (rings * sectors) as f32
    }

    /// The horizon elevation (radians, ≥ 0, from the core plane) at `p` towards the unit
    /// texel-space direction `dir`, searched up to `max_distance` texels in half-texel steps.
    pub fn horizon(&self, p: Vec2, dir: Vec2, max_distance: f32) -> f32 {
        let h0 = self.sample(p);
        let mut best = 0.0f32;
        let mut s = 0.5;
        while s <= max_distance {
            let rise = self.sample(p + dir * s) - h0;
            best = best.max(rise.atan2(s * self.texel_size));
            s += 0.5;
        }
        best
    }

    /// The method's own model with exact horizons: `1/(2π) ∫ cos² h(θ) dθ` over `azimuths`
    /// directions, elevations from the core plane (cosine-weighted form of paper eq. 3–6).
    pub fn horizon_ambient_occlusion(&self, p: Vec2, azimuths: u32, max_distance: f32) -> f32 {
        (0..azimuths)
            .map(|i| {
                let a = std::f32::consts::TAU * (i as f32 + 0.5) / azimuths as f32;
                self.horizon(p, Vec2::new(a.cos(), a.sin()), max_distance)
                    .cos()
                    .powi(2)
            })
            .sum::<f32>()
            / azimuths as f32
    }

    /// Whether a directional light travelling along `light_direction` (world, z up; pointing
    /// down for a light above) reaches the surface point at `p`.
    pub fn light_visible(&self, p: Vec2, light_direction: Vec3) -> bool {
        let to_light = -light_direction.normalize();
        to_light.z > 0.0 && self.normal(p).dot(to_light) > 0.0 && self.ray_escapes(p, to_light)
    }
}

impl HeightField {
    /// One-bounce irradiance at texel coordinates `p` from the surface lit directly by a
    /// directional light travelling along `light_direction`, relative to E0, the irradiance of a
    /// surface facing that light; all surfaces white and Lambertian. Each surface point S sends
    /// radiance `E0 / π · max(0, N_S · l) · V(S, l)`, so `E1 / E0 = mean over cosine-weighted
    /// directions of max(0, N_S · l) · V(S, l)` for the rays that hit S (those that escape see
    /// the sky, which is not this term). The outgoing one-bounce radiance of P is
    /// `ρ_P / π · E0 · one_bounce`. Stratified over `rings × sectors` directions.
    pub fn one_bounce(&self, p: Vec2, light_direction: Vec3, rings: u32, sectors: u32) -> f32 {
        let to_light = -light_direction.normalize();
        let n = self.normal(p);
        let (t, b) = orthonormal_basis(n);
        let mut sum = 0.0;
        for i in 0..rings {
            for j in 0..sectors {
                let u = (i as f32 + 0.5) / rings as f32;
                let phi = std::f32::consts::TAU * (j as f32 + 0.5 * (i % 2) as f32 + 0.5)
                    / sectors as f32;
                let r = u.sqrt();
                let local = Vec3::new(r * phi.cos(), r * phi.sin(), (1.0 - u).max(0.0).sqrt());
                let d = (t * local.x + b * local.y + n * local.z).normalize();
                let Some(s) = self.ray_hit(p, d) else {
                    continue;
                };
                let n_s = self.normal(s);
                // S faces P and is lit.
                if n_s.dot(-d) > 0.0 && to_light.z > 0.0 {
                    let cos_l = n_s.dot(to_light);
                    if cos_l > 0.0 && self.ray_escapes(s, to_light) {
                        sum += cos_l;
                    }
                }
            }
        }
        sum / (rings * sectors) as f32
    }
}

fn orthonormal_basis(n: Vec3) -> (Vec3, Vec3) {
    let t = if n.x.abs() < 0.9 { Vec3::X } else { Vec3::Y };
    let t = (t - n * n.dot(t)).normalize();
    (t, n.cross(t))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v_groove(size: u32, slope_deg: f32) -> HeightField {
        // Ridges at x = 0 and x = size, bottom at size/2; walls at slope α; 1 world unit per texel.
        let t = slope_deg.to_radians().tan();
        let values: Vec<f32> = (0..size * size)
            .map(|i| {
                let x = (i % size) as f32 + 0.5;
                (x - size as f32 / 2.0).abs() * t
            })
            .collect();
        HeightField {
            width: size,
            height: size,
            texel_size: 1.0,
            heights: values,
        }
    }

    #[test]
    fn flat_field_is_open_and_lit() {
        let f = HeightField::new(16, 16, &vec![0.5; 256], 1.0, 0.1);
        assert_eq!(f.ambient_occlusion(Vec2::new(8.0, 8.0), 8, 16), 1.0);
        assert_eq!(
            f.horizon_ambient_occlusion(Vec2::new(8.0, 8.0), 16, 8.0),
            1.0
        );
        assert!(f.light_visible(Vec2::new(3.0, 3.0), Vec3::new(0.3, 0.2, -1.0)));
    }

    #[test]
    fn v_groove_bottom_matches_the_closed_form() {
        // At the bottom of a V-groove with walls at slope α, h(θ) = atan(tan α |cos θ|) and
        // 1/(2π) ∫ cos² h dθ = 1/sqrt(1 + tan² α) = cos α.
        for slope in [20.0f32, 35.0, 50.0] {
            let f = v_groove(64, slope);
            let p = Vec2::new(32.0, 32.0);
            let model = f.horizon_ambient_occlusion(p, 256, 40.0);
            assert!(
                (model - slope.to_radians().cos()).abs() < 0.01,
                "slope {slope}: {model}"
            );
            // The path-traced AO about the true normal (the bottom is a crease: n = up).
            let traced = f.ambient_occlusion(p, 24, 48);
            assert!(
                (traced - slope.to_radians().cos()).abs() < 0.03,
                "slope {slope}: traced {traced}"
            );
        }
    }

    #[test]
    fn one_bounce_at_the_bottom_of_a_v_groove_matches_the_closed_form() {
        // Light from straight above: both walls (slope α) send E0 cos α / π; they fill the
        // directions under the horizon h(θ) = atan(tan α |cos θ|), whose cosine-weighted
        // solid angle is π (1 − cos α) (the AO closed form): E1 / E0 = cos α (1 − cos α).
        for slope in [30.0f32, 45.0] {
            let f = v_groove(64, slope);
            let c = slope.to_radians().cos();
            let bounce = f.one_bounce(Vec2::new(32.0, 32.0), Vec3::NEG_Z, 24, 48);
            assert!(
                (bounce - c * (1.0 - c)).abs() < 0.02,
                "slope {slope}: {bounce} vs {}",
                c * (1.0 - c)
            );
        }
        // A flat field has no bounce.
        let flat = HeightField::new(16, 16, &vec![0.5; 256], 1.0, 0.1);
        assert_eq!(flat.one_bounce(Vec2::new(8.0, 8.0), Vec3::NEG_Z, 4, 8), 0.0);
    }

    #[test]
    fn light_under_the_wall_is_shadowed() {
        let f = v_groove(64, 45.0);
        let p = Vec2::new(34.0, 32.0); // just right of the bottom, the left wall rises at 45°
        // A light low from the left (travelling towards +x, 20° elevation): blocked.
        let low = Vec3::new(1.0, 0.0, -(20f32.to_radians().tan()));
        assert!(!f.light_visible(p, low));
        // From straight above: lit.
        assert!(f.light_visible(p, Vec3::NEG_Z));
    }
}
