//! `F`, the form factors between all patches that see each other (the module above gives the
//! formula), with far-field clusters in two levels: a row links to a whole cluster once it is
//! further than `far_field_ratio` of the cluster's radius.

use bevy::prelude::*;

use super::{SceneRays, SparseMatrix, TransportSettings, parallel_rows};
use crate::translucency::{
    far_field::{Cluster, clusters, coarser_clusters, disc_kernel, near_kernel},
    patches::Patches,
};

/// `F` and what building it cast and dropped.
pub(super) struct FormFactors {
    /// `F`: columns `n..` are the clusters' area-mean exitances.
    pub matrix: SparseMatrix<f32>,
    /// Row `c`: cluster `c`'s members with their share of its area.
    pub cluster_means: SparseMatrix<f32>,
    /// Per patch, the form-factor sum the cut-off dropped (before visibility).
    pub dropped: Vec<f32>,
    /// Visibility rays cast.
    pub rays_cast: usize,
}

/// Builds `F` for `patches`, one ray per kept link.
pub(super) fn build(
    patches: &Patches,
    rays: &SceneRays,
    settings: &TransportSettings,
) -> FormFactors {
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
        // The light a cluster's patches send towards patch `i`, as one link.
        let cluster_sum =
            |c: &Cluster| -> f32 { c.members.iter().map(|&j| kernel(j) * p[j].area).sum() };
        // One link of the row: nothing at zero or below, dropped under the cut-off, kept
        // where its target (a patch or a cluster's representative) is visible.
        let mut link = |f: f32, column: usize, target: Vec3| {
            if !(f > 0.0) {
                return;
            }
            if f < cutoff {
                dropped += f;
                return;
            }
            rays_cast += 1;
            if rays.visible(xi, target) {
                row.push((column as u32, f));
            }
        };
        for (c2, (big, fines)) in coarse.iter().enumerate() {
            if fines.len() > 1 && far_from(big) {
                link(
                    cluster_sum(big),
                    n + fine_count + c2,
                    lifted[big.representative],
                );
                continue;
            }
            for &c in fines {
                let cluster = &clusters[c];
                if far_from(cluster) {
                    link(cluster_sum(cluster), n + c, lifted[cluster.representative]);
                } else {
                    for &j in cluster.members.iter().filter(|&&j| j != i) {
                        link(kernel(j) * p[j].area, j, lifted[j]);
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
    FormFactors {
        matrix: form_factors,
        cluster_means,
        dropped,
        rays_cast,
    }
}
