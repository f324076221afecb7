//! Micro-shadows of directional, point and spot lights (paper §3.2) against the CPU oracle,
//! and their effect on the picture.

use bevy::{light::GlobalAmbientLight, prelude::*};
use bevy_mesostructure::{CapturedFrame, prelude::*, reference};

use crate::harness::*;

const SIZE: u32 = 96;

/// A top-down bricks plane (k 0.1, grey) lit only by `light`, captured.
fn bricks_under(light: impl Bundle) -> (App, Entity, Handle<Image>, CapturedFrame) {
    let mut app = app();
    let target = target(&mut app, SIZE, SIZE);
    let camera = camera(
        &mut app,
        &target,
        top_down(),
        // The oracle mirrors the screen-space micro-shadows of the apex sets; the texture-space
        // ones of the first directional light have their own checks (closed forms, unseen).
        Mesostructure {
            occlusion: false,
            bleeding: false,
            texture_space_horizons: false,
            ..default()
        },
    );
    let bricks = image(&mut app, HeightMap::bricks(256, 4, 0.15).to_image());
    app.insert_resource(GlobalAmbientLight {
        brightness: 0.0,
        ..default()
    });
    app.world_mut().spawn(light);
    let grey = app
        .world_mut()
        .resource_mut::<Assets<StandardMaterial>>()
        .add(Color::srgb(0.5, 0.5, 0.5));
    mesostructure_plane(&mut app, MeshMaterial3d(grey), bricks, 0.1);
    let frame = capture(&mut app, camera, 5);
    (app, camera, target, frame)
}

/// The oracle's micro-shadow visibility per pixel (NaN where there is no mesostructure or it is
/// near the screen edge), for the direction to the light from each surface point.
fn oracle(frame: &CapturedFrame, to_light: impl Fn(Vec3) -> Vec3) -> Vec<f32> {
    let mhm = frame.screen_height_map();
    let mhgm = frame.gradient_map();
    let normals = frame.normals();
    let softness = Mesostructure::default().micro_shadow_softness;
    let mut out = vec![f32::NAN; (SIZE * SIZE) as usize];
    for y in 2..SIZE - 2 {
        for x in 2..SIZE - 2 {
            let set = frame.apex_set(x, y);
            if let Some(h) =
                reference::sector_horizons(&mhm, &mhgm, &normals, &frame.view, &set, (x, y))
            {
                out[(y * SIZE + x) as usize] =
                    reference::micro_shadow(&frame.view, &h, to_light(h.point), softness);
            }
        }
    }
    out
}

/// Compares the GPU's micro-shadow visibility with the oracle's; returns the pixels the oracle
/// shadows.
fn assert_matches(kind: &str, frame: &CapturedFrame, expected: &[f32]) -> Vec<usize> {
    assert_eq!(frame.micro_shadow.len(), expected.len(), "{kind}: captured");
    let (mut total, mut close, mut sum) = (0, 0, 0.0);
    let mut shadowed = vec![];
    for (i, (&gpu, &cpu)) in frame.micro_shadow.iter().zip(expected).enumerate() {
        if cpu.is_nan() {
            continue;
        }
        total += 1;
        sum += (gpu - cpu).abs();
        close += ((gpu - cpu).abs() < 0.05) as u32;
        if cpu < 0.5 {
            shadowed.push(i);
        }
    }
    let share = close as f32 / total as f32;
    let mean = sum / total as f32;
    eprintln!(
        "{kind} light: {} of {total} pixels in micro-shadow; GPU within 0.05 of the oracle on \
         {share:.4}, mean difference {mean:.4}",
        shadowed.len()
    );
    assert!(
        shadowed.len() > 50,
        "{kind}: a low light casts micro-shadows"
    );
    assert!(
        share > 0.98 && mean < 0.01,
        "{kind}: GPU vs oracle {share} {mean}"
    );
    shadowed
}

#[test]
fn micro_shadows_of_directional_point_and_spot_lights_match_the_oracle() {
    if !gpu_or_skip() {
        return;
    }
    // 20° above the horizon, from −x.
    let elevation = 20f32.to_radians();
    let direction = Vec3::new(elevation.cos(), -elevation.sin(), 0.0);
    let (_, _, _, frame) = bricks_under((
        DirectionalLight {
            illuminance: 3000.0,
            shadow_maps_enabled: false,
            ..default()
        },
        Transform::default().looking_to(direction, Vec3::Y),
    ));
    assert_matches("directional", &frame, &oracle(&frame, |_| -direction));

    // Point and spot lights low on the −x side: the direction to the light differs per pixel.
    let position = Vec3::new(-3.0, 1.0, 0.4);
    let (mut app, camera, target, frame) = bricks_under((
        PointLight {
            intensity: 4.0e6,
            range: 20.0,
            shadow_maps_enabled: false,
            ..default()
        },
        Transform::from_translation(position),
    ));
    let shadowed = assert_matches(
        "point",
        &frame,
        &oracle(&frame, |p| (position - p).normalize()),
    );
    // And the picture: where the oracle shadows, the point light's contribution is gone.
    let (on, off) =
        crate::lighting::before_and_after(&mut app, camera, &target, |m| m.micro_shadows = false);
    let (dim, bright) = shadowed
        .iter()
        .filter(|&&i| frame.micro_shadow[i] < 0.1 && off[i][0] > 30)
        .fold((0u32, 0u32), |(a, b), &i| {
            (a + on[i][0] as u32, b + off[i][0] as u32)
        });
    eprintln!("point light: shadowed pixels sum to {dim} with micro-shadows, {bright} without");
    assert!(bright > 0 && (dim as f32) < 0.5 * bright as f32);

    let (_, _, _, frame) = bricks_under((
        SpotLight {
            intensity: 4.0e6,
            range: 20.0,
            outer_angle: 0.6,
            inner_angle: 0.5,
            shadow_maps_enabled: false,
            ..default()
        },
        Transform::from_translation(position).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    assert_matches(
        "spot",
        &frame,
        &oracle(&frame, |p| (position - p).normalize()),
    );
}
