//! A beam's table directions: incidence cosines `(k + ½)/cosines` times azimuths about the
//! patch's normal, in a frame fixed by the normal alone.

use bevy::prelude::*;

/// The frame a patch's table directions are measured in: a tangent and bitangent fixed by
/// its normal alone (Duff et al. 2017, "Building an orthonormal basis, revisited", the sign
/// taken as `z ≥ 0`; `tangent_frame` in `boundary.wgsl` is its twin).
pub(crate) fn tangent_frame(normal: Vec3) -> (Vec3, Vec3) {
    let sign = if normal.z >= 0.0 { 1.0 } else { -1.0 };
    let a = -1.0 / (sign + normal.z);
    let b = normal.x * normal.y * a;
    (
        Vec3::new(1.0 + sign * normal.x * normal.x * a, sign * b, -sign * normal.x),
        Vec3::new(b, sign + normal.y * normal.y * a, -normal.y),
    )
}

/// The table direction nearest a beam travelling along the unit `travel` onto a patch of
/// unit `normal`: its incidence cosine `μ = −travel·n` rounded down to `(k + ½)/cosines`'s
/// bin, its azimuth to the nearest of `azimuths`; `bin = k · azimuths + m`. `None` for a beam
/// along or behind the surface.
pub fn direction_bin(travel: Vec3, normal: Vec3, cosines: u32, azimuths: u32) -> Option<u32> {
    let (mu, turns) = incidence_and_turns(travel, normal, cosines, azimuths)?;
    let m = turns.round().rem_euclid(azimuths as f32) as u32;
    let k = ((mu * cosines as f32) as u32).min(cosines - 1);
    Some(k * azimuths + m.min(azimuths - 1))
}

/// A beam's incidence cosine `μ = −travel·n` onto a patch of unit `normal` and its azimuth
/// in the patch's frame ([`tangent_frame`]) in steps of the table's azimuths (not wrapped);
/// `None` for a beam along or behind the surface or an empty table.
fn incidence_and_turns(travel: Vec3, normal: Vec3, cosines: u32, azimuths: u32) -> Option<(f32, f32)> {
    let mu = -travel.dot(normal);
    if !(mu > 0.0) || cosines == 0 || azimuths == 0 {
        return None;
    }
    let (t, b) = tangent_frame(normal);
    let along = travel + mu * normal;
    let step = std::f32::consts::TAU / azimuths as f32;
    Some((mu, along.dot(b).atan2(along.dot(t)) / step))
}

/// The table directions about a beam travelling along the unit `travel` onto a patch of unit
/// `normal`, with their weights: bilinear in the incidence cosine between the bins' centres
/// `(k + ½)/cosines` (held at the first and last) and in the azimuth between its two
/// neighbours (round the circle). Four `(bin, weight)` pairs, weights summing to 1 (a pair
/// may repeat a bin); `None` as for [`direction_bin`].
pub fn direction_weights(travel: Vec3, normal: Vec3, cosines: u32, azimuths: u32) -> Option<[(u32, f32); 4]> {
    let (mu, turns) = incidence_and_turns(travel, normal, cosines, azimuths)?;
    let turn = turns.rem_euclid(azimuths as f32);
    let m0 = (turn.floor() as u32).min(azimuths - 1);
    let (m1, g) = ((m0 + 1) % azimuths, (turn - m0 as f32).clamp(0.0, 1.0));
    let place = (mu.min(1.0) * cosines as f32 - 0.5).clamp(0.0, (cosines - 1) as f32);
    let k0 = (place.floor() as u32).min(cosines - 1);
    let (k1, f) = ((k0 + 1).min(cosines - 1), place - k0 as f32);
    Some([
        (k0 * azimuths + m0, (1.0 - f) * (1.0 - g)),
        (k0 * azimuths + m1, (1.0 - f) * g),
        (k1 * azimuths + m0, f * (1.0 - g)),
        (k1 * azimuths + m1, f * g),
    ])
}

/// The travel direction of table direction `bin` onto a patch of unit `normal` (see
/// [`direction_bin`]).
pub fn bin_direction(bin: u32, normal: Vec3, cosines: u32, azimuths: u32) -> Vec3 {
    let (k, m) = (bin / azimuths.max(1), bin % azimuths.max(1));
    let mu = (k as f32 + 0.5) / cosines.max(1) as f32;
    let azimuth = std::f32::consts::TAU * m as f32 / azimuths.max(1) as f32;
    let (t, b) = tangent_frame(normal);
    let sine = (1.0 - mu * mu).max(0.0).sqrt();
    (sine * (azimuth.cos() * t + azimuth.sin() * b) - mu * normal).normalize()
}
