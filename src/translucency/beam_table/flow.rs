//! How a table's light flows in and leans as it leaves: each patch's axis of the light it
//! receives from elsewhere (the deep law's), and the lean of its light from afar (the exit
//! lobes'), fitted to the object's own walks.

use bevy::prelude::*;

use super::BeamTable;
use crate::translucency::patches::Patches;

/// How far, in patch sizes, light must have come to leave a patch by its exit lobe
/// ([`ExitLean`]): nearer light leaves in the patch's own limb-darkened law. 1 – 4 measured
/// (`docs/translucent.md`): the ball's skin lit from behind 0.175 / 0.178 / 0.190 / 0.199 in
/// relative L1, from the front 0.078 / 0.065 / 0.057 / 0.054; 2 keeps most of the gain from
/// behind with every front-lit case within 0.08.
pub const LOBE_SOURCE_DISTANCE: f32 = 2.0;

/// The least distance light must have come to leave by an exit lobe, in transport mean free
/// paths of the medium's most translucent channel: with small patches, light from two patch
/// sizes away has not yet forgotten where it entered, so it leaves as the patch's own law
/// says, not by the lobe fitted to light from afar (`docs/translucent.md`, "The exit lobes'
/// threshold in the medium's units").
pub const LOBE_SOURCE_MEAN_FREE_PATHS: f32 = 2.0;

/// How far light must have come to leave patch `i` by its exit lobe, world units: the larger
/// of [`LOBE_SOURCE_DISTANCE`] patch sizes and [`LOBE_SOURCE_MEAN_FREE_PATHS`] of its
/// medium's longest transport mean free path (`source_depths[i]`, per channel: one such path,
/// [`EnergyTransport::source_depths`](crate::translucency::transport::EnergyTransport::source_depths)).
pub fn lobe_source_distance(patches: &Patches, source_depths: &[Vec3], i: usize) -> f32 {
    let mean_free_path = source_depths.get(i).map_or(0.0, |d| d.max_element());
    (LOBE_SOURCE_DISTANCE * patches.size_of(i)).max(LOBE_SOURCE_MEAN_FREE_PATHS * mean_free_path)
}

/// Whether light from patch `j` reaches patch `i` from afar ([`lobe_source_distance`]).
pub fn from_afar(patches: &Patches, source_depths: &[Vec3], i: usize, j: usize) -> bool {
    let p = &patches.patches;
    p[i].surface_point.distance(p[j].surface_point) > lobe_source_distance(patches, source_depths, i)
}

/// The unit direction light travels from patch `j`'s diffusion source, `depth` under its
/// surface point, to patch `i`'s surface point (zero where they meet): what
/// [`BeamTable::flow`] and [`ExitLean`] measure a patch's light by.
pub(super) fn from_source(patches: &Patches, i: usize, j: usize, depth: f32) -> Vec3 {
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
/// ([`BeamTable::flow`], [`ExitLaw::set_far_lobes`](crate::translucency::transport::ExitLaw::set_far_lobes)):
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
pub(super) struct LeanSums {
    pub(super) along: Vec3,
    pub(super) walks: Vec3,
    pub(super) across: Vec3,
    pub(super) spread: Vec3,
}

impl LeanSums {
    pub(super) fn add(&mut self, other: &Self) {
        self.along += other.along;
        self.walks += other.walks;
        self.across += other.across;
        self.spread += other.spread;
    }

    pub(super) fn lean(&self) -> ExitLean {
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
    /// patches (what [`ExitLaw::set_flow`](crate::translucency::transport::ExitLaw::set_flow) takes).
    pub axis: [Vec3; 3],
    /// The table's early light from afar ([`from_afar`]).
    pub far: Vec3,
    /// Per channel, the same mean over that light alone (what [`ExitLean::mean`] takes).
    pub far_axis: [Vec3; 3],
}

impl BeamTable {
    /// Per patch, the way the light the table gives it flows in ([`TableFlow`]): per channel
    /// `Σ_j c_ij u_ij / Σ_j c_ij` over the other patches `j`, `c_ij` what `j`'s beams
    /// (`light`, as for [`apply`](Self::apply)) give patch `i` through the early and late
    /// columns, `u_ij` the unit direction to `i`'s surface point from `j`'s diffusion source
    /// (`source_depths[j]` under its surface point, per channel; what
    /// [`ExitLaw::flow`](crate::translucency::transport::ExitLaw::flow) takes about); and the same over the
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
                    let afar = early && from_afar(patches, source_depths, i, j);
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
}
