//! Local apex sets f(P) (paper §2.2): gradient ascent over the MHGM.

use super::{
    ApexSearch, GradientMap, MAX_APEX_DIRECTIONS, NEIGHBOURS, ScreenHeightMap, packed,
    sample_directions,
};

/// An apex must rise above P by more than this (world units) to occlude anything; it keeps
/// flat maps free of apexes.
pub const APEX_MIN_RISE: f32 = 1.0e-6;

/// Relative height change under which a line climb counts the surface as flat and stops.
pub const CLIMB_FLATNESS: f32 = 1.0e-4;

/// How an ascent ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ApexKind {
    /// A local maximum of height among the connected neighbours.
    Local,
    /// The ascent wanted to leave the visible region M' here: a boundary point B_P.
    Boundary,
    /// The step bound was hit; the pixel reached stands in for the apex.
    Truncated,
}

/// One apex of a set, in absolute pixel coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Apex {
    /// Column.
    pub x: i32,
    /// Row.
    pub y: i32,
    /// How the ascent that found it ended.
    pub kind: ApexKind,
}

/// The local apex set f(P) of one pixel.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ApexSet {
    /// H_P, found by ascending from P itself; `None` where P is already at a local maximum.
    pub direct: Option<Apex>,
    /// H_P^i, distinct apexes found by ascending from the sample points around P.
    pub indirect: Vec<Apex>,
    /// Whether any ascent of this pixel hit the step bound.
    pub truncated: bool,
}

impl ApexSet {
    /// Number of distinct apexes.
    pub fn len(&self) -> usize {
        self.direct.is_some() as usize + self.indirect.len()
    }

    /// Whether the set is empty.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// All apexes, direct first.
    pub fn iter(&self) -> impl Iterator<Item = &Apex> {
        self.direct.iter().chain(self.indirect.iter())
    }
}

/// Follows the gradient upward from `(x, y)` one pixel a step: to the neighbour the quantized
/// gradient points at while it is connected and higher; else to the highest connected higher
/// neighbour (ridges, where the quantized direction misses); stops at a local maximum, where the
/// gradient points out of the visible region (a boundary point), or after `max_steps` steps.
pub fn ascend(
    mhm: &ScreenHeightMap,
    mhgm: &GradientMap,
    (mut x, mut y): (i32, i32),
    max_steps: u32,
) -> (Apex, u32) {
    let mut steps = 0;
    loop {
        let i = mhm.index(x as u32, y as u32);
        if steps == max_steps {
            return (
                Apex {
                    x,
                    y,
                    kind: ApexKind::Truncated,
                },
                steps,
            );
        }
        let h = mhm.heights[i];
        let height_of = |dir: usize| {
            let (ox, oy) = NEIGHBOURS[dir];
            mhm.heights[mhm.index((x + ox) as u32, (y + oy) as u32)]
        };
        let mut next = None;
        if let Some(dir) = mhgm.ascent_direction(i) {
            if !mhgm.connected(i, dir) {
                return (
                    Apex {
                        x,
                        y,
                        kind: ApexKind::Boundary,
                    },
                    steps,
                );
            }
            if height_of(dir) > h {
                next = Some(dir);
            }
        }
        if next.is_none() {
            let mut best = h;
            for dir in 0..8 {
                if mhgm.connected(i, dir) && height_of(dir) > best {
                    best = height_of(dir);
                    next = Some(dir);
                }
            }
        }
        let Some(dir) = next else {
            return (
                Apex {
                    x,
                    y,
                    kind: ApexKind::Local,
                },
                steps,
            );
        };
        x += NEIGHBOURS[dir].0;
        y += NEIGHBOURS[dir].1;
        steps += 1;
    }
}

/// Where the indirect sample of direction `d` starts: walk from P along `d` one pixel at a
/// time (`P + floor(t·d + 0.5)`) while the height does not rise — down into the valley between
/// P and whatever lies that way — and start at the first pixel that is higher than the one
/// before it; returns it and its `t`. `None` if the walk leaves the visible region or goes
/// `max_walk` pixels without rising (nothing stands up that way). Mirrors `valley_walk` in
/// `apex.wgsl`.
pub fn valley_walk(
    mhm: &ScreenHeightMap,
    mhgm: &GradientMap,
    (x, y): (i32, i32),
    d: [f32; 2],
    max_walk: u32,
) -> Option<((i32, i32), u32)> {
    let (mut px, mut py) = (x, y);
    let mut previous = mhm.heights[mhm.index(x as u32, y as u32)];
    for t in 1..=max_walk {
        let (qx, qy) = line_point((x, y), d, t);
        if (qx, qy) == (px, py) {
            continue;
        }
        let dir = NEIGHBOURS.iter().position(|&o| o == (qx - px, qy - py))?;
        if !mhgm.connected(mhm.index(px as u32, py as u32), dir) {
            return None;
        }
        let h = mhm.heights[mhm.index(qx as u32, qy as u32)];
        if h > previous {
            return Some(((qx, qy), t));
        }
        (px, py, previous) = (qx, qy, h);
    }
    None
}

/// Pixel `t` of the line from P along `d`: `P + floor(t·d + 0.5)`.
pub fn line_point((x, y): (i32, i32), d: [f32; 2], t: u32) -> (i32, i32) {
    (
        x + (t as f32 * d[0] + 0.5).floor() as i32,
        y + (t as f32 * d[1] + 0.5).floor() as i32,
    )
}

/// The apex of direction `d`: from the valley-walk start (pixel `t0` of the line), climb along
/// the line while the height rises, and keep the pixel of steepest rise seen from P,
/// `(h − h(P)) / t` — the horizon in that direction (paper §3.1 takes `h(θ)` from "the apex in
/// that direction"). Climbing along the direction rather than the gradient [beyond the paper]
/// makes the apex the occluder of that direction (see docs/accuracy.md). Boundary if the line
/// leaves the visible region at that pixel while still rising. The climb looks at most
/// `max_walk` pixels beyond the valley, like any bounded horizon search; reaching that bound is
/// not an error (a long gentle ramp seen along its length), so it is not reported as one.
/// Mirrors `line_climb` in `apex.wgsl`.
pub fn line_climb(
    mhm: &ScreenHeightMap,
    mhgm: &GradientMap,
    p: (i32, i32),
    d: [f32; 2],
    (start, t0): ((i32, i32), u32),
    max_walk: u32,
) -> Apex {
    let h0 = mhm.heights[mhm.index(p.0 as u32, p.1 as u32)];
    let (mut cx, mut cy) = start;
    let mut previous = mhm.heights[mhm.index(cx as u32, cy as u32)];
    let mut best = (start, (previous - h0) / t0 as f32);
    let mut kind = ApexKind::Local;
    for t in t0 + 1..=t0 + max_walk {
        let (qx, qy) = line_point(p, d, t);
        if (qx, qy) == (cx, cy) {
            continue;
        }
        let Some(dir) = NEIGHBOURS.iter().position(|&o| o == (qx - cx, qy - cy)) else {
            break;
        };
        if !mhgm.connected(mhm.index(cx as u32, cy as u32), dir) {
            if best.0 == (cx, cy) {
                kind = ApexKind::Boundary;
            }
            break;
        }
        let h = mhm.heights[mhm.index(qx as u32, qy as u32)];
        // Past the top of the rise (flat or falling) the rise over distance only shrinks;
        // "flat" allows filtering noise of 1e-4 of the height (plateaus are not exactly flat
        // after mip filtering).
        if h <= previous + CLIMB_FLATNESS * previous.abs() {
            break;
        }
        let rise = (h - h0) / t as f32;
        if rise > best.1 {
            best = ((qx, qy), rise);
        }
        (cx, cy, previous) = (qx, qy, h);
    }
    Apex {
        x: best.0.0,
        y: best.0.1,
        kind,
    }
}

/// The apex set of pixel `(x, y)`. Mirrors `apex.wgsl`:
/// 1. the direct apex H_P by [`ascend`] (gradient ascent) from P;
/// 2. for each direction `θ_i` the indirect apex H_P^i: [`valley_walk`] to the sample point
///    P^i, then [`line_climb`] to the apex of that direction — the nearest structure standing
///    up that way, however far (up to `max_walk`), so the set adapts to the size of the
///    structures with no hand-set radius;
/// 3. an apex (boundary points included) enters the set if it rises above P by more than
///    [`APEX_MIN_RISE`] and is not in the set yet.
pub fn apex_set(
    mhm: &ScreenHeightMap,
    mhgm: &GradientMap,
    search: &ApexSearch,
    directions: &[[f32; 2]],
    (x, y): (i32, i32),
) -> ApexSet {
    let mut set = ApexSet::default();
    let i = mhm.index(x as u32, y as u32);
    if mhm.objects[i] == 0 {
        return set;
    }
    let h0 = mhm.heights[i];
    let rises = |a: &Apex| mhm.heights[mhm.index(a.x as u32, a.y as u32)] > h0 + APEX_MIN_RISE;

    let (direct, _) = ascend(mhm, mhgm, (x, y), search.max_steps);
    set.truncated |= direct.kind == ApexKind::Truncated;
    if rises(&direct) {
        set.direct = Some(direct);
    }
    for d in directions.iter().take(search.directions as usize) {
        let Some(start) = valley_walk(mhm, mhgm, (x, y), *d, search.max_walk) else {
            continue;
        };
        let apex = line_climb(mhm, mhgm, (x, y), *d, start, search.max_walk);
        if rises(&apex) && !set.iter().any(|a| a.x == apex.x && a.y == apex.y) {
            set.indirect.push(apex);
        }
    }
    set
}

/// The apex sets of every pixel, row-major.
pub fn apex_sets(mhm: &ScreenHeightMap, mhgm: &GradientMap, search: &ApexSearch) -> Vec<ApexSet> {
    let directions = sample_directions(search.directions.min(MAX_APEX_DIRECTIONS));
    let mut sets = Vec::with_capacity((mhm.width * mhm.height) as usize);
    for y in 0..mhm.height as i32 {
        for x in 0..mhm.width as i32 {
            sets.push(apex_set(mhm, mhgm, search, &directions, (x, y)));
        }
    }
    sets
}

/// Decodes one pixel's apex set from the GPU apex buffer (`words` is its stride-long slice).
/// Apexes that hit the step bound come back as [`ApexKind::Local`] with `truncated` set.
pub fn unpack_apex_set(words: &[u32], (x, y): (i32, i32)) -> ApexSet {
    let header = words[0];
    let count = (header & packed::COUNT_MASK) as usize;
    let mut set = ApexSet {
        truncated: header & packed::TRUNCATED != 0,
        ..Default::default()
    };
    for slot in 0..count.min(words.len() - 1) {
        let w = words[1 + slot];
        let dx = (w & 0xffff) as u16 as i16 as i32;
        let dy = (w >> 16) as u16 as i16 as i32;
        let kind = if header >> (packed::BOUNDARY_SHIFT + slot as u32) & 1 == 1 {
            ApexKind::Boundary
        } else {
            ApexKind::Local
        };
        let apex = Apex {
            x: x + dx,
            y: y + dy,
            kind,
        };
        if slot == 0 && header & packed::DIRECT_PRESENT != 0 {
            set.direct = Some(apex);
        } else {
            set.indirect.push(apex);
        }
    }
    set
}
