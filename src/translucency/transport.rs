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
//!   share leaving through patch `i` is [`DiffusionProfile::patch_transfer`], so
//!   `K_ij = (1 − F_dr,ext) P_ij A_j / A_i`, for pairs of the same object closer than the
//!   radius that holds [`TransportSettings::diffusion_energy_kept`] of the profile's energy.
//!   On opaque patches `K_ii = albedo`.
//!
//! The kernels and far-field clusters of `F` are in `far_field.rs`; the lights' direct part,
//! re-exported here, in `lights.rs`.

use std::time::Instant;

use bevy::prelude::*;
use super::far_field::{Cluster, clusters, coarser_clusters, disc_kernel, near_kernel};
pub use super::lights::{DirectLight, PatchLight, direct_irradiance, direct_light};
pub use super::{rays::SceneRays, sparse::SparseMatrix};
use super::{
    diffusion::{DiffusionKernel, DiffusionProfile},
    medium::TranslucentMedium,
    patches::Patches,
    shape_diffusion::{MAX_SHAPE_PATCHES, SHAPE_SOURCE_DEPTH, ShapePatch, boundary_correction},
};

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
}

impl ExitLaw {
    /// The exit radiance over the Lambertian `B/π` at exit cosine `mu`, per channel, for
    /// exitance `b` and direct irradiance `e0`: `1 + D (s(μ) − 1)`, with
    /// `D = g · clamp(1 − A E⁰/B, 0, 1)` the share of `B` that came from elsewhere in the deep
    /// field's mode (the same arithmetic as `gather.wgsl`).
    pub fn factor(&self, b: Vec3, e0: Vec3, mu: f32) -> Vec3 {
        Vec3::from_array(std::array::from_fn(|c| {
            let law = self.channels[c].to_array();
            if law[3] <= 0.0 || b[c] <= 0.0 {
                return 1.0;
            }
            let deep = law[3] * (1.0 - self.local_albedo[c] * e0[c] / b[c]).clamp(0.0, 1.0);
            1.0 + deep * (super::diffusion::deep_exit_shape(law, self.eta, mu) - 1.0)
        }))
    }
}

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
    /// totals (the slab's, times the object's walks); only where the light leaves moves. For
    /// objects of up to [`MAX_SHAPE_PATCHES`]
    /// patches with a dipole kernel; larger ones keep the flat profile (one dense system of
    /// their side per channel, `O(N³)`: 1.4 s at 960 patches on 2 cores). On by default: lit
    /// from behind, a 1 cm skin ball goes from 0.612 to 0.420 in relative L1 against a
    /// light-traced reference, marble from 0.277 to 0.153 (with [`deep_exit_law`](Self::deep_exit_law)
    /// 0.431 and 0.078); from the front both stay within 0.002 (`docs/translucent.md`).
    pub shape_diffusion: bool,
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
}

impl Default for TransportSettings {
    /// 99.9 % of the profile (the tail beyond holds 0.1 %: lit from behind, the light that
    /// crosses a 2 cm marble ball — 0.55 → 0.28 relative L1 against 99 %, for 1.8× the ball's
    /// memory, +3 % in the test room's); form factors down to 1e-5 (a
    /// patch of 1/1000 of a room's wall area seen face-on from 5 wall widths away); clusters
    /// 4 patches wide linked as one beyond 3 radii; each object's own random walks and each
    /// beam's incidence (both measured closer to a light-traced reference; see
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
            deep_exit_law: true,
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
    /// Translucent objects that kept the flat profile because they have more than
    /// [`MAX_SHAPE_PATCHES`] patches.
    pub shape_too_large_objects: usize,
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
}

/// The converged transport of one frame's light.
#[derive(Clone, Debug, Default)]
pub struct TransportSolution {
    /// Exitance `B` per patch (outgoing radiance `B/π`).
    pub exitance: Vec<Vec3>,
    /// Irradiance `E` arriving per patch, direct and bounced.
    pub irradiance: Vec<Vec3>,
    /// Iterations run (each one `F` and one `K` product).
    pub iterations: u32,
    /// The energy of the last increment relative to the first bounce's: below the
    /// threshold unless `iterations` hit the cap.
    pub energy_left: f32,
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

/// Runs `f(i)` for `0..n` on every core, interleaved so uneven rows balance; results in order.
pub(super) fn parallel_rows<R: Send>(n: usize, f: impl Fn(usize) -> R + Sync) -> Vec<R> {
    let t = threads().min(n.max(1));
    let mut parts: Vec<Vec<(usize, R)>> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..t)
            .map(|k| {
                let f = &f;
                scope.spawn(move || (k..n).step_by(t).map(|i| (i, f(i))).collect::<Vec<_>>())
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
        let p = &patches.patches;
        let n = p.len();
        let lifted: Vec<Vec3> = (0..n)
            .map(|i| p[i].surface_point + p[i].normal * (0.05 * patches.size_of(i)))
            .collect();
        let cutoff = settings.form_factor_cutoff.max(0.0);

        // Far-field clusters: patches grouped by object, normal axis and a grid `cluster_size`
        // patches wide. A row links to a whole cluster (one entry, one ray to the member
        // nearest its centroid, the cluster's area-mean exitance) once the cluster is further
        // than `far_field_ratio` × its radius; nearer, to each member.
        let clustering = settings.cluster_size > 1;
        // Each object's clusters as wide as `cluster_size` of its own patches.
        let cells: Vec<f32> = patches
            .object_patch_sizes
            .iter()
            .map(|s| {
                if s.is_finite() {
                    s * settings.cluster_size as f32
                } else {
                    f32::INFINITY
                }
            })
            .collect();
        let clusters = clusters(p, &cells, clustering);
        // A second level, each cluster of clusters `cluster_size` times wider, linked as one
        // beyond `far_field_ratio` of its own radius (a hierarchy of two levels: far rooms
        // cost one entry per coarse cluster).
        let coarse: Vec<(Cluster, Vec<usize>)> = if clustering {
            coarser_clusters(p, &clusters, settings.cluster_size as f32)
        } else {
            vec![(clusters[0].clone(), vec![0])]
        };
        let fine_count = clusters.len();
        let far_ratio2 = settings.far_field_ratio.max(1.0).powi(2);
        let rows = parallel_rows(n, |i| {
            let (pi, xi) = (&p[i], lifted[i]);
            let mut row = Vec::new();
            let (mut dropped, mut rays_cast) = (0.0f32, 0usize);
            let kernel = |j: usize| -> f32 {
                let pj = &p[j];
                let d = pj.centre - pi.centre;
                let r2 = d.length_squared();
                let near = 2.5 * patches.size_of(i).max(patches.size_of(j));
                if r2 < near * near {
                    // Neighbours: the kernel summed over both patches' samples, where the
                    // centres' single disc term is far off (corners, curved patches).
                    near_kernel(
                        patches.samples_of(i),
                        patches.samples_of(j),
                        pi.area,
                        pj.area,
                    )
                } else {
                    let dir = d / r2.sqrt();
                    let (ci, cj) = (pi.normal.dot(dir), -pj.normal.dot(dir));
                    if ci <= 0.0 || cj <= 0.0 {
                        return 0.0;
                    }
                    disc_kernel(ci, cj, r2, pi.area, pj.area)
                }
            };
            let far_from = |cluster: &Cluster| {
                clustering
                    && cluster.members.len() > 1
                    && pi.centre.distance_squared(cluster.centroid)
                        > far_ratio2 * cluster.radius * cluster.radius
            };
            for (c2, (big, fines)) in coarse.iter().enumerate() {
                if fines.len() > 1 && far_from(big) {
                    let f: f32 = big.members.iter().map(|&j| kernel(j) * p[j].area).sum();
                    if !(f > 0.0) {
                        continue;
                    }
                    if f < cutoff {
                        dropped += f;
                        continue;
                    }
                    rays_cast += 1;
                    if rays.visible(xi, lifted[big.representative]) {
                        row.push(((n + fine_count + c2) as u32, f));
                    }
                    continue;
                }
                for &c in fines {
                    let cluster = &clusters[c];
                    if far_from(cluster) {
                        let f: f32 = cluster.members.iter().map(|&j| kernel(j) * p[j].area).sum();
                        if !(f > 0.0) {
                            continue;
                        }
                        if f < cutoff {
                            dropped += f;
                            continue;
                        }
                        rays_cast += 1;
                        if rays.visible(xi, lifted[cluster.representative]) {
                            row.push(((n + c) as u32, f));
                        }
                    } else {
                        for &j in cluster.members.iter().filter(|&&j| j != i) {
                            let f = kernel(j) * p[j].area;
                            if !(f > 0.0) {
                                continue;
                            }
                            if f < cutoff {
                                dropped += f;
                                continue;
                            }
                            rays_cast += 1;
                            if rays.visible(xi, lifted[j]) {
                                row.push((j as u32, f));
                            }
                        }
                    }
                }
            }
            (row, dropped, rays_cast)
        });
        let rays_cast: usize = rows.iter().map(|r| r.2).sum();
        let dropped: Vec<f32> = rows.iter().map(|r| r.1).collect();
        let form_factors = SparseMatrix::from_rows(rows.into_iter().map(|r| r.0).collect());
        let cluster_means = if clustering {
            let mean = |c: &Cluster| -> Vec<(u32, f32)> {
                c.members
                    .iter()
                    .map(|&j| (j as u32, p[j].area / c.area))
                    .collect()
            };
            SparseMatrix::from_rows(
                clusters
                    .iter()
                    .map(mean)
                    .chain(coarse.iter().map(|(c, _)| mean(c)))
                    .collect(),
            )
        } else {
            SparseMatrix::from_rows(Vec::new())
        };

        // Each patch's index among its object's.
        let mut local_index = vec![0usize; n];
        let mut members: Vec<Vec<usize>> = vec![Vec::new(); surfaces.len()];
        for (i, q) in p.iter().enumerate() {
            if let Some(list) = members.get_mut(q.object as usize) {
                local_index[i] = list.len();
                list.push(i);
            }
        }
        // The translucent objects solved in their shape (`shape_diffusion`): their profile,
        // its sources where diffuse light's sit (`SHAPE_SOURCE_DEPTH`), and the correction per
        // channel (row exit, column entry, local indices). Too large, or (never seen) a
        // singular system: the flat profile.
        let valid_medium = |s: &PatchSurface| match *s {
            PatchSurface::Translucent {
                medium,
                world_units_per_mm,
                ..
            } if medium.invalid_reason().is_none()
                && world_units_per_mm.is_finite()
                && world_units_per_mm > 0.0 =>
            {
                Some((medium, world_units_per_mm as f64))
            }
            _ => None,
        };
        let mut shape_too_large_objects = 0;
        let shape_solutions: Vec<Option<(DiffusionProfile, [Vec<f64>; 3])>> = surfaces
            .iter()
            .enumerate()
            .map(|(object, s)| {
                let (medium, units_per_mm) = valid_medium(s)?;
                if !settings.shape_diffusion {
                    return None;
                }
                let profile = DiffusionProfile::with_source_depth(
                    &medium,
                    settings.kernel,
                    SHAPE_SOURCE_DEPTH,
                );
                let channels = profile.dipole_channels()?;
                let count = members[object].len();
                if count > MAX_SHAPE_PATCHES {
                    shape_too_large_objects += 1;
                    info!(
                        "translucency: object {object} has {count} patches, more than the \
                         {MAX_SHAPE_PATCHES} whose diffusion is solved in their shape; it keeps \
                         the flat profile"
                    );
                    return None;
                }
                let mm = 1.0 / units_per_mm;
                let shape: Vec<ShapePatch> = members[object]
                    .iter()
                    .map(|&i| ShapePatch {
                        centre: p[i].centre.as_dvec3() * mm,
                        normal: p[i].normal.as_dvec3(),
                        area: p[i].area as f64 * mm * mm,
                    })
                    .collect();
                let [r, g, b] = channels.map(|c| boundary_correction(&shape, c));
                let solved = r.zip(g).zip(b).map(|((r, g), b)| (profile, [r, g, b]));
                if solved.is_none() {
                    warn!(
                        "translucency: object {object}'s diffusion could not be solved in its \
                         shape (a singular system); it keeps the flat profile"
                    );
                }
                solved
            })
            .collect();

        // K: per translucent object, the profile between its patches; albedo on opaque ones.
        // Solved in its shape, an object's pairs are all kept (the correction carries light
        // across it) and its sources sit at `SHAPE_SOURCE_DEPTH`.
        let profiles: Vec<Option<(DiffusionProfile, f64, f64)>> = surfaces
            .iter()
            .zip(&shape_solutions)
            .map(|(s, solution)| {
                let (medium, units_per_mm) = valid_medium(s)?;
                if let Some((profile, _)) = solution {
                    return Some((*profile, units_per_mm, f64::INFINITY));
                }
                let profile = DiffusionProfile::new(&medium, settings.kernel);
                let reach_mm =
                    profile.radius_holding(settings.diffusion_energy_kept.clamp(0.5, 1.0) as f64);
                Some((profile, units_per_mm, reach_mm))
            })
            .collect();
        let shape_solved_objects = shape_solutions.iter().flatten().count();

        // Each row's entries: the column and `K_ij` (an object with `oriented_dipole` or solved
        // in its shape: the oriented dipole, the flat share times the pair's orientation
        // factor; in its shape, plus the correction; the columns' totals are set below).
        let scattering_rows = parallel_rows(n, |i| {
            let pi = &p[i];
            let surface = surfaces.get(pi.object as usize);
            match (surface, profiles.get(pi.object as usize).copied().flatten()) {
                (
                    Some(&PatchSurface::Translucent {
                        oriented_dipole, ..
                    }),
                    Some((profile, units_per_mm, reach_mm)),
                ) => {
                    let mm = 1.0 / units_per_mm;
                    let area_i_mm2 = pi.area as f64 * mm * mm;
                    let t_in = profile.entrance_transmittance;
                    let correction = shape_solutions
                        .get(pi.object as usize)
                        .and_then(Option::as_ref)
                        .map(|(_, correction)| correction);
                    let own = &members[pi.object as usize];
                    let row_start = local_index[i] * own.len();
                    own.iter()
                        .enumerate()
                        .filter_map(|(lj, &j)| {
                            let pj = &p[j];
                            let r_mm = pi.centre.distance(pj.centre) as f64 * mm;
                            (r_mm <= reach_mm).then(|| {
                                let share = profile.patch_transfer(r_mm, area_i_mm2);
                                let k = t_in * pj.area as f64 / pi.area as f64;
                                let factor = if (oriented_dipole || correction.is_some()) && i != j
                                {
                                    profile.orientation_factor(
                                        pj.centre.as_dvec3() * mm,
                                        pj.normal.as_dvec3(),
                                        pi.centre.as_dvec3() * mm,
                                        pi.normal.as_dvec3(),
                                    )
                                } else {
                                    [1.0; 3]
                                };
                                let beyond =
                                    |c: usize| correction.map_or(0.0, |u| u[c][row_start + lj]);
                                // Exitance is never negative; the correction's collocation
                                // can undershoot where the dipole alone is near zero.
                                let value = Vec3::new(
                                    ((share[0] * factor[0] + beyond(0)) * k).max(0.0) as f32,
                                    ((share[1] * factor[1] + beyond(1)) * k).max(0.0) as f32,
                                    ((share[2] * factor[2] + beyond(2)) * k).max(0.0) as f32,
                                );
                                (j as u32, value)
                            })
                        })
                        .collect()
                }
                (Some(&PatchSurface::Opaque { albedo }), _) => {
                    vec![(i as u32, albedo.clamp(Vec3::ZERO, Vec3::ONE))]
                }
                // An invalid medium or a patch without a surface reflects nothing.
                _ => Vec::new(),
            }
        });

        let mut scattering = SparseMatrix::from_rows(scattering_rows);

        // Per translucent object: the slab's W∞ of its profile, and the factor its columns
        // carry beyond it — 1, or (`object_exit_share`) what random walks find leaving the
        // object's own shape over what leaves a slab.
        let object_totals: Vec<Option<(Vec3, Vec3)>> = profiles
            .iter()
            .enumerate()
            .map(|(object, profile)| {
                let (profile, units_per_mm, _) = (*profile)?;
                let total = profile.total_reflectance();
                let slab = Vec3::new(total[0] as f32, total[1] as f32, total[2] as f32);
                let PatchSurface::Translucent { medium, .. } = surfaces[object] else {
                    return Some((slab, Vec3::ONE));
                };
                if !settings.object_exit_share {
                    return Some((slab, Vec3::ONE));
                }
                let entries: Vec<_> = (0..n)
                    .filter(|&i| p[i].object as usize == object)
                    .flat_map(|i| patches.samples_of(i))
                    .map(|s| super::random_walk::EntryPoint {
                        position: s.position,
                        normal: s.normal,
                        area: s.area,
                    })
                    .collect();
                // Chiang et al.'s `A` (the scaled dipole's and Burley's total) is an
                // index-matched slab's: over an index-matched slab's share, the walks' share
                // (Fresnel reflecting them back inside the boundary) carries the boundary's
                // internal reflection as well as the shape (over the slab's own share it
                // carried the shape alone, and a skin ball at η 1.3 under uniform light came
                // out 1.28–1.70× too bright against a path tracer; `docs/translucent.md`).
                // Jensen's dipole holds its boundary already (`A = (1 + F_dr)/(1 − F_dr)`).
                let slab_medium = if medium.index_of_refraction > 1.0
                    && settings.kernel != super::diffusion::DiffusionKernel::Dipole
                {
                    super::medium::TranslucentMedium {
                        index_of_refraction: 1.0,
                        ..medium
                    }
                } else {
                    medium
                };
                let (walks, seed) = (super::random_walk::WALKS_PER_CHANNEL, object as u64);
                let object_share = super::random_walk::object_exit_share(
                    &medium,
                    units_per_mm as f32,
                    &entries,
                    rays,
                    walks,
                    seed,
                );
                let slab_share = super::random_walk::slab_exit_share(
                    &slab_medium,
                    units_per_mm as f32,
                    walks,
                    seed,
                );
                let finite =
                    object_share
                        .zip(slab_share)
                        .map_or(Vec3::ONE, |(object_share, slab_share)| {
                            Vec3::select(
                                slab_share.cmpgt(Vec3::ZERO),
                                object_share / slab_share.max(Vec3::splat(1e-9)),
                                Vec3::ONE,
                            )
                        });
                Some((slab, finite))
            })
            .collect();

        // Each translucent column carries the slab's total reflectance: Σ_i P_ij = W∞. The
        // cut-off drops ~1 %, and equal-area discs about neighbouring centres overlap the
        // source's own disc where the profile is narrower than a patch (measured up to +28 %
        // on a 5 cm marble ball in 34 mm patches); the columns are rescaled to W∞, and what
        // they held before is reported.
        let areas: Vec<f32> = p.iter().map(|q| q.area).collect();
        let column_sums = scattering.weighted_column_sums(&areas, n);
        let (mut kept_sum, mut kept_count) = (Vec3::ZERO, 0);
        let mut walked_sum = Vec3::ZERO;
        let mut column_scale = vec![Vec3::ONE; n];
        for (j, pj) in p.iter().enumerate() {
            if let (Some((profile, ..)), Some(&Some((slab, finite)))) = (
                profiles.get(pj.object as usize).copied().flatten(),
                object_totals.get(pj.object as usize),
            ) {
                let entering = profile.entrance_transmittance as f32 * pj.area;
                kept_sum += column_sums[j] / (slab * entering).max(Vec3::splat(1e-30));
                walked_sum += finite;
                kept_count += 1;
                let held = column_sums[j];
                column_scale[j] = Vec3::select(
                    held.cmpgt(Vec3::ZERO),
                    slab * finite * entering / held.max(Vec3::splat(1e-30)),
                    Vec3::ONE,
                );
            }
        }
        for (value, &column) in scattering.values.iter_mut().zip(&scattering.columns) {
            *value *= column_scale[column as usize];
        }
        // Single scattering leaves where it enters: on the diagonal, for diffuse light
        // (`single_scattering` keeps the factor for direct light's own incidence).
        let single_scattering: Vec<Vec3> = p
            .iter()
            .map(
                |q| match profiles.get(q.object as usize).copied().flatten() {
                    Some((profile, ..)) => {
                        let a = profile.single_scattering_albedo;
                        Vec3::new(a[0] as f32, a[1] as f32, a[2] as f32)
                            * (0.5 * profile.entrance_transmittance) as f32
                    }
                    None => Vec3::ZERO,
                },
            )
            .collect();
        let diffuse_shape = super::diffusion::diffuse_single_scattering_shape() as f32;
        for (i, single) in single_scattering.iter().enumerate() {
            let range = scattering.row_offsets[i] as usize..scattering.row_offsets[i + 1] as usize;
            for e in range {
                if scattering.columns[e] as usize == i {
                    scattering.values[e] += *single * diffuse_shape;
                }
            }
        }

        let report = TransportReport {
            form_factor_entries: form_factors.entries(),
            clusters: cluster_means.rows(),
            scattering_entries: scattering.entries(),
            rays: rays_cast,
            dropped_form_factor_mean: dropped.iter().sum::<f32>() / n.max(1) as f32,
            dropped_form_factor_max: dropped.iter().copied().fold(0.0, f32::max),
            diffusion_kept_mean: kept_sum / kept_count.max(1) as f32,
            object_exit_over_slab_mean: walked_sum / kept_count.max(1) as f32,
            shape_solved_objects,
            shape_too_large_objects,
            seconds: start.elapsed().as_secs_f32(),
        };
        Self {
            scattering,
            form_factors,
            cluster_means,
            single_scattering,
            areas: p.iter().map(|q| q.area).collect(),
            incidence: Self::incidence_weights(surfaces, settings),
            report,
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
        // The law is the medium's: once per object, not per patch.
        let laws: Vec<Option<([Vec4; 3], f32)>> = surfaces
            .iter()
            .map(|s| match s {
                PatchSurface::Translucent { medium, .. }
                    if settings.deep_exit_law && medium.invalid_reason().is_none() =>
                {
                    let eta = medium.index_of_refraction;
                    let channels = medium
                        .single_scattering_albedo()
                        .map(|a| Vec4::from_array(super::diffusion::deep_exit_law(a, eta as f64)));
                    Some((channels, eta))
                }
                _ => None,
            })
            .collect();
        p.iter()
            .zip(&column_totals)
            .map(|(q, total)| match laws.get(q.object as usize) {
                Some(&Some((channels, eta))) if q.area > 0.0 => ExitLaw {
                    local_albedo: *total / q.area,
                    channels,
                    eta,
                },
                _ => ExitLaw::default(),
            })
            .collect()
    }

    /// Σ A_i (B_i.r + B_i.g + B_i.b): the flux of an exitance vector.
    pub fn flux(&self, exitance: &[Vec3]) -> f32 {
        exitance
            .iter()
            .zip(&self.areas)
            .map(|(b, a)| a * (b.x + b.y + b.z))
            .sum()
    }

    /// `E = F B`: the irradiance each patch gathers from the exitance `B` of the others
    /// (clusters' exitance as their members' area mean).
    pub fn gather(&self, exitance: &[Vec3]) -> Vec<Vec3> {
        let means = self.cluster_means.mul_vec(exitance);
        let extended: Vec<Vec3> = exitance.iter().chain(&means).copied().collect();
        self.form_factors.mul_vec(&extended)
    }

    /// Iterates `ΔE = F ΔB`, `ΔB = K ΔE` from `B = K E⁰` until the flux of `ΔB` is below
    /// `threshold` × the flux of the first `B`, or `max_iterations`.
    pub fn solve(&self, direct: &[Vec3], threshold: f32, max_iterations: u32) -> TransportSolution {
        self.solve_with(
            &DirectLight {
                irradiance: direct.to_vec(),
                exitance: Vec::new(),
            },
            threshold,
            max_iterations,
        )
    }

    /// [`solve`](Self::solve) from `B = K E⁰ + S⁰`: `direct.exitance` is the exitance the
    /// direct light leaves besides `K E⁰` (single scattering at each beam's own incidence).
    pub fn solve_with(
        &self,
        direct: &DirectLight,
        threshold: f32,
        max_iterations: u32,
    ) -> TransportSolution {
        let mut irradiance = direct.irradiance.clone();
        let mut delta = self.scattering.mul_vec(&direct.irradiance);
        for (d, s) in delta.iter_mut().zip(&direct.exitance) {
            *d += *s;
        }
        let mut exitance = delta.clone();
        let first = self.flux(&exitance);
        let mut iterations = 0;
        // Nothing lit: nothing to iterate.
        let mut energy_left = if first > 0.0 { 1.0 } else { 0.0 };
        while iterations < max_iterations && energy_left > threshold {
            let gathered = self.gather(&delta);
            for (e, g) in irradiance.iter_mut().zip(&gathered) {
                *e += *g;
            }
            delta = self.scattering.mul_vec(&gathered);
            for (b, d) in exitance.iter_mut().zip(&delta) {
                *b += *d;
            }
            iterations += 1;
            energy_left = self.flux(&delta) / first;
        }
        TransportSolution {
            exitance,
            irradiance,
            iterations,
            energy_left,
        }
    }
}
