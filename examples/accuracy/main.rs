//! Error against the ground truth, for each method at each cost it offers: the numbers behind
//! the speed/accuracy chart.
//!
//! ```text
//! cargo run --example accuracy -- [--out FILE.csv] [--chart FILE.png] [--quick]
//!     [--size N] [--maps bricks,rivets,stone,sine] [--scales 0.05,0.1,0.2,0.4]
//! cargo run --example accuracy -- --from A.csv --from B.csv [--out FILE.csv] [--chart FILE.png]
//! cargo run --example accuracy -- --suite unseen [--scenes NAME,..] [--variants high,..]
//!     [--size N] [--step N] [--out FILE.csv]
//! ```
//!
//! `--suite unseen` runs the unseen-content suite instead (`examples/common/unseen/`:
//! photo-derived maps on the plane, UV sphere and torus in close-up, oblique, grazing,
//! top-down and far views, scored at each pixel's UV against a ray caster on the displaced
//! mesh) and writes the columns `scene,core,map,view,light,method,setting,width,height,
//! texels_per_px,pixels,facing,gpu_ms,ao_mae,ao_bias,shadow_recall,shadow_precision,
//! bounce_rel_mae,bounce_ratio` (default `out/accuracy-unseen.csv`) and a Markdown table.
//! `--help` lists every option.
//!
//! `--maps` and `--scales` keep some of the scenes (to split a run: each scene renders ~20
//! headless apps, and some drivers run out of devices after ~40 in one process); `--from` renders nothing and merges
//! earlier runs' CSVs into one CSV and chart.
//!
//! Scenes: the 2 × 2 plane seen straight down (Bevy's default 45° field of view from 2 units)
//! with bricks, rivets, stone (fBm noise) and sine height maps at scales 0.05, 0.1, 0.2 and 0.4,
//! one directional light at 20°, 45° and 70° elevation (travelling towards +x), no ambient
//! light for the light terms. Ground truth: `reference::ground_truth` on the height field
//! itself, every 4th pixel (jittered in its 4 × 4 cell) at least 8 px from the edge (AO with 8 × 16 rays, light visibility,
//! one-bounce with 6 × 16 rays).
//!
//! Methods: `none` (no mesostructure term); `bevy-ssao` (Bevy's SSAO on the same bricks built as
//! real geometry — a 256² grid — its AO taken as the ratio of an ambient-only picture with and
//! without it; it has no shadow or bounce term); `horizon-search` (the brute-force baseline,
//! `HorizonSearchBaseline`: 8 directions out to 32 px with 4, 8, 16 and 32
//! samples each; AO only); `mesostructure` at each quality preset (`low`, `medium`, `high`,
//! `ultra`) and the default at quarter working resolution (`high@quarter`; `medium` is `high`
//! at half).
//! Errors: MAE and RMSE of AO and of the one-bounce term (relative to the irradiance of a
//! surface facing the light), the share of directly lit pixels whose micro-shadow agrees, and
//! the mean NVIDIA FLIP (`nv-flip`, LDR, 67 pixels per degree) of a shaded picture of the
//! central half of the view (every pixel): radiance `A·AO + V·max(N·l, 0) + B` in units of
//! a surface facing the light (A = 0.25, an ambient light a quarter of the sun), shown ×0.75 in
//! sRGB grey. The reference takes AO, light visibility V, normal N and bounce B from the ground
//! truth; each method its own terms (where it has none: AO 1, V 1, B 0, and the flat plane's
//! normal — or the true one for SSAO, which runs on real geometry). Shading all of them with one
//! Lambert model leaves the BRDF out, so FLIP measures what each method's terms change in the
//! picture. Time: the median GPU time of the passes each method adds (for this plugin: all
//! passes but the lighting pass, which replaces Bevy's own).
//!
//! Writes `FILE.csv` (default `out/accuracy.csv`) with the columns
//! `scene,method,setting,width,height,gpu_ms,ao_mae,ao_rmse,shadow_agreement,bounce_mae,flip_mean`
//! and `FILE.png` (default `out/accuracy.png`): GPU time against AO error, one line per method.
//! `--quick`: bricks and stone at 0.1 under the 45° light.

#[path = "../common/mod.rs"]
mod common;
mod chart;
mod scene;
mod unseen_suite;

use chart::*;
use scene::*;
use unseen_suite::*;

use std::{fmt::Write as _, path::PathBuf};

use clap::Parser;

use bevy::{
    camera::{Hdr, RenderTarget},
    core_pipeline::tonemapping::Tonemapping,
    pbr::ScreenSpaceAmbientOcclusion,
    prelude::*,
};
use bevy_mesostructure::{
    CapturedFrame, HorizonSearchBaseline, MesostructureCapture, prelude::*,
    reference::ground_truth::HeightField,
};


/// Error against the ground truth for each method at each cost (the speed/accuracy chart), on
/// the synthetic top-down suite or on the unseen-content suite.
#[derive(Parser)]
#[command(long_about = None)]
struct Args {
    /// The CSV to write (default: out/accuracy.csv, or out/accuracy-unseen.csv for
    /// `--suite unseen`).
    #[arg(long)]
    out: Option<PathBuf>,
    /// The chart to write (synthetic suite).
    #[arg(long, default_value = "out/accuracy.png")]
    chart: PathBuf,
    /// Bricks and stone at 0.1 under the 45° light only.
    #[arg(long)]
    quick: bool,
    /// Picture size in pixels (square; default 96, or 128 for `--suite unseen`).
    #[arg(long)]
    size: Option<u32>,
    /// Keep these height maps (comma-separated: bricks,rivets,stone,sine).
    #[arg(long)]
    maps: Option<String>,
    /// Keep these scales (comma-separated).
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
    scales: Option<Vec<f32>>,
    /// Render nothing: merge earlier runs' CSVs into one CSV and chart (repeated or
    /// comma-separated).
    #[arg(long, value_delimiter = ',')]
    from: Vec<PathBuf>,
    /// Which scenes: the synthetic top-down plane suite, or photo-derived maps on curved cores
    /// in game-like views (`unseen`).
    #[arg(long, value_enum, default_value_t = Suite::Synthetic)]
    suite: Suite,
    /// `--suite unseen`: keep the scenes whose name contains one of these (comma-separated).
    #[arg(long)]
    scenes: Option<String>,
    /// `--suite unseen`: the plugin's settings to score (comma-separated): a preset (low,
    /// medium, high, ultra), `search=N` (the brute-force horizon search with N samples),
    /// `radius=PX` (high with that `max_sample_radius`), `directions=N`, `steps=N`,
    /// `softness=S` (micro-shadow edge), `samples=N` (bleeding samples), `no-coarse`,
    /// `no-texture-bounce` (the bounce from the screen-space gather alone), `screen-space`
    /// (high without the texture-space occlusion of minified maps)
    #[arg(long, default_value = "high", value_delimiter = ',')]
    variants: Vec<String>,
    /// `--suite unseen`: score every N-th pixel in x and y.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..))]
    step: u32,
}

#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum Suite {
    Synthetic,
    Unseen,
}

fn main() {
    let args = Args::parse();
    if args.suite == Suite::Unseen {
        run_unseen(&args);
        return;
    }
    let out = args.out.clone().unwrap_or_else(|| "out/accuracy.csv".into());
    let chart = args.chart.clone();
    let mut size = args.size.unwrap_or(96);
    let mut rows = read_rows(&args.from, &mut size);
    if args.from.is_empty() {
        rows.extend(measure_synthetic(&args, size));
    }

    let mut csv = String::from(
        "scene,method,setting,width,height,gpu_ms,ao_mae,ao_rmse,shadow_agreement,bounce_mae,flip_mean\n",
    );
    for r in &rows {
        let _ = writeln!(
            csv,
            "{},{},{},{size},{size},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4}",
            r.scene, r.method, r.setting, r.gpu_ms, r.ao.0, r.ao.1, r.shadow, r.bounce, r.flip
        );
    }
    for path in [&out, &chart] {
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir).expect("cannot create the output folder");
        }
    }
    std::fs::write(&out, csv).expect("cannot write the CSV");
    println!("wrote {}", out.display());
    draw_chart(&rows, &chart);
    println!("wrote {}", chart.display());
}

/// Where a picture is scored: `samples`, every 4th pixel jittered inside its 4 × 4 cell (so
/// that all positions in a block of the reduced working resolutions are sampled alike), and
/// `interior`, the central half of the view at every pixel (the pictures FLIP compares; the
/// ground truth at every pixel is the slow part of a run).
struct Pixels {
    size: u32,
    samples: Vec<(u32, u32)>,
    interior: Vec<(u32, u32)>,
    /// The interior's width.
    inner: u32,
}

impl Pixels {
    fn new(size: u32) -> Self {
        let samples = (0..(size - 16) / 4)
            .flat_map(|j| {
                (0..(size - 16) / 4)
                    .map(move |i| (8 + 4 * i + (i + 2 * j) % 4, 8 + 4 * j + (3 * i + j) % 4))
            })
            .collect();
        let inner = size / 2;
        let interior = (size / 4..size / 4 + inner)
            .flat_map(|y| (size / 4..size / 4 + inner).map(move |x| (x, y)))
            .collect();
        Self {
            size,
            samples,
            interior,
            inner,
        }
    }

    fn index(&self, &(x, y): &(u32, u32)) -> usize {
        (y * self.size + x) as usize
    }
}

/// Every row of the synthetic suite that `args` keeps.
fn measure_synthetic(args: &Args, size: u32) -> Vec<Row> {
    let quick = args.quick;
    let mut maps: Vec<(&str, HeightMap)> = if quick {
        vec![
            ("bricks", HeightMap::bricks(256, 4, 0.12)),
            ("stone", HeightMap::noise(256, 16, 3, 7)),
        ]
    } else {
        vec![
            ("bricks", HeightMap::bricks(256, 4, 0.12)),
            ("rivets", HeightMap::rivets(256, 4, 0.35)),
            ("stone", HeightMap::noise(256, 16, 3, 7)),
            ("sine", HeightMap::sine(256, 4)),
        ]
    };
    if let Some(only) = &args.maps {
        maps.retain(|(name, _)| only.split(',').any(|o| o == *name));
    }
    let scales: Vec<f32> = match args.scales.clone() {
        Some(scales) => scales,
        None if quick => vec![0.1],
        None => vec![0.05, 0.1, 0.2, 0.4],
    };
    let elevations: &[f32] = if quick { &[45.0] } else { &[20.0, 45.0, 70.0] };
    let pixels = Pixels::new(size);
    // The radiance unit ρ E0 / π (exposure applied) of a surface facing the light, from a flat
    // map under a light from the zenith.
    let flat = HeightMap::from_fn(16, 16, |_, _| 0.5);
    let (calibration, _) = render(
        &flat,
        0.1,
        size,
        Some(Mesostructure::default().into()),
        false,
        Some(90.0),
    );
    let calibration = calibration.frame.expect("the flat plane renders");
    let unit = pixels
        .samples
        .iter()
        .map(|s| calibration.lit[pixels.index(s)][1])
        .sum::<f32>()
        / pixels.samples.len() as f32;
    println!("radiance unit ρE0/π = {unit:.5}");
    let mut rows = Vec::new();
    for (name, map) in &maps {
        for &k in &scales {
            let measured = MapMeasures::new(map, k, &pixels);
            for &e in elevations {
                rows.extend(rows_under_light(name, map, k, e, &measured, &pixels, unit));
            }
        }
    }
    rows
}

/// What one map at one scale gives whatever the light: the AO ground truth, Bevy's SSAO on
/// real geometry, and the brute-force horizon search.
struct MapMeasures {
    field: HeightField,
    ao_truth: Vec<f32>,
    ao_truth_full: Vec<f32>,
    ssao_gpu_ms: f64,
    ssao_ao: Vec<f32>,
    ssao_ao_full: Vec<f32>,
    /// (samples per direction, GPU ms, capture)
    searches: Vec<(u32, f64, CapturedFrame)>,
}

impl MapMeasures {
    fn new(map: &HeightMap, k: f32, pixels: &Pixels) -> Self {
        let size = pixels.size;
        let field = HeightField::new(map.width, map.height, &map.values, 2.0, k);
        let at = |s: &(u32, u32)| uv(s.0, s.1, size) * map.width as f32;
        let ao_truth: Vec<f32> = pixels
            .samples
            .iter()
            .map(|s| field.ambient_occlusion(at(s), 8, 16))
            .collect();
        let clock = std::time::Instant::now();
        let ao_truth_full =
            common::unseen::par_map(&pixels.interior, |s| field.ambient_occlusion(at(s), 8, 16));
        println!("  ground-truth AO: {:.1} s", clock.elapsed().as_secs_f32());
        // SSAO on real geometry: its AO is the ratio of ambient-only pictures.
        let (with, lit_with) = render(map, k, size, None, true, None);
        let (_, lit_without) = render(map, k, size, None, false, None);
        let ssao_ao_at = |s: &(u32, u32)| {
            (lit_with[pixels.index(s)] / lit_without[pixels.index(s)].max(1e-6)).min(1.0)
        };
        // The brute-force, fixed-radius horizon search (8 directions out to 32 px) at several
        // sample counts: AO only, independent of the light.
        let searches = [4u32, 8, 16, 32]
            .into_iter()
            .filter_map(|steps| {
                let settings = common::unseen::Variant {
                    settings: Mesostructure {
                        micro_shadows: false,
                        bleeding: false,
                        ..default()
                    },
                    baseline: Some(HorizonSearchBaseline { steps }),
                };
                let (r, _) = render(map, k, size, Some(settings), false, None);
                Some((steps, r.gpu_ms, r.frame?))
            })
            .collect();
        Self {
            ssao_ao: pixels.samples.iter().map(ssao_ao_at).collect(),
            ssao_ao_full: pixels.interior.iter().map(ssao_ao_at).collect(),
            ssao_gpu_ms: with.gpu_ms,
            field,
            ao_truth,
            ao_truth_full,
            searches,
        }
    }
}

/// The rows of one map at scale `k` under the light at elevation `e` (degrees): `none`,
/// `bevy-ssao`, `horizon-search` and the plugin at each preset.
fn rows_under_light(
    name: &str,
    map: &HeightMap,
    k: f32,
    e: f32,
    measured: &MapMeasures,
    pixels: &Pixels,
    unit: f32,
) -> Vec<Row> {
    let (size, samples, interior) = (pixels.size, &pixels.samples, &pixels.interior);
    let index = |s: &(u32, u32)| pixels.index(s);
    let field = &measured.field;
    let at = |s: &(u32, u32)| uv(s.0, s.1, size) * map.width as f32;
    let ao_truth = &measured.ao_truth;
    let mut rows = Vec::new();
    let scene = format!("{name}/k{k}/light{e}");
    println!("accuracy: {scene}");
    let r = e.to_radians();
    let light = Vec3::new(r.cos(), 0.0, -r.sin()); // the field's frame: z up
    let visible: Vec<bool> = samples
        .iter()
        .map(|s| field.light_visible(at(s), light))
        .collect();
    let facing: Vec<bool> = samples
        .iter()
        .map(|s| field.normal(at(s)).dot(-light) > 0.05)
        .collect();
    let bounce_truth: Vec<f32> = samples
        .iter()
        .map(|s| field.one_bounce(at(s), light, 6, 16))
        .collect();
    // The reference picture, from the ground truth at every interior pixel.
    let clock = std::time::Instant::now();
    let reference: Vec<f32> = common::unseen::par_map(&interior, |s| {
        let lit = field.light_visible(at(s), light) as u32 as f32
            * field.normal(at(s)).dot(-light).max(0.0);
        (lit, field.one_bounce(at(s), light, 6, 16))
    })
    .iter()
    .zip(&measured.ao_truth_full)
    .map(|(&(lit, bounce), &ao)| shade(ao, lit, bounce))
    .collect();
    println!(
        "  ground-truth light and bounce: {:.1} s",
        clock.elapsed().as_secs_f32()
    );
    let flip_of = |test: &[f32]| flip_mean(&reference, test, pixels.inner);
    // Lambert factor of the flat plane, and of the plugin's shading normal (world
    // space: the light travels along (cos e, −sin e, 0)).
    let to_light = Vec3::new(-r.cos(), r.sin(), 0.0);
    let flat_lit = to_light.y.max(0.0);
    // `normals`: a frame's `facing_normals()`, built once per picture.
    let normal_lit =
        |normals: &[Vec3], s: &(u32, u32)| normals[index(s)].dot(to_light).max(0.0);
    let agreement = |shadowed: &dyn Fn(usize) -> bool| {
        let (mut agree, mut n) = (0, 0);
        for (j, _) in samples.iter().enumerate() {
            if facing[j] {
                n += 1;
                agree += (shadowed(j) == !visible[j]) as u32;
            }
        }
        agree as f32 / n.max(1) as f32
    };
    let none_bounce = errors(&vec![0.0; samples.len()], &bounce_truth).0;
    rows.push(Row {
        scene: scene.clone(),
        method: "none".into(),
        setting: "-".into(),
        gpu_ms: 0.0,
        ao: errors(&vec![1.0; samples.len()], &ao_truth),
        shadow: agreement(&|_| false),
        bounce: none_bounce,
        flip: flip_of(&vec![shade(1.0, flat_lit, 0.0); interior.len()]),
    });
    // SSAO runs on the real geometry: its normal is the true one.
    let ssao_picture: Vec<f32> = interior
        .iter()
        .zip(&measured.ssao_ao_full)
        .map(|(s, &ao)| shade(ao, field.normal(at(s)).dot(-light).max(0.0), 0.0))
        .collect();
    rows.push(Row {
        scene: scene.clone(),
        method: "bevy-ssao".into(),
        setting: "default".into(),
        gpu_ms: measured.ssao_gpu_ms,
        ao: errors(&measured.ssao_ao, ao_truth),
        shadow: agreement(&|_| false),
        bounce: none_bounce,
        flip: flip_of(&ssao_picture),
    });
    for (steps, gpu_ms, frame) in &measured.searches {
        let ao: Vec<f32> =
            samples.iter().map(|s| frame.occlusion[index(s)]).collect();
        let normals = frame.facing_normals();
        let picture: Vec<f32> = interior
            .iter()
            .map(|s| shade(frame.occlusion[index(s)], normal_lit(&normals, s), 0.0))
            .collect();
        rows.push(Row {
            scene: scene.clone(),
            method: "horizon-search".into(),
            setting: format!("steps={steps}"),
            gpu_ms: *gpu_ms,
            ao: errors(&ao, &ao_truth),
            shadow: agreement(&|_| false),
            bounce: none_bounce,
            flip: flip_of(&picture),
        });
    }
    let variants = MesostructureQuality::ALL.map(|quality| {
        (quality.name().to_string(), Mesostructure { quality, ..default() })
    });
    let quarter = (
        "high@quarter".to_string(),
        Mesostructure {
            quality: MesostructureQuality::High
                .custom(|c| c.working_resolution = WorkingResolution::Quarter),
            ..default()
        },
    );
    for (setting, settings) in variants.into_iter().chain([quarter]) {
        // AO under ambient light alone is not needed: the capture carries it.
        let (lit, _) = render(map, k, size, Some(settings.into()), false, Some(e));
        let Some(frame) = lit.frame else { continue };
        let ao: Vec<f32> =
            samples.iter().map(|s| frame.occlusion[index(s)]).collect();
        let bounce_at = |s: &(u32, u32)| {
            frame.bleeding.get(index(s)).map_or(0.0, |b| b[1] / unit)
        };
        let bounce: Vec<f32> = samples.iter().map(bounce_at).collect();
        let normals = frame.facing_normals();
        let picture: Vec<f32> = interior
            .iter()
            .map(|s| {
                let v = frame.micro_shadow.get(index(s)).copied().unwrap_or(1.0);
                shade(
                    frame.occlusion[index(s)],
                    v * normal_lit(&normals, s),
                    bounce_at(s),
                )
            })
            .collect();
        rows.push(Row {
            scene: scene.clone(),
            method: "mesostructure".into(),
            setting,
            gpu_ms: lit.gpu_ms,
            ao: errors(&ao, &ao_truth),
            shadow: agreement(&|j| {
                frame
                    .micro_shadow
                    .get(index(&samples[j]))
                    .is_some_and(|&v| v < 0.5)
            }),
            bounce: errors(&bounce, &bounce_truth).0,
            flip: flip_of(&picture),
        });
    }
    rows
}
