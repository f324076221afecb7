//! The texture-space terms in plain Rust: the mirror of `texel_occlusion`,
//! `footprint_terms` (magnified branch), `texel_light_visibility`, `point_light_visibility` and
//! `texture_bounce` in
//! `render/height/height.wgsl`, the oracle of their GPU contract tests and of their CPU
//! accuracy tests.

use bevy::math::{Vec2, Vec3};

use crate::height_map_import::{
    EDGE_SHADOWED_PERCENT, HORIZON_AZIMUTHS, HorizonMap, TEXTURE_BOUNCE_SAMPLES, horizon_direction,
};

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
    let CoreFrame { n, k, .. } = *core;
    let i = (y * map.width + x) as usize;
    let true_normal = true_normal(map.gradient[i], core);
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

/// The true normal for the map's `gradient` by Blinn's formula (oriented like the core
/// normal), as the bump normal is made.
fn true_normal(gradient: [f32; 2], core: &CoreFrame) -> Vec3 {
    let CoreFrame { n, pu, pv, k, .. } = *core;
    let base = pu.cross(pv);
    let orientation = if base.dot(n) >= 0.0 { 1.0 } else { -1.0 };
    (orientation * (base + k * gradient[0] * n.cross(pv) - k * gradient[1] * n.cross(pu)))
        .normalize()
}

/// The bilinear value of `values` (one per texel of `map`, row-major) at texel coordinates `p`
/// (texel centres at integers), wrapped however far.
fn bilinear<T>(map: &HorizonMap, values: impl Fn(usize) -> T, p: Vec2) -> T
where
    T: std::ops::Add<Output = T> + std::ops::Mul<f32, Output = T> + Copy,
{
    let (w, h) = (map.width as i64, map.height as i64);
    let at = |x: i64, y: i64| values((y.rem_euclid(h) * w + x.rem_euclid(w)) as usize);
    let base = p.floor();
    let f = p - base;
    let (x0, y0) = (base.x as i64, base.y as i64);
    let top = at(x0, y0) * (1.0 - f.x) + at(x0 + 1, y0) * f.x;
    let bottom = at(x0, y0 + 1) * (1.0 - f.x) + at(x0 + 1, y0 + 1) * f.x;
    top * (1.0 - f.y) + bottom * f.y
}

/// A directional light as the texture-space shadow test sees it over one core frame
/// (`LightInUv` in `render/height/height.wgsl`).
#[derive(Clone, Copy, Debug)]
pub struct LightInUv {
    /// Tangent of its elevation above the core plane.
    pub tan_l: f32,
    /// Its direction in UV space (unit).
    pub uv_direction: Vec2,
    /// World length per UV unit along it.
    pub reach: f32,
    /// The core's normal curvature along it (1/world units, positive where convex).
    pub curvature: f32,
    /// The two horizon azimuths around it and the weight of the second.
    pub azimuths: (usize, usize, f32),
}

impl LightInUv {
    /// The light from the unit direction `to_light` over `core`; `None` where it is below the
    /// core plane or at the zenith (it reaches every point: n·l's and the shadow maps' job).
    pub fn new(core: &CoreFrame, to_light: Vec3) -> Option<Self> {
        let CoreFrame { n, pu, pv, .. } = *core;
        let sin_l = to_light.dot(n);
        let tangential = to_light - n * sin_l;
        let t2 = tangential.length_squared();
        if sin_l <= 0.0 || t2 <= 1e-12 {
            return None;
        }
        // The light's azimuth in UV space: tangential = pu a + pv b (least squares in the plane).
        let (g00, g01, g11) = (pu.dot(pu), pu.dot(pv), pv.dot(pv));
        let det = g00 * g11 - g01 * g01;
        if det.abs() <= 1e-20 {
            return None;
        }
        let r = Vec2::new(tangential.dot(pu), tangential.dot(pv));
        let ab = Vec2::new(g11 * r.x - g01 * r.y, g00 * r.y - g01 * r.x) / det;
        let uv_length = ab.length();
        if uv_length <= 0.0 {
            return None;
        }
        let (along, curvature) = core.along(ab / uv_length);
        let position = ab.y.atan2(ab.x) / std::f32::consts::TAU * HORIZON_AZIMUTHS as f32;
        let lower = position.floor();
        let i0 = (lower as i64).rem_euclid(HORIZON_AZIMUTHS as i64) as usize;
        Some(Self {
            tan_l: sin_l / t2.sqrt(),
            uv_direction: ab / uv_length,
            reach: along.length(),
            curvature,
            azimuths: (i0, (i0 + 1) % HORIZON_AZIMUTHS, position - lower),
        })
    }

    /// The horizon tangent at texel `index` of `map` towards the light's azimuth, the two
    /// nearest azimuths interpolated, each lowered by the core's fall with `curvature`.
    fn horizon(&self, map: &HorizonMap, index: usize, k: f32, curvature: f32) -> f32 {
        let (i0, i1, f) = self.azimuths;
        let h0 = map.tangent(index, i0, k, self.reach, curvature);
        h0 + (map.tangent(index, i1, k, self.reach, curvature) - h0) * f
    }

    /// The farther of the two light azimuths' highest occluders at texel `index`, in texel
    /// steps: beyond it nothing rises above the flat horizon.
    fn occluder_steps(&self, map: &HorizonMap, index: usize) -> u32 {
        let (i0, i1, _) = self.azimuths;
        map.distances[index][0][i0].max(map.distances[index][0][i1]) as u32
    }

    /// Whether the light reaches texel coordinates `p` (texel centres at integers): the
    /// bilinear heights marched towards it `step` texels at a time for `steps` steps, each
    /// lowered by the core's fall κ D² / 2 at its world distance D.
    fn march(&self, map: &HorizonMap, p: Vec2, k: f32, step: f32, steps: u32) -> bool {
        let size = Vec2::new(map.width as f32, map.height as f32);
        let texel_direction = (self.uv_direction * size).normalize();
        let uv_step = (texel_direction / size).length() * step;
        let h0 = bilinear(map, |i| map.heights[i], p);
        (1..=steps).all(|t| {
            let height = bilinear(map, |i| map.heights[i], p + t as f32 * step * texel_direction);
            let d = t as f32 * uv_step * self.reach;
            k * (height - h0) - 0.5 * self.curvature * d * d <= self.tan_l * d
        })
    }

    /// Whether the light reaches texel `(x, y)` of `map`: [`texel_light_visibility`].
    fn reaches_texel(&self, map: &HorizonMap, x: u32, y: u32, k: f32) -> bool {
        let index = (y * map.width + x) as usize;
        if self.tan_l < self.horizon(map, index, k, self.curvature) {
            return false;
        }
        if self.curvature <= 0.0 || self.tan_l >= self.horizon(map, index, k, 0.0) {
            return true;
        }
        let p = Vec2::new(x as f32, y as f32);
        self.march(map, p, k, 1.0, self.occluder_steps(map, index))
    }
}

/// Whether light from the unit direction `to_light` reaches texel `(x, y)`: its elevation
/// above the core plane against the texel's horizon towards its azimuth, the two nearest
/// azimuths interpolated (horizon mapping, Max 1988). Light from below the core plane or from
/// the zenith counts as reaching it (n·l's and the shadow maps' job). On a convex core the
/// horizons lowered by the core's fall are a lower bound and the flat map's an upper one; a
/// light between them is decided by marching the heights towards it, each lowered by the fall.
pub fn texel_light_visibility(
    map: &HorizonMap,
    x: u32,
    y: u32,
    core: &CoreFrame,
    to_light: Vec3,
) -> bool {
    LightInUv::new(core, to_light).is_none_or(|light| light.reaches_texel(map, x, y, core.k))
}

/// The visibility of light from the unit direction `to_light` at `uv` itself, as a ray cast
/// from that point finds: the four texels around it decide where they agree
/// ([`texel_light_visibility`]); where they do not, a shadow edge crosses them and a march
/// from `uv` in half-texel steps, as far as their highest occluders plus a texel, decides the
/// side of one half (lit ≥ 0.5, shadowed ≤ [`EDGE_SHADOWED_PERCENT`] %) while the texels'
/// bilinear mix shapes the edge's soft profile. Mirrors `point_light_visibility` in
/// `render/height/height.wgsl`.
pub fn point_light_visibility(map: &HorizonMap, uv: Vec2, core: &CoreFrame, to_light: Vec3) -> f32 {
    let Some(light) = LightInUv::new(core, to_light) else {
        return 1.0;
    };
    let (w, h) = (map.width as i64, map.height as i64);
    let p = uv.fract_gl() * Vec2::new(w as f32, h as f32) - 0.5;
    let base = p.floor();
    let f = p - base;
    let texels = [(0, 0), (1, 0), (0, 1), (1, 1)].map(|(dx, dy)| {
        let x = (base.x as i64 + dx).rem_euclid(w) as u32;
        let y = (base.y as i64 + dy).rem_euclid(h) as u32;
        (x, y)
    });
    let corners = texels.map(|(x, y)| light.reaches_texel(map, x, y, core.k) as u32 as f32);
    let mix = |a: f32, b: f32, t: f32| a + (b - a) * t;
    let soft = mix(mix(corners[0], corners[1], f.x), mix(corners[2], corners[3], f.x), f.y);
    let lit: f32 = corners.iter().sum();
    if lit == 0.0 || lit == 4.0 {
        return soft;
    }
    // Only at an edge: how far the march goes, the corners' farthest occluder.
    let steps = texels
        .iter()
        .map(|&(x, y)| light.occluder_steps(map, (y * map.width + x) as usize))
        .max()
        .unwrap_or(0);
    if light.march(map, p, core.k, 0.5, 2 * (steps + 1)) {
        soft.max(0.5)
    } else {
        soft.min(EDGE_SHADOWED_PERCENT as f32 / 100.0)
    }
}

/// The one-bounce irradiance at `uv` from the surface lit by a directional light from the
/// unit direction `to_light`, relative to E0 (the irradiance of a surface facing the light),
/// every surface white: what `ground_truth::HeightField::one_bounce` computes by ray tracing,
/// here from the horizon map. Along each of the [`HORIZON_AZIMUTHS`] azimuths, between the
/// point and the distance where its horizon is reached (beyond it the rays escape),
/// [`TEXTURE_BOUNCE_SAMPLES`] points S of the surface (bilinear heights, lowered by the core's
/// curvature) are seen at rising elevations above the true tangent plane; each stands for the
/// band of cosine-weighted solid angle between the previous visible point and itself
/// (`(sin² e_j − sin² e_{j−1}) / 2 · Δθ`, paper eq. 8 with the band's area) and sends
/// `max(0, N_S · l) · V(S)` if it faces the point (N_S from the gradient at S, bilinear; V(S)
/// of S's nearest texel by [`texel_light_visibility`]; both about S's own core normal — turned by the core's
/// curvature on the way — and nothing where the light is below S's core plane). The sum is then rescaled to the blocked part of the
/// hemisphere the texture-space occlusion `occlusion` gives (`(1 − AO) / the bands' own
/// total`): the few samples give the mean radiance of what the point sees instead of the sky,
/// the occlusion how much of it there is. `map.heights` are the level's heights.
pub fn texture_bounce(
    map: &HorizonMap,
    uv: Vec2,
    core: &CoreFrame,
    to_light: Vec3,
    occlusion: f32,
) -> f32 {
    let (w, h) = (map.width as i64, map.height as i64);
    let wrap = |x: i64, y: i64| (y.rem_euclid(h) * w + x.rem_euclid(w)) as usize;
    let height = |p: Vec2| bilinear(map, |i| map.heights[i], p);
    let gradient = |p: Vec2| bilinear(map, |i| Vec2::from(map.gradient[i]), p).into();
    // Texel coordinates (texel centres at integers), as the horizon map was built.
    let p = uv.fract_gl() * Vec2::new(w as f32, h as f32) - 0.5;
    let h0 = height(p);
    let normal = true_normal(gradient(p), core);
    let nearest = wrap(p.x.round() as i64, p.y.round() as i64);
    let mut irradiance = 0.0;
    let mut covered = 0.0;
    for i in 0..HORIZON_AZIMUTHS {
        let [dx, dy] = horizon_direction(i);
        let (_, curvature) = core.along(Vec2::new(dx, dy));
        let distance = map.distances[nearest][0][i] as f32;
        let mut seen = 0.0f32;
        for j in 1..=TEXTURE_BOUNCE_SAMPLES {
            let t = distance * j as f32 / TEXTURE_BOUNCE_SAMPLES as f32;
            let s = p + t * Vec2::new(dx, dy);
            let along = core.pu * (t * dx / w as f32) + core.pv * (t * dy / h as f32);
            // The core falls κ D² / 2 below its tangent plane at world distance D.
            let fall = 0.5 * curvature * along.length_squared();
            let d = along + core.n * (core.k * (height(s) - h0) - fall);
            let length = d.length();
            if length <= 0.0 {
                continue;
            }
            let sine = d.dot(normal) / length;
            if sine <= seen {
                continue;
            }
            let band = 0.5 * (sine * sine - seen * seen);
            let (qx, qy) = (s.x.round() as i64, s.y.round() as i64);
            // S's own core frame: on a curved core the normal has turned on the way.
            let core_s = CoreFrame {
                n: (core.n + core.nu * (t * dx / w as f32) + core.nv * (t * dy / h as f32))
                    .normalize(),
                ..*core
            };
            let n_s = true_normal(gradient(s), &core_s);
            let cos_l = n_s.dot(to_light);
            if n_s.dot(-d) > 0.0
                && cos_l > 0.0
                && core_s.n.dot(to_light) > 0.0
                && texel_light_visibility(
                    map,
                    qx.rem_euclid(w) as u32,
                    qy.rem_euclid(h) as u32,
                    &core_s,
                    to_light,
                )
            {
                irradiance += cos_l * band;
            }
            covered += band;
            seen = sine;
        }
    }
    // Both sums times Δθ / π; the ratio needs none.
    let scale = std::f32::consts::TAU / HORIZON_AZIMUTHS as f32 / std::f32::consts::PI;
    let gathered = covered * scale;
    if gathered > 1e-4 {
        irradiance * scale * (1.0 - occlusion).max(0.0) / gathered
    } else {
        irradiance * scale
    }
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

    /// The photo-derived pebbles map, point-sampled down to 128².
    /// A map's horizon map, its ray-traced height field (one world unit per UV unit) and the
    /// flat core frame of a surface of scale `k` over it.
    fn fixture(map: &HeightMap, k: f32) -> (HorizonMap, HeightField, CoreFrame) {
        (
            HorizonMap::new(&map.values, map.width, map.height),
            HeightField::new(map.width, map.height, &map.values, 1.0, k),
            CoreFrame::flat(Vec3::Z, Vec3::X, Vec3::Y, k),
        )
    }

    /// The direction to a light `elevation` degrees above the core plane, 0.7 rad round from u.
    fn light_at(elevation: f32) -> Vec3 {
        let e = elevation.to_radians();
        Vec3::new(e.cos() * 0.7f32.cos(), e.cos() * 0.7f32.sin(), e.sin())
    }

    fn pebbles_128() -> HeightMap {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("assets/height_maps/photo/pebbles.png");
        let grey = image::open(&path).expect("the pebbles map").to_luma16();
        let (w, h) = grey.dimensions();
        let f = (w / 128).max(1);
        HeightMap::from_fn(w / f, h / f, |u, v| {
            let x = (u * (w / f) as f32) as u32 * f;
            let y = (v * (h / f) as f32) as u32 * f;
            grey.get_pixel(x, y)[0] as f32 / 65535.0
        })
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
    /// measured 0.0038 and 0.0156 (`cargo test --lib texture_space -- --nocapture`), held to
    /// ±0.005. The rivets' error is the search radius: they stand 32 texels apart and the
    /// horizons of this 128² map are searched to 64 (half its width), while the truth sees
    /// every rivet (too open by 0.014; with the 32-texel search of before, 0.0368 and 0.037).
    #[test]
    fn texture_space_occlusion_is_close_to_the_ray_traced_truth() {
        for (name, map, k, measured) in [
            ("stone", HeightMap::noise(128, 8, 4, 3), 0.1, 0.0038),
            ("rivets", HeightMap::rivets(128, 4, 0.35), 0.2, 0.0156),
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

    /// The texture-space bounce against the ray-traced one bounce of the same height field
    /// (`HeightField::one_bounce`, 12 × 24 rays) at 49 texels, lights at 15°, 35° and 60°:
    /// relative error Σ|b − t| / Σt and mean ratio Σb / Σt. Measured (`cargo test --lib
    /// texture_bounce -- --nocapture`): pebbles (photo-derived, 128², k 0.05) 0.253 / 0.127 /
    /// 0.088 and ratio 0.95 / 0.95 / 0.96; fractal noise (k 0.1) 0.201 / 0.166 / 0.158 and
    /// 0.92 / 0.88 / 0.88 (with the horizons searched 4× as far; 0.243 / 0.137 / 0.097 and
    /// 0.200 / 0.164 / 0.161 before); held to ±0.03 and ±0.05. (The sample's normal at its nearest texel
    /// instead of bilinear: 0.267 / 0.159 / 0.135 and 0.205 / 0.178 / 0.184.) (On a nearly flat map the truth is tiny
    /// and the relative error large: noise with 5 octaves at k 0.05 gave 0.65–0.76.)
    #[test]
    fn texture_bounce_is_close_to_the_ray_traced_truth() {
        let pebbles = pebbles_128();
        let measured = [
            ("pebbles", [(0.253, 0.95), (0.127, 0.95), (0.088, 0.96)]),
            ("stone", [(0.201, 0.92), (0.166, 0.88), (0.158, 0.88)]),
        ];
        for ((name, expected), map) in measured.into_iter().zip([(pebbles, 0.05), (HeightMap::noise(128, 8, 4, 3), 0.1)]) {
            let (map, k) = map;
            let (horizons, field, core) = fixture(&map, k);
            for (elevation, (relative, ratio)) in [15.0f32, 35.0, 60.0].into_iter().zip(expected) {
                let to_light = light_at(elevation);
                let (mut error, mut sum, mut truth_sum) = (0.0, 0.0, 0.0);
                for j in 0..7 {
                    for i in 0..7 {
                        let (x, y) = (i * 18 + 5, j * 18 + 11);
                        let at = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                        let truth = field.one_bounce(at, -to_light, 12, 24);
                        let uv = at / map.width as f32;
                        let ao = texel_occlusion(&horizons, x, y, &core);
                        let model = texture_bounce(&horizons, uv, &core, to_light, ao);
                        error += (model - truth).abs();
                        sum += model;
                        truth_sum += truth;
                    }
                }
                let (rel, mean) = (error / truth_sum, sum / truth_sum);
                eprintln!("{name} light {elevation}°: texture-space bounce relative error {rel:.3}, ratio {mean:.2}");
                assert!((rel - relative).abs() <= 0.03, "{name} {elevation}°: {rel} against {relative} ± 0.03");
                assert!((mean - ratio).abs() <= 0.05, "{name} {elevation}°: ratio {mean} against {ratio} ± 0.05");
            }
        }
    }

    /// On a convex core the map's horizon lowered by the fall at the highest occluder's
    /// distance is only a lower bound: a nearer, lower wall falls less and can still shadow.
    /// A low wall 4 texels away and a high one 24 away on a cylinder whose fall hides the high
    /// one: a light just under the low wall's lowered horizon is shadowed (the march finds
    /// it), one above it lit, and on the plane both walls count.
    #[test]
    fn a_near_wall_still_shadows_where_the_curvature_hides_the_far_one() {
        let map = HeightMap::from_fn(64, 64, |u, _| {
            let x = (u * 64.0) as u32;
            if (20..24).contains(&x) {
                0.12
            } else if (40..44).contains(&x) {
                1.0
            } else {
                0.0
            }
        });
        let horizons = HorizonMap::new(&map.values, 64, 64);
        let (n, pu, pv, k) = (Vec3::Z, Vec3::X * 2.0, Vec3::Y * 2.0, 0.2);
        // Radius 0.6: the far wall (0.75 away, tangent 0.267 flat) falls 0.47 below the
        // tangent plane, the near one (0.125 away, tangent 0.192 flat) 0.013: lowered by
        // κ D / 2, its horizon tangent is 0.088.
        let cylinder = CoreFrame { nu: Vec3::X * 2.0 / 0.6, ..CoreFrame::flat(n, pu, pv, k) };
        let light = |tan: f32| Vec3::new(1.0, 0.0, tan).normalize();
        assert!(!texel_light_visibility(&horizons, 16, 7, &cylinder, light(0.06)), "under the near wall");
        assert!(texel_light_visibility(&horizons, 16, 7, &cylinder, light(0.12)), "over the near wall");
        let flat = CoreFrame::flat(n, pu, pv, k);
        assert!(!texel_light_visibility(&horizons, 16, 7, &flat, light(0.25)), "the far wall on a plane");
        assert!(texel_light_visibility(&horizons, 16, 7, &flat, light(0.29)), "over both on a plane");
    }

    /// The light's visibility at 1024 points between texel centres against a ray cast from the
    /// same point of the same height field (`HeightField::ray_hit`), on points whose true normal
    /// faces the light (n·l > 0.05) and whose own slope does not already hide it (no hit within
    /// half a texel), lights at 15°, 35° and 50°: micro-shadow recall and precision. Measured
    /// (`cargo test --lib point_light -- --nocapture`), recall / precision: pebbles
    /// (photo-derived, 128², k 0.1) 0.978 / 0.989, 0.986 / 0.986, 0.949 / 1.000 (270, 146, 79
    /// shadowed points); fractal noise (k 0.2) 0.977 / 0.964, 0.971 / 0.971, 0.941 / 1.000
    /// (221, 68, 17); held to ±0.03 (one point of the 17 is 0.06). The texels' 0s and 1s
    /// interpolated instead (before the march across edges) gave 0.72–0.93 / 0.80–0.91.
    #[test]
    fn point_light_visibility_agrees_with_a_ray_cast_from_the_point() {
        let measured = [
            ("pebbles", [(0.978, 0.989), (0.986, 0.986), (0.949, 1.000)]),
            ("stone", [(0.977, 0.964), (0.971, 0.971), (0.941, 1.000)]),
        ];
        let maps = [(pebbles_128(), 0.1), (HeightMap::noise(128, 8, 4, 3), 0.2)];
        for ((name, expected), (map, k)) in measured.into_iter().zip(maps) {
            let (horizons, field, core) = fixture(&map, k);
            for (elevation, (recall, precision)) in [15.0f32, 35.0, 50.0].into_iter().zip(expected) {
                let to_light = light_at(elevation);
                // [method][texels interpolated]: true positives, false positives, misses.
                let mut counts = [[0u32; 3]; 2];
                for j in 0..32 {
                    for i in 0..32 {
                        // Points off the texel centres, spread over the map.
                        let at = Vec2::new(i as f32 * 3.97 + 0.83, j as f32 * 4.03 + 0.37);
                        if field.normal(at).dot(to_light) <= 0.05 {
                            continue;
                        }
                        // A ray that meets the surface within half a texel meets the point's
                        // own slope (steeper than the normal's central differences say): that
                        // is n·l's to darken, not an occluder's.
                        let hit = field.ray_hit(at, to_light);
                        if hit.is_some_and(|q| q.distance(at) < 0.5) {
                            continue;
                        }
                        let truth = hit.is_some();
                        let uv = at / map.width as f32;
                        let point = point_light_visibility(&horizons, uv, &core, to_light) < 0.5;
                        // The texels' 0s and 1s interpolated, as before the march.
                        let lit = |i: usize| {
                            let (x, y) = (i as u32 % map.width, i as u32 / map.width);
                            texel_light_visibility(&horizons, x, y, &core, to_light) as u32 as f32
                        };
                        let interpolated = bilinear(&horizons, lit, at - 0.5) < 0.5;
                        for (c, method) in counts.iter_mut().zip([point, interpolated]) {
                            match (truth, method) {
                                (true, true) => c[0] += 1,
                                (false, true) => c[1] += 1,
                                (true, false) => c[2] += 1,
                                _ => {}
                            }
                        }
                    }
                }
                let score = |c: [u32; 3]| {
                    (c[0] as f32 / (c[0] + c[2]).max(1) as f32, c[0] as f32 / (c[0] + c[1]).max(1) as f32)
                };
                let ((r, p), (ri, pi)) = (score(counts[0]), score(counts[1]));
                eprintln!(
                    "{name} light {elevation}°: point visibility recall {r:.3} precision {p:.3} \
                     ({} shadowed); texels interpolated {ri:.3} / {pi:.3}",
                    counts[0][0] + counts[0][2]
                );
                assert!(counts[0][0] + counts[0][2] >= 15, "{name} {elevation}°: shadows to find");
                assert!((r - recall).abs() <= 0.03, "{name} {elevation}°: recall {r} against {recall} ± 0.03");
                assert!((p - precision).abs() <= 0.03, "{name} {elevation}°: precision {p} against {precision} ± 0.03");
            }
        }
    }
}
