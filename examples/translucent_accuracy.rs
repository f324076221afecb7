//! Accuracy of the translucency transport against a path tracer: a ball of one of Jensen's
//! media (radius 1 cm, an index-matched boundary so that the picture is the light diffused
//! out of the medium alone) lit by one directional light, seen from 4 cm. The plugin's picture
//! is computed on the CPU with the same patches, transport, iteration and gather as the GPU
//! passes (`translucency::gather::gathered_radiance`, the oracle the GPU tests hold the passes
//! to: within 0.22/255 mean of it); the reference is Mitsuba 3's volumetric path tracing
//! (`tools/translucent_reference.py`, which this example runs where `python3` has `mitsuba`, or
//! reads with `--reference`).
//!
//! ```text
//! cargo run --example translucent_accuracy -- [--medium skin1] [--budgets 250,500,1000,2000]
//!     [--kernel dipole|burley] [--size 96] [--spp 1024] [--reference FILE.exr]
//!     [--out docs/translucent.csv]
//! ```
//!
//! CSV header (issue 13): `scene,method,setting,patches,width,height,gpu_ms,precompute_s,
//! memory_mb,rel_l1,flip,adapter` — `gpu_ms` is empty (not measured here), `rel_l1` is
//! Σ|plugin − reference| / Σ reference over the ball's pixels (the silhouette's rim left out),
//! all channels; `flip` is NVIDIA FLIP's mean on both pictures scaled by the reference's
//! brightest pixel.

use std::{io::Write, path::PathBuf, process::Command, time::Instant};

use bevy::prelude::*;
use bevy_mesostructure::translucency::{
    DiffusionKernel, EnergyTransport, PatchLight, PatchObject, PatchSurface, SceneRays,
    TransportSettings, TranslucentPreset, direct_light, gather::gathered_radiance,
    patches::world_triangles, resample_into_patches,
};

const RADIUS: f32 = 0.01;
const EYE: Vec3 = Vec3::new(0.0, 0.0, 0.04);
const LIGHT: Vec3 = Vec3::new(-1.0, -0.2, -0.3);
const FOV_Y: f32 = std::f32::consts::FRAC_PI_4;

/// The translucency's picture of a ball against Mitsuba's, per patch budget, into a CSV.
#[derive(clap::Parser)]
#[command(long_about = None)]
struct Cli {
    /// Jensen's medium
    #[arg(long, value_enum, default_value_t = Medium::Skin1)]
    medium: Medium,
    /// Patch budgets, comma-separated
    #[arg(long, value_delimiter = ',', default_value = "250,500,1000,2000",
          value_parser = clap::value_parser!(u32).range(16..=200_000))]
    budgets: Vec<u32>,
    /// Diffusion profile
    #[arg(long, value_enum, default_value_t = Kernel::Burley)]
    kernel: Kernel,
    /// Picture width = height
    #[arg(long, default_value_t = 96, value_parser = clap::value_parser!(u32).range(8..=1024))]
    size: u32,
    /// Samples per pixel of the reference (when rendered here)
    #[arg(long, default_value_t = 1024, value_parser = clap::value_parser!(u32).range(1..))]
    spp: u32,
    /// A reference EXR made before (else it is rendered into out/translucent_accuracy/)
    #[arg(long)]
    reference: Option<PathBuf>,
    /// CSV to append rows to (header written if the file is new)
    #[arg(long)]
    out: Option<PathBuf>,
}

#[derive(Clone, Copy, clap::ValueEnum, Debug)]
enum Medium {
    Skin1,
    Skin2,
    Marble,
    Ketchup,
    Apple,
}

#[derive(Clone, Copy, clap::ValueEnum, Debug)]
enum Kernel {
    Dipole,
    Burley,
}

fn fail(message: String) -> ! {
    eprintln!("error: {message}");
    std::process::exit(1);
}

fn main() {
    let cli: Cli = clap::Parser::parse();
    let preset = match cli.medium {
        Medium::Skin1 => TranslucentPreset::Skin1,
        Medium::Skin2 => TranslucentPreset::Skin2,
        Medium::Marble => TranslucentPreset::Marble,
        Medium::Ketchup => TranslucentPreset::Ketchup,
        Medium::Apple => TranslucentPreset::Apple,
    };
    // Index-matched: no Fresnel at the boundary, in either renderer.
    let medium = bevy_mesostructure::translucency::TranslucentMedium {
        index_of_refraction: 1.0,
        ..preset.medium()
    };
    let name = format!("{:?}", cli.medium).to_lowercase();
    let size = cli.size;
    let reference_path = cli.reference.clone().unwrap_or_else(|| {
        let dir = PathBuf::from("out/translucent_accuracy");
        std::fs::create_dir_all(&dir).unwrap_or_else(|e| fail(format!("cannot create {}: {e}", dir.display())));
        let path = dir.join(format!("reference_{name}_{size}_{}.exr", cli.spp));
        if !path.exists() {
            let list = |v: Vec3| format!("{},{},{}", v.x, v.y, v.z);
            let mut command = Command::new("python3");
            command.args([
                "tools/translucent_reference.py",
                &format!("--sigma-a={}", list(medium.absorption)),
                &format!("--sigma-s={}", list(medium.reduced_scattering)),
                &format!("--radius={RADIUS}"),
                &format!("--eye={}", list(EYE)),
                &format!("--light={}", list(LIGHT)),
                &format!("--fov={}", FOV_Y.to_degrees()),
                &format!("--size={size}"),
                &format!("--spp={}", cli.spp),
                &format!("--out={}", path.display()),
            ]);
            eprintln!("rendering the reference: {command:?}");
            let start = Instant::now();
            match command.status() {
                Ok(s) if s.success() => eprintln!("reference in {:.1} s", start.elapsed().as_secs_f32()),
                _ => fail("the reference did not render: `pip install mitsuba numpy` (or pass --reference)".into()),
            }
        }
        path
    });
    let reference = image::open(&reference_path)
        .unwrap_or_else(|e| fail(format!("cannot read {}: {e}", reference_path.display())))
        .to_rgb32f();
    if reference.width() != size || reference.height() != size {
        fail(format!("{} is {}×{}, not {size}×{size}", reference_path.display(), reference.width(), reference.height()));
    }

    // The ball as the plugin takes it: Bevy's ico sphere, 20 480 triangles.
    let (positions, indices) = world_triangles(
        &Sphere::new(RADIUS).mesh().ico(5).expect("a valid subdivision"),
        &GlobalTransform::IDENTITY,
    )
    .expect("a triangle list");
    let views = [PatchObject { positions: &positions, indices: &indices }];
    let surfaces = [PatchSurface::Translucent { medium, world_units_per_mm: 0.001 }];
    let settings = TransportSettings {
        kernel: match cli.kernel {
            Kernel::Dipole => DiffusionKernel::Dipole,
            Kernel::Burley => DiffusionKernel::Burley,
        },
        ..default()
    };
    let lights = [PatchLight::Directional { direction: LIGHT.normalize(), illuminance: Vec3::ONE }];
    let method = format!("patches_{:?}", cli.kernel).to_lowercase();
    let header = "scene,method,setting,patches,width,height,gpu_ms,precompute_s,memory_mb,rel_l1,flip,adapter";
    let mut rows = Vec::new();
    for &budget in &cli.budgets {
        let start = Instant::now();
        let patches = resample_into_patches(&views, budget as usize);
        let rays = SceneRays::new(&views);
        let transport = EnergyTransport::build(&patches, &surfaces, &rays, &settings);
        let precompute = start.elapsed().as_secs_f32();
        let direct = direct_light(&patches, Some(&transport), &lights, &rays);
        let solution = transport.solve_with(&direct, 1e-4, 256);
        let albedo = vec![Vec3::ZERO; patches.patches.len()];
        let mut picture = vec![Vec3::ZERO; (size * size) as usize];
        let (mut difference, mut total) = (0.0f64, 0.0f64);
        let mut mask = vec![false; picture.len()];
        let tan = (FOV_Y / 2.0).tan();
        let forward = (-EYE).normalize();
        let right = forward.cross(Vec3::Y).normalize();
        let up = right.cross(forward);
        for y in 0..size {
            for x in 0..size {
                let sx = (2.0 * (x as f32 + 0.5) / size as f32 - 1.0) * tan;
                let sy = (1.0 - 2.0 * (y as f32 + 0.5) / size as f32) * tan;
                let d = (forward + right * sx + up * sy).normalize();
                let b = EYE.dot(d);
                let disc = b * b - (EYE.length_squared() - RADIUS * RADIUS);
                if disc <= 0.0 {
                    continue;
                }
                let hit = EYE + d * (-b - disc.sqrt());
                let n = hit.normalize();
                let i = (y * size + x) as usize;
                let radiance = gathered_radiance(&patches, &albedo, &direct.irradiance, &solution.exitance, hit, n)
                    .unwrap_or(Vec3::ZERO);
                picture[i] = radiance;
                // The silhouette's rim (mesh against sphere, pixels half on the ball) left out.
                if n.dot(-d) < 0.3 {
                    continue;
                }
                mask[i] = true;
                let r = reference.get_pixel(x, y).0;
                for c in 0..3 {
                    difference += (radiance[c] - r[c]).abs() as f64;
                    total += r[c] as f64;
                }
            }
        }
        let rel_l1 = difference / total;
        // FLIP on both scaled by the reference's brightest pixel (sRGB-encoded, 8 bits).
        let peak = reference.pixels().flat_map(|p| p.0).fold(0.0f32, f32::max).max(1e-9);
        let encode = |value: &dyn Fn(u32, u32) -> [f32; 3]| -> Vec<u8> {
            (0..size * size)
                .flat_map(|i| value(i % size, i / size))
                .map(|v| {
                    let c = (v / peak).clamp(0.0, 1.0);
                    let s = if c <= 0.003_130_8 { 12.92 * c } else { 1.055 * c.powf(1.0 / 2.4) - 0.055 };
                    (s * 255.0).round() as u8
                })
                .collect()
        };
        let ours = encode(&|x, y| picture[(y * size + x) as usize].to_array());
        let theirs = encode(&|x, y| reference.get_pixel(x, y).0);
        let flip_image = nv_flip::flip(
            nv_flip::FlipImageRgb8::with_data(size, size, &theirs),
            nv_flip::FlipImageRgb8::with_data(size, size, &ours),
            nv_flip::DEFAULT_PIXELS_PER_DEGREE,
        );
        let flip = nv_flip::FlipPool::from_image(&flip_image).mean();
        let n = patches.patches.len();
        let bytes = 8 * (2 * (n + 1)) + 8 * transport.form_factors.entries() + 16 * transport.scattering.entries();
        // Mean ratio per channel (a scale error shows here first).
        let mut sums = [[0.0f64; 2]; 3];
        for (i, &m) in mask.iter().enumerate() {
            if m {
                let r = reference.get_pixel(i as u32 % size, i as u32 / size).0;
                for c in 0..3 {
                    sums[c][0] += picture[i][c] as f64;
                    sums[c][1] += r[c] as f64;
                }
            }
        }
        eprintln!(
            "{name} {budget}: {n} patches, rel L1 {rel_l1:.4}, FLIP {flip:.4}, mean ratio r {:.3} g {:.3} b {:.3}, {} iterations",
            sums[0][0] / sums[0][1],
            sums[1][0] / sums[1][1],
            sums[2][0] / sums[2][1],
            solution.iterations
        );
        rows.push(format!(
            "ball_{name}_r10mm,{method},{budget},{n},{size},{size},,{precompute:.3},{:.3},{rel_l1:.4},{flip:.4},cpu oracle of the GPU passes",
            bytes as f32 / 1e6
        ));
        // The picture for a look (linear EXR).
        let exr = image::Rgb32FImage::from_fn(size, size, |x, y| image::Rgb(picture[(y * size + x) as usize].to_array()));
        let path = PathBuf::from("out/translucent_accuracy").join(format!("plugin_{name}_{method}_{budget}.exr"));
        if let Err(e) = std::fs::create_dir_all("out/translucent_accuracy").and_then(|_| {
            exr.save(&path).map_err(std::io::Error::other)
        }) {
            eprintln!("warning: cannot write {}: {e}", path.display());
        }
    }
    println!("{header}");
    for row in &rows {
        println!("{row}");
    }
    if let Some(out) = cli.out {
        let new = !out.exists();
        let written = std::fs::OpenOptions::new().create(true).append(true).open(&out).and_then(|mut f| {
            if new {
                writeln!(f, "{header}")?;
            }
            for row in &rows {
                writeln!(f, "{row}")?;
            }
            Ok(())
        });
        if let Err(e) = written {
            fail(format!("cannot write {}: {e}", out.display()));
        }
    }
}
