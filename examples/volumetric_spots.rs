//! Volumetric spot lights (seed 004): a dark room with brick walls (mesostructure), three
//! swinging spot lights seen in a light haze, and a pillar casting shafts through their beams.
//!
//! Where there is a display it opens a window with the tuning panel (the medium on the camera,
//! each spot's `VolumetricSpot`, the mesostructure settings; the GPU time of each pass). Where
//! there is none (or with `--headless`) it renders headless and writes PNG screenshots: the
//! room, and the same frame without the haze.
//!
//! ```text
//! cargo run --example volumetric_spots -- [--frames N] [--out DIR] [--size WxH] [--headless]
//!     [--samples N] [--scattering S] [--asymmetry G] [--method equal-angle|planes]
//! ```

#[path = "common/mod.rs"]
mod common;

use bevy::{camera::Hdr, prelude::*};
use bevy_mesostructure::{
    prelude::*,
    volumetric::{VolumetricMedium, VolumetricMethod, VolumetricSpot, VolumetricSpotsPlugin},
};

/// A dark room lit by swinging spot lights in a haze; a window with the tuning panel, or
/// headless PNGs with and without the haze.
#[derive(clap::Parser)]
#[command(long_about = None)]
struct Cli {
    #[command(flatten)]
    common: common::CommonArgs,
    /// Points per pixel and spot at equal angles around the light, or planes per spot (1–64)
    #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u32).range(1..=64))]
    samples: u32,
    /// Scattering coefficient of the haze, per metre (> 0)
    #[arg(long, default_value_t = 0.12, value_parser = common::parse_positive)]
    scattering: f32,
    /// Henyey–Greenstein asymmetry of the haze (−0.95 to 0.95)
    #[arg(long, default_value_t = 0.3, allow_negative_numbers = true, value_parser = parse_asymmetry)]
    asymmetry: f32,
    /// How the in-scatter is sampled: per-pixel rays at equal angles, or seed 004's slicing
    /// planes (`samples` per spot)
    #[arg(long, value_enum, default_value_t = Method::EqualAngle)]
    method: Method,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum Method {
    EqualAngle,
    Planes,
}

fn parse_asymmetry(s: &str) -> Result<f32, String> {
    let g: f32 = s.parse().map_err(|_| format!("{s:?} is not a number"))?;
    if (-0.95..=0.95).contains(&g) {
        Ok(g)
    } else {
        Err(format!("{g} is outside −0.95 to 0.95"))
    }
}

fn main() {
    use clap::Parser;
    let cli = Cli::parse();
    let args = common::ExampleArgs::from_cli("volumetric_spots", cli.common);
    let shots = vec![
        common::Shot {
            file: "volumetric_spots.png".into(),
            apply: Box::new(|_: &mut World| {}),
        },
        common::Shot {
            file: "volumetric_spots_no-haze.png".into(),
            apply: Box::new(|world: &mut World| {
                let mut cameras = world.query_filtered::<Entity, With<VolumetricMedium>>();
                for camera in cameras.iter(world).collect::<Vec<_>>() {
                    world.entity_mut(camera).remove::<VolumetricMedium>();
                }
            }),
        },
    ];
    let mut app = common::app(&args, "bevy_mesostructure: volumetric spots", shots);
    app.add_plugins(VolumetricSpotsPlugin)
        .insert_resource(ClearColor(Color::BLACK))
        .insert_resource(bevy::light::GlobalAmbientLight {
            brightness: 20.0,
            ..default()
        })
        .add_systems(Update, swing_spots);
    setup(
        app.world_mut(),
        VolumetricMedium {
            scattering: cli.scattering,
            absorption: 0.01,
            asymmetry: cli.asymmetry,
            method: match cli.method {
                Method::EqualAngle => VolumetricMethod::EqualAngleRays,
                Method::Planes => VolumetricMethod::SlicingPlanes,
            },
            ..default()
        },
        cli.samples,
    );
    common::run(app);
}

/// A spot that swings about its mount: `phase` offsets it from the others.
#[derive(Component)]
struct Swing {
    mount: Vec3,
    phase: f32,
}

fn setup(world: &mut World, medium: VolumetricMedium, samples: u32) {
    let target = world.resource::<common::Output>().target();
    world.spawn((
        Camera3d::default(),
        target,
        Hdr,
        Msaa::Off,
        Mesostructure::default(),
        medium,
        Transform::from_xyz(0.0, 1.7, 7.5).looking_at(Vec3::new(0.0, 1.6, 0.0), Vec3::Y),
    ));

    // Brick walls and floor: mesostructure surfaces.
    let map = HeightMap::bricks(512, 6, 0.12);
    let height_map = world.resource_mut::<Assets<Image>>().add(map.to_image());
    let colours = world.resource_mut::<Assets<Image>>().add(common::two_tone(
        &map,
        [150, 80, 62],
        [170, 166, 158],
    ));
    // Bricks of about 0.4 m: the maps repeat 4 times across a 10 m surface.
    let tiling = bevy::math::Affine2::from_scale(Vec2::splat(4.0));
    let bricks = world
        .resource_mut::<Assets<StandardMaterial>>()
        .add(StandardMaterial {
            base_color_texture: Some(colours),
            perceptual_roughness: 0.85,
            uv_transform: tiling,
            ..default()
        });
    let wall = world
        .resource_mut::<Assets<Mesh>>()
        .add(Plane3d::default().mesh().size(10.0, 5.0));
    let floor = world
        .resource_mut::<Assets<Mesh>>()
        .add(Plane3d::default().mesh().size(10.0, 10.0));
    let surfaces = [
        (floor.clone(), Transform::default()),
        (
            wall.clone(),
            Transform::from_xyz(0.0, 2.5, -3.0).with_rotation(Quat::from_rotation_x(std::f32::consts::FRAC_PI_2)),
        ),
        (
            wall.clone(),
            Transform::from_xyz(-4.0, 2.5, 1.0).with_rotation(
                Quat::from_rotation_y(std::f32::consts::FRAC_PI_2)
                    * Quat::from_rotation_x(std::f32::consts::FRAC_PI_2),
            ),
        ),
        (
            wall,
            Transform::from_xyz(4.0, 2.5, 1.0).with_rotation(
                Quat::from_rotation_y(-std::f32::consts::FRAC_PI_2)
                    * Quat::from_rotation_x(std::f32::consts::FRAC_PI_2),
            ),
        ),
    ];
    for (mesh, transform) in surfaces {
        world.spawn((
            Mesh3d(mesh),
            MeshMaterial3d(bricks.clone()),
            MesostructureMaterial {
                height_map: height_map.clone(),
                scale: 0.04,
                uv_transform: tiling,
                ..default()
            },
            transform,
        ));
    }

    // A pillar that casts shafts through the beams.
    let pillar = world
        .resource_mut::<Assets<Mesh>>()
        .add(Cuboid::new(0.5, 2.2, 0.5));
    let grey = world
        .resource_mut::<Assets<StandardMaterial>>()
        .add(Color::srgb(0.4, 0.4, 0.42));
    world.spawn((
        Mesh3d(pillar),
        MeshMaterial3d(grey),
        Transform::from_xyz(0.2, 2.4, 0.0),
    ));

    // Three spots under the ceiling, swinging.
    for (i, (x, colour)) in [
        (-2.2, Color::srgb(1.0, 0.85, 0.65)),
        (0.0, Color::srgb(0.7, 0.8, 1.0)),
        (2.2, Color::srgb(1.0, 0.6, 0.35)),
    ]
    .into_iter()
    .enumerate()
    {
        let mount = Vec3::new(x, 4.6, -0.5);
        world.spawn((
            SpotLight {
                color: colour,
                intensity: 300_000.0,
                range: 20.0,
                outer_angle: 0.38,
                inner_angle: 0.28,
                shadow_maps_enabled: true,
                ..default()
            },
            VolumetricSpot {
                samples,
                ..default()
            },
            Swing {
                mount,
                phase: i as f32 * 2.1,
            },
            Transform::from_translation(mount).looking_at(Vec3::new(x, 0.0, -0.5), Vec3::Z),
        ));
    }
}

fn swing_spots(clock: Res<common::Clock>, mut spots: Query<(&Swing, &mut Transform)>) {
    for (swing, mut transform) in &mut spots {
        let a = (clock.t * 0.7 + swing.phase).sin() * 0.5;
        let b = (clock.t * 0.45 + swing.phase).cos() * 0.35;
        let aim = swing.mount + Vec3::new(a.sin() * 4.6, -4.6, b.sin() * 4.6 + 0.8);
        *transform = Transform::from_translation(swing.mount).looking_at(aim, Vec3::Z);
    }
}
