//! The diffusion equation solved in a translucent object's own shape: the dipole of each entry
//! patch's tangent plane plus a boundary-element correction for where the object's surface
//! leaves that plane.
//!
//! The dipole (`diffusion`) solves diffusion `D∇²φ − σa φ = −Q` under a plane, with the
//! boundary condition `φ + 2AD ∂φ/∂n = 0` it approximates by its image. In an object a few
//! diffusion lengths across that plane is wrong twice over: light crossing the object meets
//! the far surface head-on (the oriented dipole's flux, [`DipoleChannel::fields`]), and on
//! its way it leaks out through the whole surface, which no pair of sources in a half-space
//! sees (the oriented dipole alone made a back-lit marble ball 1.6× too bright,
//! `docs/translucent.md`). For flux entering at patch `k`, write `φ = φ_k + ψ`: `φ_k` the
//! dipole of `k`'s plane (its image lies outside a convex object), `ψ` the correction, which
//! solves the homogeneous equation inside with the dipole's residual on the real surface,
//! `b_k = φ_k + 2AD ∂φ_k/∂n`, on the boundary: `ψ + 2AD ∂ψ/∂n = −b_k`. The residual the dipole
//! leaves on its own plane (it holds the condition only approximately) is subtracted at each
//! distance, so that on a plane `b_k = 0` and the profile is the dipole's exactly.
//!
//! Green's representation on a smooth surface, with the free-space solution
//! `G(r) = e^(−σtr r)/(4πD r)`: `½ψ(x) = D∮(G ∂ψ/∂n − ψ ∂G/∂n_y) dS_y`. With the boundary
//! condition and `u = ψ + b_k`:
//!
//! `(½ I + S + K) u = (½ I + K) b_k`,  `S = ∮ G/(2A) ·`,  `K = ∮ D ∂G/∂n_y ·`,
//!
//! collocated at the patch centres (one value a patch; the single layer's self term integrated
//! over the patch's equal-area disc, `S_ii = (1 − e^(−σtr ρ))/(2Dσtr)/(2A)`, the double
//! layer's from Gauss's identity, `K_ii = −½ − Σ_{j≠i} K⁰_ij` with `K⁰` the double layer
//! without absorption — on a smooth patch the curvature's `−ρH/4`, which an open object,
//! [`is_closed`], keeps). The exitance through the surface is `−D ∂φ/∂n = J_k + u/(2A)`: the
//! oriented dipole's plus the correction, which this module returns as the share of the
//! entering flux that leaves through each patch, `a_i u_ik/(2A)`.
//!
//! One dense `N × N` system an object and channel, solved by LU with partial pivoting for all
//! `N` entry patches at once: `O(N³)`, so an object above [`MAX_SHAPE_PATCHES`] patches is
//! solved on [`ShapeClusters`] of them, each pair's dipole still its own patches'.

use bevy::math::DVec3;
use std::f64::consts::PI;

use super::transport::parallel_rows;

/// The most patches an object's shape is solved on: a dense system of this side per channel
/// (3 × 2 × 32 MB at 2048) and `O(N³)` work; a larger object is solved on as many
/// [`ShapeClusters`] of its patches.
pub const MAX_SHAPE_PATCHES: usize = 2048;

/// Where an object solved in its shape puts each dipole's real source, in reduced mean free
/// paths under the entry (Jensen's is 1). `K` carries diffuse light (a light's own beam is
/// weighted per frame by its incidence only in what it gives back), and under diffuse light
/// the diffusion field deep inside is that of a source at 2/3: the transmission of a thick
/// slab under diffuse light is diffusion theory's for a source this deep — random walks
/// through slabs 8 and 15 mean free paths thick, 4·10⁵ a case, give 0.66 for albedo 0.999
/// and 0.66–0.73 for skin's red (0.959), against 1.00–1.12 under a normal beam, as transport
/// theory's `H(μ₀)/√3 − 2/3` has it for no absorption (`H(1)/√3 = 1.68`, and its
/// cosine-weighted mean 4/3). With Jensen's depth a back-lit marble ball came out 1.35–1.45×
/// too bright (`docs/translucent.md`).
pub const SHAPE_SOURCE_DEPTH: f64 = 2.0 / 3.0;

/// One patch of an object, in millimetres.
#[derive(Clone, Copy, Debug)]
pub struct ShapePatch {
    /// Centre, mm.
    pub centre: DVec3,
    /// Outward unit normal.
    pub normal: DVec3,
    /// Area, mm².
    pub area: f64,
}

/// An object's patches gathered into at most `most` clusters, for the solve of an object
/// larger than [`MAX_SHAPE_PATCHES`]: the correction `ψ` solves the homogeneous diffusion
/// equation with the dipoles' smooth residual as its boundary data, so it changes over a
/// diffusion length, not a patch, and collocation at coarser patches gives it back while
/// each pair's dipole stays the fine patches' own.
#[derive(Clone, Debug)]
pub struct ShapeClusters {
    /// The clusters as collocation patches: their area-weighted centre, their mean normal,
    /// their summed area.
    pub patches: Vec<ShapePatch>,
    /// Each fine patch's cluster.
    pub of: Vec<u32>,
}

impl ShapeClusters {
    /// Grid cells of the patches' centres, each cell's patches apart by the way they face
    /// (the major axis of the normal and its sign: a thin part's two faces never share a
    /// cluster), the cells grown until at most `most` clusters are left.
    pub fn new(patches: &[ShapePatch], most: usize) -> Self {
        let most = most.max(1);
        let area: f64 = patches.iter().map(|p| p.area).sum();
        let mut cell = (area / most as f64).sqrt().max(1e-9);
        loop {
            let mut index = std::collections::HashMap::new();
            let of: Vec<u32> = patches
                .iter()
                .map(|p| {
                    let k = (p.centre / cell).floor().as_i64vec3();
                    let facing = super::patches::normal_axis(p.normal.as_vec3());
                    let next = index.len() as u32;
                    *index.entry((k.x, k.y, k.z, facing)).or_insert(next)
                })
                .collect();
            if index.len() <= most {
                return Self::gathered(patches, of, index.len());
            }
            cell *= 1.1;
        }
    }

    fn gathered(patches: &[ShapePatch], of: Vec<u32>, count: usize) -> Self {
        // Per cluster: area-weighted centre and normal, area, and a member's normal (where
        // the mean cancels).
        let mut sums = vec![(DVec3::ZERO, DVec3::ZERO, 0.0f64, DVec3::ZERO); count];
        for (p, &c) in patches.iter().zip(&of) {
            let s = &mut sums[c as usize];
            s.0 += p.centre * p.area;
            s.1 += p.normal * p.area;
            s.2 += p.area;
            if s.3 == DVec3::ZERO {
                s.3 = p.normal;
            }
        }
        // Collocated at the area-weighted centre, the midpoint rule of the cluster's own
        // integral: at the member nearest it (a point on the surface, but up to half a patch
        // off the middle), a back-lit marble ball of 3680 patches on 2048 clusters scored
        // 0.083 instead of 0.076 (`docs/translucent.md`).
        let patches = sums
            .iter()
            .map(|&(weighted, normal, area, member_normal)| ShapePatch {
                centre: weighted / area.max(1e-300),
                normal: normal.try_normalize().unwrap_or(member_normal),
                area,
            })
            .collect();
        Self { patches, of }
    }
}

/// Jensen's dipole for one colour channel: `α′/2`, `σtr`, and the real and virtual sources'
/// distances from the surface (mm).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DipoleChannel {
    /// `α′/2` (or what a rescaled total makes of it).
    pub half_albedo: f64,
    /// `σtr = √(3 σa σt′)`, mm⁻¹.
    pub sigma_tr: f64,
    /// `z_r = 1/σt′`, mm.
    pub z_real: f64,
    /// `z_v = z_r + 4AD`, mm.
    pub z_virtual: f64,
    /// `D = 1/(3σt′)`, mm.
    pub diffusion: f64,
    /// The boundary's `A = (1 + F_dr)/(1 − F_dr)`.
    pub boundary: f64,
}

impl DipoleChannel {
    /// The fluence `φ` of the pair of sources of flux entering at `entry` (outward normal
    /// `entry_normal`: the real source `z_r` under it, the virtual one `z_v` above), and its
    /// flux `−D ∂φ/∂n` along `exit_normal`, at `exit` — per unit flux, positions in mm. Where
    /// exit and entry share one plane the flux is `R_d(r)`.
    pub fn fields(
        &self,
        entry: DVec3,
        entry_normal: DVec3,
        exit: DVec3,
        exit_normal: DVec3,
    ) -> (f64, f64) {
        let d = self.diffusion;
        // Per source at `s`: `e^(−σ r)/r` and `(x − s)·n (σ r + 1) e^(−σ r)/r³`.
        let source = |s: DVec3| {
            let to_exit = exit - s;
            let r = to_exit.length().max(1e-9);
            let e = (-self.sigma_tr * r).exp();
            (
                e / r,
                to_exit.dot(exit_normal) * (self.sigma_tr * r + 1.0) * e / (r * r * r),
            )
        };
        let (real_phi, real_flux) = source(entry - self.z_real * entry_normal);
        let (virtual_phi, virtual_flux) = source(entry + self.z_virtual * entry_normal);
        let scale = self.half_albedo / (2.0 * PI);
        (
            scale / d * (real_phi - virtual_phi),
            scale * (real_flux - virtual_flux),
        )
    }

    /// Jensen's `R_d(r)`, mm⁻²: the exitance at distance `r` on the entry's own plane per
    /// unit flux, `α′/(4π) Σ_{z ∈ {z_r, z_v}} z (σtr d + 1) e^(−σtr d) / d³`, `d = √(r² + z²)`.
    pub fn reflectance(&self, r: f64) -> f64 {
        let source = |z: f64| {
            let d = (r * r + z * z).sqrt();
            z * (self.sigma_tr * d + 1.0) * (-self.sigma_tr * d).exp() / (d * d * d)
        };
        self.half_albedo / (2.0 * PI) * (source(self.z_real) + source(self.z_virtual))
    }

    /// `W(R) = ∫₀^R 2π r R_d(r) dr`, closed form: `α′/2 Σ z (e^(−σtr z)/z − e^(−σtr d)/d)`.
    pub fn within(&self, radius: f64) -> f64 {
        let part = |z: f64| {
            let d = (radius * radius + z * z).sqrt();
            (-self.sigma_tr * z).exp() - z * (-self.sigma_tr * d).exp() / d
        };
        self.half_albedo * (part(self.z_real) + part(self.z_virtual))
    }

    /// `W(∞) = α′/2 (e^(−σtr z_r) + e^(−σtr z_v))`: the slab's total diffuse reflectance.
    pub fn total(&self) -> f64 {
        self.half_albedo
            * ((-self.sigma_tr * self.z_real).exp() + (-self.sigma_tr * self.z_virtual).exp())
    }

    /// [`fields`](Self::fields) on the entry's own plane at distance `r`: `(φ(r), R_d(r))`.
    fn plane_fields(&self, r: f64) -> (f64, f64) {
        self.fields(DVec3::ZERO, DVec3::Z, DVec3::new(r, 0.0, 0.0), DVec3::Z)
    }
}

/// The correction of [`module docs`](self) for one object and channel: row-major `N × N`,
/// entry `(i, k)` the share of the flux entering at patch `k` that leaves through patch `i`
/// beyond the oriented dipole's `J_k(x_i) a_i`. `None` if the system is singular (it is not
/// for a closed object: `½ I` dominates).
pub fn boundary_correction(patches: &[ShapePatch], channel: DipoleChannel) -> Option<Vec<f64>> {
    let n = patches.len();
    if n == 0 {
        return Some(Vec::new());
    }
    let sigma = channel.sigma_tr;
    let d = channel.diffusion;
    let a = channel.boundary;
    let rho = |p: &ShapePatch| (p.area / PI).sqrt();
    let closed = is_closed(patches);

    // b: the dipole's residual on the real surface less its residual on its own plane.
    let residual_rows = parallel_rows(n, |i| {
        let x = &patches[i];
        (0..n)
            .map(|k| {
                if k == i {
                    return 0.0;
                }
                let entry = &patches[k];
                let (phi, flux) = channel.fields(entry.centre, entry.normal, x.centre, x.normal);
                let (plane_phi, plane_flux) = channel.plane_fields(entry.centre.distance(x.centre));
                (phi - 2.0 * a * flux) - (plane_phi - 2.0 * a * plane_flux)
            })
            .collect::<Vec<_>>()
    });
    let b: Vec<f64> = residual_rows.into_iter().flatten().collect();

    // Row by row: the system `½ I + S + K` (the self terms over the patch's disc), and the
    // right-hand sides, one column per entry patch, `(½ I + K) b`.
    let rows = parallel_rows(n, |i| {
        let x = &patches[i];
        let rho_i = rho(x);
        let mut system = vec![0.0; n];
        let mut half_plus_double = vec![0.0; n];
        // Σ_{j≠i} of the double layer without absorption, for the self term on a closed
        // surface (Gauss); on an open one, the normal curvatures towards the neighbours.
        let mut others_solid_angle = 0.0;
        let (mut curvature, mut neighbours) = (0.0, 0);
        let reach = 3.0 * rho_i;
        for (j, y) in patches.iter().enumerate() {
            if j == i {
                continue;
            }
            let to_y = y.centre - x.centre;
            let r = to_y.length().max(1e-9);
            let e = (-sigma * r).exp();
            let single = y.area * e / (4.0 * PI * d * r) / (2.0 * a);
            let solid_angle = -y.area / (4.0 * PI * r * r) * to_y.dot(y.normal) / r;
            let double = (1.0 + sigma * r) * e * solid_angle;
            system[j] = single + double;
            half_plus_double[j] = double;
            others_solid_angle += solid_angle;
            if r < reach {
                // Normal curvature towards y; their mean over directions is H.
                curvature += -2.0 * to_y.dot(x.normal) / (r * r);
                neighbours += 1;
            }
        }
        let single = if sigma * rho_i > 1e-9 {
            -(-sigma * rho_i).exp_m1() / (2.0 * d * sigma) / (2.0 * a)
        } else {
            rho_i / (2.0 * d) / (2.0 * a)
        };
        // Gauss: the double layer of `1/(4πr)` over a closed surface is −½ at each of its
        // points, so the patch's own share is what the others leave of it. Near the patch
        // `(1 + σr)e^(−σr) = 1 − O(σ²r²)`, so absorption does not change it to first order;
        // and since the others are each taken at their centre, this also cancels the error
        // of that one-point rule in the row's sum (the curvature's `−ρH/4` left it: the
        // bunny's rows missed −½ by 0.08 at the 90th percentile). An open surface misses
        // its hole's solid angle over 4π (0.15 at a hemisphere's pole), so there the
        // curvature's stands.
        let double = if closed {
            -0.5 - others_solid_angle
        } else {
            let mean_curvature = if neighbours > 0 { curvature / neighbours as f64 } else { 0.0 };
            -rho_i * mean_curvature / 4.0
        }
        .clamp(-0.25, 0.25);
        system[i] = 0.5 + single + double;
        half_plus_double[i] = 0.5 + double;
        let mut rhs = vec![0.0; n];
        for (j, &m) in half_plus_double.iter().enumerate() {
            if m != 0.0 {
                for (o, &v) in rhs.iter_mut().zip(&b[j * n..(j + 1) * n]) {
                    *o += m * v;
                }
            }
        }
        (system, rhs)
    });
    let (mut system, mut u): (Vec<f64>, Vec<f64>) = rows.into_iter().fold(
        (Vec::with_capacity(n * n), Vec::with_capacity(n * n)),
        |(mut m, mut r), (row, rhs)| {
            m.extend(row);
            r.extend(rhs);
            (m, r)
        },
    );
    solve_in_place(&mut system, n, &mut u)?;
    for (i, p) in patches.iter().enumerate() {
        for v in &mut u[i * n..(i + 1) * n] {
            *v *= p.area / (2.0 * a);
        }
    }
    Some(u)
}

/// The most `|Σ aᵢ nᵢ| / Σ aᵢ` of an object's patches that [`boundary_correction`] takes for a
/// closed surface (0 for one, by the divergence theorem; ½ for a hemisphere's shell, 1 for a
/// flat sheet). The accuracy suite's ball, bunny and torus hold at most 0.002.
pub const MAX_CLOSED_NORMAL_SUM: f64 = 0.02;

/// Whether `patches` close a surface, as far as their area-weighted normals tell
/// ([`MAX_CLOSED_NORMAL_SUM`]; a tube open at both ends passes).
pub fn is_closed(patches: &[ShapePatch]) -> bool {
    let (normals, area) = patches
        .iter()
        .fold((DVec3::ZERO, 0.0), |(v, a), p| (v + p.normal * p.area, a + p.area));
    area > 0.0 && normals.length() <= MAX_CLOSED_NORMAL_SUM * area
}

/// Solves `M X = B` for the row-major `n × n` matrix `M` (overwritten by its LU factors) and
/// the row-major `n × m` right-hand sides `B` (overwritten by `X`, `m = B.len() / n`): LU with
/// partial pivoting, the updates of rows and of columns of `B` spread over the cores. `None`
/// if a pivot vanishes.
pub fn solve_in_place(matrix: &mut [f64], n: usize, rhs: &mut [f64]) -> Option<()> {
    let m = rhs.len() / n.max(1);
    let threads = std::thread::available_parallelism().map_or(1, |t| t.get());
    let mut pivots = vec![0usize; n];
    for p in 0..n {
        let (best, value) = (p..n)
            .map(|r| (r, matrix[r * n + p].abs()))
            .fold((p, -1.0), |a, b| if b.1 > a.1 { b } else { a });
        if !(value > 1e-300) {
            return None;
        }
        pivots[p] = best;
        if best != p {
            for c in 0..n {
                matrix.swap(p * n + c, best * n + c);
            }
        }
        let (top, below) = matrix.split_at_mut((p + 1) * n);
        let pivot_row = &top[p * n..];
        let pivot = pivot_row[p];
        let rows = below.chunks_mut(n).collect::<Vec<_>>();
        let per = rows.len().div_ceil(threads).max(16);
        std::thread::scope(|scope| {
            let mut rows = rows;
            while !rows.is_empty() {
                let take = per.min(rows.len());
                let chunk: Vec<&mut [f64]> = rows.drain(..take).collect();
                let work = move || {
                    for row in chunk {
                        let l = row[p] / pivot;
                        row[p] = l;
                        if l != 0.0 {
                            for (v, &q) in row[p + 1..].iter_mut().zip(&pivot_row[p + 1..]) {
                                *v -= l * q;
                            }
                        }
                    }
                };
                if rows.is_empty() {
                    work();
                } else {
                    scope.spawn(work);
                }
            }
        });
    }
    // The right-hand sides by bands of columns, each band on its own core.
    let band = m.div_ceil(threads).max(1);
    let matrix = &*matrix;
    let pivots = &pivots;
    let mut bands: Vec<Vec<f64>> = (0..m.div_ceil(band))
        .map(|t| {
            let (c0, c1) = (t * band, ((t + 1) * band).min(m));
            (0..n)
                .flat_map(|r| rhs[r * m + c0..r * m + c1].iter().copied())
                .collect()
        })
        .collect();
    std::thread::scope(|scope| {
        for (t, x) in bands.iter_mut().enumerate() {
            let w = ((t + 1) * band).min(m) - t * band;
            scope.spawn(move || {
                for (p, &q) in pivots.iter().enumerate() {
                    if q != p {
                        for c in 0..w {
                            x.swap(p * w + c, q * w + c);
                        }
                    }
                }
                // L y = P b (unit lower), then U x = y.
                for r in 0..n {
                    let (done, rest) = x.split_at_mut(r * w);
                    let row = &mut rest[..w];
                    for (j, &l) in matrix[r * n..r * n + r].iter().enumerate() {
                        if l != 0.0 {
                            for (v, &y) in row.iter_mut().zip(&done[j * w..(j + 1) * w]) {
                                *v -= l * y;
                            }
                        }
                    }
                }
                for r in (0..n).rev() {
                    let (head, tail) = x.split_at_mut((r + 1) * w);
                    let row = &mut head[r * w..];
                    for (j, &u) in matrix[r * n + r + 1..(r + 1) * n].iter().enumerate() {
                        if u != 0.0 {
                            let y = &tail[j * w..(j + 1) * w];
                            for (v, &yy) in row.iter_mut().zip(y) {
                                *v -= u * yy;
                            }
                        }
                    }
                    let diagonal = matrix[r * n + r];
                    for v in row.iter_mut() {
                        *v /= diagonal;
                    }
                }
            });
        }
    });
    for (t, x) in bands.iter().enumerate() {
        let (c0, c1) = (t * band, ((t + 1) * band).min(m));
        let w = c1 - c0;
        for r in 0..n {
            rhs[r * m + c0..r * m + c1].copy_from_slice(&x[r * w..(r + 1) * w]);
        }
    }
    Some(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// LU against a product: `M X = B` for a random well-conditioned `M`.
    #[test]
    fn the_dense_solve_inverts_a_product() {
        let n = 37;
        let mut seed = 7u64;
        let mut random = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let matrix: Vec<f64> = (0..n * n)
            .map(|k| random() + if k % (n + 1) == 0 { 0.1 } else { 0.0 })
            .collect();
        let m = 5;
        let x: Vec<f64> = (0..n * m).map(|_| random()).collect();
        let mut b = vec![0.0; n * m];
        for r in 0..n {
            for c in 0..m {
                b[r * m + c] = (0..n).map(|j| matrix[r * n + j] * x[j * m + c]).sum();
            }
        }
        let mut lu = matrix.clone();
        solve_in_place(&mut lu, n, &mut b).unwrap();
        let worst = b
            .iter()
            .zip(&x)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-9, "{worst}");
        // A singular matrix says so.
        let mut zero = vec![0.0; 4];
        assert!(solve_in_place(&mut zero, 2, &mut [1.0, 1.0]).is_none());
    }

    /// On a plane the dipole is the solution: the correction vanishes.
    #[test]
    fn on_a_plane_the_correction_vanishes() {
        let channel = DipoleChannel {
            half_albedo: 0.45,
            sigma_tr: 0.27,
            z_real: 1.3,
            z_virtual: 1.3 * (1.0 + 4.0 / 3.0),
            diffusion: 1.3 / 3.0,
            boundary: 1.0,
        };
        let patches: Vec<ShapePatch> = (0..100)
            .map(|k| ShapePatch {
                centre: DVec3::new((k % 10) as f64, (k / 10) as f64, 0.0),
                normal: DVec3::Z,
                area: 1.0,
            })
            .collect();
        let u = boundary_correction(&patches, channel).unwrap();
        assert!(u.iter().all(|v| v.abs() < 1e-12));
        // And the dipole's own flux on its plane is `R_d`.
        let (_, flux) = channel.plane_fields(2.0);
        let r_d = {
            let s = |z: f64| {
                let d = (4.0 + z * z).sqrt();
                z * (0.27 * d + 1.0) * (-0.27 * d).exp() / (d * d * d)
            };
            0.45 / (2.0 * PI) * (s(1.3) + s(1.3 * (1.0 + 4.0 / 3.0)))
        };
        assert!((flux - r_d).abs() < 1e-12 * r_d.max(1.0));
    }
}
