//! The same scene five ways: no effect, Bevy's SSAO, Bevy's parallax mapping, this plugin, and
//! this plugin with Bevy's SSAO on top. A bricks plane with a box standing on it, a low light.
//!
//! ```text
//! cargo run --example compare -- [--frames N] [--out DIR] [--size WxH] [--headless]
//! ```
//!
//! In a window, C cycles the five (the title names the current one); headless, one PNG each in
//! `out/compare/` (`compare_<mode>.png`).

#[path = "common/mod.rs"]
mod common;

use bevy::{
    image::{ImageAddressMode, ImageSampler, ImageSamplerDescriptor},
    pbr::{ParallaxMappingMethod, ScreenSpaceAmbientOcclusion},
    prelude::*,
};
use bevy_mesostructure::prelude::*;

/// Height of white in the height map, world units; the plane is 2.4 wide.
const K: f32 = 0.08;
const PLANE: f32 = 2.4;

#[derive(Resource, Clone, Copy, PartialEq, Eq, Debug)]
enum Mode {
    Plain,
    Ssao,
    Parallax,
    Plugin,
    PluginAndSsao,
}

impl Mode {
    const ALL: [Mode; 5] = [
        Mode::Plain,
        Mode::Ssao,
        Mode::Parallax,
        Mode::Plugin,
        Mode::PluginAndSsao,
    ];

    fn name(self) -> &'static str {
        match self {
            Mode::Plain => "plain",
            Mode::Ssao => "bevy-ssao",
            Mode::Parallax => "bevy-parallax",
            Mode::Plugin => "mesostructure",
            Mode::PluginAndSsao => "mesostructure+ssao",
        }
    }
}

/// The bricks plane's variants.
#[derive(Component)]
struct Variants {
    plain: Handle<StandardMaterial>,
    parallax: Handle<StandardMaterial>,
    mesostructure: MesostructureMaterial,
}

/// The bricks plane five ways: plain, Bevy's SSAO, Bevy's parallax mapping, this plugin, and
/// this plugin with SSAO.
#[derive(clap::Parser)]
#[command(long_about = None)]
struct Cli {
    #[command(flatten)]
    common: common::CommonArgs,
}

fn main() {
    use clap::Parser;
    let args = common::ExampleArgs::from_cli("compare", Cli::parse().common);
    let shots = Mode::ALL
        .into_iter()
        .map(|mode| common::Shot {
            file: format!("compare_{}.png", mode.name()),
            apply: Box::new(move |world: &mut World| apply(world, mode)),
        })
        .collect();
    let mut app = common::app(&args, "bevy_mesostructure: compare", shots);
    app.insert_resource(ClearColor(Color::srgb(0.55, 0.62, 0.72)))
        .insert_resource(bevy::light::GlobalAmbientLight {
            brightness: 1500.0,
            ..default()
        })
        .insert_resource(Mode::PluginAndSsao)
        .add_systems(Update, cycle);
    setup(app.world_mut());
    apply(app.world_mut(), Mode::Plugin);
    common::run(app);
}

fn setup(world: &mut World) {
    let target = world.resource::<common::Output>().target();
    world.spawn((
        Camera3d::default(),
        target,
        Msaa::Off,
        Transform::from_xyz(0.0, 1.6, 2.2).looking_at(Vec3::new(0.0, -0.1, 0.0), Vec3::Y),
    ));
    world.spawn((
        DirectionalLight {
            illuminance: 8000.0,
            shadow_maps_enabled: true,
            ..default()
        },
        Transform::from_xyz(-2.5, 1.4, 0.8).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    let map = HeightMap::bricks(512, 8, 0.15);
    let height_map = world.resource_mut::<Assets<Image>>().add(map.to_image());
    let colours = world.resource_mut::<Assets<Image>>().add(common::two_tone(
        &map,
        [191, 97, 71],
        [217, 214, 207],
    ));
    // Bevy's parallax mapping reads depth (white = deep): the inverted height map.
    let mut depth = HeightMap {
        values: map.values.iter().map(|v| 1.0 - v).collect(),
        ..map.clone()
    }
    .to_image_gray8();
    depth.sampler = ImageSampler::Descriptor(ImageSamplerDescriptor {
        address_mode_u: ImageAddressMode::Repeat,
        address_mode_v: ImageAddressMode::Repeat,
        ..ImageSamplerDescriptor::linear()
    });
    let depth = world.resource_mut::<Assets<Image>>().add(depth);
    let mut materials = world.resource_mut::<Assets<StandardMaterial>>();
    let plain = materials.add(StandardMaterial {
        base_color_texture: Some(colours.clone()),
        perceptual_roughness: 0.8,
        ..default()
    });
    let parallax = materials.add(StandardMaterial {
        base_color_texture: Some(colours),
        perceptual_roughness: 0.8,
        depth_map: Some(depth),
        // Depth relative to the texture's extent (the plane).
        parallax_depth_scale: K / PLANE,
        parallax_mapping_method: ParallaxMappingMethod::Relief { max_steps: 5 },
        max_parallax_layer_count: 32.0,
        ..default()
    });
    let grey = materials.add(Color::srgb(0.7, 0.7, 0.72));
    let plane = world.resource_mut::<Assets<Mesh>>().add(
        Plane3d::default()
            .mesh()
            .size(PLANE, PLANE)
            .build()
            .with_generated_tangents()
            .expect("a plane has UVs and normals"),
    );
    world.spawn((
        Mesh3d(plane),
        MeshMaterial3d(plain.clone()),
        Variants {
            plain,
            parallax,
            mesostructure: MesostructureMaterial {
                height_map,
                scale: K,
                ..default()
            },
        },
    ));
    let cube = world
        .resource_mut::<Assets<Mesh>>()
        .add(Cuboid::new(0.5, 0.5, 0.5));
    world.spawn((
        Mesh3d(cube),
        MeshMaterial3d(grey),
        Transform::from_xyz(0.35, 0.25 + K, -0.2).with_rotation(Quat::from_rotation_y(0.5)),
    ));
}

/// Sets the camera's effects and the plane's material for `mode`.
fn apply(world: &mut World, mode: Mode) {
    world.insert_resource(mode);
    let cameras: Vec<Entity> = world
        .query_filtered::<Entity, With<Camera3d>>()
        .iter(world)
        .collect();
    for camera in cameras {
        let mut e = world.entity_mut(camera);
        if matches!(mode, Mode::Plugin | Mode::PluginAndSsao) {
            e.insert(Mesostructure::default());
        } else {
            e.remove::<Mesostructure>();
        }
        if matches!(mode, Mode::Ssao | Mode::PluginAndSsao) {
            e.insert(ScreenSpaceAmbientOcclusion::default());
        } else {
            e.remove::<ScreenSpaceAmbientOcclusion>();
        }
    }
    let planes: Vec<Entity> = world
        .query_filtered::<Entity, With<Variants>>()
        .iter(world)
        .collect();
    for plane in planes {
        let variants = world.get::<Variants>(plane).unwrap();
        let (plain, parallax, meso) = (
            variants.plain.clone(),
            variants.parallax.clone(),
            variants.mesostructure.clone(),
        );
        let mut e = world.entity_mut(plane);
        match mode {
            Mode::Parallax => {
                e.remove::<MesostructureMaterial>();
                e.insert(MeshMaterial3d(parallax));
            }
            Mode::Plugin | Mode::PluginAndSsao => {
                e.insert((MeshMaterial3d(plain), meso));
            }
            Mode::Plain | Mode::Ssao => {
                e.remove::<MesostructureMaterial>();
                e.insert(MeshMaterial3d(plain));
            }
        }
    }
    let mut windows = world.query::<&mut Window>();
    for mut window in windows.iter_mut(world) {
        window.title = format!("bevy_mesostructure: compare — {} (C: next)", mode.name());
    }
}

fn cycle(world: &mut World) {
    let pressed = world
        .get_resource::<ButtonInput<KeyCode>>()
        .is_some_and(|i| i.just_pressed(KeyCode::KeyC));
    if pressed {
        let mode = *world.resource::<Mode>();
        let i = Mode::ALL.iter().position(|m| *m == mode).unwrap_or(0);
        apply(world, Mode::ALL[(i + 1) % Mode::ALL.len()]);
    }
}
