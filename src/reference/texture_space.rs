//! The texture-space occlusion in plain Rust: the mirror of `texel_occlusion` and
//! `footprint_occlusion` (magnified branch) in `render/height/height.wgsl`, the oracle of its GPU
//! contract test and of its CPU accuracy test.

use bevy::math::{Vec2, Vec3};

use crate::height_map_import::{HORIZON_AZIMUTHS, HorizonMap};

/// The core around a point, as the texture-space horizons need it (`CoreFrame` in
/// `render/height/height.wgsl`): the core normal, the world vectors per UV unit, the normal's change
/// per UV unit (the core's curvature; zero on a plane) and the material's scale.
#[derive(Clone, Copy, Debug)]
pub struct CoreFrame {
    /// The core normal.
    pub n: Vec3,
    /// World vector per UV unit along u.
    pub pu: Vec3,
    /// World vector per UV unit along v.
    pub pv: Vec3,
    /// The normal's change per UV unit along u.
    pub nu: Vec3,
    /// The normal's change per UV unit along v.
    pub nv: Vec3,
    /// The material's scale (world height of white).
    pub k: f32,
}

impl CoreFrame {
    /// A flat core: normal `n`, world vectors per UV unit `pu` and `pv`, scale `k`.
    pub fn flat(n: Vec3, pu: Vec3, pv: Vec3, k: f32) -> Self {
        Self { n, pu, pv, nu: Vec3::ZERO, nv: Vec3::ZERO, k }
    }

    /// The world vector per UV unit along texel-space direction `d` and the core's normal
    /// curvature along it (1/world units, positive where convex).
    pub fn along(&self, d: Vec2) -> (Vec3, f32) {
        let along = self.pu * d.x + self.pv * d.y;
        let bend = self.nu * d.x + self.nv * d.y;
        let reach2 = along.length_squared();
        (along, if reach2 > 0.0 { bend.dot(along) / reach2 } else { 0.0 })
    }
}

/// `∫ cos(φ − γ) sin φ dφ`: the cosine-weighted solid angle of a slice through the core normal.
fn slice_antiderivative(phi: f32, gamma: f32) -> f32 {
    -0.25 * (2.0 * phi - gamma).cos() + 0.5 * phi * gamma.sin()
}

/// Cosine-weighted ambient occlusion of the true surface at texel `(x, y)` of `map`, about its
/// true normal, from the horizons of its [`HORIZON_AZIMUTHS`] azimuths (half as many slices
/// through the core normal), each lowered by the core's curvature along it
/// ([`crate::height_map_import::horizon_tangent`]), each slice integrated in closed form.
pub fn texel_occlusion(map: &HorizonMap, x: u32, y: u32, core: &CoreFrame) -> f32 {
    let CoreFrame { n, pu, pv, k, .. } = *core;
    let i = (y * map.width + x) as usize;
    let gradient = map.gradient[i];
    let base = pu.cross(pv);
    let orientation = if base.dot(n) >= 0.0 { 1.0 } else { -1.0 };
    let true_normal = (orientation
        * (base + k * gradient[0] * n.cross(pv) - k * gradient[1] * n.cross(pu)))
        .normalize();
    let half = HORIZON_AZIMUTHS / 2;
    let mut sum = 0.0;
    for s in 0..half {
        let a = s as f32 * std::f32::consts::TAU / HORIZON_AZIMUTHS as f32;
        let (along, curvature) = core.along(Vec2::new(a.cos(), a.sin()));
        let reach = along.length();
        let t = along - n * along.dot(n);
        if reach <= 0.0 || t.length_squared() <= 0.0 {
            sum += 1.0;
            continue;
        }
        let tangent = t.normalize();
        let up = map.tangent(i, s, k, reach, curvature).atan();
        let down = map.tangent(i, s + half, k, reach, curvature).atan();
        let projected = Vec2::new(true_normal.dot(tangent), true_normal.dot(n));
        let gamma = projected.x.atan2(projected.y);
        let half_pi = std::f32::consts::FRAC_PI_2;
        let hi = (half_pi - up).min(gamma + half_pi).max(0.0);
        let lo = (-(half_pi - down)).max(gamma - half_pi).min(0.0);
        let f0 = slice_antiderivative(0.0, gamma);
        sum += projected.length()
            * (slice_antiderivative(hi, gamma) - f0 + slice_antiderivative(lo, gamma) - f0);
    }
    (sum / half as f32).clamp(0.0, 1.0)
}

/// The texture-space occlusion of a magnified surface at `uv`: [`texel_occlusion`]
/// interpolated bilinearly between the four texels around it (wrapped).
pub fn magnified_occlusion(map: &HorizonMap, uv: Vec2, core: &CoreFrame) -> f32 {
    let (w, h) = (map.width as i64, map.height as i64);
    let p = uv.fract_gl() * Vec2::new(w as f32, h as f32) - 0.5;
    let base = p.floor();
    let f = p - base;
    let at = |dx: i64, dy: i64| {
        let x = (base.x as i64 + dx).rem_euclid(w) as u32;
        let y = (base.y as i64 + dy).rem_euclid(h) as u32;
        texel_occlusion(map, x, y, core)
    };
    let top = at(0, 0) * (1.0 - f.x) + at(1, 0) * f.x;
    let bottom = at(0, 1) * (1.0 - f.x) + at(1, 1) * f.x;
    top * (1.0 - f.y) + bottom * f.y
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{
        height_map_import::horizon_tangent, height_maps::HeightMap,
        reference::ground_truth::HeightField,
    };

    /// The z-up frame of `ground_truth::HeightField` for a plane `size` wide: UV along x and y.
    fn frame(size: f32) -> (Vec3, Vec3, Vec3) {
        (Vec3::Z, Vec3::X * size, Vec3::Y * size)
    }

    #[test]
    fn a_flat_map_is_open() {
        let flat = HeightMap::from_fn(16, 16, |_, _| 0.4);
        let map = HorizonMap::new(&flat.values, 16, 16);
        let (n, pu, pv) = frame(2.0);
        for (x, y) in [(0, 0), (5, 9), (15, 15)] {
            let ao = texel_occlusion(&map, x, y, &CoreFrame::flat(n, pu, pv, 0.3));
            assert!((ao - 1.0).abs() < 1e-5, "flat map AO {ao}");
        }
    }

    /// At the bottom of a V-groove with walls at slope α the cosine-weighted AO is cos α: the
    /// mean over the slices of `cos² h` with `tan h = tan α |cos θ|`, within 0.002 of it at 25°
    /// and 40° (measured 0.9063 and 0.7660).
    #[test]
    fn v_groove_bottom_meets_the_closed_form() {
        for slope in [25.0f32, 40.0] {
            // Grooves along v, 32 texels a period, the bottom on texel 16; 2 world units over 64
            // texels, so a half-groove is 0.5 wide and k = 0.5 tan α.
            let map = HeightMap::from_fn(64, 64, |u, _| ((u * 64.0 - 0.5) % 32.0 - 16.0).abs() / 16.0);
            let horizons = HorizonMap::new(&map.values, 64, 64);
            let (n, pu, pv) = frame(2.0);
            let k = 0.5 * slope.to_radians().tan();
            let ao = texel_occlusion(&horizons, 16, 7, &CoreFrame::flat(n, pu, pv, k));
            let closed = slope.to_radians().cos();
            eprintln!("V-groove {slope}°: texture-space AO {ao:.4}, closed form {closed:.4}");
            assert!((ao - closed).abs() < 0.002, "{slope}°: {ao} against {closed}");
        }
    }

    /// The model against the ray-traced ground truth of the same height field (cosine-weighted
    /// AO, infinite radius) at 64 texels of fractal noise (k 0.1) and of rivets (k 0.2): MAE
    /// measured 0.0039 and 0.0368 (`cargo test --lib texture_space -- --nocapture`), held to
    /// ±0.005. The rivets' error is the search radius: they stand 32 texels apart, as far as
    /// the horizons are searched, and the truth sees every one of them (too open by 0.037).
    #[test]
    fn texture_space_occlusion_is_close_to_the_ray_traced_truth() {
        for (name, map, k, measured) in [
            ("stone", HeightMap::noise(128, 8, 4, 3), 0.1, 0.0039),
            ("rivets", HeightMap::rivets(128, 4, 0.35), 0.2, 0.0368),
        ] {
            let horizons = HorizonMap::new(&map.values, map.width, map.height);
            let field = HeightField::new(map.width, map.height, &map.values, 2.0, k);
            let (n, pu, pv) = frame(2.0);
            let (mut mae, mut bias, mut count) = (0.0, 0.0, 0);
            for j in 0..8 {
                for i in 0..8 {
                    let (x, y) = (i * 16 + 5, j * 16 + 11);
                    let model = texel_occlusion(&horizons, x, y, &CoreFrame::flat(n, pu, pv, k));
                    let truth =
                        field.ambient_occlusion(Vec2::new(x as f32 + 0.5, y as f32 + 0.5), 16, 16);
                    mae += (model - truth).abs();
                    bias += model - truth;
                    count += 1;
                }
            }
            let (mae, bias) = (mae / count as f32, bias / count as f32);
            eprintln!("{name} k {k}: texture-space AO MAE {mae:.4}, bias {bias:+.4}");
            assert!(
                (mae - measured).abs() <= 0.005,
                "{name}: MAE {mae}, measured {measured} ± 0.005"
            );
        }
    }

    /// A wall 8 texels away: the map stores its slope and distance, and on a convex core the
    /// horizon towards it drops by κ D / 2 (the core falls κ D² / 2 below its tangent plane):
    /// exactly as much that the wall hides below the tangent plane once κ D² / 2 exceeds its
    /// height, which opens the texel's occlusion.
    #[test]
    fn curvature_lowers_the_horizon_by_the_cores_fall() {
        // A 64-texel map, flat at 0 but for a 4-texel-wide wall of height 1 at x = 24 … 27.
        let map = HeightMap::from_fn(64, 64, |u, _| {
            let x = (u * 64.0) as u32;
            if (24..28).contains(&x) { 1.0 } else { 0.0 }
        });
        let horizons = HorizonMap::new(&map.values, 64, 64);
        let i = 7 * 64 + 16;
        let (slope, steps) = (horizons.slopes[i][0][0], horizons.distances[i][0][0]);
        assert_eq!(steps, 8, "the wall is 8 texels away");
        let distance = steps as f32 / 64.0;
        assert!((slope - 1.0 / distance).abs() < 1e-3, "slope {slope}");
        // 2 world units per UV unit, k 0.2: the wall rises 0.2 at D = 0.25; a core of radius
        // R falls D² / 2R there, 0.2 at R = 0.15625.
        let (n, pu, pv, k) = (Vec3::Z, Vec3::X * 2.0, Vec3::Y * 2.0, 0.2);
        let flat = horizon_tangent(slope, distance, k, 2.0, 0.0);
        assert!((flat - 0.2 / 0.25).abs() < 1e-3, "flat horizon tangent {flat}");
        let level = horizon_tangent(slope, distance, k, 2.0, 1.0 / 0.15625);
        assert!(level.abs() < 1e-3, "the wall level with the tangent plane: {level}");
        // A cylinder along v, radius R: the normal turns by 1/R per world unit along u, so its
        // normal curvature along azimuth a is cos² a / R and the wall, 0.25 / cos a away
        // along it, hides at the same R on every azimuth. A little tighter than level: open.
        let on_cylinder = |radius: f32| CoreFrame {
            nu: Vec3::X * 2.0 / radius,
            ..CoreFrame::flat(n, pu, pv, k)
        };
        let flat_ao = texel_occlusion(&horizons, 16, 7, &CoreFrame::flat(n, pu, pv, k));
        let bent_ao = texel_occlusion(&horizons, 16, 7, &on_cylinder(0.9 * 0.15625));
        let concave_ao = texel_occlusion(&horizons, 16, 7, &on_cylinder(-0.15625));
        eprintln!("wall AO: flat {flat_ao:.4}, convex {bent_ao:.4}, concave {concave_ao:.4}");
        assert!(flat_ao < 0.99, "the wall occludes on a plane: {flat_ao}");
        assert!((bent_ao - 1.0).abs() < 1e-3, "hidden by the curvature: {bent_ao}");
        assert!(concave_ao < flat_ao - 0.005, "a concave core rises: {concave_ao}");
    }
}
