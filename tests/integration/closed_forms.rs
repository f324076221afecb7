//! The whole pipeline on a height field whose answers are known in closed form: V-grooves with
//! walls at slope α. At the bottom of a groove the cosine-weighted AO is cos α, and a light
//! from across the groove is blocked exactly when it is lower than α.

use bevy::{light::GlobalAmbientLight, prelude::*};
use bevy_mesostructure::{CapturedFrame, prelude::*};

use crate::harness::*;

const SIZE: u32 = 96;

/// Four V-grooves across u (bottoms at u = 0.125, 0.375, 0.625, 0.875, ridges between), walls
/// at slope α over the 2 × 2 plane: each half-groove is 0.25 world units wide and 1 map unit high,
/// so `k = tan α / 4`.
fn grooves(slope_deg: f32) -> (HeightMap, f32) {
    let map = HeightMap::from_fn(256, 256, |u, _| ((u * 4.0).fract() - 0.5).abs() * 2.0);
    (map, slope_deg.to_radians().tan() / 4.0)
}

/// Renders the grooves top-down with one directional light travelling towards +x at
/// `elevation_deg` and returns the capture.
fn render(slope_deg: f32, elevation_deg: f32) -> CapturedFrame {
    render_with(slope_deg, elevation_deg, Mesostructure::default())
}

fn render_with(slope_deg: f32, elevation_deg: f32, settings: Mesostructure) -> CapturedFrame {
    render_with_baseline(slope_deg, elevation_deg, settings, None)
}

/// [`render_with`], with the horizon-search baseline on the camera where given.
fn render_with_baseline(
    slope_deg: f32,
    elevation_deg: f32,
    settings: Mesostructure,
    baseline: Option<bevy_mesostructure::HorizonSearchBaseline>,
) -> CapturedFrame {
    let mut app = app();
    let target = target(&mut app, SIZE, SIZE);
    let camera = camera(&mut app, &target, top_down(), settings);
    if let Some(baseline) = baseline {
        app.world_mut().entity_mut(camera).insert(baseline);
    }
    let (map, k) = grooves(slope_deg);
    let height_map = image(&mut app, map.to_image());
    app.insert_resource(GlobalAmbientLight {
        brightness: 0.0,
        ..default()
    });
    let e = elevation_deg.to_radians();
    app.world_mut().spawn((
        DirectionalLight {
            illuminance: 3000.0,
            ..default()
        },
        Transform::default().looking_to(Vec3::new(e.cos(), -e.sin(), 0.0), Vec3::Y),
    ));
    let grey = app
        .world_mut()
        .resource_mut::<Assets<StandardMaterial>>()
        .add(Color::srgb(0.5, 0.5, 0.5));
    mesostructure_plane(&mut app, MeshMaterial3d(grey), height_map, k);
    capture(&mut app, camera, 5)
}

/// The bottom pixel of the groove whose bottom is at world x = −0.25 (u = 0.375), per row away
/// from the screen edge: the lowest height-map value near the column where it should be.
fn bottoms(frame: &CapturedFrame) -> Vec<usize> {
    let column = top_down_column(-0.25);
    (8..SIZE - 8)
        .map(|y| {
            (column - 3..=column + 3)
                .map(|x| (y * SIZE + x) as usize)
                .min_by(|&a, &b| frame.mhm[a][3].total_cmp(&frame.mhm[b][3]))
                .unwrap()
        })
        .collect()
}

/// The pixel column of the top-down camera over world x.
fn top_down_column(x: f32) -> u32 {
    let half_width = (std::f32::consts::FRAC_PI_4 * 0.5).tan() * TOP_DOWN_HEIGHT;
    ((x / half_width + 1.0) * 0.5 * SIZE as f32) as u32
}

#[test]
fn v_groove_bottoms_match_the_closed_forms() {
    if !gpu_or_skip() {
        return;
    }
    for slope in [25.0f32, 40.0] {
        // AO at the bottom: cos α (the 8-sector method came within 0.03 on the CPU). The
        // screen-space occlusion of the apex sets, point-sampled at the bottom pixel; the
        // texture-space one averages each pixel's footprint (2.7 texels here, up the walls)
        // and has its own closed-form check (`reference::texture_space`).
        let frame = render_with(
            slope,
            60.0,
            Mesostructure {
                texture_space_horizons: false,
                ..default()
            },
        );
        let bottom = bottoms(&frame);
        let ao = bottom.iter().map(|&i| frame.occlusion[i]).sum::<f32>() / bottom.len() as f32;
        let worst = bottom
            .iter()
            .map(|&i| (frame.occlusion[i] - slope.to_radians().cos()).abs())
            .fold(0.0f32, f32::max);
        eprintln!(
            "V-groove {slope}°: AO at the bottom {ao:.4} (closed form {:.4}), worst row off by \
             {worst:.4}",
            slope.to_radians().cos()
        );
        assert!(worst < 0.05, "{slope}°: AO off the closed form by {worst}");

        // A light 10° under the wall's slope is blocked at the bottom; 10° over it is not.
        for (elevation, blocked) in [(slope - 10.0, true), (slope + 10.0, false)] {
            let frame = render(slope, elevation);
            let visible = bottoms(&frame)
                .iter()
                .map(|&i| frame.micro_shadow[i])
                .collect::<Vec<_>>();
            let lit = visible.iter().filter(|&&v| v > 0.9).count();
            let dark = visible.iter().filter(|&&v| v < 0.1).count();
            eprintln!(
                "V-groove {slope}°, light at {elevation}°: {dark} of {} bottom pixels \
                 micro-shadowed, {lit} lit",
                visible.len()
            );
            if blocked {
                assert_eq!(
                    dark,
                    visible.len(),
                    "{slope}° groove, light at {elevation}°"
                );
            } else {
                assert_eq!(lit, visible.len(), "{slope}° groove, light at {elevation}°");
            }
        }
    }
}

#[test]
fn brute_force_horizon_search_matches_its_oracle_and_the_closed_form() {
    if !gpu_or_skip() {
        return;
    }
    // The fixed-radius baseline of the accuracy chart: 16 directions, 32 samples out to 24 px
    // (each half-groove is ~10 px wide here).
    let settings = Mesostructure {
        quality: MesostructureQuality::High.custom(|c| {
            c.apex_directions = 16;
            c.max_sample_radius = 24;
        }),
        micro_shadows: false,
        bleeding: false,
        ..default()
    };
    for slope in [25.0f32, 40.0] {
        let baseline = bevy_mesostructure::HorizonSearchBaseline { steps: 32 };
        let frame = render_with_baseline(slope, 60.0, settings.clone(), Some(baseline));
        // Against the CPU oracle on the same captured images, every pixel.
        let mhm = frame.screen_height_map();
        let mhgm = frame.gradient_map();
        let normals = frame.normals();
        let directions = bevy_mesostructure::reference::sample_directions(16);
        let mut worst = 0.0f32;
        for y in 0..SIZE {
            for x in 0..SIZE {
                let cpu = bevy_mesostructure::reference::horizon_search_occlusion(
                    &mhm,
                    &mhgm,
                    &normals,
                    &frame.view,
                    (x, y),
                    &directions,
                    32,
                    24,
                    bevy_mesostructure::reference::OcclusionForm::CosineWeighted,
                );
                worst = worst.max((cpu - frame.occlusion[(y * SIZE + x) as usize]).abs());
            }
        }
        // And at the groove bottoms, against cos α.
        let bottom = bottoms(&frame);
        let ao = bottom.iter().map(|&i| frame.occlusion[i]).sum::<f32>() / bottom.len() as f32;
        eprintln!(
            "horizon search, V-groove {slope}°: AO at the bottom {ao:.4} (closed form {:.4}); \
             GPU vs oracle worst {worst:.2e}",
            slope.to_radians().cos()
        );
        assert!(worst < 1e-4, "GPU vs oracle: {worst}");
        assert!(
            (ao - slope.to_radians().cos()).abs() < 0.03,
            "{slope}°: {ao}"
        );
    }
}
