//! Seed 001's energy transport between patches: the scattering operator `K` (dipole transfer
//! inside each translucent object, albedo on opaque patches) and the form factors `F` between
//! all patches that see each other, both stored sparse (CSR); per frame, the direct irradiance
//! `E⁰` of the lights and the iteration of `B ← K E⁰ + K F B` (the seed's `L = (S F)^N S L`)
//! until the energy still moving falls below a threshold.
//!
//! Units: `E` irradiance and `B` exitance per patch, per RGB channel, in the lights' units per
//! world unit² (lux for Bevy's lights); the outgoing radiance of a patch is `B / π`.
//!
//! - **`F`**: `F_ij = V_ij cos θ_i cos θ_j A_j / (π r² + (A_i + A_j)/2)`, the disc
//!   approximation of the point-to-patch form factor (Wallace et al. 1989) with the two areas
//!   averaged, so that reciprocity `A_i F_ij = A_j F_ji` holds exactly and nearby patches stay
//!   bounded; `V_ij` one ray between the patches' centres (offset along their normals).
//!   Pairs whose larger `F` is below [`TransportSettings::form_factor_cutoff`] are dropped
//!   without a ray; [`TransportReport`] gives what that drops.
//! - **`K`** on translucent objects: flux `(1 − F_dr,ext) E_j A_j` enters at patch `j`; the
//!   share leaving through patch `i` is [`DiffusionProfile::patch_transfer`](super::diffusion::DiffusionProfile::patch_transfer), so
//!   `K_ij = (1 − F_dr,ext) P_ij A_j / A_i`, for pairs of the same object closer than the
//!   radius that holds [`TransportSettings::diffusion_energy_kept`] of the profile's energy.
//!   On opaque patches `K_ii = albedo`.
//!
//! The two stages of the build are `form_factors.rs` (`F`, with the kernels and far-field
//! clusters of `far_field.rs`) and `scattering.rs` (`K`: the profiles, the shape's solve, the
//! object's walks, the columns' totals); the per-frame solve, cold or warm, is `solve.rs`; the
//! lights' direct part, re-exported here, is in `lights.rs`.

mod form_factors;
mod scattering;
#[cfg(test)]
pub(crate) use scattering::drop_lightest_of_columns;
mod solve;

pub use solve::{
    MAX_TAIL_RATIO, TransportSolution, WARM_MAX_ITERATIONS, WARM_THRESHOLD_SHARE, geometric_tail,
    settle_frames, warm_iterations,
};

use std::time::Instant;

pub use super::lights::{DirectLight, PatchLight, ReachingLights, direct_irradiance, direct_light, lights_reaching};
use super::{
    diffusion::DiffusionKernel,
    beam_table::{ExitLean, TableFlow, from_afar},
    exit_lobe::{ExitLobe, LobeFits},
    medium::TranslucentMedium,
    patches::Patches,
};
pub use super::{rays::SceneRays, sparse::SparseMatrix};
use bevy::prelude::*;

/// What an object's surface does with the light that reaches it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PatchSurface {
    /// Light enters and diffuses through the object's medium.
    Translucent {
        /// The medium.
        medium: TranslucentMedium,
        /// World units per millimetre (0.001 for a scene in metres).
        world_units_per_mm: f32,
        /// Take the dipole's flux along the exit patch's own normal
        /// ([`Translucent::oriented_dipole`](super::plugin::Translucent::oriented_dipole)).
        oriented_dipole: bool,
    },
    /// Lambertian, with this albedo per channel (0–1).
    Opaque {
        /// Diffuse albedo per channel.
        albedo: Vec3,
    },
}

/// How a patch's light leaves it, for the gather: the light a translucent patch received
/// from elsewhere leaves in the deep field's limb-darkened law
/// ([`deep_exit_law`](super::diffusion::deep_exit_law)), what its own direct light gives back
/// in Lambert's. The default (all zero) is Lambert's: opaque patches.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ExitLaw {
    /// What a unit irradiance on the patch gives back in all, per channel (its column of `K`
    /// summed over the exit areas): its own direct light accounts for this times `E⁰` of its
    /// exitance.
    pub local_albedo: Vec3,
    /// Per channel, [`deep_exit_law`](super::diffusion::deep_exit_law):
    /// `(α, ν, 1/N, g)`.
    pub channels: [Vec4; 3],
    /// The boundary's index of refraction (1: index-matched).
    pub eta: f32,
    /// Per channel, the axis the deep field's light flows along (`xyz`: its unit direction
    /// times how much of the light from elsewhere flows one way, 0 – 1) and `1/N` of the law
    /// about it (`w`, [`deep_exit_norm_about`](super::diffusion::deep_exit_norm_about)); all
    /// zero (the default): about the patch's normal, [`deep_exit_law`](super::diffusion::deep_exit_law)'s.
    pub flow: [Vec4; 3],
    /// Per channel, the lobe the light from afar leaves by, fitted to the mean direction it
    /// leaves along ([`ExitLaw::set_far_lobes`], or for the CPU oracle all of its light:
    /// [`ExitLaw::set_leaving`]); a zero `norm` (the default): none, the laws above.
    pub lobes: [ExitLobe; 3],
    /// How much of the patch's exitance leaves by [`lobes`](Self::lobes), per channel; the
    /// rest leaves in the laws above.
    pub lobe_exitance: Vec3,
    /// With a beam table and [`TransportSettings::exit_lobes`], how the patch's object's light
    /// from afar leans as it leaves (what [`set_far_lobes`](Self::set_far_lobes) takes);
    /// zero: no lobes.
    pub lean: ExitLean,
    /// Per channel, the weight of the diffusion field's flux along the surface in the exit
    /// radiance ([`tangential_flux_weight`](super::diffusion::tangential_flux_weight), world
    /// units; [`TransportSettings::tangential_flux`]): the gather leans the light that leaves
    /// by the laws above (not by [`lobes`](Self::lobes)) down the exitance's gradient. Zero:
    /// none.
    pub tangential: Vec3,
}

impl ExitLaw {
    /// The exit radiance over the Lambertian `B/π` at exit cosine `mu`, per channel, for
    /// exitance `b` and irradiance `e0`: `1 + D (s(μ) − 1)`, with
    /// `D = g · clamp(1 − A E/B, 0, 1)` the share of `B` that came from elsewhere in the deep
    /// field's mode (the same arithmetic as `gathered.wgsl`). The gather passes the patch's
    /// irradiance direct and bounced: light bounced onto a patch enters as its direct light
    /// does, and leaves about where it entered.
    pub fn factor(&self, b: Vec3, e0: Vec3, mu: f32) -> Vec3 {
        Vec3::from_array(std::array::from_fn(|c| {
            self.channel_factor(c, b[c], e0[c], |law| super::diffusion::deep_exit_shape(law, self.eta, mu))
        }))
    }

    /// One channel's `1 + D (s − 1)` for exitance `b` and direct irradiance `e0`, `s` the
    /// law's shape from `shape` (not evaluated where the channel is Lambert's or nothing
    /// leaves).
    fn channel_factor(&self, c: usize, b: f32, e0: f32, shape: impl FnOnce([f32; 4]) -> f32) -> f32 {
        let law = self.channels[c].to_array();
        if law[3] <= 0.0 || b <= 0.0 {
            return 1.0;
        }
        let deep = law[3] * (1.0 - self.local_albedo[c] * e0 / b).clamp(0.0, 1.0);
        1.0 + deep * (shape(law) - 1.0)
    }

    /// Takes the deep field's law about `flow` (per channel, as [`BeamTable::flow`](super::beam_table::BeamTable::flow)
    /// gives it) for a patch of unit `normal`: each channel's axis and the normalisation that
    /// keeps its exitance ([`deep_exit_norm_about`](super::diffusion::deep_exit_norm_about)).
    /// Lambert's channels (`g` = 0) and a zero flow keep the normal's law.
    pub fn set_flow(&mut self, normal: Vec3, flow: [Vec3; 3]) {
        let eta = self.eta;
        self.flow = std::array::from_fn(|c| {
            let (law, axis) = (self.channels[c].to_array(), flow[c]);
            if law[3] > 0.0 && axis != Vec3::ZERO {
                let along = axis.dot(normal);
                let across = (axis - normal * along).length();
                axis.extend(super::diffusion::deep_exit_norm_about(law, eta, along, across))
            } else {
                Vec4::ZERO
            }
        });
    }

    /// Gives each channel's light out by the lobe fitted to `mean`, the exitance-weighted
    /// mean direction it leaves along ([`LobeFits::lobe`]) from a patch of unit `normal`.
    pub fn set_leaving(&mut self, normal: Vec3, mean: [Vec3; 3], exitance: Vec3) {
        let fits = LobeFits::get();
        self.lobes = mean.map(|m| fits.lobe(normal, m));
        self.lobe_exitance = exitance;
    }

    /// Gives the light from afar of a patch of unit `normal` out by lobes: `flow`'s
    /// [`far`](TableFlow::far) light, each channel by the lobe fitted to the mean its
    /// [`lean`](Self::lean) gives for the directions it came from
    /// ([`ExitLean::mean`] of [`far_axis`](TableFlow::far_axis)). No lobes without a lean.
    pub fn set_far_lobes(&mut self, normal: Vec3, flow: &TableFlow) {
        if self.lean == ExitLean::default() {
            return;
        }
        let fits = LobeFits::get();
        self.lobes = std::array::from_fn(|c| {
            if flow.far[c] > 0.0 {
                fits.lobe(normal, self.lean.mean(c, normal, flow.far_axis[c]))
            } else {
                ExitLobe::default()
            }
        });
        self.lobe_exitance = flow.far;
    }

    /// The exitance-weighted mean direction light leaves a patch of unit `normal` along in
    /// this law, per channel (a 16 × 32 rule).
    pub fn mean_leaving(&self, b: Vec3, e0: Vec3, normal: Vec3) -> [Vec3; 3] {
        let (t, s) = normal.any_orthonormal_pair();
        let (mut sum, mut weight) = ([Vec3::ZERO; 3], Vec3::ZERO);
        for w in super::diffusion::cosine_weighted_directions(16, 32) {
            let towards = w.x * t + w.y * s + w.z * normal;
            let f = self.factor_towards(b, e0, normal, towards);
            for c in 0..3 {
                sum[c] += f[c] * towards;
            }
            weight += f;
        }
        std::array::from_fn(|c| if weight[c] > 0.0 { sum[c] / weight[c] } else { normal * (2.0 / 3.0) })
    }

    /// [`factor`](Self::factor) towards the unit `towards` from a point of unit normal `n`,
    /// the deep field's mode about each channel's [`flow`](Self::flow) axis where it has one.
    /// The share `lobe_exitance / B` of the exitance leaving by its lobe leaves by it, the
    /// rest by the law above as if it were all there were (`exit_factor` in `gathered.wgsl`).
    pub fn factor_towards(&self, b: Vec3, e0: Vec3, n: Vec3, towards: Vec3) -> Vec3 {
        self.factor_towards_parts(b, e0, n, towards).0
    }

    /// [`factor_towards`](Self::factor_towards), and of it the part that leaves by the laws
    /// about the normal or the flow, not by the lobes: what the flux along the surface leans
    /// ([`tangential`](Self::tangential); the lobes lean already, fitted to the walks' own
    /// exits).
    pub fn factor_towards_parts(&self, b: Vec3, e0: Vec3, n: Vec3, towards: Vec3) -> (Vec3, Vec3) {
        let parts: [(f32, f32); 3] = std::array::from_fn(|c| {
            let lobe = self.lobes[c];
            let share = if lobe.norm > 0.0 && b[c] > 0.0 {
                (self.lobe_exitance[c] / b[c]).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let flow = self.flow[c];
            let own = self.channel_factor(c, b[c] * (1.0 - share), e0[c], |law| {
                if flow == Vec4::ZERO {
                    super::diffusion::deep_exit_shape(law, self.eta, n.dot(towards))
                } else {
                    super::diffusion::deep_exit_shape_about(law, self.eta, n, flow.truncate(), towards) * flow.w
                }
            });
            (share * lobe.factor(towards) + (1.0 - share) * own, (1.0 - share) * own)
        });
        (Vec3::from_array(parts.map(|p| p.0)), Vec3::from_array(parts.map(|p| p.1)))
    }
}

/// The most [`TransportSettings::shape_energy_dropped`] takes: beyond it a back-lit object
/// loses the light crossing it (`docs/translucent.md`).
pub const MAX_SHAPE_ENERGY_DROPPED: f32 = 0.01;

/// How the transport is built.
#[derive(Clone, Copy, Debug, PartialEq, Reflect)]
pub struct TransportSettings {
    /// The diffusion profile.
    pub kernel: DiffusionKernel,
    /// The share of each profile's energy its sparse rows keep (0.9 – 1): pairs of patches
    /// further apart than the radius holding it are dropped.
    pub diffusion_energy_kept: f32,
    /// Form factors below this (before visibility) are dropped, 0 – 0.01.
    pub form_factor_cutoff: f32,
    /// Width of a far-field cluster in patches (≥ 2; 0 or 1: every link is patch to patch).
    pub cluster_size: u32,
    /// A cluster further than this many times its radius is linked as one (≥ 1).
    pub far_field_ratio: f32,
    /// Scale each translucent object's columns from the semi-infinite slab's total `W∞` by
    /// what random walks find leaves the object's own shape over what leaves a slab
    /// (`random_walk`; 3 × 4096 walks an object at build time: +0.03–0.2 s for a 1 cm ball,
    /// twice behind a dielectric boundary: there the slab is index-matched, as Chiang et al.'s
    /// `A` is, so the walks also carry the boundary's internal reflection — a skin ball at
    /// η 1.3 in uniform light was 1.3–1.7× too bright without).
    /// On by default: a 1 cm skin ball gives off 1.19× / 1.13× / 1.10× a slab's share, and
    /// against a light-traced reference the walks take skin from 0.137 to 0.076 and marble
    /// from 0.073 to 0.045 in relative L1 (`docs/translucent.md`).
    pub object_exit_share: bool,
    /// Weight the direct light on translucent patches by how much a beam at its own
    /// incidence takes in and gives back ([`IncidenceWeight`](super::diffusion::IncidenceWeight):
    /// Chandrasekhar's plane albedo, up to 1.9× at grazing incidence against normal) instead of
    /// the diffuse albedo `K` holds for every light. On by default: against a light-traced
    /// reference it takes a 1 cm skin ball lit from the side from 0.112 to 0.076 in relative
    /// L1 and marble from 0.053 to 0.045 (`docs/translucent.md`). Per frame only; the
    /// transport is the same. Used with the kernels that carry Chiang et al.'s albedo (the dipole keeps its own
    /// single-scattering term for a beam's incidence).
    pub beam_incidence: bool,
    /// Solve the diffusion in each translucent object's own shape
    /// ([`shape_diffusion`](super::shape_diffusion): the oriented dipole of each entry patch
    /// plus a boundary-element correction for the light its surface lets out on the way)
    /// instead of taking the flat profile between every pair of patches. Columns keep their
    /// totals (the slab's, times the object's walks); only where the light leaves moves. One
    /// dense system per object and channel, `O(N³)` (1.4 s at 960 patches on 2 cores): an
    /// object of more than [`MAX_SHAPE_PATCHES`](super::shape_diffusion::MAX_SHAPE_PATCHES)
    /// patches has its correction solved on as many clusters of them
    /// ([`ShapeClusters`](super::shape_diffusion::ShapeClusters); it used to keep the flat
    /// profile, and a back-lit marble ball of 3680 patches scored 0.315 instead of 0.077).
    /// On by default: lit from behind, a 1 cm skin ball goes from 0.612 to 0.420 in relative
    /// L1 against a light-traced reference, marble from 0.277 to 0.153 (with
    /// [`deep_exit_law`](Self::deep_exit_law) 0.431 and 0.078); from the front both stay
    /// within 0.002 (`docs/translucent.md`).
    pub shape_diffusion: bool,
    /// Solved in its shape, an object has every pair of its patches (the correction has no
    /// radius: `O(N²)`); each of its columns drops its lightest entries while they hold at
    /// most this share of the column's energy, in every channel (0 – 0.01; 0: all kept). The
    /// columns keep their totals. 1e-6 by default: the `translucent` example's room at a
    /// 20 k budget keeps 579 k of its 789 k entries of `K` (61.2 → 57.0 MB), a 1 cm marble
    /// ball lit from behind moves by 0.0002 in relative L1 at 3680 patches and not at all at
    /// 960; at 1e-5 the room kept 451 k and that ball lost 0.002, at 1e-3 (the flat profile's
    /// tail) 159 k and the light crossing the ball at 960 patches (0.061 → 0.162;
    /// `docs/translucent.md`).
    pub shape_energy_dropped: f32,
    /// Let the light a translucent patch received from elsewhere leave it in the deep field's
    /// limb-darkened law ([`ExitLaw`], [`deep_exit_law`](super::diffusion::deep_exit_law))
    /// instead of Lambert's: light that crossed an object comes out brighter facing the
    /// camera and dimmer at grazing angles. On by default: a back-lit 1 cm marble ball goes
    /// from 0.15 to 0.08 in relative L1 against a light-traced reference (its Lambertian
    /// picture was 0.86× the reference's at the centre and 1.33× at the rim); from the front
    /// both media move by less than 0.003; behind the presets' η 1.3 (the boundary's Fresnel
    /// and internal reflection shape the law) marble lit from behind goes from 0.088 to 0.083
    /// and skin from the front from 0.076 to 0.074 (`docs/translucent.md`). Per frame only
    /// (the gather); the transport is the same.
    pub deep_exit_law: bool,
    /// Carry each light's beam into translucent patches by a per-patch table of beam columns
    /// from random walks ([`BeamTable`](super::beam_table::BeamTable)) instead of `K`, and
    /// give single scattering by the lit face in its own law per pixel (`None`: the
    /// diffusion profile's `K` alone). On by default: against path-traced references every
    /// front-lit case comes within 0.08 in relative L1 with it and not without (the Stanford
    /// bunny's skin 0.160 → 0.059–0.064 over three table seeds, marble 0.089 → 0.072–0.076;
    /// lit from behind a 1 cm skin ball 0.431 → 0.132–0.154; `docs/translucent.md`). Its
    /// price: ~0.05 s a translucent patch on one core in release to build (the `translucent`
    /// example's room at a 20 000 budget, 1224 translucent patches: 8.7 s with the rest of
    /// the precompute on 16 cores, the table alone 29.7 s on 2; 18 MB), in the background
    /// (cached on disk with [`cache_dir`](super::TranslucencySettings::cache_dir)); and per frame on an
    /// H100 0.06 ms with the lights still, 0.1–0.2 ms with a light moving (the room at
    /// 1920×1080). Scenes of more than [`max_patches`](super::beam_table::BeamTableSettings::max_patches)
    /// translucent patches keep the profile, with a warning.
    pub beam_table: Option<super::beam_table::BeamTableSettings>,
    /// With a beam table, give the light a translucent patch receives from farther than
    /// [`lobe_source_distance`](super::beam_table::lobe_source_distance) out
    /// by a lobe leaning the way it travelled ([`ExitLean`], fitted to the table's own walks)
    /// instead of the deep law: light that crossed an object leaves leaning the way it was
    /// going. On by default (per frame; the table's build is the same): lit from behind, a
    /// 1 cm skin ball goes from 0.264 to 0.147 in relative L1 against a light-traced
    /// reference, the Stanford bunny's skin from 0.264 to 0.236, and from the front the
    /// bunny's skin from 0.074 to 0.072, the ball's from 0.051 to 0.057
    /// (`docs/translucent.md`). Without a beam table it does nothing: the profile's light
    /// from afar is mostly late light, which the lean does not describe (a back-lit marble
    /// ball went from 0.078 to 0.53).
    pub exit_lobes: bool,
    /// With a beam table, let all the light a translucent patch received from elsewhere leave
    /// it by the deep law about the way that light flows in
    /// ([`ExitLaw::set_flow`]), not only the share `g = 1 − √(3(1 − α))` that
    /// [`deep_exit_law`](super::diffusion::deep_exit_law) puts in the diffusion mode (the rest
    /// by Lambert's law). The share was chosen for light from deep inside; the table's light
    /// from elsewhere came after a few scatterings and leans the way it travelled, further from
    /// Lambert's law than the mode (skin's blue, `g` 0.02, left almost all of it by Lambert's).
    /// On by default (per frame; the table's build is the same): lit from behind, a 1 cm skin
    /// ball goes from 0.104 to 0.098 in relative L1 against a light-traced reference at 960
    /// patches and from 0.110 to 0.098 at 3680 (three seeds' means), behind a dielectric
    /// boundary (η 1.3) from 0.111 to 0.101; at 960 patches no case of the suite gets worse by
    /// more than 0.001, at 3680 the bunny's skin from behind by 0.002 (`docs/translucent.md`).
    /// Without a beam table it does nothing: the normal's law with all the light was 0.28
    /// from behind.
    pub flow_law_takes_all: bool,
    /// With a beam table and [`deep_exit_law`](Self::deep_exit_law), lean the light a
    /// translucent pixel shows down the exitance's gradient along the surface: the diffusion
    /// field's flux along the surface in P1
    /// ([`tangential_flux_weight`](super::diffusion::tangential_flux_weight),
    /// [`ExitLaw::tangential`]; the gradient a plane fitted to the exitance of the patches the
    /// gather takes about the pixel). Light that crossed an object lit from behind flows along
    /// its surface at the silhouette and leaves towards the camera. Only in a channel whose
    /// flow's law hardly leans ([`tangential_flux_mode_weight`](super::diffusion::tangential_flux_mode_weight):
    /// the mode's decay `ν` at most 0.1 takes all of it, 0.3 and more none): marble, milk, not
    /// skin, whose light already leans by its flow's law and the exit lobes (with the whole
    /// term the skin ball from behind went 0.072 → 0.078 at 4000 patches). On by default
    /// since 2026-12-07 (per frame; the transport is the same): against light-traced
    /// references at 4000 patches, marble lit from behind 0.087 → 0.079 in relative L1 on the
    /// Stanford bunny, a torus 0.058 → 0.051, a 1 cm ball 0.060 → 0.061; from the front within
    /// ±0.002; skin exactly as without it (`docs/translucent.md`, "The flux along the surface
    /// by default").
    pub tangential_flux: bool,
}

impl Default for TransportSettings {
    /// 99.9 % of the profile (the tail beyond holds 0.1 %: lit from behind, the light that
    /// crosses a 2 cm marble ball — 0.55 → 0.28 relative L1 against 99 %, for 1.8× the ball's
    /// memory, +3 % in the test room's); form factors down to 1e-5 (a
    /// patch of 1/1000 of a room's wall area seen face-on from 5 wall widths away); clusters
    /// 4 patches wide linked as one beyond 3 radii; each object's own random walks and each
    /// beam's incidence, a beam table, its exit lobes and the flux along the surface where the
    /// flow's law does not lean (all measured closer to light-traced references; see
    /// `docs/translucent.md` for what each costs and changes).
    fn default() -> Self {
        Self {
            kernel: DiffusionKernel::ScaledDipole,
            diffusion_energy_kept: 0.999,
            form_factor_cutoff: 1e-5,
            cluster_size: 4,
            far_field_ratio: 3.0,
            object_exit_share: true,
            beam_incidence: true,
            shape_diffusion: true,
            shape_energy_dropped: 1e-6,
            deep_exit_law: true,
            beam_table: Some(super::beam_table::BeamTableSettings::default()),
            exit_lobes: true,
            flow_law_takes_all: true,
            tangential_flux: true,
        }
    }
}

impl TransportSettings {
    /// The settings that act only on what a scene derives from its built transport — each
    /// patch's exit law ([`EnergyTransport::exit_laws`]) and each object's incidence weight
    /// ([`EnergyTransport::incidence_weights`]) — not on `K`, `F` or the beam table: the
    /// plugin derives those again when these change, without a precompute.
    pub fn derived(&self) -> [bool; 5] {
        [self.deep_exit_law, self.exit_lobes, self.flow_law_takes_all, self.tangential_flux, self.beam_incidence]
    }

    /// `self` with [`derived`](Self::derived)'s settings taken from `other`.
    pub fn with_derived_from(self, other: &Self) -> Self {
        Self {
            deep_exit_law: other.deep_exit_law,
            exit_lobes: other.exit_lobes,
            flow_law_takes_all: other.flow_law_takes_all,
            tangential_flux: other.tangential_flux,
            beam_incidence: other.beam_incidence,
            ..self
        }
    }
}

/// What building the transport kept and dropped, and what it cost.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TransportReport {
    /// Entries of `F`.
    pub form_factor_entries: usize,
    /// Far-field clusters (0 without clustering).
    pub clusters: usize,
    /// Entries of `K`.
    pub scattering_entries: usize,
    /// Visibility rays cast.
    pub rays: usize,
    /// Mean over patches of the form-factor sum dropped by the cut-off (before visibility:
    /// an upper bound).
    pub dropped_form_factor_mean: f32,
    /// Largest such sum.
    pub dropped_form_factor_max: f32,
    /// Mean over translucent patches of the profile energy their column of `K` carried before
    /// it was rescaled to the semi-infinite slab's, relative to it, per channel (below 1:
    /// the cut-off and the object's finite extent; above: overlapping patch discs).
    pub diffusion_kept_mean: Vec3,
    /// Mean over translucent patches of what their object gives off in all (the columns'
    /// total: random walks in its shape, or the slab's), relative to the slab's `W∞`, per
    /// channel (above 1: an object a few diffusion lengths across).
    pub object_exit_over_slab_mean: Vec3,
    /// Translucent objects whose diffusion was solved in their shape
    /// ([`TransportSettings::shape_diffusion`]).
    pub shape_solved_objects: usize,
    /// Of those, the objects of more than
    /// [`MAX_SHAPE_PATCHES`](super::shape_diffusion::MAX_SHAPE_PATCHES) patches, whose
    /// correction was solved on clusters of their patches
    /// ([`ShapeClusters`](super::shape_diffusion::ShapeClusters)).
    pub shape_clustered_objects: usize,
    /// Entries of the beam table (early and late columns; 0 without one).
    pub beam_table_entries: usize,
    /// The scene's translucent patches where a beam table was asked for but not built, since
    /// they were more than [`BeamTableSettings::max_patches`](super::beam_table::BeamTableSettings::max_patches)
    /// (0: built, or none asked for).
    pub beam_table_skipped: usize,
    /// Wall-clock seconds to build.
    pub seconds: f32,
}

/// The precomputed transport of one static scene.
#[derive(Clone, Debug, Default)]
pub struct EnergyTransport {
    /// `K`: exitance from entering irradiance (per channel).
    pub scattering: SparseMatrix<Vec3>,
    /// `F`: irradiance at `i` from exitance at `j`; columns `n..` are clusters' area-mean
    /// exitances (the far field).
    pub form_factors: SparseMatrix<f32>,
    /// Row `c`: cluster `c`'s members with their share of its area (`A_j / A_c`).
    pub cluster_means: SparseMatrix<f32>,
    /// Per patch, `(1 − F_dr,ext) α/2` of its medium (zero on opaque patches): times
    /// [`single_scattering_shape`](super::diffusion::single_scattering_shape) of a beam's
    /// incidence, the single-scattered exitance per unit irradiance.
    pub single_scattering: Vec<Vec3>,
    /// Patch areas (for energies).
    pub areas: Vec<f32>,
    /// Per object, the weight of a beam's incidence on a translucent surface (`None`: opaque,
    /// the dipole kernel, or [`TransportSettings::beam_incidence`] off); see
    /// [`EnergyTransport::incidence_weights`]. Not kept in the cache: set again on load.
    pub incidence: Vec<Option<super::diffusion::IncidenceWeight>>,
    /// What was kept and dropped.
    pub report: TransportReport,
    /// The translucent patches' beam table ([`TransportSettings::beam_table`]).
    pub beam_table: Option<super::beam_table::BeamTable>,
}

fn threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// Each patch's albedo: its object's on opaque patches, zero on translucent ones (all their
/// light is the transport's; the gather and the ambient light tell them apart by it).
pub fn patch_albedos(patches: &Patches, surfaces: &[PatchSurface]) -> Vec<Vec3> {
    patches
        .patches
        .iter()
        .map(|p| match surfaces.get(p.object as usize) {
            Some(PatchSurface::Opaque { albedo }) => *albedo,
            _ => Vec3::ZERO,
        })
        .collect()
}

/// Runs `f(i)` for `0..n` on every core, each core taking the next row as it finishes one
/// (rows of one patch or object differ in cost by orders of magnitude: a wall's form factors
/// against a translucent patch's beam walks); results in order, whichever core made them.
pub(super) fn parallel_rows<R: Send>(n: usize, f: impl Fn(usize) -> R + Sync) -> Vec<R> {
    let t = threads().min(n.max(1));
    // Rows taken a few at a time where there are many (cheap rows, one counter), one at a
    // time where there are few.
    let chunk = (n / (t * 64)).max(1);
    let next = std::sync::atomic::AtomicUsize::new(0);
    let mut parts: Vec<Vec<(usize, R)>> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..t)
            .map(|_| {
                let (f, next) = (&f, &next);
                scope.spawn(move || {
                    let mut done = Vec::new();
                    loop {
                        let first = next.fetch_add(chunk, std::sync::atomic::Ordering::Relaxed);
                        if first >= n {
                            return done;
                        }
                        done.extend((first..(first + chunk).min(n)).map(|i| (i, f(i))));
                    }
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("transport worker panicked"))
            .collect()
    });
    let mut out: Vec<Option<R>> = (0..n).map(|_| None).collect();
    for part in parts.iter_mut() {
        for (i, r) in part.drain(..) {
            out[i] = Some(r);
        }
    }
    out.into_iter()
        .map(|r| r.expect("every row computed"))
        .collect()
}

impl EnergyTransport {
    /// Builds `K` and `F` for `patches`; `surfaces[o]` is object `o`'s surface.
    pub fn build(
        patches: &Patches,
        surfaces: &[PatchSurface],
        rays: &SceneRays,
        settings: &TransportSettings,
    ) -> Self {
        let start = Instant::now();
        let n = patches.patches.len();
        let f = form_factors::build(patches, rays, settings);
        let k = scattering::build(patches, surfaces, rays, settings);
        // The patches the table would walk.
        let translucent = patches
            .patches
            .iter()
            .filter(|q| super::beam_table::build::tabled_medium(surfaces, q.object).is_some())
            .count();
        let too_many = settings.beam_table.filter(|t| translucent > t.max_patches as usize).map(|_| translucent);
        let (beam_table, scattering) = match settings.beam_table.filter(|_| too_many.is_none()) {
            Some(table) => {
                let (table, diffuse) =
                    super::beam_table::BeamTable::build_walked(patches, surfaces, rays, &k.matrix, table, None);
                // Diffuse light entering a tabled patch leaves by its walks, not the profile
                // (`K` unchanged with `diffuse_columns_walked` off).
                let scattering = diffuse.scattering(&table, &k.matrix);
                (Some(table), scattering)
            }
            None => (None, k.matrix),
        };
        let report = TransportReport {
            form_factor_entries: f.matrix.entries(),
            clusters: f.cluster_means.rows(),
            scattering_entries: scattering.entries(),
            rays: f.rays_cast,
            dropped_form_factor_mean: f.dropped.iter().sum::<f32>() / n.max(1) as f32,
            dropped_form_factor_max: f.dropped.iter().copied().fold(0.0, f32::max),
            diffusion_kept_mean: k.diffusion_kept_mean,
            object_exit_over_slab_mean: k.object_exit_over_slab_mean,
            shape_solved_objects: k.shape_solved_objects,
            shape_clustered_objects: k.shape_clustered_objects,
            beam_table_entries: beam_table
                .as_ref()
                .map_or(0, |t| t.early.entries() + t.late.entries()),
            beam_table_skipped: too_many.unwrap_or(0),
            seconds: start.elapsed().as_secs_f32(),
        };
        Self {
            scattering,
            form_factors: f.matrix,
            cluster_means: f.cluster_means,
            single_scattering: k.single_scattering,
            areas: patches.patches.iter().map(|q| q.area).collect(),
            incidence: Self::incidence_weights(surfaces, settings),
            report,
            beam_table,
        }
    }

    /// Per object, the [`IncidenceWeight`](super::diffusion::IncidenceWeight) of its medium
    /// where it applies: translucent, valid, a kernel carrying Chiang et al.'s `A` (the diffuse
    /// albedo; the dipole keeps its own single-scattering term for a beam's incidence), and
    /// [`TransportSettings::beam_incidence`] on.
    pub fn incidence_weights(
        surfaces: &[PatchSurface],
        settings: &TransportSettings,
    ) -> Vec<Option<super::diffusion::IncidenceWeight>> {
        surfaces
            .iter()
            .map(|s| match *s {
                PatchSurface::Translucent { medium, .. }
                    if settings.beam_incidence
                        && settings.kernel != DiffusionKernel::Dipole
                        && medium.invalid_reason().is_none() =>
                {
                    Some(super::diffusion::IncidenceWeight::new(
                        medium.single_scattering_albedo(),
                        medium.index_of_refraction as f64,
                    ))
                }
                _ => None,
            })
            .collect()
    }

    /// Each patch's [`ExitLaw`]: on translucent patches of a valid medium with
    /// [`TransportSettings::deep_exit_law`] on, its column of `K` summed over the exit areas
    /// (what a unit irradiance on it gives back in all) and its medium's
    /// [`deep_exit_law`](super::diffusion::deep_exit_law) per channel; Lambert's elsewhere.
    pub fn exit_laws(
        &self,
        patches: &Patches,
        surfaces: &[PatchSurface],
        settings: &TransportSettings,
    ) -> Vec<ExitLaw> {
        let p = &patches.patches;
        let column_totals = self.scattering.weighted_column_sums(&self.areas, p.len());
        // With the exit lobes, each tabled patch takes its object's lean.
        let lean_table = self.beam_table.as_ref().filter(|_| settings.exit_lobes);
        // With a table, all the light from elsewhere in the law about its flow (`g` = 1).
        let flow_takes_all = settings.flow_law_takes_all && self.beam_table.is_some();
        // The law is the medium's: once per object, not per patch.
        let laws: Vec<Option<([Vec4; 3], f32, Vec3)>> = surfaces
            .iter()
            .map(|s| match s {
                PatchSurface::Translucent { medium, world_units_per_mm, .. }
                    if settings.deep_exit_law && medium.invalid_reason().is_none() =>
                {
                    let eta = medium.index_of_refraction;
                    let albedo = medium.single_scattering_albedo();
                    let channels = albedo.map(|a| {
                        let law = Vec4::from_array(super::diffusion::deep_exit_law(a, eta as f64));
                        if flow_takes_all { law.with_w(1.0) } else { law }
                    });
                    let extinction = medium.reduced_scattering + medium.absorption;
                    let tangential = if settings.tangential_flux && self.beam_table.is_some() {
                        Vec3::from_array(std::array::from_fn(|c| {
                            super::diffusion::tangential_flux_weight(
                                albedo[c],
                                extinction[c] as f64,
                                eta as f64,
                                *world_units_per_mm as f64,
                            )
                        }))
                    } else {
                        Vec3::ZERO
                    };
                    Some((channels, eta, tangential))
                }
                _ => None,
            })
            .collect();
        p.iter()
            .zip(&column_totals)
            .map(|(q, total)| match laws.get(q.object as usize) {
                Some(&Some((channels, eta, tangential))) if q.area > 0.0 => ExitLaw {
                    local_albedo: *total / q.area,
                    channels,
                    eta,
                    tangential,
                    ..Default::default()
                },
                _ => ExitLaw::default(),
            })
            .enumerate()
            .map(|(i, mut law)| {
                if let Some(table) = lean_table
                    && let Some(&slot) = table.slots.get(i)
                {
                    law.lean = table.exit_lean.get(slot as usize).copied().unwrap_or_default();
                }
                law
            })
            .collect()
    }

    /// `exit_laws` as the plugin's gather takes them for `direct`: with a beam table, each
    /// patch's deep law about the way the table's light flows into it
    /// ([`BeamTable::flow`](super::beam_table::BeamTable::flow) of `direct.beam_light` from
    /// `source_depths`, [`ExitLaw::set_flow`]; what `table_rows` in `iterate.wgsl` gives the
    /// GPU's gather); unchanged without a table.
    pub fn exit_laws_along_flow(
        &self,
        patches: &Patches,
        exit_laws: &[ExitLaw],
        direct: &DirectLight,
        source_depths: &[Vec3],
    ) -> Vec<ExitLaw> {
        let mut laws = exit_laws.to_vec();
        if let Some(table) = &self.beam_table {
            let flows = table.flow(patches, &direct.beam_light, source_depths);
            for ((law, flow), q) in laws.iter_mut().zip(flows).zip(&patches.patches) {
                law.set_flow(q.normal, flow.axis);
                law.set_far_lobes(q.normal, &flow);
            }
        }
        laws
    }

    /// `exit_laws` with each tabled patch's light given out by the lobe fitted to the mean
    /// direction it leaves along ([`ExitLaw::set_leaving`]; needs
    /// [`BeamTableSettings::exit_directions`](super::beam_table::BeamTableSettings::exit_directions)):
    /// the table's early light from patches farther than
    /// [`lobe_source_distance`](super::beam_table::lobe_source_distance) (`source_depths`)
    /// along its walks' own directions
    /// ([`BeamTable::early_moments`](super::beam_table::BeamTable::early_moments) of
    /// `direct.beam_light`), the mean's length taken back by its noise (`E|m̂|² = R² + v(1 −
    /// R²)`); the rest of `exitance` (nearer light, the late light, the bounces) in the mean
    /// of the patch's own law ([`ExitLaw::mean_leaving`]). Unchanged without a table or its
    /// directions. An oracle of the CPU path: `docs/translucent.md`.
    pub fn exit_laws_along_lobes(
        &self,
        patches: &Patches,
        exit_laws: &[ExitLaw],
        direct: &DirectLight,
        exitance: &[Vec3],
        source_depths: &[Vec3],
    ) -> Vec<ExitLaw> {
        let mut laws = exit_laws.to_vec();
        let Some(table) = self.beam_table.as_ref().filter(|t| !t.early_leaving.is_empty()) else {
            return laws;
        };
        let p = &patches.patches;
        // Light from nearby leaves in the patch's own (limb-darkened) law: as lobes of their
        // mean, the ball's skin lit from the front went 0.058 → 0.088 in relative L1.
        let moments = table.early_moments(&direct.beam_light, |i, j| from_afar(patches, source_depths, i, j));
        for (i, (law, (early, moment))) in laws.iter_mut().zip(moments).enumerate() {
            if table.slot(i).is_none() {
                continue;
            }
            let (b, normal) = (exitance.get(i).copied().unwrap_or(Vec3::ZERO), p[i].normal);
            let e0 = direct.irradiance.get(i).copied().unwrap_or(Vec3::ZERO);
            // The rest in the patch's own law, without the far lobes of `exit_laws_along_flow`.
            (law.lobes, law.lobe_exitance) = Default::default();
            let rest = law.mean_leaving(b, e0, normal);
            let mean = std::array::from_fn(|c| {
                if !(b[c] > 0.0 && early[c] > 0.0) {
                    return rest[c];
                }
                let m = moment[c].truncate() / early[c];
                let v = (moment[c].w / (early[c] * early[c])).min(0.999);
                let length = ((m.length_squared() - v) / (1.0 - v)).max(0.0).sqrt();
                (m.normalize_or_zero() * length * early[c] + (b[c] - early[c]).max(0.0) * rest[c])
                    / b[c].max(early[c])
            });
            law.set_leaving(normal, mean, b);
        }
        laws
    }

    /// Per patch, where diffuse light entering it acts as a source: a reduced mean free path
    /// `1/(σa + σs′)` under its surface, per channel, in world units (zero on opaque patches
    /// and invalid media) — what [`BeamTable::flow`](super::beam_table::BeamTable::flow) measures
    /// directions from.
    pub fn source_depths(patches: &Patches, surfaces: &[PatchSurface]) -> Vec<Vec3> {
        patches
            .patches
            .iter()
            .map(|q| match surfaces.get(q.object as usize) {
                Some(&PatchSurface::Translucent { medium, world_units_per_mm, .. })
                    if medium.invalid_reason().is_none()
                        && world_units_per_mm.is_finite()
                        && world_units_per_mm > 0.0 =>
                {
                    world_units_per_mm / (medium.reduced_scattering + medium.absorption).max(Vec3::splat(1e-6))
                }
                _ => Vec3::ZERO,
            })
            .collect()
    }
}
