//! Stability where screen-space methods fail (issue 5): a static camera gives identical frames;
//! grazing views of a flat map stay open and unshadowed; sweeps of scale and distance stay
//! finite, free of isolated outliers, and fade smoothly; a groove keeps its occlusion until it
//! nearly leaves the screen. Each prints its numbers (docs/stability.md).

use bevy::{light::GlobalAmbientLight, prelude::*};
use bevy_mesostructure::{CapturedFrame, prelude::*};

use crate::harness::*;

const SIZE: u32 = 64;

/// A 2 × 2 plane with `map` at scale `k`, seen from `eye` towards the origin, lit by a light
/// travelling along `light`; captured after the warm-up.
fn render(
    map: &HeightMap,
    k: f32,
    eye: Transform,
    light: Vec3,
) -> (App, Entity, Handle<Image>, CapturedFrame) {
    let mut app = app();
    let target = target(&mut app, SIZE, SIZE);
    let camera = camera(&mut app, &target, eye, Mesostructure::default());
    let height_map = image(&mut app, map.to_image());
    app.insert_resource(GlobalAmbientLight {
        brightness: 800.0,
        ..default()
    });
    sun(&mut app, light, 3000.0);
    let grey = app
        .world_mut()
        .resource_mut::<Assets<StandardMaterial>>()
        .add(Color::srgb(0.6, 0.6, 0.6));
    mesostructure_plane(&mut app, MeshMaterial3d(grey), height_map, k);
    let frame = capture(&mut app, camera, 5);
    (app, camera, target, frame)
}

/// Every lighting term of every mesostructure pixel is finite.
fn all_finite(frame: &CapturedFrame) -> bool {
    (0..frame.mhm.len())
        .filter(|&i| frame.mhm[i][2] != 0.0)
        .all(|i| {
            frame.occlusion[i].is_finite()
                && frame.micro_shadow[i].is_finite()
                && frame.bleeding[i].iter().all(|c| c.is_finite())
        })
}

/// Mean occlusion over the mesostructure pixels at least 4 px from the edge.
fn mean_occlusion(frame: &CapturedFrame) -> f32 {
    let (mut sum, mut n) = (0.0, 0);
    for y in 4..SIZE - 4 {
        for x in 4..SIZE - 4 {
            let i = (y * SIZE + x) as usize;
            if frame.mhm[i][2] != 0.0 {
                sum += frame.occlusion[i];
                n += 1;
            }
        }
    }
    sum / n.max(1) as f32
}

/// Share of inner mesostructure pixels whose occlusion differs by more than 0.25 from every one
/// of its 8 neighbours: isolated spikes ("sparkle"). A thin line of structure (a cliff one pixel
/// wide) has neighbours along the line and is not counted.
fn sparkle(frame: &CapturedFrame) -> f32 {
    let (mut spikes, mut n) = (0, 0);
    for y in 1..SIZE - 1 {
        for x in 1..SIZE - 1 {
            let i = (y * SIZE + x) as usize;
            if frame.mhm[i][2] == 0.0 {
                continue;
            }
            let v = frame.occlusion[i];
            let isolated = (-1..=1)
                .flat_map(|dy| (-1..=1).map(move |dx| (dx, dy)))
                .filter(|&d| d != (0, 0))
                .all(|(dx, dy)| {
                    let j = ((y as i32 + dy) as u32 * SIZE + (x as i32 + dx) as u32) as usize;
                    (frame.occlusion[j] - v).abs() > 0.25
                });
            n += 1;
            spikes += isolated as u32;
        }
    }
    spikes as f32 / n.max(1) as f32
}

fn low_light() -> Vec3 {
    Vec3::new(1.0, -0.5, 0.3).normalize()
}

#[test]
fn a_static_camera_gives_bit_identical_frames() {
    if !gpu_or_skip() {
        return;
    }
    let (mut app, camera, target, first) = render(
        &HeightMap::bricks(256, 4, 0.15),
        0.1,
        top_down(),
        low_light(),
    );
    let a = screenshot(&mut app, &target);
    run(&mut app, 3);
    let b = screenshot(&mut app, &target);
    let second = capture(&mut app, camera, 5);
    let same_picture = a.data == b.data;
    let same_terms = first.occlusion == second.occlusion
        && first.micro_shadow == second.micro_shadow
        && first.bleeding == second.bleeding;
    eprintln!("static camera: identical picture {same_picture}, identical terms {same_terms}");
    assert!(same_picture && same_terms);
}

#[test]
fn grazing_views_of_a_flat_map_are_open_and_unshadowed() {
    if !gpu_or_skip() {
        return;
    }
    let flat = HeightMap::from_fn(64, 64, |_, _| 0.5);
    for elevation in [89.0f32, 60.0, 30.0, 10.0, 3.0] {
        let e = elevation.to_radians();
        let eye =
            Transform::from_xyz(0.0, 2.0 * e.sin(), 2.0 * e.cos()).looking_at(Vec3::ZERO, Vec3::Y);
        // The light grazes too, from the side.
        let (_, _, _, frame) = render(&flat, 0.2, eye, Vec3::new(1.0, -0.05, 0.2).normalize());
        let pixels: Vec<usize> = (0..frame.mhm.len())
            .filter(|&i| frame.mhm[i][2] != 0.0)
            .collect();
        let closed = pixels
            .iter()
            .filter(|&&i| frame.occlusion[i] != 1.0)
            .count();
        let shadowed = pixels
            .iter()
            .filter(|&&i| frame.micro_shadow[i] != 1.0)
            .count();
        let bleeding = pixels
            .iter()
            .filter(|&&i| frame.bleeding[i][..3].iter().any(|&c| c != 0.0))
            .count();
        eprintln!(
            "flat map seen at {elevation}°: {} pixels; AO ≠ 1 on {closed}, micro-shadow on \
             {shadowed}, bleeding on {bleeding}",
            pixels.len()
        );
        assert!(pixels.len() > 100, "{elevation}°: the plane is in view");
        assert!(all_finite(&frame));
        assert_eq!((closed, shadowed, bleeding), (0, 0, 0), "{elevation}°");
    }
}

#[test]
fn scale_and_distance_sweeps_stay_finite_and_fade_smoothly() {
    if !gpu_or_skip() {
        return;
    }
    let map = HeightMap::bricks(256, 4, 0.15);
    // Scale 0.01 → 2 at a fixed view: finite and without spikes everywhere; the occlusion
    // deepens monotonically inside the valid range.
    let mut previous = 1.0f32;
    for k in [0.01f32, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0] {
        let (_, _, _, frame) = render(&map, k, top_down(), low_light());
        let mean = mean_occlusion(&frame);
        let s = sparkle(&frame);
        eprintln!("scale {k}: mean AO {mean:.4}, sparkle {:.4}", s);
        assert!(all_finite(&frame), "scale {k}: a NaN or infinity");
        // Monotone inside the paper's valid range (up to 0.8 for unit-sized structures; these
        // bricks are 0.5 units tall); beyond it only finite and spike-free (docs/stability.md).
        if k <= 0.5 {
            assert!(
                mean <= previous + 0.01,
                "scale {k}: AO rose from {previous} to {mean}"
            );
        }
        assert!(
            s < 0.005,
            "scale {k}: {s} of the pixels are isolated spikes"
        );
        previous = mean;
    }
    // Distance: top-down from 2 to 64 units; the bricks shrink below a pixel. The occlusion of
    // the minified map is the mean of its fine occlusion over each pixel (texture-space), so the
    // mean over the plane stays what it is up close — measured within 0.046 up to 16 units,
    // held to 0.06 (docs/stability.md) — without spikes on the way.
    let mut near = None;
    for height in [2.0f32, 4.0, 8.0, 16.0, 32.0, 64.0] {
        let eye = Transform::from_xyz(0.0, height, 0.0).looking_at(Vec3::ZERO, Vec3::NEG_Z);
        let (_, _, _, frame) = render(&map, 0.1, eye, low_light());
        let mean = mean_occlusion(&frame);
        let s = sparkle(&frame);
        eprintln!("distance {height}: mean AO {mean:.4}, sparkle {s:.4}");
        assert!(all_finite(&frame), "distance {height}: a NaN or infinity");
        let near = *near.get_or_insert(mean);
        // Past 16 units the plane is a few pixels across (2.4 at 64): only finite and
        // spike-free there.
        if height <= 16.0 {
            assert!(
                (mean - near).abs() <= 0.06,
                "distance {height}: mean AO {mean}, up close {near}"
            );
        }
        assert!(
            s < 0.005,
            "distance {height}: {s} of the pixels are isolated spikes"
        );
    }
}

#[test]
fn a_groove_keeps_its_occlusion_until_it_nearly_leaves_the_screen() {
    if !gpu_or_skip() {
        return;
    }
    // Four V-grooves across x (walls at 30°, ridges every 0.5 world units); the camera pans so
    // that the groove whose bottom is at x = 0.25 moves from the middle of the screen to its
    // right edge. Its far ridge (x = 0.5) is ~10 px beyond the bottom at 64².
    let map = HeightMap::from_fn(256, 256, |u, _| ((u * 4.0).fract() - 0.5).abs() * 2.0);
    let k = 30f32.to_radians().tan() / 4.0;
    let half_width = std::f32::consts::FRAC_PI_8.tan() * TOP_DOWN_HEIGHT;
    let px_per_unit = SIZE as f32 / (2.0 * half_width);
    let mut centre = None;
    for camera_x in [0.25f32, 0.1, 0.0, -0.1, -0.2, -0.3, -0.4, -0.45, -0.5] {
        let eye = Transform::from_xyz(camera_x, TOP_DOWN_HEIGHT, 0.0)
            .looking_at(Vec3::new(camera_x, 0.0, 0.0), Vec3::NEG_Z);
        let (_, _, _, frame) = render(&map, k, eye, Vec3::NEG_Y);
        // The bottom column: the lowest height-map value near where it should be.
        let expected = ((0.25 - camera_x + half_width) * px_per_unit) as i32;
        if expected > SIZE as i32 - 2 {
            break;
        }
        let row = |y: u32| {
            (expected - 2..=expected + 2)
                .filter(|&x| (0..SIZE as i32).contains(&x))
                .map(|x| (y * SIZE + x as u32) as usize)
                .min_by(|&a, &b| frame.mhm[a][3].total_cmp(&frame.mhm[b][3]))
                .unwrap()
        };
        let rows: Vec<usize> = (SIZE / 4..3 * SIZE / 4).map(row).collect();
        let ao = rows.iter().map(|&i| frame.occlusion[i]).sum::<f32>() / rows.len() as f32;
        let to_edge = SIZE as i32 - 1 - expected;
        let reference = *centre.get_or_insert(ao);
        eprintln!(
            "groove bottom {to_edge} px from the right edge: AO {ao:.4} (in the middle {reference:.4})"
        );
        if to_edge >= 12 {
            assert!(
                (ao - reference).abs() < 0.03,
                "{to_edge} px from the edge: {ao} vs {reference}"
            );
        }
    }
}

/// The pixel of `camera` (a `SIZE`² view with Bevy's default 45° vertical field of view) that
/// sees the world point `p`, or `None` off screen.
fn project(camera: &Transform, p: Vec3) -> Option<Vec2> {
    let view = camera.to_matrix().inverse();
    let projection = Mat4::perspective_infinite_reverse_rh(std::f32::consts::FRAC_PI_4, 1.0, 0.1);
    let clip = projection * view * p.extend(1.0);
    let ndc = clip.truncate() / clip.w;
    let pixel = Vec2::new((ndc.x + 1.0) * 0.5, (1.0 - ndc.y) * 0.5) * SIZE as f32;
    (clip.w > 0.0 && pixel.cmpge(Vec2::ZERO).all() && pixel.cmplt(Vec2::splat(SIZE as f32)).all())
        .then_some(pixel)
}

/// The point of the y = 0 plane seen through the centre of `pixel`.
fn unproject(camera: &Transform, pixel: UVec2) -> Option<Vec3> {
    let ndc = Vec2::new(
        (pixel.x as f32 + 0.5) / SIZE as f32 * 2.0 - 1.0,
        1.0 - (pixel.y as f32 + 0.5) / SIZE as f32 * 2.0,
    );
    let t = (std::f32::consts::FRAC_PI_8).tan();
    let dir = camera.rotation * Vec3::new(ndc.x * t, ndc.y * t, -1.0);
    let s = -camera.translation.y / dir.y;
    (s > 0.0).then(|| camera.translation + dir * s)
}

#[test]
fn an_orbiting_camera_sees_steady_occlusion_compared_with_ssao() {
    if !gpu_or_skip() {
        return;
    }
    // Ambient light only, so that the picture is ambient × occlusion; the camera orbits the
    // bricks at 50° elevation, 2° a frame. Each surface point seen in two consecutive frames is
    // compared (reprojected through the plane): the mean frame-to-frame change of its
    // brightness. Three runs: this plugin on the flat plane with the height map; Bevy's SSAO on
    // the same bricks as real geometry; and, as the floor of what reprojection alone changes,
    // the bricks' pattern as an unlit texture.
    let orbit = |frame: u32| {
        let a = (frame as f32 * 2.0).to_radians();
        let e = 50f32.to_radians();
        Transform::from_xyz(
            1.8 * e.cos() * a.sin(),
            1.8 * e.sin(),
            1.8 * e.cos() * a.cos(),
        )
        .looking_at(Vec3::ZERO, Vec3::Y)
    };
    let map = HeightMap::bricks(256, 4, 0.15);
    let k = 0.1;
    let mut report = vec![];
    for run_kind in ["mesostructure", "ssao", "floor"] {
        let mut app = app();
        let target = target(&mut app, SIZE, SIZE);
        let camera = camera(
            &mut app,
            &target,
            orbit(0),
            Mesostructure {
                micro_shadows: false,
                bleeding: false,
                bump_mapping: false,
                ..default()
            },
        );
        app.insert_resource(GlobalAmbientLight {
            brightness: 3000.0,
            ..default()
        });
        match run_kind {
            "mesostructure" => {
                let bricks = image(&mut app, map.to_image());
                let grey = app
                    .world_mut()
                    .resource_mut::<Assets<StandardMaterial>>()
                    .add(Color::srgb(0.8, 0.8, 0.8));
                mesostructure_plane(&mut app, MeshMaterial3d(grey), bricks, k);
            }
            "ssao" => {
                app.world_mut()
                    .entity_mut(camera)
                    .remove::<Mesostructure>()
                    .insert(bevy::pbr::ScreenSpaceAmbientOcclusion::default());
                let grid = mesh(&mut app, map.displaced_plane(k, 256));
                let grey = app
                    .world_mut()
                    .resource_mut::<Assets<StandardMaterial>>()
                    .add(Color::srgb(0.8, 0.8, 0.8));
                app.world_mut().spawn((grid, MeshMaterial3d(grey)));
            }
            _ => {
                app.world_mut().entity_mut(camera).remove::<Mesostructure>();
                let pattern = image(&mut app, map.to_image_gray8());
                let material = app
                    .world_mut()
                    .resource_mut::<Assets<StandardMaterial>>()
                    .add(StandardMaterial {
                        base_color_texture: Some(pattern),
                        unlit: true,
                        ..default()
                    });
                let plane = mesh(&mut app, Plane3d::default().mesh().size(2.0, 2.0));
                app.world_mut().spawn((plane, MeshMaterial3d(material)));
            }
        }
        run(&mut app, 4);
        let mut frames = vec![];
        for f in 0..6 {
            *app.world_mut().get_mut::<Transform>(camera).unwrap() = orbit(f);
            run(&mut app, 2);
            frames.push((
                orbit(f),
                crate::lighting::pixels(&screenshot(&mut app, &target)),
            ));
        }
        let (mut sum, mut n) = (0.0f64, 0u32);
        // The picture's own contrast between neighbouring pixels: what a sub-pixel misregistration
        // of a perfectly steady picture changes in proportion to.
        let (mut contrast, mut m) = (0.0f64, 0u32);
        for (_, picture) in &frames {
            for y in 8..SIZE - 8 {
                for x in 8..SIZE - 8 {
                    let i = (y * SIZE + x) as usize;
                    contrast += (picture[i][0] as f64 - picture[i + 1][0] as f64).abs() / 255.0;
                    m += 1;
                }
            }
        }
        let contrast = contrast / m as f64;
        for pair in frames.windows(2) {
            let ((a_cam, a), (b_cam, b)) = (&pair[0], &pair[1]);
            for y in 8..SIZE - 8 {
                for x in 8..SIZE - 8 {
                    let Some(p) = unproject(a_cam, UVec2::new(x, y)) else {
                        continue;
                    };
                    if p.x.abs() > 0.95 || p.z.abs() > 0.95 {
                        continue;
                    }
                    let Some(q) = project(b_cam, p) else {
                        continue;
                    };
                    let j = (q.y as u32 * SIZE + q.x as u32) as usize;
                    let i = (y * SIZE + x) as usize;
                    sum += (a[i][0] as f64 - b[j][0] as f64).abs() / 255.0;
                    n += 1;
                }
            }
        }
        let change = sum / n as f64;
        let relative = change / contrast;
        eprintln!(
            "orbiting camera, {run_kind}: mean frame-to-frame change at fixed surface points \
             {change:.4} (over {n} reprojected pixels), neighbour contrast {contrast:.4}, \
             relative {relative:.3}"
        );
        report.push(relative);
    }
    // The floor that reprojection alone sets (docs/stability.md: 0.974 measured): a steady
    // pattern changes by about its own neighbour contrast, within 0.05 of the measured value.
    assert!(
        (report[2] - 0.974).abs() <= 0.05,
        "steady pattern's relative change {} is not the measured floor 0.974 ± 0.05",
        report[2]
    );
    // The plugin stays at that floor (measured 0.897 against 0.974): no flicker beyond what
    // reprojection changes.
    assert!(
        report[0] <= report[2] * 1.05,
        "relative change: mesostructure {} above the steady floor {}",
        report[0],
        report[2]
    );
    // And, relative to its own contrast, the occlusion computed from object-space heights
    // changes along the orbit no more than SSAO's on real geometry.
    assert!(
        report[0] <= report[1] * 1.1,
        "relative change: mesostructure {} vs SSAO {} (steady pattern {})",
        report[0],
        report[1],
        report[2]
    );
}
