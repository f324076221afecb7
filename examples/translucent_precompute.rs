//! What seed 001's precompute costs on the CPU, per patch budget: issue 13's scene (a marble
//! bunny and a skin sphere in a closed room) resampled into patches, the sparse transport built
//! (form factors with ray-traced visibility, dipole transfer), one frame's light injected and
//! iterated to convergence. One CSV row per budget.
//!
//! ```text
//! cargo run --example translucent_precompute -- [--budgets 1000,5000] [--kernel scaled-dipole|burley|dipole]
//!     [--cutoff 1e-5] [--shape-energy-dropped 1e-6] [--out docs/translucent-precompute.csv]
//!     [--beam-table [--walks N] [--far-splits N] [--max-last-order N] [--late-walks N]]
//! ```
//!
//! CSV header: `patches,budget,precompute_s,memory_mb,form_factor_entries,scattering_entries,
//! rays,dropped_form_factor_mean,dropped_form_factor_max,diffusion_kept_r,diffusion_kept_g,
//! diffusion_kept_b,iterations,solve_ms,threads,shadow_ray_injection_ms`
//! (`memory_mb`: the two CSR matrices as the GPU would hold them; `solve_ms`: the CPU iteration
//! to a threshold of 1e-3, one thread; `shadow_ray_injection_ms`: the spot's direct light by
//! one shadow ray per patch on every core, what `LightInjection::ShadowRays` costs the main
//! thread each frame the light moves).

// Only `read_obj` and `asset_path` are used here.
#[allow(dead_code)]
#[path = "common/meshes.rs"]
mod meshes;
#[path = "common/translucent_scene.rs"]
mod translucent_scene;
// Only `save` and `line_with_points` are used here.
#[allow(dead_code)]
#[path = "common/chart.rs"]
mod chart;

use std::{io::Write, path::PathBuf, time::Instant};

use bevy::prelude::*;
use bevy_mesostructure::translucency::{
    beam_table::{BeamTable, BeamTableSettings},
    DiffusionKernel, DirectLight, EnergyTransport, MAX_SHAPE_ENERGY_DROPPED, PatchLight, PatchObject, Patches, SceneRays,
    TranslucencySettings, TransportSettings, TransportSolution, direct_irradiance,
    resample_into_patches_with_caps, translucent_patch_cap,
    transport::{settle_frames, warm_iterations},
};

/// Precompute cost of the translucency transport per patch budget, into a CSV.
#[derive(clap::Parser)]
#[command(long_about = None)]
struct Cli {
    /// Patch budgets, comma-separated
    #[arg(long, value_delimiter = ',', default_value = "500,1000,2000,5000",
          value_parser = clap::value_parser!(u32).range(1..=200_000))]
    budgets: Vec<u32>,
    /// Diffusion profile
    #[arg(long, value_enum, default_value_t = Kernel::ScaledDipole)]
    kernel: Kernel,
    /// Form factors below this are dropped (before visibility)
    #[arg(long, default_value_t = 1e-5)]
    cutoff: f32,
    /// Share of each shape-solved column's energy its lightest entries may hold and be
    /// dropped (`TransportSettings::shape_energy_dropped`, 0 – 0.01; 0: every pair kept)
    #[arg(long, default_value_t = TransportSettings::default().shape_energy_dropped)]
    shape_energy_dropped: f32,
    /// CSV to write (stdout as well)
    #[arg(long)]
    out: Option<PathBuf>,
    /// PNG chart of precompute time and memory against patches
    #[arg(long)]
    chart: Option<PathBuf>,
    /// Also build the translucent patches' beam table (`beam_table::BeamTable`, default
    /// settings; the plugin builds it by default) and report its time, entries and memory on
    /// stderr (the CSV's `precompute_s` and `memory_mb` are the transport's without it)
    #[arg(long)]
    beam_table: bool,
    /// With `--beam-table`: beam walks a direction (`BeamTableSettings::walks`; default the
    /// plugin's)
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=65536))]
    walks: Option<u32>,
    /// With `--beam-table`: how many walks each beam walk becomes far from its entry
    /// (`BeamTableSettings::far_splits`; default the plugin's)
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=64))]
    far_splits: Option<u32>,
    /// With `--beam-table`: the most scatterings a walk takes in a medium that barely absorbs
    /// (`BeamTableSettings::max_last_order`; default the plugin's)
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=4096))]
    max_last_order: Option<u32>,
    /// With `--beam-table`: diffuse walks a patch for its late light, before
    /// `beam_table::late_walks_for` scales them (`BeamTableSettings::late_walks`; default the
    /// plugin's)
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=65536))]
    late_walks: Option<u32>,
    /// Also turn the spot this many frames by 0.75° each about the vertical through the
    /// objects (the `translucent` example's swing at 60 frames a second) and report on stderr
    /// each frame's products and distance from the converged exitance, warm-started from the
    /// last frame (`EnergyTransport::solve_from`, at most `WARM_MAX_ITERATIONS` products, as
    /// the plugin) against a cold start, at the plugin's defaults (1e-2, at most 16); then the
    /// same for a quarter turn at once, and after the plugin's settling frames
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u32).range(0..=1000))]
    warm_frames: u32,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum Kernel {
    Dipole,
    Burley,
    ScaledDipole,
}

fn main() {
    let cli: Cli = clap::Parser::parse();
    if !(cli.cutoff.is_finite() && cli.cutoff >= 0.0) {
        eprintln!("error: --cutoff must be a finite number ≥ 0");
        std::process::exit(2);
    }
    if !(0.0..=MAX_SHAPE_ENERGY_DROPPED).contains(&cli.shape_energy_dropped) {
        eprintln!("error: --shape-energy-dropped must be a number from 0 to {MAX_SHAPE_ENERGY_DROPPED}");
        std::process::exit(2);
    }
    let scene = translucent_scene::translucent_room(&meshes::asset_path("meshes/bunny.obj"));
    let views: Vec<PatchObject> = scene.iter().map(|o| o.view()).collect();
    let surfaces: Vec<_> = scene.iter().map(|o| o.surface).collect();
    let settings = TransportSettings {
        kernel: match cli.kernel {
            Kernel::Dipole => DiffusionKernel::Dipole,
            Kernel::Burley => DiffusionKernel::Burley,
            Kernel::ScaledDipole => DiffusionKernel::ScaledDipole,
        },
        form_factor_cutoff: cli.cutoff,
        shape_energy_dropped: cli.shape_energy_dropped,
        // Built and timed on its own below (`--beam-table`).
        beam_table: None,
        ..default()
    };
    // A spot from the front-left, aimed at the bunny (turned `angle` about the vertical).
    let spot = |angle: f32| {
        let position = Quat::from_rotation_y(angle) * Vec3::new(0.2, 0.45, 0.25);
        [PatchLight::Spot {
            position,
            direction: (Vec3::new(-0.03, 0.04, 0.0) - position).normalize(),
            intensity: Vec3::splat(800.0 / (4.0 * std::f32::consts::PI)),
            inner_angle: 0.3,
            outer_angle: 0.5,
            range: 10.0,
        }]
    };
    let lights = spot(0.0);
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let header = "patches,budget,precompute_s,memory_mb,form_factor_entries,scattering_entries,rays,\
dropped_form_factor_mean,dropped_form_factor_max,diffusion_kept_r,diffusion_kept_g,diffusion_kept_b,\
iterations,solve_ms,threads,shadow_ray_injection_ms";
    let mut lines = vec![header.to_string()];
    let mut measured: Vec<(f64, f64, f64)> = Vec::new();
    println!("{header}");
    for &budget in &cli.budgets {
        let start = Instant::now();
        // Translucent objects' patches capped as the plugin caps them.
        let caps: Vec<Option<f32>> = surfaces
            .iter()
            .map(|s| translucent_patch_cap(s, &settings))
            .collect();
        let patches = resample_into_patches_with_caps(&views, &caps, budget as usize);
        let rays = SceneRays::new(&views);
        let transport = EnergyTransport::build(&patches, &surfaces, &rays, &settings);
        let precompute = start.elapsed().as_secs_f32();
        let n = patches.patches.len();
        let per_object: Vec<String> = scene
            .iter()
            .enumerate()
            .map(|(o, object)| {
                let count = patches
                    .patches
                    .iter()
                    .filter(|p| p.object == o as u32)
                    .count();
                format!("{} {count}", object.name)
            })
            .collect();
        eprintln!("budget {budget}: {}", per_object.join(", "));
        // CSR as uploaded: offsets + columns (u32) and values (f32 for F, vec4 for K).
        let bytes = 4 * (2 * (n + 1))
            + 8 * transport.form_factors.entries()
            + 20 * transport.scattering.entries();
        if cli.beam_table {
            let (table, diffuse) = BeamTable::build_walked(
                &patches,
                &surfaces,
                &rays,
                &transport.scattering,
                BeamTableSettings {
                    walks: cli.walks.unwrap_or(BeamTableSettings::default().walks),
                    far_splits: cli.far_splits.unwrap_or(BeamTableSettings::default().far_splits),
                    max_last_order: cli.max_last_order.unwrap_or(BeamTableSettings::default().max_last_order),
                    late_walks: cli.late_walks.unwrap_or(BeamTableSettings::default().late_walks),
                    ..default()
                },
                None,
            );
            let entries = table.early.entries() + table.late.entries();
            eprintln!(
                "budget {budget}: beam table of {} translucent patches × {} directions: {} early \
                 and {} late entries ({:.1} MB as CSR), {:.2} s on {threads} threads",
                table.media.len(),
                table.bins(),
                table.early.entries(),
                table.late.entries(),
                (8 * (n + 1) + 16 * entries + 12 * table.late_share.len()) as f32 / 1e6,
                table.seconds,
            );
            // `K` as the plugin keeps it with the table: the tabled patches' columns walked.
            let walked_start = Instant::now();
            let walked = diffuse.scattering(&table, &transport.scattering);
            eprintln!(
                "budget {budget}: K's {} entries, with the tabled patches' columns walked {} \
                 (`BeamTableSettings::diffuse_columns_walked`, put in place in {:.2} s)",
                transport.scattering.entries(),
                walked.entries(),
                walked_start.elapsed().as_secs_f32(),
            );
        }
        let inject_start = Instant::now();
        let direct = direct_irradiance(&patches, &lights, &rays);
        let inject_ms = inject_start.elapsed().as_secs_f32() * 1e3;
        let solve_start = Instant::now();
        let solution = transport.solve(&direct, 1e-3, 200);
        let solve_ms = solve_start.elapsed().as_secs_f32() * 1e3;
        let r = &transport.report;
        let line = format!(
            "{n},{budget},{precompute:.3},{:.2},{},{},{},{:.4},{:.4},{:.4},{:.4},{:.4},{},{solve_ms:.2},{threads},{inject_ms:.2}",
            bytes as f32 / 1e6,
            r.form_factor_entries,
            r.scattering_entries,
            r.rays,
            r.dropped_form_factor_mean,
            r.dropped_form_factor_max,
            r.diffusion_kept_mean.x,
            r.diffusion_kept_mean.y,
            r.diffusion_kept_mean.z,
            solution.iterations,
        );
        println!("{line}");
        lines.push(line);
        if cli.warm_frames > 0 {
            warm_starts(&transport, &patches, &rays, &spot, cli.warm_frames, budget);
        }
        measured.push((n as f64, precompute as f64, bytes as f64 / 1e6));
    }
    if let Some(path) = &cli.chart {
        use plotters::prelude::*;
        let top_x = measured.iter().map(|m| m.0).fold(1.0, f64::max) * 1.05;
        chart::save(1200, 480, path, |root| {
            let panels = root.split_evenly((1, 2));
            for (panel, (title, pick)) in panels.iter().zip([
                ("precompute, s (2 CPU cores)", 1usize),
                ("memory of K and F, MB", 2usize),
            ]) {
                let value = |m: &(f64, f64, f64)| if pick == 1 { m.1 } else { m.2 };
                let top_y = measured.iter().map(value).fold(0.1, f64::max) * 1.1;
                let mut c = ChartBuilder::on(panel)
                    .caption(title, ("sans-serif", 18))
                    .margin(12)
                    .x_label_area_size(40)
                    .y_label_area_size(56)
                    .build_cartesian_2d(0.0..top_x, 0.0..top_y)
                    .expect("draw");
                c.configure_mesh()
                    .x_desc("patches (marble bunny, skin sphere, room)")
                    .label_style(("sans-serif", 13))
                    .draw()
                    .expect("draw");
                let points: Vec<(f64, f64)> = measured.iter().map(|m| (m.0, value(m))).collect();
                chart::line_with_points(&mut c, title, &points, BLUE.to_rgba());
            }
        });
        println!("wrote {}", path.display());
    }
    if let Some(out) = cli.out {
        let written = std::fs::File::create(&out)
            .and_then(|mut f| f.write_all((lines.join("\n") + "\n").as_bytes()));
        if let Err(e) = written {
            eprintln!("error: cannot write {}: {e}", out.display());
            std::process::exit(1);
        }
    }
}

/// `--warm-frames`: the spot turned 0.75° a frame, each frame solved warm from the last warm
/// solution and cold, both against the converged exitance (relative L1 of `B`).
fn warm_starts(
    transport: &EnergyTransport,
    patches: &Patches,
    rays: &SceneRays,
    spot: &dyn Fn(f32) -> [PatchLight; 1],
    frames: u32,
    budget: u32,
) {
    let defaults = TranslucencySettings::default();
    let (threshold, cap) = (defaults.iteration_threshold, defaults.max_iterations);
    let off = |b: &[Vec3], exact: &[Vec3]| {
        let difference: Vec<Vec3> = b.iter().zip(exact).map(|(x, y)| *x - *y).collect();
        transport.absolute_flux(&difference) / transport.flux(exact).max(1e-30)
    };
    /// A warm solve whose products are sized as the plugin sizes them on the GPU: read back
    /// from the last solve (`next_products`: one more than it took, the whole cap after a
    /// solve that took all it was given), or (`grow`) one more after such a solve instead.
    struct ReadBack {
        grow: bool,
        last: Option<TransportSolution>,
        asked: u32,
        recorded: u32,
        taken: u32,
        worst: f32,
    }
    let mut read_back = [false, true].map(|grow| ReadBack { grow, last: None, asked: cap, recorded: 0, taken: 0, worst: 0.0 });
    let mut last = None;
    let (mut warm, mut cold) = ((0u32, 0u32, 0.0f32), (0u32, 0u32, 0.0f32));
    for frame in 0..=frames {
        let irradiance = direct_irradiance(patches, &spot(frame as f32 * 0.013), rays);
        let direct = DirectLight { irradiance, ..default() };
        let exact = transport.solve_with(&direct, 1e-7, 1000);
        let from_cold = transport.solve_with(&direct, threshold, cap);
        // As the plugin: the first solve cold, the others warm and capped.
        let most = if last.is_some() { warm_iterations(cap) } else { cap };
        let from_last = transport.solve_from(&direct, threshold, most, last.as_ref());
        if frame > 0 {
            let tally = |(sum, most, worst): (u32, u32, f32), s: &TransportSolution| {
                (sum + s.iterations, most.max(s.iterations), worst.max(off(&s.exitance, &exact.exitance)))
            };
            warm = tally(warm, &from_last);
            cold = tally(cold, &from_cold);
        }
        last = Some(from_last);
        for r in &mut read_back {
            let recorded = if r.last.is_some() { r.asked.clamp(1, warm_iterations(cap)) } else { cap };
            let solved = transport.solve_from(&direct, threshold, recorded, r.last.as_ref());
            if frame > 0 {
                r.recorded += recorded;
                r.taken += solved.iterations;
                r.worst = r.worst.max(off(&solved.exitance, &exact.exitance));
            }
            r.asked = if r.grow && solved.iterations >= recorded {
                (recorded + 1).min(warm_iterations(cap))
            } else {
                bevy_mesostructure::translucency::iteration::next_products(warm_iterations(cap), recorded, solved.iterations)
            };
            r.last = Some(solved);
        }
    }
    eprintln!(
        "budget {budget}: {frames} frames of a spot turning 0.75° a frame: warm {:.1} products a frame \
         (at most {}), at worst {:.2e} from the converged B; cold {:.1} (at most {}), {:.2e}",
        warm.0 as f32 / frames as f32,
        warm.1,
        warm.2,
        cold.0 as f32 / frames as f32,
        cold.1,
        cold.2,
    );
    for r in &read_back {
        let name = if r.grow { "one more after a full solve" } else { "the cap after a full solve" };
        eprintln!(
            "budget {budget}: read back, {name}: {:.2} products recorded a frame, {:.2} taken, at worst {:.2e} from the converged B",
            r.recorded as f32 / frames as f32,
            r.taken as f32 / frames as f32,
            r.worst
        );
    }
    // And a jump: the spot a quarter turn on from the last frame.
    let irradiance = direct_irradiance(patches, &spot(frames as f32 * 0.013 + std::f32::consts::FRAC_PI_2), rays);
    let direct = DirectLight { irradiance, ..default() };
    let exact = transport.solve_with(&direct, 1e-7, 1000);
    let (jump_cold, jump_warm) = (
        transport.solve_with(&direct, threshold, cap),
        transport.solve_from(&direct, threshold, warm_iterations(cap), last.as_ref()),
    );
    // Then the light stays: the plugin's settling frames, each warm from the last.
    let mut settled = jump_warm.clone();
    let mut settle_products = 0;
    for _ in 0..settle_frames(cap) {
        settled = transport.solve_from(&direct, threshold, warm_iterations(cap), Some(&settled));
        settle_products += settled.iterations;
    }
    eprintln!(
        "budget {budget}: a quarter turn at once: warm {} products, {:.2e} from the converged B, \
         and after {} settling frames ({settle_products} products) {:.2e}; cold {}, {:.2e}",
        jump_warm.iterations,
        off(&jump_warm.exitance, &exact.exitance),
        settle_frames(cap),
        off(&settled.exitance, &exact.exitance),
        jump_cold.iterations,
        off(&jump_cold.exitance, &exact.exitance),
    );
}
