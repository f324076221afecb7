//! The accuracy scene's oracles: what it swaps in for the plugin's own stages to measure
//! them — `K` from random walks, single scattering marched per pixel by rays, single
//! scattering re-shaped into each lit pixel's own law ([`Oracles`]).

use super::*;

/// `K` of the one translucent object of `patches` from random walks: column `j` the share of
/// the walks from patch `j`'s samples leaving through each patch `i` (the nearest sample
/// facing the exit's way), times `T A_j / A_i` — the profile's own normalisation
/// (`Σ_i A_i K_ij` = what leaves of `T A_j`).
#[allow(clippy::too_many_arguments)]
pub(super) fn walked_scattering(
    patches: &Patches,
    medium: TranslucentMedium,
    world_units_per_mm: f32,
    rays: &SceneRays,
    walks: u32,
    launch: impl Fn(usize) -> WalkLaunch,
    orders: ScatteringOrders,
    (late, late_walks, lit_face_single_to_law): (LateLight, u32, bool),
    profile: &SparseMatrix<Vec3>,
) -> SparseMatrix<Vec3> {
    // The profile's columns, for the walks still inside after `orders.last`.
    let mut profile_columns: Vec<Vec<(u32, Vec3)>> = vec![Vec::new(); patches.patches.len()];
    for i in 0..profile.rows() {
        for (j, v) in profile.row(i) {
            profile_columns[j].push((i as u32, v));
        }
    }
    let p = &patches.patches;
    let exit_patches = ExitPatches::new(patches);
    // One object: the ball's or the bunny's.
    let exit_patch = |x: Vec3, outward: Vec3| exit_patches.of(0, x, outward);
    // What diffuse light gets past the boundary (the profiles' `entrance_transmittance`).
    let entering = (1.0 - diffuse_fresnel_reflectance(medium.index_of_refraction as f64)) as f32;
    let mut rows: Vec<Vec<(u32, Vec3)>> = vec![Vec::new(); p.len()];
    for (j, pj) in p.iter().enumerate() {
        let entries: Vec<EntryPoint> = patches
            .samples_of(j)
            .iter()
            .map(|s| EntryPoint { position: s.position, normal: s.normal, area: s.area })
            .collect();
        // Each walk's exits by patch, and the share still inside after `orders.last`.
        let walked = |launch: WalkLaunch, orders: ScatteringOrders, walks: u32, lit_face_single_to_law: bool| {
            let mut column: Vec<(u32, Vec3)> = Vec::new();
            let mut remaining = Vec3::ZERO;
            walk_ends(&medium, world_units_per_mm, &entries, rays, walks as usize, j as u64, launch, orders, None, |weight, end| {
                let exit = match end {
                    // Single scattering leaving by the lit face is the pixel's own law's.
                    WalkEnd::Exit(exit)
                        if lit_face_single_to_law
                            && exit.order == 1
                            && matches!(launch, WalkLaunch::Beam(d) if law_gives_single_scattering(pj.normal, d, exit.outward)) =>
                    {
                        return;
                    }
                    WalkEnd::Exit(exit) => exit,
                    // Through a gap in the mesh: lost.
                    WalkEnd::Gap => return,
                    WalkEnd::Remainder => {
                        remaining += weight / walks as f32;
                        return;
                    }
                };
                let Some(i) = exit_patch(exit.position, exit.outward) else {
                    return;
                };
                let at = match column.iter().position(|e| e.0 == i) {
                    Some(at) => at,
                    None => {
                        column.push((i, Vec3::ZERO));
                        column.len() - 1
                    }
                };
                column[at].1 += weight;
            });
            (column, remaining)
        };
        let (column, remaining) = walked(launch(j), orders, walks, lit_face_single_to_law);
        let mut entries_of: BTreeMap<u32, Vec3> = Default::default();
        for (i, count) in column {
            let value = count * (entering / walks as f32) * pj.area / p[i as usize].area;
            *entries_of.entry(i).or_default() += value;
        }
        if remaining != Vec3::ZERO && late == LateLight::Profile {
            for &(i, v) in &profile_columns[j] {
                *entries_of.entry(i).or_default() += v * remaining;
            }
        } else if remaining != Vec3::ZERO {
            // The late part of diffuse light entering here: the profile's column less the
            // early exits of diffuse walks, per unit of their own remainder.
            let (early, diffuse_remaining) = walked(
                WalkLaunch::Diffuse,
                ScatteringOrders { first: 0, last: orders.last },
                late_walks,
                false,
            );
            let scale = Vec3::select(
                diffuse_remaining.cmpgt(Vec3::ZERO),
                remaining / diffuse_remaining.max(Vec3::splat(1e-9)),
                Vec3::ZERO,
            );
            let mut late_column: BTreeMap<u32, Vec3> = profile_columns[j].iter().copied().collect();
            for (i, count) in early {
                let value = count * (entering / late_walks as f32) * pj.area / p[i as usize].area;
                *late_column.entry(i).or_default() -= value;
            }
            if late == LateLight::ProfileLessEarlyClamped {
                let flux = |m: &BTreeMap<u32, Vec3>| -> Vec3 {
                    m.iter().map(|(&i, &v)| v * p[i as usize].area).sum()
                };
                let total = flux(&late_column);
                late_column.values_mut().for_each(|v| *v = v.max(Vec3::ZERO));
                let clamped = flux(&late_column);
                let rescale = Vec3::select(
                    clamped.cmpgt(Vec3::ZERO),
                    total.max(Vec3::ZERO) / clamped.max(Vec3::splat(1e-30)),
                    Vec3::ZERO,
                );
                late_column.values_mut().for_each(|v| *v *= rescale);
            }
            for (i, v) in late_column {
                *entries_of.entry(i).or_default() += v * scale;
            }
        }
        for (i, value) in entries_of {
            rows[i as usize].push((j as u32, value));
        }
    }
    SparseMatrix::from_rows(rows)
}

/// The stretches `(from, to)` of the ray from `origin` (inside the shape) along the unit
/// `direction` that lie inside it, nearest first: the ball's in closed form (its reference
/// is the sphere, not the patches' mesh), the others' by the parity of their closed mesh.
fn inside_stretches(shape: Shape, rays: &SceneRays, origin: Vec3, direction: Vec3) -> Vec<(f32, f32)> {
    if shape == Shape::Ball {
        let b = origin.dot(direction);
        let disc = b * b - (origin.length_squared() - RADIUS * RADIUS);
        return vec![(0.0, if disc > 0.0 { (disc.sqrt() - b).max(0.0) } else { 0.0 })];
    }
    let (mut stretches, mut inside, mut from, mut t) = (Vec::new(), true, 0.0f32, 0.0f32);
    // A closed mesh is crossed an even number of times; a ray of the torus at most four.
    for _ in 0..16 {
        let Some((hit, _)) = rays.first_hit_within(origin + direction * t, direction, 1e3) else {
            break;
        };
        let at = t + hit;
        if inside {
            stretches.push((from, at));
        } else {
            from = at;
        }
        inside = !inside;
        t = at + 1e-6;
    }
    if inside {
        // Out through a gap: the rest counts as outside.
        stretches.push((from, t));
    }
    stretches
}

/// Single scattering at a pixel, marched along its ray through the object against the
/// light's own path in it, index-matched (`BeamTableSettings::single_scattering_to_pixels`:
/// an oracle of a per-pixel term, what the half-space law of the lit face and the table's
/// single scattering past it would give way to). Lit by a directional light of irradiance 1
/// travelling along the unit `travel`, with isotropic scattering:
/// `L = α/(4π) ∫ e^{−τ} e^{−σt ℓ(τ)} dτ` over the optical depth `τ` along the pixel's ray
/// inside the object (every stretch of it), `ℓ` the length of the light's path inside on
/// its way to the point; 64 depths a channel (`optical_depth_quantile`). Against Mitsuba's
/// single scattering (`max_depth` 2) on the torus: `docs/translucent.md`.
pub fn marched_single_scattering(shape: Shape, rays: &SceneRays, medium: TranslucentMedium, travel: Vec3, hit: &PixelHit) -> Vec3 {
    const DEPTHS: u32 = 64;
    let alpha = medium.single_scattering_albedo();
    let start = hit.point + hit.direction * 1e-6;
    let seen = inside_stretches(shape, rays, start, hit.direction);
    Vec3::from_array(std::array::from_fn(|c| {
        let sigma_t = (medium.absorption[c] + medium.reduced_scattering[c]) / WORLD_UNITS_PER_MM;
        let mut sum = 0.0f32;
        for k in 0..DEPTHS {
            // The depth's length inside, laid along the stretches the pixel's ray crosses.
            let mut left = optical_depth_quantile(k, DEPTHS) / sigma_t;
            let Some(t) = seen.iter().find_map(|&(a, b)| {
                if left <= b - a {
                    Some(a + left)
                } else {
                    left -= b - a;
                    None
                }
            }) else {
                continue;
            };
            let x = start + hit.direction * t;
            let to_light: f32 = inside_stretches(shape, rays, x, -travel).iter().map(|&(a, b)| b - a).sum();
            sum += (-sigma_t * to_light).exp();
        }
        alpha[c] as f32 / (4.0 * std::f32::consts::PI) * sum / DEPTHS as f32
    }))
}

/// [`Oracles::single_scattering_law`] on `pixels`, lit by a directional light of irradiance 1
/// travelling along the unit `travel`.
pub(super) fn single_scattering_law(
    hits: &[Option<PixelHit>],
    pixels: Vec<Vec3>,
    medium: TranslucentMedium,
    travel: Vec3,
    rays: &SceneRays,
    lambert_held: bool,
) -> Vec<Vec3> {
    let alpha = Vec3::from_array(medium.single_scattering_albedo().map(|a| a as f32));
    pixels
        .into_iter()
        .zip(hits)
        .map(|(pixel, hit)| {
            let Some(hit) = hit else {
                return pixel;
            };
            let (mu0, mu) = (hit.normal.dot(-travel), hit.normal.dot(-hit.direction).max(0.0));
            if mu0 <= 0.0 || rays.first_hit(hit.point + hit.normal * 1e-5, -travel).is_some() {
                return pixel;
            }
            if !lambert_held {
                return pixel + single_scattering_radiance(alpha, 1.0, Vec3::splat(mu0), mu0, mu);
            }
            let shape = single_scattering_shape(mu0 as f64) as f32;
            let change = alpha * mu0 / (4.0 * std::f32::consts::PI) * (1.0 / (mu0 + mu) - 2.0 * shape);
            (pixel + change).max(Vec3::ZERO)
        })
        .collect()
}
