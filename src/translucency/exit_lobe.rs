//! Exit lobes: the law light leaves a translucent patch by, fitted to the mean direction the
//! beam table's walks leave along. Light that crossed an object after a few scatterings
//! still leans the way it travelled; Lambert's law gives it out evenly and, lit from behind,
//! no transport beats 0.36 in relative L1 with it (`docs/translucent.md`: the exact
//! transport given out by Lambert's law). A von Mises–Fisher lobe `exp(κ(ω·u − 1))` over the
//! outward hemisphere with the walks' own exitance-weighted mean direction scored 0.129
//! there.
//!
//! A lobe is found from its mean by a table over the mean's two components (along the
//! normal and across it), [`LobeFits`], built once from a grid of lobes.

use std::sync::OnceLock;

use bevy::math::Vec3;

/// A von Mises–Fisher lobe over a patch's outward hemisphere, as a factor on Lambert's law:
/// `norm · exp(κ (ω·u − 1))`, `norm` such that the factor's cosine-weighted mean is 1 (it
/// keeps the exitance).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ExitLobe {
    /// Unit axis `u`.
    pub axis: Vec3,
    /// `κ ≥ 0`: 0 is Lambert's law.
    pub sharpness: f32,
    /// `norm`.
    pub norm: f32,
}

impl ExitLobe {
    /// The factor on Lambert's law towards the unit `towards` (outside).
    pub fn factor(&self, towards: Vec3) -> f32 {
        self.norm * (self.sharpness * (towards.dot(self.axis) - 1.0)).exp()
    }
}

/// Cells of the fit table per unit of the mean's components (`FIT_CELLS` in `iterate.wgsl`).
pub const FIT_CELLS: usize = 64;

/// The table of lobes by their mean direction's components along the normal and across it
/// (`FIT_CELLS` cells each over 0 – 1): per cell, `(κ, θ, norm)` of the lobe whose mean is
/// nearest the cell's centre, `θ` its axis's angle from the normal towards the mean's
/// tangential side.
pub struct LobeFits {
    cells: Vec<[f32; 3]>,
}

impl LobeFits {
    /// The table, built on first use (a grid of 97 sharpnesses by 121 angles).
    pub fn get() -> &'static Self {
        static FITS: OnceLock<LobeFits> = OnceLock::new();
        FITS.get_or_init(Self::build)
    }

    fn build() -> Self {
        // Hemisphere quadrature about +z, uniform in the polar angle, weighted by sin θ cos θ
        // (the cosine-weighted measure): not `diffusion::cosine_weighted_directions`, whose
        // rings uniform in μ² leave 7° about the normal empty at 32 rings, wider than the
        // sharpest lobes here (κ 80: ~6°).
        let (polar, azimuthal) = (32, 64);
        let mut samples = Vec::with_capacity(polar * azimuthal);
        for r in 0..polar {
            let theta = std::f32::consts::FRAC_PI_2 * (r as f32 + 0.5) / polar as f32;
            let weight = theta.sin() * theta.cos();
            for k in 0..azimuthal {
                let phi = std::f32::consts::TAU * (k as f32 + 0.5) / azimuthal as f32;
                let omega = Vec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos());
                samples.push((omega, weight));
            }
        }
        let total: f32 = samples.iter().map(|s| s.1).sum();
        // Each lobe's mean (along, across) and norm.
        let mut lobes = Vec::new();
        let sharpnesses = std::iter::once(0.0).chain((0..96).map(|i| 0.05 * (1600.0f32).powf(i as f32 / 95.0)));
        for kappa in sharpnesses {
            for a in 0..121 {
                let theta = std::f32::consts::PI * a as f32 / 120.0;
                let axis = Vec3::new(theta.sin(), 0.0, theta.cos());
                let (mut flux, mut mean) = (0.0f32, Vec3::ZERO);
                for &(omega, weight) in &samples {
                    let f = (kappa * (omega.dot(axis) - 1.0)).exp() * weight;
                    flux += f;
                    mean += f * omega;
                }
                if flux > 0.0 {
                    mean /= flux;
                    lobes.push((mean.z, mean.x, kappa, theta, total / flux));
                }
                if kappa == 0.0 {
                    break;
                }
            }
        }
        let cells = (0..FIT_CELLS * FIT_CELLS)
            .map(|cell| {
                let along = ((cell / FIT_CELLS) as f32 + 0.5) / FIT_CELLS as f32;
                let across = ((cell % FIT_CELLS) as f32 + 0.5) / FIT_CELLS as f32;
                let nearest = lobes
                    .iter()
                    .min_by(|a, b| {
                        let d = |l: &&(f32, f32, f32, f32, f32)| (l.0 - along).powi(2) + (l.1 - across).powi(2);
                        d(a).total_cmp(&d(b))
                    })
                    .expect("the grid holds lobes");
                [nearest.2, nearest.3, nearest.4]
            })
            .collect();
        Self { cells }
    }

    /// The table's cells, `(κ, θ, norm)`, by the mean's component along the normal, then
    /// across it (what `exit_lobe` in `iterate.wgsl` reads).
    pub fn cells(&self) -> &[[f32; 3]] {
        &self.cells
    }

    /// The lobe about a patch of unit `normal` whose exitance-weighted mean leaving direction
    /// is `mean` (length ≤ 1); Lambert's where the mean is zero or not finite.
    pub fn lobe(&self, normal: Vec3, mean: Vec3) -> ExitLobe {
        let lambert = ExitLobe { axis: normal, sharpness: 0.0, norm: 1.0 };
        if !mean.is_finite() || mean == Vec3::ZERO {
            return lambert;
        }
        let along = mean.dot(normal);
        let tangent = mean - along * normal;
        let across = tangent.length();
        let tangent = if across > 1e-6 { tangent / across } else { normal.any_orthonormal_vector() };
        let index = |v: f32| ((v * FIT_CELLS as f32) as usize).min(FIT_CELLS - 1);
        let [kappa, theta, norm] = self.cells[index(along.clamp(0.0, 1.0)) * FIT_CELLS + index(across.clamp(0.0, 1.0))];
        ExitLobe { axis: theta.cos() * normal + theta.sin() * tangent, sharpness: kappa, norm }
    }
}
