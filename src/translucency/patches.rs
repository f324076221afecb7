//! Seed 001's "scene of uniform patches": every object's surface resampled into patches of
//! near-equal area, whatever its triangles (a bunny's 70 k slivers or a wall's two triangles).
//!
//! The surface is first cut into samples much smaller than a patch (each triangle split into
//! `m²` similar sub-triangles with edges ≤ half the patch size), then the samples are grouped by
//! object, by the cell of a grid whose spacing is the patch size `h`, and by the axis their
//! normal is closest to (so the two sides of a thin wall never merge). Groups smaller than a
//! fifth of `h²` join their largest neighbour of the same object and axis. `h` starts at
//! `√(area / budget)` and is rescaled until the count is within 75–100 % of the budget.
//! Areas are exact: every sample's area lands in exactly one patch.

use bevy::{platform::collections::HashMap, prelude::*};

/// One object's surface in world space: a triangle list.
#[derive(Clone, Copy, Debug)]
pub struct PatchObject<'a> {
    /// Vertex positions, world space.
    pub positions: &'a [Vec3],
    /// Three indices per triangle.
    pub indices: &'a [u32],
}

/// A near-uniform piece of surface: the unit of the energy transport.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Patch {
    /// Area-weighted centroid of the patch's surface, world space (inside a convex surface
    /// by the patch's sag).
    pub centre: Vec3,
    /// The point of the patch's surface nearest its centre: where its rays start.
    pub surface_point: Vec3,
    /// Area-weighted mean normal, unit length.
    pub normal: Vec3,
    /// Area, world units².
    pub area: f32,
    /// Index of the object it belongs to.
    pub object: u32,
}

/// Every object's patches.
#[derive(Clone, Debug, Default)]
pub struct Patches {
    /// The patches, grouped by object in order.
    pub patches: Vec<Patch>,
    /// The largest patch size the grid settled on (world units): patches are about `h²` in
    /// area.
    pub patch_size: f32,
    /// Each object's patch size.
    pub object_patch_sizes: Vec<f32>,
    /// Triangles left out: non-finite vertices, indices out of range or zero area.
    pub skipped_triangles: usize,
    /// The surface samples (pieces of triangles, edges ≤ `patch_size / 2`) of each patch:
    /// patch `i`'s are `samples[sample_offsets[i]..sample_offsets[i + 1]]`.
    pub samples: Vec<PatchSample>,
    /// Where each patch's samples start; one more entry than patches.
    pub sample_offsets: Vec<u32>,
}

/// A small piece of a patch's surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PatchSample {
    /// Centroid of the piece.
    pub position: Vec3,
    /// Its triangle's unit normal.
    pub normal: Vec3,
    /// Its area.
    pub area: f32,
}

impl Patches {
    /// The patch size of patch `i`'s object.
    pub fn size_of(&self, i: usize) -> f32 {
        let s = self.object_patch_sizes[self.patches[i].object as usize];
        if s.is_finite() { s } else { 1.0 }
    }

    /// Patch `i`'s samples.
    pub fn samples_of(&self, i: usize) -> &[PatchSample] {
        &self.samples[self.sample_offsets[i] as usize..self.sample_offsets[i + 1] as usize]
    }

    /// A sphere about every sample (centre, radius): the middle of their bounding box and
    /// 1 % beyond its half-diagonal. The unit sphere about the origin where there are none.
    pub fn bounding_sphere(&self) -> (Vec3, f32) {
        let (lo, hi) = self.samples.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), s| (lo.min(s.position), hi.max(s.position)),
        );
        if lo.x <= hi.x {
            ((lo + hi) * 0.5, ((hi - lo).length() * 0.5).max(1e-6) * 1.01)
        } else {
            (Vec3::ZERO, 1.0)
        }
    }
}

/// A surface sample: a small piece of one triangle.
#[derive(Clone, Copy)]
struct Sample {
    position: Vec3,
    normal: Vec3,
    area: f32,
    object: u32,
}

/// Grouping key: object, grid cell, the axis (0–5: ±X, ±Y, ±Z) nearest the normal.
type Key = (u32, IVec3, u8);

/// Which of ±X, ±Y, ±Z (0–5) is nearest the normal `n`.
pub(crate) fn normal_axis(n: Vec3) -> u8 {
    let a = n.abs();
    let (axis, value) = if a.x >= a.y && a.x >= a.z {
        (0, n.x)
    } else if a.y >= a.z {
        (1, n.y)
    } else {
        (2, n.z)
    };
    axis * 2 + u8::from(value < 0.0)
}

/// The valid triangles of every object, with their object index.
fn triangles<'a>(objects: &'a [PatchObject<'a>], skipped: &'a mut usize) -> Vec<(u32, [Vec3; 3])> {
    let mut out = Vec::new();
    for (object, o) in objects.iter().enumerate() {
        for t in o.indices.chunks(3) {
            let vertex = |k: usize| t.get(k).and_then(|&i| o.positions.get(i as usize)).copied();
            let (Some(a), Some(b), Some(c)) = (vertex(0), vertex(1), vertex(2)) else {
                *skipped += 1;
                continue;
            };
            let area2 = (b - a).cross(c - a).length();
            if !(a.is_finite() && b.is_finite() && c.is_finite() && area2 > 0.0 && area2.is_finite())
            {
                *skipped += 1;
                continue;
            }
            out.push((object as u32, [a, b, c]));
        }
    }
    out
}

/// Splits each triangle into `m²` similar pieces with edges ≤ `max_edge`.
fn samples(triangles: &[(u32, [Vec3; 3])], sizes: &[f32]) -> Vec<Sample> {
    let mut out = Vec::new();
    for &(object, [a, b, c]) in triangles {
        let max_edge = 0.5 * sizes[object as usize];
        let cross = (b - a).cross(c - a);
        let area = 0.5 * cross.length();
        let normal = cross.normalize();
        let longest = (b - a).length().max((c - b).length()).max((a - c).length());
        // Capped so a degenerate-but-huge triangle cannot ask for billions of samples.
        let m = ((longest / max_edge).ceil() as u32).clamp(1, 512);
        let piece = area / (m * m) as f32;
        let (u, v) = ((b - a) / m as f32, (c - a) / m as f32);
        for i in 0..m {
            for j in 0..m - i {
                let (fi, fj) = (i as f32, j as f32);
                out.push(Sample {
                    position: a + u * (fi + 1.0 / 3.0) + v * (fj + 1.0 / 3.0),
                    normal,
                    area: piece,
                    object,
                });
                if i + j + 1 < m {
                    out.push(Sample {
                        position: a + u * (fi + 2.0 / 3.0) + v * (fj + 2.0 / 3.0),
                        normal,
                        area: piece,
                        object,
                    });
                }
            }
        }
    }
    out
}

#[derive(Clone, Copy, Default)]
struct Accumulated {
    weighted_position: Vec3,
    weighted_normal: Vec3,
    area: f32,
}

fn group(samples: &[Sample], sizes: &[f32]) -> (Vec<Key>, HashMap<Key, Accumulated>) {
    let mut groups: HashMap<Key, Accumulated> = HashMap::default();
    let mut order = Vec::new();
    for s in samples {
        let key = sample_key(s, sizes);
        let g = groups.entry(key).or_insert_with(|| {
            order.push(key);
            Accumulated::default()
        });
        g.weighted_position += s.position * s.area;
        g.weighted_normal += s.normal * s.area;
        g.area += s.area;
    }
    (order, groups)
}

/// Merges groups smaller than `min_area` into their largest neighbour (26 cells) of the same
/// object and normal axis; returns the surviving keys in first-seen order.
fn merge_slivers(
    order: &[Key],
    groups: &mut HashMap<Key, Accumulated>,
    sizes: &[f32],
) -> (Vec<Key>, HashMap<Key, Key>) {
    let mut redirect = HashMap::default();
    for &key in order {
        let Some(&g) = groups.get(&key) else { continue };
        let size = sizes[key.0 as usize];
        if g.area >= 0.2 * size * size {
            continue;
        }
        let (object, cell, axis) = key;
        let mut best: Option<(Key, f32)> = None;
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let n = (object, cell + IVec3::new(dx, dy, dz), axis);
                    if n == key {
                        continue;
                    }
                    if let Some(other) = groups.get(&n)
                        && best.is_none_or(|(_, a)| other.area > a)
                    {
                        best = Some((n, other.area));
                    }
                }
            }
        }
        if let Some((target, _)) = best {
            groups.remove(&key);
            redirect.insert(key, target);
            let t = groups.get_mut(&target).expect("neighbour found above");
            t.weighted_position += g.weighted_position;
            t.weighted_normal += g.weighted_normal;
            t.area += g.area;
        }
    }
    let kept = order
        .iter()
        .copied()
        .filter(|k| groups.contains_key(k))
        .collect();
    (kept, redirect)
}

fn sample_key(s: &Sample, sizes: &[f32]) -> Key {
    let h = sizes[s.object as usize];
    (
        s.object,
        (s.position / h).floor().as_ivec3(),
        normal_axis(s.normal),
    )
}

/// Resamples `objects` into at most `budget` patches of near-equal area (at least one per
/// object that has any area).
pub fn resample_into_patches(objects: &[PatchObject], budget: usize) -> Patches {
    resample_into_patches_with_caps(objects, &vec![None; objects.len()], budget)
}

/// [`resample_into_patches`], with patches on object `o` no wider than `caps[o]` relative to
/// the others: sizes are `k · min(h₀, cap)` with `h₀ = √(area / budget)` and `k` fitted to
/// the budget, so an object whose cap is below `h₀` gets patches finer by `cap / h₀` (a
/// translucent object's patches as wide as a fraction of its diffusion reach) and the rest
/// share what is left.
pub fn resample_into_patches_with_caps(
    objects: &[PatchObject],
    caps: &[Option<f32>],
    budget: usize,
) -> Patches {
    let mut skipped = 0;
    let triangles = triangles(objects, &mut skipped);
    let total_area: f64 = triangles
        .iter()
        .map(|(_, [a, b, c])| 0.5 * (*b - *a).cross(*c - *a).length() as f64)
        .sum();
    if triangles.is_empty() || budget == 0 {
        return Patches {
            skipped_triangles: skipped,
            ..default()
        };
    }
    let h0 = (total_area / budget as f64).sqrt() as f32;
    let base: Vec<f32> = (0..objects.len())
        .map(|o| match caps.get(o).copied().flatten() {
            Some(cap) if cap.is_finite() && cap > 0.0 => cap.min(h0),
            _ => h0,
        })
        .collect();
    let mut k = 1.0f32;
    type Grouping = (
        Vec<f32>,
        Vec<Sample>,
        Vec<Key>,
        HashMap<Key, Accumulated>,
        HashMap<Key, Key>,
    );
    let mut best: Option<Grouping> = None;
    for _ in 0..10 {
        let sizes: Vec<f32> = base.iter().map(|b| b * k).collect();
        let samples = samples(&triangles, &sizes);
        let (order, mut groups) = group(&samples, &sizes);
        let (order, redirect) = merge_slivers(&order, &mut groups, &sizes);
        let count = order.len();
        let fits = count <= budget;
        let done = fits && count * 4 >= budget * 3;
        if fits && best.as_ref().is_none_or(|b| count > b.2.len()) {
            best = Some((sizes, samples, order, groups, redirect));
        }
        if done {
            break;
        }
        // Patch count goes as 1/k²; aim a little under the budget.
        k *= ((count as f32) / (0.9 * budget as f32))
            .sqrt()
            .clamp(0.5, 2.0);
    }
    let (sizes, samples, order, groups, redirect) = best.unwrap_or_else(|| {
        // Never fitted (a budget smaller than the number of objects × axes): one patch per
        // object and axis.
        let sizes = vec![f32::INFINITY; objects.len()];
        let samples = samples(&triangles, &sizes);
        let (order, groups) = group(&samples, &sizes);
        (sizes, samples, order, groups, HashMap::default())
    });
    // Patches grouped by object (stable), then each sample into its patch.
    let mut order = order;
    order.sort_by_key(|k| k.0);
    let index: HashMap<Key, usize> = order.iter().enumerate().map(|(i, k)| (*k, i)).collect();
    let final_key = |mut k: Key| {
        while let Some(&next) = redirect.get(&k) {
            k = next;
        }
        k
    };
    let mut members: Vec<Vec<PatchSample>> = vec![Vec::new(); order.len()];
    for s in &samples {
        let i = index[&final_key(sample_key(s, &sizes))];
        members[i].push(PatchSample {
            position: s.position,
            normal: s.normal,
            area: s.area,
        });
    }
    let mut patches = Vec::with_capacity(order.len());
    let mut all_samples = Vec::with_capacity(samples.len());
    let mut sample_offsets = vec![0u32];
    for (key, members) in order.iter().zip(members) {
        let g = groups[key];
        let centre = g.weighted_position / g.area;
        let surface_point = members
            .iter()
            .min_by(|a, b| {
                a.position
                    .distance_squared(centre)
                    .total_cmp(&b.position.distance_squared(centre))
            })
            .map_or(centre, |s| s.position);
        patches.push(Patch {
            centre,
            surface_point,
            normal: g.weighted_normal.try_normalize().unwrap_or(Vec3::Y),
            area: g.area,
            object: key.0,
        });
        all_samples.extend(members);
        sample_offsets.push(all_samples.len() as u32);
    }
    Patches {
        patches,
        patch_size: sizes.iter().copied().fold(0.0, f32::max),
        object_patch_sizes: sizes,
        skipped_triangles: skipped,
        samples: all_samples,
        sample_offsets,
    }
}

/// A mesh's triangles in world space (positions transformed, a triangle list with three
/// indices each); `None` for meshes that are not triangle lists or have no `Float32x3`
/// positions.
pub fn world_triangles(mesh: &Mesh, transform: &GlobalTransform) -> Option<(Vec<Vec3>, Vec<u32>)> {
    use bevy::mesh::{PrimitiveTopology, VertexAttributeValues};
    if mesh.primitive_topology() != PrimitiveTopology::TriangleList {
        return None;
    }
    let Some(VertexAttributeValues::Float32x3(positions)) =
        mesh.attribute(Mesh::ATTRIBUTE_POSITION)
    else {
        return None;
    };
    let affine = transform.affine();
    let positions: Vec<Vec3> = positions
        .iter()
        .map(|&p| affine.transform_point3(Vec3::from(p)))
        .collect();
    let indices: Vec<u32> = match mesh.indices() {
        Some(i) => i.iter().map(|i| i as u32).collect(),
        None => (0..positions.len() as u32).collect(),
    };
    Some((positions, indices))
}
