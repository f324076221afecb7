//! A per-patch table of beam columns: where a translucent patch gives back the light of a beam
//! arriving along each of a few directions in its own frame, from random walks in the
//! object's triangles — the beam-resolved first scatterings that a diffusion profile, whose
//! sources sit under the entry whatever the light's direction, does not carry
//! (`docs/translucent.md`: on the Stanford bunny lit from the front, skin 0.160 → 0.078 and
//! marble 0.089 → 0.073 in relative L1 against Mitsuba).
//!
//! Each table direction's column comes from three parts:
//! - **the walks' low orders**: `walks` beam walks from the patch's samples, each shared by
//!   the three channels ([`walk_ends`](super::random_walk::walk_ends)), refracted in, each exit after 1 … `last_order`
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
//!   diffuse walks (more on patches narrower than a transport mean free path) leave by within
//!   the same orders, scaled down by those early exits' share of it — per unit of the
//!   diffuse walks' own remainder. Stopping the walks there bounds their cost (marble's
//!   albedo 0.999 would take hundreds of scatterings) and puts the light that crosses an
//!   object where the profile, not a few hundred walks' noise, says. A medium that keeps
//!   more than half its light over `last_order` scatterings walks on until half is lost, up
//!   to `max_last_order` ([`BeamTableSettings::last_order_for`]).
//!
//! Columns are per unit of light that got in: a frame weights each beam by the boundary's
//! Fresnel transmittance at its own incidence.
//!
//! The pieces: [`directions`] (a beam's table directions in its patch's frame),
//! [`single_scattering`] (the share the gather gives in its own law), [`flow`] (how the
//! table's light flows in and leans as it leaves) and `build` (the walks that fill the
//! columns).

pub(crate) mod build;
pub mod directions;
pub mod flow;
pub mod single_scattering;

pub use build::{ExitPatches, LATE_WALKS_ORDER, MAX_LATE_WALK_SCALE, late_walks_for, marched_objects};
pub use directions::{bin_direction, direction_bin, direction_weights};
pub use flow::{ExitLean, LOBE_SOURCE_DISTANCE, LOBE_SOURCE_MEAN_FREE_PATHS, TableFlow, from_afar, lobe_source_distance};
pub use single_scattering::{
    LIT_FACE_NODES, entering, law_gives_single_scattering, lit_face_exitance, single_scattering_radiance,
};

use bevy::prelude::*;

use super::{patches::Patches, transport::SparseMatrix};

/// How a beam table is built.
#[derive(Clone, Copy, Debug, PartialEq, Reflect)]
pub struct BeamTableSettings {
    /// Incidence cosines of the table's directions, `(k + ½)/cosines` (1 – 16).
    pub cosines: u32,
    /// Azimuths about the patch's normal, `2π m/azimuths` (1 – 32).
    pub azimuths: u32,
    /// Beam walks a direction (≥ 1), each shared by the three channels (hero channels:
    /// [`walk_ends`](super::random_walk::walk_ends)).
    pub walks: u32,
    /// Diffuse walks a patch for the late light's near field (≥ 1), shared by the channels;
    /// times `(ℓ/h)²` on patches narrower than the medium's longest transport mean free path
    /// `ℓ`, at most 4×, and times `order/32` in a medium walked past 32 scatterings
    /// ([`late_walks_for`]: marble's 64 take twice as many).
    pub late_walks: u32,
    /// How many walks a beam walk becomes once it scatters more than
    /// [`lobe_source_distance`] from where it entered (≥ 1; 1: none;
    /// [`FarSplit`](super::random_walk::FarSplit)): the far exits, few and blotchy, walked
    /// that many times as often for a fraction of the cost of as many more walks.
    pub far_splits: u32,
    /// Scatterings a walk takes before it leaves as late light (≥ 1), in a medium that loses
    /// half its light to absorption within them or sooner (skin's red: 16); see
    /// [`max_last_order`](Self::max_last_order) for media that absorb less.
    pub last_order: u32,
    /// In a medium that absorbs less, walks go on until half their light would be absorbed
    /// (`ln ½ / ln α`, `α` the medium's highest single-scattering albedo), up to this many
    /// scatterings ([`last_order_for`](Self::last_order_for); below `last_order` it is
    /// `last_order`). The late light is diffuse light entering at the walk's entry, which a
    /// barely absorbing medium's light still mostly is after 16 scatterings (marble keeps
    /// 98 % of it, ~1.5 mm from its entry): on a torus's 6 mm tube lit from behind that put
    /// its light back by its entry, 0.093 → 0.074 in relative L1 at 4000 patches against
    /// Mitsuba (`docs/translucent.md`, "Walks in a medium that barely absorbs go on").
    /// Higher is closer and slower to build: the marble bunny lit from behind at 4000 patches
    /// scores 0.111 / 0.092 at 32 / 64 (the mean of three table seeds; `docs/translucent.md`,
    /// "Marble walks to 64 scatterings"), the `translucent` example's room's table taking
    /// 1.0 / 1.6× as long.
    pub max_last_order: u32,
    /// Keep the mean direction each entry's light leaves along ([`BeamTable::early_leaving`],
    /// 12 more floats an entry): what the exit lobes are fitted to
    /// ([`EnergyTransport::exit_laws_along_lobes`](super::transport::EnergyTransport::exit_laws_along_lobes)),
    /// measured on the CPU path only (`translucent_accuracy --exit-axis lobe`; the GPU
    /// gather does not take them yet, and the plugin turns this off with a warning; not
    /// reflected, so the example's tuning panel does not offer it).
    #[reflect(ignore)]
    pub exit_directions: bool,
    /// Leave all the light that leaves after one scattering out of the table, not only what
    /// leaves by the lit face, for the gather to march per pixel through the object against
    /// the light's own path in it (a map per translucent object and light in the GPU light
    /// injection: `docs/translucent.md`, "Single scattering marched per pixel on the GPU").
    /// On by default. Where lights are injected by `LightInjection::ShadowRays` (no maps) the
    /// table keeps single scattering; of more than
    /// [`MAX_MARCHED_OBJECTS`](super::MAX_MARCHED_OBJECTS) translucent objects, it keeps it
    /// for all but the largest that many ([`marched_objects`], with a warning).
    pub single_scattering_to_pixels: bool,
    /// Light that enters a tabled patch diffusely — what left the object and came back in
    /// (the bounce's `K F B`), a floor's, any light the table does not carry — leaves by the
    /// late light's own diffuse walks through their last order and the late light after
    /// them ([`DiffuseColumns`]), in place of the profile's `K` column: the walks are
    /// already taken for the late light's near field, so it costs no walk. The profile
    /// carried the skin bunny's light that came back in 5 – 8 % short on its far side
    /// (`docs/translucent.md`, "Light that came back in, walked").
    pub diffuse_columns_walked: bool,
    /// Offsets every walk's seed (0: the tables the docs' figures come from). Tables of
    /// different seeds differ by their walks' noise alone, which moves the accuracy figures
    /// by ~±0.005 from the front (`docs/translucent.md`): what a variant must beat.
    pub seed: u32,
    /// The most translucent patches a scene may have for a table to be built (its precompute
    /// and memory grow with them: ~0.07 s a translucent patch on one core in release with
    /// marble walked to 64 scatterings, ~15 kB a patch); a scene with more keeps the
    /// profile's `K`, with one warning
    /// ([`TransportReport::beam_table_skipped`](super::transport::TransportReport::beam_table_skipped)).
    pub max_patches: u32,
}

impl Default for BeamTableSettings {
    /// 4 × 8 directions (measured as close as 6 × 12 on the bunny and the ball; with each
    /// beam spread over four of them, 3 × 6 took the bunny's skin past 0.08 in relative L1
    /// with one seed of three: `docs/translucent.md`), 256 walks shared by the channels, each
    /// split in 16 once two patch sizes from its entry (in 4, the back-lit skin ball scored
    /// 0.098 in relative L1 over three seeds at 1000 patches, 0.075 in 16; the rest moved
    /// within ±0.003; the ball's precompute at 4000 patches 1.15× as long, the 20 k room's
    /// table, whose patches few walks outgrow, about as long), and 3072 late walks (against
    /// 384 unsplit walks before: the back-lit skin ball 0.141 → 0.112, the bunny's 0.160 →
    /// 0.152, the 20 k room's table built 30 % faster), the 17th scattering on (from the 9th
    /// the back-lit bunny's skin went 0.286 → 0.316).
    fn default() -> Self {
        Self {
            cosines: 4,
            azimuths: 8,
            walks: 256,
            late_walks: 3072,
            far_splits: 16,
            last_order: 16,
            // Skin's red halves in 16 scatterings, marble's (0.999) in ~700. Marble at 4000
            // patches, 32 → 64 with twice the late walks (`late_walks_for`), from behind: the
            // bunny 0.111 → 0.092 (the mean of three table seeds), the torus 0.0679 → 0.0578,
            // the ball 0.0667 → 0.0595; from the front the bunny 0.0579 → 0.0559, the ball
            // 0.0475 → 0.0491, the torus 0.0386 → 0.0416 (`docs/translucent.md`, "Marble
            // walks to 64 scatterings"). Skin at 32 took its ball from behind 0.094 → 0.122:
            // it stops at 16.
            max_last_order: 64,
            exit_directions: false,
            single_scattering_to_pixels: true,
            diffuse_columns_walked: true,
            seed: 0,
            // 3.3× the `translucent` example's room at a 20 000 budget (1224 translucent
            // patches, 17 MB): by its measured rate (41.5 s on 2 threads in release since
            // marble walks to 64 scatterings) about 140 s on 2 and, by the docs' 2 : 16 core
            // ratio, ~30 s on 16 (not measured), ~60 MB.
            max_patches: 4096,
        }
    }
}

impl BeamTableSettings {
    /// Directions a patch.
    pub fn bins(&self) -> u32 {
        self.cosines * self.azimuths
    }

    /// The scatterings a walk takes in `medium` before it leaves as late light: until half
    /// its light would be absorbed, `ln ½ / ln α` for the highest single-scattering albedo
    /// `α`, rounded and held within `last_order` – `max_last_order` (a medium that does not
    /// absorb takes the most).
    pub fn last_order_for(&self, medium: &super::medium::TranslucentMedium) -> u32 {
        let most = self.max_last_order.max(self.last_order);
        let albedo = medium.single_scattering_albedo().into_iter().fold(0.0f64, f64::max);
        if albedo >= 1.0 {
            return most;
        }
        // `as` saturates: a huge count takes `most`, and the −0 of no scattering (or a NaN)
        // the least.
        ((0.5f64.ln() / albedo.ln()).round() as u32).clamp(self.last_order, most)
    }

    /// Why these settings cannot build a table, if they cannot.
    pub fn invalid_reason(&self) -> Option<&'static str> {
        if !(1..=16).contains(&self.cosines) || !(1..=32).contains(&self.azimuths) {
            Some("a beam table takes 1 – 16 cosines and 1 – 32 azimuths")
        } else if self.walks == 0 || self.late_walks == 0 || self.last_order == 0 || self.far_splits == 0 {
            Some("a beam table needs at least one walk, late walk, scattering and far split")
        } else {
            None
        }
    }
}

/// How far apart [`BeamTableSettings::seed`]s put the walks' seeds (a prime above any
/// patch's directions' seeds, `patch · bins + bin`, at a budget's patches).
const SEED_STRIDE: u64 = 1_000_003;

/// Per tabled patch, the exitance its late light's diffuse walks leave through their last
/// order, per unit of light that got in ([`BeamTableSettings::diffuse_columns_walked`]):
/// with the table's late column (its share 1 for these walks' own remainder) the whole
/// response of the patch to diffuse light.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DiffuseColumns {
    /// Rows: the patch the light leaves by; columns: the entry patch's slot.
    pub early: SparseMatrix<Vec3>,
    /// Per slot, whether its walks were taken (an entry without a valid sample keeps `K`).
    pub walked: Vec<bool>,
}

impl DiffuseColumns {
    /// `K` with each walked tabled patch's column replaced by `(1 − F_dr)` (the diffuse
    /// Fresnel transmittance of its medium, as `K`'s columns hold) times its walks' early
    /// column plus its late column: exitance per unit irradiance, as `K`. Where no column
    /// was walked (the setting off), `K` as it was.
    pub fn scattering(&self, table: &BeamTable, profile: &SparseMatrix<Vec3>) -> SparseMatrix<Vec3> {
        if !self.walked.contains(&true) {
            return profile.clone();
        }
        let rows = profile.rows();
        let walked = |j: usize| table.slot(j).is_some_and(|s| self.walked.get(s as usize).copied().unwrap_or(false));
        let patch_of = table.slot_patches();
        let got_in: Vec<f32> = table
            .media
            .iter()
            .map(|m| (1.0 - super::diffusion::diffuse_fresnel_reflectance(m.w as f64)) as f32)
            .collect();
        let mut by_row: Vec<Vec<(u32, Vec3)>> = (0..rows)
            .map(|i| profile.row(i).filter(|&(j, _)| !walked(j)).map(|(j, v)| (j as u32, v)).collect())
            .collect();
        for matrix in [&self.early, &table.late] {
            for (i, row) in by_row.iter_mut().enumerate().take(matrix.rows()) {
                for (slot, v) in matrix.row(i) {
                    let j = patch_of[slot] as usize;
                    if walked(j) && v != Vec3::ZERO {
                        row.push((j as u32, v * got_in[slot]));
                    }
                }
            }
        }
        // A column's early and late entries on one row add up.
        for row in &mut by_row {
            row.sort_by_key(|e| e.0);
            row.dedup_by(|later, kept| {
                let same = later.0 == kept.0;
                if same {
                    kept.1 += later.1;
                }
                same
            });
        }
        SparseMatrix::from_rows(by_row)
    }
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
    /// leaving one way, ⅔ along the normal for Lambert's law) and what its walks weigh in
    /// the channel (`w`, their hero-channel weights summed: for the mean's noise).
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

impl BeamTable {
    /// Directions a patch.
    pub fn bins(&self) -> u32 {
        self.settings.bins()
    }

    /// Where a beam travelling along `travel` onto patch `j` goes in the table's light
    /// vector (`slot · bins + bin`, the four directions about it by their weights:
    /// [`direction_weights`]), and the share of it that gets in (`entering`); `None` for a
    /// patch without a table or a beam along or behind its surface.
    pub fn light_index(&self, patches: &Patches, j: usize, travel: Vec3) -> Option<([(usize, f32); 4], f32)> {
        let slot = self.slot(j)?;
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
        (0..self.slots.len()).map(|i| self.patch_medium(i).unwrap_or(Vec4::ZERO)).collect()
    }

    /// Patch `i`'s medium, `(α, η)`, where it has a table slot.
    pub fn patch_medium(&self, i: usize) -> Option<Vec4> {
        self.slot(i).and_then(|s| self.media.get(s as usize)).copied()
    }

    /// Patch `i`'s slot, where it has a table (`slots` holds `u32::MAX` elsewhere).
    pub fn slot(&self, i: usize) -> Option<u32> {
        self.slots.get(i).copied().filter(|&s| s != u32::MAX)
    }

    /// Direction `bin` of patch `j`'s column: the exitance per unit of irradiance that got
    /// in, by the patch it leaves through (early and late light summed; empty without a
    /// table).
    pub fn column(&self, j: usize, bin: u32) -> Vec<(usize, Vec3)> {
        let Some(slot) = self.slot(j) else {
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
