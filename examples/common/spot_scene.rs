//! Issue 12's reference set-up for the volumetric spots, shared by the `volumetric_bench`
//! example and the integration tests: a spot at (0, 4, 0) aimed at (0.5, 0, 0), outer 30°,
//! inner 20°, 20 000 lm, range 100, over a black 20 × 20 floor, optionally a 1 m cube at
//! (0, 2.5, 0); σs 0.10, σa 0.01. And its exact fog-only radiance per pixel.

use bevy::{
    camera::Exposure,
    math::{DVec2, DVec3, DVec4},
    prelude::*,
};
use bevy_mesostructure::volumetric::reference::{self, Medium, Occluder, Sampling};

/// The cameras' exposure (linear radiance × 2^−3 / 1.2 lands mid-range).
pub const EV100: f32 = 3.0;
/// Where the spot hangs.
pub const SPOT_POSITION: Vec3 = Vec3::new(0.0, 4.0, 0.0);
/// Where it points.
pub const SPOT_AIM: Vec3 = Vec3::new(0.5, 0.0, 0.0);
/// Its scattering and absorption coefficients, per metre.
pub const SCATTERING: f32 = 0.10;
pub const ABSORPTION: f32 = 0.01;

/// The spot as Bevy lights it.
pub fn bevy_spot(shadow_maps_enabled: bool) -> SpotLight {
    SpotLight {
        intensity: 20_000.0,
        range: 100.0,
        outer_angle: 30f32.to_radians(),
        inner_angle: 20f32.to_radians(),
        shadow_maps_enabled,
        ..default()
    }
}

/// Its transform.
pub fn spot_transform() -> Transform {
    Transform::from_translation(SPOT_POSITION).looking_at(SPOT_AIM, Vec3::Z)
}

/// The cube's box, and where the cube mesh stands.
pub fn cube() -> Occluder {
    Occluder {
        min: DVec3::new(-0.5, 2.0, -0.5),
        max: DVec3::new(0.5, 3.0, 0.5),
    }
}

/// Where the view ray from `o` along `d` ends: the floor (y = 0, 20 × 20), the first of
/// `occluders` it enters, the exit of `volume` (a bounded medium), or nowhere (1e30).
pub fn ray_end(o: DVec3, d: DVec3, occluders: &[Occluder], volume: Option<&Occluder>) -> f64 {
    let t_floor = -o.y / d.y;
    let hit = o + d * t_floor;
    let mut end = if d.y < 0.0 && hit.x.abs() <= 10.0 && hit.z.abs() <= 10.0 {
        t_floor
    } else {
        1.0e30
    };
    for b in occluders {
        let (near, far) = slabs(o, d, b);
        if near <= far && far > 0.0 {
            end = end.min(near.max(0.0));
        }
    }
    if let Some(v) = volume {
        let (near, far) = slabs(o, d, v);
        end = end.min(if near <= far { far.max(0.0) } else { 0.0 });
    }
    end
}

fn slabs(o: DVec3, d: DVec3, b: &Occluder) -> (f64, f64) {
    let (mut near, mut far) = (f64::NEG_INFINITY, f64::INFINITY);
    for axis in 0..3 {
        let (t0, t1) = ((b.min[axis] - o[axis]) / d[axis], (b.max[axis] - o[axis]) / d[axis]);
        near = near.max(t0.min(t1));
        far = far.min(t0.max(t1));
    }
    (near, far)
}

/// Per pixel of a `size` view (`world_from_view` the camera's transform, `clip_from_view` its
/// projection): the exact fog-only radiance (exposure applied) in a medium of asymmetry `g`,
/// where asked the `n`-sample estimate with `sampling` (the CPU mirror of a pass; empty
/// otherwise), and whether the ray passes within 15° of the light.
pub struct Truth {
    pub exact: Vec<f64>,
    pub estimate: Vec<f64>,
    pub tip: Vec<bool>,
    /// Per pixel, the angle between its ray and the direction to the light, degrees.
    pub angle_to_light: Vec<f32>,
}

/// The set-up's spot as the reference lights with it ([`bevy_spot`]'s light).
pub fn reference_light() -> reference::SpotLight {
    reference::SpotLight {
        position: SPOT_POSITION.as_dvec3(),
        direction: (SPOT_AIM - SPOT_POSITION).normalize().as_dvec3(),
        intensity: 20_000.0 / (4.0 * std::f64::consts::PI),
        inner_angle: 20f64.to_radians(),
        outer_angle: 30f64.to_radians(),
        range: 100.0,
    }
}

pub fn truth(
    world_from_view: Mat4,
    clip_from_view: Mat4,
    size: UVec2,
    g: f32,
    occluders: &[Occluder],
    volume: Option<&Occluder>,
    estimator: Option<(Sampling, u32)>,
) -> Truth {
    let spot = reference_light();
    let medium = Medium {
        scattering: SCATTERING as f64,
        absorption: ABSORPTION as f64,
        asymmetry: g as f64,
    };
    let exposure = Exposure { ev100: EV100 }.exposure() as f64;
    // In f64 from the view's own frame: a direction taken as (near-plane point − eye) in f32
    // world space loses ~1e-5 rad to cancellation (the near plane is 0.1 m from an eye metres
    // from the origin), which near the light, where the in-scatter goes as 1/h, is a visible
    // error at 1080p.
    let world_from_view = world_from_view.as_dmat4();
    let view_from_clip = clip_from_view.as_dmat4().inverse();
    let o = world_from_view.w_axis.truncate();
    let to_light = (SPOT_POSITION.as_dvec3() - o).normalize();
    let mut t = Truth {
        exact: vec![],
        estimate: vec![],
        tip: vec![],
        angle_to_light: vec![],
    };
    for y in 0..size.y {
        for x in 0..size.x {
            let ndc = DVec2::new(
                (x as f64 + 0.5) / size.x as f64 * 2.0 - 1.0,
                1.0 - (y as f64 + 0.5) / size.y as f64 * 2.0,
            );
            // Through the pixel's centre, from the camera (the medium starts there).
            let near = view_from_clip * DVec4::new(ndc.x, ndc.y, 1.0, 1.0);
            let d = world_from_view.transform_vector3(near.truncate() / near.w).normalize();
            let ray = reference::Ray {
                origin: o,
                direction: d,
                start: 0.0,
                end: ray_end(o, d, occluders, volume),
            };
            t.exact
                .push(reference::in_scattered(&ray, &spot, &medium, occluders) * exposure);
            if let Some((sampling, n)) = estimator {
                t.estimate.push(
                    reference::estimate(&ray, &spot, &medium, occluders, sampling, n) * exposure,
                );
            }
            let angle = d.dot(to_light).clamp(-1.0, 1.0).acos().to_degrees() as f32;
            t.tip.push(angle < 15.0);
            t.angle_to_light.push(angle);
        }
    }
    t
}

/// Σ|a − b| / Σ b over the pixels where `b` is above 1 % of its largest value (and `mask`
/// holds, where given).
pub fn relative_l1<A: Copy + Into<f64>>(a: &[A], b: &[f64], mask: Option<&[bool]>) -> f64 {
    let max = b.iter().cloned().fold(0.0, f64::max);
    let (mut num, mut den) = (0.0, 0.0);
    for (i, (&a, &b)) in a.iter().zip(b).enumerate() {
        if b > 0.01 * max && mask.is_none_or(|m| m[i]) {
            num += (a.into() - b).abs();
            den += b;
        }
    }
    num / den
}

/// The red channel of an `Rgba16Float` image (linear, exposure applied), row-major.
pub fn red(image: &Image) -> Vec<f32> {
    image
        .data
        .as_ref()
        .expect("image data")
        .chunks_exact(8)
        .map(|px| half::f16::from_le_bytes([px[0], px[1]]).to_f32())
        .collect()
}
