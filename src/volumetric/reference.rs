//! Exact single scattering of a spot light in a homogeneous medium along one view ray, the
//! reference the volumetric passes are measured against; and the estimators the passes use.
//!
//! Along a ray `x(t) = o + t·d`, `t ∈ [t_a, t_b]` (the camera to the depth buffer), the
//! in-scattered radiance of one spot light at `p` is
//!
//! `L = ∫ σs · I · F(x) · W(|x − p|) · V(x) · ρ(cos θ) · e^(−σt (t + |x − p|)) / |x − p|² dt`
//!
//! with `I` the intensity (luminous intensity for Bevy's lights: Φ / 4π), `F` Bevy's angular
//! fall-off `saturate(cos ψ · s + o)²` about the spot axis, `W` Bevy's range window
//! `saturate(1 − (d²/R²)²)²`, `V` the visibility of the light from `x`, `ρ` the Henyey–Greenstein
//! phase function of the angle between the light's travel and the ray's way back to the
//! camera. Seed 004's equal angles are the change of variable `t = t_c + h tan γ` (`t_c`: the
//! ray's point closest to the light, `h`: its distance), for which `dt / |x − p|² = dγ / h`:
//!
//! `L = σs · I / h · ∫ F · W · V · ρ · e^(−σt (t_c + h tan γ + h sec γ)) dγ`,
//!
//! smooth and bounded between the break points where `F`, `W` or `V` change form — the inner
//! and outer cone, the range sphere, the shadow boundaries. [`in_scattered`] integrates each
//! piece with 64-point Gauss–Legendre in `f64`. With `g = 0`, no extinction, no shadow and the
//! whole segment inside the inner cone and the range, it is the closed form
//! `σs · I · (γ_b − γ_a) / (4π h)` ([`closed_form_unshadowed`]).

use bevy::math::DVec3;
use std::f64::consts::PI;

/// A spot light as Bevy lights it.
#[derive(Clone, Copy, Debug)]
pub struct SpotLight {
    /// Position.
    pub position: DVec3,
    /// Unit axis of the cone (where the light points).
    pub direction: DVec3,
    /// Intensity on the axis (candela for Bevy's lights: lumens / 4π), before fall-off.
    pub intensity: f64,
    /// Half-angle of the cone's full-intensity core, radians.
    pub inner_angle: f64,
    /// Half-angle of the cone's edge, radians (0 < inner ≤ outer < π/2).
    pub outer_angle: f64,
    /// Range `R` of Bevy's window `saturate(1 − (d²/R²)²)²`.
    pub range: f64,
}

impl SpotLight {
    /// Bevy's angular fall-off `saturate(cos ψ · scale + offset)²` at `x`, with
    /// `scale = 1 / max(cos inner − cos outer, 1e-4)`, `offset = −cos outer · scale`.
    pub fn falloff(&self, x: DVec3) -> f64 {
        let to_x = (x - self.position).normalize_or_zero();
        let cos_psi = to_x.dot(self.direction);
        let cos_outer = self.outer_angle.cos();
        let scale = 1.0 / (self.inner_angle.cos() - cos_outer).max(1e-4);
        let a = (cos_psi * scale - cos_outer * scale).clamp(0.0, 1.0);
        a * a
    }

    /// Bevy's range window at distance `d`.
    pub fn range_window(&self, d: f64) -> f64 {
        let f = d * d / (self.range * self.range);
        let s = (1.0 - f * f).clamp(0.0, 1.0);
        s * s
    }
}

/// A homogeneous medium.
#[derive(Clone, Copy, Debug)]
pub struct Medium {
    /// Scattering coefficient σs, per world unit.
    pub scattering: f64,
    /// Absorption coefficient σa, per world unit.
    pub absorption: f64,
    /// Henyey–Greenstein asymmetry g ∈ (−1, 1).
    pub asymmetry: f64,
}

impl Medium {
    /// Extinction σt = σs + σa.
    pub fn extinction(&self) -> f64 {
        self.scattering + self.absorption
    }

    /// The Henyey–Greenstein phase function (1/sr) of the cosine between the light's direction
    /// of travel and the scattered light's.
    pub fn phase(&self, cos_theta: f64) -> f64 {
        let g = self.asymmetry;
        (1.0 - g * g) / (4.0 * PI * (1.0 + g * g - 2.0 * g * cos_theta).powf(1.5))
    }
}

/// An axis-aligned box that blocks the light (an occluder casting a shaft).
#[derive(Clone, Copy, Debug)]
pub struct Occluder {
    /// Lowest corner.
    pub min: DVec3,
    /// Highest corner.
    pub max: DVec3,
}

impl Occluder {
    /// Whether the open segment from `a` to `b` passes through the box (slab test).
    pub fn blocks(&self, a: DVec3, b: DVec3) -> bool {
        let d = b - a;
        let (mut near, mut far) = (0.0f64, 1.0f64);
        for axis in 0..3 {
            let (o, v, lo, hi) = (a[axis], d[axis], self.min[axis], self.max[axis]);
            if v.abs() < 1e-300 {
                if o < lo || o > hi {
                    return false;
                }
                continue;
            }
            let (t0, t1) = ((lo - o) / v, (hi - o) / v);
            near = near.max(t0.min(t1));
            far = far.min(t0.max(t1));
            if near > far {
                return false;
            }
        }
        near < 1.0 && far > 0.0
    }
}

/// A view ray from `origin` along the unit `direction`, over `t ∈ [start, end]` (`end`: the
/// depth buffer's distance, or the far end of the medium).
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    /// Origin (the camera).
    pub origin: DVec3,
    /// Unit direction.
    pub direction: DVec3,
    /// Where the medium starts along the ray.
    pub start: f64,
    /// Where the ray stops (a surface, or the end of the medium).
    pub end: f64,
}

/// The ray in the equal-angle variable of one light: `t = t_c + h tan γ`.
#[derive(Clone, Copy, Debug)]
pub struct EqualAngle {
    /// Parameter of the ray's point closest to the light.
    pub t_closest: f64,
    /// Distance of the light from the ray's line.
    pub h: f64,
}

impl EqualAngle {
    /// The change of variable for `ray` and a light at `p`.
    pub fn of(ray: &Ray, p: DVec3) -> Self {
        let t_closest = (p - ray.origin).dot(ray.direction);
        let h = (p - ray.origin - ray.direction * t_closest).length();
        Self { t_closest, h }
    }

    /// γ of the ray parameter `t`.
    pub fn angle(&self, t: f64) -> f64 {
        ((t - self.t_closest) / self.h).atan()
    }

    /// The ray parameter of γ.
    pub fn t(&self, gamma: f64) -> f64 {
        self.t_closest + self.h * gamma.tan()
    }
}

/// The integrand in γ (without the constant σs · I / h): `F · W · V · ρ · e^(−σt (t + |x − p|))`.
fn integrand_in_angle(
    ray: &Ray,
    light: &SpotLight,
    medium: &Medium,
    occluders: &[Occluder],
    ea: &EqualAngle,
    gamma: f64,
) -> f64 {
    let t = ea.t(gamma);
    let x = ray.origin + ray.direction * t;
    let to_x = x - light.position;
    let d = to_x.length();
    let f = light.falloff(x) * light.range_window(d);
    if f == 0.0 || occluders.iter().any(|o| o.blocks(light.position, x)) {
        return 0.0;
    }
    // The light travels along to_x / d and is scattered back towards the camera (−direction).
    let cos_theta = -(to_x / d).dot(ray.direction);
    f * medium.phase(cos_theta) * (-medium.extinction() * (t + d)).exp()
}

/// Ray parameters in `(a, b)` where the ray crosses the cone of half-angle `angle` about the
/// light's axis (its forward half), sorted.
fn cone_crossings(ray: &Ray, light: &SpotLight, angle: f64, (a, b): (f64, f64)) -> Vec<f64> {
    // (w·u)² = cos² · |w|² with w = o − p + t d, u the axis: a quadratic in t.
    let c2 = angle.cos().powi(2);
    let u = light.direction;
    let w0 = ray.origin - light.position;
    let (du, wu) = (ray.direction.dot(u), w0.dot(u));
    let qa = du * du - c2;
    let qb = 2.0 * (du * wu - c2 * ray.direction.dot(w0));
    let qc = wu * wu - c2 * w0.length_squared();
    let mut roots = vec![];
    if qa.abs() < 1e-14 {
        if qb.abs() > 1e-14 {
            roots.push(-qc / qb);
        }
    } else {
        let disc = qb * qb - 4.0 * qa * qc;
        if disc >= 0.0 {
            let s = disc.sqrt();
            roots.push((-qb - s) / (2.0 * qa));
            roots.push((-qb + s) / (2.0 * qa));
        }
    }
    let mut out: Vec<f64> = roots
        .into_iter()
        .filter(|&t| t > a && t < b && (ray.origin + ray.direction * t - light.position).dot(u) > 0.0)
        .collect();
    out.sort_by(f64::total_cmp);
    out
}

/// Ray parameters in `(a, b)` where the ray crosses the sphere of radius `r` about `p`.
fn sphere_crossings(ray: &Ray, p: DVec3, r: f64, (a, b): (f64, f64)) -> Vec<f64> {
    let w0 = ray.origin - p;
    let qb = ray.direction.dot(w0);
    let disc = qb * qb - (w0.length_squared() - r * r);
    if disc < 0.0 {
        return vec![];
    }
    let s = disc.sqrt();
    [-qb - s, -qb + s].into_iter().filter(|&t| t > a && t < b).collect()
}

/// 64-point Gauss–Legendre nodes and weights on [−1, 1] (Newton on the Legendre polynomial).
pub(crate) fn gauss_legendre_64() -> &'static [(f64, f64)] {
    static NODES: std::sync::OnceLock<Vec<(f64, f64)>> = std::sync::OnceLock::new();
    NODES.get_or_init(|| {
        let n = 64;
        (0..n)
            .map(|i| {
                let mut x = (PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
                let mut dp = 0.0;
                for _ in 0..100 {
                    let (mut p0, mut p1) = (1.0, x);
                    for k in 2..=n {
                        let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                        p0 = p1;
                        p1 = p2;
                    }
                    dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
                    let dx = p1 / dp;
                    x -= dx;
                    if dx.abs() < 1e-16 {
                        break;
                    }
                }
                (x, 2.0 / ((1.0 - x * x) * dp * dp))
            })
            .collect()
    })
}

/// The exact in-scattered radiance of `light` along `ray` (see the module docs), shadowed by
/// `occluders`: Gauss–Legendre in the equal-angle variable between the break points of the
/// cone, the range sphere and the shadow boundaries (these located by bisection to 1e-13 rad
/// over 512 pieces, enough for shadows wider than 1/512 of the segment's angle).
pub fn in_scattered(ray: &Ray, light: &SpotLight, medium: &Medium, occluders: &[Occluder]) -> f64 {
    if !(ray.end > ray.start) {
        return 0.0;
    }
    let ea = EqualAngle::of(ray, light.position);
    if !(ea.h > 1e-12) {
        // The ray passes through the light: the integral diverges; callers offset such rays.
        return f64::INFINITY;
    }
    let span = (ray.start, ray.end);
    let mut breaks = vec![ray.start, ray.end];
    breaks.extend(cone_crossings(ray, light, light.inner_angle, span));
    breaks.extend(cone_crossings(ray, light, light.outer_angle, span));
    breaks.extend(sphere_crossings(ray, light.position, light.range, span));
    let mut gammas: Vec<f64> = breaks.into_iter().map(|t| ea.angle(t)).collect();
    gammas.sort_by(f64::total_cmp);
    gammas.dedup_by(|a, b| (*a - *b).abs() < 1e-15);
    if !occluders.is_empty() {
        let visible = |g: f64| {
            let x = ray.origin + ray.direction * ea.t(g);
            !occluders.iter().any(|o| o.blocks(light.position, x))
        };
        let (g0, g1) = (gammas[0], *gammas.last().unwrap());
        let pieces = 512;
        let mut extra = vec![];
        for i in 0..pieces {
            let (mut lo, mut hi) = (
                g0 + (g1 - g0) * i as f64 / pieces as f64,
                g0 + (g1 - g0) * (i + 1) as f64 / pieces as f64,
            );
            let v_lo = visible(lo);
            if v_lo == visible(hi) {
                continue;
            }
            while hi - lo > 1e-13 {
                let mid = 0.5 * (lo + hi);
                if visible(mid) == v_lo {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            extra.push(0.5 * (lo + hi));
        }
        gammas.extend(extra);
        gammas.sort_by(f64::total_cmp);
    }
    let nodes = gauss_legendre_64();
    let mut sum = 0.0;
    for w in gammas.windows(2) {
        let (a, b) = (w[0], w[1]);
        let (mid, half) = (0.5 * (a + b), 0.5 * (b - a));
        for &(x, weight) in nodes {
            sum += weight * half * integrand_in_angle(ray, light, medium, occluders, &ea, mid + half * x);
        }
    }
    medium.scattering * light.intensity / ea.h * sum
}

/// The closed form for `g = 0`, no extinction, no shadow, and a segment entirely inside the
/// inner cone and well inside the range: `σs · I · (γ_b − γ_a) / (4π h)`.
pub fn closed_form_unshadowed(ray: &Ray, light: &SpotLight, medium: &Medium) -> f64 {
    let ea = EqualAngle::of(ray, light.position);
    medium.scattering * light.intensity * (ea.angle(ray.end) - ea.angle(ray.start)) / (4.0 * PI * ea.h)
}

/// The part of `ray` inside the light's outer cone and range, where the in-scatter is not 0
/// (the cone is convex for half-angles below 90°, so the part is one interval); `None` where the
/// ray misses it.
pub fn clip_to_light(ray: &Ray, light: &SpotLight) -> Option<(f64, f64)> {
    let span = (ray.start, ray.end);
    let mut cuts = vec![ray.start, ray.end];
    cuts.extend(cone_crossings(ray, light, light.outer_angle, span));
    cuts.extend(sphere_crossings(ray, light.position, light.range, span));
    cuts.sort_by(f64::total_cmp);
    let cos_outer = light.outer_angle.cos();
    let inside = |t: f64| {
        let v = ray.origin + ray.direction * t - light.position;
        v.dot(light.direction) >= cos_outer * v.length() && v.length() < light.range
    };
    let pieces: Vec<(f64, f64)> = cuts
        .windows(2)
        .map(|w| (w[0], w[1]))
        .filter(|&(a, b)| b > a && inside(0.5 * (a + b)))
        .collect();
    Some((pieces.first()?.0, pieces.last()?.1))
}

/// How the estimators place their `n` samples along the segment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Sampling {
    /// Equal steps of γ (seed 004's planes at equal angles around the light, per ray): each
    /// sample stands for `Δγ`, and `dt / |x − p|² = dγ / h` cancels the 1/d² spike near the
    /// light.
    EqualAngle,
    /// Equal steps of depth `t` (a uniform ray march).
    EqualDepth,
    /// Seed 004's sampling planes as it rasterises them: shared by every pixel of a view.
    SlicingPlanes(SlicingPlanes),
}

/// Seed 004's sampling planes for one light in one view (`VolumetricMethod::SlicingPlanes`):
/// planes perpendicular to the view axis `forward` at view depths `z_p + H tan γ_k`, `n` equal
/// steps of γ around the light between the view depths `near` and `far` — `z_p` the light's
/// view depth, `H` its distance from the view axis (at least 1 % of `far − near`, so that a
/// light on the axis does not pile every plane onto its own depth). A ray adds, at each plane
/// it meets in front of its surface, the integrand there times the length of ray the plane
/// stands for (the depth between its neighbours' midpoints in γ, over the ray's cosine to the
/// axis). Mirrors `plane_vertex` and `plane_fragment` in `volumetric/spots.wgsl`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SlicingPlanes {
    /// Unit view axis (the camera's forward).
    pub forward: DVec3,
    /// The planes' span along the view axis: its near end (a view depth).
    pub near: f64,
    /// Its far end.
    pub far: f64,
}

impl SlicingPlanes {
    /// The planes' span for a light whose cone lies in the sphere (`center`, `radius`), seen
    /// from `eye` along `forward` with the camera's near plane at `camera_near`: the sphere's
    /// depths, not nearer than the near plane (as `plane_vertex` places them).
    pub fn around(eye: DVec3, forward: DVec3, center: DVec3, radius: f64, camera_near: f64) -> Self {
        let z = (center - eye).dot(forward);
        Self {
            forward,
            near: (z - radius).max(camera_near),
            far: z + radius,
        }
    }

    /// The planes' span for `light` (its cone's bounding sphere, as the render world bounds
    /// it) seen from `eye` along `forward`, the camera's near plane at `camera_near`.
    pub fn for_light(eye: DVec3, forward: DVec3, light: &SpotLight, camera_near: f64) -> Self {
        let bounds = super::extract::cone_bounds(
            light.position.as_vec3(),
            light.direction.as_vec3(),
            light.outer_angle as f32,
            light.range as f32,
        );
        let center = bevy::math::Vec3::from(bounds.center).as_dvec3();
        Self::around(eye, forward, center, bounds.radius as f64, camera_near)
    }

    /// Plane `k` of `n` for a light at `light` seen from `eye`: its view depth and the view
    /// depth it stands for.
    pub fn plane(&self, eye: DVec3, light: DVec3, k: u32, n: u32) -> (f64, f64) {
        let w = light - eye;
        let z_p = w.dot(self.forward);
        let h = (w - self.forward * z_p).length().max(0.01 * (self.far - self.near));
        let (ga, gb) = (((self.near - z_p) / h).atan(), ((self.far - z_p) / h).atan());
        let step = (gb - ga) / n as f64;
        let depth = |i: f64| z_p + h * (ga + i * step).tan();
        (depth(k as f64 + 0.5), depth(k as f64 + 1.0) - depth(k as f64))
    }
}

/// The `n`-sample midpoint estimate of [`in_scattered`] over the ray clipped to the light's cone
/// and range ([`clip_to_light`]; no other break points, shadows as sampled): what a GPU pass
/// with that sampling computes, for comparing the two samplings with the reference.
pub fn estimate(
    ray: &Ray,
    light: &SpotLight,
    medium: &Medium,
    occluders: &[Occluder],
    sampling: Sampling,
    n: u32,
) -> f64 {
    let ea = EqualAngle::of(ray, light.position);
    if !(ray.end > ray.start) || !(ea.h > 1e-12) || n == 0 {
        return 0.0;
    }
    let Some((start, end)) = clip_to_light(ray, light) else {
        return 0.0;
    };
    let ray = &Ray { start, end, ..*ray };
    let n = n as f64;
    match sampling {
        Sampling::EqualAngle => {
            let (ga, gb) = (ea.angle(ray.start), ea.angle(ray.end));
            let step = (gb - ga) / n;
            let sum: f64 = (0..n as u32)
                .map(|i| integrand_in_angle(ray, light, medium, occluders, &ea, ga + (i as f64 + 0.5) * step))
                .sum();
            medium.scattering * light.intensity / ea.h * sum * step
        }
        Sampling::SlicingPlanes(planes) => {
            // The ray's origin is the camera (`ray.start` where the medium starts).
            let along = ray.direction.dot(planes.forward);
            if along <= 0.0 {
                return 0.0;
            }
            let sum: f64 = (0..n as u32)
                .map(|k| {
                    let (z, dz) = planes.plane(ray.origin, light.position, k, n as u32);
                    let t = z / along;
                    if t <= ray.start || t >= ray.end {
                        return 0.0;
                    }
                    let d2 = (ray.origin + ray.direction * t - light.position).length_squared();
                    integrand_in_angle(ray, light, medium, occluders, &ea, ea.angle(t)) * ea.h / d2
                        * (dz / along)
                })
                .sum();
            medium.scattering * light.intensity / ea.h * sum
        }
        Sampling::EqualDepth => {
            let step = (ray.end - ray.start) / n;
            let sum: f64 = (0..n as u32)
                .map(|i| {
                    let t = ray.start + (i as f64 + 0.5) * step;
                    let d2 = (ray.origin + ray.direction * t - light.position).length_squared();
                    // Back from γ to t: the integrand in γ times dγ/dt = h / |x − p|².
                    integrand_in_angle(ray, light, medium, occluders, &ea, ea.angle(t)) * ea.h / d2
                })
                .sum();
            medium.scattering * light.intensity / ea.h * sum * step
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The reference set-up: a spot at (0, 4, 0) aimed at (0.5, 0, 0), outer 30°,
    /// 20 000 lm (I = Φ / 4π), range 100, σs 0.10, σa 0.01.
    fn setup(inner_deg: f64, g: f64) -> (SpotLight, Medium) {
        let position = DVec3::new(0.0, 4.0, 0.0);
        (
            SpotLight {
                position,
                direction: (DVec3::new(0.5, 0.0, 0.0) - position).normalize(),
                intensity: 20_000.0 / (4.0 * PI),
                inner_angle: inner_deg.to_radians(),
                outer_angle: 30f64.to_radians(),
                range: 100.0,
            },
            Medium {
                scattering: 0.10,
                absorption: 0.01,
                asymmetry: g,
            },
        )
    }

    fn ray_through(from: DVec3, to: DVec3, end: f64) -> Ray {
        Ray {
            origin: from,
            direction: (to - from).normalize(),
            start: 0.0,
            end,
        }
    }

    #[test]
    fn gauss_legendre_integrates_polynomials_exactly() {
        let nodes = gauss_legendre_64();
        let weights: f64 = nodes.iter().map(|&(_, w)| w).sum();
        assert!((weights - 2.0).abs() < 1e-13, "{weights}");
        // ∫ x^126 over [−1, 1] = 2/127 (degree 2n − 2).
        let m: f64 = nodes.iter().map(|&(x, w)| w * x.powi(126)).sum();
        assert!((m - 2.0 / 127.0).abs() < 1e-13, "{m}");
    }

    #[test]
    fn unshadowed_isotropic_without_extinction_is_the_closed_form() {
        // A segment along the axis region: below the light, inside a wide inner cone.
        let light = SpotLight {
            position: DVec3::new(0.0, 4.0, 0.0),
            direction: DVec3::NEG_Y,
            intensity: 1000.0,
            inner_angle: 85f64.to_radians(),
            outer_angle: 89f64.to_radians(),
            range: 1.0e6,
        };
        // No extinction: σs small enough that e^(−σs · 5) is 1 to 5e-9 (σs only scales L).
        let medium = Medium {
            scattering: 1.0e-9,
            absorption: 0.0,
            asymmetry: 0.0,
        };
        // Passes 0.2 below the light: the 1/d² spike the equal angles cancel.
        let ray = ray_through(DVec3::new(-1.5, 3.8, 0.0), DVec3::new(1.5, 3.8, 0.0), 3.0);
        let exact = closed_form_unshadowed(&ray, &light, &medium);
        let quadrature = in_scattered(&ray, &light, &medium, &[]);
        assert!(
            ((quadrature - exact) / exact).abs() < 1e-7,
            "{quadrature} against {exact}"
        );
    }

    #[test]
    fn quadrature_agrees_with_a_brute_force_march_with_every_term() {
        // Soft cone edge, HG g = 0.6, extinction, a ray crossing the cone's edge and the range.
        let (mut light, medium) = setup(20.0, 0.6);
        light.range = 6.0;
        let ray = ray_through(DVec3::new(0.0, 1.6, 7.0), DVec3::new(0.5, 1.5, 0.0), 12.0);
        let exact = in_scattered(&ray, &light, &medium, &[]);
        // A million equal depth steps, midpoint rule (an independent discretisation).
        let n = 1_000_000;
        let step = (ray.end - ray.start) / n as f64;
        let mut brute = 0.0;
        for i in 0..n {
            let t = ray.start + (i as f64 + 0.5) * step;
            let x = ray.origin + ray.direction * t;
            let v = x - light.position;
            let d = v.length();
            let cos_theta = -(v / d).dot(ray.direction);
            brute += medium.scattering
                * light.intensity
                * light.falloff(x)
                * light.range_window(d)
                * medium.phase(cos_theta)
                * (-medium.extinction() * (t + d)).exp()
                / (d * d)
                * step;
        }
        assert!(exact > 0.0);
        assert!(((brute - exact) / exact).abs() < 1e-6, "{brute} against {exact}");
    }

    #[test]
    fn a_box_occluder_cuts_a_shaft_and_the_bisected_boundaries_are_exact() {
        // The reference set-up's 1 m cube at (0, 2.5, 0) under the light; a ray through the
        // shaft's shadow below the cube.
        let (light, medium) = setup(20.0, 0.0);
        let cube = Occluder {
            min: DVec3::new(-0.5, 2.0, -0.5),
            max: DVec3::new(0.5, 3.0, 0.5),
        };
        let ray = ray_through(DVec3::new(-3.0, 0.5, 0.3), DVec3::new(3.0, 0.5, 0.3), 6.0);
        let open = in_scattered(&ray, &light, &medium, &[]);
        let shadowed = in_scattered(&ray, &light, &medium, &[cube]);
        // The shaft's shadow takes 93 % of this ray's in-scatter (measured 0.0671 left).
        assert!((shadowed / open - 0.0671).abs() < 0.001, "{shadowed} of {open}");
        // Brute force over depth with the shadow test: agrees to the march's resolution.
        let n = 400_000;
        let step = ray.end / n as f64;
        let ea = EqualAngle::of(&ray, light.position);
        let brute: f64 = (0..n)
            .map(|i| {
                let t = (i as f64 + 0.5) * step;
                let d2 = (ray.origin + ray.direction * t - light.position).length_squared();
                integrand_in_angle(&ray, &light, &medium, &[cube], &ea, ea.angle(t)) * ea.h / d2
            })
            .sum::<f64>()
            * medium.scattering
            * light.intensity
            / ea.h
            * step;
        assert!(((brute - shadowed) / shadowed).abs() < 1e-4, "{brute} against {shadowed}");
    }

    #[test]
    fn equal_angles_hold_near_the_tip_where_equal_depths_fail() {
        // Looking up the cone from near the floor at rays that pass 2–20 cm from the light: the
        // part inside the cone runs from the floor to the tip, and the 1/d² spike sits at its
        // far end.
        let (light, medium) = setup(25.0, 0.0);
        let origin = DVec3::new(0.4, 0.5, 0.2);
        let mut worst = [0.0f64; 2];
        for miss in [0.02, 0.05, 0.1, 0.2] {
            let aim = light.position + DVec3::new(miss, 0.0, 0.0);
            let ray = ray_through(origin, aim, 6.0);
            let exact = in_scattered(&ray, &light, &medium, &[]);
            for (k, sampling) in [Sampling::EqualAngle, Sampling::EqualDepth].into_iter().enumerate() {
                let e = estimate(&ray, &light, &medium, &[], sampling, 16);
                worst[k] = worst[k].max(((e - exact) / exact).abs());
            }
        }
        // Measured: equal angles 0.0009 at 16 samples (the tip goal is 0.02), equal
        // depths 0.41; asserted with margins of 0.001 and 0.05.
        assert!(worst[0] <= 0.0019, "equal angles {:.4}", worst[0]);
        assert!((worst[1] - 0.41).abs() <= 0.05, "equal depths {:.4}", worst[1]);
    }

    /// Seed 004's sampling planes, shared by a view's pixels: many converge to the exact
    /// in-scatter; at 16, rays passing near the light see few planes there (the planes are
    /// spaced at equal angles about the view axis's point closest to the light, not about
    /// each ray's), where each ray's own equal angles hold.
    #[test]
    fn slicing_planes_converge_but_miss_the_tip_that_per_ray_angles_hold() {
        let (light, medium) = setup(25.0, 0.0);
        let eye = DVec3::new(0.0, 1.6, 7.0);
        let forward = (DVec3::new(0.0, 1.5, 0.0) - eye).normalize();
        let planes = SlicingPlanes::for_light(eye, forward, &light, 0.1);
        let mut worst = [0.0f64; 3];
        // Across the beam, 1–2 m below the light, and rays through its axis 2–20 cm from it.
        let targets = [DVec3::new(0.3, 3.0, 0.0), DVec3::new(0.6, 2.0, 0.2)];
        let beside = [0.02, 0.05, 0.1, 0.2].map(|m| light.position + light.direction * m);
        for (i, aim) in targets.iter().chain(&beside).enumerate() {
            let ray = ray_through(eye, *aim, 12.0);
            let exact = in_scattered(&ray, &light, &medium, &[]);
            let error = |sampling, n| ((estimate(&ray, &light, &medium, &[], sampling, n) - exact) / exact).abs();
            if i < targets.len() {
                worst[0] = worst[0].max(error(Sampling::SlicingPlanes(planes), 256));
            } else {
                worst[1] = worst[1].max(error(Sampling::SlicingPlanes(planes), 16));
                worst[2] = worst[2].max(error(Sampling::EqualAngle, 16));
            }
        }
        eprintln!(
            "slicing planes: 256 across the beam {:.5}; near the light 16 planes {:.4}, 16 \
             equal angles per ray {:.4}",
            worst[0], worst[1], worst[2]
        );
        // Measured: 256 planes 0.0013 across the beam; near the light 16 planes miss the
        // segment inside the cone altogether (1.0: no plane crosses it), 16 equal angles per ray
        // 0.0036. Margins 0.0005, 0.05 and 0.001.
        assert!(worst[0] <= 0.0018, "256 planes across the beam {:.5}", worst[0]);
        assert!(worst[1] >= 0.95, "16 planes near the light {:.4}", worst[1]);
        assert!(worst[2] <= 0.0046, "16 equal angles per ray near the light {:.4}", worst[2]);
    }
}
