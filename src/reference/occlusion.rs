//! Mesostructure ambient occlusion from the apex sets (paper §3.1, eqs. 3–6).

use bevy::math::{Mat4, Vec2, Vec3, Vec4};

use super::{ApexSet, GradientMap, OcclusionForm, ScreenHeightMap};

/// Azimuth sectors of the occlusion integral: each apex occludes the sector its screen-space
/// direction falls in, with its elevation; sectors without an apex are open.
pub const OCCLUSION_SECTORS: usize = 8;

/// How pixels map back to the world: the view's inverse view-projection and viewport.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewGeometry {
    /// Clip space → world space.
    pub world_from_clip: Mat4,
    /// Viewport `(x, y, width, height)` in pixels.
    pub viewport: Vec4,
}

impl ViewGeometry {
    /// The core point P0 seen through the centre of pixel `(x, y)` at NDC depth `depth`.
    pub fn core_point(&self, x: u32, y: u32, depth: f32) -> Vec3 {
        let uv = (Vec2::new(x as f32 + 0.5, y as f32 + 0.5) - self.viewport.truncate().truncate())
            / Vec2::new(self.viewport.z, self.viewport.w);
        let ndc = Vec4::new(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, depth, 1.0);
        let p = self.world_from_clip * ndc;
        p.truncate() / p.w
    }
}

/// The surface point `P = P0 + n0 · dis · k` (eq. 7) of pixel `(x, y)`.
pub fn surface_point(
    mhm: &ScreenHeightMap,
    normals: &[Vec3],
    view: &ViewGeometry,
    x: u32,
    y: u32,
) -> Vec3 {
    let i = mhm.index(x, y);
    view.core_point(x, y, mhm.depths[i]) + normals[i] * mhm.heights[i]
}

/// The normal N' of the mesostructure surface at pixel `(x, y)`: the cross product of the
/// screen-space derivatives of the surface points (eq. 7) — central differences where both
/// neighbours on an axis are connected, one-sided where one is — oriented like n0; n0 itself
/// where an axis has no connected neighbour. Mirrors `mesostructure_normal` in `occlusion.wgsl`.
pub fn mesostructure_normal(
    mhm: &ScreenHeightMap,
    mhgm: &GradientMap,
    normals: &[Vec3],
    view: &ViewGeometry,
    (x, y): (u32, u32),
) -> Vec3 {
    let i = mhm.index(x, y);
    let n0 = normals[i];
    let p = surface_point(mhm, normals, view, x, y);
    let at = |dx: i32, dy: i32| {
        surface_point(
            mhm,
            normals,
            view,
            (x as i32 + dx) as u32,
            (y as i32 + dy) as u32,
        )
    };
    // Neighbours 0 (+x), 4 (−x), 2 (+y), 6 (−y).
    let derivative = |plus: usize, minus: usize, o: (i32, i32)| match (
        mhgm.connected(i, plus),
        mhgm.connected(i, minus),
    ) {
        (true, true) => Some((at(o.0, o.1) - at(-o.0, -o.1)) * 0.5),
        (true, false) => Some(at(o.0, o.1) - p),
        (false, true) => Some(p - at(-o.0, -o.1)),
        (false, false) => None,
    };
    let (Some(dx), Some(dy)) = (derivative(0, 4, (1, 0)), derivative(2, 6, (0, 1))) else {
        return n0;
    };
    let n = dx.cross(dy);
    let len = n.length();
    if !(len > 0.0) {
        return n0;
    }
    let n = n / len;
    limit_tilt(if n.dot(n0) < 0.0 { -n } else { n }, n0)
}

/// Cosine of the largest angle N' may make with n0 (see `limit_tilt`).
pub const MAX_NORMAL_TILT_COS: f32 = 0.5;

/// N' turned back towards n0 to at most the angle of [`MAX_NORMAL_TILT_COS`]: steeper walls
/// (cliffs a pixel or two wide) have no reliable tangent plane on screen, and horizons sorted by
/// screen azimuth stop describing a hemisphere about a near-horizontal normal. Mirrors
/// `limit_tilt` in `surface.wgsl`.
pub fn limit_tilt(n: Vec3, n0: Vec3) -> Vec3 {
    let c = n.dot(n0);
    if c >= MAX_NORMAL_TILT_COS {
        return n;
    }
    let side = n - n0 * c;
    let len = side.length();
    if !(len > 0.0) {
        return n0;
    }
    n0 * MAX_NORMAL_TILT_COS + side / len * (1.0 - MAX_NORMAL_TILT_COS * MAX_NORMAL_TILT_COS).sqrt()
}

/// Ambient occlusion of pixel `(x, y)` from its apex set (1 = open): per apex H the horizon
/// angle `sin h = ((H − P) · N) / |H − P|` with both points from eq. 7 (eq. 5) and N the normal
/// of the form's tangent plane; per sector the highest horizon; then the form's integral over
/// the sectors. Mirrors `occlusion.wgsl`.
pub fn occlusion(
    mhm: &ScreenHeightMap,
    mhgm: &GradientMap,
    normals: &[Vec3],
    view: &ViewGeometry,
    set: &ApexSet,
    (x, y): (u32, u32),
    form: OcclusionForm,
) -> f32 {
    let i = mhm.index(x, y);
    if mhm.objects[i] == 0 {
        return 1.0;
    }
    let p = surface_point(mhm, normals, view, x, y);
    let n = match form {
        OcclusionForm::CosineWeighted => mesostructure_normal(mhm, mhgm, normals, view, (x, y)),
        OcclusionForm::Paper => normals[i],
    };
    let (sin_h, _) = super::lighting::horizons_about(mhm, normals, view, set, (x, y), p, n);
    sin_h
        .iter()
        .map(|&s| form.sector_visibility(s))
        .sum::<f32>()
        / OCCLUSION_SECTORS as f32
}

/// The brute-force, fixed-radius baseline (`Mesostructure::horizon_search_steps` > 0): along
/// each direction of `directions` (unit, screen space), `steps` samples out to `radius` pixels
/// on the same object; per direction the highest horizon; the form's integral over the
/// directions. Mirrors `horizon_search` in `occlusion.wgsl`.
#[allow(clippy::too_many_arguments)]
pub fn horizon_search_occlusion(
    mhm: &ScreenHeightMap,
    mhgm: &GradientMap,
    normals: &[Vec3],
    view: &ViewGeometry,
    (x, y): (u32, u32),
    directions: &[[f32; 2]],
    steps: u32,
    radius: u32,
    form: OcclusionForm,
) -> f32 {
    let i = mhm.index(x, y);
    let object = mhm.objects[i];
    if object == 0 {
        return 1.0;
    }
    let p = surface_point(mhm, normals, view, x, y);
    let n = match form {
        OcclusionForm::CosineWeighted => mesostructure_normal(mhm, mhgm, normals, view, (x, y)),
        OcclusionForm::Paper => normals[i],
    };
    let count = directions.len().max(1);
    let mut visibility = 0.0;
    for k in 0..count {
        let d = directions.get(k).copied().unwrap_or([0.0, 0.0]);
        let mut sin_h = 0.0f32;
        for j in 1..=steps {
            let o = |c: f32| (c * radius as f32 * j as f32 / steps as f32).round_ties_even() as i32;
            let (qx, qy) = (x as i32 + o(d[0]), y as i32 + o(d[1]));
            if !mhm.contains(qx, qy) || mhm.objects[mhm.index(qx as u32, qy as u32)] != object {
                break;
            }
            let v = surface_point(mhm, normals, view, qx as u32, qy as u32) - p;
            let len = v.length();
            if len > 0.0 {
                sin_h = sin_h.max((v.dot(n) / len).clamp(0.0, 1.0));
            }
        }
        visibility += form.sector_visibility(sin_h);
    }
    visibility / count as f32
}

/// The sector of a screen-space offset: `round(atan2(dy, dx) / (2π) · N) mod N`. The GPU
/// shader uses the same formula.
pub fn sector_of(dx: i32, dy: i32) -> usize {
    let a = (dy as f32).atan2(dx as f32) / std::f32::consts::TAU * OCCLUSION_SECTORS as f32;
    ((a + 0.5).floor() as i32).rem_euclid(OCCLUSION_SECTORS as i32) as usize
}
