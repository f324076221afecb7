//! How much of the light entering a translucent object leaves it again, in the object's own
//! shape: random walks of the medium's similarity-theory coefficients (σs′ scattering
//! isotropically, σa absorbing) inside its triangles, the boundary's Fresnel reflection turning
//! walks back in.
//!
//! The diffusion profiles give off, in all, the total diffuse reflectance `W∞` of a
//! semi-infinite slab. A closed object of a few diffusion lengths gives off more — light that
//! would wander sideways under a slab's surface meets the object's curving surface sooner —
//! and the patches' transfer then fell short: on a skin ball of radius 1 cm, red came out at
//! 0.84 of a path tracer's (walks on that ball: 0.74 of what enters, in a slab 0.62;
//! `docs/translucent.md`). The transport scales each translucent object's columns by the ratio
//! of the two — the object's walks against walks under a flat boundary, from the same entry
//! distribution and the same random numbers — so the profile's own calibration of `W∞` stays
//! and only the object's finite extent is added.

use bevy::math::Vec3;

use super::{diffusion::fresnel_reflectance, medium::TranslucentMedium, transport::SceneRays};

/// Walks per colour channel and object: a share known to ±0.016 (one standard deviation at
/// worst, a share of one half).
pub const WALKS_PER_CHANNEL: usize = 4096;

/// Scattering events a walk may take before it counts as absorbed (at the highest albedo of
/// Jensen's media, marble's red 0.999, a walk survives 20 000 events with e⁻²⁰ odds).
const MAX_EVENTS: u32 = 20_000;

/// A point on an object's surface light may enter at, with its outward normal and its area.
#[derive(Clone, Copy, Debug)]
pub struct EntryPoint {
    /// On the surface.
    pub position: Vec3,
    /// Unit, outward.
    pub normal: Vec3,
    /// The surface it stands for.
    pub area: f32,
}

/// The share of the light entering an object (past its boundary, spread diffusely: cosine
/// distributed about the inward normal) that leaves it again, per colour channel, for `walks`
/// walks a channel starting at `entries` drawn by area. `world_units_per_mm` scales the
/// medium's coefficients (mm⁻¹) to the scene. Deterministic for a given `seed`, and with the
/// same seed [`slab_exit_share`] walks the same random numbers under a flat boundary. `None`
/// where the medium or the scale is invalid or there is no entry point.
pub fn object_exit_share(
    medium: &TranslucentMedium,
    world_units_per_mm: f32,
    entries: &[EntryPoint],
    rays: &SceneRays,
    walks: usize,
    seed: u64,
) -> Option<Vec3> {
    Some(
        exit_share(medium, world_units_per_mm, entries, walks, seed, |x, d| {
            rays.first_hit(x, d)
        })?
        .left,
    )
}

/// [`object_exit_share`] under a flat boundary of infinite extent: the share of the light
/// entering a semi-infinite slab that leaves it again, per channel.
pub fn slab_exit_share(
    medium: &TranslucentMedium,
    world_units_per_mm: f32,
    walks: usize,
    seed: u64,
) -> Option<Vec3> {
    // The plane z = 0 above the medium, entered at the origin; downwards the medium never
    // ends.
    let flat = [EntryPoint {
        position: Vec3::ZERO,
        normal: Vec3::Z,
        area: 1.0,
    }];
    Some(
        exit_share(medium, world_units_per_mm, &flat, walks, seed, |x, d| {
            Some(slab_hit(x, d, f32::INFINITY))
        })?
        .left,
    )
}

/// The shares of the light entering a slab `thickness_mm` thick (diffusely, through its top
/// face) that leave through the top and through the bottom, per channel: what the oriented
/// dipole is held to (`Translucent::oriented_dipole`).
pub fn slab_exits(
    medium: &TranslucentMedium,
    thickness_mm: f32,
    walks: usize,
    seed: u64,
) -> Option<(Vec3, Vec3)> {
    let top = [EntryPoint {
        position: Vec3::ZERO,
        normal: Vec3::Z,
        area: 1.0,
    }];
    let exits = exit_share(medium, 1.0, &top, walks, seed, |x, d| {
        Some(slab_hit(x, d, thickness_mm))
    })?;
    Some((exits.left - exits.other_face, exits.other_face))
}

/// The first face a ray from `x` along `d` meets in the slab `−thickness < z < 0` (infinite:
/// the half-space), with the faces' normal.
fn slab_hit(x: Vec3, d: Vec3, thickness: f32) -> (f32, Vec3) {
    let distance = if d.z > 0.0 {
        (-x.z).max(0.0) / d.z
    } else if d.z < 0.0 {
        (x.z + thickness).max(0.0) / -d.z
    } else {
        f32::INFINITY
    };
    (distance, Vec3::Z)
}

/// The shares of the light entering a right-angled edge of a medium (the quarter-space
/// `x < 0, y < 0`) through its face `y = 0`, `distance_mm` from the edge, that leave through
/// that face and through the other one, `x = 0`, per channel: the geometry a convex object's
/// curve between two patches a quarter of the way round it stands for.
pub fn edge_exits(
    medium: &TranslucentMedium,
    distance_mm: f32,
    walks: usize,
    seed: u64,
) -> Option<(Vec3, Vec3)> {
    let entry = [EntryPoint {
        position: Vec3::new(-distance_mm, 0.0, 0.0),
        normal: Vec3::Y,
        area: 1.0,
    }];
    let exits = exit_share(medium, 1.0, &entry, walks, seed, |x, d| {
        let to = |position: f32, direction: f32| {
            if direction > 0.0 {
                (-position).max(0.0) / direction
            } else {
                f32::INFINITY
            }
        };
        let (tx, ty) = (to(x.x, d.x), to(x.y, d.y));
        Some(if tx < ty {
            (tx, Vec3::X)
        } else {
            (ty, Vec3::Y)
        })
    })?;
    Some((exits.left - exits.other_face, exits.other_face))
}

/// What walks from a set of entry points do, per channel.
struct Exits {
    /// The share that leaves.
    left: Vec3,
    /// The share that leaves through another face than the one it entered by (outward
    /// normals' cosine below 0.99).
    other_face: Vec3,
}

/// [`object_exit_share`] and [`slab_exit_share`] for one boundary: `first_hit(x, d)` the
/// distance to it along the unit `d` and its unit normal (either side), `None` where a ray
/// leaves the medium for good.
fn exit_share(
    medium: &TranslucentMedium,
    world_units_per_mm: f32,
    entries: &[EntryPoint],
    walks: usize,
    seed: u64,
    first_hit: impl Fn(Vec3, Vec3) -> Option<(f32, Vec3)> + Sync,
) -> Option<Exits> {
    let mut left = [0usize; 3];
    let mut other_face = [0usize; 3];
    walk(
        medium,
        world_units_per_mm,
        entries,
        walks,
        seed,
        WalkLaunch::Diffuse,
        ScatteringOrders {
            first: 0,
            last: MAX_EVENTS,
        },
        first_hit,
        |channel, entry, end| match end {
            WalkEnd::Exit(exit) => {
                left[channel] += 1;
                if entry.normal.dot(exit.outward) < 0.99 {
                    other_face[channel] += 1;
                }
            }
            WalkEnd::Gap => left[channel] += 1,
            WalkEnd::Remainder => {}
        },
    )?;
    let n = walks.max(1) as f32;
    let share = |c: [usize; 3]| Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32) / n;
    Some(Exits {
        left: share(left),
        other_face: share(other_face),
    })
}

/// Where a walk left its object.
#[derive(Clone, Copy, Debug)]
pub struct WalkExit {
    /// On the boundary.
    pub position: Vec3,
    /// The boundary's unit normal there, outward.
    pub outward: Vec3,
    /// How many times the walk scattered before it left (0: a diffuse launch's light that
    /// left unscattered).
    pub order: u32,
    /// The unit direction it leaves along, outside: its travel refracted out by the boundary
    /// (what the beam table's exit lobes are fitted to).
    pub leaving: Vec3,
}

/// How walks enter the medium.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum WalkLaunch {
    /// Diffusely: cosine-distributed about the inward normal, as light from everywhere
    /// enters (what the transport's `K` carries).
    Diffuse,
    /// As a beam travelling along this unit direction, refracted by the boundary (each walk
    /// is light that got in: the share the boundary reflects on the way in is the caller's);
    /// the light it carries out without scattering is not reported (it goes on along the
    /// beam).
    Beam(Vec3),
}

/// Which orders of scattering a walk reports (`walk_ends`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ScatteringOrders {
    /// Walks that leave after fewer scatterings than this are not reported (0: all; 1: not
    /// a beam's uncollided light; 2: not single scattering either, which a caller gives in
    /// its own law).
    pub first: u32,
    /// Walks still inside after this many scatterings stop and are reported as
    /// [`WalkEnd::Remainder`] (at most `MAX_EVENTS`, 20 000, beyond which a walk counts as
    /// absorbed).
    pub last: u32,
}

/// Splitting a walk that travels far from where it entered into several of a share each
/// (importance splitting; `walk_ends`). Far from its entry a column's exits are few, and the
/// patches there took each its own handful of walks: a back-lit skin ball's picture was
/// blotched by it. A split walk's copies go on from the same collision each in its own
/// direction, so the far exits are walked `into` times as often for a fraction of the cost
/// of that many more walks (most walks leave near their entry), and the expectation is
/// unchanged.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FarSplit {
    /// How far from its entry point (world units) a walk's collision must be for it to split.
    pub beyond: f32,
    /// How many walks it becomes there (once; 1: none).
    pub into: u32,
}

/// How a walk ended, where it is reported.
#[derive(Clone, Copy, Debug)]
pub enum WalkEnd {
    /// It left through the boundary.
    Exit(WalkExit),
    /// It left through a gap in the mesh (only the object's own walks, whose queries are
    /// unbounded, tell one apart).
    Gap,
    /// It was still inside after [`ScatteringOrders::last`] scatterings.
    Remainder,
}

/// Walks `walks` paths into `rays`' triangles from `entries` (drawn by area), shared by the
/// three colour channels, and calls `on_end(weight, end)` for each that leaves after at least
/// `orders.first` scatterings or is still inside after `orders.last`: `weight / walks` is its
/// share of the light that entered, per channel (with `split`, a split walk's copies each
/// carry their share of it in `weight`). A beam's walks enter by each entry's projected
/// area, none through an entry that faces away from it (its light enters there, and where a
/// patch curves away from the light a walk drawn by area at its back lost its share). `false`
/// where the medium, the scale or the entries are invalid, or a beam meets none of the
/// entries from outside (nothing walked). The same physics as the path-traced references
/// (`tools/translucent_reference.py`): `translucent_accuracy --scattering walks` builds `K`
/// from it to measure what the diffusion profile costs, and the beam table its columns.
///
/// **Hero channels** (Wilkie et al. 2014, "Hero wavelength spectral sampling"): each walk
/// draws its free flights by one channel's `σt` — the channels in turn — and every channel
/// takes it by the balance heuristic over the three, `weight_c = (α_c / α_max)ⁿ · p_c / p̄`,
/// `p_k = σt_kⁿ e^{−σt_k L}` the density of its `n` flights of total length `L` under channel
/// `k` and `p̄` their mean (so `p_c / p̄ ≤ 3`); absorption is Russian roulette at the highest
/// albedo `α_max`. One BVH query a flight then serves all three channels (the beam table's
/// build: 1.5–1.6× faster at 384 shared walks than at 256 a channel, each channel's noise
/// between that of as many walks of its own and of a third of them; `docs/translucent.md`).
///
/// The mesh is queried only as far as each free flight reaches (several times faster for
/// walks of a few mean free paths), so a walk that left through a gap in the mesh is not told
/// apart: it scatters on outside until it is absorbed or ends as a [`WalkEnd::Remainder`] —
/// use short `orders.last` on meshes that may be open.
#[allow(clippy::too_many_arguments)]
pub fn walk_ends(
    medium: &TranslucentMedium,
    world_units_per_mm: f32,
    entries: &[EntryPoint],
    rays: &SceneRays,
    walks: usize,
    seed: u64,
    launch: WalkLaunch,
    orders: ScatteringOrders,
    split: Option<FarSplit>,
    mut on_end: impl FnMut(Vec3, WalkEnd),
) -> bool {
    let Some(entry_table) = (match launch {
        // A beam enters each sample by its projected area, and none where it meets the
        // sample's back: a walk drawn there would count in `walks` unwalked, and a patch
        // curving away from the light (a terminator, an ear's rim) would lose its share
        // (`docs/translucent.md`, "A beam's walks enter by projected area").
        WalkLaunch::Beam(d) => {
            EntryTable::weighted(medium, world_units_per_mm, entries, |e| e.area.max(0.0) * (-d.dot(e.normal)).max(0.0))
        }
        _ => EntryTable::new(medium, world_units_per_mm, entries),
    }) else {
        return false;
    };
    let scale = world_units_per_mm as f64;
    let sigma_t: [f64; 3] = std::array::from_fn(|c| {
        (medium.reduced_scattering[c] as f64 + medium.absorption[c] as f64) / scale
    });
    let albedo: [f64; 3] =
        std::array::from_fn(|c| medium.reduced_scattering[c] as f64 / scale / sigma_t[c]);
    let survival = albedo[0].max(albedo[1]).max(albedo[2]);
    let ln_sigma_t = sigma_t.map(f64::ln);
    // Walks w = c, c + 3, … draw by channel c: each channel's share of them, for p̄.
    let heroes: [f64; 3] =
        std::array::from_fn(|c| walks.saturating_sub(c).div_ceil(3) as f64 / walks.max(1) as f64);
    // The walk's worth per channel after `n` collisions over a path `length` long.
    let weight = |n: u32, length: f64| {
        let log_p =
            std::array::from_fn::<f64, 3, _>(|k| n as f64 * ln_sigma_t[k] - sigma_t[k] * length);
        let top = log_p[0].max(log_p[1]).max(log_p[2]);
        let mean: f64 = (0..3).map(|k| heroes[k] * (log_p[k] - top).exp()).sum();
        Vec3::from_array(std::array::from_fn(|c| {
            ((albedo[c] / survival).powi(n as i32) * (log_p[c] - top).exp() / mean) as f32
        }))
    };
    // Steps off the surface: a thousandth of the shortest mean free path.
    let epsilon = (1e-3 / sigma_t[0].max(sigma_t[1]).max(sigma_t[2])) as f32;
    let eta = entry_table.eta;
    // Each hero channel's flights.
    let by_hero = sigma_t.map(|sigma_t| WalkMedium {
        sigma_t,
        survival,
        epsilon,
        eta,
    });
    let query = |x, d, t_max| rays.first_hit_within(x, d, t_max);
    let mut random = SplitMix(seed);
    for w in 0..walks {
        let e = entry_table.pick(random.next());
        let Some(d) = launch_direction(launch, e.normal, eta, &mut random) else {
            continue;
        };
        walk_one(
            e,
            d,
            by_hero[w % 3],
            (query, true),
            (orders, split),
            &mut random,
            |order, length, share, end| on_end(weight(order, length) * share, end),
        );
    }
    true
}

/// Entry points drawn by area, and the medium's index (at least 1).
struct EntryTable<'a> {
    entries: &'a [EntryPoint],
    /// Running sums of the entries' areas.
    cumulative: Vec<f64>,
    eta: f32,
}

impl<'a> EntryTable<'a> {
    /// `None` where the medium, the scale or the entries are invalid.
    fn new(
        medium: &TranslucentMedium,
        world_units_per_mm: f32,
        entries: &'a [EntryPoint],
    ) -> Option<Self> {
        Self::weighted(medium, world_units_per_mm, entries, |e| e.area.max(0.0))
    }

    fn weighted(
        medium: &TranslucentMedium,
        world_units_per_mm: f32,
        entries: &'a [EntryPoint],
        weight: impl Fn(&EntryPoint) -> f32,
    ) -> Option<Self> {
        if medium.invalid_reason().is_some()
            || !(world_units_per_mm.is_finite() && world_units_per_mm > 0.0)
            || entries.is_empty()
        {
            return None;
        }
        let mut cumulative = Vec::with_capacity(entries.len());
        let mut total = 0.0f64;
        for e in entries {
            total += weight(e) as f64;
            cumulative.push(total);
        }
        (total > 0.0).then(|| Self {
            entries,
            cumulative,
            eta: medium.index_of_refraction.max(1.0),
        })
    }

    /// The entry at the uniform number `u` in [0, 1).
    fn pick(&self, u: f64) -> &'a EntryPoint {
        let pick = u * self.cumulative.last().copied().unwrap_or(0.0);
        &self.entries[self
            .cumulative
            .partition_point(|&c| c < pick)
            .min(self.entries.len() - 1)]
    }
}

/// The direction a walk entering through a face of outward unit `normal` starts along;
/// `None` where a beam does not enter through that face.
fn launch_direction(
    launch: WalkLaunch,
    normal: Vec3,
    eta: f32,
    random: &mut SplitMix,
) -> Option<Vec3> {
    match launch {
        WalkLaunch::Diffuse => Some(cosine_about(-normal, random.next(), random.next())),
        // A beam along or behind this face does not enter through it.
        WalkLaunch::Beam(direction) => refracted(direction, normal, eta),
    }
}

/// What a walk travelling along `d` does at a boundary of unit `normal` (either side).
enum Crossing {
    /// Turned back in by Fresnel reflection (or total internal reflection).
    Reflected { travel: Vec3, outward: Vec3 },
    /// Out, along `leaving`.
    Left { outward: Vec3, leaving: Vec3 },
}

/// At the boundary, from inside: Fresnel reflection back in (total internal reflection
/// beyond the critical angle), else out.
fn cross_boundary(d: Vec3, normal: Vec3, eta: f32, random: &mut SplitMix) -> Crossing {
    let outward = if normal.dot(d) > 0.0 { normal } else { -normal };
    let cos_i = d.dot(outward) as f64;
    if eta > 1.0 && random.next() < fresnel_reflectance(cos_i, 1.0 / eta as f64) {
        return Crossing::Reflected {
            travel: d - 2.0 * d.dot(outward) * outward,
            outward,
        };
    }
    Crossing::Left {
        outward,
        leaving: refracted_out(d, outward, eta),
    }
}

/// The walks of [`exit_share`], a channel at a time (the three on their own cores: marble's
/// walks run hundreds of scatterings, each an unbounded query, and held the transport's
/// build up on one core), to the end (absorbed by Russian roulette at the channel's albedo,
/// or out): `on_end(channel, entry, end)` for each that leaves, channel by channel;
/// `first_hit(x, d)` the whole ray's nearest boundary, `None` out through a gap.
#[allow(clippy::too_many_arguments)]
fn walk<'a>(
    medium: &TranslucentMedium,
    world_units_per_mm: f32,
    entries: &'a [EntryPoint],
    walks: usize,
    seed: u64,
    launch: WalkLaunch,
    orders: ScatteringOrders,
    first_hit: impl Fn(Vec3, Vec3) -> Option<(f32, Vec3)> + Sync,
    mut on_end: impl FnMut(usize, &EntryPoint, WalkEnd),
) -> Option<()> {
    let entry_table = EntryTable::new(medium, world_units_per_mm, entries)?;
    let eta = entry_table.eta;
    let channels = super::transport::parallel_rows(3, |c| {
        let mut ends: Vec<(&'a EntryPoint, WalkEnd)> = Vec::new();
        let sigma_s = medium.reduced_scattering[c] as f64 / world_units_per_mm as f64;
        let sigma_t = sigma_s + medium.absorption[c] as f64 / world_units_per_mm as f64;
        let albedo = sigma_s / sigma_t;
        // Steps off the surface: a thousandth of a mean free path.
        let epsilon = (1e-3 / sigma_t) as f32;
        let mut random = SplitMix(seed ^ (c as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
        let medium = WalkMedium {
            sigma_t,
            survival: albedo,
            epsilon,
            eta,
        };
        let query = |x, d, _| first_hit(x, d);
        for _ in 0..walks {
            let e = entry_table.pick(random.next());
            let Some(d) = launch_direction(launch, e.normal, eta, &mut random) else {
                continue;
            };
            walk_one(
                e,
                d,
                medium,
                (query, false),
                (orders, None),
                &mut random,
                |_, _, _, end| ends.push((e, end)),
            );
        }
        ends
    });
    for (c, ends) in channels.into_iter().enumerate() {
        for (e, end) in ends {
            on_end(c, e, end);
        }
    }
    Some(())
}

/// What one walk's steps take of the medium.
#[derive(Clone, Copy)]
struct WalkMedium {
    /// The extinction its free flights are drawn by (world units⁻¹).
    sigma_t: f64,
    /// The odds of going on at each collision (Russian roulette).
    survival: f64,
    /// How far it steps off the surface, in and after a reflection.
    epsilon: f32,
    /// The medium's relative index (at least 1).
    eta: f32,
}

/// One walk from `entry` along `d` (already inside) until it leaves, is absorbed or has
/// scattered more than `orders.last` times: `on_end(order, length, share, end)` for an end
/// that [`walk_ends`] reports (`order` its scatterings, `length` its path in the medium,
/// `share` its part of the walk: 1 unless `split` split it). `query(x, d, t_max)` the nearest
/// boundary along `d` (`bounded`: only within `t_max`, so that none is no gap but a
/// collision).
fn walk_one(
    entry: &EntryPoint,
    d: Vec3,
    medium: WalkMedium,
    (query, bounded): (impl Fn(Vec3, Vec3, f32) -> Option<(f32, Vec3)>, bool),
    (orders, split): (ScatteringOrders, Option<FarSplit>),
    random: &mut SplitMix,
    mut on_end: impl FnMut(u32, f64, f32, WalkEnd),
) {
    let split = split.filter(|s| s.into > 1);
    // The walk, then its split copies still to go: where, which way, their scatterings and
    // path so far, their share, and whether they have split. Only a walk that splits fills
    // `copies` (an empty `Vec` does not allocate: most walks never split, and the object's
    // own walks never do).
    let mut walk = Some((entry.position - entry.normal * medium.epsilon, d, 0u32, 0.0f64, 1.0f32, false));
    let mut copies = Vec::new();
    'walks: while let Some((mut x, mut d, mut order, mut length, mut share, mut split_yet)) =
        walk.take().or_else(|| copies.pop())
    {
        for _ in 0..MAX_EVENTS {
            let free_path = (-(1.0 - random.next()).ln() / medium.sigma_t) as f32;
            let (to_boundary, normal) = match query(x, d, free_path) {
                Some((t, normal)) if t <= free_path => (t, normal),
                // Out through a gap in the mesh: it has left.
                None if !bounded => {
                    if order >= orders.first {
                        on_end(order, length, share, WalkEnd::Gap);
                    }
                    continue 'walks;
                }
                // The boundary is beyond the free flight: a collision.
                _ => {
                    x += d * free_path;
                    length += free_path as f64;
                    if random.next() >= medium.survival {
                        continue 'walks;
                    }
                    order += 1;
                    if order > orders.last {
                        on_end(order, length, share, WalkEnd::Remainder);
                        continue 'walks;
                    }
                    if let Some(split) = split.filter(|s| !split_yet && x.distance(entry.position) > s.beyond) {
                        split_yet = true;
                        share /= split.into as f32;
                        for _ in 1..split.into {
                            let d = uniform_direction(random.next(), random.next());
                            copies.push((x, d, order, length, share, true));
                        }
                    }
                    d = uniform_direction(random.next(), random.next());
                    continue;
                }
            };
            length += to_boundary as f64;
            let hit = x + d * to_boundary;
            match cross_boundary(d, normal, medium.eta, random) {
                Crossing::Reflected { travel, outward } => {
                    d = travel;
                    x = hit - outward * medium.epsilon;
                }
                Crossing::Left { outward, leaving } => {
                    if order >= orders.first {
                        let exit = WalkExit {
                            position: hit,
                            outward,
                            order,
                            leaving,
                        };
                        on_end(order, length, share, WalkEnd::Exit(exit));
                    }
                    continue 'walks;
                }
            }
        }
    }
}

/// A direction cosine-distributed about the unit vector `axis`.
fn cosine_about(axis: Vec3, u1: f64, u2: f64) -> Vec3 {
    let r = u1.sqrt() as f32;
    let phi = (2.0 * std::f64::consts::PI * u2) as f32;
    let (t, b) = axis.any_orthonormal_pair();
    (t * (r * phi.cos()) + b * (r * phi.sin()) + axis * (1.0 - r * r).max(0.0).sqrt()).normalize()
}

/// The direction a beam travelling along the unit `direction` takes past a boundary of
/// outward unit normal `normal` into a medium of relative index `eta` (Snell's law); `None`
/// where the beam does not meet the face from outside.
fn refracted(direction: Vec3, normal: Vec3, eta: f32) -> Option<Vec3> {
    let cos_i = -direction.dot(normal);
    if cos_i <= 0.0 {
        return None;
    }
    let eta = eta.max(1.0);
    let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    let cos_t = (1.0 - sin2_t).max(0.0).sqrt();
    Some((direction / eta + (cos_i / eta - cos_t) * normal).normalize())
}

/// The direction light travelling along the unit `direction` inside leaves along past a
/// boundary of outward unit normal `outward` into the outside, `eta` the inside's relative
/// index (Snell's law; the caller has taken total internal reflection as a reflection).
fn refracted_out(direction: Vec3, outward: Vec3, eta: f32) -> Vec3 {
    let along = direction.dot(outward);
    let tangent = (direction - along * outward) * eta.max(1.0);
    let normal = (1.0 - tangent.length_squared()).max(0.0).sqrt();
    (tangent + normal * outward).normalize_or(outward)
}

/// A direction uniform over the sphere (isotropic scattering).
fn uniform_direction(u1: f64, u2: f64) -> Vec3 {
    let z = (1.0 - 2.0 * u1) as f32;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = (2.0 * std::f64::consts::PI * u2) as f32;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// SplitMix64 (Steele, Lea and Flood 2014): a small, seedable generator, enough for walks.
struct SplitMix(u64);

impl SplitMix {
    /// Uniform in [0, 1).
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }
}
