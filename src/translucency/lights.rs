//! The lights' direct contribution to the patches (the CPU oracle of the injection): each
//! patch's irradiance `E⁰` with one shadow ray, and on translucent patches the single
//! scattering of each beam at its own incidence, or each beam for the transport's beam table.

use bevy::{math::DVec3, prelude::*};

use super::{
    patches::Patches,
    transport::{EnergyTransport, SceneRays, parallel_rows},
};
use crate::volumetric::reference::SpotLight as ReferenceSpot;

/// The lights' direct contribution to the patches.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DirectLight {
    /// Irradiance `E⁰` per patch; on translucent patches each light's weighted by its
    /// incidence where the transport says so ([`EnergyTransport::incidence`]).
    pub irradiance: Vec<Vec3>,
    /// Exitance `S⁰` per patch besides `K E⁰` (may be empty: none): on translucent patches,
    /// the single scattering of each beam at its own incidence less the diffuse mean `K`
    /// already holds.
    pub exitance: Vec<Vec3>,
    /// The part of `irradiance` per patch that the transport's
    /// [`BeamTable`](super::beam_table::BeamTable) carries (may be empty: none): `K` takes
    /// the rest.
    pub tabled: Vec<Vec3>,
    /// That irradiance by table direction (`slot · bins + bin`, each beam over the four
    /// directions about it by their weights: `BeamTable::light_index`; empty without a
    /// table).
    pub beam_light: Vec<Vec3>,
    /// Per patch with a table, its beams' irradiance at normal incidence (shadowed), summed:
    /// what single scattering by the lit face leaves by (`single_scattering_radiance`, in the
    /// gather). Empty without a table.
    pub beam_irradiance: Vec<Vec3>,
    /// Per patch with a table, its beams' travel directions weighted by their irradiance at
    /// normal incidence (unnormalised; the gather takes the mean). Empty without a table.
    pub beam_direction: Vec<Vec3>,
    /// Per patch with a table, the exitance of single scattering by its lit face, each beam
    /// at its own incidence ([`lit_face_exitance`](super::beam_table::lit_face_exitance)).
    /// The gather gives that light per pixel, so it is not in `B`; it joins `B` only as what
    /// the first bounce gathers (`F`), lighting the other patches. Empty without a table.
    pub lit_face_exitance: Vec<Vec3>,
}

/// A light as the transport injects it (Bevy's conventions: colour × intensity per channel).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PatchLight {
    /// A directional light.
    Directional {
        /// The way the light travels (unit).
        direction: Vec3,
        /// Illuminance on a surface facing it, per channel.
        illuminance: Vec3,
    },
    /// A point light.
    Point {
        /// Position.
        position: Vec3,
        /// Luminous intensity per channel (Bevy: lumens / 4π).
        intensity: Vec3,
        /// Bevy's range.
        range: f32,
    },
    /// A spot light.
    Spot {
        /// Position.
        position: Vec3,
        /// Axis (unit).
        direction: Vec3,
        /// Luminous intensity on the axis per channel (Bevy: lumens / 4π).
        intensity: Vec3,
        /// Inner half-angle, radians.
        inner_angle: f32,
        /// Outer half-angle, radians.
        outer_angle: f32,
        /// Bevy's range.
        range: f32,
    },
}

impl PatchLight {
    /// The way the light travels onto a small object about `centre` (a point or spot light:
    /// from its position to the centre; `None` where it sits there, or for a zero
    /// direction).
    pub fn travel_towards(&self, centre: Vec3) -> Option<Vec3> {
        match *self {
            PatchLight::Directional { direction, .. } => direction.try_normalize(),
            PatchLight::Point { position, .. } | PatchLight::Spot { position, .. } => {
                (centre - position).try_normalize()
            }
        }
    }

    /// The light's irradiance at `x` across its travel, unshadowed: Bevy's fall-off, cone and
    /// range window for a point or spot light (`translucent_light` in `inject.wgsl`).
    pub fn irradiance_across(&self, x: Vec3) -> Vec3 {
        let (position, intensity, cone, range) = match *self {
            PatchLight::Directional { illuminance, .. } => return illuminance,
            PatchLight::Point { position, intensity, range } => (position, intensity, None, range),
            PatchLight::Spot { position, direction, intensity, inner_angle, outer_angle, range } => {
                (position, intensity, Some((direction, inner_angle, outer_angle)), range)
            }
        };
        let dist2 = position.distance_squared(x);
        if !(dist2 > 1e-20) {
            return Vec3::ZERO;
        }
        // Bevy's fall-off and range window, one copy (the volumetric reference's).
        let spot = ReferenceSpot {
            position: position.as_dvec3(),
            direction: cone.map_or(DVec3::Z, |c| c.0.as_dvec3().normalize_or_zero()),
            intensity: 1.0,
            inner_angle: cone.map_or(0.0, |c| c.1 as f64),
            outer_angle: cone.map_or(0.0, |c| c.2 as f64),
            range: range as f64,
        };
        let falloff = if cone.is_some() { spot.falloff(x.as_dvec3()) } else { 1.0 };
        intensity * ((falloff * spot.range_window(dist2.sqrt() as f64)) as f32 / dist2)
    }
}

impl PatchLight {
    /// The most irradiance across its travel this light gives anywhere in the sphere about
    /// `centre` of `radius`, unshadowed: zero where its range window, or a spot's cone, leaves
    /// the whole sphere dark; infinite where a point or spot light sits inside it; zero for a
    /// light with a non-finite number (Bevy would not draw it either). What the lights are
    /// culled and ranked by ([`lights_reaching`]).
    pub fn irradiance_bound(&self, centre: Vec3, radius: f32) -> Vec3 {
        // Every number finite, but a range may be unbounded.
        let numbers = light_numbers(self);
        let range_at = match self {
            PatchLight::Directional { .. } => None,
            _ => Some(numbers.len() - 1),
        };
        let finite = numbers.iter().enumerate().all(|(k, x)| x.is_finite() || (Some(k) == range_at && *x == f32::INFINITY));
        if !finite {
            return Vec3::ZERO;
        }
        let (position, intensity, axis) = match *self {
            PatchLight::Directional { illuminance, .. } => return illuminance.max(Vec3::ZERO),
            PatchLight::Point { position, intensity, .. } => (position, intensity, None),
            PatchLight::Spot { position, direction, intensity, .. } => (position, intensity, Some(direction)),
        };
        let to_centre = centre - position;
        let d = to_centre.length();
        let nearest = d - radius;
        if !(nearest * nearest > 1e-20) || nearest < 0.0 {
            return intensity.max(Vec3::ZERO).map(|i| if i > 0.0 { f32::INFINITY } else { 0.0 });
        }
        let towards = to_centre / d;
        // Every point of the sphere is at least `nearest` from the light and at least the
        // sphere's half-angle nearer a spot's axis than its centre: the fall-off, the cone
        // and the range window each fall away from there, so their value at that distance
        // and angle bounds them all.
        let direction = match axis.map(Vec3::normalize_or_zero) {
            Some(axis) if axis != Vec3::ZERO => {
                let half = (radius / d).clamp(0.0, 1.0).asin();
                let angle = axis.dot(towards).clamp(-1.0, 1.0).acos();
                if angle <= half {
                    axis
                } else {
                    let across = (axis - towards * axis.dot(towards))
                        .try_normalize()
                        .unwrap_or_else(|| towards.any_orthonormal_vector());
                    towards * half.cos() + across * half.sin()
                }
            }
            _ => towards,
        };
        self.irradiance_across(position + direction * nearest).max(Vec3::ZERO)
    }
}

/// The lights the transport takes out of a scene's ([`lights_reaching`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ReachingLights {
    /// The lights taken, in the order given.
    pub lights: Vec<PatchLight>,
    /// Lights left out because none of their light can reach the participants (lossless).
    pub unreachable: usize,
    /// Lights that reach the participants but were left out for the `most` brighter ones.
    pub left_out: usize,
    /// Their share of the reaching lights' summed [`PatchLight::irradiance_bound`] (0 – 1):
    /// at most what they would have added.
    pub left_out_share: f32,
}

/// Of `lights`, those whose light can reach the participants within the sphere about
/// `centre` of `radius` ([`PatchLight::irradiance_bound`] above zero), and of them at most
/// `most`: the brightest by that bound, kept in the order given (so that a light's place,
/// and the GPU's maps for it, change only when the choice does).
pub fn lights_reaching(lights: &[PatchLight], centre: Vec3, radius: f32, most: usize) -> ReachingLights {
    // Finite ranks for the lights inside the sphere, so that shares stay numbers.
    let cap = f32::MAX / (lights.len() as f32 + 1.0);
    let mut by_brightness: Vec<(usize, f32)> = lights
        .iter()
        .enumerate()
        .map(|(i, l)| (i, l.irradiance_bound(centre, radius).element_sum().min(cap)))
        .filter(|&(_, bound)| bound > 0.0)
        .collect();
    by_brightness.sort_by(|a, b| b.1.total_cmp(&a.1));
    let total: f32 = by_brightness.iter().map(|r| r.1).sum();
    let left: f32 = by_brightness.iter().skip(most).map(|r| r.1).sum();
    let mut taken: Vec<usize> = by_brightness.iter().take(most).map(|r| r.0).collect();
    taken.sort_unstable();
    ReachingLights {
        lights: taken.iter().map(|&i| lights[i]).collect(),
        unreachable: lights.len() - by_brightness.len(),
        left_out: by_brightness.len().saturating_sub(most),
        left_out_share: if total > 0.0 { left / total } else { 0.0 },
    }
}

/// A light's numbers (position, direction, intensity, angles, range): what says whether it
/// changed, and whether it is finite.
pub fn light_numbers(light: &PatchLight) -> Vec<f32> {
    match *light {
        PatchLight::Directional { direction, illuminance } => [direction.to_array(), illuminance.to_array()].concat(),
        PatchLight::Point { position, intensity, range } => {
            [position.to_array().as_slice(), &intensity.to_array(), &[range]].concat()
        }
        PatchLight::Spot { position, direction, intensity, inner_angle, outer_angle, range } => [
            position.to_array().as_slice(),
            &direction.to_array(),
            &intensity.to_array(),
            &[inner_angle, outer_angle, range],
        ]
        .concat(),
    }
}

/// Each patch's direct irradiance `E⁰` from `lights`, shadowed by one ray from its centre:
/// `LightInjection::ShadowRays`, and the CPU oracle of the GPU's light-view injection
/// (`injection/`).
pub fn direct_irradiance(patches: &Patches, lights: &[PatchLight], rays: &SceneRays) -> Vec<Vec3> {
    direct_light(patches, None, lights, rays).irradiance
}

/// [`direct_irradiance`], and with `transport` the single-scattering exitance `S⁰` of each
/// beam at its incidence, or — on the patches its beam table covers — each beam's light that
/// got in by table direction, for the table instead of `K` (see [`DirectLight`]).
pub fn direct_light(
    patches: &Patches,
    transport: Option<&EnergyTransport>,
    lights: &[PatchLight],
    rays: &SceneRays,
) -> DirectLight {
    let diffuse_shape = super::diffusion::diffuse_single_scattering_shape() as f32;
    let table = transport.and_then(|t| t.beam_table.as_ref());
    let per_patch = parallel_rows(patches.patches.len(), |i| {
        let p = &patches.patches[i];
        let x = p.surface_point + p.normal * (0.05 * patches.size_of(i));
        let single = transport
            .and_then(|t| t.single_scattering.get(i))
            .copied()
            .unwrap_or(Vec3::ZERO);
        let incidence = transport
            .and_then(|t| t.incidence.get(p.object as usize))
            .copied()
            .flatten();
        let (mut irradiance, mut exitance) = (Vec3::ZERO, Vec3::ZERO);
        // With a beam table: (light index, irradiance that got in), and the beams' normal
        // irradiance and weighted direction for single scattering's law.
        let mut beams: Vec<(usize, Vec3)> = Vec::new();
        let (mut normal_irradiance, mut direction, mut lit_face) = (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
        // The medium's (α, η) where the patch has a table slot.
        let medium = table.and_then(|t| t.patch_medium(i));
        for light in lights {
            let (e, to_light) = match *light {
                PatchLight::Directional {
                    direction,
                    illuminance,
                } => {
                    let to_light = -direction.normalize_or_zero();
                    let cos = p.normal.dot(to_light);
                    let e = if cos > 0.0 && rays.free(x, to_light, f32::INFINITY) {
                        illuminance * cos
                    } else {
                        Vec3::ZERO
                    };
                    (e, to_light)
                }
                PatchLight::Point { position, .. } | PatchLight::Spot { position, .. } => (
                    point_irradiance(light, p.normal, x, position, rays),
                    (position - x).normalize_or_zero(),
                ),
            };
            let cos = p.normal.dot(to_light);
            if let Some((at, entering)) = table
                .filter(|_| e != Vec3::ZERO)
                .and_then(|t| t.light_index(patches, i, -to_light))
            {
                // The table's columns hold the beam's incidence and its scattering.
                let got_in = e * entering;
                irradiance += got_in;
                beams.extend(at.into_iter().filter(|&(_, w)| w > 0.0).map(|(at, w)| (at, got_in * w)));
                normal_irradiance += e / cos;
                direction += -to_light * ((e / cos).element_sum());
                if let Some(m) = medium {
                    lit_face += super::beam_table::lit_face_exitance(m.truncate(), m.w, e / cos, cos);
                }
                continue;
            }
            // A beam takes in and gives back by its own incidence, not by the diffuse
            // albedo `K` holds (Chandrasekhar's plane albedo; `IncidenceWeight`).
            let e = match incidence {
                Some(weight) if e != Vec3::ZERO => {
                    let w = weight.at(p.normal.dot(to_light) as f64);
                    e * Vec3::new(w[0] as f32, w[1] as f32, w[2] as f32)
                }
                _ => e,
            };
            irradiance += e;
            if single != Vec3::ZERO && e != Vec3::ZERO {
                let shape =
                    super::diffusion::single_scattering_shape(p.normal.dot(to_light) as f64) as f32;
                exitance += single * e * (shape - diffuse_shape);
            }
        }
        (irradiance, exitance, beams, normal_irradiance, direction, lit_face)
    });
    let has_single =
        transport.is_some_and(|t| t.single_scattering.iter().any(|s| *s != Vec3::ZERO));
    let mut direct = DirectLight {
        exitance: if has_single {
            per_patch.iter().map(|d| d.1).collect()
        } else {
            Vec::new()
        },
        irradiance: per_patch.iter().map(|d| d.0).collect(),
        ..default()
    };
    if let Some(table) = table {
        direct.beam_light = vec![Vec3::ZERO; table.media.len() * table.bins() as usize];
        direct.tabled = vec![Vec3::ZERO; per_patch.len()];
        for (i, (_, _, beams, _, _, _)) in per_patch.iter().enumerate() {
            for &(at, got_in) in beams {
                direct.beam_light[at] += got_in;
                direct.tabled[i] += got_in;
            }
        }
        direct.beam_irradiance = per_patch.iter().map(|d| d.3).collect();
        direct.beam_direction = per_patch.iter().map(|d| d.4).collect();
        direct.lit_face_exitance = per_patch.iter().map(|d| d.5).collect();
    }
    direct
}

/// A point or spot light's irradiance on a surface of unit `normal` at `x`
/// ([`PatchLight::irradiance_across`] times the incidence cosine), shadowed by one ray.
fn point_irradiance(light: &PatchLight, normal: Vec3, x: Vec3, position: Vec3, rays: &SceneRays) -> Vec3 {
    let d = position - x;
    let cos = normal.dot(d) / d.length();
    if !(cos > 0.0) {
        return Vec3::ZERO;
    }
    let e = light.irradiance_across(x) * cos;
    if e.max_element() > 0.0 && rays.visible(x, position) { e } else { Vec3::ZERO }
}
