//! The method's parameters and GPU layouts that the render passes and the CPU oracle share:
//! compiled with or without the `oracle` feature (the rest of [`crate::reference`] is the
//! oracle itself, for tests and tools).

use bevy::reflect::std_traits::ReflectDefault;

/// The most indirect sample directions a pixel may use (the GPU uniform holds this many).
pub const MAX_APEX_DIRECTIONS: u32 = 16;

/// Bounds and sampling of the apex search.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ApexSearch {
    /// Indirect sample directions around P (0..=[`MAX_APEX_DIRECTIONS`]).
    pub directions: u32,
    /// Ascent steps (one pixel each) before an ascent gives up; bounds the work per pixel.
    pub max_steps: u32,
    /// Longest walk, in pixels, from P towards each direction's valley.
    pub max_walk: u32,
}

impl Default for ApexSearch {
    fn default() -> Self {
        Self {
            directions: 8,
            max_steps: 64,
            max_walk: 32,
        }
    }
}

/// The unit direction `(cos θ_i, sin θ_i)` of each indirect sample, `θ_i = 2π i / n`, as `f32`.
/// The GPU receives this table, so both sides round the sample points identically.
pub fn sample_directions(n: u32) -> Vec<[f32; 2]> {
    (0..n)
        .map(|i| {
            let theta = std::f64::consts::TAU * i as f64 / n as f64;
            [theta.cos() as f32, theta.sin() as f32]
        })
        .collect()
}

/// How neighbouring depths are judged continuous.
///
/// Neighbour `q` of `p` is across a depth discontinuity when
/// `|d(q) − d(p)| > max(relative · d(p), slope_factor · |d(p) − d(p − (q − p))|)`:
/// a jump larger than a small fraction of the depth and larger than the slope seen on the
/// opposite side. Reverse-Z NDC depth is affine in screen space on a plane, so planes at grazing
/// angles stay connected through the second term.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthContinuity {
    /// Relative depth jump always accepted (fraction of the pixel's NDC depth).
    pub relative: f32,
    /// How much steeper than the opposite side a continuous neighbour may be.
    pub slope_factor: f32,
}

impl Default for DepthContinuity {
    fn default() -> Self {
        Self {
            relative: 0.02,
            slope_factor: 3.0,
        }
    }
}

/// Which integral turns horizon angles into occlusion.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, bevy::reflect::Reflect)]
#[reflect(Default, Clone, Debug, PartialEq, Hash)]
pub enum OcclusionForm {
    /// `1/(2π) ∫ cos² h(θ) dθ`, elevations from the tangent plane of the mesostructure surface
    /// (its normal N' from the surface points of the neighbours): the cosine-weighted
    /// visibility of a Lambertian surface, what a path tracer computes under a white sky.
    #[default]
    CosineWeighted,
    /// `1/(2π) ∫ (1 − sin h(θ)) dθ`, elevations from the core tangent plane (normal n0): the
    /// paper's eq. (6) as it stands.
    Paper,
}

impl OcclusionForm {
    /// Shader-side code.
    pub fn code(self) -> u32 {
        match self {
            Self::CosineWeighted => 0,
            Self::Paper => 1,
        }
    }

    /// Visibility of one sector whose horizon elevation is `h` (radians).
    pub fn sector_visibility(self, sin_h: f32) -> f32 {
        match self {
            Self::CosineWeighted => 1.0 - sin_h * sin_h,
            Self::Paper => 1.0 - sin_h,
        }
    }
}

/// GPU layout of one pixel's apex set in the apex buffer: a header word, then one word per apex
/// (direct first), each `(dx: i16, dy: i16)` relative to P. Decoded by the oracle's
/// `unpack_apex_set`.
pub mod packed {
    /// Bits 0..5 of the header: number of apexes.
    pub const COUNT_MASK: u32 = 0x3f;
    /// The first apex is the direct apex.
    pub const DIRECT_PRESENT: u32 = 1 << 6;
    /// An ascent of this pixel hit the step bound.
    pub const TRUNCATED: u32 = 1 << 7;
    /// Bit `BOUNDARY_SHIFT + slot` marks a boundary point.
    pub const BOUNDARY_SHIFT: u32 = 8;
    /// Bits `ORIGIN_SHIFT..+2` and `ORIGIN_SHIFT + 2..+4`: x and y of the searched pixel inside
    /// its block, at a reduced working resolution (offsets are relative to it).
    pub const ORIGIN_SHIFT: u32 = 25;

    /// The pixel a set was searched from, from its header and its block's top-left pixel.
    pub const fn origin(header: u32, (x, y): (i32, i32)) -> (i32, i32) {
        (
            x + ((header >> ORIGIN_SHIFT) & 3) as i32,
            y + ((header >> (ORIGIN_SHIFT + 2)) & 3) as i32,
        )
    }

    /// Words per pixel for `directions` indirect samples: header, direct apex, indirect apexes.
    pub const fn stride(directions: u32) -> u32 {
        2 + directions
    }
}
