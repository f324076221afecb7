//! What a translucent object is made of: the absorption and reduced scattering coefficients of
//! its medium per colour channel and the index of refraction of its boundary (Jensen et al.
//! 2001), with the measured presets of that paper's table.

use bevy::prelude::*;

/// A homogeneous scattering medium inside a smooth dielectric boundary, per RGB channel.
///
/// Coefficients are in mm⁻¹, as measured (Jensen, Marschner, Levoy and Hanrahan, "A Practical
/// Model for Subsurface Light Transport", SIGGRAPH 2001, table 2); the scene's length unit is
/// tied to millimetres by `world_units_per_mm` where the medium is used.
#[derive(Clone, Copy, Debug, PartialEq, Reflect)]
pub struct TranslucentMedium {
    /// Absorption coefficient σa per channel, mm⁻¹, ≥ 0.
    pub absorption: Vec3,
    /// Reduced scattering coefficient σs′ = σs (1 − g) per channel, mm⁻¹, > 0.
    pub reduced_scattering: Vec3,
    /// Relative index of refraction η of the boundary (medium / outside), 1.0 – 2.0.
    pub index_of_refraction: f32,
}

impl Default for TranslucentMedium {
    /// Marble: the preset whose diffusion reaches furthest at an albedo close to 1, so that
    /// the effect is plain to see on an object of a few centimetres.
    fn default() -> Self {
        TranslucentPreset::Marble.medium()
    }
}

/// The measured media of Jensen et al. 2001 (table 2), η = 1.3 as that paper renders them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Reflect, Default)]
pub enum TranslucentPreset {
    /// Apple.
    Apple,
    /// Chicken (first sample).
    Chicken1,
    /// Chicken (second sample).
    Chicken2,
    /// Cream.
    Cream,
    /// Ketchup.
    Ketchup,
    /// Marble.
    #[default]
    Marble,
    /// Potato.
    Potato,
    /// Skimmed milk.
    Skimmilk,
    /// Skin (first sample).
    Skin1,
    /// Skin (second sample).
    Skin2,
    /// Spectralon (a near-perfect white diffuser: no absorption).
    Spectralon,
    /// Whole milk.
    Wholemilk,
}

impl TranslucentPreset {
    /// Every preset, in the table's order.
    pub const ALL: [TranslucentPreset; 12] = [
        Self::Apple,
        Self::Chicken1,
        Self::Chicken2,
        Self::Cream,
        Self::Ketchup,
        Self::Marble,
        Self::Potato,
        Self::Skimmilk,
        Self::Skin1,
        Self::Skin2,
        Self::Spectralon,
        Self::Wholemilk,
    ];

    /// (σs′, σa) in mm⁻¹, RGB, as Jensen et al. 2001 measured them.
    pub fn coefficients(self) -> ([f32; 3], [f32; 3]) {
        match self {
            Self::Apple => ([2.29, 2.39, 1.97], [0.0030, 0.0034, 0.046]),
            Self::Chicken1 => ([0.15, 0.21, 0.38], [0.015, 0.077, 0.19]),
            Self::Chicken2 => ([0.19, 0.25, 0.32], [0.018, 0.088, 0.20]),
            Self::Cream => ([7.38, 5.47, 3.15], [0.0002, 0.0028, 0.0163]),
            Self::Ketchup => ([0.18, 0.07, 0.03], [0.061, 0.97, 1.45]),
            Self::Marble => ([2.19, 2.62, 3.00], [0.0021, 0.0041, 0.0071]),
            Self::Potato => ([0.68, 0.70, 0.55], [0.0024, 0.0090, 0.12]),
            Self::Skimmilk => ([0.70, 1.22, 1.90], [0.0014, 0.0025, 0.0142]),
            Self::Skin1 => ([0.74, 0.88, 1.01], [0.032, 0.17, 0.48]),
            Self::Skin2 => ([1.09, 1.59, 1.79], [0.013, 0.070, 0.145]),
            Self::Spectralon => ([11.6, 20.4, 14.9], [0.0, 0.0, 0.0]),
            Self::Wholemilk => ([2.55, 3.21, 3.77], [0.0011, 0.0024, 0.014]),
        }
    }

    /// The preset as a medium with η = 1.3.
    pub fn medium(self) -> TranslucentMedium {
        let (reduced_scattering, absorption) = self.coefficients();
        TranslucentMedium {
            absorption: Vec3::from(absorption),
            reduced_scattering: Vec3::from(reduced_scattering),
            index_of_refraction: 1.3,
        }
    }
}

impl TranslucentMedium {
    /// The single-scattering albedo `α′ = σs′ / (σa + σs′)` per channel (`g = 0`: `σs = σs′`).
    pub fn single_scattering_albedo(&self) -> [f64; 3] {
        std::array::from_fn(|c| {
            let (a, s) = (self.absorption[c] as f64, self.reduced_scattering[c] as f64);
            s / (a + s)
        })
    }

    /// Why the medium cannot be used, if it cannot: coefficients that are negative or not
    /// finite, no scattering, or an index of refraction outside 1.0 – 3.0.
    pub fn invalid_reason(&self) -> Option<String> {
        let finite = self.absorption.is_finite() && self.reduced_scattering.is_finite();
        if !finite {
            return Some(format!(
                "coefficients must be finite (σa {}, σs′ {})",
                self.absorption, self.reduced_scattering
            ));
        }
        if self.absorption.min_element() < 0.0 {
            return Some(format!("absorption σa {} is negative", self.absorption));
        }
        if !(self.reduced_scattering.min_element() > 0.0) {
            return Some(format!(
                "reduced scattering σs′ {} must be positive in every channel",
                self.reduced_scattering
            ));
        }
        if !(1.0..=3.0).contains(&self.index_of_refraction) {
            return Some(format!(
                "index of refraction {} is outside 1.0 – 3.0",
                self.index_of_refraction
            ));
        }
        None
    }
}
