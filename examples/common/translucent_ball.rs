//! The translucency accuracy scene, shared by `examples/translucent_accuracy.rs` and the
//! integration test that holds the plugin to a light-traced reference: a ball of radius 1 cm
//! (Bevy's ico sphere, 20 480 triangles) of one medium, index-matched or behind a dielectric
//! boundary, lit by one directional light of irradiance 1 or a uniform environment of
//! radiance 1, seen from 4 cm; the plugin's picture computed on the
//! CPU by the same patches, transport, iteration and gather as the passes, and its score
//! against a reference picture.
#![allow(dead_code)] // The example reads every field; the test only the picture and its score.

use std::time::Instant;

use bevy::prelude::*;
use bevy_mesostructure::translucency::{
    EnergyTransport, GatherMethod, PatchLight, PatchObject, PatchSurface, SceneRays,
    TranslucentMedium, TransportSettings, direct_light, gather::gathered_radiance,
    patches::world_triangles, resample_into_patches,
};

pub const RADIUS: f32 = 0.01;
pub const EYE: Vec3 = Vec3::new(0.0, 0.0, 0.04);
/// The default light: from the right, slightly above and in front.
pub const FRONT_LIGHT: Vec3 = Vec3::new(-1.0, -0.2, -0.3);
/// Lit from behind, a little from the left and above.
pub const BACK_LIGHT: Vec3 = Vec3::new(0.4, -0.2, 1.0);
pub const FOV_Y: f32 = std::f32::consts::FRAC_PI_4;

/// The camera ray through pixel `(x, y)` and where it meets the ball (point, normal), if it
/// does.
pub fn ball_hit(x: u32, y: u32, size: u32) -> Option<(Vec3, Vec3, Vec3)> {
    let tan = (FOV_Y / 2.0).tan();
    let forward = (-EYE).normalize();
    let right = forward.cross(Vec3::Y).normalize();
    let up = right.cross(forward);
    let sx = (2.0 * (x as f32 + 0.5) / size as f32 - 1.0) * tan;
    let sy = (1.0 - 2.0 * (y as f32 + 0.5) / size as f32) * tan;
    let d = (forward + right * sx + up * sy).normalize();
    let b = EYE.dot(d);
    let disc = b * b - (EYE.length_squared() - RADIUS * RADIUS);
    (disc > 0.0).then(|| {
        let hit = EYE + d * (-b - disc.sqrt());
        (d, hit, hit.normalize())
    })
}

/// Whether pixel `(x, y)` is scored: on the ball, the silhouette's rim (mesh against sphere,
/// pixels half on the ball) left out.
pub fn scored(x: u32, y: u32, size: u32) -> bool {
    ball_hit(x, y, size).is_some_and(|(d, _, n)| n.dot(-d) >= 0.3)
}

/// The plugin's picture of the ball and what it cost.
pub struct BallPicture {
    /// Linear radiance per pixel, row by row.
    pub pixels: Vec<Vec3>,
    pub patches: usize,
    /// Patches and transport, seconds.
    pub precompute_s: f32,
    /// The sparse matrices' bytes.
    pub memory_bytes: usize,
    pub iterations: u32,
}

/// How the ball is lit.
#[derive(Clone, Copy, Debug)]
pub enum BallLighting {
    /// A directional light of irradiance 1 travelling along this (unit) direction.
    Directional(Vec3),
    /// A uniform environment of radiance 1: Bevy's ambient light, irradiance π on every
    /// translucent patch, as the plugin injects it.
    Uniform,
}

/// The plugin's picture of a ball of `medium` lit by `lighting`, at `budget` patches,
/// `size`² pixels.
pub fn plugin_picture(
    medium: TranslucentMedium,
    oriented_dipole: bool,
    settings: &TransportSettings,
    gather: GatherMethod,
    budget: u32,
    lighting: BallLighting,
    size: u32,
) -> BallPicture {
    let (positions, indices) = world_triangles(
        &Sphere::new(RADIUS).mesh().ico(5).expect("a valid subdivision"),
        &GlobalTransform::IDENTITY,
    )
    .expect("a triangle list");
    let views = [PatchObject {
        positions: &positions,
        indices: &indices,
    }];
    let surfaces = [PatchSurface::Translucent {
        medium,
        world_units_per_mm: 0.001,
        oriented_dipole,
    }];
    let (lights, ambient) = match lighting {
        BallLighting::Directional(direction) => (
            vec![PatchLight::Directional {
                direction,
                illuminance: Vec3::ONE,
            }],
            Vec3::ZERO,
        ),
        BallLighting::Uniform => (Vec::new(), Vec3::splat(std::f32::consts::PI)),
    };
    let start = Instant::now();
    let patches = resample_into_patches(&views, budget as usize);
    let rays = SceneRays::new(&views);
    let transport = EnergyTransport::build(&patches, &surfaces, &rays, settings);
    let precompute_s = start.elapsed().as_secs_f32();
    let mut direct = direct_light(&patches, Some(&transport), &lights, &rays);
    for e in &mut direct.irradiance {
        *e += ambient;
    }
    let solution = transport.solve_with(&direct, 1e-4, 256);
    let albedo = vec![Vec3::ZERO; patches.patches.len()];
    let exit_laws = transport.exit_laws(&patches, &surfaces, settings);
    let pixels = (0..size * size)
        .map(|i| {
            ball_hit(i % size, i / size, size)
                .and_then(|(_, hit, n)| {
                    gathered_radiance(
                        gather,
                        &patches,
                        &albedo,
                        &exit_laws,
                        &direct.irradiance,
                        &solution.exitance,
                        EYE,
                        hit,
                        n,
                    )
                })
                .unwrap_or(Vec3::ZERO)
        })
        .collect();
    let n = patches.patches.len();
    BallPicture {
        pixels,
        patches: n,
        precompute_s,
        memory_bytes: 8 * (2 * (n + 1))
            + 8 * transport.form_factors.entries()
            + 16 * transport.scattering.entries(),
        iterations: solution.iterations,
    }
}

/// A picture against the reference over the scored pixels.
pub struct BallScore {
    /// `Σ|plugin − reference| / Σ reference`, all channels.
    pub rel_l1: f64,
    /// Mean plugin / mean reference per channel (a scale error shows here first).
    pub ratio: [f64; 3],
}

/// Scores `pixels` against `reference` (both `size`², linear).
pub fn score(pixels: &[Vec3], reference: &image::Rgb32FImage, size: u32) -> BallScore {
    let (mut difference, mut total) = (0.0f64, 0.0f64);
    let mut sums = [[0.0f64; 2]; 3];
    for y in 0..size {
        for x in 0..size {
            if !scored(x, y, size) {
                continue;
            }
            let ours = pixels[(y * size + x) as usize];
            let theirs = reference.get_pixel(x, y).0;
            for c in 0..3 {
                difference += (ours[c] - theirs[c]).abs() as f64;
                total += theirs[c] as f64;
                sums[c][0] += ours[c] as f64;
                sums[c][1] += theirs[c] as f64;
            }
        }
    }
    BallScore {
        rel_l1: difference / total.max(1e-30),
        ratio: sums.map(|[a, b]| a / b.max(1e-30)),
    }
}
