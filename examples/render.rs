//! A scriptable renderer: one frame of one scene, written as a picture (`.png`) or as 32-bit
//! floats (`.exr`), so that other renderers can reproduce the scene exactly and compare.
//!
//! ```text
//! cargo run --example render -- [--mesh plane|sphere|torus|teapot|bunny|PATH.obj]
//!     [--height-map NAME|PATH] [--scale K] [--eye x,y,z] [--target x,y,z] [--fov DEG]
//!     [--light-dir x,y,z] [--size N|WxH]
//!     [--view lit|occlusion|micro-shadow|bleeding|height|uv] [--out PATH.png|PATH.exr]
//! ```
//!
//! Defaults: the plane with bricks at k = 0.1, seen from (0, 2, 0) looking at the origin
//! (screen up = −z), 45° vertical field of view, light travelling along (1, −1, 0.3), 256²,
//! `lit`, `out/render.png`.
//!
//! Conventions (world: +y up, right-handed; the camera looks along −z of its own frame):
//! - `plane`: 2 × 2 world units in the XZ plane, centred at the origin, normal +Y; UV (0, 0) at
//!   (−1, 0, −1), u along +x, v along +z (Bevy's `Plane3d`).
//! - `sphere`: radius 1 at the origin, poles on ±Y; u = azimuth / 2π, v = 0 at the north
//!   pole (+Y) to 1 at the south pole (Bevy's UV sphere, 64 × 32 segments).
//! - `torus`: minor radius 0.25, major radius 0.75, around +Y in the XZ plane; u around the
//!   major circle, v around the tube (Bevy's `Torus`, 64 × 32 segments).
//! - `teapot`, `bunny`, `PATH.obj`: the OBJ's vertices, smooth normals, spherical UVs about
//!   the origin (u = 0.5 + atan2(z, x) / 2π, v = acos(y / r) / π), 4 tiles around.
//! - Height maps: white is high, `dis ∈ [0, 1]`, the surface stands at `P + n · dis · k`; they
//!   repeat. A `NAME` is a built-in generator at 512² (bricks, rivets, weave, sine, stone,
//!   cone); a `PATH` is any PNG or EXR.
//! - Views: `lit` is the picture (tonemapped in a PNG; linear HDR radiance, exposure applied,
//!   before tonemapping in an EXR); `occlusion` and `micro-shadow` are visibilities (1 = open,
//!   lit); `bleeding` is the radiance it adds; `height` is `dis`; `uv` is fract(u), fract(v) as
//!   the material sees them (±0.001). All but `lit` in a PNG are linear values in 8 bits. In an
//!   EXR, alpha is 1 on mesostructure pixels, 0 elsewhere (where the other views are 0).

#[path = "common/mod.rs"]
mod common;

use std::path::PathBuf;

use bevy::{
    camera::{Hdr, RenderTarget},
    image::{ImageAddressMode, ImageSampler, ImageSamplerDescriptor},
    prelude::*,
    render::{
        render_resource::{Extent3d, TextureDimension, TextureFormat, TextureUsages},
        view::screenshot::{Screenshot, save_to_disk},
    },
};
use bevy_mesostructure::{CapturedFrame, MesostructureCapture, MesostructureCaptures, prelude::*};

struct Args {
    mesh: String,
    height_map: String,
    scale: f32,
    eye: Vec3,
    target: Vec3,
    fov: f32,
    light_dir: Vec3,
    size: UVec2,
    view: String,
    out: PathBuf,
}

fn vec3(s: &str) -> Vec3 {
    let v: Vec<f32> = s
        .split(',')
        .map(|x| x.trim().parse().expect("x,y,z"))
        .collect();
    assert_eq!(v.len(), 3, "expected x,y,z, got {s}");
    Vec3::new(v[0], v[1], v[2])
}

fn parse() -> Args {
    let mut a = Args {
        mesh: "plane".into(),
        height_map: "bricks".into(),
        scale: 0.1,
        eye: Vec3::new(0.0, 2.0, 0.0),
        target: Vec3::ZERO,
        fov: 45.0,
        light_dir: Vec3::new(1.0, -1.0, 0.3),
        size: UVec2::splat(256),
        view: "lit".into(),
        out: PathBuf::from("out/render.png"),
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut value = || it.next().unwrap_or_else(|| panic!("{flag} needs a value"));
        match flag.as_str() {
            "--mesh" => a.mesh = value(),
            "--height-map" => a.height_map = value(),
            "--scale" => a.scale = value().parse().expect("--scale K"),
            "--eye" => a.eye = vec3(&value()),
            "--target" => a.target = vec3(&value()),
            "--fov" => a.fov = value().parse().expect("--fov DEG"),
            "--light-dir" => a.light_dir = vec3(&value()),
            "--size" => {
                let v = value();
                let (w, h) = v.split_once('x').unwrap_or((&v, &v));
                a.size = UVec2::new(w.parse().expect("--size"), h.parse().expect("--size"));
            }
            "--view" => a.view = value(),
            "--out" => a.out = value().into(),
            "--help" | "-h" => {
                println!("see the doc comment at the top of examples/render.rs");
                std::process::exit(0);
            }
            other => panic!("unknown argument {other}"),
        }
    }
    assert!(
        [
            "lit",
            "occlusion",
            "micro-shadow",
            "bleeding",
            "height",
            "uv"
        ]
        .contains(&a.view.as_str()),
        "unknown view {}",
        a.view
    );
    a
}

fn mesh(name: &str) -> Mesh {
    match name {
        "plane" => Plane3d::default().mesh().size(2.0, 2.0).build(),
        "sphere" => Sphere::new(1.0).mesh().uv(64, 32),
        "torus" => Torus::new(0.5, 1.0)
            .mesh()
            .major_resolution(64)
            .minor_resolution(32)
            .build(),
        "teapot" | "bunny" => common::meshes::obj_mesh(
            &common::meshes::asset_path(&format!("meshes/{name}.obj")),
            4.0,
        ),
        path => common::meshes::obj_mesh(std::path::Path::new(path), 4.0),
    }
}

fn height_map(name: &str) -> Image {
    if let Some(map) = HeightMap::by_name(name, 512) {
        return map.to_image();
    }
    let dynamic = image::open(name).unwrap_or_else(|e| panic!("cannot read {name}: {e}"));
    let mut image = Image::from_dynamic(dynamic, false, bevy::asset::RenderAssetUsages::default());
    image.sampler = ImageSampler::Default;
    image
}

/// A texture whose linear filtering returns the UV itself: texel i holds (i + 0.5) / n.
fn uv_texture() -> Image {
    let n = 1024u32;
    let mut data = Vec::with_capacity((n * n * 8) as usize);
    for y in 0..n {
        for x in 0..n {
            for c in [
                (x as f32 + 0.5) / n as f32,
                (y as f32 + 0.5) / n as f32,
                0.0,
                1.0,
            ] {
                data.extend(half::f16::from_f32(c).to_le_bytes());
            }
        }
    }
    let mut image = Image::new(
        Extent3d {
            width: n,
            height: n,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        data,
        TextureFormat::Rgba16Float,
        bevy::asset::RenderAssetUsages::default(),
    );
    image.sampler = ImageSampler::Descriptor(ImageSamplerDescriptor {
        address_mode_u: ImageAddressMode::Repeat,
        address_mode_v: ImageAddressMode::Repeat,
        ..ImageSamplerDescriptor::linear()
    });
    image
}

fn main() {
    let args = parse();
    let float = args.out.extension().is_some_and(|e| e == "exr");
    if let Some(dir) = args.out.parent() {
        std::fs::create_dir_all(dir).expect("cannot create the output folder");
    }
    let mut app = App::new();
    app.add_plugins(common::headless_plugins())
        .add_plugins(MesostructurePlugin)
        .insert_resource(ClearColor(Color::BLACK))
        .insert_resource(bevy::light::GlobalAmbientLight {
            brightness: 500.0,
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
    let up = if (args.target - args.eye).normalize().cross(Vec3::Y).length() < 1e-3 {
        Vec3::NEG_Z
    } else {
        Vec3::Y
    };
    let mut camera = world.spawn((
        Camera3d::default(),
        RenderTarget::Image(target.clone().into()),
        Projection::Perspective(PerspectiveProjection {
            fov: args.fov.to_radians(),
            ..default()
        }),
        Msaa::Off,
        Mesostructure::default(),
        MesostructureCapture,
        Transform::from_translation(args.eye).looking_at(args.target, up),
    ));
    if float {
        camera.insert(Hdr);
    }
    let camera = camera.id();
    let light_up = if args.light_dir.normalize().cross(Vec3::Y).length() < 1e-3 {
        Vec3::Z
    } else {
        Vec3::Y
    };
    world.spawn((
        DirectionalLight {
            illuminance: 5000.0,
            shadow_maps_enabled: true,
            ..default()
        },
        Transform::default().looking_to(args.light_dir, light_up),
    ));
    let height = world
        .resource_mut::<Assets<Image>>()
        .add(height_map(&args.height_map));
    let material = if args.view == "uv" {
        let uv = world.resource_mut::<Assets<Image>>().add(uv_texture());
        StandardMaterial {
            base_color_texture: Some(uv),
            unlit: true,
            ..default()
        }
    } else {
        StandardMaterial::from(Color::srgb(0.8, 0.8, 0.8))
    };
    let material = world
        .resource_mut::<Assets<StandardMaterial>>()
        .add(material);
    let object = world.resource_mut::<Assets<Mesh>>().add(mesh(&args.mesh));
    world.spawn((
        Mesh3d(object),
        MeshMaterial3d(material),
        MesostructureMaterial {
            height_map: height,
            scale: args.scale,
            ..default()
        },
    ));
    for _ in 0..8 {
        app.update();
    }
    let captures = app.world().resource::<MesostructureCaptures>().clone();
    let mut frame = None;
    for _ in 0..20 {
        app.update();
        if let Some(f) = captures.take(camera) {
            frame = Some(f);
            break;
        }
    }
    if !float && args.view == "lit" {
        app.world_mut()
            .spawn(Screenshot::image(target))
            .observe(save_to_disk(args.out.clone()));
        for _ in 0..3 {
            app.update();
        }
        println!("wrote {}", args.out.display());
        return;
    }
    let frame = frame.expect("no mesostructure surface on screen: nothing to write");
    write(&args, &frame, float);
}

/// Writes the chosen view of `frame` as an RGBA32F EXR or an 8-bit PNG.
fn write(args: &Args, frame: &CapturedFrame, float: bool) {
    let (w, h) = (frame.width, frame.height);
    let pixel = |i: usize| -> [f32; 4] {
        let on = frame.mhm[i][2] != 0.0;
        let a = if on { 1.0 } else { 0.0 };
        let grey = |v: f32| [v * a, v * a, v * a, a];
        match args.view.as_str() {
            "occlusion" => grey(frame.occlusion[i]),
            "micro-shadow" => grey(frame.micro_shadow.get(i).copied().unwrap_or(1.0)),
            "height" => grey(frame.mhm[i][3]),
            "bleeding" => {
                let b = frame.bleeding.get(i).copied().unwrap_or([0.0; 4]);
                [b[0] * a, b[1] * a, b[2] * a, a]
            }
            // lit / uv in floats: the opaque image plus the bleeding added to it.
            _ => {
                let l = frame.lit.get(i).copied().unwrap_or([0.0; 4]);
                let b = if args.view == "lit" {
                    frame.bleeding.get(i).copied().unwrap_or([0.0; 4])
                } else {
                    [0.0; 4]
                };
                [l[0] + b[0], l[1] + b[1], l[2] + b[2], a]
            }
        }
    };
    if float {
        let data: Vec<f32> = (0..(w * h) as usize).flat_map(pixel).collect();
        image::Rgba32FImage::from_raw(w, h, data)
            .expect("w × h pixels")
            .save(&args.out)
            .expect("cannot write the EXR");
    } else {
        let data: Vec<u8> = (0..(w * h) as usize)
            .flat_map(pixel)
            .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
            .collect();
        image::RgbaImage::from_raw(w, h, data)
            .expect("w × h pixels")
            .save(&args.out)
            .expect("cannot write the PNG");
    }
    println!("wrote {}", args.out.display());
}
