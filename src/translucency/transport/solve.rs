//! The per-frame solve: `B = K (E⁰ − E_t) + S⁰ + T x + K F (B + P)` (`P` the lit faces'
//! single scattering, which the gather gives per pixel) iterated as a series of
//! increments from zero or (a warm start) from the last solution, stopped at a threshold, the
//! rest added as the series' geometric tail. `iterate.wgsl` is its GPU twin.

use bevy::prelude::*;

use super::{DirectLight, EnergyTransport};

/// The converged transport of one frame's light.
#[derive(Clone, Debug, Default)]
pub struct TransportSolution {
    /// Exitance `B` per patch (outgoing radiance `B/π`).
    pub exitance: Vec<Vec3>,
    /// Irradiance `E` arriving per patch, direct and bounced.
    pub irradiance: Vec<Vec3>,
    /// Iterations run (each one `F` and one `K` product).
    pub iterations: u32,
    /// The energy of the last increment relative to the first bounce's: below the
    /// threshold unless `iterations` hit the cap.
    pub energy_left: f32,
    /// How much the last increment's flux shrank from the one before: `B` holds the
    /// geometric tail `ΔB r/(1 − r)` beyond it ([`MAX_TAIL_RATIO`] at most; 0 without an
    /// iteration).
    pub tail_ratio: f32,
}

/// A warm start ([`EnergyTransport::solve_from`]) stops at this share of the threshold: its
/// increments are differences between two lights' solutions, not the dominant mode the
/// geometric tail assumes, so stopped at the threshold itself they left 0.1 – 0.6 % of `B`
/// in error over a chain of frames (a one-off trial); at a tenth, the room of
/// `docs/translucent.md` with its spot turning 0.75° a frame takes 2.3 – 2.6 products a frame
/// instead of 10, at worst 6.6e-4 from the converged `B` (a cold start's: 2.8e-4;
/// `translucent_precompute --warm-frames 30`).
pub const WARM_THRESHOLD_SHARE: f32 = 0.1;

/// The most products a warm start takes in one frame, its first application counted
/// ([`warm_iterations`]): the GPU records no more (`GpuTransport::record`), and the plugin
/// goes on warm from where it stopped in the frames after the lights stop
/// ([`settle_frames`]). A spot turning 0.75° a frame took at most 5 in the room of
/// `docs/translucent.md`, 2.3 – 2.6 on average (`translucent_precompute --warm-frames`);
/// the loop's recorded iterations cost even when empty (22 µs each on an H100: 0.58 ms a
/// frame at 16 against 0.36 at 6, `tools/translucency-h100.sh`).
pub const WARM_MAX_ITERATIONS: u32 = 6;

/// The most products a warm start takes for a cap of `max_iterations`.
pub fn warm_iterations(max_iterations: u32) -> u32 {
    max_iterations.min(WARM_MAX_ITERATIONS)
}

/// How many warm solves of [`warm_iterations`] products the plugin records after the lights
/// stop (their own light unchanged), so that a solve the cap cut short gets at least
/// `max_iterations` more products, as a cold start would.
pub fn settle_frames(max_iterations: u32) -> u32 {
    max_iterations.div_ceil(warm_iterations(max_iterations).max(1))
}

/// The most the iteration's tail ratio is trusted: 0.95 adds at most 19 last increments.
/// A closed box of albedo ρ converges as ρ (the room of `docs/translucent.md` as ~0.62).
pub const MAX_TAIL_RATIO: f32 = 0.95;

/// The geometric tail of the increments the iteration stopped before: each one about `ratio`
/// times the last (the dominant eigenvalue of `K F`), so the rest sums to
/// `last · ratio / (1 − ratio)` (`ratio` capped at [`MAX_TAIL_RATIO`]).
pub fn geometric_tail(last: Vec3, ratio: f32) -> Vec3 {
    let r = ratio.clamp(0.0, MAX_TAIL_RATIO);
    last * (r / (1.0 - r))
}

impl EnergyTransport {
    /// Σ A_i (|B_i.r| + |B_i.g| + |B_i.b|): the size of an increment whose sign varies (a
    /// warm start's, [`solve_from`](Self::solve_from)).
    pub fn absolute_flux(&self, exitance: &[Vec3]) -> f32 {
        exitance
            .iter()
            .zip(&self.areas)
            .map(|(b, a)| a * (b.x.abs() + b.y.abs() + b.z.abs()))
            .sum()
    }

    /// Σ A_i (B_i.r + B_i.g + B_i.b): the flux of an exitance vector.
    pub fn flux(&self, exitance: &[Vec3]) -> f32 {
        exitance
            .iter()
            .zip(&self.areas)
            .map(|(b, a)| a * (b.x + b.y + b.z))
            .sum()
    }

    /// `E = F B`: the irradiance each patch gathers from the exitance `B` of the others
    /// (clusters' exitance as their members' area mean).
    pub fn gather(&self, exitance: &[Vec3]) -> Vec<Vec3> {
        let means = self.cluster_means.mul_vec(exitance);
        let extended: Vec<Vec3> = exitance.iter().chain(&means).copied().collect();
        self.form_factors.mul_vec(&extended)
    }

    /// Iterates `ΔE = F ΔB`, `ΔB = K ΔE` from `B = K E⁰` until the flux of `ΔB` is below
    /// `threshold` × the flux of the first `B`, or `max_iterations`; then adds the
    /// [`geometric_tail`] of the last `ΔB` to `B`.
    pub fn solve(&self, direct: &[Vec3], threshold: f32, max_iterations: u32) -> TransportSolution {
        self.solve_with(
            &DirectLight {
                irradiance: direct.to_vec(),
                ..default()
            },
            threshold,
            max_iterations,
        )
    }

    /// [`solve`](Self::solve) from `B = K (E⁰ − E_t) + S⁰ + T x`: `direct.exitance` is the
    /// exitance the direct light leaves besides (single scattering at each beam's own
    /// incidence), `direct.tabled` (`E_t`) the irradiance that the beam table `T` carries
    /// instead of `K`, `direct.beam_light` (`x`) that irradiance by table direction. The
    /// first bounce gathers `B + P`, `P` the lit faces' single scattering
    /// (`direct.lit_face_exitance`, which the gather gives per pixel), so that
    /// `B = K (E⁰ − E_t) + S⁰ + T x + K F (B + P)`.
    pub fn solve_with(
        &self,
        direct: &DirectLight,
        threshold: f32,
        max_iterations: u32,
    ) -> TransportSolution {
        self.solve_from(direct, threshold, max_iterations, None)
    }

    /// [`solve_with`](Self::solve_with), warm-started from `previous` (this transport's last
    /// solution, for other light) where given: one application of the whole map,
    /// `B₁ = K (E⁰ − E_t + F B_prev) + S⁰ + T x` (`E = E⁰ + F B_prev`), then the series of
    /// its increment `ΔB = B₁ − B_prev` as from a cold start; the application counts as an
    /// iteration. The increment's sign varies, so its size is its absolute flux; the loop
    /// stops once that is at most [`WARM_THRESHOLD_SHARE`] × `threshold` of the first
    /// bounce's, estimated as `flux(B₁) (1 − r)` with `r` the previous solution's tail ratio
    /// (the series sums to the first bounce over `1 − r`), and the tail takes `r` until the
    /// increments show their own. A light that moves a little a frame leaves a small
    /// increment (`docs/translucent.md`). `previous` of another size is ignored (a cold
    /// start).
    pub fn solve_from(
        &self,
        direct: &DirectLight,
        threshold: f32,
        max_iterations: u32,
        previous: Option<&TransportSolution>,
    ) -> TransportSolution {
        let previous = previous.filter(|s| s.exitance.len() == self.areas.len());
        let mut irradiance = direct.irradiance.clone();
        let mut scattered: Vec<Vec3> = if direct.tabled.is_empty() {
            direct.irradiance.clone()
        } else {
            direct.irradiance.iter().zip(&direct.tabled).map(|(e, t)| *e - *t).collect()
        };
        // Single scattering by the lit faces leaves by the gather, not `B`, but lights the
        // others: it joins the source of the first bounce (`direct.lit_face_exitance`).
        let with_lit_face = |b: &[Vec3]| -> Vec<Vec3> {
            b.iter()
                .enumerate()
                .map(|(i, v)| *v + direct.lit_face_exitance.get(i).copied().unwrap_or(Vec3::ZERO))
                .collect()
        };
        if let Some(previous) = previous {
            let gathered = self.gather(&with_lit_face(&previous.exitance));
            for ((e, s), g) in irradiance.iter_mut().zip(scattered.iter_mut()).zip(&gathered) {
                *e += *g;
                *s += *g;
            }
        }
        let mut delta = self.scattering.mul_vec(&scattered);
        for (d, s) in delta.iter_mut().zip(&direct.exitance) {
            *d += *s;
        }
        if let Some(table) = self.beam_table.as_ref().filter(|_| !direct.beam_light.is_empty()) {
            for (d, s) in delta.iter_mut().zip(table.apply(&direct.beam_light)) {
                *d += s;
            }
        }
        let mut exitance = delta.clone();
        // Cold: the first bounce gathers the lit faces' single scattering with `B`.
        if previous.is_none() {
            delta = with_lit_face(&delta);
        }
        // Cold: the first bounce's flux, the increments' flux (never negative but for a
        // profile's negative correction), the ratio found by the loop. Warm: B₁'s share the
        // first bounce holds, the increments' absolute flux, the last solution's ratio until
        // the increments show their own; the application counted as an iteration.
        let (first, size, threshold, mut tail_ratio, mut iterations): (f32, fn(&Self, &[Vec3]) -> f32, f32, f32, u32) =
            match previous {
                None => (self.flux(&delta), Self::flux, threshold, 0.0, 0),
                Some(previous) => {
                    let ratio = previous.tail_ratio.clamp(0.0, MAX_TAIL_RATIO);
                    for (d, b) in delta.iter_mut().zip(&previous.exitance) {
                        *d -= *b;
                    }
                    let first = self.flux(&exitance) * (1.0 - ratio);
                    (first, Self::absolute_flux, threshold * WARM_THRESHOLD_SHARE, ratio, 1)
                }
            };
        let start = size(self, &delta);
        // Nothing lit: nothing to iterate.
        let mut energy_left = if first > 0.0 { start / first } else { 0.0 };
        let mut previous_flux = start;
        while iterations < max_iterations && energy_left > threshold {
            let gathered = self.gather(&delta);
            for (e, g) in irradiance.iter_mut().zip(&gathered) {
                *e += *g;
            }
            delta = self.scattering.mul_vec(&gathered);
            for (b, d) in exitance.iter_mut().zip(&delta) {
                *b += *d;
            }
            iterations += 1;
            let flux = size(self, &delta);
            energy_left = flux / first;
            tail_ratio = if previous_flux > 0.0 { flux / previous_flux } else { 0.0 };
            previous_flux = flux;
        }
        // What the truncated series leaves: with the tail a threshold of 1e-2 (10 iterations
        // in the room of docs/translucent.md) comes within 0.03 % of the converged B, where
        // 1e-3 without it (15 iterations) came within 0.05–0.07 %.
        if iterations > 0 {
            for (b, d) in exitance.iter_mut().zip(&delta) {
                *b += geometric_tail(*d, tail_ratio);
            }
        }
        TransportSolution {
            exitance,
            irradiance,
            iterations,
            energy_left,
            tail_ratio: if iterations > 0 { tail_ratio.clamp(0.0, MAX_TAIL_RATIO) } else { 0.0 },
        }
    }
}
