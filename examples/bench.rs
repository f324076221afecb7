//! GPU time per pass, from timestamp queries, for the paper's two experiments (its Tables 1 and
//! 2) and for each quality preset at 1920×1080, with Bevy's SSAO and contact shadows measured on
//! the same scenes as peers.
//!
//! ```text
//! cargo run --example bench -- [--out FILE.csv] [--frames N] [--warm-up N]
//!     [--table 1|2|presets|all] [--quality low|medium|high|ultra] [--quick]
//! ```
//!
//! Table 1: resolutions 256², 512², 1024² and 1920×1080 over a torus (2,880 triangles, the
//! paper's), a sphere of ~40 thousand and one of ~1 million triangles (its teapot and Happy
//! Buddha), bricks at scale 0.2. Table 2: scales 0.05–1 on the torus at 1024². Presets: each
//! `MesostructureQuality` at 1920×1080 on the 40-thousand-triangle sphere and on a plane that
//! fills the view (`fullscreen`: every pixel a mesostructure pixel); the scene column reads
//! `scene@preset` where the preset is not the default `high`. Every run renders headless with
//! `Mesostructure` (default, or `--quality`) and Bevy's SSAO on the camera; a second run with
//! Bevy's contact shadows on adds the row `contact_shadows` (its cost, the difference in the
//! lighting pass, which evaluates them for these pixels). Bevy's own `early deferred prepass`
//! (the G-buffer pass over the same mesh) and `tonemapping` (a fullscreen fragment pass) are
//! recorded as yardsticks of what the GPU does with raster work. For each pass: median and
//! 95th percentile over N frames after the warm-up, and the sums `mesostructure/total` and
//! `mesostructure/total_without_lighting` (the lighting pass replaces Bevy's own deferred
//! lighting for these pixels, so it is not all added cost). Each scene is also rendered without
//! the plugin (the same deferred camera and meshes, lit by Bevy): `frame/plugin_on`,
//! `frame/plugin_off` and the headline `frame/added` are whole-frame GPU times from a raw
//! timestamp pair around all cameras (`common/frame_timer.rs`), and `bevy/deferred_lighting`
//! (`_plugin_off`) is Bevy's deferred lighting pass. `--quick` keeps 256² and 512², three
//! scales and the presets at 256² (for the software driver, whose figures are relative only).
//!
//! Writes `FILE.csv` (default `out/bench.csv`) with the columns
//! `scene,triangles,width,height,scale,pass,gpu_ms_median,gpu_ms_p95,frames,adapter` and prints
//! a Markdown table.

#[path = "common/mod.rs"]
mod common;
#[path = "common/frame_timer.rs"]
mod frame_timer;

use std::{fmt::Write as _, path::PathBuf};

use bevy::{
    camera::RenderTarget,
    diagnostic::{DiagnosticPath, DiagnosticsStore},
    core_pipeline::prepass::{DeferredPrepass, DepthPrepass},
    pbr::{ContactShadows, ScreenSpaceAmbientOcclusion},
    camera::Hdr,
    prelude::*,
    render::{
        diagnostic::RenderDiagnosticsPlugin,
        render_resource::{TextureFormat, TextureUsages},
        renderer::RenderAdapterInfo,
    },
};
use bevy_mesostructure::prelude::*;

/// The plugin's passes, in frame order.
const PASSES: [&str; 8] = [
    "height_raster",
    "height",
    "gradient",
    "apex",
    "occlusion",
    "lighting",
    "bleeding",
    "bleeding_composite",
];

/// Bevy's own passes on the same frames, as yardsticks of what this GPU does with a mesh pass
/// (the deferred G-buffer prepass), a fullscreen fragment pass (tonemapping) and a compute pass
/// (SSAO, listed on its own as a peer).
const YARDSTICKS: [&str; 2] = ["early deferred prepass", "tonemapping"];

#[derive(Clone, Copy)]
struct Config {
    scene: &'static str,
    size: UVec2,
    scale: f32,
    quality: MesostructureQuality,
    texture_space: TextureSpace,
}

impl Config {
    /// The scene column: the mesh, the preset where it is not the default, and the
    /// texture-space terms where they are not the defaults'.
    fn label(&self) -> String {
        let scene = match self.quality {
            MesostructureQuality::High => self.scene.to_string(),
            q => format!("{}@{}", self.scene, q.name()),
        };
        match self.texture_space {
            TextureSpace::Bounce => scene,
            TextureSpace::Horizons => format!("{scene}+no-ts-bounce"),
            TextureSpace::Off => format!("{scene}+no-ts-horizons"),
        }
    }
}

/// `--texture-space`: which of `Mesostructure`'s texture-space terms are on, to see what each
/// costs in the height pass.
#[derive(clap::ValueEnum, Clone, Copy, PartialEq, Eq)]
enum TextureSpace {
    /// `texture_space_horizons` and `texture_space_bounce` (the defaults).
    Bounce,
    /// `texture_space_horizons` only.
    Horizons,
    /// Neither: the paper's screen-space terms alone.
    Off,
}

struct Row {
    config: Config,
    triangles: usize,
    pass: String,
    median: f64,
    p95: f64,
    frames: usize,
}

impl Row {
    /// The median and 95th percentile of `values` as the row of `pass`.
    fn of(config: Config, triangles: usize, pass: impl Into<String>, values: &[f64]) -> Self {
        Self {
            config,
            triangles,
            pass: pass.into(),
            median: percentile(values, 0.5),
            p95: percentile(values, 0.95),
            frames: values.len(),
        }
    }
}

fn mesh(scene: &str) -> Mesh {
    match scene {
        "torus" => Torus::new(0.45, 0.8)
            .mesh()
            .major_resolution(48)
            .minor_resolution(30)
            .build(),
        "sphere-40k" => Sphere::new(0.8).mesh().uv(200, 100),
        "sphere-1M" => Sphere::new(0.8).mesh().uv(1000, 500),
        "fullscreen" => Plane3d::default().mesh().size(6.0, 6.0).build(),
        other => panic!("unknown scene {other}"),
    }
}

fn triangles(mesh: &Mesh) -> usize {
    mesh.indices().map_or(mesh.count_vertices(), |i| i.len()) / 3
}

/// How a scene is rendered: with the plugin, or without (the same meshes lit by Bevy's deferred
/// renderer), to measure what the plugin adds to a frame.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Run {
    PluginOn,
    /// The plugin on, Bevy's contact shadows too.
    ContactShadows,
    PluginOff,
}

/// Renders `config` for `warm_up + frames` frames; the per-frame GPU milliseconds of each span
/// in `spans` and of the whole frame (`frame`) and Bevy's deferred lighting
/// (`bevy/deferred_lighting`), and the adapter's name.
fn measure(config: Config, run: Run, frames: usize, warm_up: usize) -> (Vec<(String, Vec<f64>)>, usize, String) {
    let contact_shadows = run == Run::ContactShadows;
    let mut app = App::new();
    app.add_plugins(common::headless_plugins().disable::<bevy::log::LogPlugin>())
        .add_plugins((MesostructurePlugin, RenderDiagnosticsPlugin, frame_timer::FrameTimerPlugin));
    app.finish();
    app.cleanup();
    let world = app.world_mut();
    let mut image = Image::new_target_texture(
        config.size.x,
        config.size.y,
        TextureFormat::Rgba8UnormSrgb,
        None,
    );
    image.texture_descriptor.usage |= TextureUsages::COPY_SRC;
    let target = world.resource_mut::<Assets<Image>>().add(image);
    let mut camera = world.spawn((
        Camera3d::default(),
        RenderTarget::Image(target.into()),
        Msaa::Off,
        // What `Mesostructure` requires, so that the plugin-off frame is the same deferred
        // frame without the plugin's passes.
        DepthPrepass,
        DeferredPrepass,
        Hdr,
        ScreenSpaceAmbientOcclusion::default(),
        Transform::from_xyz(0.0, 1.2, 2.2).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    if run != Run::PluginOff {
        camera.insert(Mesostructure {
            quality: config.quality,
            texture_space_horizons: config.texture_space != TextureSpace::Off,
            texture_space_bounce: config.texture_space == TextureSpace::Bounce,
            ..default()
        });
    }
    if contact_shadows {
        camera.insert(ContactShadows::default());
    }
    world.spawn((
        DirectionalLight {
            illuminance: 8000.0,
            shadow_maps_enabled: true,
            contact_shadows_enabled: contact_shadows,
            ..default()
        },
        Transform::from_xyz(2.0, 3.0, 1.5).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    world.insert_resource(bevy::light::GlobalAmbientLight {
        brightness: 1000.0,
        ..default()
    });
    let object = mesh(config.scene);
    let count = triangles(&object);
    let object = world.resource_mut::<Assets<Mesh>>().add(object);
    let height_map = world
        .resource_mut::<Assets<Image>>()
        .add(HeightMap::bricks(512, 8, 0.15).to_image());
    // Deferred in both runs: with the plugin off Bevy's deferred lighting lights the mesh (the
    // frame the plugin's lighting pass replaces); with it on the plugin's copy is deferred too.
    let material = world.resource_mut::<Assets<StandardMaterial>>().add(StandardMaterial {
        opaque_render_method: bevy::material::OpaqueRendererMethod::Deferred,
        ..StandardMaterial::from(Color::srgb(0.75, 0.4, 0.3))
    });
    let mut mesh = world.spawn((
        Mesh3d(object),
        MeshMaterial3d(material),
        if config.scene == "fullscreen" {
            // Facing the camera and filling its view: every pixel a mesostructure pixel.
            Transform::from_rotation(Quat::from_rotation_arc(
                Vec3::Y,
                Vec3::new(0.0, 1.2, 2.2).normalize(),
            ))
        } else {
            Transform::from_rotation(Quat::from_rotation_x(0.5))
        },
    ));
    if run != Run::PluginOff {
        mesh.insert(MesostructureMaterial {
            height_map,
            scale: config.scale,
            uv_transform: bevy::math::Affine2::from_scale(Vec2::new(6.0, 3.0)),
        });
    }
    // (The diagnostics keep the last frames: none of them while a height map is being built.)
    common::update_when_ready(&mut app, warm_up + frames);
    let adapter = app
        .world()
        .get_resource::<RenderAdapterInfo>()
        .map_or("unknown".to_string(), |a| a.0.name.clone());
    let store = app.world().resource::<DiagnosticsStore>();
    let mut spans: Vec<String> = PASSES
        .iter()
        .map(|p| format!("mesostructure/{p}"))
        .collect();
    spans.push("ssao".into());
    spans.extend(YARDSTICKS.iter().map(|s| s.to_string()));
    let tail = |values: &[f64]| values[values.len().saturating_sub(frames)..].to_vec();
    let mut series: Vec<(String, Vec<f64>)> = spans
        .into_iter()
        .filter_map(|span| {
            let path = DiagnosticPath::new(format!("render/{span}/elapsed_gpu"));
            let values: Vec<f64> = store.get(&path)?.values().copied().collect();
            let tail = tail(&values);
            (!tail.is_empty()).then_some((span, tail))
        })
        .collect();
    // Fragment invocations of the raster passes (pipeline statistics; where supported).
    for pass in ["height", "lighting", "bleeding_composite"] {
        let path = DiagnosticPath::new(format!(
            "render/mesostructure/{pass}/fragment_shader_invocations"
        ));
        // Over the measured frames only (recorded with or after the first measured frame's
        // time): a pass that changes form — the lighting pass becomes compute once its pipeline
        // has compiled — has statistics from its first, raster frames alone.
        let elapsed = DiagnosticPath::new(format!("render/mesostructure/{pass}/elapsed_gpu"));
        let first_measured = store
            .get(&elapsed)
            .and_then(|d| {
                let times: Vec<_> = d.measurements().map(|m| m.time).collect();
                times.len().checked_sub(frames.max(1)).map(|i| times[i])
            });
        let measured = store
            .get(&path)
            .zip(first_measured)
            .map(|(d, since)| {
                d.measurements()
                    .filter(|m| m.time >= since)
                    .map(|m| m.value)
                    .collect::<Vec<_>>()
            })
            .filter(|v| !v.is_empty());
        if let Some(values) = measured {
            let median = percentile(&values, 0.5);
            println!("  mesostructure/{pass}: {median:.0} fragment invocations a frame");
        }
    }
    let times = app.world().resource::<frame_timer::FrameGpuTimes>();
    let times = times.0.lock().expect("frame timer lock");
    if !times.lead_ms.is_empty() {
        println!(
            "  frame timer: lead {:.1} ms (median; the GPU idles on nothing inside the bracket)",
            percentile(&tail(&times.lead_ms), 0.5)
        );
    }
    for (name, values) in [
        ("frame", &times.frame_ms),
        ("bevy/deferred_lighting", &times.deferred_lighting_ms),
    ] {
        if !values.is_empty() {
            series.push((name.to_string(), tail(values)));
        }
    }
    (series, count, adapter)
}

fn percentile(values: &[f64], p: f64) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * p).round() as usize]
}

/// GPU time per pass for the paper's Tables 1 and 2 and the quality presets.
#[derive(clap::Parser)]
#[command(long_about = None)]
struct Cli {
    /// The CSV to write
    #[arg(long, default_value = "out/bench.csv")]
    out: PathBuf,
    /// Frames measured per scene (1–100: the diagnostics keep 120 values)
    #[arg(long, default_value_t = 60, value_parser = clap::value_parser!(u16).range(1..=100))]
    frames: u16,
    /// Frames rendered before measuring
    #[arg(long, default_value_t = 20)]
    warm_up: usize,
    /// Which table
    #[arg(long, default_value = "all", value_parser = ["1", "2", "presets", "all"])]
    table: String,
    /// The preset of every run but the presets table
    #[arg(long, default_value = "high", value_parser = parse_quality)]
    quality: MesostructureQuality,
    /// Small sizes only (for the software driver)
    #[arg(long)]
    quick: bool,
    /// Which texture-space terms are on (`Mesostructure::texture_space_horizons` and
    /// `texture_space_bounce`): both (the defaults), the horizons only, or neither
    #[arg(long, value_enum, default_value_t = TextureSpace::Bounce)]
    texture_space: TextureSpace,
}

fn parse_quality(s: &str) -> Result<MesostructureQuality, String> {
    MesostructureQuality::from_name(s).ok_or_else(|| format!("expected low, medium, high or ultra, got {s:?}"))
}

fn main() {
    use clap::Parser;
    let cli = Cli::parse();
    let (out, mut frames, warm_up, table, quick, quality) = (
        cli.out,
        cli.frames as usize,
        cli.warm_up,
        cli.table,
        cli.quick,
        cli.quality,
    );
    // The diagnostics keep 120 values.
    frames = frames.clamp(1, 100);
    let sizes: Vec<UVec2> = if quick {
        vec![UVec2::splat(256), UVec2::splat(512)]
    } else {
        vec![
            UVec2::splat(256),
            UVec2::splat(512),
            UVec2::splat(1024),
            UVec2::new(1920, 1080),
        ]
    };
    let mut configs = vec![];
    if table == "1" || matches!(table.as_str(), "all" | "both") {
        for scene in ["torus", "sphere-40k", "sphere-1M"] {
            for &size in &sizes {
                configs.push(Config {
                    scene,
                    size,
                    scale: 0.2,
                    quality,
                    texture_space: cli.texture_space,
                });
            }
        }
    }
    if table == "2" || matches!(table.as_str(), "all" | "both") {
        let scales: &[f32] = if quick {
            &[0.05, 0.2, 1.0]
        } else {
            &[0.05, 0.1, 0.2, 0.4, 0.6, 0.8, 1.0]
        };
        let size = if quick {
            UVec2::splat(512)
        } else {
            UVec2::splat(1024)
        };
        for &scale in scales {
            configs.push(Config {
                scene: "torus",
                size,
                scale,
                quality,
                texture_space: cli.texture_space,
            });
        }
    }
    if table == "presets" || matches!(table.as_str(), "all" | "both") {
        // The performance goal's setting: 1920×1080, each preset, on the sphere and on a plane
        // that fills the view (the most mesostructure pixels a frame can have).
        let size = if quick {
            UVec2::splat(256)
        } else {
            UVec2::new(1920, 1080)
        };
        for scene in ["sphere-40k", "fullscreen"] {
            for quality in MesostructureQuality::ALL {
                configs.push(Config {
                    scene,
                    size,
                    scale: 0.2,
                    quality,
                    texture_space: cli.texture_space,
                });
            }
        }
    }

    let mut rows = vec![];
    let mut adapter = String::new();
    for config in configs {
        println!(
            "bench: {} at {}×{}, scale {} ...",
            config.label(),
            config.size.x,
            config.size.y,
            config.scale
        );
        let (series, triangles, name) = measure(config, Run::PluginOn, frames, warm_up);
        adapter = name;
        // All passes, and all but the lighting pass (which replaces Bevy's own deferred lighting
        // for these pixels rather than adding to it).
        // Over the newest frames that every pass reported (the timestamps of a frame can be
        // dropped when the GPU falls behind; summing ragged series would count zeros).
        let reported = series
            .iter()
            .filter(|(span, _)| span.starts_with("mesostructure/"))
            .map(|(_, values)| values.len())
            .min()
            .unwrap_or(0);
        let mut total = vec![0.0; reported];
        let mut added = vec![0.0; reported];
        let mut lighting_without = None;
        for (span, values) in &series {
            if span == "frame" {
                continue; // `frame/plugin_on` below
            }
            if span.starts_with("mesostructure/") {
                let newest = &values[values.len() - reported..];
                for (t, v) in total.iter_mut().zip(newest) {
                    *t += v;
                }
                if span != "mesostructure/lighting" {
                    for (t, v) in added.iter_mut().zip(newest) {
                        *t += v;
                    }
                }
            }
            if span == "mesostructure/lighting" {
                lighting_without = Some(percentile(values, 0.5));
            }
            rows.push(Row::of(config, triangles, span, values));
        }
        rows.push(Row::of(config, triangles, "mesostructure/total", &total));
        rows.push(Row::of(config, triangles, "mesostructure/total_without_lighting", &added));
        // What the plugin adds: the same frame without it (Bevy's deferred lighting for the
        // same meshes), whole frames bracketed by raw timestamps.
        let (off, _, _) = measure(config, Run::PluginOff, frames, warm_up);
        let find = |series: &[(String, Vec<f64>)], name: &str| {
            series.iter().find(|(s, _)| s == name).map(|(_, v)| v.clone())
        };
        if let (Some(on_frames), Some(off_frames)) = (find(&series, "frame"), find(&off, "frame")) {
            for (pass, values) in [("frame/plugin_on", &on_frames), ("frame/plugin_off", &off_frames)] {
                rows.push(Row::of(config, triangles, pass, values));
            }
            rows.push(Row {
                config,
                triangles,
                pass: "frame/added".into(),
                median: percentile(&on_frames, 0.5) - percentile(&off_frames, 0.5),
                p95: percentile(&on_frames, 0.95) - percentile(&off_frames, 0.95),
                frames: on_frames.len().min(off_frames.len()),
            });
        }
        if let Some(values) = find(&off, "bevy/deferred_lighting") {
            rows.push(Row::of(config, triangles, "bevy/deferred_lighting_plugin_off", &values));
        }
        // Contact shadows: the same scene with them on; their cost is the lighting pass's growth.
        let (with, _, _) = measure(config, Run::ContactShadows, frames, warm_up);
        if let (Some(without), Some((_, values))) = (
            lighting_without,
            with.iter().find(|(s, _)| s == "mesostructure/lighting"),
        ) {
            rows.push(Row {
                config,
                triangles,
                pass: "contact_shadows".into(),
                median: percentile(values, 0.5) - without,
                p95: percentile(values, 0.95) - without,
                frames: values.len(),
            });
        }
    }


    let mut csv = String::from(
        "scene,triangles,width,height,scale,pass,gpu_ms_median,gpu_ms_p95,frames,adapter\n",
    );
    let mut table = String::from(
        "| scene | triangles | size | scale | pass | median ms | p95 ms |\n|---|---|---|---|---|---|---|\n",
    );
    for r in &rows {
        let c = r.config;
        let _ = writeln!(
            csv,
            "{},{},{},{},{},{},{:.4},{:.4},{},\"{}\"",
            c.label(),
            r.triangles,
            c.size.x,
            c.size.y,
            c.scale,
            r.pass,
            r.median,
            r.p95,
            r.frames,
            adapter
        );
        let _ = writeln!(
            table,
            "| {} | {} | {}×{} | {} | {} | {:.3} | {:.3} |",
            c.label(),
            r.triangles,
            c.size.x,
            c.size.y,
            c.scale,
            r.pass,
            r.median,
            r.p95
        );
    }
    if let Some(dir) = out.parent() {
        std::fs::create_dir_all(dir).expect("cannot create the output folder");
    }
    std::fs::write(&out, csv).expect("cannot write the CSV");
    println!(
        "\nGPU time per pass on {adapter} ({frames} frames after {warm_up} of warm-up):\n\n{table}"
    );
    println!("wrote {}", out.display());
}
