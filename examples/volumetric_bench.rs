//! Speed against accuracy of volumetric spot lights: this crate's equal-angle pass at 4, 8,
//! 16 and 32 samples and seed 004's slicing planes at 4, 8, 16 and 32 planes against Bevy's
//! `VolumetricFog` at 16, 32, 64 and 128 steps, on issue 12's
//! reference set-up (a spot at (0, 4, 0) aimed at (0.5, 0, 0), outer 30°, inner 20°, 20 000 lm,
//! range 100, in a 20 × 10 × 20 m fog volume of σs 0.10, σa 0.01; all surfaces black), with and
//! without a 1 m cube casting a shaft. Each run's fog-only radiance (HDR, read back) is scored
//! against the exact CPU reference (`volumetric::reference`), and its GPU time is what it adds
//! to a frame (median frame GPU time with it, less the same scene without volumetrics).
//!
//! ```text
//! cargo run --example volumetric_bench -- [--size WxH] [--frames N] [--g G]
//!     [--out docs/volumetric.csv] [--only equal_angle:16,bevy_fog:64] [--scene shadowed]
//! ```
//!
//! CSV header: `scene,method,setting,width,height,gpu_ms,rel_l1,rmse,tip_rel_l1,adapter`
//! (`tip_rel_l1`: the pixels whose ray passes within 15° of the light).

#[path = "common/mod.rs"]
mod common;
#[path = "common/frame_timer.rs"]
mod frame_timer;
#[path = "common/spot_scene.rs"]
mod spot_scene;

use std::{
    io::Write,
    path::PathBuf,
    sync::{Arc, Mutex},
};

use bevy::{
    camera::{CameraProjection, Exposure, Hdr, RenderTarget},
    core_pipeline::tonemapping::{DebandDither, Tonemapping},
    light::{FogVolume, GlobalAmbientLight, VolumetricFog, VolumetricLight},
    math::DVec3,
    prelude::*,
    render::{
        render_resource::{TextureFormat, TextureUsages},
        renderer::RenderAdapterInfo,
        view::screenshot::{Screenshot, ScreenshotCaptured},
    },
};
use bevy_mesostructure::volumetric::{
    VolumetricMedium, VolumetricMethod, VolumetricResolution, VolumetricSpot, VolumetricSpotsPlugin,
    reference::Occluder,
};
use spot_scene::{ABSORPTION, EV100, SCATTERING};

const EYE: Vec3 = Vec3::new(0.0, 1.6, 7.0);

/// Speed against accuracy of the volumetric spots and Bevy's fog, into a CSV.
#[derive(clap::Parser)]
#[command(long_about = None)]
struct Cli {
    /// Picture size, N or WxH
    #[arg(long, default_value = "256x144", value_parser = common::parse_size)]
    size: UVec2,
    /// Frames timed per run (after 5 of warm-up)
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(1..))]
    frames: u32,
    /// Henyey–Greenstein g of the medium
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    g: f32,
    /// The CSV to write
    #[arg(long, default_value = "docs/volumetric.csv")]
    out: PathBuf,
    /// The chart to draw (GPU time against relative L1, per scene)
    #[arg(long, default_value = "docs/images/volumetric_chart.png")]
    chart: PathBuf,
    /// Only these runs, as METHOD:SETTING (e.g. `equal_angle:16,bevy_fog:64`); all when absent
    #[arg(long, value_delimiter = ',')]
    only: Vec<String>,
    /// Only this scene (`unshadowed` or `shadowed`); both when absent
    #[arg(long, value_parser = ["unshadowed", "shadowed"])]
    scene: Option<String>,
}

/// One measured run.
struct Row {
    scene: &'static str,
    method: &'static str,
    gpu_ms: f64,
    rel_l1: f64,
}

/// Per scene, GPU time against relative L1 (log scale) of each method's settings.
fn draw_chart(rows: &[Row], path: &PathBuf) {
    use plotters::prelude::*;
    common::chart::save(1200, 480, path, |root| {
        for (panel, scene) in root.split_evenly((1, 2)).iter().zip(["unshadowed", "shadowed"]) {
            let of_scene: Vec<&Row> = rows.iter().filter(|r| r.scene == scene).collect();
            let max_x = of_scene.iter().map(|r| r.gpu_ms).fold(1e-3, f64::max) * 1.1;
            let mut chart = ChartBuilder::on(panel)
                .caption(format!("{scene} spot: GPU time against error"), ("sans-serif", 20))
                .margin(15)
                .x_label_area_size(45)
                .y_label_area_size(60)
                .build_cartesian_2d(0.0..max_x, (1e-4..10.0).log_scale())
                .expect("draw");
            chart
                .configure_mesh()
                .x_desc("GPU time added to the frame, ms")
                .y_desc("relative L1 against the exact reference")
                .label_style(("sans-serif", 14))
                .draw()
                .expect("draw");
            for (i, method) in
                ["equal_angle", "equal_angle (reduced)", "equal_angle (fragment)", "planes", "bevy_fog"]
                .into_iter()
                .enumerate()
            {
                let mut points: Vec<(f64, f64)> = of_scene
                    .iter()
                    .filter(|r| r.method == method)
                    .map(|r| (r.gpu_ms.max(0.0), r.rel_l1.max(1e-4)))
                    .collect();
                points.sort_by(|a, b| a.0.total_cmp(&b.0));
                let color = [RED, MAGENTA, CYAN, GREEN, BLUE][i].to_rgba();
                common::chart::line_with_points(&mut chart, method, &points, color);
            }
            common::chart::legend(&mut chart);
        }
    });
}

#[derive(Clone, Copy, PartialEq)]
enum Method {
    /// No volumetrics: the frame time to subtract.
    Off,
    EqualAngle(u32),
    /// 16 samples at a reduced resolution.
    EqualAngleReduced(VolumetricResolution),
    /// This many samples in the fullscreen fragment pass (the fallback where the camera's
    /// main images take no storage writes) instead of the compute pass.
    EqualAngleRaster(u32),
    /// Seed 004's slicing planes, this many per spot.
    Planes(u32),
    BevyFog(u32),
}

/// One run: renders the scene with `method`, returns the fog-only radiance (red channel,
/// exposure applied), the median frame GPU time, and the adapter's name.
/// `None` (after one line on stderr) when the screenshot never arrives.
fn run(size: UVec2, frames: u32, g: f32, shadowed: bool, method: Method) -> Option<(Vec<f32>, f64, String)> {
    let mut app = App::new();
    app.add_plugins((
        common::headless_plugins().disable::<bevy::log::LogPlugin>(),
        VolumetricSpotsPlugin,
        frame_timer::FrameTimerPlugin,
    ))
    .insert_resource(GlobalAmbientLight {
        brightness: 0.0,
        ..default()
    })
    .insert_resource(ClearColor(Color::BLACK));
    let world = app.world_mut();
    let black = world
        .resource_mut::<Assets<StandardMaterial>>()
        .add(StandardMaterial {
            base_color: Color::BLACK,
            unlit: true,
            ..default()
        });
    let plane = world
        .resource_mut::<Assets<Mesh>>()
        .add(Plane3d::default().mesh().size(20.0, 20.0));
    world.spawn((Mesh3d(plane), MeshMaterial3d(black.clone())));
    if shadowed {
        let cube = world.resource_mut::<Assets<Mesh>>().add(Cuboid::new(1.0, 1.0, 1.0));
        world.spawn((Mesh3d(cube), MeshMaterial3d(black), Transform::from_xyz(0.0, 2.5, 0.0)));
    }
    // Shadow maps on in both scenes: Bevy 0.19.1's fog lights only spots with shadow maps (its
    // VOLUMETRIC flag needs them); the unshadowed scene has nothing to cast a shadow.
    let mut spot = world.spawn((spot_scene::bevy_spot(true), spot_scene::spot_transform()));
    match method {
        Method::EqualAngle(samples) | Method::Planes(samples) | Method::EqualAngleRaster(samples) => {
            spot.insert(VolumetricSpot {
                samples,
                ..default()
            });
        }
        Method::EqualAngleReduced(_) => {
            spot.insert(VolumetricSpot::default());
        }
        Method::BevyFog(_) => {
            spot.insert(VolumetricLight);
        }
        Method::Off => {}
    }
    let mut image = Image::new_target_texture(size.x, size.y, TextureFormat::Rgba16Float, None);
    image.texture_descriptor.usage |= TextureUsages::COPY_SRC;
    let target = world.resource_mut::<Assets<Image>>().add(image);
    let mut camera_entity = world.spawn((
        Camera3d::default(),
        RenderTarget::Image(target.clone().into()),
        Hdr,
        Msaa::Off,
        Tonemapping::None,
        DebandDither::Disabled,
        Exposure { ev100: EV100 },
        Transform::from_translation(EYE).looking_at(Vec3::new(0.0, 1.5, 0.0), Vec3::Y),
    ));
    match method {
        Method::EqualAngle(_)
        | Method::EqualAngleReduced(_)
        | Method::Planes(_)
        | Method::EqualAngleRaster(_) => {
            camera_entity.insert(VolumetricMedium {
                scattering: SCATTERING,
                absorption: ABSORPTION,
                asymmetry: g,
                resolution: match method {
                    Method::EqualAngleReduced(r) => r,
                    _ => VolumetricResolution::Full,
                },
                method: match method {
                    Method::Planes(_) => VolumetricMethod::SlicingPlanes,
                    _ => VolumetricMethod::EqualAngleRays,
                },
            });
        }
        Method::BevyFog(steps) => {
            camera_entity.insert(VolumetricFog {
                ambient_intensity: 0.0,
                jitter: 0.0,
                step_count: steps,
                ..default()
            });
        }
        Method::Off => {}
    }
    let camera = camera_entity.id();
    if let Method::BevyFog(_) = method {
        world.spawn((
            FogVolume {
                density_factor: 1.0,
                scattering: SCATTERING,
                absorption: ABSORPTION,
                scattering_asymmetry: g,
                ..default()
            },
            Transform::from_xyz(0.0, 5.0, 0.0).with_scale(Vec3::new(20.0, 10.0, 20.0)),
        ));
    }
    app.finish();
    app.cleanup();
    app.update();
    if let Method::EqualAngleRaster(_) = method {
        // The camera's own usages, without the storage writes the plugin asked for.
        app.world_mut()
            .entity_mut(camera)
            .insert(bevy::camera::CameraMainTextureUsages::default());
    }
    for _ in 0..4 {
        app.update();
    }
    app.world()
        .resource::<frame_timer::FrameGpuTimes>()
        .0
        .lock()
        .unwrap()
        .frame_ms
        .clear();
    for _ in 0..frames {
        app.update();
    }
    let slot: Arc<Mutex<Option<Image>>> = Arc::default();
    let s = slot.clone();
    app.world_mut()
        .spawn(Screenshot::image(target))
        .observe(move |ev: On<ScreenshotCaptured>| {
            *s.lock().unwrap() = Some(ev.image.clone());
        });
    let mut shot = None;
    // (At 1920×1080 the screenshot's readback can take more than ten frames to arrive.)
    for _ in 0..60 {
        app.update();
        if let Some(image) = slot.lock().unwrap().take() {
            shot = Some(image);
            break;
        }
    }
    let Some(shot) = shot else {
        eprintln!("warning: no screenshot after 60 frames; this run is left out");
        return None;
    };
    let red = spot_scene::red(&shot);
    let mut times = app
        .world()
        .resource::<frame_timer::FrameGpuTimes>()
        .0
        .lock()
        .unwrap()
        .frame_ms
        .clone();
    times.sort_by(f64::total_cmp);
    let median = times.get(times.len() / 2).copied().unwrap_or(f64::NAN);
    let adapter = app
        .get_sub_app(bevy::render::RenderApp)
        .and_then(|r| r.world().get_resource::<RenderAdapterInfo>())
        .map_or_else(|| "unknown".into(), |info| info.name.clone());
    Some((red, median, adapter))
}

/// Per pixel, the exact fog-only radiance (exposure applied) and whether the ray passes within
/// 15° of the light; the medium ends at the fog volume's box, as Bevy's fog does.
fn truth(size: UVec2, g: f32, shadowed: bool) -> spot_scene::Truth {
    let transform = Transform::from_translation(EYE).looking_at(Vec3::new(0.0, 1.5, 0.0), Vec3::Y);
    let projection = PerspectiveProjection {
        aspect_ratio: size.x as f32 / size.y as f32,
        ..default()
    };
    let volume = Occluder {
        min: DVec3::new(-10.0, 0.0, -10.0),
        max: DVec3::new(10.0, 10.0, 10.0),
    };
    let cube = [spot_scene::cube()];
    let occluders: &[Occluder] = if shadowed { &cube } else { &[] };
    spot_scene::truth(
        transform.to_matrix(),
        projection.get_clip_from_view(),
        size,
        g,
        occluders,
        Some(&volume),
        None,
    )
}

/// Where the error lies: of the scored pixels (truth above 1 % of its largest), the share of
/// Σ|v − t| and the signed Σ(v − t)/Σt in bands of angle between the ray and the light.
fn error_by_angle(values: &[f32], truth: &spot_scene::Truth) -> String {
    let max = truth.exact.iter().cloned().fold(0.0, f64::max);
    let bands = [0.0, 0.5, 2.0, 15.0, 180.0];
    let mut abs = [0.0; 4];
    let mut signed = [0.0; 4];
    let mut sum = [0.0; 4];
    let mut count = [0u32; 4];
    for ((&v, &t), &a) in values.iter().zip(&truth.exact).zip(&truth.angle_to_light) {
        if t > 0.01 * max {
            let band = bands.windows(2).position(|w| a >= w[0] && a < w[1]).unwrap_or(3);
            abs[band] += (v as f64 - t).abs();
            signed[band] += v as f64 - t;
            sum[band] += t;
            count[band] += 1;
        }
    }
    let total: f64 = abs.iter().sum::<f64>().max(1e-30);
    (0..4)
        .map(|i| {
            format!(
                "{}–{}°: {} px, {:.0} % of the error, bias {:+.4}",
                bands[i],
                bands[i + 1],
                count[i],
                100.0 * abs[i] / total,
                signed[i] / sum[i].max(1e-30)
            )
        })
        .collect::<Vec<_>>()
        .join("; ")
}

/// Relative L1, RMSE (relative to the mean) and relative L1 over `mask`, on the pixels where
/// the truth is above 1 % of its largest value.
fn scores(values: &[f32], truth: &[f64], mask: &[bool]) -> (f64, f64, f64) {
    let max = truth.iter().cloned().fold(0.0, f64::max);
    let (mut sq, mut sum, mut n) = (0.0, 0.0, 0.0);
    for (&v, &t) in values.iter().zip(truth) {
        if t > 0.01 * max {
            sq += (v as f64 - t).powi(2);
            sum += t;
            n += 1.0;
        }
    }
    (
        spot_scene::relative_l1(values, truth, None),
        (sq / n).sqrt() / (sum / n),
        spot_scene::relative_l1(values, truth, Some(mask)),
    )
}

fn main() {
    use clap::Parser;
    let cli = Cli::parse();
    let mut rows = vec!["scene,method,setting,width,height,gpu_ms,rel_l1,rmse,tip_rel_l1,adapter".to_string()];
    let mut measured = vec![];
    for (scene, shadowed) in [("unshadowed", false), ("shadowed", true)] {
        if cli.scene.as_deref().is_some_and(|s| s != scene) {
            continue;
        }
        let truth = truth(cli.size, cli.g, shadowed);
        let Some((_, off_ms, _)) = run(cli.size, cli.frames, cli.g, shadowed, Method::Off) else {
            continue;
        };
        let methods = [4, 8, 16, 32]
            .map(|n| ("equal_angle", Method::EqualAngle(n), n.to_string()))
            .into_iter()
            .chain([
                ("equal_angle", Method::EqualAngleRaster(16), "16@raster".to_string()),
                (
                    "equal_angle",
                    Method::EqualAngleReduced(VolumetricResolution::Half),
                    "16@half".to_string(),
                ),
                (
                    "equal_angle",
                    Method::EqualAngleReduced(VolumetricResolution::Quarter),
                    "16@quarter".to_string(),
                ),
            ])
            .chain([4, 8, 16, 32].map(|n| ("planes", Method::Planes(n), n.to_string())))
            .chain([16, 32, 64, 128].map(|n| ("bevy_fog", Method::BevyFog(n), n.to_string())));
        for (name, method, setting) in methods {
            if !cli.only.is_empty() && !cli.only.contains(&format!("{name}:{setting}")) {
                continue;
            }
            let Some((values, ms, adapter)) = run(cli.size, cli.frames, cli.g, shadowed, method) else {
                continue;
            };
            let (rel_l1, rmse, tip_l1) = scores(&values, &truth.exact, &truth.tip);
            let ratio =
                values.iter().map(|&v| v as f64).sum::<f64>() / truth.exact.iter().sum::<f64>();
            eprintln!(
                "{scene} {name} {setting}: mean radiance {ratio:.3} × the reference; {}",
                error_by_angle(&values, &truth)
            );
            let row = format!(
                "{scene},{name},{setting},{},{},{:.4},{rel_l1:.4},{rmse:.4},{tip_l1:.4},\"{adapter}\"",
                cli.size.x,
                cli.size.y,
                ms - off_ms
            );
            println!("{row}");
            rows.push(row);
            measured.push(Row {
                scene,
                method: if setting.ends_with("@raster") {
                    "equal_angle (fragment)"
                } else if setting.contains('@') {
                    "equal_angle (reduced)"
                } else {
                    name
                },
                gpu_ms: ms - off_ms,
                rel_l1,
            });
        }
    }
    if let Some(dir) = cli.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).ok();
    }
    let mut file = std::fs::File::create(&cli.out)
        .unwrap_or_else(|e| panic!("cannot write {}: {e}", cli.out.display()));
    writeln!(file, "{}", rows.join("\n")).unwrap();
    println!("wrote {}", cli.out.display());
    draw_chart(&measured, &cli.chart);
    println!("wrote {}", cli.chart.display());
}
