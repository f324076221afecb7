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
    // The lighting and bleeding passes read them from the occlusion pass's sector record.
    Some(
        SectorHorizons {
            point,
            normal,
            sin_h,
            apex,
        }
        .as_stored(),
    )
}

impl SectorHorizons {
    /// These horizons as the lighting and bleeding passes read them back from the sector record
    /// ([`sector_record`]): sines and N' quantised; a sector whose sine rounds to 0 is open
    /// (no apex).
    pub fn as_stored(&self) -> Self {
        let index = std::array::from_fn(|s| s as u32);
        let (sin_h, normal, _) =
            sector_record::unpack(sector_record::pack(&self.sin_h, self.normal, &index));
        Self {
            point: self.point,
            normal,
            sin_h,
            apex: std::array::from_fn(|s| self.apex[s].filter(|_| sin_h[s] > 0.0)),
        }
    }
}

/// The sector record the occlusion pass stores per pixel for the lighting and bleeding passes
/// (one `Rgba32Uint` texel; `surface.wgsl` packs and reads it), so that each pixel's horizons
/// and N' are found once rather than once per pass: words 0 and 1 the sine of each sector's
/// horizon as 8-bit unorm (sectors 0–3, 4–7); word 2 bits 0–21 N' in octahedral form (two
/// 11-bit unorm); word 2 bits 22–31 and word 3 bits 0–29 the index in the apex set of the apex
/// that sets each sector's horizon (5 bits each: sectors 0–1, then 2–7). 8 bits of sine are
/// 0.002 at most, a quarter of a degree of elevation; 11 bits of octahedral normal about 0.1°.
pub mod sector_record {
    use super::OCCLUSION_SECTORS;
    use bevy::math::{Vec2, Vec2Swizzles, Vec3, Vec3Swizzles};

    /// Levels of a stored sine.
    pub const SINE_LEVELS: f32 = 255.0;
    /// Bits of each octahedral coordinate of N'.
    pub const NORMAL_BITS: u32 = 11;
    /// Bits of a sector's apex index (an apex set holds at most 17 apexes).
    pub const APEX_INDEX_BITS: u32 = 5;

    fn quantize_unorm(v: f32, levels: f32) -> u32 {
        (0.5 + levels * v.clamp(0.0, 1.0)).floor() as u32
    }

    fn bits(word: u32, offset: u32, count: u32) -> u32 {
        (word >> offset) & ((1 << count) - 1)
    }

    /// The unit vector `n` as a point of the octahedron unfolded onto [-1, 1]².
    pub fn octahedral_encode(n: Vec3) -> Vec2 {
        let p = n.xy() / (n.x.abs() + n.y.abs() + n.z.abs());
        if n.z >= 0.0 {
            return p;
        }
        let sign = Vec2::new(
            if p.x >= 0.0 { 1.0 } else { -1.0 },
            if p.y >= 0.0 { 1.0 } else { -1.0 },
        );
        (Vec2::ONE - p.yx().abs()) * sign
    }

    /// The unit vector of an octahedral point.
    pub fn octahedral_decode(e: Vec2) -> Vec3 {
        let mut n = Vec3::new(e.x, e.y, 1.0 - e.x.abs() - e.y.abs());
        let fold = (-n.z).max(0.0);
        n.x += if n.x >= 0.0 { -fold } else { fold };
        n.y += if n.y >= 0.0 { -fold } else { fold };
        n.normalize()
    }

    /// Word and first bit of a sector's apex index.
    fn apex_index_field(sector: usize) -> (usize, u32) {
        if sector < 2 {
            (2, 2 * NORMAL_BITS + sector as u32 * APEX_INDEX_BITS)
        } else {
            (3, (sector as u32 - 2) * APEX_INDEX_BITS)
        }
    }

    /// Packs the sines of the sector horizons, N' and each sector's apex index.
    pub fn pack(
        sin_h: &[f32; OCCLUSION_SECTORS],
        normal: Vec3,
        apex_index: &[u32; OCCLUSION_SECTORS],
    ) -> [u32; 4] {
        let mut r = [0u32; 4];
        for (s, &sine) in sin_h.iter().enumerate() {
            r[s / 4] |= quantize_unorm(sine, SINE_LEVELS) << ((s % 4) * 8);
            let (word, offset) = apex_index_field(s);
            r[word] |= (apex_index[s] & ((1 << APEX_INDEX_BITS) - 1)) << offset;
        }
        let levels = ((1u32 << NORMAL_BITS) - 1) as f32;
        let e = octahedral_encode(normal) * 0.5 + 0.5;
        r[2] |= quantize_unorm(e.x, levels) | quantize_unorm(e.y, levels) << NORMAL_BITS;
        r
    }

    /// The sines, N' and apex indices of a record.
    pub fn unpack(r: [u32; 4]) -> ([f32; OCCLUSION_SECTORS], Vec3, [u32; OCCLUSION_SECTORS]) {
        let sin_h = std::array::from_fn(|s| bits(r[s / 4], (s % 4) as u32 * 8, 8) as f32 / SINE_LEVELS);
        let index = std::array::from_fn(|s| {
            let (word, offset) = apex_index_field(s);
            bits(r[word], offset, APEX_INDEX_BITS)
        });
        let levels = ((1u32 << NORMAL_BITS) - 1) as f32;
        let e = Vec2::new(
            bits(r[2], 0, NORMAL_BITS) as f32,
            bits(r[2], NORMAL_BITS, NORMAL_BITS) as f32,
        ) / levels;
        (sin_h, octahedral_decode(e * 2.0 - 1.0), index)
    }

    #[cfg(test)]
    mod tests {
        use super::*;

        #[test]
        fn records_round_trip_within_their_quantisation() {
            let mut worst_angle = 0.0f32;
            for i in 0..2000 {
                // Directions over the whole sphere (a Fibonacci spiral), both hemispheres.
                let z = 1.0 - 2.0 * (i as f32 + 0.5) / 2000.0;
                let a = i as f32 * 2.399_963;
                let r = (1.0 - z * z).sqrt();
                let n = Vec3::new(r * a.cos(), r * a.sin(), z);
                let sin_h = std::array::from_fn(|s| ((i * 7 + s * 13) % 101) as f32 / 100.0);
                let index = std::array::from_fn(|s| ((i + s * 5) % 17) as u32);
                let (sines, normal, indices) = unpack(pack(&sin_h, n, &index));
                assert_eq!(indices, index);
                for s in 0..OCCLUSION_SECTORS {
                    assert!((sines[s] - sin_h[s]).abs() <= 0.5 / SINE_LEVELS + 1e-6);
                }
                worst_angle = worst_angle.max(normal.dot(n).clamp(-1.0, 1.0).acos().to_degrees());
            }
            // 11 bits per octahedral coordinate: about 0.1° at worst.
            assert!(worst_angle < 0.15, "worst N' error {worst_angle}°");
        }
    }
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
