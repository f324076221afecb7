//! The coarse horizon-based AO on the depth buffer (paper §3.1): the core geometry around a
//! mesostructure surface occludes it, with the apex sets' adaptive step. And Bevy's SSAO on top.

use bevy::prelude::*;
use bevy_mesostructure::prelude::*;

use crate::harness::*;

const SIZE: u32 = 96;
/// The largest loss of visibility 30 px and more from the slab, measured.
const FAR_LOSS: f32 = 0.0013;

#[test]
fn a_slab_on_the_plane_occludes_its_foot_and_little_far_away() {
    if !gpu_or_skip() {
        return;
    }
    let mut app = app();
    let target = target(&mut app, SIZE, SIZE);
    let camera = camera(&mut app, &target, top_down(), Mesostructure::default());
    let bricks = image(&mut app, HeightMap::bricks(256, 4, 0.15).to_image());
    let material = unlit(&mut app, Color::WHITE);
    mesostructure_plane(&mut app, material.clone(), bricks, 0.05);
    // A low slab (seen from above, its top is within the coarse radius of its foot).
    let slab = mesh(&mut app, Cuboid::new(0.3, 0.12, 0.3));
    app.world_mut()
        .spawn((slab, material, Transform::from_xyz(0.0, 0.06, 0.0)));
    let with = capture(&mut app, camera, 5);
    app.world_mut()
        .get_mut::<Mesostructure>(camera)
        .unwrap()
        .coarse_occlusion = false;
    run(&mut app, 1);
    let without = capture(&mut app, camera, 5);

    // Distance in pixels from each plane pixel to the slab's footprint on screen.
    let index = |x: u32, y: u32| (y * SIZE + x) as usize;
    let boxed: Vec<(i32, i32)> = (0..SIZE * SIZE)
        .filter(|&i| with.mhm[i as usize][2] == 0.0)
        .map(|i| ((i % SIZE) as i32, (i / SIZE) as i32))
        .collect();
    assert!(boxed.len() > 100, "the slab covers the middle of the plane");
    let (mut near, mut near_ratio, mut far, mut far_loss) = (0, 0.0, 0, 0.0f32);
    let mut darkened = 0;
    for y in 4..SIZE - 4 {
        for x in 4..SIZE - 4 {
            let i = index(x, y);
            if with.mhm[i][2] == 0.0 {
                continue;
            }
            let d = boxed
                .iter()
                .map(|&(bx, by)| (((bx - x as i32).pow(2) + (by - y as i32).pow(2)) as f32).sqrt())
                .fold(f32::MAX, f32::min);
            if d <= 4.0 {
                near += 1;
                let ratio = with.occlusion[i] / without.occlusion[i].max(1e-6);
                near_ratio += ratio;
                darkened += (ratio < 0.9) as u32;
            } else if d >= 30.0 {
                far += 1;
                far_loss = far_loss.max(1.0 - with.occlusion[i] / without.occlusion[i].max(1e-6));
            }
        }
    }
    let near_ratio = near_ratio / near as f32;
    eprintln!(
        "coarse AO: {near} pixels at the slab's foot keep {near_ratio:.3} of their visibility \
         ({darkened} less than 0.9); \
         {far} pixels 30 px and more away lose at most {far_loss:.4}"
    );
    assert!(
        near > 50 && (near_ratio - 0.923).abs() <= 0.02 && darkened > 20,
        "the slab occludes its foot: {near_ratio}, measured 0.923 ± 0.02"
    );
    // Measured 0.923 and 102 at the foot; far away the slab subtends little, and what it
    // takes is held to its measured value (docs/accuracy.md, "Coarse horizon-based AO").
    assert!(far > 50 && far_loss <= FAR_LOSS + 0.005, "little far from it: {far_loss}");
}

#[test]
fn bevy_ssao_multiplies_with_the_mesostructure_occlusion() {
    if !gpu_or_skip() {
        return;
    }
    // Ambient light only, so the picture is ambient × occlusion; a slab for SSAO to find.
    let render = |ssao: bool| {
        let mut app = app();
        let target = target(&mut app, SIZE, SIZE);
        let camera = camera(&mut app, &target, top_down(), Mesostructure::default());
        if ssao {
            app.world_mut()
                .entity_mut(camera)
                .insert(bevy::pbr::ScreenSpaceAmbientOcclusion::default());
        }
        app.insert_resource(bevy::light::GlobalAmbientLight {
            brightness: 2000.0,
            ..default()
        });
        let bricks = image(&mut app, HeightMap::bricks(256, 4, 0.15).to_image());
        let grey = app
            .world_mut()
            .resource_mut::<Assets<StandardMaterial>>()
            .add(Color::srgb(0.6, 0.6, 0.6));
        mesostructure_plane(&mut app, MeshMaterial3d(grey.clone()), bricks, 0.05);
        let slab = mesh(&mut app, Cuboid::new(0.3, 0.12, 0.3));
        app.world_mut().spawn((
            slab,
            MeshMaterial3d(grey),
            Transform::from_xyz(0.0, 0.06, 0.0),
        ));
        let frame = capture(&mut app, camera, 5);
        (
            crate::lighting::pixels(&screenshot(&mut app, &target)),
            frame,
        )
    };
    let (plain, frame) = render(false);
    let (with_ssao, _) = render(true);
    let (mut brighter, mut darker, mut total) = (0, 0, 0);
    let mut sums = (0u32, 0u32);
    for i in 0..plain.len() {
        if frame.mhm[i][2] == 0.0 {
            continue;
        }
        total += 1;
        brighter += (with_ssao[i][1] > plain[i][1].saturating_add(1)) as u32;
        darker += (with_ssao[i][1] + 2 < plain[i][1]) as u32;
        sums.0 += plain[i][1] as u32;
        sums.1 += with_ssao[i][1] as u32;
    }
    eprintln!(
        "mean green without SSAO {}, with {}",
        sums.0 / total,
        sums.1 / total
    );
    eprintln!(
        "SSAO on top of the mesostructure occlusion: {darker} of {total} mesostructure pixels \
         darker, {brighter} brighter"
    );
    // Multiplying by SSAO's visibility (≤ 1) never brightens. (Bevy's SSAO darkens even a flat
    // plane by about as much without this plugin: 160 → 151 in the same setting.)
    assert!(brighter * 100 <= total, "SSAO brightened {brighter} pixels");
    assert!(darker > 50, "SSAO darkened only {darker} pixels");
}
