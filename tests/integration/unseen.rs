//! The unseen-content suite in CI (`examples/common/unseen/`, included by path): three of its
//! scenes — a photo-derived map seen top-down on the plane, an oblique whole sphere, the top of
//! a torus ring — rendered small, scored against the ray-cast truth of the displaced mesh.
//!
//! Each score is asserted at the value measured on the software driver (docs/accuracy.md,
//! "Unseen content") within a stated margin, in both directions: a change of the method that
//! moves a score by more than the margin fails here and must update the documented figure.

#[path = "../../examples/common/unseen/mod.rs"]
mod suite;

use bevy_mesostructure::prelude::*;

use crate::harness::{
    gpu_or_skip,
    headless::{self, headless_plugins},
};

/// Picture side, pixel step between scored pixels and AO rays per axis: small enough for CI
/// (the `accuracy` example runs the suite at 128², every 2nd pixel, 16 × 16 rays).
const SIZE: u32 = 96;
const STEP: u32 = 3;
const RINGS: u32 = 12;

/// Measured scores of one scene, and the margins they are held to.
struct Expected {
    scene: &'static str,
    ao_mae: f32,
    ao_bias: f32,
    shadow_recall: f32,
    shadow_precision: f32,
    bounce_rel_mae: f32,
    bounce_ratio: f32,
}

/// AO MAE and bias within ±0.01; recall, precision and the bounce's relative MAE and ratio
/// within ±0.05 (a few pixels' worth at this size, and the Monte-Carlo noise of 144 rays).
const AO_MARGIN: f32 = 0.01;
const RATIO_MARGIN: f32 = 0.05;

/// Scores one scene and returns what is off from the measured values (every score is printed
/// first, so that one run shows them all).
fn check(expected: &Expected, unit: f32) -> Vec<String> {
    let scene = suite::scenes()
        .into_iter()
        .find(|s| s.name == expected.scene)
        .unwrap_or_else(|| panic!("no scene {}", expected.scene));
    let r = suite::run_scene(headless_plugins, &scene, Mesostructure::default(), SIZE, STEP, unit, RINGS)
        .expect("the scene renders");
    let (p, n) = (&r.plugin, &r.none);
    eprintln!(
        "{}: {} pixels ({} light-facing), {:.2} texels/px; AO MAE {:.4} (none {:.4}) bias {:+.4}; \
         shadow recall {:.3} precision {:.3}; bounce rel. MAE {:.3} ratio {:.3}",
        scene.name,
        p.pixels,
        p.facing,
        p.texels_per_pixel,
        p.ao_mae,
        n.ao_mae,
        p.ao_bias,
        p.shadow_recall,
        p.shadow_precision,
        p.bounce_rel_mae,
        p.bounce_ratio
    );
    let mut off = vec![];
    if p.pixels <= 200 {
        off.push(format!("{}: too few pixels scored ({})", scene.name, p.pixels));
    }
    let mut near = |name: &str, got: f32, want: f32, margin: f32| {
        if (got - want).abs() > margin {
            off.push(format!("{}: {name} {got:.4}, measured {want:.4} ± {margin}", scene.name));
        }
    };
    near("AO MAE", p.ao_mae, expected.ao_mae, AO_MARGIN);
    near("AO bias", p.ao_bias, expected.ao_bias, AO_MARGIN);
    near("shadow recall", p.shadow_recall, expected.shadow_recall, RATIO_MARGIN);
    near("shadow precision", p.shadow_precision, expected.shadow_precision, RATIO_MARGIN);
    near("bounce relative MAE", p.bounce_rel_mae, expected.bounce_rel_mae, RATIO_MARGIN);
    near("bounce ratio", p.bounce_ratio, expected.bounce_ratio, RATIO_MARGIN);
    // And the method does better than no effect on AO wherever it is measured.
    if p.ao_mae >= n.ao_mae {
        off.push(format!("{}: AO no better than none", scene.name));
    }
    off
}

#[test]
fn unseen_content_scores_hold_their_measured_values() {
    if !gpu_or_skip() {
        return;
    }
    let unit = suite::radiance_unit(headless_plugins(), SIZE);
    let off: Vec<String> = EXPECTED.iter().flat_map(|e| check(e, unit)).collect();
    assert!(off.is_empty(), "{}", off.join("\n"));
}

/// Measured on the software driver (llvmpipe) with this test's size, step and rays
/// (`cargo test --test integration unseen_content -- --nocapture`); the goals are AO
/// MAE ≤ 0.04 with |bias| ≤ 0.015, micro-shadow recall ≥ 0.75 at precision ≥ 0.85, bounce
/// relative MAE ≤ 0.35 with the mean within ±15 %: on the full suite they are met on the
/// means, not in every scene (the torus seen from above has a handful of shadowed pixels;
/// docs/accuracy.md). The shadows' figures are with the light's visibility at each pixel's own
/// point (before it, the texels' 0s and 1s interpolated: recall 0.932 / 0.632 / 0.714,
/// precision 0.793 / 0.774 / 0.625); the bounce's with the first directional light's bounce
/// from texture space (before it: 0.358 / 0.684 / 0.313 and ratio 0.955 / 0.756 / 0.824); all
/// re-measured after the horizons were searched 4× as far (AO MAE was 0.0338 / 0.0776 /
/// 0.0506, bias +0.0123 / −0.0016 / +0.0401).
const EXPECTED: &[Expected] = &[
    Expected {
        scene: "plane/pebbles/top-down/light35",
        ao_mae: 0.0326,
        ao_bias: 0.0079,
        shadow_recall: 1.000,
        shadow_precision: 0.961,
        bounce_rel_mae: 0.250,
        bounce_ratio: 0.890,
    },
    Expected {
        scene: "sphere/cracked/oblique/light35",
        ao_mae: 0.0770,
        ao_bias: 0.0006,
        shadow_recall: 1.000,
        shadow_precision: 0.905,
        bounce_rel_mae: 0.289,
        bounce_ratio: 0.990,
    },
    Expected {
        scene: "torus/pebbles/top-down/light60",
        ao_mae: 0.0509,
        ao_bias: 0.0409,
        shadow_recall: 0.714,
        shadow_precision: 0.556,
        bounce_rel_mae: 0.278,
        bounce_ratio: 0.798,
    },
];

/// The ground truth itself, against closed forms, before it judges anything: a flat map on the
/// plane is open everywhere (AO 1), lit, and receives no bounce; on the inner equator of a torus
/// with a flat map the core's own occlusion shows.
#[test]
fn the_unseen_ground_truth_meets_closed_forms() {
    let flat = HeightMap::from_fn(16, 16, |_, _| 0.5);
    let plane = suite::GroundTruth::new(suite::Core::Plane, flat.clone(), 0.05, bevy::math::Vec2::ONE);
    let down = bevy::math::Vec3::NEG_Y;
    let light = bevy::math::Vec3::new(0.3, 0.8, 0.2).normalize();
    let t = plane
        .at(bevy::math::Vec3::new(0.1, 1.0, 0.2), down, light, 8, 8)
        .expect("the ray meets the plane");
    assert_eq!(t.ao, 1.0, "a flat plane is open");
    assert!(t.lit && t.facing && !t.core_shadowed);
    assert_eq!(t.bounce, 0.0, "nothing to bounce from");
    assert!((t.uv - bevy::math::Vec2::new(0.55, 0.6)).length() < 1e-4, "uv {}", t.uv);
    // Torus (R 0.75, r 0.25): the inner equator at (0, 0, 0.5), seen from the centre; its
    // normal points at the axis and the far side of the ring fills part of its hemisphere.
    let torus = suite::GroundTruth::new(suite::Core::Torus, flat, 0.002, bevy::math::Vec2::ONE);
    let t = torus
        .at(bevy::math::Vec3::new(0.0, 0.0, 0.1), bevy::math::Vec3::Z, bevy::math::Vec3::Y, 16, 16)
        .expect("the ray meets the ring");
    // Independent reference: the same cosine-weighted AO by sphere tracing the torus's exact
    // distance function in f64, 64 × 64 stratified directions.
    let sdf = |p: [f64; 3]| ((p[0].hypot(p[2]) - 0.75).powi(2) + p[1] * p[1]).sqrt() - 0.25;
    let (mut open, n) = (0.0, 64);
    for i in 0..n {
        for j in 0..n {
            let u1 = (i as f64 + 0.5) / n as f64;
            let phi = std::f64::consts::TAU * (j as f64 + 0.5) / n as f64;
            let (s, c) = (u1.sqrt(), (1.0 - u1).sqrt());
            // Normal −z; tangents x and y.
            let d = [s * phi.cos(), s * phi.sin(), -c];
            let (mut t, mut hit) = (1e-3, false);
            for _ in 0..100_000 {
                if t > 4.0 {
                    break;
                }
                let p = [d[0] * t, d[1] * t, 0.5 + d[2] * t];
                let h = sdf(p);
                if h < 1e-6 {
                    hit = true;
                    break;
                }
                t += h;
            }
            open += (!hit) as u32 as f64;
        }
    }
    let reference = open / (n * n) as f64;
    eprintln!("torus inner equator AO: ray-cast mesh {:.4}, sphere-traced {reference:.4}", t.ao);
    assert!(reference < 0.95, "the ring occludes itself there ({reference})");
    assert!(
        (t.ao as f64 - reference).abs() < 0.03,
        "torus inner equator AO {} against the sphere-traced {reference}",
        t.ao
    );
}

/// The mesh ray caster agrees with the crate's height-field ray marcher
/// (`reference::ground_truth`, the truth of the synthetic suite) on the plane: the same
/// photo-derived map, one tile over the 2 × 2 plane, points in its central half.
#[test]
fn the_unseen_ground_truth_agrees_with_the_height_field_marcher() {
    use bevy::math::{Vec2, Vec3};
    use bevy_mesostructure::reference::ground_truth::HeightField;
    let map = suite::height_map("pebbles");
    let k = 0.05;
    let mesh = suite::GroundTruth::new(suite::Core::Plane, map.clone(), k, Vec2::ONE);
    let field = HeightField::new(map.width, map.height, &map.values, 2.0, k);
    let (mut diff, mut bias, mut n) = (0.0, 0.0, 0);
    for j in 0..8 {
        for i in 0..8 {
            let uv = Vec2::new(0.25 + 0.5 * (i as f32 + 0.37) / 8.0, 0.25 + 0.5 * (j as f32 + 0.61) / 8.0);
            let above = Vec3::new(uv.x * 2.0 - 1.0, 1.0, uv.y * 2.0 - 1.0);
            let t = mesh
                .at(above, Vec3::NEG_Y, Vec3::new(0.3, 0.8, 0.1).normalize(), 16, 16)
                .expect("the ray meets the plane");
            let reference = field.ambient_occlusion(uv * map.width as f32, 16, 16);
            diff += (t.ao - reference).abs();
            bias += t.ao - reference;
            n += 1;
        }
    }
    let (diff, bias) = (diff / n as f32, bias / n as f32);
    eprintln!("mesh ray caster against the height-field marcher: AO mean |Δ| {diff:.4}, mean Δ {bias:+.4}");
    assert!(diff < 0.03 && bias.abs() < 0.015, "mean |Δ| {diff}, mean Δ {bias}");
}
