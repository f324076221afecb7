//! A light tracer of a closed triangle mesh of homogeneous medium (index-matched boundary,
//! isotropic phase): the reference for scenes a camera path tracer cannot converge. Lit from
//! behind, Mitsuba's `volpathmis` has to find the light by walks started at the camera, and
//! in marble (albedo 0.999, walks of hundreds of scatterings) the few that wander to the lit
//! side are fireflies: four 8192-sample renders of the marble bunny lit from behind differ
//! from each other by 0.22 – 0.38 in relative L1. This tracer runs the walks from the light
//! and sends each collision's in-scattered light to the pinhole camera, so every
//! contribution is bounded (transmittance ≤ 1, the eye outside the object), as
//! `tools/translucent_light_tracer.py` does on an analytic sphere.
//!
//! - Photons start uniformly over the disc of the mesh's bounding sphere seen from the light
//!   (irradiance 1 on a plane facing it) or, from a point light, uniformly in solid angle over
//!   the cone of that sphere; they enter where they first meet the mesh, unrefracted.
//! - Free flights in `σt = σa + σs`; the weight times the albedo `σs/σt` at each collision;
//!   Russian roulette below a twentieth of the start. A flight that reaches the surface leaves
//!   and goes on in a straight line: it may enter again elsewhere (a concave mesh).
//! - At every collision the isotropic phase `1/4π` times the transmittance along the segment
//!   to the eye (the medium's parts of it only: it may leave and enter again, an ear in front
//!   of the head), `1/r²` and the pinhole's importance `1/(a cos³θ)` (a pixel of area `a` on
//!   the image plane at distance 1) go into the pixel the eye sees the collision through.
//!
//! Rays are the plugin's [`SceneRays`] (the same BVH queries the precompute makes) over the
//! mesh in millimetres; the transport is its own. Checked against Mitsuba where Mitsuba
//! converges (the bunny's skin and marble, the torus's under a point light and its single
//! scattering: 0.018 – 0.052 in relative L1, the means within 1.1 %): docs/translucent.md,
//! "A light tracer for meshes".

use bevy::math::Vec3;
use bevy_mesostructure::translucency::{PatchObject, SceneRays, TranslucentMedium, beam_table::ExitPatches, patches::Patches};
use rand::rngs::SmallRng;
use rand::{RngExt, SeedableRng};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use super::translucent_accuracy_scene::camera_frame;

/// Millimetres per world unit (metres): the media's coefficients are per millimetre.
const MM: f32 = 1000.0;
/// Photons a work item walks (its own seed, so the picture is the same on any thread count).
const CHUNK: usize = 4096;
/// A connection is left out once the medium's optical depth on the way to the eye passes
/// this (transmittance under 1e-13 of a unit).
const OPAQUE_DEPTH: f32 = 30.0;
/// How far past a surface a ray that crossed it starts again (mm): well under any medium's
/// mean free path here (marble's 0.4 mm), well over f32's spacing at the scenes' sizes.
const PAST_SURFACE: f32 = 1e-3;

/// Where the photons come from.
#[derive(Clone, Copy, Debug)]
pub enum Source {
    /// A directional light travelling along the unit vector, of irradiance 1.
    Directional(Vec3),
    /// A point light at this position (world units), of irradiance 1 across its rays at the
    /// origin (the accuracy scenes' point light).
    Point(Vec3),
}

/// Which of the light the picture holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Part {
    /// All of it: the reference.
    All,
    /// Single scattering alone (each photon's first collision).
    Single,
    /// What a method that gives light out by Lambert's law would show with the exact
    /// transport: each photon's exit after a scattering or more counted as flux on the
    /// surface point it leaves by (where the eye sees that point), the pixel's radiance that
    /// exitance over π. The unscattered beam is not counted.
    LambertianExit,
    /// All of it but the light that left the mesh and entered it again: each photon stops at
    /// its first exit, so that the reference over this picture is what light coming back in
    /// (a lit ear's light onto the head behind it) is worth.
    FirstExit,
    /// All of it but the light that crossed a thin part without scattering and entered the
    /// mesh again: a photon that leaves before its first collision stops there (the plugin
    /// lights only the first surface a light meets), so that the reference over this picture
    /// is what light through a thin part onto the mesh behind it is worth.
    NoUncollidedReentry,
}

/// The pinhole camera of the accuracy scenes: at `eye`, looking at the origin, +Y up
/// ([`camera_frame`]).
#[derive(Clone, Copy, Debug)]
pub struct Pinhole {
    pub eye: Vec3,
    pub fov_y: f32,
    pub size: u32,
}

/// A light-traced picture: radiance per unit irradiance, rows from the top, and its noise
/// (the relative L1 between the pictures of the two halves of the photons, halved).
pub struct LightTraced {
    pub pixels: Vec<[f32; 3]>,
    pub noise: f32,
    /// Crossings where the side the walk thought it was on disagreed with the face's winding
    /// (a mesh that is not closed, or rays along an edge): should be a tiny share.
    pub side_disagreements: u64,
    pub crossings: u64,
    /// With [`ExitBins`]: per bin, the flux (mm², per unit irradiance) that left through the
    /// surface after a scattering or more, per channel.
    pub binned_exits: Vec<[f32; 3]>,
    /// With [`ExitBins`]: the flux of exits after a scattering that no bin took, per channel.
    pub unbinned_exits: [f32; 3],
}

/// Where each exit after a scattering or more is tallied (an oracle of a method's transport
/// on its own patches): `of(point, outward normal)`, both in the tracer's millimetres, gives
/// the bin, of `count`.
pub struct ExitBins<'a> {
    pub of: &'a (dyn Fn(Vec3, Vec3) -> Option<usize> + Sync),
    pub count: usize,
    /// Only exits after more than this many scatterings (0: all that scattered).
    pub after: u32,
    /// Which of the light that left the mesh and came back in is followed.
    pub reentering: Reentering,
}

/// Which of the light that left the mesh and entered it again [`ExitBins`] follow.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Reentering {
    /// All of it (the exact transport).
    All,
    /// Only what scattered before it left: a photon that crosses a thin part unscattered
    /// stops there (the plugin lights only the first surface a light meets).
    Scattered,
    /// None: each photon stops at its first exit.
    None,
}

impl Reentering {
    /// Its name in file names and method names (empty for all of it).
    pub fn suffix(self) -> &'static str {
        match self {
            Self::All => "",
            Self::Scattered => "reenteringscattered",
            Self::None => "reenteringnone",
        }
    }
}

struct Camera {
    eye: Vec3,
    forward: Vec3,
    right: Vec3,
    up: Vec3,
    tan_half: f32,
    size: u32,
}

impl Camera {
    /// The pixel the eye sees `x` through and the cosine of that ray to the axis.
    fn pixel(&self, x: Vec3) -> Option<(usize, f32)> {
        let d = (x - self.eye).normalize();
        let cos = d.dot(self.forward);
        if cos <= 0.0 {
            return None;
        }
        let sx = d.dot(self.right) / cos / self.tan_half;
        let sy = d.dot(self.up) / cos / self.tan_half;
        let px = ((sx + 1.0) * 0.5 * self.size as f32).floor();
        let py = ((1.0 - sy) * 0.5 * self.size as f32).floor();
        let n = self.size as f32;
        (px >= 0.0 && px < n && py >= 0.0 && py < n).then(|| (py as usize * self.size as usize + px as usize, cos))
    }
}

/// One channel's medium, per millimetre.
#[derive(Clone, Copy)]
struct Channel {
    sigma_t: f32,
    albedo: f32,
}

struct Tracer<'a> {
    rays: &'a SceneRays,
    /// +1 where the mesh's faces wind outwards, −1 inwards (by its signed volume).
    winding: f32,
    camera: Camera,
    source: Source,
    part: Part,
    centre: Vec3,
    radius: f32,
    bins: Option<&'a ExitBins<'a>>,
}

#[derive(Default)]
struct Tally {
    halves: [Vec<f32>; 2],
    bins: Vec<f32>,
    unbinned: f32,
    disagreements: u64,
    crossings: u64,
}

impl Tracer<'_> {
    /// Whether crossing the face of `normal` along `d` enters the mesh.
    fn enters(&self, d: Vec3, normal: Vec3) -> bool {
        d.dot(normal) * self.winding < 0.0
    }

    /// The medium's transmittance from `x` (inside) to the eye, or `None` where it is
    /// negligible. Which side of the surface each stretch lies on is the faces' word (the
    /// stretch before a face the ray leaves through is inside), not a count of crossings, so a
    /// crossing the rays miss or see twice does not turn the rest of the way inside out.
    fn to_eye(&self, x: Vec3, channel: Channel, tally: &mut Tally) -> Option<f32> {
        let to_eye = self.camera.eye - x;
        let mut left = to_eye.length();
        let w = to_eye / left;
        let budget = OPAQUE_DEPTH / channel.sigma_t;
        let (mut cursor, mut inside, mut in_medium, mut step) = (x, true, 0.0f32, 0.0f32);
        loop {
            let start = cursor + w * step;
            let reach = if inside { (budget - in_medium).min(left - step) } else { left - step };
            if reach <= 0.0 {
                return (!inside).then(|| (-channel.sigma_t * in_medium).exp());
            }
            match self.rays.first_hit_within(start, w, reach) {
                Some((t, normal)) => {
                    tally.crossings += 1;
                    let entering = self.enters(w, normal);
                    if entering == inside {
                        tally.disagreements += 1;
                    }
                    if !entering {
                        in_medium += step + t;
                    }
                    cursor = start + w * t;
                    left -= step + t;
                    inside = entering;
                    step = PAST_SURFACE;
                }
                // Inside, nothing within the budget: too deep to matter (the eye is outside).
                None if inside => return None,
                None => return Some((-channel.sigma_t * in_medium).exp()),
            }
        }
    }

    /// Walks `count` photons of `power` each into `image`.
    fn walk(&self, count: usize, power: f32, channel: Channel, random: &mut SmallRng, image: &mut [f32], tally: &mut Tally) {
        let c = &self.camera;
        let pixel_area = (2.0 * c.tan_half / c.size as f32).powi(2);
        for _ in 0..count {
            let (origin, mut d) = self.emit(random);
            let Some((t, normal)) = self.rays.first_hit(origin, d) else { continue };
            tally.crossings += 1;
            if !self.enters(d, normal) {
                tally.disagreements += 1;
            }
            let mut x = origin + d * t;
            let mut weight = power;
            // Which side of the surface the photon is on after each crossing is the face's
            // word (as in `to_eye`).
            let mut inside = true;
            let mut on_surface = true;
            let mut collisions = 0u32;
            loop {
                if !inside {
                    if self.part == Part::FirstExit || (self.part == Part::NoUncollidedReentry && collisions == 0) {
                        break;
                    }
                    // Out through the surface: on in a straight line, perhaps into the mesh
                    // again.
                    let start = x + d * PAST_SURFACE;
                    let Some((t, normal)) = self.rays.first_hit(start, d) else { break };
                    tally.crossings += 1;
                    inside = self.enters(d, normal);
                    if !inside {
                        tally.disagreements += 1;
                    }
                    x = start + d * t;
                    continue;
                }
                let flight = -(1.0 - random.random::<f32>()).ln() / channel.sigma_t;
                let start = if on_surface { x + d * PAST_SURFACE } else { x };
                if let Some((t, normal)) = self.rays.first_hit_within(start, d, flight) {
                    tally.crossings += 1;
                    inside = self.enters(d, normal);
                    if inside {
                        tally.disagreements += 1;
                    }
                    x = start + d * t;
                    on_surface = true;
                    if !inside && self.part == Part::LambertianExit && collisions > 0 {
                        self.exit_seen(x, normal * self.winding, weight, pixel_area, image);
                    }
                    // `after` is at least 0: only exits after a scattering or more.
                    if !inside
                        && let Some(bins) = self.bins
                        && collisions > bins.after
                    {
                        match (bins.of)(x, normal * self.winding) {
                            Some(bin) => tally.bins[bin] += weight,
                            None => tally.unbinned += weight,
                        }
                    }
                    if !inside
                        && let Some(bins) = self.bins
                        && (bins.reentering == Reentering::None || (bins.reentering == Reentering::Scattered && collisions == 0))
                    {
                        break;
                    }
                    continue;
                }
                if self.part == Part::Single && collisions == 1 {
                    break;
                }
                x = start + d * flight;
                on_surface = false;
                weight *= channel.albedo;
                collisions += 1;
                if self.part != Part::LambertianExit
                    && let (Some(transmittance), Some((pixel, cos))) = (self.to_eye(x, channel, tally), c.pixel(x))
                {
                    let r2 = (c.eye - x).length_squared();
                    image[pixel] += weight * transmittance / (4.0 * std::f32::consts::PI * pixel_area * cos.powi(3) * r2);
                }
                if weight < power / 20.0 {
                    if random.random::<f32>() < 0.5 {
                        break;
                    }
                    weight *= 2.0;
                }
                d = isotropic(random);
            }
        }
    }

    /// `Part::LambertianExit`: the photon's `flux` leaving by the surface point `s` (outward
    /// unit normal `outward`) as exitance over π, into the pixel that sees `s`.
    fn exit_seen(&self, s: Vec3, outward: Vec3, flux: f32, pixel_area: f32, image: &mut [f32]) {
        let c = &self.camera;
        let to_eye = c.eye - s;
        let r = to_eye.length();
        let w = to_eye / r;
        let view_cos = w.dot(outward);
        if view_cos <= 0.0 || self.rays.first_hit_within(s + w * PAST_SURFACE, w, r - PAST_SURFACE).is_some() {
            return;
        }
        if let Some((pixel, cos)) = c.pixel(s) {
            image[pixel] += flux * view_cos / (std::f32::consts::PI * pixel_area * cos.powi(3) * r * r);
        }
    }

    /// A photon's start and direction.
    fn emit(&self, random: &mut SmallRng) -> (Vec3, Vec3) {
        let u = random.random::<f32>();
        let phi = std::f32::consts::TAU * random.random::<f32>();
        match self.source {
            Source::Directional(light) => {
                let (lu, lv) = light.any_orthonormal_pair();
                let r = self.radius * u.sqrt();
                let origin = self.centre - light * (2.0 * self.radius) + (lu * phi.cos() + lv * phi.sin()) * r;
                (origin, light)
            }
            Source::Point(lamp) => {
                let axis = (self.centre - lamp).normalize();
                let (lu, lv) = axis.any_orthonormal_pair();
                let cos_max = self.cos_max(lamp);
                let ct = 1.0 - u * (1.0 - cos_max);
                let st = (1.0 - ct * ct).max(0.0).sqrt();
                (lamp, axis * ct + (lu * phi.cos() + lv * phi.sin()) * st)
            }
        }
    }

    fn cos_max(&self, lamp: Vec3) -> f32 {
        let d = (self.centre - lamp).length();
        (1.0 - (self.radius / d).powi(2)).max(0.0).sqrt()
    }

    /// Each photon's share of the light (mm²: radiance per unit irradiance in the end).
    fn power(&self, photons: usize) -> f32 {
        match self.source {
            Source::Directional(_) => std::f32::consts::PI * self.radius * self.radius / photons as f32,
            Source::Point(lamp) => {
                // Intensity |lamp|² (irradiance 1 across its rays at the origin) over the cone.
                let solid_angle = std::f32::consts::TAU * (1.0 - self.cos_max(lamp));
                lamp.length_squared() * solid_angle / photons as f32
            }
        }
    }
}

fn isotropic(random: &mut SmallRng) -> Vec3 {
    let z = 2.0 * random.random::<f32>() - 1.0;
    let s = (1.0 - z * z).max(0.0).sqrt();
    let a = std::f32::consts::TAU * random.random::<f32>();
    Vec3::new(s * a.cos(), s * a.sin(), z)
}

/// Light-traces the closed mesh (`positions` in world units, metres; three `indices` a
/// triangle) of `medium` (its coefficients; the boundary index-matched whatever its η),
/// `photons` a channel over `threads` threads; `part` of the light.
#[allow(clippy::too_many_arguments)]
pub fn light_trace(
    positions: &[Vec3],
    indices: &[u32],
    medium: &TranslucentMedium,
    source: Source,
    part: Part,
    camera: Pinhole,
    photons: usize,
    seed: u64,
    threads: usize,
    bins: Option<&ExitBins>,
) -> LightTraced {
    let mm: Vec<Vec3> = positions.iter().map(|p| *p * MM).collect();
    let rays = SceneRays::new(&[PatchObject { positions: &mm, indices }]);
    let volume: f32 = indices
        .chunks_exact(3)
        .map(|t| mm[t[0] as usize].dot(mm[t[1] as usize].cross(mm[t[2] as usize])) / 6.0)
        .sum();
    let (low, high) = mm.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(l, h), p| (l.min(*p), h.max(*p)));
    let centre = (low + high) * 0.5;
    let radius = mm.iter().map(|p| (*p - centre).length()).fold(0.0, f32::max) * 1.001;
    let (forward, right, up) = camera_frame(camera.eye);
    let tracer = Tracer {
        rays: &rays,
        winding: if volume >= 0.0 { 1.0 } else { -1.0 },
        camera: Camera {
            eye: camera.eye * MM,
            forward,
            right,
            up,
            tan_half: (camera.fov_y / 2.0).tan(),
            size: camera.size,
        },
        source: match source {
            Source::Directional(d) => Source::Directional(d.normalize()),
            Source::Point(p) => Source::Point(p * MM),
        },
        part,
        centre,
        radius,
        bins,
    };
    let bin_count = bins.map_or(0, |b| b.count);
    let mut binned_exits = vec![[0.0f32; 3]; bin_count];
    let mut unbinned_exits = [0.0f32; 3];
    let n = (camera.size * camera.size) as usize;
    // An even number of chunks, so the two halves walk as many photons.
    let chunks = photons.div_ceil(CHUNK).max(2).next_multiple_of(2);
    let per_chunk = photons.div_ceil(chunks);
    let power = tracer.power(chunks * per_chunk) * 2.0;
    let mut pixels = vec![[0.0f32; 3]; n];
    let mut halves = [vec![[0.0f32; 3]; n], vec![[0.0f32; 3]; n]];
    let (mut disagreements, mut crossings) = (0, 0);
    let start = Instant::now();
    for (c, (&a, &s)) in medium.absorption.to_array().iter().zip(&medium.reduced_scattering.to_array()).enumerate() {
        let channel = Channel { sigma_t: a + s, albedo: s / (a + s) };
        let next = AtomicUsize::new(0);
        let tallies: Vec<Tally> = std::thread::scope(|scope| {
            let workers: Vec<_> = (0..threads.max(1))
                .map(|_| {
                    scope.spawn(|| {
                        let mut tally = Tally { halves: [vec![0.0; n], vec![0.0; n]], bins: vec![0.0; bin_count], ..Default::default() };
                        loop {
                            let k = next.fetch_add(1, Ordering::Relaxed);
                            if k >= chunks {
                                break tally;
                            }
                            let mut random = SmallRng::seed_from_u64(seed ^ ((c * chunks + k) as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
                            let mut half = std::mem::take(&mut tally.halves[k % 2]);
                            tracer.walk(per_chunk, power, channel, &mut random, &mut half, &mut tally);
                            tally.halves[k % 2] = half;
                        }
                    })
                })
                .collect();
            workers.into_iter().map(|w| w.join().expect("a light-tracing thread panicked")).collect()
        });
        for tally in tallies {
            for (half, tallied) in halves.iter_mut().zip(&tally.halves) {
                for (pixel, v) in half.iter_mut().zip(tallied) {
                    pixel[c] += v;
                }
            }
            for (b, v) in binned_exits.iter_mut().zip(&tally.bins) {
                // Each photon's power counts twice (for the two halves' pictures).
                b[c] += 0.5 * v;
            }
            unbinned_exits[c] += 0.5 * tally.unbinned;
            disagreements += tally.disagreements;
            crossings += tally.crossings;
        }
        eprintln!("light tracer: channel {c} in {:.0} s", start.elapsed().as_secs_f32());
    }
    let (mut difference, mut total) = (0.0f64, 0.0f64);
    for i in 0..n {
        for c in 0..3 {
            let (a, b) = (halves[0][i][c] as f64, halves[1][i][c] as f64);
            pixels[i][c] = (0.5 * (a + b)) as f32;
            difference += (a - b).abs();
            total += a + b;
        }
    }
    LightTraced {
        pixels,
        noise: if total > 0.0 { (difference / total) as f32 } else { 0.0 },
        side_disagreements: disagreements,
        crossings,
        binned_exits,
        unbinned_exits,
    }
}

/// The exact transport's exitance on a method's own patches: each exit after a scattering or
/// more tallied on the patch the plugin's own walks would leave by (`ExitPatches`: the
/// nearest surface sample facing its way, else the nearest), over the patch's area — per unit irradiance, as the plugin's `B`, with the light that left and
/// came back in counted at each exit (as the plugin's bounce counts it). An oracle of the
/// transport alone, before any exit law or gather. Patches of the first object only (the
/// mesh traced; world units metres); the others are zero. Also the share of the binned
/// flux no patch took (an exit further than a patch size from every sample).
/// With `after` above 0, only the exits after more than that many scatterings; `reentering`
/// says which of the light that left and came back in is followed.
#[allow(clippy::too_many_arguments)]
pub fn patch_exitance(
    positions: &[Vec3],
    indices: &[u32],
    medium: &TranslucentMedium,
    light: Vec3,
    patches: &Patches,
    camera: Pinhole,
    photons: usize,
    seed: u64,
    threads: usize,
    after: u32,
    reentering: Reentering,
) -> (Vec<Vec3>, Vec3) {
    let object = patches.patches.iter().take_while(|q| q.object == 0).count();
    // The patch the table's walks would leave by (`ExitPatches`, in world units).
    let exit_patches = ExitPatches::new(patches);
    let of = |x: Vec3, outward: Vec3| exit_patches.of(0, x / MM, outward).map(|i| i as usize);
    let bins = ExitBins { of: &of, count: object, after, reentering };
    let traced = light_trace(positions, indices, medium, Source::Directional(light), Part::LambertianExit, camera, photons, seed, threads, Some(&bins));
    let mut exitance = vec![Vec3::ZERO; patches.patches.len()];
    for (e, (b, q)) in exitance.iter_mut().zip(traced.binned_exits.iter().zip(&patches.patches)) {
        *e = Vec3::from_array(*b) / (q.area * MM * MM);
    }
    let binned = traced.binned_exits.iter().fold(Vec3::ZERO, |sum, b| sum + Vec3::from_array(*b));
    let unbinned = Vec3::from_array(traced.unbinned_exits);
    (exitance, unbinned / (binned + unbinned).max(Vec3::splat(f32::MIN_POSITIVE)))
}
