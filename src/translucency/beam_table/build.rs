//! Building a table: each translucent patch's walks for each table direction, their exits
//! counted on the patches they leave by, and the late light from the profile's column.

use bevy::{platform::collections::HashMap, prelude::*};

use super::{
    BeamTable, BeamTableSettings, DiffuseColumns, SEED_STRIDE,
    directions::bin_direction,
    flow::{ExitLean, LeanSums, from_afar, from_source, lobe_source_distance},
    single_scattering::law_gives_single_scattering,
};
use crate::translucency::{
    diffusion::diffuse_fresnel_reflectance,
    patches::Patches,
    random_walk::{EntryPoint, FarSplit, ScatteringOrders, WalkEnd, WalkLaunch, walk_ends},
    transport::{PatchSurface, SceneRays, SparseMatrix, parallel_rows},
};

/// The patch a walk leaves by: the nearest sample facing the exit's way (not the far side of
/// a thin part), else the nearest of any, among a grid of its object's samples (cells of the
/// object's own patch size: a room's wall patches would make a grid of the largest size
/// hold a whole small object in a cell).
pub struct ExitPatches {
    grids: Vec<SampleGrid>,
}

/// The most cells a [`SampleGrid`] takes (16 MB of offsets).
const MAX_SAMPLE_CELLS: usize = 1 << 22;

/// One object's samples by cell, dense over the cells they occupy (a walk's exit looks up 27
/// cells: as a hash map's keys they took 15 % of a table's build).
#[derive(Default)]
struct SampleGrid {
    /// Cell size (world units): the object's patch size.
    cell: f32,
    /// The lowest cell's integer coordinates (`floor(x / cell)`).
    low: IVec3,
    /// Cells along each axis.
    size: IVec3,
    /// Where each cell's samples start in `samples` (one more than there are cells).
    starts: Vec<u32>,
    /// Position, unit normal and patch of each sample, by cell, in the patches' order.
    samples: Vec<(Vec3, Vec3, u32)>,
}

impl SampleGrid {
    /// The grid of `samples` (position, normal, patch) in cells of `cell`, coarser where that
    /// would take more than [`MAX_SAMPLE_CELLS`] (a large hollow object at a high budget).
    fn new(cell: f32, samples: &[(Vec3, Vec3, u32)]) -> Self {
        let Some(first) = samples.first() else {
            return Self { cell, ..default() };
        };
        let (low, high) = samples
            .iter()
            .fold((first.0, first.0), |(low, high), s| (low.min(s.0), high.max(s.0)));
        let cells = ((high - low) / cell + 2.0).max(Vec3::ONE);
        let count = cells.x as f64 * cells.y as f64 * cells.z as f64;
        let cell = if count > MAX_SAMPLE_CELLS as f64 {
            cell * (count / MAX_SAMPLE_CELLS as f64).cbrt() as f32 * 1.01
        } else {
            cell
        };
        let key = |x: Vec3| (x / cell).floor().as_ivec3();
        let (low, high) = samples.iter().fold((key(first.0), key(first.0)), |(low, high), s| {
            (low.min(key(s.0)), high.max(key(s.0)))
        });
        let size = high - low + IVec3::ONE;
        let index = |k: IVec3| {
            let k = (k - low).as_uvec3();
            (k.x + size.x as u32 * (k.y + size.y as u32 * k.z)) as usize
        };
        // A counting sort keeps each cell's samples in the patches' order.
        let cells = size.x as usize * size.y as usize * size.z as usize;
        let mut starts = vec![0u32; cells + 1];
        for s in samples {
            starts[index(key(s.0)) + 1] += 1;
        }
        for c in 0..cells {
            starts[c + 1] += starts[c];
        }
        let mut next = starts.clone();
        let mut sorted = vec![(Vec3::ZERO, Vec3::ZERO, 0); samples.len()];
        for &s in samples {
            let c = index(key(s.0));
            sorted[next[c] as usize] = s;
            next[c] += 1;
        }
        Self { cell, low, size, starts, samples: sorted }
    }

    /// The samples in the cell of integer coordinates `k` (none outside the grid).
    fn cell(&self, k: IVec3) -> &[(Vec3, Vec3, u32)] {
        // Saturating: an exit far outside (a walk out through a gap) stays outside.
        let k = k.saturating_sub(self.low);
        if k.cmplt(IVec3::ZERO).any() || k.cmpge(self.size).any() {
            return &[];
        }
        let c = (k.x + self.size.x * (k.y + self.size.y * k.z)) as usize;
        &self.samples[self.starts[c] as usize..self.starts[c + 1] as usize]
    }
}

impl ExitPatches {
    /// The grids of `patches`' samples, one per object.
    pub fn new(patches: &Patches) -> Self {
        let objects = patches.object_patch_sizes.len();
        let mut samples: Vec<Vec<(Vec3, Vec3, u32)>> = vec![Vec::new(); objects];
        for (i, q) in patches.patches.iter().enumerate() {
            let Some(object) = samples.get_mut(q.object as usize) else {
                continue;
            };
            object.extend(patches.samples_of(i).iter().map(|s| (s.position, s.normal, i as u32)));
        }
        let grids = samples
            .iter()
            .enumerate()
            .map(|(o, s)| SampleGrid::new(patches.object_patch_sizes[o].max(1e-9), s))
            .collect();
        Self { grids }
    }

    /// The patch of `object` a walk leaving at `x` through a boundary of unit `outward`
    /// normal leaves by; `None` where none of its samples is within a patch size.
    pub fn of(&self, object: u32, x: Vec3, outward: Vec3) -> Option<u32> {
        let grid = self.grids.get(object as usize)?;
        let scaled = x / grid.cell;
        let key = scaled.floor().as_ivec3();
        // The nearest sample facing the exit's way (not the far side of a thin part), else
        // the nearest of any: (distance², patch).
        let (mut facing, mut any): (Option<(f32, u32)>, Option<(f32, u32)>) = (None, None);
        // Of samples exactly as near, the first patch: the same whichever order the cells
        // are looked in.
        let nearer = |d: f32, patch: u32, best: Option<(f32, u32)>| best.is_none_or(|b| d < b.0 || (d == b.0 && patch < b.1));
        let visit = |offset: IVec3, any: &mut Option<(f32, u32)>, facing: &mut Option<(f32, u32)>| {
            for &(position, normal, patch) in grid.cell(key.saturating_add(offset)) {
                let d = position.distance_squared(x);
                if nearer(d, patch, *any) {
                    *any = Some((d, patch));
                }
                if normal.dot(outward) > 0.0 && nearer(d, patch, *facing) {
                    *facing = Some((d, patch));
                }
            }
        };
        // The exit's own cell first, then of the 26 about it only those nearer than the
        // nearest facing sample found yet (a grid's nearest-neighbour bound): most exits
        // look in a few cells, not 27 (the scan was a sixth of a table's build).
        visit(IVec3::ZERO, &mut any, &mut facing);
        let within = scaled - key.as_vec3();
        // Per axis, the distance² from `x` to the cell at offset -1, 0, +1 (a hair short, so
        // rounding never skips a cell that holds a nearer sample).
        let gap = |f: f32| {
            let cell = grid.cell * 0.999;
            [(f * cell).powi(2), 0.0, ((1.0 - f) * cell).max(0.0).powi(2)]
        };
        let (gx, gy, gz) = (gap(within.x), gap(within.y), gap(within.z));
        for dz in -1..=1i32 {
            for dy in -1..=1i32 {
                for dx in -1..=1i32 {
                    let bound = gx[(dx + 1) as usize] + gy[(dy + 1) as usize] + gz[(dz + 1) as usize];
                    if (dx, dy, dz) == (0, 0, 0) || facing.is_some_and(|b| bound > b.0) {
                        continue;
                    }
                    visit(IVec3::new(dx, dy, dz), &mut any, &mut facing);
                }
            }
        }
        facing.or(any).map(|b| b.1)
    }
}

/// Exitance per unit of light entering patch `j`, by the patch it leaves through.
type Column = HashMap<u32, Vec3>;

/// A [`Column`]'s first moments in the directions its light leaves along: per channel
/// `Σ exitance · ω` and (`w`) how many walks left, by the patch it leaves through.
type Moments = HashMap<u32, [Vec4; 3]>;

/// One patch's late column and, per direction walked, its early column, their moments and
/// its late share.
type PatchColumns = (Option<Column>, Vec<(u32, Column, Moments, Vec3)>, LeanSums, Column);

impl BeamTable {
    /// The table of `patches`' translucent ones (`surfaces[o]` object `o`'s), `profile` the
    /// transport's `K` (its columns give the late light). With `only`, patch `j` walks only
    /// the bins `only[j]` (the others stay empty: what one directional light needs, for the
    /// accuracy tool). Every core.
    pub fn build(
        patches: &Patches,
        surfaces: &[PatchSurface],
        rays: &SceneRays,
        profile: &SparseMatrix<Vec3>,
        settings: BeamTableSettings,
        only: Option<&[Vec<u32>]>,
    ) -> Self {
        Self::build_walked(patches, surfaces, rays, profile, settings, only).0
    }

    /// [`build`](Self::build), and the late light's diffuse walks' early columns where
    /// [`BeamTableSettings::diffuse_columns_walked`] (else empty): what
    /// [`DiffuseColumns::scattering`] puts in `K`'s place.
    pub fn build_walked(
        patches: &Patches,
        surfaces: &[PatchSurface],
        rays: &SceneRays,
        profile: &SparseMatrix<Vec3>,
        settings: BeamTableSettings,
        only: Option<&[Vec<u32>]>,
    ) -> (Self, DiffuseColumns) {
        let start = std::time::Instant::now();
        let p = &patches.patches;
        let n = p.len();
        if let Some(reason) = settings.invalid_reason() {
            warn!("translucency: {reason} (got {settings:?}); no beam table");
            return (Self { settings, slots: vec![u32::MAX; n], ..default() }, DiffuseColumns::default());
        }
        let medium_of = |j: usize| tabled_medium(surfaces, p[j].object);
        let marched = marched_objects(patches, surfaces);
        let mut slots = vec![u32::MAX; n];
        let mut tabled = Vec::new();
        let mut media = Vec::new();
        for (j, slot) in slots.iter_mut().enumerate() {
            if let Some((medium, _)) = medium_of(j) {
                *slot = tabled.len() as u32;
                tabled.push(j);
                let alpha = medium.single_scattering_albedo();
                media.push(Vec4::new(
                    alpha[0] as f32,
                    alpha[1] as f32,
                    alpha[2] as f32,
                    medium.index_of_refraction,
                ));
            }
        }
        // The profile's columns (it is stored by rows).
        let mut profile_columns: Vec<Vec<(u32, Vec3)>> = vec![Vec::new(); n];
        for i in 0..profile.rows().min(n) {
            for (j, v) in profile.row(i) {
                if j < n {
                    profile_columns[j].push((i as u32, v));
                }
            }
        }
        let exits = ExitPatches::new(patches);
        let source_depths = crate::translucency::transport::EnergyTransport::source_depths(patches, surfaces);
        let bins = settings.bins();
        let columns: Vec<PatchColumns> = parallel_rows(tabled.len(), |slot| {
            let j = tabled[slot];
            let Some((medium, units_per_mm)) = medium_of(j) else {
                return (None, Vec::new(), LeanSums::default(), Column::default());
            };
            let walked: Vec<u32> = match only {
                Some(only) => only.get(j).cloned().unwrap_or_default(),
                None => (0..bins).collect(),
            };
            // Without a direction to walk, the diffuse walks still give the patch's column.
            if walked.is_empty() && !settings.diffuse_columns_walked {
                return (None, Vec::new(), LeanSums::default(), Column::default());
            }
            let column_of = ColumnWalks {
                patches,
                rays,
                exits: &exits,
                medium,
                units_per_mm,
                j,
                entries: patches
                    .samples_of(j)
                    .iter()
                    .map(|s| EntryPoint { position: s.position, normal: s.normal, area: s.area })
                    .collect(),
                last_order: settings.last_order_for(&medium),
                far_split: FarSplit {
                    beyond: lobe_source_distance(patches, &source_depths, j),
                    into: settings.far_splits,
                },
                directions: settings.exit_directions,
                single_to_pixels: settings.single_scattering_to_pixels && marched[p[j].object as usize],
                source_depths: &source_depths,
                seed_offset: settings.seed as u64 * SEED_STRIDE,
            };
            let diffuse_entering =
                (1.0 - diffuse_fresnel_reflectance(medium.index_of_refraction as f64)) as f32;
            let (late, diffuse_early) = column_of.late_light(
                &profile_columns[j],
                diffuse_entering,
                late_walks_for(
                    settings.late_walks,
                    patches.size_of(j),
                    source_depths[j].max_element(),
                    column_of.last_order,
                ),
            );
            let mut lean = LeanSums::default();
            let directions = walked
                .into_iter()
                .map(|bin| {
                    let travel = bin_direction(bin, p[j].normal, settings.cosines, settings.azimuths);
                    let seed = (j as u64 * bins as u64 + bin as u64).wrapping_add(column_of.seed_offset);
                    let (column, moments, remaining, walks_lean) = column_of.walk(
                        WalkLaunch::Beam(travel),
                        settings.walks,
                        seed,
                        true,
                    );
                    lean.add(&walks_lean);
                    let share = match &late {
                        Some((_, late_remaining)) => Vec3::select(
                            late_remaining.cmpgt(Vec3::ZERO),
                            remaining / late_remaining.max(Vec3::splat(1e-9)),
                            Vec3::ZERO,
                        ),
                        None => Vec3::ZERO,
                    };
                    (bin, column, moments, share)
                })
                .collect::<Vec<_>>();
            (late.map(|l| l.0), directions, lean, diffuse_early)
        });
        let mut early_rows: Vec<Vec<(u32, Vec3)>> = vec![Vec::new(); n];
        // With the exit directions, each early entry's at the same (row, column): sorted as
        // `early`'s rows are, their values line up with its.
        let mut leaving_rows: Vec<Vec<(u32, [Vec4; 3])>> = vec![Vec::new(); n];
        let mut late_rows: Vec<Vec<(u32, Vec3)>> = vec![Vec::new(); n];
        let mut diffuse_rows: Vec<Vec<(u32, Vec3)>> = vec![Vec::new(); n];
        let mut diffuse_walked = vec![false; tabled.len()];
        let mut late_share = vec![Vec3::ZERO; tabled.len() * bins as usize];
        // Each object's lean, pooled over its patches' walks.
        let mut object_leans: HashMap<u32, LeanSums> = HashMap::default();
        for (slot, (late, directions, lean, diffuse_early)) in columns.into_iter().enumerate() {
            diffuse_walked[slot] = settings.diffuse_columns_walked && (late.is_some() || !diffuse_early.is_empty());
            for (i, v) in diffuse_early.into_iter().filter(|_| settings.diffuse_columns_walked) {
                if v != Vec3::ZERO {
                    diffuse_rows[i as usize].push((slot as u32, v));
                }
            }
            object_leans.entry(p[tabled[slot]].object).or_default().add(&lean);
            for (bin, column, moments, share) in directions {
                late_share[slot * bins as usize + bin as usize] = share;
                for (i, v) in column {
                    if v == Vec3::ZERO {
                        continue;
                    }
                    let at = slot as u32 * bins + bin;
                    early_rows[i as usize].push((at, v));
                    if settings.exit_directions {
                        // The mean direction it leaves along, per channel (the moment over
                        // the exitance): length 1 for light all leaving one way.
                        let moment = moments.get(&i).copied().unwrap_or([Vec4::ZERO; 3]);
                        let leaving = std::array::from_fn(|c| {
                            if v[c] > 0.0 { (moment[c].truncate() / v[c]).extend(moment[c].w) } else { Vec4::ZERO }
                        });
                        leaving_rows[i as usize].push((at, leaving));
                    }
                }
            }
            for (i, v) in late.into_iter().flatten() {
                if v != Vec3::ZERO {
                    late_rows[i as usize].push((slot as u32, v));
                }
            }
        }
        let table = Self {
            settings,
            slots,
            early: SparseMatrix::from_rows(early_rows),
            early_leaving: SparseMatrix::from_rows(leaving_rows).values,
            late_share,
            late: SparseMatrix::from_rows(late_rows),
            media,
            exit_lean: tabled
                .iter()
                .map(|&j| object_leans.get(&p[j].object).map_or_else(ExitLean::default, LeanSums::lean))
                .collect(),
            seconds: start.elapsed().as_secs_f32(),
        };
        (table, DiffuseColumns { early: SparseMatrix::from_rows(diffuse_rows), walked: diffuse_walked })
    }
}

/// The most [`late_walks_for`] multiplies [`BeamTableSettings::late_walks`] by: 4, as measured
/// (`docs/translucent.md`, "The late light's near field held to the medium's scale"); past it
/// the near field shrinks again with the patches, and the build's cost grows as `1/h²`.
pub const MAX_LATE_WALK_SCALE: f32 = 4.0;

/// The last order [`BeamTableSettings::late_walks`] is given for: a medium walked further
/// ([`BeamTableSettings::last_order_for`]) takes `order / 32` times as many ([`late_walks_for`]).
pub const LATE_WALKS_ORDER: u32 = 32;

/// Diffuse walks for a patch's late light: `late_walks · (ℓ/h)² · max(1, order/32)`, `ℓ` the
/// medium's longest transport mean free path, `h` the patch size and `order` the walks' last
/// order in this medium.
///
/// - `(ℓ/h)²`, the patches in a square of side `ℓ`, at least 1 and at most
///   [`MAX_LATE_WALK_SCALE`]: the near field is the set of patches the walks leave by, so with
///   a fixed count it shrank as patches got smaller: per patch fewer walks land, and a patch in
///   the early exits' tail is touched less often. The ball's skin lit from behind darkened
///   from 0.1046 at 960 patches to 0.164 at 3680. Walks that grow as `1/h²` give each patch as
///   many exits whatever its size, which holds the set's reach in the medium's own units.
///   Patches wider than `ℓ` (marble's 0.46 mm at any budget of the suite, the example's room)
///   keep `late_walks`.
/// - `order / 32` ([`LATE_WALKS_ORDER`]): the late light is the profile's column less these
///   walks' exits through the last order, a difference whose share of the column shrinks as
///   the order grows, so its noise grows against it. Marble walked to 64 scatterings on 3072
///   walks lost the ball from behind (0.0667 at 32 → 0.0747) and held it on 6144 (0.0595):
///   `docs/translucent.md`, "Marble walks to 64 scatterings". Media that stop sooner (skin:
///   16) keep `late_walks`.
pub fn late_walks_for(late_walks: u32, patch_size: f32, transport_mean_free_path: f32, last_order: u32) -> u32 {
    let squares = (transport_mean_free_path / patch_size).powi(2);
    let scale = if squares.is_finite() { squares.clamp(1.0, MAX_LATE_WALK_SCALE) } else { 1.0 };
    let orders = (last_order as f32 / LATE_WALKS_ORDER as f32).max(1.0);
    (late_walks as f32 * scale * orders).round() as u32
}

/// Object `object`'s medium and scale where the table walks its patches: translucent, with a
/// valid medium and a positive scale (else its patches keep the profile's `K`).
/// Per object, whether it marches its single scattering per pixel where the table leaves
/// that to the pixels ([`BeamTableSettings::single_scattering_to_pixels`]): the
/// [`MAX_MARCHED_OBJECTS`](crate::translucency::MAX_MARCHED_OBJECTS) translucent objects of
/// the largest surface (the first of equal ones); the others' single scattering stays in the
/// table. A map a light each, so the count is capped; the largest are those a camera most
/// likely sees large.
pub fn marched_objects(patches: &Patches, surfaces: &[PatchSurface]) -> Vec<bool> {
    let mut area = vec![0.0f64; surfaces.len()];
    for p in &patches.patches {
        if let Some(a) = area.get_mut(p.object as usize) {
            *a += p.area.max(0.0) as f64;
        }
    }
    let mut translucent: Vec<usize> =
        (0..surfaces.len()).filter(|&o| tabled_medium(surfaces, o as u32).is_some()).collect();
    translucent.sort_by(|&a, &b| area[b].total_cmp(&area[a]).then(a.cmp(&b)));
    let mut marched = vec![false; surfaces.len()];
    for &o in translucent.iter().take(crate::translucency::MAX_MARCHED_OBJECTS) {
        marched[o] = true;
    }
    marched
}

pub(crate) fn tabled_medium(
    surfaces: &[PatchSurface],
    object: u32,
) -> Option<(crate::translucency::medium::TranslucentMedium, f32)> {
    match surfaces.get(object as usize) {
        Some(&PatchSurface::Translucent { medium, world_units_per_mm, .. })
            if medium.invalid_reason().is_none()
                && world_units_per_mm.is_finite()
                && world_units_per_mm > 0.0 =>
        {
            Some((medium, world_units_per_mm))
        }
        _ => None,
    }
}

/// One patch's walks.
struct ColumnWalks<'a> {
    patches: &'a Patches,
    rays: &'a SceneRays,
    exits: &'a ExitPatches,
    medium: crate::translucency::medium::TranslucentMedium,
    units_per_mm: f32,
    j: usize,
    /// Patch `j`'s samples, where its walks enter (once for all its directions).
    entries: Vec<EntryPoint>,
    last_order: u32,
    /// How a beam walk splits far from its entry ([`BeamTableSettings::far_splits`]; the
    /// late light's diffuse walks do not split: the patches they reach are its near field).
    far_split: FarSplit,
    /// Whether to take the exits' moments.
    directions: bool,
    /// [`BeamTableSettings::single_scattering_to_pixels`].
    single_to_pixels: bool,
    /// Where light entering each patch acts as a source, per channel
    /// ([`EnergyTransport::source_depths`](crate::translucency::transport::EnergyTransport::source_depths)).
    source_depths: &'a [Vec3],
    /// Added to every walk's seed ([`BeamTableSettings::seed`]).
    seed_offset: u64,
}

impl ColumnWalks<'_> {
    /// `walks` walks a channel of `launch` from patch `j`'s samples: the exitance per unit
    /// of light that got in by exit patch, its first moment in the directions it leaves along
    /// (per channel, `Σ exitance · ω`), and the share still inside after the last order.
    /// With `law_takes_lit_face_single`, what leaves after one scattering by the lit face
    /// where the law can give it ([`law_gives_single_scattering`]) is left to
    /// [`single_scattering_radiance`] — and all that leaves after one scattering with
    /// [`BeamTableSettings::single_scattering_to_pixels`].
    fn walk(
        &self,
        launch: WalkLaunch,
        walks: u32,
        seed: u64,
        law_takes_lit_face_single: bool,
    ) -> (Column, Moments, Vec3, LeanSums) {
        let p = &self.patches.patches;
        let pj = &p[self.j];
        let share = 1.0 / walks as f32;
        // A beam's uncollided light goes on along the beam; diffuse light that crosses a thin
        // part unscattered is the surface's.
        let first = u32::from(matches!(launch, WalkLaunch::Beam(_)));
        let orders = ScatteringOrders { first, last: self.last_order };
        let mut column = Column::default();
        let mut moments = Moments::default();
        let mut remaining = Vec3::ZERO;
        // A beam's walks that leave from afar: what the object's `ExitLean` is fitted to.
        let mut lean = LeanSums::default();
        let beam = matches!(launch, WalkLaunch::Beam(_));
        let to_law = |order: u32, outward: Vec3| match launch {
            WalkLaunch::Beam(d) => {
                law_takes_lit_face_single
                    && order == 1
                    && (self.single_to_pixels || law_gives_single_scattering(pj.normal, d, outward))
            }
            WalkLaunch::Diffuse => false,
        };
        walk_ends(
            &self.medium,
            self.units_per_mm,
            &self.entries,
            self.rays,
            walks as usize,
            seed,
            launch,
            orders,
            beam.then_some(self.far_split),
            |weight, end| match end {
                WalkEnd::Exit(exit) if to_law(exit.order, exit.outward) => {}
                WalkEnd::Exit(exit) => {
                    if let Some(i) = self.exits.of(pj.object, exit.position, exit.outward) {
                        let exitance = weight * (share * pj.area / p[i as usize].area);
                        *column.entry(i).or_default() += exitance;
                        if self.directions {
                            let moment = moments.entry(i).or_insert([Vec4::ZERO; 3]);
                            for c in 0..3 {
                                moment[c] += (exitance[c] * exit.leaving).extend(weight[c]);
                            }
                        }
                        let i = i as usize;
                        if beam && from_afar(self.patches, self.source_depths, i, self.j) {
                            let n = p[i].normal;
                            let depth = self.source_depths.get(self.j).copied().unwrap_or(Vec3::ZERO);
                            for c in 0..3 {
                                let from = from_source(self.patches, i, self.j, depth[c]);
                                let t = from - n * from.dot(n);
                                lean.along[c] += weight[c] * n.dot(exit.leaving);
                                lean.walks[c] += weight[c];
                                lean.across[c] += weight[c] * t.dot(exit.leaving);
                                lean.spread[c] += weight[c] * t.length_squared();
                            }
                        }
                    }
                }
                // Through a gap in the mesh: lost.
                WalkEnd::Gap => {}
                WalkEnd::Remainder => remaining += weight * share,
            },
        );
        (column, moments, remaining, lean)
    }

    /// The late light per unit of diffuse walks' remainder: the profile's column (per unit
    /// of light that got in: over `diffuse_entering`) with its near field — where `late_walks`
    /// diffuse walks leave within the orders — scaled down by their share of it; and that
    /// remainder. `None` where no diffuse walk outlasts the orders.
    fn late_light(
        &self,
        profile_column: &[(u32, Vec3)],
        diffuse_entering: f32,
        late_walks: u32,
    ) -> (Option<(Column, Vec3)>, Column) {
        let p = &self.patches.patches;
        let seed = (u64::MAX - self.j as u64).wrapping_sub(self.seed_offset);
        let (early, _, remaining, _) = self.walk(WalkLaunch::Diffuse, late_walks, seed, false);
        if remaining == Vec3::ZERO {
            return (None, early);
        }
        let flux = |v: Vec3, i: u32| v * p[i as usize].area;
        let per_entered = 1.0 / diffuse_entering.max(1e-6);
        let near: Vec3 = profile_column
            .iter()
            .filter(|(i, _)| early.contains_key(i))
            .map(|&(i, v)| flux(v * per_entered, i))
            .sum();
        let early_flux: Vec3 = early.iter().map(|(&i, &v)| flux(v, i)).sum();
        let kept = Vec3::select(
            near.cmpgt(Vec3::ZERO),
            (near - early_flux).max(Vec3::ZERO) / near.max(Vec3::splat(1e-30)),
            Vec3::ZERO,
        );
        let mut column: Column = profile_column
            .iter()
            .map(|&(i, v)| {
                let v = v * per_entered;
                (i, if early.contains_key(&i) { v * kept } else { v })
            })
            .collect();
        // The late light cannot give out more than the light still inside: on a thin part
        // the flat profile reaches patches the walks never do, and a fifth of the bunny's
        // skin patches gave out more (up to 10⁴× on an ear), which a beam's share
        // (`remaining / late remaining`) then multiplied into a red blotch.
        let late_flux: Vec3 = column.iter().map(|(&i, &v)| flux(v, i)).sum();
        let inside = remaining * p[self.j].area;
        let scale = Vec3::select(late_flux.cmpgt(inside), inside / late_flux.max(Vec3::splat(1e-30)), Vec3::ONE);
        column.values_mut().for_each(|v| *v *= scale);
        (Some((column, remaining)), early)
    }
}
