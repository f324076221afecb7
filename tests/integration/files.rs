//! Height maps loaded from files through Bevy's asset server — 8-bit and 16-bit grey PNG and
//! 32-bit float EXR (written by `cargo run --example height_maps`) — give the same screen-space
//! height map as the map built in memory.

use bevy::prelude::*;
use bevy_mesostructure::prelude::*;

use crate::harness::*;

const SIZE: u32 = 64;

/// The height-map values `dis` the height pass saw, per pixel.
fn rendered(height_map: impl FnOnce(&mut App) -> Handle<Image>) -> Vec<f32> {
    let mut app = app();
    let target = target(&mut app, SIZE, SIZE);
    let camera = camera(&mut app, &target, top_down(), Mesostructure::default());
    let map = height_map(&mut app);
    let material = unlit(&mut app, Color::WHITE);
    mesostructure_plane(&mut app, material, map, 0.1);
    let frame = capture(&mut app, camera, 30);
    assert_eq!(frame.mesostructure_pixels(), (SIZE * SIZE) as usize);
    frame.mhm.iter().map(|t| t[3]).collect()
}

#[test]
fn png_8_and_16_bit_and_exr_height_maps_load_like_the_map_in_memory() {
    if !gpu_or_skip() {
        return;
    }
    let reference =
        rendered(|app| image(app, HeightMap::by_name("stone", 128).unwrap().to_image()));
    // 8-bit quantization is 1/255 ≈ 0.004.
    for (file, tolerance) in [
        ("stone_8bit.png", 0.004),
        ("stone_16bit.png", 0.0005),
        ("stone_float.exr", 0.0005),
    ] {
        let path = format!("height_maps/formats/{file}");
        let loaded = rendered(|app| app.world().resource::<AssetServer>().load(path));
        let worst = loaded
            .iter()
            .zip(&reference)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        eprintln!("{file}: worst difference from the map in memory {worst:.5}");
        assert!(worst <= tolerance, "{file}: {worst} > {tolerance}");
    }
}

/// A height map's mip chain and texture-space horizon map (seconds for a large map in an
/// unoptimised build) are built on a background task: the frame that meets the map returns
/// with the build under way and the mesh drawn without mesostructure; once built, the effect
/// appears.
#[test]
fn height_maps_are_derived_in_the_background() {
    if !gpu_or_skip() {
        return;
    }
    let mut app = app();
    let target = target(&mut app, SIZE, SIZE);
    let camera = camera(&mut app, &target, top_down(), Mesostructure::default());
    let map = image(&mut app, HeightMap::noise(1024, 8, 4, 7).to_image());
    let material = unlit(&mut app, Color::WHITE);
    mesostructure_plane(&mut app, material, map, 0.1);
    app.update();
    assert_eq!(
        *app.world().resource::<MesostructureStatus>(),
        MesostructureStatus {
            height_maps_building: 1,
            height_maps_ready: 0
        },
        "the first frame returns while the map is built"
    );
    // (`run`, under `capture`, waits for the build.)
    let frame = capture(&mut app, camera, 30);
    assert_eq!(
        *app.world().resource::<MesostructureStatus>(),
        MesostructureStatus {
            height_maps_building: 0,
            height_maps_ready: 1
        }
    );
    assert!(
        frame.mesostructure_pixels() > (SIZE * SIZE / 2) as usize,
        "the plane is a mesostructure surface once its map is built"
    );
}
