//! The main example: a mesostructure object morphing between a sphere and a cube (the paper's
//! Fig. 13), with a bricks height map, a moving light and a ground.
//!
//! This build renders headless (no window support is compiled in yet) and writes PNG
//! screenshots of the lit picture and of each debug view:
//!
//! ```text
//! cargo run --example deforming -- [--frames N] [--out DIR] [--size WxH]
//!     [--shape morph|sphere|plane] [--height-map bricks|rivets|weave|sine|stone|cone]
//!     [--scale K] [--off occlusion,micro-shadows,bleeding,bump-mapping]
//!     [--light-height H]
//!     [--view none|height|gradient|apex-distance|apex-count|boundary|occlusion|
//!             micro-shadow|bleeding|all]
//! ```
//!
//! `--off` switches effects off (the file names get `_no-<effect>`); `--light-height` sets how
//! high above the object the circling light stands (default 4; lower casts longer
//! micro-shadows). The object is two-tone: the raised parts of the height map in brick red,
//! the low parts in light grey, so that the bleeding of the red onto the grey shows.

use std::{f32::consts::PI, path::PathBuf};

use bevy::{
    asset::RenderAssetUsages,
    camera::RenderTarget,
    mesh::VertexAttributeValues,
    prelude::*,
    render::{
        RenderPlugin,
        pipelined_rendering::PipelinedRenderingPlugin,
        render_resource::{TextureFormat, TextureUsages},
        view::screenshot::{Screenshot, save_to_disk},
    },
    window::ExitCondition,
};
use bevy_mesostructure::prelude::*;

/// The effects `--off` can switch off.
const EFFECTS: [&str; 4] = ["occlusion", "micro-shadows", "bleeding", "bump-mapping"];

struct Args {
    off: Vec<String>,
    light_height: f32,
    frames: u32,
    out: PathBuf,
    size: UVec2,
    shape: String,
    height_map: String,
    scale: f32,
    views: Vec<MesostructureDebugView>,
}

fn parse_args() -> Args {
    let mut args = Args {
        off: vec![],
        light_height: 4.0,
        frames: 30,
        out: PathBuf::from("out/deforming"),
        size: UVec2::new(512, 384),
        shape: "morph".into(),
        height_map: "bricks".into(),
        scale: 0.08,
        views: MesostructureDebugView::ALL.to_vec(),
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut value = || it.next().unwrap_or_else(|| panic!("{flag} needs a value"));
        match flag.as_str() {
            "--frames" => args.frames = value().parse().expect("--frames N"),
            "--out" => args.out = value().into(),
            "--size" => {
                let v = value();
                let (w, h) = v.split_once('x').unwrap_or((&v, &v));
                args.size = UVec2::new(
                    w.parse().expect("--size WxH"),
                    h.parse().expect("--size WxH"),
                );
            }
            "--shape" => args.shape = value(),
            "--height-map" => args.height_map = value(),
            "--scale" => args.scale = value().parse().expect("--scale K"),
            "--occlusion" => {
                if value() == "off" {
                    args.off.push("occlusion".into());
                }
            }
            "--off" => {
                for effect in value().split(',').filter(|e| !e.is_empty()) {
                    assert!(
                        EFFECTS.contains(&effect),
                        "unknown effect {effect}; one of {EFFECTS:?}"
                    );
                    args.off.push(effect.into());
                }
            }
            "--light-height" => args.light_height = value().parse().expect("--light-height H"),
            "--view" => {
                let v = value();
                args.views = if v == "all" {
                    MesostructureDebugView::ALL.to_vec()
                } else {
                    vec![
                        MesostructureDebugView::from_name(&v)
                            .unwrap_or_else(|| panic!("unknown view {v}")),
                    ]
                };
            }
            "--help" | "-h" => {
                println!("see the doc comment at the top of examples/deforming.rs");
                std::process::exit(0);
            }
            other => panic!("unknown argument {other}"),
        }
    }
    args
}

/// A repeating sRGB colour texture over `map`: `high` where the height map is above 0.1 (the
/// bumps and their walls), `low` on the floor between them.
fn two_tone(map: &HeightMap, high: [u8; 3], low: [u8; 3]) -> Image {
    use bevy::image::{ImageAddressMode, ImageSampler, ImageSamplerDescriptor};
    let data = map
        .values
        .iter()
        .flat_map(|&v| {
            let c = if v > 0.1 { high } else { low };
            [c[0], c[1], c[2], 255]
        })
        .collect();
    let mut image = Image::new(
        bevy::render::render_resource::Extent3d {
            width: map.width,
            height: map.height,
            depth_or_array_layers: 1,
        },
        bevy::render::render_resource::TextureDimension::D2,
        data,
        TextureFormat::Rgba8UnormSrgb,
        RenderAssetUsages::RENDER_WORLD,
    );
    image.sampler = ImageSampler::Descriptor(ImageSamplerDescriptor {
        address_mode_u: ImageAddressMode::Repeat,
        address_mode_v: ImageAddressMode::Repeat,
        ..ImageSamplerDescriptor::linear()
    });
    image
}

/// The morphing object: a UV sphere whose vertices blend towards the cube they project onto.
#[derive(Component)]
struct Morphing {
    sphere: Vec<Vec3>,
}

fn cube_point(p: Vec3) -> Vec3 {
    p / p.abs().max_element() * 0.8
}

fn morph(t: f32, m: &Morphing, mesh: &mut Mesh) {
    let w = 0.5 - 0.5 * (t * 0.8).cos();
    let positions: Vec<[f32; 3]> = m
        .sphere
        .iter()
        .map(|p| p.lerp(cube_point(*p), w).to_array())
        .collect();
    let normals: Vec<[f32; 3]> = m
        .sphere
        .iter()
        .map(|p| {
            let n = p.normalize();
            let a = n.abs();
            let face = if a.x >= a.y && a.x >= a.z {
                Vec3::X * n.x.signum()
            } else if a.y >= a.z {
                Vec3::Y * n.y.signum()
            } else {
                Vec3::Z * n.z.signum()
            };
            n.lerp(face, w).normalize().to_array()
        })
        .collect();
    mesh.insert_attribute(Mesh::ATTRIBUTE_POSITION, positions);
    mesh.insert_attribute(Mesh::ATTRIBUTE_NORMAL, normals);
}

fn main() {
    let args = parse_args();
    std::fs::create_dir_all(&args.out).expect("cannot create the output folder");
    println!(
        "bevy_mesostructure deforming: no window support in this build; rendering {} frames \
         headless, writing PNGs to {}",
        args.frames,
        args.out.display()
    );

    let mut app = App::new();
    app.add_plugins(
        DefaultPlugins
            .set(WindowPlugin {
                primary_window: None,
                exit_condition: ExitCondition::DontExit,
                ..default()
            })
            .set(RenderPlugin {
                synchronous_pipeline_compilation: true,
                ..default()
            })
            .disable::<PipelinedRenderingPlugin>(),
    )
    .add_plugins(MesostructurePlugin)
    .insert_resource(ClearColor(Color::srgb(0.55, 0.62, 0.72)))
    // A bright sky: ambient light is what the mesostructure occlusion darkens.
    .insert_resource(bevy::light::GlobalAmbientLight {
        brightness: 1500.0,
        ..default()
    });
    app.finish();
    app.cleanup();

    let world = app.world_mut();
    let mut target = Image::new_target_texture(
        args.size.x,
        args.size.y,
        TextureFormat::Rgba8UnormSrgb,
        None,
    );
    target.texture_descriptor.usage |= TextureUsages::COPY_SRC;
    let target = world.resource_mut::<Assets<Image>>().add(target);
    let map = HeightMap::by_name(&args.height_map, 512).unwrap_or_else(|| {
        panic!(
            "unknown height map {}; one of {:?}",
            args.height_map,
            HeightMap::NAMES
        )
    });
    let height_map = world.resource_mut::<Assets<Image>>().add(map.to_image());
    let colours =
        world
            .resource_mut::<Assets<Image>>()
            .add(two_tone(&map, [191, 97, 71], [217, 214, 207]));

    let camera = world
        .spawn((
            Camera3d::default(),
            RenderTarget::Image(target.clone().into()),
            Msaa::Off,
            Mesostructure {
                occlusion: !args.off.iter().any(|e| e == "occlusion"),
                micro_shadows: !args.off.iter().any(|e| e == "micro-shadows"),
                bleeding: !args.off.iter().any(|e| e == "bleeding"),
                bump_mapping: !args.off.iter().any(|e| e == "bump-mapping"),
                ..default()
            },
            Transform::from_xyz(0.0, 1.3, 2.6).looking_at(Vec3::new(0.0, 0.1, 0.0), Vec3::Y),
        ))
        .id();
    world.spawn((
        DirectionalLight {
            illuminance: 8000.0,
            shadow_maps_enabled: true,
            ..default()
        },
        Transform::from_xyz(2.0, 4.0, 1.5).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    let ground = world
        .resource_mut::<Assets<Mesh>>()
        .add(Plane3d::default().mesh().size(8.0, 8.0));
    let ground_material = world
        .resource_mut::<Assets<StandardMaterial>>()
        .add(Color::srgb(0.35, 0.33, 0.3));
    world.spawn((
        Mesh3d(ground),
        MeshMaterial3d(ground_material),
        Transform::from_xyz(0.0, -0.85, 0.0),
    ));

    let uv_transform = if args.shape == "plane" {
        bevy::math::Affine2::IDENTITY
    } else {
        bevy::math::Affine2::from_scale(Vec2::new(2.0, 1.0))
    };
    let brick_red = world
        .resource_mut::<Assets<StandardMaterial>>()
        .add(StandardMaterial {
            base_color_texture: Some(colours),
            uv_transform,
            perceptual_roughness: 0.8,
            ..default()
        });
    let material = MesostructureMaterial {
        height_map,
        scale: args.scale,
        uv_transform,
    };
    match args.shape.as_str() {
        "plane" => {
            let plane = world
                .resource_mut::<Assets<Mesh>>()
                .add(Plane3d::default().mesh().size(2.4, 2.4));
            world.spawn((
                Mesh3d(plane),
                MeshMaterial3d(brick_red),
                material,
                Transform::from_xyz(0.0, -0.2, 0.0),
            ));
        }
        shape @ ("sphere" | "morph") => {
            let mut sphere_mesh = Sphere::new(0.8).mesh().uv(96, 48);
            sphere_mesh.asset_usage = RenderAssetUsages::default();
            let Some(VertexAttributeValues::Float32x3(p)) =
                sphere_mesh.attribute(Mesh::ATTRIBUTE_POSITION)
            else {
                unreachable!("a sphere has positions")
            };
            let morphing = Morphing {
                sphere: p.iter().map(|q| Vec3::from_array(*q)).collect(),
            };
            let handle = world.resource_mut::<Assets<Mesh>>().add(sphere_mesh);
            let mut entity = world.spawn((
                Mesh3d(handle),
                MeshMaterial3d(brick_red),
                material,
                Transform::from_rotation(Quat::from_rotation_y(0.4)),
            ));
            if shape == "morph" {
                entity.insert(morphing);
            }
        }
        other => panic!("unknown shape {other}"),
    }

    for frame in 0..args.frames {
        let t = frame as f32 / 30.0;
        let world = app.world_mut();
        let mut q = world.query::<(&Morphing, &Mesh3d)>();
        let updates: Vec<_> = q
            .iter(world)
            .map(|(m, h)| {
                (
                    Morphing {
                        sphere: m.sphere.clone(),
                    },
                    h.0.clone(),
                )
            })
            .collect();
        for (m, h) in updates {
            if let Some(mut mesh) = world.resource_mut::<Assets<Mesh>>().get_mut(&h) {
                morph(t + PI * 0.6, &m, &mut mesh);
            }
        }
        // The light circles the object.
        let mut lights = world.query_filtered::<&mut Transform, With<DirectionalLight>>();
        for mut light in lights.iter_mut(world) {
            let (s, c) = (t * 0.5).sin_cos();
            *light = Transform::from_xyz(2.5 * c, args.light_height, 2.5 * s)
                .looking_at(Vec3::ZERO, Vec3::Y);
        }
        app.update();
    }
    for view in &args.views {
        app.world_mut()
            .get_mut::<Mesostructure>(camera)
            .unwrap()
            .debug_view = *view;
        for _ in 0..2 {
            app.update();
        }
        let suffix: String = args.off.iter().map(|e| format!("_no-{e}")).collect();
        let path = args
            .out
            .join(format!("{}_{}{suffix}.png", args.shape, view.name()));
        app.world_mut()
            .spawn(Screenshot::image(target.clone()))
            .observe(save_to_disk(path.clone()));
        for _ in 0..3 {
            app.update();
        }
        println!("wrote {}", path.display());
    }
}
