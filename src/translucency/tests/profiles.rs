use super::*;

/// `∫_a^b f` by 64-point Gauss–Legendre on each of `pieces` log-spaced pieces.
fn integrate_log(f: impl Fn(f64) -> f64, a: f64, b: f64, pieces: usize) -> f64 {
    let (la, lb) = (a.ln(), b.ln());
    (0..pieces)
        .map(|k| {
            let x0 = (la + (lb - la) * k as f64 / pieces as f64).exp();
            let x1 = (la + (lb - la) * (k + 1) as f64 / pieces as f64).exp();
            gauss_legendre_64()
                .iter()
                .map(|&(t, w)| {
                    let x = 0.5 * (x0 + x1) + 0.5 * (x1 - x0) * t;
                    w * 0.5 * (x1 - x0) * f(x)
                })
                .sum::<f64>()
        })
        .sum()
}

#[test]
fn the_dipole_profile_integrates_to_jensens_total_diffuse_reflectance() {
    for preset in [
        TranslucentPreset::Marble,
        TranslucentPreset::Skin1,
        TranslucentPreset::Ketchup,
    ] {
        let medium = preset.medium();
        let profile = DiffusionProfile::new(&medium, DiffusionKernel::Dipole);
        let total = profile.total_reflectance();
        for c in 0..3 {
            // Jensen 2001 eq. (5), written out independently of the profile's code.
            let (sa, ss) = (
                medium.absorption[c] as f64,
                medium.reduced_scattering[c] as f64,
            );
            let alpha = ss / (sa + ss);
            let f_dr = jensen_internal_diffuse_reflectance(medium.index_of_refraction as f64);
            let a = (1.0 + f_dr) / (1.0 - f_dr);
            let root = (3.0 * (1.0 - alpha)).sqrt();
            let jensen = alpha / 2.0 * (1.0 + (-4.0 / 3.0 * a * root).exp()) * (-root).exp();
            assert!(
                (total[c] - jensen).abs() < 1e-12 * jensen.max(1e-3),
                "{preset:?} {c}: {} vs {jensen}",
                total[c]
            );
            // The profile itself integrated numerically, whole and within one diffusion length.
            let numeric =
                integrate_log(|r| 2.0 * PI * r * profile.reflectance(r)[c], 1e-7, 1e5, 400);
            assert!(
                (numeric - total[c]).abs() < 1e-6 * total[c],
                "{preset:?} {c}: ∫ = {numeric}, W∞ = {}",
                total[c]
            );
            let radius = 1.0 / (3.0 * sa * (sa + ss)).sqrt();
            let numeric = integrate_log(
                |r| 2.0 * PI * r * profile.reflectance(r)[c],
                1e-7,
                radius,
                300,
            );
            let closed = profile.reflectance_within(radius)[c];
            assert!(
                (numeric - closed).abs() < 1e-6 * closed,
                "{preset:?} {c}: {numeric} vs {closed}"
            );
        }
    }
}

#[test]
fn the_burley_profile_integrates_to_its_fitted_albedo() {
    let medium = TranslucentPreset::Skin1.medium();
    let burley = DiffusionProfile::new(&medium, DiffusionKernel::Burley);
    for c in 0..3 {
        let numeric = integrate_log(|r| 2.0 * PI * r * burley.reflectance(r)[c], 1e-9, 1e4, 400);
        let total = burley.total_reflectance()[c];
        assert!(
            (numeric - total).abs() < 1e-6 * total,
            "{c}: {numeric} vs {total}"
        );
        // A is the inverse of Chiang et al.'s fit at the medium's albedo.
        let (a, s) = (
            medium.absorption[c] as f64,
            medium.reduced_scattering[c] as f64,
        );
        assert!((crate::translucency::diffusion::single_scattering_albedo_of(total) - s / (a + s)).abs() < 1e-9);
    }
    // Its ends: no scattering reflects nothing, no absorption everything.
    assert!(crate::translucency::diffusion::surface_albedo(0.0) < 1e-3);
    assert!(crate::translucency::diffusion::surface_albedo(1.0) > 0.999);
}

/// Chandrasekhar's `H(μ)` for isotropic scattering by iterating its integral equation
/// `1/H(μ) = √(1 − α) + α/2 ∫₀¹ μ′ H(μ′)/(μ + μ′) dμ′` on 64 Gauss–Legendre nodes (a fixed
/// point; 4000 rounds reach 1e-9 at α = 0.999): nodes and values.
pub(super) fn h_by_iteration(alpha: f64) -> Vec<(f64, f64, f64)> {
    let nodes: Vec<(f64, f64)> = gauss_legendre_64()
        .iter()
        .map(|&(t, w)| (0.5 * (t + 1.0), 0.5 * w))
        .collect();
    let mut h = vec![1.0; nodes.len()];
    for _ in 0..4000 {
        h = nodes
            .iter()
            .map(|&(mu, _)| {
                let integral: f64 =
                    nodes.iter().zip(&h).map(|(&(m, w), &hm)| w * m * hm / (mu + m)).sum();
                1.0 / ((1.0 - alpha).sqrt() + 0.5 * alpha * integral)
            })
            .collect();
    }
    nodes.iter().zip(h).map(|(&(mu, w), h)| (mu, w, h)).collect()
}

#[test]
fn a_beams_plane_albedo_follows_chandrasekhar_and_averages_to_burleys() {
    use crate::translucency::diffusion::{IncidenceWeight, chandrasekhar_h, collimated_albedo, surface_albedo};
    // Skin's three channels, marble's red, and both ends.
    for alpha in [0.3, 0.6779, 0.8381, 0.9585, 0.999, 0.99999] {
        let exact = h_by_iteration(alpha);
        // Hapke's closed form: measured within 0.96 % of the integral equation.
        let worst = exact
            .iter()
            .map(|&(mu, _, h)| (chandrasekhar_h(alpha, mu) / h - 1.0).abs())
            .fold(0.0, f64::max);
        assert!(worst < 0.01, "α {alpha}: H off by {worst}");
        // Under diffuse light the plane albedo's mean is the slab's diffuse albedo: the `A`
        // of Chiang et al.'s Monte Carlo fit that Burley's profile carries. Measured within
        // 0.003 (exact H) and 0.004 (Hapke's); asserted 0.005.
        let diffuse_exact: f64 = exact
            .iter()
            .map(|&(mu, w, h)| 2.0 * w * mu * (1.0 - h * (1.0 - alpha).sqrt()))
            .sum();
        let diffuse_closed: f64 = exact
            .iter()
            .map(|&(mu, w, _)| 2.0 * w * mu * collimated_albedo(alpha, mu))
            .sum();
        let a = surface_albedo(alpha);
        assert!((diffuse_exact - a).abs() < 0.005, "α {alpha}: {diffuse_exact} vs Chiang {a}");
        assert!((diffuse_closed - a).abs() < 0.005, "α {alpha}: {diffuse_closed} vs Chiang {a}");
    }
    // The weight: 1 on average under diffuse light, with or without a boundary (a finer
    // rule than its own 8 points); index-matched, more at grazing incidence than at normal;
    // behind a boundary of glass's index, less (Fresnel turns grazing light away).
    for eta in [1.0, 1.4] {
        let weight = IncidenceWeight::new([0.6779, 0.9585, 0.999], eta);
        let n = 20_000;
        let mut mean = [0.0; 3];
        for k in 0..n {
            let mu = (k as f64 + 0.5) / n as f64;
            let w = weight.at(mu);
            for c in 0..3 {
                mean[c] += 2.0 * mu * w[c] / n as f64;
            }
        }
        for c in 0..3 {
            assert!((mean[c] - 1.0).abs() < 2e-3, "η {eta}, channel {c}: diffuse mean {}", mean[c]);
            assert_eq!(weight.at(0.1)[c] > weight.at(1.0)[c], eta == 1.0, "η {eta}, channel {c}");
        }
    }
    // Index-matched skin blue (α 0.678): 0.83 of the diffuse albedo at normal incidence,
    // 1.54 at μ = 0.1 (Chandrasekhar: 0.195 and 0.371 against 0.241).
    let blue = IncidenceWeight::new([0.6779; 3], 1.0);
    assert!((blue.at(1.0)[0] - 0.195 / 0.241).abs() < 0.02, "{:?}", blue.at(1.0));
    assert!((blue.at(0.1)[0] - 0.371 / 0.241).abs() < 0.03, "{:?}", blue.at(0.1));
}

#[test]
fn diffuse_fresnel_reflectance_matches_known_values() {
    // Hemispherical reflectance of a smooth dielectric lit diffusely from outside: about
    // 0.066 for water (η 1.333) and 0.092 for glass (η 1.5); 0 without a boundary.
    assert!(diffuse_fresnel_reflectance(1.0).abs() < 1e-9);
    let water = diffuse_fresnel_reflectance(1.333);
    let glass = diffuse_fresnel_reflectance(1.5);
    assert!((water - 0.066).abs() < 0.002, "water {water}");
    assert!((glass - 0.092).abs() < 0.002, "glass {glass}");
}

#[test]
fn patch_transfer_keeps_the_profiles_energy_over_a_plane() {
    // A flat grid of patches about one entry point: Σ transfer over the grid ≈ W over the
    // grid's disc, even with patches as wide as the profile (skin's blue channel).
    let profile =
        DiffusionProfile::new(&TranslucentPreset::Skin1.medium(), DiffusionKernel::Dipole);
    for size in [0.05, 0.5, 2.0] {
        let n = (40.0 / size) as i32;
        let mut sum = [0.0; 3];
        for y in -n..=n {
            for x in -n..=n {
                let r = ((x * x + y * y) as f64).sqrt() * size;
                let t = profile.patch_transfer(r, size * size);
                for c in 0..3 {
                    sum[c] += t[c];
                }
            }
        }
        let total = profile.total_reflectance();
        for c in 0..3 {
            let kept = sum[c] / total[c];
            eprintln!("patch {size} mm, channel {c}: {kept:.4}");
            // Measured 0.967 – 1.00 (worst: 0.5 mm patches, blue).
            assert!(
                (kept - 1.0).abs() < 0.04,
                "patch {size} mm, channel {c}: {kept}"
            );
        }
    }
}

#[test]
fn the_oriented_dipole_is_the_flat_profile_on_a_plane() {
    use bevy::math::DVec3;
    for kernel in [DiffusionKernel::Dipole, DiffusionKernel::ScaledDipole, DiffusionKernel::Burley] {
        let profile = DiffusionProfile::new(&TranslucentPreset::Marble.medium(), kernel);
        let normal = DVec3::new(0.3, 0.4, 0.5).normalize();
        let (t, b) = normal.any_orthonormal_pair();
        let entry = DVec3::new(1.0, -2.0, 0.5);
        for r in [0.01, 0.3, 1.0, 4.0, 30.0] {
            let exit = entry + r * (0.6 * t + 0.8 * b);
            let factor = profile.orientation_factor(entry, normal, exit, normal);
            for f in factor {
                assert!((f - 1.0).abs() < 1e-9, "{kernel:?} at {r} mm: {factor:?}");
            }
        }
    }
}

/// Holds a model's share of light to random walks' in an index-matched `preset`: `walked` the
/// walks' share, `through(profile, oriented)` the scaled dipole's with the orientation factor
/// (`true`) and without it (the flat profile), each to its measured ratio ±0.05.
fn holds_to_walks(
    case: &str,
    preset: TranslucentPreset,
    walked: impl Fn(&TranslucentMedium) -> f64,
    through: impl Fn(&DiffusionProfile, bool) -> f64,
    oriented_ratio: f64,
    flat_ratio: f64,
) {
    let medium = TranslucentMedium {
        index_of_refraction: 1.0,
        ..preset.medium()
    };
    let profile = DiffusionProfile::new(&medium, DiffusionKernel::ScaledDipole);
    let walked = walked(&medium);
    let oriented = through(&profile, true) / walked;
    let flat = through(&profile, false) / walked;
    eprintln!("{case}: walks {walked:.5}, oriented {oriented:.3}×, flat {flat:.3}×");
    assert!(
        (oriented - oriented_ratio).abs() < 0.05 && (flat - flat_ratio).abs() < 0.05,
        "{case}: oriented {oriented:.3}× (measured {oriented_ratio}), flat {flat:.3}× (measured {flat_ratio})"
    );
}

/// Across a slab, the oriented dipole's flux through the far face is the leading term of
/// diffusion theory's slab transmittance (Contini et al. 1997, their `m = 0` image pair). Held
/// to random walks through index-matched slabs (16 384 walks a channel, the channels where
/// enough cross to count): skin 2.5–10 mm thick carries 0.83–0.87 (red) and 0.92–1.13 (green,
/// 2.5–5 mm) of the walks' transmission, where the flat profile at the same distances carries
/// 0.32–0.77 and 0.24–0.42; marble (red) 0.60–0.62 against 0.26–0.87 — at its low absorption
/// the further images of the slab's two faces, which the pair leaves out, carry a third of
/// the light. Measured ratios, held within ±0.05 (the walks' seeds fixed).
#[test]
fn the_oriented_dipole_carries_a_slabs_transmission_where_the_flat_profile_does_not() {
    use crate::translucency::random_walk::slab_exits;
    use bevy::math::DVec3;
    // (medium, thickness mm, channel, oriented ÷ walks, flat ÷ walks), measured.
    let cases = [
        (TranslucentPreset::Skin1, 2.5, 0, 0.867, 0.771),
        (TranslucentPreset::Skin1, 5.0, 0, 0.864, 0.569),
        (TranslucentPreset::Skin1, 10.0, 0, 0.831, 0.323),
        (TranslucentPreset::Skin1, 2.5, 1, 1.125, 0.416),
        (TranslucentPreset::Skin1, 5.0, 1, 0.918, 0.235),
        (TranslucentPreset::Marble, 5.0, 0, 0.601, 0.865),
        (TranslucentPreset::Marble, 10.0, 0, 0.617, 0.527),
        (TranslucentPreset::Marble, 20.0, 0, 0.600, 0.263),
    ];
    for (preset, thickness, c, oriented_ratio, flat_ratio) in cases {
        let transmitted = |medium: &TranslucentMedium| {
            slab_exits(medium, thickness as f32, 16384, 3).unwrap().1[c] as f64
        };
        // ∫ 2πρ R(ρ) dρ over the far face, with and without the orientation factor.
        let through = |profile: &DiffusionProfile, oriented: bool| {
            integrate_log(
                |rho| {
                    let exit = DVec3::new(rho, 0.0, -thickness);
                    let factor = if oriented {
                        profile.orientation_factor(DVec3::ZERO, DVec3::Z, exit, -DVec3::Z)[c]
                    } else {
                        1.0
                    };
                    2.0 * PI * rho * profile.reflectance(exit.length())[c] * factor
                },
                1e-4,
                1e3,
                48,
            )
        };
        let case = format!("{preset:?} {thickness} mm, channel {c}");
        holds_to_walks(&case, preset, transmitted, through, oriented_ratio, flat_ratio);
    }
}

/// At a right-angled convex edge (the quarter-space `x, y < 0`, light entering the face
/// `y = 0` at 1–10 mm from the edge), the share leaving through the other face: both the flat
/// profile and the oriented dipole carry less than random walks (16 384 a channel). For skin
/// the oriented dipole is the closer (0.81–0.91 of the walks in red, 1.06–1.09 in green,
/// against 0.58–0.70 and 0.56); for marble, neither (0.66–0.70 against 0.60–0.88). Measured
/// ratios, held within ±0.05.
#[test]
fn at_a_convex_edge_the_profiles_carry_less_round_the_corner_than_walks() {
    use crate::translucency::random_walk::edge_exits;
    use bevy::math::DVec3;
    // (medium, distance from the edge mm, channel, oriented ÷ walks, flat ÷ walks), measured.
    let cases = [
        (TranslucentPreset::Skin1, 1.0, 0, 0.910, 0.673),
        (TranslucentPreset::Skin1, 3.0, 0, 0.896, 0.697),
        (TranslucentPreset::Skin1, 6.0, 0, 0.813, 0.581),
        (TranslucentPreset::Skin1, 1.0, 1, 1.088, 0.562),
        (TranslucentPreset::Skin1, 3.0, 1, 1.064, 0.563),
        (TranslucentPreset::Marble, 2.0, 0, 0.703, 0.881),
        (TranslucentPreset::Marble, 5.0, 0, 0.685, 0.749),
        (TranslucentPreset::Marble, 10.0, 0, 0.659, 0.599),
    ];
    for (preset, distance, c, oriented_ratio, flat_ratio) in cases {
        let round = |medium: &TranslucentMedium| {
            edge_exits(medium, distance as f32, 16384, 5).unwrap().1[c] as f64
        };
        let entry = DVec3::new(-distance, 0.0, 0.0);
        // ∫∫ over the face x = 0 (y < 0, both signs of z).
        let through = |profile: &DiffusionProfile, oriented: bool| {
            integrate_log(
                |y| {
                    integrate_log(
                        |z| {
                            let exit = DVec3::new(0.0, -y, z);
                            let factor = if oriented {
                                profile.orientation_factor(entry, DVec3::Y, exit, DVec3::X)[c]
                            } else {
                                1.0
                            };
                            2.0 * profile.reflectance(exit.distance(entry))[c] * factor
                        },
                        1e-4,
                        1e3,
                        24,
                    )
                },
                1e-4,
                1e3,
                24,
            )
        };
        let case = format!("{preset:?} {distance} mm from the edge, channel {c}");
        holds_to_walks(&case, preset, round, through, oriented_ratio, flat_ratio);
    }
}

#[test]
fn the_gpu_injections_incidence_table_interpolates_the_weights_it_holds() {
    use crate::translucency::diffusion::{
        IncidenceWeight, diffuse_single_scattering_shape, single_scattering_shape,
    };
    use crate::translucency::injection::{INCIDENCE_TABLE_SIZE, incidence_table};
    let weight =
        IncidenceWeight::new(TranslucentPreset::Skin1.medium().single_scattering_albedo(), 1.3);
    let table = incidence_table(Some(&weight));
    assert_eq!(table.len(), INCIDENCE_TABLE_SIZE as usize);
    let last = (INCIDENCE_TABLE_SIZE - 1) as f64;
    let exact = |cos: f64| {
        let w = weight.at(cos);
        let shape = single_scattering_shape(cos) - diffuse_single_scattering_shape();
        [w[0], w[1], w[2], shape]
    };
    // At its cosines: the weights themselves (to f32).
    for (i, entry) in table.iter().enumerate() {
        let e = exact(i as f64 / last);
        for c in 0..4 {
            assert!((entry[c] as f64 - e[c]).abs() < 1e-6, "{i} {c}");
        }
    }
    // Between them (the shader's linear interpolation), at μ ≥ 0.05: the weights within
    // 0.2 % (measured 0.086 %, where Fresnel steepens at grazing incidence), the shape within
    // 5e-4 of the single-scattering factor (measured 1.4e-4).
    let (mut worst_weight, mut worst_shape) = (0.0f64, 0.0f64);
    for i in 0..INCIDENCE_TABLE_SIZE as usize - 1 {
        let cos = (i as f64 + 0.5) / last;
        if cos < 0.05 {
            continue;
        }
        let e = exact(cos);
        for c in 0..4 {
            let mid = 0.5 * (table[i][c] + table[i + 1][c]) as f64;
            let off = (mid - e[c]).abs();
            if c < 3 {
                worst_weight = worst_weight.max(off / e[c]);
            } else {
                worst_shape = worst_shape.max(off);
            }
        }
    }
    eprintln!("incidence table: weights {worst_weight:.2e}, shape {worst_shape:.2e}");
    assert!(worst_weight < 2e-3 && worst_shape < 5e-4, "{worst_weight} {worst_shape}");
    // No medium: a weight of one.
    assert!(incidence_table(None).iter().all(|e| e[..3] == [1.0; 3]));
}
