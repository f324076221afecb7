//! The form factors' kernels and far-field clusters of the transport
//! (`transport/form_factors.rs`): the disc kernel between two patches, its sum over nearby
//! patches' samples, and the two levels of clusters a distant row links to as one entry.

use bevy::prelude::*;

use super::patches::{Patch, PatchSample};

/// A far-field cluster.
#[derive(Clone)]
pub(super) struct Cluster {
    pub(super) members: Vec<usize>,
    pub(super) area: f32,
    pub(super) centroid: Vec3,
    /// Furthest reach of a member's disc from the centroid.
    pub(super) radius: f32,
    /// The member nearest the centroid: where the cluster's ray ends.
    pub(super) representative: usize,
}

pub(super) fn clusters(p: &[Patch], cells: &[f32], clustering: bool) -> Vec<Cluster> {
    if !clustering {
        return vec![Cluster {
            members: (0..p.len()).collect(),
            area: p.iter().map(|q| q.area).sum(),
            centroid: Vec3::ZERO,
            radius: f32::INFINITY,
            representative: 0,
        }];
    }
    group_by_cell(p.iter().map(|q| {
        (
            q.object,
            (q.centre / cells[q.object as usize]).floor().as_ivec3(),
            super::patches::normal_axis(q.normal),
        )
    }))
    .into_iter()
    .map(|members| cluster_of(p, members))
    .collect()
}

/// The indices of `keys` grouped by equal key (object, grid cell, normal axis), groups in the
/// order their keys first appear.
pub(super) fn group_by_cell(keys: impl Iterator<Item = (u32, IVec3, u8)>) -> Vec<Vec<usize>> {
    let mut index: bevy::platform::collections::HashMap<(u32, IVec3, u8), usize> = default();
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for (i, key) in keys.enumerate() {
        let g = *index.entry(key).or_insert_with(|| {
            groups.push(Vec::new());
            groups.len() - 1
        });
        groups[g].push(i);
    }
    groups
}

/// Groups `fine` clusters into clusters `factor` times wider (by object, normal axis of their
/// first member and the cell of their centroid); each with the fine clusters it holds.
pub(super) fn coarser_clusters(
    p: &[Patch],
    fine: &[Cluster],
    factor: f32,
) -> Vec<(Cluster, Vec<usize>)> {
    group_by_cell(fine.iter().map(|cluster| {
        let first = &p[cluster.members[0]];
        // A cell `factor` of this cluster's own radii across.
        let cell = (factor * cluster.radius).max(1e-9);
        (
            first.object,
            (cluster.centroid / cell).floor().as_ivec3(),
            super::patches::normal_axis(first.normal),
        )
    }))
    .into_iter()
    .map(|fines| {
        let members: Vec<usize> = fines
            .iter()
            .flat_map(|&c| fine[c].members.iter().copied())
            .collect();
        (cluster_of(p, members), fines)
    })
    .collect()
}

/// A cluster of the patches `members`: area, centroid, reach and the member nearest the
/// centroid.
pub(super) fn cluster_of(p: &[Patch], members: Vec<usize>) -> Cluster {
    let area: f32 = members.iter().map(|&j| p[j].area).sum();
    let centroid = members
        .iter()
        .map(|&j| p[j].centre * p[j].area)
        .sum::<Vec3>()
        / area;
    let radius = members
        .iter()
        .map(|&j| p[j].centre.distance(centroid) + (p[j].area / std::f32::consts::PI).sqrt())
        .fold(0.0, f32::max);
    let representative = *members
        .iter()
        .min_by(|&&a, &&b| {
            p[a].centre
                .distance_squared(centroid)
                .total_cmp(&p[b].centre.distance_squared(centroid))
        })
        .expect("clusters are never empty");
    Cluster {
        members,
        area,
        centroid,
        radius,
        representative,
    }
}

/// The symmetric form-factor kernel `G_ij = cos θ_i cos θ_j / (π r² + (A_i + A_j)/2)`
/// (`F_ij = G_ij A_j`).
pub(super) fn disc_kernel(cos_i: f32, cos_j: f32, r2: f32, area_i: f32, area_j: f32) -> f32 {
    cos_i * cos_j / (std::f32::consts::PI * r2 + 0.5 * (area_i + area_j))
}

/// `G_ij` of two nearby patches: the disc kernel between every pair of their samples,
/// area-weighted, `Σ_s Σ_t G_st A_s A_t / (A_i A_j)` (still symmetric).
pub(super) fn near_kernel(
    samples_i: &[PatchSample],
    samples_j: &[PatchSample],
    area_i: f32,
    area_j: f32,
) -> f32 {
    let mut sum = 0.0;
    for s in samples_i {
        for t in samples_j {
            let d = t.position - s.position;
            let r2 = d.length_squared();
            if !(r2 > 0.0) {
                continue;
            }
            let dir = d / r2.sqrt();
            let (cs, ct) = (s.normal.dot(dir), -t.normal.dot(dir));
            if cs > 0.0 && ct > 0.0 {
                sum += disc_kernel(cs, ct, r2, s.area, t.area) * s.area * t.area;
            }
        }
    }
    sum / (area_i * area_j)
}
