//! A gallery: a torus, the Utah teapot and the Stanford bunny (rows), each with four height
//! maps at scales across the paper's valid range 0.05–0.8 (columns): bricks at 0.05, weave at
//! 0.15, rivets at 0.4, stone at 0.8 (world units of height for objects about 1.6 across).
//! The teapot and bunny come from the public-domain npm packages `teapot` and `bunny`, converted
//! once into `assets/meshes/*.obj` (see `assets/meshes/convert_npm.py`); they have no UVs, so
//! they get a spherical projection.
//!
//! ```text
//! cargo run --example gallery -- [--frames N] [--out DIR] [--size WxH] [--headless]
//!     [--view none|occlusion|micro-shadow|bleeding|...|all]
//! ```
//!
//! Windowed where there is a display (with the tuning panel and keys of the `deforming`
//! example), headless PNGs in `out/gallery/` where not.

#[path = "common/mod.rs"]
mod common;

use bevy::prelude::*;
use bevy_mesostructure::prelude::*;

/// The columns: height map and scale k.
const COLUMNS: [(&str, f32); 4] = [
    ("bricks", 0.05),
    ("weave", 0.15),
    ("rivets", 0.4),
    ("stone", 0.8),
];

/// A torus, the teapot and the bunny with four height maps each.
#[derive(clap::Parser)]
#[command(long_about = None)]
struct Cli {
    #[command(flatten)]
    common: common::CommonArgs,
    /// Debug view to write: none, height, gradient, apex-distance, apex-count, boundary,
    /// occlusion, micro-shadow, bleeding, or all
    #[arg(long, default_value = "none", value_parser = common::parse_views)]
    view: common::ViewList,
}

fn main() {
    use clap::Parser;
    let cli = Cli::parse();
    let sized = cli.common.size.is_some();
    let mut args = common::ExampleArgs::from_cli("gallery", cli.common);
    if !sized {
        args.size = UVec2::new(960, 640);
    }
    let views = cli.view.0;
    let shots = views
        .into_iter()
        .map(|v| common::view_shot("gallery", v))
        .collect();
    let mut app = common::app(&args, "bevy_mesostructure: gallery", shots);
    app.insert_resource(ClearColor(Color::srgb(0.55, 0.62, 0.72)))
        .insert_resource(bevy::light::GlobalAmbientLight {
            brightness: 1200.0,
            ..default()
        })
        .add_systems(Update, turn);
    setup(app.world_mut());
    common::run(app);
}

#[derive(Component)]
struct Turning;

fn setup(world: &mut World) {
    let target = world.resource::<common::Output>().target();
    world.spawn((
        Camera3d::default(),
        target,
        Msaa::Off,
        Mesostructure::default(),
        Transform::from_xyz(0.0, 2.5, 7.2).looking_at(Vec3::new(0.0, -0.2, 0.0), Vec3::Y),
    ));
    world.spawn((
        DirectionalLight {
            illuminance: 7000.0,
            shadow_maps_enabled: true,
            ..default()
        },
        Transform::from_xyz(-3.0, 4.0, 3.0).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    let models: [(&str, Mesh); 3] = [
        (
            "torus",
            Torus::new(0.45, 0.8)
                .mesh()
                .minor_resolution(24)
                .major_resolution(48)
                .build(),
        ),
        (
            "teapot",
            common::meshes::obj_mesh(&common::meshes::asset_path("meshes/teapot.obj"), 4.0),
        ),
        (
            "bunny",
            common::meshes::obj_mesh(&common::meshes::asset_path("meshes/bunny.obj"), 4.0),
        ),
    ];
    for (row, (name, mesh)) in models.into_iter().enumerate() {
        let mesh = world.resource_mut::<Assets<Mesh>>().add(mesh);
        for (column, (map_name, k)) in COLUMNS.into_iter().enumerate() {
            let map = HeightMap::by_name(map_name, 256).expect("a built-in height map");
            let height_map = world.resource_mut::<Assets<Image>>().add(map.to_image());
            let colours = world.resource_mut::<Assets<Image>>().add(common::two_tone(
                &map,
                [191, 97, 71],
                [217, 214, 207],
            ));
            let material = world
                .resource_mut::<Assets<StandardMaterial>>()
                .add(StandardMaterial {
                    base_color_texture: Some(colours),
                    perceptual_roughness: 0.8,
                    ..default()
                });
            // Torus UVs run once around each way: tile the map more there.
            let uv_transform = if name == "torus" {
                bevy::math::Affine2::from_scale(Vec2::new(6.0, 2.0))
            } else {
                bevy::math::Affine2::IDENTITY
            };
            world.spawn((
                Mesh3d(mesh.clone()),
                MeshMaterial3d(material),
                MesostructureMaterial {
                    height_map,
                    scale: k,
                    uv_transform,
                },
                Transform::from_xyz((column as f32 - 1.5) * 2.1, (1.0 - row as f32) * 1.9, 0.0)
                    .with_scale(Vec3::splat(0.9)),
                Turning,
            ));
        }
    }
}

fn turn(clock: Res<common::Clock>, mut objects: Query<&mut Transform, With<Turning>>) {
    for mut t in &mut objects {
        t.rotation = Quat::from_rotation_y(0.6 + clock.t * 0.3) * Quat::from_rotation_x(0.3);
    }
}
