//! The gradient map (MHGM, paper §2.1) with one-sided differences and boundary flags.

use super::{DepthContinuity, ScreenHeightMap};

/// Pixel offsets of the 8 neighbours, in the order of the connectivity bits.
/// `y` grows downwards (texture rows). The GPU shaders use the same table.
pub const NEIGHBOURS: [(i32, i32); 8] = [
    (1, 0),
    (1, 1),
    (0, 1),
    (-1, 1),
    (-1, 0),
    (-1, -1),
    (0, -1),
    (1, -1),
];

/// The pixel carries a mesostructure surface.
pub const FLAG_VALID: u32 = 1 << 0;
/// The pixel touches the screen edge.
pub const FLAG_SCREEN_EDGE: u32 = 1 << 1;
/// A neighbour belongs to another object or to no mesostructure surface (silhouette).
pub const FLAG_OBJECT_EDGE: u32 = 1 << 2;
/// A neighbour of the same object lies across a depth discontinuity.
pub const FLAG_DEPTH_EDGE: u32 = 1 << 3;
/// All boundary kinds: a pixel with any of them is a boundary point of the visible region M'.
pub const FLAG_BOUNDARY: u32 = FLAG_SCREEN_EDGE | FLAG_OBJECT_EDGE | FLAG_DEPTH_EDGE;
/// Shift of the 8-bit neighbour connectivity mask (bit `i` = [`NEIGHBOURS`]`[i]` is connected).
pub const CONNECTIVITY_SHIFT: u32 = 8;

/// Shift of the ascent direction in a pixel's packed flags word (`gradient.wgsl`): bits 0–15
/// are the `FLAG_*` bits and the connectivity mask, bits 16–19 the gradient's direction
/// quantised to an index into [`NEIGHBOURS`] ([`NO_ASCENT`]: a zero gradient).
pub const ASCENT_SHIFT: u32 = 16;
/// The ascent direction of a pixel whose gradient is zero.
pub const NO_ASCENT: u8 = 8;

/// The gradient map of a [`ScreenHeightMap`], in the form the apex search reads it: the
/// gradient only ever chooses the gradient ascent's next neighbour (§2.2), so each pixel keeps
/// its direction quantised to one of the 8 neighbours ([`quantize_direction`]) rather than the
/// gradient itself (the GPU packs height, flags and direction in 8 bytes a pixel).
#[derive(Clone, Debug, PartialEq)]
pub struct GradientMap {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// The height gradient's direction, an index into [`NEIGHBOURS`], or [`NO_ASCENT`].
    pub ascent: Vec<u8>,
    /// `FLAG_*` bits and the connectivity mask.
    pub flags: Vec<u32>,
}

impl GradientMap {
    /// The neighbour the height gradient of pixel `i` points at, if it is not zero.
    #[inline]
    pub fn ascent_direction(&self, i: usize) -> Option<usize> {
        (self.ascent[i] < NO_ASCENT).then_some(self.ascent[i] as usize)
    }

    /// Whether pixel `i` is connected to its neighbour `dir` (an index into [`NEIGHBOURS`]).
    #[inline]
    pub fn connected(&self, i: usize, dir: usize) -> bool {
        self.flags[i] >> (CONNECTIVITY_SHIFT + dir as u32) & 1 == 1
    }

    /// Whether pixel `i` is a boundary point of the visible region.
    #[inline]
    pub fn is_boundary(&self, i: usize) -> bool {
        self.flags[i] & FLAG_VALID != 0 && self.flags[i] & FLAG_BOUNDARY != 0
    }
}

/// Computes the MHGM: per valid pixel, the 8-neighbour connectivity (same object, on screen, no
/// depth discontinuity), the boundary flags, and the direction of the gradient
/// ([`gradient_at`]).
pub fn gradient_map(mhm: &ScreenHeightMap, continuity: DepthContinuity) -> GradientMap {
    let n = (mhm.width * mhm.height) as usize;
    let mut ascent = vec![NO_ASCENT; n];
    let mut flags = vec![0u32; n];
    for y in 0..mhm.height as i32 {
        for x in 0..mhm.width as i32 {
            let i = mhm.index(x as u32, y as u32);
            let (g, f) = gradient_at(mhm, continuity, x, y);
            ascent[i] = quantize_direction(g).map_or(NO_ASCENT, |d| d as u8);
            flags[i] = f;
        }
    }
    GradientMap {
        width: mhm.width,
        height: mhm.height,
        ascent,
        flags,
    }
}

/// Quantizes a gradient to the index of the 8-neighbour nearest its direction (22.5° sectors),
/// or `None` for a zero gradient. Mirrors `quantize_direction` in `gradient.wgsl`.
pub fn quantize_direction(g: [f32; 2]) -> Option<usize> {
    const TAN_22_5: f32 = 0.414_213_57;
    let (ax, ay) = (g[0].abs(), g[1].abs());
    if ax == 0.0 && ay == 0.0 {
        return None;
    }
    let sx = if ax > TAN_22_5 * ay {
        g[0].signum() as i32
    } else {
        0
    };
    let sy = if ay > TAN_22_5 * ax {
        g[1].signum() as i32
    } else {
        0
    };
    NEIGHBOURS.iter().position(|&o| o == (sx, sy))
}

/// One pixel of [`gradient_map`]: the gradient of height in world units per pixel,
/// `(∂h/∂x, ∂h/∂y)` with y down — by central differences where both neighbours on an axis are
/// connected, one-sided differences where one is, and 0 where none is — and the pixel's flags.
/// Mirrors `gradient.wgsl`.
pub fn gradient_at(mhm: &ScreenHeightMap, c: DepthContinuity, x: i32, y: i32) -> ([f32; 2], u32) {
    let i = mhm.index(x as u32, y as u32);
    let object = mhm.objects[i];
    if object == 0 {
        return ([0.0, 0.0], 0);
    }
    let d0 = mhm.depths[i];
    let same_object = |qx: i32, qy: i32| {
        mhm.contains(qx, qy) && mhm.objects[mhm.index(qx as u32, qy as u32)] == object
    };
    let mut flags = FLAG_VALID;
    for (dir, &(ox, oy)) in NEIGHBOURS.iter().enumerate() {
        let (qx, qy) = (x + ox, y + oy);
        if !mhm.contains(qx, qy) {
            flags |= FLAG_SCREEN_EDGE;
            continue;
        }
        if !same_object(qx, qy) {
            flags |= FLAG_OBJECT_EDGE;
            continue;
        }
        let dq = mhm.depths[mhm.index(qx as u32, qy as u32)];
        let mut tolerance = c.relative * d0;
        let (px, py) = (x - ox, y - oy);
        if same_object(px, py) {
            let dp = mhm.depths[mhm.index(px as u32, py as u32)];
            tolerance = tolerance.max(c.slope_factor * (d0 - dp).abs());
        }
        if (dq - d0).abs() > tolerance {
            flags |= FLAG_DEPTH_EDGE;
            continue;
        }
        flags |= 1 << (CONNECTIVITY_SHIFT + dir as u32);
    }
    let h0 = mhm.heights[i];
    let height_at = |dir: usize| {
        let (ox, oy) = NEIGHBOURS[dir];
        mhm.heights[mhm.index((x + ox) as u32, (y + oy) as u32)]
    };
    let connected = |dir: usize| flags >> (CONNECTIVITY_SHIFT + dir as u32) & 1 == 1;
    // Axis pairs: +x is neighbour 0, −x is 4, +y is 2, −y is 6.
    let axis = |plus: usize, minus: usize| match (connected(plus), connected(minus)) {
        (true, true) => (height_at(plus) - height_at(minus)) * 0.5,
        (true, false) => height_at(plus) - h0,
        (false, true) => h0 - height_at(minus),
        (false, false) => 0.0,
    };
    ([axis(0, 4), axis(2, 6)], flags)
}
