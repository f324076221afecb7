//! Bad input: each case gets a one-time warning and a sane fallback; nothing panics and the
//! rest of the scene still renders.

use bevy::{
    asset::RenderAssetUsages,
    mesh::{Indices, PrimitiveTopology},
    prelude::*,
    render::render_resource::{Extent3d, TextureDimension, TextureFormat},
};
use bevy_mesostructure::prelude::*;

use crate::harness::*;

fn gray_image(format: TextureFormat, w: u32, h: u32, texel: impl Fn(u32, u32) -> Vec<u8>) -> Image {
    let mut data = Vec::new();
    for y in 0..h {
        for x in 0..w {
            data.extend(texel(x, y));
        }
    }
    Image::new(
        Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        data,
        format,
        RenderAssetUsages::default(),
    )
}

fn bump(x: u32, y: u32, w: u32, h: u32) -> f32 {
    let (u, v) = (
        (x as f32 + 0.5) / w as f32 - 0.5,
        (y as f32 + 0.5) / h as f32 - 0.5,
    );
    (1.0 - 4.0 * (u * u + v * v)).max(0.0)
}

#[test]
fn odd_height_maps_and_meshes_fall_back_without_panicking() {
    if !gpu_or_skip() {
        return;
    }
    let mut app = app();
    app.insert_resource(ClearColor(Color::BLACK));
    let target = target(&mut app, 192, 128);
    let camera = camera(
        &mut app,
        &target,
        Transform::from_xyz(0.0, 0.0, 6.0).looking_at(Vec3::ZERO, Vec3::Y),
        Mesostructure::default(),
    );
    let quad = Plane3d::new(Vec3::Z, Vec2::splat(0.45));
    let plane = mesh(&mut app, quad.mesh());
    let green = unlit(&mut app, Color::srgb(0.0, 1.0, 0.0));

    // Valid formats: 8-bit grey, 16-bit grey, RGBA8 sRGB, R32Float, non-square.
    let g8 = gray_image(TextureFormat::R8Unorm, 32, 32, |x, y| {
        vec![(bump(x, y, 32, 32) * 255.0) as u8]
    });
    let g16 = gray_image(TextureFormat::R16Unorm, 32, 32, |x, y| {
        ((bump(x, y, 32, 32) * 65535.0) as u16)
            .to_le_bytes()
            .to_vec()
    });
    let rgba = gray_image(TextureFormat::Rgba8UnormSrgb, 32, 32, |x, y| {
        let v = (bump(x, y, 32, 32) * 255.0) as u8;
        vec![v, v, v, 255]
    });
    let f32s = gray_image(TextureFormat::R32Float, 32, 32, |x, y| {
        bump(x, y, 32, 32).to_le_bytes().to_vec()
    });
    let wide = gray_image(TextureFormat::R8Unorm, 48, 16, |x, y| {
        vec![(bump(x, y, 48, 16) * 255.0) as u8]
    });
    let valid: Vec<Handle<Image>> = [g8, g16, rgba, f32s, wide]
        .into_iter()
        .map(|i| image(&mut app, i))
        .collect();
    // Still loading: a handle whose image arrives later.
    let late = app
        .world_mut()
        .resource_mut::<Assets<Image>>()
        .reserve_handle();
    // Missing on disk, and an unsupported format.
    let missing: Handle<Image> = app
        .world()
        .resource::<AssetServer>()
        .load("no/such/height_map.png");
    let depth = image(
        &mut app,
        gray_image(TextureFormat::R8Sint, 4, 4, |_, _| vec![0]),
    );

    let at = |app: &mut App, i: usize, mesh: Mesh3d, material: MesostructureMaterial| {
        let (col, row) = ((i % 6) as f32, (i / 6) as f32);
        app.world_mut()
            .spawn((
                mesh,
                green.clone(),
                material,
                Transform::from_xyz(-2.5 + col, 1.0 - row, 0.0),
            ))
            .id()
    };
    let mut good = Vec::new();
    for (i, h) in valid.iter().enumerate() {
        good.push(at(
            &mut app,
            i,
            plane.clone(),
            MesostructureMaterial {
                height_map: h.clone(),
                scale: 0.1,
                ..default()
            },
        ));
    }
    let late_entity = at(
        &mut app,
        5,
        plane.clone(),
        MesostructureMaterial {
            height_map: late.clone(),
            scale: 0.1,
            ..default()
        },
    );
    let m = |h: &Handle<Image>, scale: f32| MesostructureMaterial {
        height_map: h.clone(),
        scale,
        ..default()
    };
    at(&mut app, 6, plane.clone(), m(&missing, 0.1));
    at(&mut app, 7, plane.clone(), m(&depth, 0.1));
    at(&mut app, 8, plane.clone(), m(&valid[0], 0.0));
    at(&mut app, 9, plane.clone(), m(&valid[0], -1.0));
    at(&mut app, 10, plane.clone(), m(&valid[0], f32::NAN));
    at(
        &mut app,
        11,
        plane.clone(),
        MesostructureMaterial {
            scale: 0.1,
            ..default()
        },
    ); // no height map
    // Meshes without UVs and without normals.
    let mut no_uv = quad.mesh().build();
    no_uv.remove_attribute(Mesh::ATTRIBUTE_UV_0);
    let mut no_normals = quad.mesh().build();
    no_normals.remove_attribute(Mesh::ATTRIBUTE_NORMAL);
    let no_uv = mesh(&mut app, no_uv);
    let no_normals = mesh(&mut app, no_normals);
    at(&mut app, 12, no_uv, m(&valid[0], 0.1));
    at(&mut app, 13, no_normals, m(&valid[0], 0.1));
    // A degenerate mesh (no triangles) with the component.
    let empty = mesh(
        &mut app,
        Mesh::new(
            PrimitiveTopology::TriangleList,
            RenderAssetUsages::default(),
        )
        .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, Vec::<[f32; 3]>::new())
        .with_inserted_indices(Indices::U32(vec![])),
    );
    at(&mut app, 14, empty, m(&valid[0], 0.1));

    let first = capture(&mut app, camera, 20);
    let ids: std::collections::BTreeSet<u32> = first
        .mhm
        .iter()
        .map(|t| t[2] as u32)
        .filter(|&i| i != 0)
        .collect();
    let expected: std::collections::BTreeSet<u32> =
        good.iter().map(|e| e.index_u32() + 1).collect();
    assert_eq!(
        ids, expected,
        "exactly the five valid height maps give mesostructure pixels"
    );

    // The late image arrives: its plane joins.
    app.world_mut()
        .resource_mut::<Assets<Image>>()
        .insert(
            late.id(),
            gray_image(TextureFormat::R8Unorm, 8, 8, |x, y| {
                vec![(bump(x, y, 8, 8) * 255.0) as u8]
            }),
        )
        .unwrap();
    run(&mut app, 2);
    let second = capture(&mut app, camera, 5);
    assert!(
        second
            .mhm
            .iter()
            .any(|t| t[2] as u32 == late_entity.index_u32() + 1),
        "the late height map is used once loaded"
    );

    // Every quad still renders green, mesostructure or not (the degenerate mesh draws nothing).
    let shot = screenshot(&mut app, &target);
    let data = shot.data.as_ref().unwrap();
    for i in 0..14 {
        let (col, row) = ((i % 6) as f32, (i / 6) as f32);
        // World (−2.5 + col, 1 − row) → pixel, at 6 units with a 45° vertical fov.
        let half_h = 6.0 * (std::f32::consts::FRAC_PI_8).tan();
        let px = ((-2.5 + col) / (half_h * 1.5) * 0.5 + 0.5) * 192.0;
        let py = (0.5 - (1.0 - row) / half_h * 0.5) * 128.0;
        let o = ((py as u32 * 192 + px as u32) * 4) as usize;
        assert!(
            data[o + 1] > 200 && data[o] < 30,
            "quad {i} is drawn: {:?}",
            &data[o..o + 3]
        );
    }

    let w = warnings(&app);
    for key in [
        "scale",
        "missing",
        "failed",
        "convert",
        "attributes",
        "note",
    ] {
        assert!(
            w.iter().any(|k| k.starts_with(key)),
            "a warning about {key}: {w:?}"
        );
    }
    // One-time: running on gives no new warnings.
    let count = w.len();
    run(&mut app, 3);
    assert_eq!(warnings(&app).len(), count);
}

#[test]
fn msaa_and_nan_settings_do_not_panic() {
    if !gpu_or_skip() {
        return;
    }
    let mut app = app();
    let map = image(&mut app, HeightMap::sine(64, 2).to_image());
    let white = unlit(&mut app, Color::WHITE);
    mesostructure_plane(&mut app, white, map, 0.1);

    // MSAA on: the effect is off for this camera, the scene renders.
    let t1 = target(&mut app, 64, 64);
    let msaa = camera(&mut app, &t1, top_down(), Mesostructure::default());
    app.world_mut().entity_mut(msaa).insert(Msaa::Sample4);
    // (A zero-sized viewport is not tested end to end: Bevy 0.19.1's own light clustering
    // fails validation on it before any pass of ours runs.)
    // NaN and out-of-range settings: sanitized, the effect runs.
    let t3 = target(&mut app, 64, 64);
    let nan = camera(
        &mut app,
        &t3,
        top_down(),
        Mesostructure {
            depth_discontinuity: f32::NAN,
            quality: MesostructureQuality::High.custom(|c| {
                c.apex_directions = 1000;
                c.max_ascent_steps = 0;
            }),
            ..default()
        },
    );
    app.world_mut().entity_mut(nan).insert(Camera {
        order: 1,
        ..default()
    });

    let frame = capture(&mut app, nan, 20);
    assert_eq!(frame.mesostructure_pixels(), 64 * 64);
    assert_eq!(frame.apex_stride, 2 + 16, "apex_directions clamped to 16");
    let captures = app
        .world()
        .resource::<bevy_mesostructure::MesostructureCaptures>()
        .clone();
    run(&mut app, 2);
    // Mesostructure requires the deferred prepass, and Bevy turns MSAA off on deferred cameras
    // (with its own warning): the effect then runs.
    assert_eq!(app.world().get::<Msaa>(msaa), Some(&Msaa::Off));
    assert!(
        (0..10).any(|_| {
            run(&mut app, 1);
            captures.take(msaa).is_some()
        }),
        "the effect runs once MSAA is off"
    );
    let shot = screenshot(&mut app, &t1);
    assert!(
        shot.data.as_ref().unwrap()[..4]
            .iter()
            .take(3)
            .all(|&c| c > 200),
        "the MSAA camera still renders the plane"
    );
    let w = warnings(&app);
    assert!(
        w.iter().any(|k| k.starts_with("settings")),
        "a warning about settings: {w:?}"
    );
}

#[test]
fn an_apex_buffer_too_large_for_the_gpu_leaves_the_surface_lit_without_the_terms() {
    if !gpu_or_skip() {
        return;
    }
    // A GPU that binds at most 1 MiB of storage buffer: a 128² view at `ultra` needs
    // 128² × 18 words (1.2 MB) of apex sets.
    let mut app = app_with_limits(bevy::render::settings::WgpuLimits {
        max_storage_buffer_binding_size: 1 << 20,
        ..default()
    });
    let map = image(&mut app, HeightMap::bricks(128, 4, 0.15).to_image());
    let grey = app
        .world_mut()
        .resource_mut::<Assets<StandardMaterial>>()
        .add(Color::srgb(0.5, 0.5, 0.5));
    mesostructure_plane(&mut app, MeshMaterial3d(grey), map, 0.1);
    app.world_mut().spawn((
        DirectionalLight {
            illuminance: 10_000.0,
            ..default()
        },
        Transform::from_xyz(1.0, 3.0, 2.0).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    let t = target(&mut app, 128, 128);
    camera(
        &mut app,
        &t,
        top_down(),
        Mesostructure {
            quality: MesostructureQuality::Ultra,
            ..default()
        },
    );
    run(&mut app, 5);
    let shot = screenshot(&mut app, &t);
    let data = shot.data.as_ref().unwrap();
    // The plane is lit by Bevy's terms through the plugin's lighting pass (210 measured), not
    // left at the clear colour (43) as when the lighting pass skipped such a view.
    let centre = ((64 * 128 + 64) * 4) as usize;
    assert!(
        data[centre..centre + 3].iter().all(|&c| c > 150),
        "the plane is lit: {:?}",
        &data[centre..centre + 3]
    );
    let w = warnings(&app);
    assert!(
        w.iter().any(|k| k.starts_with("apex buffer")),
        "a warning about the apex buffer: {w:?}"
    );
}
