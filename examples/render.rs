//! A scriptable renderer: one frame of one scene, written as a picture (`.png`) or as 32-bit
//! floats (`.exr`), so that other renderers can reproduce the scene exactly and compare.
//!
//! ```text
//! cargo run --example render -- [--mesh plane|sphere|torus|teapot|bunny|PATH.obj]
//!     [--torus-radii R,r] [--height-map NAME|PATH] [--scale K] [--tiles U,V]
//!     [--eye x,y,z] [--target x,y,z] [--fov DEG] [--light-dir x,y,z] [--albedo A]
//!     [--reference-lighting] [--screen-space] [--size N|WxH]
//!     [--view lit|occlusion|micro-shadow|bleeding|height|uv] [--out PATH.png|PATH.exr]
//! ```
//!
//! `--help` lists every option with its default. Options take `--scale 0.1` or `--scale=0.1`;
//! negative numbers are fine (`--eye -1,2,3`). A bad argument gets one line and exit code 2.
//! Defaults: the plane with bricks at k = 0.1, seen from (0, 2, 0) looking at the origin
//! (screen up = −z), 45° vertical field of view, light travelling along (1, −1, 0.3), 256²,
//! `lit`, `out/render.png`.
//!
//! Conventions (world: +y up, right-handed; the camera looks along −z of its own frame):
//! - `plane`: 2 × 2 world units in the XZ plane, centred at the origin, normal +Y; UV (0, 0) at
//!   (−1, 0, −1), u along +x, v along +z (Bevy's `Plane3d`).
//! - `sphere`: radius 1 at the origin (Bevy's UV sphere, 64 × 32 segments). **Poles on ±Z**:
//!   v = 0 at the pole +Z, v = 1 at −Z, v = θ/π with θ the angle from +Z; u = φ/2π with φ the
//!   azimuth from +X towards +Y (position `(sin θ cos φ, sin θ sin φ, cos θ)`).
//! - `torus`: major radius R (default 0.75), minor radius r (default 0.25), around +Y in the
//!   XZ plane (Bevy's `Torus`, 64 × 32 segments): u = α/2π with α the angle around the ring
//!   from +X towards +Z, v = β/2π with β the angle around the tube from the outer equator
//!   towards +Y (position `((R + r cos β) cos α, r sin β, (R + r cos β) sin α)`).
//! - `teapot`, `bunny`, `PATH.obj`: the OBJ's vertices, smooth normals, spherical UVs about
//!   the origin (u = 0.5 + atan2(z, x) / 2π, v = acos(y / r) / π), 4 tiles around.
//! - Height maps: white is high, `dis ∈ [0, 1]`, the surface stands at `P + n · dis · k` with n
//!   the interpolated vertex normal; they repeat, `--tiles U,V` times over the mesh's UV square
//!   (default 1,1: the height map is sampled at `(u·U, v·V)`). A `NAME` is a built-in
//!   generator at 512² (bricks, rivets, weave, sine, stone, cone); a `PATH` is any PNG or EXR.
//! - Views: `lit` is the picture (tonemapped in a PNG; linear HDR radiance, exposure applied,
//!   before tonemapping in an EXR); `occlusion` and `micro-shadow` are visibilities (1 = open,
//!   lit); `bleeding` is the radiance it adds; `height` is `dis`; `uv` is (u, v) of the mesh's
//!   UVs (before `--tiles`), in 32-bit floats, from a ray cast against the same triangles on the
//!   CPU with the frame's own camera matrices. All but `lit` in a PNG are linear values in 8
//!   bits. In an EXR, alpha is 1 on mesostructure pixels, 0 elsewhere (where the other views are
//!   0).
//! - Lighting: one directional light (illuminance 5000 lx, Bevy's shadow maps on) and an
//!   ambient light of 500, material albedo `--albedo` (default 0.8), perceptual roughness 0.5.
//! - `--reference-lighting` makes the `lit` EXR comparable pixel for pixel with a path tracer:
//!   the directional light only (no ambient or environment light), irradiance 1 on a surface
//!   facing it and exposure 1 (so a white Lambertian facing the light returns 1), no specular
//!   (reflectance 0), grey albedo `--albedo`. The diffuse model is Bevy's, Burley's at
//!   perceptual roughness 1, not Lambert's: `ρ/π · F_d` with `F_d = (1 + (F90 − 1)(1 − cos θl)^5)
//!   (1 + (F90 − 1)(1 − cos θv)^5)` and `F90 = 0.5 + 2 cos² θd`, normalised here so that
//!   `F_d = 1` at normal incidence; it equals Lambert there and differs towards grazing angles
//!   (at θl = θv = 60° and θd = 0 it is 1.06 times Lambert, at 80° up to 1.9 times). Bevy's shadow
//!   maps stay on (they shadow the core as the path tracer's geometry does); the mesostructure's
//!   own shadows and bounce are the plugin's.

#[path = "common/mod.rs"]
mod common;

use std::path::PathBuf;

use bevy::{
    camera::{Exposure, Hdr, RenderTarget},
    image::ImageSampler,
    math::Affine2,
    prelude::*,
    render::{
        render_resource::{TextureFormat, TextureUsages},
        view::screenshot::{Screenshot, save_to_disk},
    },
};
use clap::Parser;
use bevy_mesostructure::{CapturedFrame, MesostructureCapture, MesostructureCaptures, prelude::*};

/// One frame of one scene, as PNG or 32-bit EXR (see the conventions at the top of
/// examples/render.rs).
#[derive(Parser)]
#[command(long_about = None)]
struct Args {
    /// plane, sphere, torus, teapot, bunny, or the path of an OBJ file
    #[arg(long, default_value = "plane")]
    mesh: String,
    /// The torus's major and minor radius, R,r (R > r > 0)
    #[arg(long, default_value = "0.75,0.25", value_parser = parse_radii)]
    torus_radii: Vec2,
    /// A built-in height map (bricks, rivets, weave, sine, stone, cone) or a PNG/EXR path
    #[arg(long, default_value = "bricks")]
    height_map: String,
    /// Height of white in the height map, world units (> 0)
    #[arg(long, default_value_t = 0.1, value_parser = common::parse_positive)]
    scale: f32,
    /// Repeats of the height map over the mesh's UV square, U,V
    #[arg(long, default_value = "1,1", value_parser = parse_tiles)]
    tiles: Vec2,
    /// Camera position x,y,z
    #[arg(long, default_value = "0,2,0", value_parser = common::parse_vec3, allow_hyphen_values = true)]
    eye: Vec3,
    /// Point the camera looks at, x,y,z
    #[arg(long, default_value = "0,0,0", value_parser = common::parse_vec3, allow_hyphen_values = true)]
    target: Vec3,
    /// Vertical field of view, degrees (0–180)
    #[arg(long, default_value_t = 45.0, value_parser = parse_fov)]
    fov: f32,
    /// Direction the light travels, x,y,z
    #[arg(long, default_value = "1,-1,0.3", value_parser = common::parse_vec3, allow_hyphen_values = true)]
    light_dir: Vec3,
    /// Grey albedo of the material (0–1)
    #[arg(long, default_value_t = 0.8, value_parser = parse_unit)]
    albedo: f32,
    /// One directional light of irradiance 1, exposure 1, no ambient light, no specular
    #[arg(long)]
    reference_lighting: bool,
    /// The paper's screen-space terms only (`Mesostructure::texture_space_horizons` off)
    #[arg(long)]
    screen_space: bool,
    /// Picture size, N or WxH
    #[arg(long, default_value = "256", value_parser = common::parse_size)]
    size: UVec2,
    /// What to write
    #[arg(long, default_value = "lit", value_parser = ["lit", "occlusion", "micro-shadow", "bleeding", "height", "uv"])]
    view: String,
    /// Output file: .png or .exr
    #[arg(long, default_value = "out/render.png")]
    out: PathBuf,
}

fn pair(s: &str) -> Result<Vec2, String> {
    let v: Result<Vec<f32>, _> = s.split(',').map(|x| x.trim().parse::<f32>()).collect();
    match v {
        Ok(v) if v.len() == 2 && v.iter().all(|x| x.is_finite()) => Ok(Vec2::new(v[0], v[1])),
        _ => Err(format!("expected two numbers a,b, got {s:?}")),
    }
}

fn parse_radii(s: &str) -> Result<Vec2, String> {
    let r = pair(s)?;
    if r.x > r.y && r.y > 0.0 {
        Ok(r)
    } else {
        Err(format!("expected R,r with R > r > 0, got {s:?}"))
    }
}

fn parse_tiles(s: &str) -> Result<Vec2, String> {
    let t = pair(s)?;
    if t.x > 0.0 && t.y > 0.0 {
        Ok(t)
    } else {
        Err(format!("expected two repeat counts above 0, got {s:?}"))
    }
}

fn parse_fov(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(v) if v > 0.0 && v < 180.0 => Ok(v),
        _ => Err(format!("expected degrees between 0 and 180, got {s:?}")),
    }
}

fn parse_unit(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(v) if (0.0..=1.0).contains(&v) => Ok(v),
        _ => Err(format!("expected a number from 0 to 1, got {s:?}")),
    }
}

fn mesh(name: &str, torus_radii: Vec2) -> Mesh {
    match name {
        "plane" => Plane3d::default().mesh().size(2.0, 2.0).build(),
        "sphere" => Sphere::new(1.0).mesh().uv(64, 32),
        "torus" => Torus::new(torus_radii.x - torus_radii.y, torus_radii.x + torus_radii.y)
            .mesh()
            .major_resolution(64)
            .minor_resolution(32)
            .build(),
        "teapot" | "bunny" => common::meshes::obj_mesh(
            &common::meshes::asset_path(&format!("meshes/{name}.obj")),
            4.0,
        ),
        path => {
            let path = std::path::Path::new(path);
            if !path.is_file() {
                common::fail(format!(
                    "--mesh {}: not plane, sphere, torus, teapot, bunny or an OBJ file",
                    path.display()
                ));
            }
            common::meshes::obj_mesh(path, 4.0)
        }
    }
}

fn height_map(name: &str) -> Image {
    if let Some(map) = HeightMap::by_name(name, 512) {
        return map.to_image();
    }
    let dynamic = image::open(name).unwrap_or_else(|e| {
        common::fail(format!(
            "--height-map {name}: not a built-in map ({}) nor a readable image: {e}",
            HeightMap::NAMES.join(", ")
        ))
    });
    let mut image = Image::from_dynamic(dynamic, false, bevy::asset::RenderAssetUsages::default());
    image.sampler = ImageSampler::Default;
    image
}

fn main() {
    let args = Args::parse();
    let float = args.out.extension().is_some_and(|e| e == "exr");
    if !float && args.out.extension().is_none_or(|e| e != "png") {
        common::fail(format!("--out {}: expected a .png or .exr file", args.out.display()));
    }
    if (args.target - args.eye).length() < 1e-6 {
        common::fail("--eye and --target are the same point");
    }
    if args.light_dir.length() < 1e-6 {
        common::fail("--light-dir is zero");
    }
    if let Some(dir) = args.out.parent() {
        std::fs::create_dir_all(dir)
            .unwrap_or_else(|e| common::fail(format!("cannot create {}: {e}", dir.display())));
    }
    let core = mesh(&args.mesh, args.torus_radii);
    let height = height_map(&args.height_map);
    let mut app = App::new();
    app.add_plugins(common::headless_plugins())
        .add_plugins(MesostructurePlugin)
        .insert_resource(ClearColor(Color::BLACK))
        .insert_resource(bevy::light::GlobalAmbientLight {
            brightness: if args.reference_lighting { 0.0 } else { 500.0 },
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
        Mesostructure {
            texture_space_horizons: !args.screen_space,
            ..default()
        },
        MesostructureCapture,
        Transform::from_translation(args.eye).looking_at(args.target, up),
    ));
    if float {
        camera.insert(Hdr);
    }
    if args.reference_lighting {
        // Exposure 1 (Bevy's factor is 2^-ev100 / 1.2).
        camera.insert(Exposure {
            ev100: -(1.2f32).log2(),
        });
    }
    let camera = camera.id();
    let light_up = if args.light_dir.normalize().cross(Vec3::Y).length() < 1e-3 {
        Vec3::Z
    } else {
        Vec3::Y
    };
    world.spawn((
        DirectionalLight {
            // Bevy's diffuse is albedo · F_d / π · illuminance · exposure · N·l with F_d = 1 at
            // normal incidence: π makes a white surface facing the light return 1.
            illuminance: if args.reference_lighting {
                std::f32::consts::PI
            } else {
                5000.0
            },
            shadow_maps_enabled: true,
            ..default()
        },
        Transform::default().looking_to(args.light_dir, light_up),
    ));
    let height = world.resource_mut::<Assets<Image>>().add(height);
    let material = StandardMaterial {
        base_color: Color::linear_rgb(args.albedo, args.albedo, args.albedo),
        perceptual_roughness: if args.reference_lighting { 1.0 } else { 0.5 },
        reflectance: if args.reference_lighting { 0.0 } else { 0.5 },
        ..default()
    };
    let material = world
        .resource_mut::<Assets<StandardMaterial>>()
        .add(material);
    let traced = (args.view == "uv").then(|| common::unseen::CoreMesh::new(&core));
    let object = world.resource_mut::<Assets<Mesh>>().add(core);
    world.spawn((
        Mesh3d(object),
        MeshMaterial3d(material),
        MesostructureMaterial {
            height_map: height,
            scale: args.scale,
            uv_transform: Affine2::from_scale(args.tiles),
        },
    ));
    common::update_when_ready(&mut app, 8);
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
    let Some(frame) = frame else {
        common::fail("no mesostructure surface on screen: nothing to write");
    };
    let uv = traced.map(|mesh| {
        (0..frame.height)
            .flat_map(|y| (0..frame.width).map(move |x| (x, y)))
            .map(|(x, y)| {
                let (o, d) = common::unseen::camera_ray(&frame, x, y);
                mesh.hit(o, d).map(|(_, _, uv)| uv)
            })
            .collect::<Vec<_>>()
    });
    write(&args, &frame, uv.as_deref(), float);
}

/// Writes the chosen view of `frame` as an RGBA32F EXR or an 8-bit PNG.
fn write(args: &Args, frame: &CapturedFrame, uv: Option<&[Option<Vec2>]>, float: bool) {
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
            "uv" => match uv.and_then(|uv| uv[i]) {
                Some(t) if on => [t.x, t.y, 0.0, 1.0],
                _ => [0.0; 4],
            },
            // lit in floats: the opaque image plus the bleeding added to it.
            _ => {
                let l = frame.lit.get(i).copied().unwrap_or([0.0; 4]);
                let b = frame.bleeding.get(i).copied().unwrap_or([0.0; 4]);
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
