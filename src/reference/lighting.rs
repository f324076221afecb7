//! Micro-shadows (paper §3.2) and one-bounce bleeding (§3.3, eq. 8) from the apex sets: the
//! oracle of the lighting and bleeding passes, step for step as `lighting.wgsl` and
//! `bleeding.wgsl` take them.

use bevy::math::{Vec3, Vec4Swizzles};

use super::{
    ApexSet, GradientMap, OCCLUSION_SECTORS, ScreenHeightMap, ViewGeometry, mesostructure_normal,
    sector_of, surface_point,
};

/// A pixel's surface point, the normal N' of the mesostructure surface there, and per azimuth
/// sector the horizon (sine of the elevation above the tangent plane of N') with the apex that
/// sets it (its screen offset).
#[derive(Clone, Debug, PartialEq)]
pub struct SectorHorizons {
    /// Surface point P (eq. 7).
    pub point: Vec3,
    /// N'.
    pub normal: Vec3,
    /// Sine of each sector's horizon, ≥ 0.
    pub sin_h: [f32; OCCLUSION_SECTORS],
    /// Offset of the apex that sets each sector's horizon.
    pub apex: [Option<(i32, i32)>; OCCLUSION_SECTORS],
}

/// The horizons of pixel `(x, y)` from its apex set; `None` where it has no mesostructure.
pub fn sector_horizons(
    mhm: &ScreenHeightMap,
    mhgm: &GradientMap,
    normals: &[Vec3],
    view: &ViewGeometry,
    set: &ApexSet,
    (x, y): (u32, u32),
) -> Option<SectorHorizons> {
    if mhm.objects[mhm.index(x, y)] == 0 {
        return None;
    }
    let point = surface_point(mhm, normals, view, x, y);
    let normal = mesostructure_normal(mhm, mhgm, normals, view, (x, y));
    let (sin_h, apex) = horizons_about(mhm, normals, view, set, (x, y), point, normal);
    Some(SectorHorizons {
        point,
        normal,
        sin_h,
        apex,
    })
}

/// Per azimuth sector, the highest horizon of the apexes of `set` seen from `point` above the
/// plane of `normal` (sine, clamped to [0, 1]), and the offset of the apex that sets it. Shared
/// by the occlusion, micro-shadow and bleeding oracles.
pub(crate) fn horizons_about(
    mhm: &ScreenHeightMap,
    normals: &[Vec3],
    view: &ViewGeometry,
    set: &ApexSet,
    (x, y): (u32, u32),
    point: Vec3,
    normal: Vec3,
) -> (
    [f32; OCCLUSION_SECTORS],
    [Option<(i32, i32)>; OCCLUSION_SECTORS],
) {
    let mut sin_h = [0.0; OCCLUSION_SECTORS];
    let mut apex = [None; OCCLUSION_SECTORS];
    for a in set.iter() {
        let d = surface_point(mhm, normals, view, a.x as u32, a.y as u32) - point;
        let len = d.length();
        if len <= 0.0 {
            continue;
        }
        let s = d.dot(normal) / len;
        let (dx, dy) = (a.x - x as i32, a.y - y as i32);
        let sector = sector_of(dx, dy);
        if s > sin_h[sector] {
            sin_h[sector] = s.min(1.0);
            apex[sector] = Some((dx, dy));
        }
    }
    (sin_h, apex)
}

/// Micro-shadow visibility (1 = lit) of the light seen from the pixel in direction `to_light`
/// (unit, world): the light's azimuth on screen placed between the two nearest profiles, the
/// horizon interpolated between them, and P in shadow where the light is lower above the
/// tangent plane than that horizon; soft over `softness` (in sine, at most the horizon's own
/// sine), hard at 0.
pub fn micro_shadow(view: &ViewGeometry, h: &SectorHorizons, to_light: Vec3, softness: f32) -> f32 {
    let sin_l = to_light.dot(h.normal);
    if sin_l <= 0.0 {
        return 1.0;
    }
    let tangential = to_light - h.normal * sin_l;
    let clip_from_world = view.world_from_clip.inverse();
    let c0 = clip_from_world * h.point.extend(1.0);
    let c1 = clip_from_world * (h.point + tangential * 0.01).extend(1.0);
    let s = (c1.xy() / c1.w - c0.xy() / c0.w) * bevy::math::Vec2::new(1.0, -1.0);
    if s == bevy::math::Vec2::ZERO {
        return 1.0;
    }
    let n = OCCLUSION_SECTORS as f32;
    let a = s.y.atan2(s.x) / std::f32::consts::TAU * n;
    let lower = a.floor();
    let i0 = (lower as i32).rem_euclid(OCCLUSION_SECTORS as i32) as usize;
    let i1 = (i0 + 1) % OCCLUSION_SECTORS;
    let horizon = h.sin_h[i0] + (h.sin_h[i1] - h.sin_h[i0]) * (a - lower);
    // The soft edge is never wider than the horizon itself: an open profile (horizon 0) leaves
    // every light above the tangent plane unshadowed.
    let w = softness.min(horizon);
    if w <= 0.0 {
        return if sin_l >= horizon { 1.0 } else { 0.0 };
    }
    let t = ((sin_l - horizon + w) / (2.0 * w)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// What the bleeding of one view gathers from: the lit opaque image (linear RGB, row-major) and
/// the normal each pixel faces with (its bump-mapped normal, or n0).
pub struct BleedingSources<'a> {
    /// Lit colour per pixel.
    pub lit: &'a [Vec3],
    /// Facing normal per pixel.
    pub normals: &'a [Vec3],
}

/// The one-bounce irradiance E_P of pixel `(x, y)` (paper eq. 8, area-weighted): per sector,
/// `samples` points S on the screen line to the apex that sets the sector's horizon; each
/// visible S that faces P adds its lit colour times the cosine-weighted solid angle of the band
/// of elevation it stands for, `(sin² e_j − sin² e_{j−1}) / 2 · 2π / sectors`. The pass writes
/// `λd · ρ_P / π · E_P`.
#[allow(clippy::too_many_arguments)]
pub fn bleeding_irradiance(
    mhm: &ScreenHeightMap,
    mhgm: &GradientMap,
    normals: &[Vec3],
    view: &ViewGeometry,
    set: &ApexSet,
    (x, y): (u32, u32),
    sources: &BleedingSources,
    samples: u32,
) -> Vec3 {
    let Some(h) = sector_horizons(mhm, mhgm, normals, view, set, (x, y)) else {
        return Vec3::ZERO;
    };
    let samples = samples.max(1);
    let mut irradiance = Vec3::ZERO;
    for sector in 0..OCCLUSION_SECTORS {
        let Some((ox, oy)) = h.apex[sector] else {
            continue;
        };
        let mut seen = 0.0f32;
        let mut last = (0, 0);
        for j in 1..=samples {
            let t = j as f32 / samples as f32;
            // WGSL's round() rounds halves to even.
            let q = (
                (ox as f32 * t).round_ties_even() as i32,
                (oy as f32 * t).round_ties_even() as i32,
            );
            if q == last {
                continue;
            }
            last = q;
            let (qx, qy) = (x as i32 + q.0, y as i32 + q.1);
            if !mhm.contains(qx, qy) || mhm.objects[mhm.index(qx as u32, qy as u32)] == 0 {
                break;
            }
            let d = surface_point(mhm, normals, view, qx as u32, qy as u32) - h.point;
            let len = d.length();
            if len <= 0.0 {
                continue;
            }
            let s = d.dot(h.normal) / len;
            if s <= seen {
                continue;
            }
            let i = mhm.index(qx as u32, qy as u32);
            if sources.normals[i].dot(-d) > 0.0 {
                irradiance += sources.lit[i] * (s * s - seen * seen) * 0.5;
            }
            seen = s;
        }
    }
    irradiance * std::f32::consts::TAU / OCCLUSION_SECTORS as f32
}
