//! Plain-Rust implementation of the method on images: the test oracle for the GPU passes, and a
//! tool for experiments (paper §2). Behind the `oracle` feature, except for the parameters and
//! GPU layouts the passes share with it (always compiled); a game needs none of the rest.
//!
//! The GPU passes (`src/render/`) implement exactly these steps, with the same constants and
//! the same tie-breaking, so the GPU contract tests can feed the screen-space height map read
//! back from the GPU into `gradient_map` and `apex_sets` and compare.
//!
//! - `ScreenHeightMap`: the MHM, per pixel the height `dis·k` in world units, an object id
//!   (0 = no mesostructure surface) and the reverse-Z NDC depth.
//! - `gradient_map`: the MHGM, per pixel the 8-neighbour connectivity, the boundary flags and
//!   the gradient's direction.
//! - `apex_sets`: the local apex set f(P) of every pixel: the direct apex by gradient ascent,
//!   indirect apexes from sampled directions, and boundary points.
//! - `occlusion`, `micro_shadow`, `bleeding_irradiance`: the lighting terms of paper §3 from the
//!   apex sets; `ground_truth` computes them from the height field itself.

mod parameters;
pub use parameters::*;

#[cfg(feature = "oracle")]
mod apex;
#[cfg(feature = "oracle")]
mod gradient;
#[cfg(feature = "oracle")]
pub mod ground_truth;
#[cfg(feature = "oracle")]
mod lighting;
#[cfg(feature = "oracle")]
mod occlusion;
#[cfg(feature = "oracle")]
pub mod texture_space;

#[cfg(feature = "oracle")]
pub use apex::*;
#[cfg(feature = "oracle")]
pub use gradient::*;
#[cfg(feature = "oracle")]
pub use lighting::*;
#[cfg(feature = "oracle")]
pub use occlusion::*;

/// The screen-space height map (MHM, paper §2.1) of one view.
#[cfg(feature = "oracle")]
#[derive(Clone, Debug, PartialEq)]
pub struct ScreenHeightMap {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Height above the core surface, `dis · k`, in world units; row-major, row 0 at the top.
    pub heights: Vec<f32>,
    /// Object id per pixel; 0 where no mesostructure surface is visible.
    pub objects: Vec<u32>,
    /// Reverse-Z NDC depth per pixel (1 at the near plane, 0 at infinity).
    pub depths: Vec<f32>,
}

#[cfg(feature = "oracle")]
impl ScreenHeightMap {
    /// A screen-space height map of one object (id 1) covering the whole image at constant depth,
    /// from a height image in world units.
    pub fn from_heights(width: u32, height: u32, heights: Vec<f32>) -> Self {
        let n = (width * height) as usize;
        assert_eq!(heights.len(), n, "height image has the wrong size");
        Self {
            width,
            height,
            heights,
            objects: vec![1; n],
            depths: vec![0.5; n],
        }
    }

    /// A height image sampled from a function of the pixel centre `(x, y)`.
    pub fn from_fn(width: u32, height: u32, f: impl Fn(f32, f32) -> f32) -> Self {
        let mut heights = Vec::with_capacity((width * height) as usize);
        for y in 0..height {
            for x in 0..width {
                heights.push(f(x as f32 + 0.5, y as f32 + 0.5));
            }
        }
        Self::from_heights(width, height, heights)
    }

    /// Index of pixel `(x, y)`.
    #[inline]
    pub fn index(&self, x: u32, y: u32) -> usize {
        (y * self.width + x) as usize
    }

    /// Whether `(x, y)` lies on screen.
    #[inline]
    pub fn contains(&self, x: i32, y: i32) -> bool {
        x >= 0 && y >= 0 && (x as u32) < self.width && (y as u32) < self.height
    }
}

#[cfg(all(test, feature = "oracle"))]
mod tests;
