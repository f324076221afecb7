//! The gather's CPU twin: the patches' hashed grids, and each pixel's light from the patches
//! about it as `gathered.wgsl` takes it (the oracle the GPU gather is tested against).

use bevy::prelude::*;

use super::GATHER_RADIUS_IN_PATCHES;
use crate::translucency::{plugin::GatherMethod, translucent_shadow_map::MarchedObject, transport::ExitLaw};

/// Some patches in a hashed grid of cells as wide as their widest reach: a pixel looks in
/// the 27 cells about it and takes from each bucket only the members of the cell it walks —
/// two of the 27 cells may hash to one bucket, whose patches would otherwise count twice
/// (with photons, twice the light).
#[derive(Clone, Debug, Default)]
pub struct PatchGrid {
    /// Cell width (world units).
    pub cell_size: f32,
    /// Bucket `b`'s patches are `members[offsets[b]..offsets[b + 1]]`.
    pub offsets: Vec<u32>,
    /// Patch indices by bucket.
    pub members: Vec<u32>,
    /// Each member's own cell.
    pub cells: Vec<IVec3>,
}

impl PatchGrid {
    /// The patches `indices` (centres `centres[i]`); buckets a power of two ≥ 4 × their
    /// number (few collisions among the 27 cells looked at).
    pub fn new(centres: &[Vec3], indices: &[u32], cell_size: f32) -> Self {
        let buckets = (indices.len() * 4).next_power_of_two().max(64) as u32;
        let mask = buckets - 1;
        let cell_of: Vec<IVec3> = indices
            .iter()
            .map(|&i| (centres[i as usize] / cell_size).floor().as_ivec3())
            .collect();
        let bucket_of: Vec<u32> = cell_of.iter().map(|&c| Self::bucket(c, mask)).collect();
        let mut offsets = vec![0u32; buckets as usize + 1];
        for &b in &bucket_of {
            offsets[b as usize + 1] += 1;
        }
        for b in 0..buckets as usize {
            offsets[b + 1] += offsets[b];
        }
        let mut fill = offsets.clone();
        let mut members = vec![0u32; indices.len()];
        let mut cells = vec![IVec3::ZERO; indices.len()];
        for ((&i, &b), &cell) in indices.iter().zip(&bucket_of).zip(&cell_of) {
            members[fill[b as usize] as usize] = i;
            cells[fill[b as usize] as usize] = cell;
            fill[b as usize] += 1;
        }
        Self {
            cell_size,
            offsets,
            members,
            cells,
        }
    }

    /// A cell's bucket: `bucket` in `gathered.wgsl`.
    pub fn bucket(cell: IVec3, mask: u32) -> u32 {
        let c = cell.as_uvec3();
        (c.x.wrapping_mul(73_856_093) ^ c.y.wrapping_mul(19_349_663) ^ c.z.wrapping_mul(83_492_791))
            & mask
    }

    /// The patches in grids by reach: one grid per power-of-two step of reach above the
    /// smallest (at most [`MAX_GRID_LEVELS`], the last taking the rest), so that a pixel near
    /// finely patched objects does not walk the buckets of cells sized for a wall's patches.
    pub fn levels(centres: &[Vec3], reaches: &[f32]) -> Vec<PatchGrid> {
        let smallest = reaches
            .iter()
            .copied()
            .fold(f32::INFINITY, f32::min)
            .max(1e-9);
        let level =
            |r: f32| ((r / smallest).log2().ceil().max(0.0) as usize).min(MAX_GRID_LEVELS - 1);
        let mut by_level: Vec<Vec<u32>> = vec![Vec::new(); MAX_GRID_LEVELS];
        for (i, &r) in reaches.iter().enumerate() {
            by_level[level(r)].push(i as u32);
        }
        by_level
            .into_iter()
            .filter(|members| !members.is_empty())
            .map(|members| {
                let cell = members
                    .iter()
                    .map(|&i| reaches[i as usize])
                    .fold(0.0, f32::max);
                PatchGrid::new(centres, &members, cell)
            })
            .collect()
    }
}

/// The most grids the gather looks in.
pub const MAX_GRID_LEVELS: usize = 8;

/// The radiance the gather gives a point `x` with normal `n` (before the view's exposure) by
/// `method` ([`GatherMethod`]): the patches within their reach `R`, weighted by
/// `(1 − d²/R²)²` and by `smoothstep(0.3, 0.9, n·n_i)`, each giving `(B_i − ρ_i E⁰_i) / π`
/// times its [`ExitLaw`] at the cosine towards `eye` for the light the patch `received` (its
/// irradiance direct and bounced, [`TransportSolution::irradiance`](crate::translucency::transport::TransportSolution::irradiance)) —
/// interpolated, or as photons of that exitance times the patch's area under a kernel of
/// unit integral; `None` where no patch is near. Interpolated, the light that leaves by the
/// laws leans down the exitance's gradient along the surface where the laws carry a weight
/// for it ([`ExitLaw::tangential`]). With `marched` (per object; `None` on those
/// without), the single scattering marched per pixel of the translucent object whose patch
/// weighs most at `x` ([`MarchedObject::radiance`]) is added. The CPU twin of `gathered.wgsl`
/// (brute force instead of the hashed grid), the oracle of its tests.
#[allow(clippy::too_many_arguments)]
pub fn gathered_radiance(
    method: GatherMethod,
    patches: &crate::translucency::patches::Patches,
    albedo: &[Vec3],
    exit_laws: &[ExitLaw],
    direct: &[Vec3],
    received: &[Vec3],
    exitance: &[Vec3],
    single: Option<&BeamSingleScattering>,
    marched: Option<&[Option<MarchedObject>]>,
    eye: Vec3,
    x: Vec3,
    n: Vec3,
) -> Option<Vec3> {
    let towards = (eye - x).normalize_or_zero();
    let mu = n.dot(towards);
    let (mut sum, mut weights) = (Vec3::ZERO, 0.0);
    let mut along = AlongSurface::default();
    let frame = tangent_frame(n);
    // The translucent patch that weighs most here: the pixel's object.
    let mut object: Option<(f32, usize)> = None;
    for (i, p) in patches.patches.iter().enumerate() {
        let d2 = p.surface_point.distance_squared(x);
        // Each patch reaches 1.5 of its own object's patch sizes.
        let r2 = (GATHER_RADIUS_IN_PATCHES * patches.size_of(i)).powi(2);
        if d2 >= r2 {
            continue;
        }
        let t = ((n.dot(p.normal) - 0.3) / 0.6).clamp(0.0, 1.0);
        let mut w = (1.0 - d2 / r2).powi(2) * t * t * (3.0 - 2.0 * t);
        if w > 0.0 {
            if method == GatherMethod::PhotonDensity {
                // K(d) = 3/(πR²)(1 − d²/R²)², times the photon's area: Φ = M·A.
                w *= 3.0 / (std::f32::consts::PI * r2) * p.area;
            }
            let law = exit_laws.get(i).copied().unwrap_or_default();
            // Light bounced onto a translucent patch enters it as its direct light does: it
            // leaves about where it entered, not by the law of the light that flowed from
            // elsewhere in the object (a skin ball over a white floor: `docs/translucent.md`).
            let (factor, unleaned) = law.factor_towards_parts(exitance[i], received[i], n, towards);
            let own = (exitance[i] - albedo[i] * direct[i]).max(Vec3::ZERO);
            sum += w * own * factor / std::f32::consts::PI;
            if method == GatherMethod::Interpolation && law.tangential != Vec3::ZERO {
                along.add(w, p.surface_point - x, frame, exitance[i], own * unleaned / std::f32::consts::PI, &law);
            }
            if let Some(single) = single {
                sum += w * single.radiance(i, n, mu);
            }
            if albedo[i] == Vec3::ZERO && object.is_none_or(|(best, _)| w > best) {
                object = Some((w, p.object as usize));
            }
            weights += w;
        }
    }
    let own = object
        .and_then(|(_, o)| marched?.get(o)?.as_ref())
        .map_or(Vec3::ZERO, |m| m.radiance(x, n, towards));
    (weights > 0.0).then(|| match method {
        GatherMethod::Interpolation => (sum + along.lean(frame, towards, mu)) / weights + own,
        GatherMethod::PhotonDensity => sum + own,
    })
}

/// A pixel's sums for the flux along the surface (`ExitLaw::tangential`; `gathered.wgsl`'s
/// `Gathered`): over the translucent patches that reach it with a weight, their light that
/// leaves by the laws (not the lobes), their weights, and for the exitance's gradient a
/// weighted least-squares plane fitted to their exitance in the pixel's tangent plane. (The
/// gradient of the interpolant itself, `ΣwB/Σw`, is about half the field's where 1.5 patch
/// sizes hold a handful of patches: 0.50× on a plane with an exponential exitance.)
#[derive(Default)]
struct AlongSurface {
    leaving: Vec3,
    weights: f32,
    weight: Vec3,
    exitance: Vec3,
    // Σ w d, Σ w (dx², dx dy, dy²) and per channel Σ w d B, `d` the patch's offset in the
    // pixel's tangent frame.
    offset: Vec2,
    second: Vec3,
    times: [Vec2; 3],
    eta: f32,
}

/// The pixel's tangent frame about its unit normal `n` (`tangent_frame` in `gathered.wgsl`).
fn tangent_frame(n: Vec3) -> (Vec3, Vec3) {
    let helper = if n.x.abs() < 0.9 { Vec3::X } else { Vec3::Y };
    let t = n.cross(helper).normalize();
    (t, n.cross(t))
}

impl AlongSurface {
    /// A patch of weight `w`, its centre `offset` from the pixel (in world space; `frame` the
    /// pixel's tangent frame), its exitance `b` and its light that leaves by the laws.
    fn add(&mut self, w: f32, offset: Vec3, frame: (Vec3, Vec3), b: Vec3, leaving: Vec3, law: &ExitLaw) {
        let d = Vec2::new(offset.dot(frame.0), offset.dot(frame.1));
        self.leaving += w * leaving;
        self.weights += w;
        self.weight += w * law.tangential;
        self.exitance += w * b;
        self.offset += w * d;
        self.second += w * Vec3::new(d.x * d.x, d.x * d.y, d.y * d.y);
        for c in 0..3 {
            self.times[c] += w * d * b[c];
        }
        self.eta = law.eta;
    }

    /// What the lean adds to the pixel's weighted sum: the light that left by the laws times
    /// `tangential_flux_factor − 1`, the gradient the fitted plane's (none where the patches
    /// do not span the plane).
    fn lean(&self, frame: (Vec3, Vec3), towards: Vec3, mu: f32) -> Vec3 {
        if self.weights <= 0.0 {
            return Vec3::ZERO;
        }
        let (total, mean) = (self.weights, self.offset / self.weights);
        let b = self.exitance / total;
        let weight = self.weight / total;
        // The offsets' covariance and its determinant.
        let (xx, xy, yy) = (
            self.second.x / total - mean.x * mean.x,
            self.second.y / total - mean.x * mean.y,
            self.second.z / total - mean.y * mean.y,
        );
        let det = xx * yy - xy * xy;
        if !(det > 1e-6 * (xx + yy) * (xx + yy)) {
            return Vec3::ZERO;
        }
        let view = Vec2::new(towards.dot(frame.0), towards.dot(frame.1));
        Vec3::from_array(std::array::from_fn(|c| {
            if b[c] <= 0.0 {
                return 0.0;
            }
            let cross = self.times[c] / total - mean * b[c];
            let gradient = Vec2::new(yy * cross.x - xy * cross.y, xx * cross.y - xy * cross.x) / det;
            let along = gradient.dot(view) / b[c];
            let factor = crate::translucency::diffusion::tangential_flux_factor(weight[c], self.eta, mu, along);
            self.leaving[c] * (factor - 1.0)
        }))
    }
}

/// What single scattering by the lit face gives the gather where a beam table carries the
/// beams (`TransportSettings::beam_table`): per patch, its beams' irradiance at normal
/// incidence and their weighted travel direction (`DirectLight::beam_irradiance`,
/// `beam_direction`), and its medium's single-scattering albedo and index (`w`; zero
/// without a table).
pub struct BeamSingleScattering<'a> {
    /// Per patch, the beams' irradiance at normal incidence, shadowed.
    pub irradiance: &'a [Vec3],
    /// Per patch, the beams' travel directions weighted by that irradiance.
    pub direction: &'a [Vec3],
    /// Per patch, `(α, η)` of its medium; zero without a table.
    pub media: &'a [Vec4],
}

impl BeamSingleScattering<'_> {
    /// The single-scattered radiance patch `i`'s beams give a pixel of unit normal `n` seen
    /// at exit cosine `mu` ([`single_scattering_radiance`](crate::translucency::beam_table::single_scattering_radiance)
    /// with the pixel's own incidence cosine; the beams' mean direction: exact for one light).
    pub fn radiance(&self, i: usize, n: Vec3, mu: f32) -> Vec3 {
        let (Some(&e), Some(&d), Some(&m)) =
            (self.irradiance.get(i), self.direction.get(i), self.media.get(i))
        else {
            return Vec3::ZERO;
        };
        let Some(travel) = d.try_normalize() else {
            return Vec3::ZERO;
        };
        let mu0 = n.dot(-travel);
        crate::translucency::beam_table::single_scattering_radiance(m.truncate(), m.w, e * mu0.max(0.0), mu0, mu)
    }
}
