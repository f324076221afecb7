//! `K`, the scattering operator: per translucent object, the diffusion profile between its
//! patches (flat, oriented, or solved in the object's shape), each column rescaled to the
//! slab's total times what random walks find leaving the object's own shape, and single
//! scattering on the diagonal; an opaque patch's albedo on its diagonal.

use bevy::prelude::*;

use super::{PatchSurface, SceneRays, SparseMatrix, TransportSettings, parallel_rows};
use crate::translucency::{
    diffusion::{self, DiffusionProfile},
    medium,
    patches::Patches,
    random_walk,
    shape_diffusion::{
        DipoleChannel, MAX_SHAPE_PATCHES, SHAPE_SOURCE_DEPTH, ShapeClusters, ShapePatch,
        boundary_correction,
    },
};

/// `K` and what building it found.
pub(super) struct Scattering {
    pub matrix: SparseMatrix<Vec3>,
    /// Per patch, `(1 − F_dr,ext) α/2` of its medium (zero on opaque patches).
    pub single_scattering: Vec<Vec3>,
    /// See [`TransportReport::diffusion_kept_mean`](super::TransportReport::diffusion_kept_mean).
    pub diffusion_kept_mean: Vec3,
    /// See [`TransportReport::object_exit_over_slab_mean`](super::TransportReport::object_exit_over_slab_mean).
    pub object_exit_over_slab_mean: Vec3,
    pub shape_solved_objects: usize,
    pub shape_clustered_objects: usize,
}

/// An object to solve in its shape: its profile, its channels, the patches (mm) its correction
/// is collocated at, and above `MAX_SHAPE_PATCHES` each of its patches' cluster among them.
type ShapeSolve = (DiffusionProfile, [DipoleChannel; 3], Vec<ShapePatch>, Option<Vec<u32>>);

/// A solved object: its profile, the correction per channel (row exit, column entry, over the
/// collocation patches), and where it was solved on clusters, those and each patch's cluster.
type ShapeSolution<'a> = (DiffusionProfile, [Vec<f64>; 3], Option<(&'a [ShapePatch], &'a [u32])>);

/// Builds `K` for `patches`; `surfaces[o]` is object `o`'s surface.
pub(super) fn build(
    patches: &Patches,
    surfaces: &[PatchSurface],
    rays: &SceneRays,
    settings: &TransportSettings,
) -> Scattering {
    let p = &patches.patches;
    let n = p.len();
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
    let mut shape_clustered_objects = 0;
    // Each object to solve: its profile, channels, and the patches (mm) the correction is
    // collocated at — its own, or above `MAX_SHAPE_PATCHES` clusters of them.
    let shapes: Vec<Option<ShapeSolve>> = surfaces
        .iter()
        .enumerate()
        .map(|(object, s)| {
            let (medium, units_per_mm) = valid_medium(s)?;
            if !settings.shape_diffusion {
                return None;
            }
            let profile =
                DiffusionProfile::with_source_depth(&medium, settings.kernel, SHAPE_SOURCE_DEPTH);
            let channels = profile.dipole_channels()?;
            let mm = 1.0 / units_per_mm;
            let shape: Vec<ShapePatch> = members[object]
                .iter()
                .map(|&i| ShapePatch {
                    centre: p[i].centre.as_dvec3() * mm,
                    normal: p[i].normal.as_dvec3(),
                    area: p[i].area as f64 * mm * mm,
                })
                .collect();
            if shape.len() > MAX_SHAPE_PATCHES {
                shape_clustered_objects += 1;
                let clusters = ShapeClusters::new(&shape, MAX_SHAPE_PATCHES);
                info!(
                    "translucency: object {object} has {} patches, more than the \
                     {MAX_SHAPE_PATCHES} its shape's solve takes; its correction is solved \
                     on {} clusters of them",
                    shape.len(),
                    clusters.patches.len()
                );
                return Some((profile, channels, clusters.patches, Some(clusters.of)));
            }
            Some((profile, channels, shape, None))
        })
        .collect();
    // Every object's three channels at once: each solve's LU steps are short and one at a
    // time, so that one solve alone keeps few cores busy.
    let mut corrections = parallel_rows(shapes.len() * 3, |task| {
        let (profile_channels_shape, c) = (&shapes[task / 3], task % 3);
        profile_channels_shape
            .as_ref()
            .and_then(|(_, channels, shape, _)| boundary_correction(shape, channels[c]))
    })
    .into_iter();
    let shape_solutions: Vec<Option<ShapeSolution>> = shapes
        .iter()
        .enumerate()
        .map(|(object, solve)| {
            let [r, g, b] = [(); 3].map(|_| corrections.next().flatten());
            let (profile, _, collocation, clusters) = solve.as_ref()?;
            let clusters = clusters.as_deref().map(|of| (collocation.as_slice(), of));
            let solved = r.zip(g).zip(b).map(|((r, g), b)| (*profile, [r, g, b], clusters));
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
            if let Some((profile, ..)) = solution {
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
                let solution = shape_solutions.get(pi.object as usize).and_then(Option::as_ref);
                let correction = solution.map(|(_, correction, _)| correction);
                let clusters = solution.and_then(|(.., clusters)| *clusters);
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
                            let factor = if (oriented_dipole || correction.is_some()) && i != j {
                                profile.orientation_factor(
                                    pj.centre.as_dvec3() * mm,
                                    pj.normal.as_dvec3(),
                                    pi.centre.as_dvec3() * mm,
                                    pi.normal.as_dvec3(),
                                )
                            } else {
                                [1.0; 3]
                            };
                            // Solved on clusters: the share leaving by `i`'s cluster, over
                            // the cluster's area.
                            let at = match clusters {
                                Some((collocation, of)) => {
                                    let (ci, cj) = (of[local_index[i]] as usize, of[lj] as usize);
                                    (ci * collocation.len() + cj, area_i_mm2 / collocation[ci].area)
                                }
                                None => (row_start + lj, 1.0),
                            };
                            let beyond =
                                |c: usize| correction.map_or(0.0, |u| u[c][at.0] * at.1);
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

    // Solved in its shape, an object has every pair (the correction has no radius: `O(N²)`);
    // each of its columns drops its lightest entries, holding at most
    // `shape_energy_dropped` of its energy (the columns are rescaled to their totals below).
    let areas: Vec<f32> = p.iter().map(|q| q.area).collect();
    let solved = |i: usize| shape_solutions.get(p[i].object as usize).is_some_and(Option::is_some);
    let scattering_rows = drop_lightest_of_columns(scattering_rows, &areas, solved, settings.shape_energy_dropped);
    let mut scattering = SparseMatrix::from_rows(scattering_rows);

    // Per translucent object: the slab's W∞ of its profile, and the factor its columns
    // carry beyond it — 1, or (`object_exit_share`) what random walks find leaving the
    // object's own shape over what leaves a slab.
    // The objects on their own cores (each walks its channels on three).
    let object_totals: Vec<Option<(Vec3, Vec3)>> = parallel_rows(profiles.len(), |object| {
        let (profile, units_per_mm, _) = profiles[object]?;
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
            .map(|s| random_walk::EntryPoint {
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
            && settings.kernel != diffusion::DiffusionKernel::Dipole
        {
            medium::TranslucentMedium {
                index_of_refraction: 1.0,
                ..medium
            }
        } else {
            medium
        };
        let (walks, seed) = (random_walk::WALKS_PER_CHANNEL, object as u64);
        let object_share = random_walk::object_exit_share(
            &medium,
            units_per_mm as f32,
            &entries,
            rays,
            walks,
            seed,
        );
        let slab_share =
            random_walk::slab_exit_share(&slab_medium, units_per_mm as f32, walks, seed);
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
    });

    // Each translucent column carries the slab's total reflectance: Σ_i P_ij = W∞. The
    // cut-off drops ~1 %, and equal-area discs about neighbouring centres overlap the
    // source's own disc where the profile is narrower than a patch (measured up to +28 %
    // on a 5 cm marble ball in 34 mm patches); the columns are rescaled to W∞, and what
    // they held before is reported.
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
    let diffuse_shape = diffusion::diffuse_single_scattering_shape() as f32;
    for (i, single) in single_scattering.iter().enumerate() {
        let range = scattering.row_offsets[i] as usize..scattering.row_offsets[i + 1] as usize;
        for e in range {
            if scattering.columns[e] as usize == i {
                scattering.values[e] += *single * diffuse_shape;
            }
        }
    }
    Scattering {
        matrix: scattering,
        single_scattering,
        diffusion_kept_mean: kept_sum / kept_count.max(1) as f32,
        object_exit_over_slab_mean: walked_sum / kept_count.max(1) as f32,
        shape_solved_objects,
        shape_clustered_objects,
    }
}

/// `rows` (exit `i`: entries `(j, K_ij)`) with each column `j` of the `solved` rows rid of
/// its lightest entries while they hold at most `dropped` (0 – 0.01) of its energy
/// `Σ_i K_ij A_i` in every channel: an entry weighs its largest share of its column over the
/// channels, and the weights dropped sum to at most `dropped` (so no channel loses more). The
/// diagonal stays; the other rows are untouched.
pub(crate) fn drop_lightest_of_columns(
    rows: Vec<Vec<(u32, Vec3)>>,
    areas: &[f32],
    solved: impl Fn(usize) -> bool + Sync,
    dropped: f32,
) -> Vec<Vec<(u32, Vec3)>> {
    let n = rows.len();
    let budget = if dropped.is_finite() { f64::from(dropped.clamp(0.0, super::MAX_SHAPE_ENERGY_DROPPED)) } else { 0.0 };
    if budget <= 0.0 || !(0..n).any(&solved) {
        return rows;
    }
    let mut totals = vec![Vec3::ZERO; n];
    for (i, row) in rows.iter().enumerate().filter(|&(i, _)| solved(i)) {
        for &(j, value) in row {
            totals[j as usize] += value * areas[i];
        }
    }
    let weight = |i: usize, j: usize, value: Vec3| {
        let total = totals[j];
        Vec3::select(total.cmpgt(Vec3::ZERO), value * areas[i] / total.max(Vec3::splat(1e-30)), Vec3::ZERO)
            .max_element()
    };
    let mut weights: Vec<Vec<f32>> = vec![Vec::new(); n];
    for (i, row) in rows.iter().enumerate().filter(|&(i, _)| solved(i)) {
        for &(j, value) in row.iter().filter(|&&(j, _)| j as usize != i) {
            weights[j as usize].push(weight(i, j as usize, value));
        }
    }
    // Per column, the least weight kept: ties with it are kept too, so the budget holds.
    let least_kept: Vec<f32> = parallel_rows(n, |j| {
        let mut column = weights[j].clone();
        column.sort_unstable_by(f32::total_cmp);
        let mut dropped = 0.0f64;
        for w in column {
            dropped += f64::from(w);
            if dropped > budget {
                return w;
            }
        }
        f32::INFINITY
    });
    drop(weights);
    rows.into_iter()
        .enumerate()
        .map(|(i, row)| {
            if !solved(i) {
                return row;
            }
            row.into_iter()
                .filter(|&(j, value)| j as usize == i || weight(i, j as usize, value) >= least_kept[j as usize])
                .collect()
        })
        .collect()
}
