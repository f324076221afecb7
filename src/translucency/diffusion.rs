//! Diffusion profiles: the radiant exitance a point of a translucent surface gives off per
//! unit flux entering at distance `r`, `R_d(r)` (mm⁻²), for a semi-infinite slab of the medium.
//!
//! - **Dipole** (Jensen et al. 2001, eq. 4 there; seed 001's kernel): a real source at depth
//!   `z_r = 1/σt′` and a negative virtual one at `z_v = z_r (1 + 4A/3)` above the surface,
//!   `R_d(r) = α′/(4π) Σ_{z ∈ {z_r, z_v}} z (σtr d + 1) e^(−σtr d) / d³`, `d = √(r² + z²)`,
//!   with `σt′ = σa + σs′`, `α′ = σs′/σt′`, `σtr = √(3 σa σt′)`, `A = (1 + F_dr)/(1 − F_dr)`
//!   and Jensen's fit `F_dr(η) = −1.440/η² + 0.710/η + 0.668 + 0.0636 η`.
//!   Since `z (σ d + 1) e^(−σ d) / d³ · r = −z · d/dr [e^(−σ d)/d]`, the exitance within a disc
//!   of radius `R` is closed form: `W(R) = α′/2 Σ z (e^(−σtr z)/z − e^(−σtr d(R))/d(R))`, and
//!   `W(∞) = α′/2 (e^(−σtr z_r) + e^(−σtr z_v))` is the paper's total diffuse reflectance.
//! - **Burley** (Christensen and Burley 2015): `R(r) = A s (e^(−s r) + e^(−s r/3)) / (8π r)`,
//!   `W(R) = A/4 (1 − e^(−s R) + 3 (1 − e^(−s R/3)))`, `s = (3.5 + 100 (A − 0.33)⁴) / ℓ_d` with
//!   `ℓ_d = 1/σtr` the diffuse mean free path (their eq. 8). `A`, the slab's whole diffuse reflectance
//!   (every order of scattering, fitted to Monte Carlo), is found from the single-scattering
//!   albedo `α′` by inverting Chiang, Kutz and Burley 2016's fit
//!   `α = 1 − (4.09712 + 4.20863 A − √(9.59217 + 41.6808 A + 17.7126 A²))²`
//!   ([`surface_albedo`]); so this kernel carries single scattering itself.
//!
//! **Single scattering** (the other term of Jensen et al. 2001's BSSRDF, light scattered once
//! just under the entry point): a collimated beam of irradiance `E` at incidence cosine `μ₀`
//! into an isotropic medium (`g = 0`, so `σs = σs′`) gives off the exitance
//! `E · α/2 · (1 − μ₀ ln(1 + 1/μ₀))`, `α = σs/σt` — integrating the single-scattered radiance
//! `α E μ₀ / (4π (μ + μ₀))` over the outgoing hemisphere; diffuse light its cosine-weighted
//! mean ([`single_scattering_shape`], [`diffuse_single_scattering_shape`]). It leaves within a
//! mean free path of the entry, so the patches keep it on the patch it enters.
//!
//! Light enters through the boundary with the hemispherical transmittance `1 − F_dr,ext(η)`,
//! integrated from Fresnel's equations ([`diffuse_fresnel_reflectance`]): every light the
//! transport sees arrives as irradiance, whose directional form the patches do not keep —
//! except a light's own beam, which [`IncidenceWeight`] weights by its incidence
//! (Chandrasekhar's plane albedo, [`collimated_albedo`]).

use bevy::prelude::*;
use std::f64::consts::PI;

use super::{medium::TranslucentMedium, shape_diffusion::DipoleChannel};

/// Which diffusion profile carries light under a translucent surface.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Reflect, Default)]
pub enum DiffusionKernel {
    /// Jensen et al. 2001's dipole with its single-scattering term, as seed 001 uses it.
    Dipole,
    /// Christensen and Burley 2015's sum of two exponentials with the albedo of Chiang et al.
    /// 2016's Monte Carlo fit. Close to [`ScaledDipole`](Self::ScaledDipole) lit from the
    /// front (relative L1 0.051 marble, 0.089 skin against a light-traced reference), but its
    /// tail falls as `e^(−s r/3)`, `s` up to 16 σtr for marble: light does not cross a thick
    /// object (lit from behind: 0.93 marble, 0.75 skin; `docs/translucent.md`).
    Burley,
    /// Jensen's dipole shape (its diffusion tail, `e^(−σtr r)` far from the entry) carrying
    /// Chiang et al.'s albedo `A` in all, single scattering included: Burley's total with the
    /// reach of diffusion theory. The default: against a light-traced reference of a 1 cm
    /// ball (960 patches, the other defaults; `docs/translucent.md`) 0.045 (marble) and 0.076
    /// (skin) in relative L1 lit from the front, where Burley's are 0.051 and 0.089 and the
    /// dipole's 0.18; lit from behind (under the flat profile) 0.28 and 0.61, where Burley's
    /// are 0.93 and 0.75.
    #[default]
    ScaledDipole,
}

/// One colour channel's profile.
#[derive(Clone, Copy, Debug)]
enum Channel {
    Dipole(DipoleChannel),
    Burley {
        albedo: f64,
        /// Shape `s`, mm⁻¹.
        s: f64,
    },
}

impl Channel {
    fn reflectance(&self, r: f64) -> f64 {
        match *self {
            Channel::Dipole(dipole) => dipole.reflectance(r),
            Channel::Burley { albedo, s } => {
                let r = r.max(1e-9);
                albedo * s * ((-s * r).exp() + (-s * r / 3.0).exp()) / (8.0 * PI * r)
            }
        }
    }

    /// The dipole's exitance at `exit` (outward normal `exit_normal`) for flux entering at
    /// `entry` (outward normal `entry_normal`), positions in mm: the real source a depth
    /// `z_r` under the entry along its normal, the virtual one `z_v` above it, and the flux
    /// `D ∇φ` of the pair taken along the exit's own normal. Where exit and entry share one
    /// plane this is [`reflectance`](Self::reflectance) (the distances to the plane are `z_r`
    /// and `−z_v`); across a curved object the flux meets the far surface head-on instead of
    /// grazing it. `None` for Burley's profile, which has no sources.
    fn oriented_reflectance(
        &self,
        entry: bevy::math::DVec3,
        entry_normal: bevy::math::DVec3,
        exit: bevy::math::DVec3,
        exit_normal: bevy::math::DVec3,
    ) -> Option<f64> {
        let (_, flux) = self
            .dipole()?
            .fields(entry, entry_normal, exit, exit_normal);
        Some(flux.max(0.0))
    }

    /// The dipole's sources, `None` for Burley's profile.
    fn dipole(&self) -> Option<DipoleChannel> {
        match *self {
            Channel::Dipole(dipole) => Some(dipole),
            Channel::Burley { .. } => None,
        }
    }

    fn within(&self, radius: f64) -> f64 {
        let radius = radius.max(0.0);
        match *self {
            Channel::Dipole(dipole) => dipole.within(radius),
            Channel::Burley { albedo, s } => {
                albedo / 4.0
                    * ((1.0 - (-s * radius).exp()) + 3.0 * (1.0 - (-s * radius / 3.0).exp()))
            }
        }
    }

    fn total(&self) -> f64 {
        match *self {
            Channel::Dipole(dipole) => dipole.total(),
            Channel::Burley { albedo, .. } => albedo,
        }
    }
}

/// Jensen's polynomial fit of the diffuse Fresnel reflectance seen from inside a medium of
/// relative index `eta` (used for the dipole's boundary condition).
pub fn jensen_internal_diffuse_reflectance(eta: f64) -> f64 {
    -1.440 / (eta * eta) + 0.710 / eta + 0.668 + 0.0636 * eta
}

/// Diffusion theory's boundary coefficient `A = (1 + F_dr)/(1 − F_dr)` behind a boundary of
/// relative index `eta` (Jensen's `F_dr`): the dipole's extrapolation, and how much the
/// boundary's internal reflection flattens the radiance inside.
pub fn boundary_coefficient(eta: f64) -> f64 {
    let f_dr = jensen_internal_diffuse_reflectance(eta);
    (1.0 + f_dr) / (1.0 - f_dr)
}

/// The absorbing half-space's mode's decay per transport mean free path, `ν = √(3(1 − α))`,
/// for the reduced albedo `alpha` (held to [0, 1]): 0 without absorption, 1 where a mean free
/// path is a diffusion length.
pub fn half_space_mode_decay(alpha: f64) -> f64 {
    (3.0 * (1.0 - alpha.clamp(0.0, 1.0))).sqrt()
}

/// The share `g = 1 − √(3(1 − α))` of the light arriving from elsewhere that is in the
/// diffusion mode, for the reduced albedo `alpha`: all of it for no absorption, none where a
/// mean free path is a diffusion length.
pub fn diffusion_mode_share(alpha: f64) -> f64 {
    (1.0 - half_space_mode_decay(alpha)).max(0.0)
}

/// Unpolarised Fresnel reflectance of a smooth boundary, light arriving from the side of index
/// 1 at `cos_i` onto index `eta`.
pub fn fresnel_reflectance(cos_i: f64, eta: f64) -> f64 {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let Some(cos_t) = refracted_cosine(cos_i, eta) else {
        return 1.0;
    };
    let rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    0.5 * (rs * rs + rp * rp)
}

/// Snell's law: the cosine of the refracted direction for light arriving at `cos_i` onto
/// index `eta`; `None` past the critical angle.
fn refracted_cosine(cos_i: f64, eta: f64) -> Option<f64> {
    let sin_t2 = (1.0 - cos_i * cos_i) / (eta * eta);
    (sin_t2 < 1.0).then(|| (1.0 - sin_t2).sqrt())
}

/// Hemispherical (cosine-weighted) Fresnel reflectance `2 ∫ F(μ) μ dμ` for light arriving
/// from the side of index 1 onto index `eta`: the share of diffuse light the boundary turns
/// away before it enters.
pub fn diffuse_fresnel_reflectance(eta: f64) -> f64 {
    // Midpoint rule in μ²; F is smooth for eta > 1 (no critical angle from outside).
    let n = 4096;
    (0..n)
        .map(|k| {
            let mu2 = (k as f64 + 0.5) / n as f64;
            fresnel_reflectance(mu2.sqrt(), eta)
        })
        .sum::<f64>()
        / n as f64
}

/// Chiang, Kutz and Burley 2016's single-scattering albedo of a medium whose slab reflects
/// `A` of diffuse light (all orders of scattering, index-matched).
pub fn single_scattering_albedo_of(surface_albedo: f64) -> f64 {
    let a = surface_albedo;
    1.0 - (4.09712 + 4.20863 * a - (9.59217 + 41.6808 * a + 17.7126 * a * a).sqrt()).powi(2)
}

/// The inverse of [`single_scattering_albedo_of`] (bisection; it rises monotonically from
/// 0 to 1): the slab's diffuse reflectance for single-scattering albedo `alpha`.
pub fn surface_albedo(alpha: f64) -> f64 {
    let alpha = alpha.clamp(0.0, 1.0);
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if single_scattering_albedo_of(mid) < alpha {
            lo = mid
        } else {
            hi = mid
        }
    }
    0.5 * (lo + hi)
}

/// The angular law of light that reaches a surface from deep inside a medium of
/// single-scattering albedo `alpha` behind a boundary of index `eta` (the diffusion field's
/// asymptotic mode), in one colour channel: its exit radiance against a Lambertian one of the
/// same exitance.
///
/// - Index-matched: `s(μ) = H(μ)/(1 − ν μ)/N` with Chandrasekhar's `H` ([`chandrasekhar_h`]),
///   `ν = √(3(1 − α))` the mode's decay per mean free path (at most 0.9), `N` making
///   `2∫ s μ dμ = 1`. Limb-darkened: for no absorption it is the emergent law of the Milne
///   problem, `√3/4 H(μ)` (`s(1) = 1.26`, `s(0) = 0.43`). Random walks through slabs 6–15 mean
///   free paths thick (`tools/slab_walks.py`, 4·10⁵ a case, albedos 0.999, 0.96, 0.85) leave in
///   this law within 5 % at exit cosines 0.1–1 and 0.78–1.21 in the noisy grazing bin below,
///   where Lambert's law is 0.36–1.44 of theirs (`docs/translucent.md`).
/// - Behind a dielectric (`eta` > 1): the boundary reflects part of the light back in, which
///   flattens the radiance inside — in diffusion theory its anisotropy goes as `1/A`,
///   `A = (1 + F_dr)/(1 − F_dr)` — and lets out `1 − F(μ)` of what meets it at the refracted
///   cosine `μ_i`: `s(μ) = (1 − F(μ)) (1 + (H(μ_i)/(1 − ν μ_i) − 1)/A)/N`, the law above at
///   `eta` 1. Against light-traced balls behind η 1.3 it beats both Lambert's law and the
///   index-matched law (`docs/translucent.md`).
///
/// Its weight: the share `g = 1 − √(3(1 − α))` of light arriving from elsewhere that is in
/// that mode — all of it for no absorption, none where a mean free path is a diffusion length
/// (skin's blue). Returns `(α, ν, 1/N, g)`, what [`deep_exit_shape`] and `gathered.wgsl` read
/// with the same `eta`.
pub fn deep_exit_law(alpha: f64, eta: f64) -> [f32; 4] {
    let alpha = alpha.clamp(0.0, 1.0);
    let nu = half_space_mode_decay(alpha).min(0.9);
    let unnormalised = [alpha as f32, nu as f32, 1.0, 0.0];
    // 2 ∫ f(μ) μ dμ by the midpoint rule (f is smooth).
    let n = 512;
    let norm = 2.0
        * (0..n)
            .map(|k| {
                let mu = (k as f64 + 0.5) / n as f64;
                deep_exit_shape(unnormalised, eta as f32, mu as f32) as f64 * mu
            })
            .sum::<f64>()
        / n as f64;
    [
        alpha as f32,
        nu as f32,
        (1.0 / norm) as f32,
        diffusion_mode_share(alpha) as f32,
    ]
}

/// `s(μ)` of a [`deep_exit_law`] behind a boundary of index `eta` at exit cosine `mu` (the
/// same arithmetic as `gathered.wgsl`).
pub fn deep_exit_shape(law: [f32; 4], eta: f32, mu: f32) -> f32 {
    let eta = f64::from(if eta.is_finite() { eta } else { 1.0 }).clamp(1.0, 3.0);
    let mu = mu.clamp(0.0, 1.0) as f64;
    let inside = (1.0 - (1.0 - mu * mu) / (eta * eta)).max(0.0).sqrt();
    let boundary = boundary_coefficient(eta);
    let mode = chandrasekhar_h(law[0] as f64, inside) / (1.0 - law[1] as f64 * inside);
    ((1.0 - fresnel_reflectance(mu, eta)) * (1.0 + (mode - 1.0) / boundary) * law[2] as f64) as f32
}

/// The most the tangential flux's term moves a pixel's radiance from the exit law's, either
/// way (a share of it): P1 holds for a small anisotropy, and a steep gradient at a
/// silhouette must not turn the radiance negative.
pub const MAX_TANGENTIAL_LEAN: f32 = 0.5;

/// The weight of the diffusion field's flux along the surface in the exit radiance, per
/// world unit of gradient: `g · 3A/(2η³) · D` ([`tangential_flux_factor`]). Inside, diffusion's
/// radiance is `(φ + 3F·ω)/4π` (P1), with `F = −D∇φ`. Along the surface `F_t = −D∇_tφ`, and
/// the exitance is `B = φ/(2A)` (the boundary condition); leaving through the boundary the
/// radiance is `(1 − F(μ))/η²` of the refracted direction's inside, whose tangential part is
/// `ω_t/η`. Over Lambert's `B/π` that adds `−(3A/(2η³)) (1 − F(μ)) D ∇_t ln B · ω` — `1.5 D`
/// index-matched — and nothing to the exitance (the term is odd in `ω_t`). Light that
/// crossed an object lit from behind flows along its surface at the silhouette and leaves
/// towards the camera brighter than any law about the normal gives (the exact exit is
/// 1.16× Lambert's share there, the deep law 1.09×: `docs/translucent.md`). Weighted by the
/// share `g = 1 − √(3(1 − α))` of the light in the diffusion mode, which P1 describes (all of
/// marble's, none of skin's blue), and by [`tangential_flux_mode_weight`] only in a channel
/// whose flow's law does not lean already; `α` the reduced albedo, `reduced_extinction`
/// `σa + σs′` (mm⁻¹).
pub fn tangential_flux_weight(alpha: f64, reduced_extinction: f64, eta: f64, world_units_per_mm: f64) -> f32 {
    let g = diffusion_mode_share(alpha) * tangential_flux_mode_weight(alpha);
    if !(reduced_extinction > 0.0 && world_units_per_mm > 0.0) || g == 0.0 {
        return 0.0;
    }
    let eta = if eta.is_finite() { eta.clamp(1.0, 3.0) } else { 1.0 };
    let boundary = boundary_coefficient(eta);
    let diffusion = world_units_per_mm / (3.0 * reduced_extinction);
    (g * 1.5 * boundary / (eta * eta * eta) * diffusion) as f32
}

/// The decay of the absorbing half-space's mode `ν = √(3(1 − α))` (per transport mean free
/// path) at and below which [`tangential_flux_weight`] takes the whole term, and
/// ([`TANGENTIAL_FLUX_MODE_DECAY_NONE`]) at and above which none of it.
pub const TANGENTIAL_FLUX_MODE_DECAY_ALL: f64 = 0.1;
/// See [`TANGENTIAL_FLUX_MODE_DECAY_ALL`].
pub const TANGENTIAL_FLUX_MODE_DECAY_NONE: f64 = 0.3;

/// How much of the flux along the surface a channel of reduced albedo `alpha` takes, by its
/// mode's decay `ν = √(3(1 − α))`: all at [`TANGENTIAL_FLUX_MODE_DECAY_ALL`] and below, none at
/// [`TANGENTIAL_FLUX_MODE_DECAY_NONE`] and above, smoothstep between. The flow's law leans the
/// light from elsewhere by `ν` already, and with the exit lobes that carries the flux along
/// the surface where `ν` is large: skin's red (ν 0.35) given the whole term came out 1.026 →
/// 1.057 bright on a 1 cm ball lit from behind (0.078 → 0.092 relative L1 at 1000 patches),
/// while marble (ν ≤ 0.084, a flow's law that hardly leans) gains wherever light crossed it
/// (`docs/translucent.md`, "The flux along the surface").
pub fn tangential_flux_mode_weight(alpha: f64) -> f64 {
    let nu = half_space_mode_decay(alpha);
    let t = ((TANGENTIAL_FLUX_MODE_DECAY_NONE - nu)
        / (TANGENTIAL_FLUX_MODE_DECAY_NONE - TANGENTIAL_FLUX_MODE_DECAY_ALL))
        .clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// The exit radiance's factor from the flux along the surface (P1, [`tangential_flux_weight`]):
/// `1 − clamp(w (1 − F(μ)) ∇_t ln B · ω, ±`[`MAX_TANGENTIAL_LEAN`]`)`, for the weight `w`,
/// the boundary's `eta`, the exit cosine `mu` and `along`, the exitance's gradient along the
/// surface over the exitance, dotted with the unit direction towards the camera (the same
/// arithmetic as `boundary.wgsl`).
pub fn tangential_flux_factor(weight: f32, eta: f32, mu: f32, along: f32) -> f32 {
    if !(weight > 0.0 && along.is_finite()) {
        return 1.0;
    }
    let eta = if eta.is_finite() { eta.clamp(1.0, 3.0) } else { 1.0 };
    let out = 1.0 - fresnel_reflectance(mu as f64, eta as f64) as f32;
    1.0 - (weight * out * along).clamp(-MAX_TANGENTIAL_LEAN, MAX_TANGENTIAL_LEAN)
}

/// [`deep_exit_shape`] with the mode's axis along `axis` instead of the normal `n`,
/// unnormalised (`law[2]` not applied): light leaving towards the unit `towards` (outside)
/// leaves from inside along its refracted direction `ω_i`, and the deep field's mode, which
/// decays by `ν` a mean free path against its flux, gives `H(μ_i)/(1 − ν ω_i·a)` there —
/// `a` the unit direction the light flows along times how much of it flows one way (0 – 1).
/// With `a = n` this is [`deep_exit_shape`]'s law. Normalise by [`deep_exit_norm_about`].
pub fn deep_exit_shape_about(law: [f32; 4], eta: f32, n: Vec3, axis: Vec3, towards: Vec3) -> f32 {
    let eta = f64::from(if eta.is_finite() { eta } else { 1.0 }).clamp(1.0, 3.0);
    let mu = f64::from(n.dot(towards)).clamp(0.0, 1.0);
    let tangent = (towards - n * n.dot(towards)).as_dvec3();
    let inside_mu = (1.0 - tangent.length_squared() / (eta * eta)).max(0.0).sqrt();
    let inside = tangent / eta + n.as_dvec3() * inside_mu;
    let boundary = boundary_coefficient(eta);
    let flow = (law[1] as f64 * inside.dot(axis.as_dvec3())).min(0.99);
    let mode = chandrasekhar_h(law[0] as f64, inside_mu) / (1.0 - flow);
    ((1.0 - fresnel_reflectance(mu, eta)) * (1.0 + (mode - 1.0) / boundary)) as f32
}

/// `1/N` for [`deep_exit_shape_about`]: `N = 2 ∫∫ s μ dμ dφ/(2π)` over the outward
/// hemisphere, for an axis `along` the normal and `across` it (its two components), so that
/// the law keeps the exitance. A 16 × 32 midpoint rule in `μ²` and `φ` (the law is smooth).
pub fn deep_exit_norm_about(law: [f32; 4], eta: f32, along: f32, across: f32) -> f32 {
    let (n, axis) = (Vec3::Z, Vec3::new(across, 0.0, along));
    let (rings, spokes) = (16, 32);
    let sum: f64 = cosine_weighted_directions(rings, spokes)
        .map(|towards| deep_exit_shape_about(law, eta, n, axis, towards) as f64)
        .sum();
    let norm = sum / (rings * spokes) as f64;
    if norm > 0.0 { (1.0 / norm) as f32 } else { 1.0 }
}

/// Directions over the outward hemisphere of +z whose plain mean is a cosine-weighted mean:
/// `rings` rings at the midpoints of `μ²` by `spokes` azimuths (the midpoint rule of
/// [`deep_exit_norm_about`] here and in `boundary.wgsl`).
pub fn cosine_weighted_directions(rings: u32, spokes: u32) -> impl Iterator<Item = Vec3> {
    (0..rings).flat_map(move |r| {
        let mu = ((r as f32 + 0.5) / rings as f32).sqrt();
        let sin = (1.0 - mu * mu).max(0.0).sqrt();
        (0..spokes).map(move |k| {
            let phi = std::f32::consts::TAU * (k as f32 + 0.5) / spokes as f32;
            Vec3::new(sin * phi.cos(), sin * phi.sin(), mu)
        })
    })
}

/// `1 − μ₀ ln(1 + 1/μ₀)`: the single-scattered exitance per unit irradiance and `α/2`, for a
/// beam at incidence cosine `μ₀` (see the module docs).
pub fn single_scattering_shape(mu0: f64) -> f64 {
    let mu0 = mu0.clamp(1e-9, 1.0);
    1.0 - mu0 * (1.0 + 1.0 / mu0).ln()
}

/// [`single_scattering_shape`] under diffuse light: `2 ∫₀¹ shape(μ) μ dμ = 4/3 (1 − ln 2)`
/// (0.4091).
pub fn diffuse_single_scattering_shape() -> f64 {
    4.0 / 3.0 * (1.0 - std::f64::consts::LN_2)
}

/// Chandrasekhar's `H(μ)` for isotropic scattering of single-scattering albedo `alpha`, in
/// Hapke's (2002) closed form `1 / (1 − α μ (r₀ + (1 − 2 r₀ μ)/2 · ln((1 + μ)/μ)))`,
/// `r₀ = (1 − γ)/(1 + γ)`, `γ = √(1 − α)`: within 1 % of the integral equation's solution
/// (tested).
pub fn chandrasekhar_h(alpha: f64, mu: f64) -> f64 {
    let alpha = alpha.clamp(0.0, 1.0);
    let mu = mu.clamp(1e-9, 1.0);
    let gamma = (1.0 - alpha).sqrt();
    let r0 = (1.0 - gamma) / (1.0 + gamma);
    1.0 / (1.0 - alpha * mu * (r0 + 0.5 * (1.0 - 2.0 * r0 * mu) * ((1.0 + mu) / mu).ln()))
}

/// The share of a collimated beam at incidence cosine `mu` that a semi-infinite,
/// index-matched medium of isotropic single-scattering albedo `alpha` gives back, every order
/// of scattering: Chandrasekhar's plane albedo `1 − H(μ) √(1 − α)`. Under diffuse light its
/// cosine-weighted mean is the medium's diffuse albedo — the `A` Chiang et al.'s fit gives
/// Burley's profile (they agree to 0.003, tested) — while a grazing beam comes back up to
/// 1.9× as strongly as a normal one (skin's blue: 0.37 at μ = 0.1 against 0.20 at μ = 1).
pub fn collimated_albedo(alpha: f64, mu: f64) -> f64 {
    1.0 - chandrasekhar_h(alpha, mu) * (1.0 - alpha.clamp(0.0, 1.0)).sqrt()
}

/// Gauss–Legendre nodes and weights of 8 points on [0, 1].
const GAUSS_8: [(f64, f64); 8] = [
    (0.019855071751231912, 0.05061426814518853),
    (0.10166676129318664, 0.11119051722668721),
    (0.2372337950418355, 0.15685332293894344),
    (0.4082826787521751, 0.18134189168918083),
    (0.5917173212478248, 0.18134189168918083),
    (0.7627662049581645, 0.15685332293894344),
    (0.8983332387068134, 0.11119051722668721),
    (0.9801449282487681, 0.05061426814518853),
];

/// How much of a beam a translucent surface takes in and gives back at the beam's own
/// incidence, relative to diffuse light of the same irradiance: the patches' scattering `K`
/// holds the diffuse albedo, and a directional light's irradiance on a translucent patch is
/// weighted by this. `T(μ) r(μ_t) / (2 ∫₀¹ T(μ′) r(μ′_t) μ′ dμ′)` per channel, with `r` the
/// [`collimated_albedo`], `T` the Fresnel transmittance into index `η` and `μ_t` the refracted
/// cosine; exact for a flat index-matched surface (`η = 1`), an estimate otherwise (light
/// reflected back inside is not followed). Its diffuse mean is 1, so diffuse light is unchanged.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IncidenceWeight {
    alpha: [f64; 3],
    eta: f64,
    diffuse_mean: [f64; 3],
}

impl IncidenceWeight {
    /// The weight of a medium with single-scattering albedos `alpha` (`g = 0`) and index `eta`.
    pub fn new(alpha: [f64; 3], eta: f64) -> Self {
        let mut weight = Self {
            alpha,
            eta: if eta.is_finite() && eta > 0.0 { eta } else { 1.0 },
            diffuse_mean: [1.0; 3],
        };
        let mut mean = [0.0; 3];
        for (mu, w) in GAUSS_8 {
            let taken = weight.unnormalised(mu);
            for c in 0..3 {
                mean[c] += 2.0 * w * mu * taken[c];
            }
        }
        weight.diffuse_mean = mean.map(|m| if m > 0.0 { m } else { 1.0 });
        weight
    }

    fn unnormalised(&self, cos_i: f64) -> [f64; 3] {
        let cos_i = cos_i.clamp(0.0, 1.0);
        let cos_t = refracted_cosine(cos_i, self.eta).unwrap_or(0.0);
        let transmitted = 1.0 - fresnel_reflectance(cos_i, self.eta);
        self.alpha.map(|a| transmitted * collimated_albedo(a, cos_t))
    }

    /// The weight per channel for a beam at incidence cosine `cos_i`.
    pub fn at(&self, cos_i: f64) -> [f64; 3] {
        let taken = self.unnormalised(cos_i);
        std::array::from_fn(|c| taken[c] / self.diffuse_mean[c])
    }
}

/// A medium's diffusion profile per RGB channel, distances in mm.
#[derive(Clone, Copy, Debug)]
pub struct DiffusionProfile {
    channels: [Channel; 3],
    /// Share of diffuse irradiance that crosses the boundary into the medium.
    pub entrance_transmittance: f64,
    /// Single-scattering albedo `α = σs/σt` per channel (`g = 0`: `σs = σs′`) for the
    /// single-scattering term; zero for the Burley kernel, whose `A` includes it.
    pub single_scattering_albedo: [f64; 3],
}

impl DiffusionProfile {
    /// The profile of `medium` (assumed valid: see [`TranslucentMedium::invalid_reason`]),
    /// the dipole's real source one reduced mean free path deep (Jensen's).
    pub fn new(medium: &TranslucentMedium, kernel: DiffusionKernel) -> Self {
        Self::with_source_depth(medium, kernel, 1.0)
    }

    /// [`new`](Self::new) with the dipole's real source `depth` reduced mean free paths deep
    /// (`z_r = depth/σt′`; the virtual one `4AD` above it). Burley's profile has no sources.
    pub fn with_source_depth(
        medium: &TranslucentMedium,
        kernel: DiffusionKernel,
        depth: f64,
    ) -> Self {
        let eta = medium.index_of_refraction as f64;
        let a_boundary = boundary_coefficient(eta);
        let albedos = medium.single_scattering_albedo();
        let channels = std::array::from_fn(|c| {
            let sigma_a = medium.absorption[c] as f64;
            let sigma_t = sigma_a + medium.reduced_scattering[c] as f64;
            let alpha = albedos[c];
            let diffusion = 1.0 / (3.0 * sigma_t);
            let z_real = depth / sigma_t;
            let dipole = |half_albedo| {
                Channel::Dipole(DipoleChannel {
                    half_albedo,
                    sigma_tr: (3.0 * sigma_a * sigma_t).sqrt(),
                    z_real,
                    z_virtual: z_real + 4.0 * a_boundary * diffusion,
                    diffusion,
                    boundary: a_boundary,
                })
            };
            match kernel {
                DiffusionKernel::Dipole => dipole(alpha / 2.0),
                DiffusionKernel::ScaledDipole => {
                    // The dipole's shape, its total rescaled (linear in α′/2) to Chiang's `A`.
                    let total = dipole(alpha / 2.0).total();
                    let albedo = surface_albedo(alpha);
                    dipole(if total > 0.0 { alpha / 2.0 * albedo / total } else { 0.0 })
                }
                DiffusionKernel::Burley => {
                    let albedo = surface_albedo(alpha);
                    // d = ℓ_d / s with ℓ_d = 1/σtr, the diffuse mean free path (σtr ≥ 1e-6 σt′
                    // keeps a medium without absorption finite).
                    let sigma_tr = (3.0 * sigma_a * sigma_t).sqrt().max(1e-6 * sigma_t);
                    Channel::Burley {
                        albedo,
                        s: (3.5 + 100.0 * (albedo - 0.33).powi(4)) * sigma_tr,
                    }
                }
            }
        });
        Self {
            channels,
            entrance_transmittance: 1.0 - diffuse_fresnel_reflectance(eta),
            // Burley's `A` holds single scattering already.
            single_scattering_albedo: match kernel {
                DiffusionKernel::Dipole => albedos,
                DiffusionKernel::Burley | DiffusionKernel::ScaledDipole => [0.0; 3],
            },
        }
    }

    /// The dipole of each channel (`None` for Burley's profile, which has no sources): what
    /// [`shape_diffusion`](super::shape_diffusion) solves the object's shape with.
    pub fn dipole_channels(&self) -> Option<[DipoleChannel; 3]> {
        let [r, g, b] = self.channels.map(|c| c.dipole());
        Some([r?, g?, b?])
    }

    /// `R_d(r)`, mm⁻² (exitance per unit flux entering at distance `r` mm).
    pub fn reflectance(&self, r: f64) -> [f64; 3] {
        self.channels.map(|c| c.reflectance(r))
    }

    /// `W(R) = ∫₀^R 2π r R_d(r) dr`: the share of the entering flux that leaves within a disc
    /// of radius `R` mm about the entry point.
    pub fn reflectance_within(&self, radius: f64) -> [f64; 3] {
        self.channels.map(|c| c.within(radius))
    }

    /// `W(∞)`: the total diffuse reflectance of a semi-infinite slab, per channel.
    pub fn total_reflectance(&self) -> [f64; 3] {
        self.channels.map(|c| c.total())
    }

    /// The smallest radius (mm) within which every channel gives off at least `fraction` of
    /// its total exitance: the reach of the sparse transport beyond which pairs are dropped.
    pub fn radius_holding(&self, fraction: f64) -> f64 {
        let total = self.total_reflectance();
        let holds = |r: f64| (0..3).all(|c| self.channels[c].within(r) >= fraction * total[c]);
        let mut hi = 1.0;
        while !holds(hi) && hi < 1e9 {
            hi *= 2.0;
        }
        let mut lo = 0.0;
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if holds(mid) { hi = mid } else { lo = mid }
        }
        hi
    }

    /// How much more (or less) leaves at `exit` than the flat profile gives at their distance,
    /// per channel, when the dipole's flux is taken along the exit's own normal (see
    /// [`Translucent::oriented_dipole`](super::plugin::Translucent::oriented_dipole));
    /// positions in mm. 1 on a plane and for Burley's profile.
    pub fn orientation_factor(
        &self,
        entry: bevy::math::DVec3,
        entry_normal: bevy::math::DVec3,
        exit: bevy::math::DVec3,
        exit_normal: bevy::math::DVec3,
    ) -> [f64; 3] {
        let r = entry.distance(exit);
        self.channels.map(|c| {
            match c.oriented_reflectance(entry, entry_normal, exit, exit_normal) {
                Some(oriented) => {
                    let flat = c.reflectance(r);
                    if flat > 0.0 { oriented / flat } else { 1.0 }
                }
                None => 1.0,
            }
        })
    }

    /// The share of the flux entering at one point that leaves through a patch of area
    /// `area` (mm²) whose centre is `r` mm away: `W` over the annulus `[r − ρ, r + ρ]` that
    /// the patch's equal-area disc (radius `ρ`) sweeps, times the patch's part of that annulus,
    /// `area / (4π r ρ)`. Unlike `R_d(r) · area`, it stays bounded and keeps the energy of
    /// patches as wide as the profile; at `r ≤ ρ` it is the disc's own `W(ρ)` share.
    pub fn patch_transfer(&self, r: f64, area: f64) -> [f64; 3] {
        let rho = (area / PI).sqrt();
        if r <= rho {
            return self.reflectance_within(rho);
        }
        let outer = self.reflectance_within(r + rho);
        let inner = self.reflectance_within(r - rho);
        let share = area / (4.0 * PI * r * rho);
        std::array::from_fn(|c| (outer[c] - inner[c]) * share)
    }
}
