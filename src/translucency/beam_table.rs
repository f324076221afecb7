//! A per-patch table of beam columns: where a translucent patch gives back the light of a beam
//! arriving along each of a few directions in its own frame, from random walks in the
//! object's triangles — the beam-resolved first scatterings that a diffusion profile, whose
//! sources sit under the entry whatever the light's direction, does not carry
//! (`docs/translucent.md`: on the Stanford bunny lit from the front, skin 0.160 → 0.078 and
//! marble 0.089 → 0.073 in relative L1 against Mitsuba).
//!
//! Each table direction's column comes from three parts:
//! - **the walks' low orders**: `walks` beam walks a channel from the patch's samples
//!   ([`walk_ends`]), refracted in, each exit after 1 … `last_order`
//!   scatterings counted on the patch it leaves by (the nearest sample facing the exit's
//!   way);
//! - **single scattering by the lit face is left out**: it leaves each lit pixel in its own
//!   law ([`single_scattering_radiance`]), limb-brightened where Lambert's law is flat; what
//!   leaves after one scattering where that law cannot give it — through the far side of a
//!   thin part, or past the terminator by a face turned from the light
//!   ([`law_gives_single_scattering`]) — stays in the column;
//! - **the late light**: the walks still inside after `last_order` scatterings leave as the
//!   late part of diffuse light entering the patch does — the profile's column (`K`'s, the
//!   object's shape and totals included) with its near field, the patches that `late_walks`
//!   diffuse walks leave by within the same orders, scaled down by those early exits' share of
//!   it — per unit of the diffuse walks' own remainder. Stopping the walks there bounds their
//!   cost (marble's albedo 0.999 would take hundreds of scatterings) and puts the light that
//!   crosses an object where the profile, not 256 walks' noise, says.
//!
//! Columns are per unit of light that got in: a frame weights each beam by the boundary's
//! Fresnel transmittance at its own incidence.

use bevy::{platform::collections::HashMap, prelude::*};

use super::{
    diffusion::{diffuse_fresnel_reflectance, fresnel_reflectance},
    patches::Patches,
    random_walk::{EntryPoint, ScatteringOrders, WalkEnd, WalkLaunch, walk_ends},
    transport::{PatchSurface, SceneRays, SparseMatrix, parallel_rows},
};

/// How a beam table is built.
#[derive(Clone, Copy, Debug, PartialEq, Reflect)]
pub struct BeamTableSettings {
    /// Incidence cosines of the table's directions, `(k + ½)/cosines` (1 – 16).
    pub cosines: u32,
    /// Azimuths about the patch's normal, `2π m/azimuths` (1 – 32).
    pub azimuths: u32,
    /// Beam walks a channel and direction (≥ 1).
    pub walks: u32,
    /// Diffuse walks a channel and patch for the late light's near field (≥ 1).
    pub late_walks: u32,
    /// Scatterings a walk takes before it leaves as late light (≥ 1).
    pub last_order: u32,
    /// Keep the mean direction each entry's light leaves along ([`BeamTable::early_leaving`],
    /// 12 more floats an entry): what the exit lobes are fitted to
    /// ([`EnergyTransport::exit_laws_along_lobes`](super::transport::EnergyTransport::exit_laws_along_lobes)),
    /// measured on the CPU path only (`translucent_accuracy --exit-axis lobe`; the GPU
    /// gather does not take them yet, and the plugin turns this off with a warning; not
    /// reflected, so the example's tuning panel does not offer it).
    #[reflect(ignore)]
    pub exit_directions: bool,
    /// Offsets every walk's seed (0: the tables the docs' figures come from). Tables of
    /// different seeds differ by their walks' noise alone, which moves the accuracy figures
    /// by ~±0.005 from the front (`docs/translucent.md`): what a variant must beat.
    pub seed: u32,
}

impl Default for BeamTableSettings {
    /// 4 × 8 directions (measured as close as 6 × 12 on the bunny and the ball; with each
    /// beam spread over four of them, 3 × 6 took the bunny's skin past 0.08 in relative L1
    /// with one seed of three: `docs/translucent.md`), 256 walks (128, 1.8× less precompute,
    /// keep every front-lit case within 0.08 but take the back-lit ball's skin from 0.147 to
    /// 0.166 over three seeds), 1024 late walks (256: 0.060 → 0.080 from the front, at the
    /// nearest direction), the 17th scattering on (from the 9th the back-lit bunny's skin
    /// went 0.286 → 0.316).
    fn default() -> Self {
        Self {
            cosines: 4,
            azimuths: 8,
            walks: 256,
            late_walks: 1024,
            last_order: 16,
            exit_directions: false,
            seed: 0,
        }
    }
}

impl BeamTableSettings {
    /// Directions a patch.
    pub fn bins(&self) -> u32 {
        self.cosines * self.azimuths
    }

    /// Why these settings cannot build a table, if they cannot.
    pub fn invalid_reason(&self) -> Option<&'static str> {
        if !(1..=16).contains(&self.cosines) || !(1..=32).contains(&self.azimuths) {
            Some("a beam table takes 1 – 16 cosines and 1 – 32 azimuths")
        } else if self.walks == 0 || self.late_walks == 0 || self.last_order == 0 {
            Some("a beam table needs at least one walk, late walk and scattering")
        } else {
            None
        }
    }
}

/// How far apart [`BeamTableSettings::seed`]s put the walks' seeds (a prime above any
/// patch's directions' seeds, `patch · bins + bin`, at a budget's patches).
const SEED_STRIDE: u64 = 1_000_003;

/// The frame a patch's table directions are measured in: a tangent and bitangent fixed by
/// its normal alone (Duff et al. 2017, "Building an orthonormal basis, revisited", the sign
/// taken as `z ≥ 0`; `tangent_frame` in `boundary.wgsl` is its twin).
pub(crate) fn tangent_frame(normal: Vec3) -> (Vec3, Vec3) {
    let sign = if normal.z >= 0.0 { 1.0 } else { -1.0 };
    let a = -1.0 / (sign + normal.z);
    let b = normal.x * normal.y * a;
    (
        Vec3::new(1.0 + sign * normal.x * normal.x * a, sign * b, -sign * normal.x),
        Vec3::new(b, sign + normal.y * normal.y * a, -normal.y),
    )
}

/// The table direction nearest a beam travelling along the unit `travel` onto a patch of
/// unit `normal`: its incidence cosine `μ = −travel·n` rounded down to `(k + ½)/cosines`'s
/// bin, its azimuth to the nearest of `azimuths`; `bin = k · azimuths + m`. `None` for a beam
/// along or behind the surface.
pub fn direction_bin(travel: Vec3, normal: Vec3, cosines: u32, azimuths: u32) -> Option<u32> {
    let (mu, turns) = incidence_and_turns(travel, normal, cosines, azimuths)?;
    let m = turns.round().rem_euclid(azimuths as f32) as u32;
    let k = ((mu * cosines as f32) as u32).min(cosines - 1);
    Some(k * azimuths + m.min(azimuths - 1))
}

/// A beam's incidence cosine `μ = −travel·n` onto a patch of unit `normal` and its azimuth
/// in the patch's frame ([`tangent_frame`]) in steps of the table's azimuths (not wrapped);
/// `None` for a beam along or behind the surface or an empty table.
fn incidence_and_turns(travel: Vec3, normal: Vec3, cosines: u32, azimuths: u32) -> Option<(f32, f32)> {
    let mu = -travel.dot(normal);
    if !(mu > 0.0) || cosines == 0 || azimuths == 0 {
        return None;
    }
    let (t, b) = tangent_frame(normal);
    let along = travel + mu * normal;
    let step = std::f32::consts::TAU / azimuths as f32;
    Some((mu, along.dot(b).atan2(along.dot(t)) / step))
}

/// The table directions about a beam travelling along the unit `travel` onto a patch of unit
/// `normal`, with their weights: bilinear in the incidence cosine between the bins' centres
/// `(k + ½)/cosines` (held at the first and last) and in the azimuth between its two
/// neighbours (round the circle). Four `(bin, weight)` pairs, weights summing to 1 (a pair
/// may repeat a bin); `None` as for [`direction_bin`].
pub fn direction_weights(travel: Vec3, normal: Vec3, cosines: u32, azimuths: u32) -> Option<[(u32, f32); 4]> {
    let (mu, turns) = incidence_and_turns(travel, normal, cosines, azimuths)?;
    let turn = turns.rem_euclid(azimuths as f32);
    let m0 = (turn.floor() as u32).min(azimuths - 1);
    let (m1, g) = ((m0 + 1) % azimuths, (turn - m0 as f32).clamp(0.0, 1.0));
    let place = (mu.min(1.0) * cosines as f32 - 0.5).clamp(0.0, (cosines - 1) as f32);
    let k0 = (place.floor() as u32).min(cosines - 1);
    let (k1, f) = ((k0 + 1).min(cosines - 1), place - k0 as f32);
    Some([
        (k0 * azimuths + m0, (1.0 - f) * (1.0 - g)),
        (k0 * azimuths + m1, (1.0 - f) * g),
        (k1 * azimuths + m0, f * (1.0 - g)),
        (k1 * azimuths + m1, f * g),
    ])
}

/// The travel direction of table direction `bin` onto a patch of unit `normal` (see
/// [`direction_bin`]).
pub fn bin_direction(bin: u32, normal: Vec3, cosines: u32, azimuths: u32) -> Vec3 {
    let (k, m) = (bin / azimuths.max(1), bin % azimuths.max(1));
    let mu = (k as f32 + 0.5) / cosines.max(1) as f32;
    let azimuth = std::f32::consts::TAU * m as f32 / azimuths.max(1) as f32;
    let (t, b) = tangent_frame(normal);
    let sine = (1.0 - mu * mu).max(0.0).sqrt();
    (sine * (azimuth.cos() * t + azimuth.sin() * b) - mu * normal).normalize()
}

/// Whether single scattering of a beam travelling along `beam` into a patch of unit `normal`,
/// leaving by a surface of outward unit normal `outward`, is the gather's to give in
/// [`single_scattering_radiance`]'s law rather than the table's: by the lit face (within 60°
/// of the patch's normal) *and* by a surface that faces the light — the law gives single
/// scattering only where the pixel's own `μ₀ > 0`, so what a grazing beam scatters out past
/// the terminator would otherwise be lost (`docs/translucent.md`: ball skin from the front
/// 0.057 → 0.047, the bunny's skin from behind 0.240 → 0.226 over three seeds).
pub fn law_gives_single_scattering(normal: Vec3, beam: Vec3, outward: Vec3) -> bool {
    outward.dot(normal) > 0.5 && outward.dot(beam) < 0.0
}

/// Single scattering's radiance leaving a half-space of single-scattering albedo `alpha`
/// (isotropic phase) behind a smooth boundary of index `eta`, lit by a beam of irradiance
/// `irradiance` (on the surface) at incidence cosine `mu0`, seen at exit cosine `mu`:
/// `α E T(μ₀) T(μ) / (4π η² (μ₀′ + μ′))`, the primed cosines refracted (Hanrahan and
/// Krueger 1993; at `η = 1`, `α E / (4π(μ₀ + μ))`). Zero outside `0 < μ₀, μ ≤ 1`.
pub fn single_scattering_radiance(alpha: Vec3, eta: f32, irradiance: Vec3, mu0: f32, mu: f32) -> Vec3 {
    if !(mu0 > 0.0 && mu > 0.0) {
        return Vec3::ZERO;
    }
    let eta = if eta.is_finite() { eta.clamp(1.0, 3.0) } else { 1.0 };
    let inside = |c: f32| (1.0 - (1.0 - c * c) / (eta * eta)).max(0.0).sqrt();
    let transmitted = |c: f32| (1.0 - fresnel_reflectance(c.min(1.0) as f64, eta as f64)) as f32;
    alpha * irradiance * (transmitted(mu0) * transmitted(mu))
        / (4.0 * std::f32::consts::PI * eta * eta * (inside(mu0) + inside(mu)))
}

/// The fraction of a beam at incidence cosine `mu0` that gets into a medium of index `eta`
/// (what a table column is per unit of).
pub fn entering(eta: f32, mu0: f32) -> f32 {
    (1.0 - fresnel_reflectance(mu0.clamp(0.0, 1.0) as f64, eta.max(1.0) as f64)) as f32
}

/// The beam table of one scene's translucent patches.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BeamTable {
    /// What it was built with.
    pub settings: BeamTableSettings,
    /// Per patch its slot (its directions are `slot · bins … + bins`), `u32::MAX` for
    /// patches without a table (opaque, an invalid medium).
    pub slots: Vec<u32>,
    /// The walks' low orders — rows: the patches light leaves by; columns: `slot · bins +
    /// bin`; values: exitance per unit of irradiance that got in, per channel.
    pub early: SparseMatrix<Vec3>,
    /// With [`BeamTableSettings::exit_directions`] (else empty): per entry of `early` (in its
    /// order), per channel, the mean direction its light leaves along outside (`xyz`, the
    /// exitance-weighted mean of the walks' leaving directions: length 1 for light all
    /// leaving one way, ⅔ along the normal for Lambert's law) and how many walks it holds
    /// (`w`, for the mean's noise).
    pub early_leaving: Vec<[Vec4; 3]>,
    /// Per direction (`slot · bins + bin`), the share of its walks still inside after the last
    /// order over the share of diffuse walks', per channel: how much of `late`'s column its
    /// light takes.
    pub late_share: Vec<Vec3>,
    /// The late light, one column per slot: where diffuse light entering the patch leaves
    /// after the last order (the profile's column, its near field scaled down), per unit of
    /// the diffuse walks' remainder. One column a patch, not one a direction: the late light
    /// has forgotten the beam but for its amount.
    pub late: SparseMatrix<Vec3>,
    /// Per slot, its medium's single-scattering albedo (rgb) and index of refraction (w).
    pub media: Vec<Vec4>,
    /// Per slot, how its object's light from afar leans as it leaves ([`ExitLean`], fitted
    /// to the object's beam walks).
    pub exit_lean: Vec<ExitLean>,
    /// Wall-clock seconds to build.
    pub seconds: f32,
}

/// How far, in patch sizes, light must have come to leave a patch by its exit lobe
/// ([`ExitLean`]): nearer light leaves in the patch's own limb-darkened law. 1 – 4 measured
/// (`docs/translucent.md`): the ball's skin lit from behind 0.175 / 0.178 / 0.190 / 0.199 in
/// relative L1, from the front 0.078 / 0.065 / 0.057 / 0.054; 2 keeps most of the gain from
/// behind with every front-lit case within 0.08.
pub const LOBE_SOURCE_DISTANCE: f32 = 2.0;

/// Whether light from patch `j` reaches patch `i` from afar ([`LOBE_SOURCE_DISTANCE`]).
pub fn from_afar(patches: &Patches, i: usize, j: usize) -> bool {
    let p = &patches.patches;
    p[i].surface_point.distance(p[j].surface_point) > LOBE_SOURCE_DISTANCE * patches.size_of(i)
}

/// The unit direction light travels from patch `j`'s diffusion source, `depth` under its
/// surface point, to patch `i`'s surface point (zero where they meet): what
/// [`BeamTable::flow`] and [`ExitLean`] measure a patch's light by.
fn from_source(patches: &Patches, i: usize, j: usize, depth: f32) -> Vec3 {
    let p = &patches.patches;
    (p[i].surface_point - (p[j].surface_point - p[j].normal * depth)).normalize_or_zero()
}

/// How an object's light from afar leans as it leaves, per channel: the mean direction it
/// leaves along (refracted out) as `along · n + across · t`, `n` the exit patch's normal and
/// `t` the part across it of the direction the light came from (from the entry's diffusion
/// source to the exit patch's surface point). Fitted by
/// least squares over the object's beam walks that leave more than [`LOBE_SOURCE_DISTANCE`]
/// patch sizes from their entry (`n` and `t` are orthogonal, so each coefficient is a ratio
/// of sums). A patch's light from afar leaves by the lobe of that mean over its sources
/// ([`BeamTable::flow`], [`ExitLaw::set_far_lobes`](super::transport::ExitLaw::set_far_lobes)):
/// a model of the walks' own directions, pooled over the whole object, so free of each
/// entry's noise (each entry's own mean needed 8× the walks to help: `docs/translucent.md`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ExitLean {
    /// Per channel, along the normal (Lambert's law: ⅔).
    pub along: Vec3,
    /// Per channel, along the way the light came (0: none).
    pub across: Vec3,
}

impl ExitLean {
    /// The mean direction light from afar leaves a patch of unit `normal` along in channel
    /// `c`, given the mean of the directions it came from, `from` ([`BeamTable::flow`]'s
    /// `far_axis`).
    pub fn mean(&self, c: usize, normal: Vec3, from: Vec3) -> Vec3 {
        normal * self.along[c] + (from - normal * from.dot(normal)) * self.across[c]
    }
}

/// [`ExitLean`]'s least-squares sums over walks, per channel: `Σ n·ω`, the walks, `Σ t·ω`
/// and `Σ |t|²`.
#[derive(Clone, Copy, Debug, Default)]
struct LeanSums {
    along: Vec3,
    walks: Vec3,
    across: Vec3,
    spread: Vec3,
}

impl LeanSums {
    fn add(&mut self, other: &Self) {
        self.along += other.along;
        self.walks += other.walks;
        self.across += other.across;
        self.spread += other.spread;
    }

    fn lean(&self) -> ExitLean {
        let ratio = |a: Vec3, b: Vec3| Vec3::select(b.cmpgt(Vec3::ZERO), a / b.max(Vec3::splat(1e-30)), Vec3::ZERO);
        ExitLean {
            along: Vec3::select(self.walks.cmpgt(Vec3::ZERO), ratio(self.along, self.walks), Vec3::splat(2.0 / 3.0)),
            across: ratio(self.across, self.spread),
        }
    }
}

/// The way the light a beam table gives a patch flows in ([`BeamTable::flow`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TableFlow {
    /// Per channel, `Σ_j c_ij u_ij / Σ_j c_ij` over all the table's light from other
    /// patches (what [`ExitLaw::set_flow`](super::transport::ExitLaw::set_flow) takes).
    pub axis: [Vec3; 3],
    /// The table's early light from afar ([`from_afar`]).
    pub far: Vec3,
    /// Per channel, the same mean over that light alone (what [`ExitLean::mean`] takes).
    pub far_axis: [Vec3; 3],
}

/// The patch a walk leaves by: the nearest sample facing the exit's way (not the far side of
/// a thin part), else the nearest of any, among a grid of its object's samples (cells of the
/// object's own patch size: a room's wall patches would make a grid of the largest size
/// hold a whole small object in a cell).
pub struct ExitPatches {
    grids: Vec<(f32, HashMap<IVec3, Vec<(Vec3, Vec3, u32)>>)>,
}

impl ExitPatches {
    /// The grids of `patches`' samples, one per object.
    pub fn new(patches: &Patches) -> Self {
        let objects = patches.object_patch_sizes.len();
        let mut grids: Vec<(f32, HashMap<IVec3, Vec<(Vec3, Vec3, u32)>>)> = (0..objects)
            .map(|o| (patches.object_patch_sizes[o].max(1e-9), HashMap::default()))
            .collect();
        for (i, q) in patches.patches.iter().enumerate() {
            let Some((cell, grid)) = grids.get_mut(q.object as usize) else {
                continue;
            };
            for s in patches.samples_of(i) {
                grid.entry((s.position / *cell).floor().as_ivec3())
                    .or_default()
                    .push((s.position, s.normal, i as u32));
            }
        }
        Self { grids }
    }

    /// The patch of `object` a walk leaving at `x` through a boundary of unit `outward`
    /// normal leaves by; `None` where none of its samples is within a patch size.
    pub fn of(&self, object: u32, x: Vec3, outward: Vec3) -> Option<u32> {
        let (cell, grid) = self.grids.get(object as usize)?;
        let key = (x / *cell).floor().as_ivec3();
        // The nearest sample facing the exit's way (not the far side of a thin part), else
        // the nearest of any: (distance², patch).
        let (mut facing, mut any): (Option<(f32, u32)>, Option<(f32, u32)>) = (None, None);
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let cell = grid.get(&(key + IVec3::new(dx, dy, dz)));
                    for &(position, normal, patch) in cell.into_iter().flatten() {
                        let d = position.distance_squared(x);
                        if any.is_none_or(|b| d < b.0) {
                            any = Some((d, patch));
                        }
                        if normal.dot(outward) > 0.0 && facing.is_none_or(|b| d < b.0) {
                            facing = Some((d, patch));
                        }
                    }
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
type PatchColumns = (Option<Column>, Vec<(u32, Column, Moments, Vec3)>, LeanSums);

impl BeamTable {
    /// Directions a patch.
    pub fn bins(&self) -> u32 {
        self.settings.bins()
    }

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
        let start = std::time::Instant::now();
        let p = &patches.patches;
        let n = p.len();
        if let Some(reason) = settings.invalid_reason() {
            warn!("translucency: {reason} (got {settings:?}); no beam table");
            return Self { settings, slots: vec![u32::MAX; n], ..default() };
        }
        let medium_of = |j: usize| match surfaces.get(p[j].object as usize) {
            Some(&PatchSurface::Translucent { medium, world_units_per_mm, .. })
                if medium.invalid_reason().is_none()
                    && world_units_per_mm.is_finite()
                    && world_units_per_mm > 0.0 =>
            {
                Some((medium, world_units_per_mm))
            }
            _ => None,
        };
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
        let source_depths = super::transport::EnergyTransport::source_depths(patches, surfaces);
        let bins = settings.bins();
        let columns: Vec<PatchColumns> = parallel_rows(tabled.len(), |slot| {
            let j = tabled[slot];
            let Some((medium, units_per_mm)) = medium_of(j) else {
                return (None, Vec::new(), LeanSums::default());
            };
            let walked: Vec<u32> = match only {
                Some(only) => only.get(j).cloned().unwrap_or_default(),
                None => (0..bins).collect(),
            };
            if walked.is_empty() {
                return (None, Vec::new(), LeanSums::default());
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
                last_order: settings.last_order,
                directions: settings.exit_directions,
                source_depth: source_depths.get(j).copied().unwrap_or(Vec3::ZERO),
                seed_offset: settings.seed as u64 * SEED_STRIDE,
            };
            let diffuse_entering =
                (1.0 - diffuse_fresnel_reflectance(medium.index_of_refraction as f64)) as f32;
            let late = column_of.late_light(
                &profile_columns[j],
                diffuse_entering,
                settings.late_walks,
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
            (late.map(|l| l.0), directions, lean)
        });
        let mut early_rows: Vec<Vec<(u32, Vec3)>> = vec![Vec::new(); n];
        // With the exit directions, each early entry's at the same (row, column): sorted as
        // `early`'s rows are, their values line up with its.
        let mut leaving_rows: Vec<Vec<(u32, [Vec4; 3])>> = vec![Vec::new(); n];
        let mut late_rows: Vec<Vec<(u32, Vec3)>> = vec![Vec::new(); n];
        let mut late_share = vec![Vec3::ZERO; tabled.len() * bins as usize];
        // Each object's lean, pooled over its patches' walks.
        let mut object_leans: HashMap<u32, LeanSums> = HashMap::default();
        for (slot, (late, directions, lean)) in columns.into_iter().enumerate() {
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
        Self {
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
        }
    }

    /// Where a beam travelling along `travel` onto patch `j` goes in the table's light
    /// vector (`slot · bins + bin`, the four directions about it by their weights:
    /// [`direction_weights`]), and the share of it that gets in (`entering`); `None` for a
    /// patch without a table or a beam along or behind its surface.
    pub fn light_index(&self, patches: &Patches, j: usize, travel: Vec3) -> Option<([(usize, f32); 4], f32)> {
        let slot = *self.slots.get(j).filter(|&&s| s != u32::MAX)?;
        let normal = patches.patches[j].normal;
        let weights = direction_weights(travel, normal, self.settings.cosines, self.settings.azimuths)?;
        let eta = self.media[slot as usize].w;
        Some((
            weights.map(|(bin, w)| ((slot * self.bins() + bin) as usize, w)),
            entering(eta, -travel.dot(normal)),
        ))
    }

    /// The exitance the table gives every patch for `light`, the irradiance that got in per
    /// `slot · bins + bin` (`light_index`): the early columns' product, and the late columns'
    /// with each slot's directions summed by their `late_share`.
    pub fn apply(&self, light: &[Vec3]) -> Vec<Vec3> {
        let mut exitance = self.early.mul_vec(light);
        for (b, late) in exitance.iter_mut().zip(self.late.mul_vec(&self.late_light(light))) {
            *b += late;
        }
        exitance
    }

    /// Per slot, its late light for `light` (as [`apply`](Self::apply) takes it): its
    /// directions' beams summed by their `late_share` (`table_late` in `iterate.wgsl`).
    fn late_light(&self, light: &[Vec3]) -> Vec<Vec3> {
        let bins = self.bins() as usize;
        (0..self.media.len())
            .map(|slot| {
                (slot * bins..(slot + 1) * bins)
                    .map(|c| self.late_share[c] * light.get(c).copied().unwrap_or(Vec3::ZERO))
                    .sum()
            })
            .collect()
    }

    /// Per slot, the patch it is the table of (the inverse of [`slots`](Self::slots)).
    pub fn slot_patches(&self) -> Vec<u32> {
        let mut patch_of = vec![u32::MAX; self.media.len()];
        for (j, &slot) in self.slots.iter().enumerate() {
            if let Some(at) = patch_of.get_mut(slot as usize) {
                *at = j as u32;
            }
        }
        patch_of
    }

    /// Per patch, the way the light the table gives it flows in ([`TableFlow`]): per channel
    /// `Σ_j c_ij u_ij / Σ_j c_ij` over the other patches `j`, `c_ij` what `j`'s beams
    /// (`light`, as for [`apply`](Self::apply)) give patch `i` through the early and late
    /// columns, `u_ij` the unit direction to `i`'s surface point from `j`'s diffusion source
    /// (`source_depths[j]` under its surface point, per channel; what
    /// [`ExitLaw::flow`](super::transport::ExitLaw::flow) takes about); and the same over the
    /// early light from afar alone, with its amount (what the exit lobes take). Lengths 0 – 1:
    /// how much of that light flows one way; zero where none comes.
    pub fn flow(&self, patches: &Patches, light: &[Vec3], source_depths: &[Vec3]) -> Vec<TableFlow> {
        let n = patches.patches.len();
        let bins = self.bins() as usize;
        let patch_of = self.slot_patches();
        let beam = |c: usize| light.get(c).copied().unwrap_or(Vec3::ZERO);
        let late_light = self.late_light(light);
        let mean = |sum: [Vec3; 3], total: Vec3| {
            std::array::from_fn(|c| if total[c] > 0.0 { sum[c] / total[c] } else { Vec3::ZERO })
        };
        (0..n)
            .map(|i| {
                let (mut flow, mut total) = ([Vec3::ZERO; 3], Vec3::ZERO);
                let (mut far_flow, mut far) = ([Vec3::ZERO; 3], Vec3::ZERO);
                let mut add = |j: usize, given: Vec3, early: bool| {
                    if j == i || j >= n {
                        return;
                    }
                    let depth = source_depths.get(j).copied().unwrap_or(Vec3::ZERO);
                    let afar = early && from_afar(patches, i, j);
                    for c in 0..3 {
                        let u = from_source(patches, i, j, depth[c]) * given[c];
                        flow[c] += u;
                        if afar {
                            far_flow[c] += u;
                        }
                    }
                    total += given;
                    if afar {
                        far += given;
                    }
                };
                if i < self.early.rows() {
                    for (column, v) in self.early.row(i) {
                        add(patch_of[column / bins] as usize, v * beam(column), true);
                    }
                }
                if i < self.late.rows() {
                    for (slot, v) in self.late.row(i) {
                        add(patch_of[slot] as usize, v * late_light[slot], false);
                    }
                }
                TableFlow { axis: mean(flow, total), far, far_axis: mean(far_flow, far) }
            })
            .collect()
    }

    /// Per patch `i`, the early light the table gives it for `light` (as for
    /// [`apply`](Self::apply)) from the patches `j` with `counted(i, j)` and, per channel, its
    /// first moment in the directions it leaves along (`xyz`: `Σ exitance · ω`, from
    /// [`early_leaving`](Self::early_leaving)) with `w = Σ exitance²/walks`, what the mean's
    /// noise grows with.
    pub fn early_moments(&self, light: &[Vec3], counted: impl Fn(usize, usize) -> bool) -> Vec<(Vec3, [Vec4; 3])> {
        let beam = |c: usize| light.get(c).copied().unwrap_or(Vec3::ZERO);
        let patch_of = self.slot_patches();
        let bins = self.bins() as usize;
        (0..self.early.rows())
            .map(|i| {
                let range = self.early.row_offsets[i] as usize..self.early.row_offsets[i + 1] as usize;
                let (mut exitance, mut moment) = (Vec3::ZERO, [Vec4::ZERO; 3]);
                for e in range {
                    let column = self.early.columns[e] as usize;
                    if !counted(i, patch_of[column / bins] as usize) {
                        continue;
                    }
                    let given = self.early.values[e] * beam(column);
                    exitance += given;
                    for c in 0..3 {
                        let l = self.early_leaving.get(e).map_or(Vec4::ZERO, |l| l[c]);
                        moment[c] += (given[c] * l.truncate()).extend(given[c] * given[c] / l.w.max(1.0));
                    }
                }
                (exitance, moment)
            })
            .collect()
    }

    /// Per patch, its medium's `(α, η)` where it has a table, zero elsewhere (what the
    /// gather's single scattering takes).
    pub fn patch_media(&self) -> Vec<Vec4> {
        self.slots
            .iter()
            .map(|&s| self.media.get(s as usize).copied().unwrap_or(Vec4::ZERO))
            .collect()
    }

    /// Direction `bin` of patch `j`'s column: the exitance per unit of irradiance that got
    /// in, by the patch it leaves through (early and late light summed; empty without a
    /// table).
    pub fn column(&self, j: usize, bin: u32) -> Vec<(usize, Vec3)> {
        let Some(&slot) = self.slots.get(j).filter(|&&s| s != u32::MAX) else {
            return Vec::new();
        };
        let (direction, share) = (
            (slot * self.bins() + bin) as usize,
            self.late_share[(slot * self.bins() + bin) as usize],
        );
        let mut column: std::collections::BTreeMap<usize, Vec3> = Default::default();
        for i in 0..self.early.rows() {
            for (c, v) in self.early.row(i) {
                if c == direction {
                    *column.entry(i).or_default() += v;
                }
            }
            for (c, v) in self.late.row(i) {
                if c == slot as usize {
                    *column.entry(i).or_default() += v * share;
                }
            }
        }
        column.into_iter().collect()
    }
}

/// One patch's walks.
struct ColumnWalks<'a> {
    patches: &'a Patches,
    rays: &'a SceneRays,
    exits: &'a ExitPatches,
    medium: super::medium::TranslucentMedium,
    units_per_mm: f32,
    j: usize,
    /// Patch `j`'s samples, where its walks enter (once for all its directions).
    entries: Vec<EntryPoint>,
    last_order: u32,
    /// Whether to take the exits' moments.
    directions: bool,
    /// Where light entering patch `j` acts as a source, per channel
    /// ([`EnergyTransport::source_depths`](super::transport::EnergyTransport::source_depths)).
    source_depth: Vec3,
    /// Added to every walk's seed ([`BeamTableSettings::seed`]).
    seed_offset: u64,
}

impl ColumnWalks<'_> {
    /// `walks` walks a channel of `launch` from patch `j`'s samples: the exitance per unit
    /// of light that got in by exit patch, its first moment in the directions it leaves along
    /// (per channel, `Σ exitance · ω`), and the share still inside after the last order.
    /// With `law_takes_lit_face_single`, what leaves after one scattering by the lit face
    /// where the law can give it ([`law_gives_single_scattering`]) is left to
    /// [`single_scattering_radiance`].
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
                law_takes_lit_face_single && order == 1 && law_gives_single_scattering(pj.normal, d, outward)
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
            |c, end| match end {
                WalkEnd::Exit(exit) if to_law(exit.order, exit.outward) => {}
                WalkEnd::Exit(exit) => {
                    if let Some(i) = self.exits.of(pj.object, exit.position, exit.outward) {
                        let exitance = share * pj.area / p[i as usize].area;
                        column.entry(i).or_default()[c] += exitance;
                        if self.directions {
                            moments.entry(i).or_insert([Vec4::ZERO; 3])[c] += (exitance * exit.leaving).extend(1.0);
                        }
                        let i = i as usize;
                        if beam && from_afar(self.patches, i, self.j) {
                            let n = p[i].normal;
                            let from = from_source(self.patches, i, self.j, self.source_depth[c]);
                            let t = from - n * from.dot(n);
                            lean.along[c] += n.dot(exit.leaving);
                            lean.walks[c] += 1.0;
                            lean.across[c] += t.dot(exit.leaving);
                            lean.spread[c] += t.length_squared();
                        }
                    }
                }
                // Through a gap in the mesh: lost.
                WalkEnd::Gap => {}
                WalkEnd::Remainder => remaining[c] += share,
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
    ) -> Option<(Column, Vec3)> {
        let p = &self.patches.patches;
        let seed = (u64::MAX - self.j as u64).wrapping_sub(self.seed_offset);
        let (early, _, remaining, _) = self.walk(WalkLaunch::Diffuse, late_walks, seed, false);
        if remaining == Vec3::ZERO {
            return None;
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
        let column = profile_column
            .iter()
            .map(|&(i, v)| {
                let v = v * per_entered;
                (i, if early.contains_key(&i) { v * kept } else { v })
            })
            .collect();
        Some((column, remaining))
    }
}
