//! Accuracy of the translucency transport against a path tracer: a ball of one of Jensen's
//! media (radius 1 cm, an index-matched boundary so that the picture is the light diffused
//! out of the medium alone) lit by one directional light, seen from 4 cm, or (`--shape
//! bunny`) the Stanford bunny 4 cm long — thin ears, creases, flat flanks — seen from above
//! and aside, against Mitsuba rendering the very same triangles. The plugin's picture
//! is computed on the CPU with the same patches, transport, iteration and gather as the GPU
//! passes (`translucency::gather::gathered_radiance`, the oracle the GPU tests hold the passes
//! to: within 0.24/255 mean of it); the reference is a light tracer of the same scene
//! (converged lit from any side, no fireflies: the ball's sphere by
//! `tools/translucent_light_tracer.py`, numpy; a mesh's triangles — the bunny, the torus, the
//! ball with `--pixels-on-mesh` — by `common/translucent_light_tracer.rs`, in this process) or
//! Mitsuba 3's volumetric path tracing (`tools/translucent_reference.py`; they agree to
//! 0.2 % in the mean where Mitsuba converges, `docs/translucent.md`); the example runs the
//! Python ones where `python3` has `numpy` and `mitsuba`, or reads one with `--reference`.
//!
//! ```text
//! cargo run --example translucent_accuracy -- [--shape ball|bunny|torus] [--medium skin1]
//!     [--budgets 250,500,1000,2000]
//!     [--kernel scaled-dipole|burley|dipole] [--gather interpolation|photons]
//!     [--object-exit-share true|false] [--beam-incidence true|false]
//!     [--oriented-dipole true|false] [--shape-diffusion true|false]
//!     [--deep-exit-law true|false] [--scattering profile|walks|beam-walks|beam-table] [--walks N]
//!     [--beam-table COSINES,AZIMUTHS] [--single-scattering-oracle]
//!     [--beam-orders FIRST,LAST] [--late-light profile|profile-less-early|clamped]
//!     [--late-walks N] [--lit-face-single-scattering-law]
//!     [--marched-single-scattering | --translucent-shadow-map N | --single-scattering-in-table]
//!     [--exit-axis plugin|normal|normal-all|flow-all|lobe] [--exit-lobes true|false]
//!     [--point-light DISTANCE] [--pixels-on-mesh]
//!     [--bounces N] [--exact-exitance PHOTONS [--exact-exitance-gathered true|false]
//!      [--exact-exitance-after N] [--exact-exitance-reentering all|scattered|none]
//!      [--exact-exitance-bounced]]
//!     [--size 96] [--tracer light|mitsuba] [--spp 1024] [--photons 40000000]
//!     [--tracer-seed 1] [--light-traced-part all|single|lambertian-exit|first-exit|no-uncollided-reentry]
//!     [--reference FILE.exr]
//!     [--out docs/translucent.csv]
//! ```
//!
//! CSV header (issue 13): `scene,method,setting,patches,width,height,gpu_ms,precompute_s,
//! memory_mb,rel_l1,flip,adapter` — `gpu_ms` is empty (not measured here), `rel_l1` is
//! Σ|plugin − reference| / Σ reference over the ball's pixels (the silhouette's rim left out),
//! all channels; `flip` is NVIDIA FLIP's mean on both pictures scaled by the reference's
//! brightest pixel.
//!
//! Each picture is written to `out/translucent_accuracy/plugin_….exr` (linear), with the
//! pixels the score counts beside it (`….scored.png`, white), for a look at where the error
//! lies.

// Only `save`, `line_with_points` and `legend_at` are used here.
#[allow(dead_code)]
#[path = "common/chart.rs"]
mod chart;
#[path = "common/headless.rs"]
mod headless;

// Only `read_obj`, `obj_mesh` and `asset_path` are used here.
#[allow(dead_code)]
#[path = "common/meshes.rs"]
mod meshes;
#[path = "common/translucent_accuracy_chart.rs"]
mod translucent_accuracy_chart;
#[path = "common/translucent_accuracy_cli.rs"]
mod translucent_accuracy_cli;
#[path = "common/translucent_accuracy_scene.rs"]
mod translucent_accuracy_scene;
#[path = "common/translucent_bevy_fit.rs"]
mod translucent_bevy_fit;
#[path = "common/translucent_light_tracer.rs"]
mod translucent_light_tracer;

use std::{
    io::Write,
    path::PathBuf,
    process::Command,
    time::Instant,
};

use bevy::prelude::*;
use bevy_mesostructure::translucency::{
    DiffusionKernel, GatherMethod, TranslucentMedium, TranslucentPreset, TransportSettings, beam_table::{BeamTableSettings, LATE_WALKS_ORDER},
    patches::Patches, random_walk::ScatteringOrders, translucent_shadow_map::{PLUGIN_DEPTHS, PLUGIN_RESOLUTION},
};
use translucent_light_tracer::{Part, Pinhole, Reentering, Source, light_trace, patch_exitance};
use translucent_accuracy_cli::{Axis, Cli, Gather, Kernel, Late, Medium, Scattering, ShapeArg, Tracer, check_combinations, fail};
use translucent_accuracy_scene::{
    ExactExitance, ExitAxis, FOV_Y, FRONT_LIGHT, Floor, LateLight, Occluder, Oracles, PatchExitanceOracle, RADIUS, ScatteringSource, SceneLighting, Shape,
    ShapeView, plugin_picture, score,
};

fn main() {
    let cli: Cli = clap::Parser::parse();
    let preset = match cli.medium {
        Medium::Skin1 => TranslucentPreset::Skin1,
        Medium::Skin2 => TranslucentPreset::Skin2,
        Medium::Marble => TranslucentPreset::Marble,
        Medium::Ketchup => TranslucentPreset::Ketchup,
        Medium::Apple => TranslucentPreset::Apple,
    };
    // Index-matched by default: no Fresnel at the boundary, in either renderer.
    let medium = TranslucentMedium {
        index_of_refraction: cli.eta,
        ..preset.medium()
    };
    let shape = match cli.shape {
        ShapeArg::Ball => Shape::Ball,
        ShapeArg::Bunny => Shape::Bunny,
        ShapeArg::Torus => Shape::Torus,
    };
    check_combinations(&cli, shape);
    let light = cli.light.unwrap_or(FRONT_LIGHT.normalize());
    let eta_suffix = if cli.eta != 1.0 { format!("_eta{}", cli.eta) } else { String::new() };
    let lighting = if cli.uniform {
        format!("uniform{eta_suffix}")
    } else if light.z > 0.3 {
        format!("back{eta_suffix}")
    } else {
        format!("front{eta_suffix}")
    } + &cli.point_light.map_or(String::new(), |d| format!("_point{d}"))
        + &cli.floor.map_or(String::new(), |a| format!("_floor{}", cli.floor_albedo_in_reference.unwrap_or(a)))
        + if cli.occluder { "_occluded" } else { "" };
    let name = format!("{:?}", cli.medium).to_lowercase();
    let size = cli.size;
    let mut view = if cli.pixels_on_mesh { ShapeView::on_mesh(shape, size) } else { ShapeView::new(shape, size) };
    let occluder = cli.occluder.then(|| Occluder::shading(&view.positions, light));
    if let Some(plate) = occluder {
        // Pixels the plate hides from the camera are not scored.
        let eye = shape.eye();
        for (scored, hit) in view.scored.iter_mut().zip(&view.hits) {
            if let Some(hit) = hit {
                let to = hit.point - eye;
                if plate.hit(eye, to.normalize()).is_some_and(|t| t < to.length()) {
                    *scored = false;
                }
            }
        }
    }
    let view = view;
    let reference = reference_picture(&cli, shape, &view, medium, light, &lighting, &name);

    let (settings, gather, method, oracles) = method_of(&cli, shape);
    // A floor the plugin leaves black under the reference's grey one: what the bounce is worth.
    let method = if cli.floor == Some(0.0) { method + "_floorblack" } else { method };
    // Only where the exact exitance is what the picture gathers (else it is only compared).
    let method = match cli.exact_exitance {
        Some(photons) if cli.exact_exitance_gathered => format!(
            "{method}_exactexitance{photons}{}",
            if cli.exact_exitance_after > 0 { format!("after{}", cli.exact_exitance_after) } else { String::new() }
                + cli.exact_exitance_reentering.suffix()
        ),
        _ => method,
    };
    let header = "scene,method,setting,patches,width,height,gpu_ms,precompute_s,memory_mb,rel_l1,flip,adapter";
    let mut rows = Vec::new();
    // The plugin's pixels at `pixel_samples`² points a pixel: the centres of a finer view's.
    let points = cli.pixel_samples;
    let fine = (points > 1).then(|| {
        if cli.pixels_on_mesh { ShapeView::on_mesh(shape, size * points) } else { ShapeView::new(shape, size * points) }
    });
    let (cli_ref, view_ref) = (&cli, &view);
    let exact = cli.exact_exitance.map(|photons| {
        move |patches: &Patches| {
            exact_patch_exitance(cli_ref, view_ref, medium, light, patches, photons, cli_ref.exact_exitance_reentering)
        }
    });
    // `--exact-exitance-bounced`: the same tally without the light that came back in, for the
    // plugin's bounce to bounce.
    let unreturned = cli.exact_exitance.filter(|_| cli.exact_exitance_bounced).map(|photons| {
        move |patches: &Patches| exact_patch_exitance(cli_ref, view_ref, medium, light, patches, photons, Reentering::None)
    });
    for &budget in &cli.budgets {
        let mut result = plugin_picture(
            fine.as_ref().unwrap_or(&view),
            medium,
            cli.oriented_dipole,
            &settings,
            gather,
            budget,
            match cli.point_light {
                _ if cli.uniform => SceneLighting::Uniform,
                Some(distance) => SceneLighting::Point(-light.normalize() * distance),
                None => SceneLighting::Directional(light),
            },
            oracles,
            cli.floor,
            occluder,
            exact.as_ref().map(|f| ExactExitance {
                trace: f,
                gathered: cli.exact_exitance_gathered,
                without_single_scattering: cli.exact_exitance_after >= 1,
                bounced_source: unreturned.as_ref().map(|f| f as PatchExitanceOracle),
            }),
        );
        if points > 1 {
            result.pixels = box_filtered(&result.pixels, size, points);
        }
        let picture = &result.pixels;
        let scores = score(picture, &reference, &view);
        let rel_l1 = scores.rel_l1;
        // Over the whole picture: with a floor the reference draws it and the harness does
        // not, so FLIP is left out there.
        let flip = (cli.floor.is_none()).then(|| flip_mean(picture, &reference, size));
        let flip_text = flip.map_or(String::new(), |f| format!("{f:.4}"));
        let n = result.patches;
        let bytes = result.memory_bytes;
        let precompute = result.precompute_s;
        if result.object_patches != n {
            eprintln!("  {} of the {n} patches on the object", result.object_patches);
        }
        eprintln!(
            "{name} {budget}: {n} patches, rel L1 {rel_l1:.4}, FLIP {}, mean ratio r {:.3} g {:.3} b {:.3}, {} iterations",
            if flip_text.is_empty() { "-" } else { &flip_text },
            scores.ratio[0], scores.ratio[1], scores.ratio[2], result.iterations
        );
        rows.push(format!(
            "{}_{name}_{}_{lighting},{method},{budget},{n},{size},{size},,{precompute:.3},{:.3},{rel_l1:.4},{flip_text},cpu oracle of the GPU passes",
            shape.scene_name(),
            shape.size_name(),
            bytes as f32 / 1e6
        ));
        let path = PathBuf::from("out/translucent_accuracy")
            .join(picture_file_name(&format!("plugin_{}_{name}_{lighting}_{method}_{budget}", shape.scene_name())));
        save_picture(&path, picture, &view);
    }
    if cli.bevy {
        let (best, transmission, thickness, colour) =
            translucent_bevy_fit::bevy_best_fit(&reference, &view, light).unwrap_or_else(|e| fail(e));
        eprintln!(
            "{name} Bevy diffuse_transmission best fit: rel L1 {best:.4} at transmission {transmission}, thickness {thickness} m, base colour {colour:?}"
        );
        rows.push(format!(
            "{}_{name}_{}_{lighting},bevy_diffuse_transmission{},transmission {transmission} thickness {thickness} base {:.3} {:.3} {:.3},,{size},{size},,,,{best:.4},,Bevy 0.19.1 on the software driver, best of a grid",
            shape.scene_name(),
            shape.size_name(),
            // Scored on the ball's triangles, against their own reference: not the sphere's rows.
            if cli.pixels_on_mesh && shape == Shape::Ball { "_onmesh" } else { "" },
            colour[0], colour[1], colour[2]
        ));
    }
    println!("{header}");
    for row in &rows {
        println!("{row}");
    }
    if let Some(out) = cli.out {
        append_rows(&out, header, &rows);
        if let Some(path) = &cli.chart {
            translucent_accuracy_chart::draw_chart(&out, path).unwrap_or_else(|e| fail(e));
        }
    }
}

/// A `size`² picture from one of `size · points` a side: each pixel the mean of its
/// `points`² (a box filter, as the references' film).
fn box_filtered(fine: &[Vec3], size: u32, points: u32) -> Vec<Vec3> {
    let side = size * points;
    (0..size * size)
        .map(|i| {
            let (x, y) = (i % size, i / size);
            let sum: Vec3 = (0..points * points)
                .map(|k| fine[((y * points + k / points) * side + x * points + k % points) as usize])
                .sum();
            sum / (points * points) as f32
        })
        .collect()
}

/// The reference `cli` names, or else the path tracer's picture of the scene, rendered into
/// `out/translucent_accuracy/` once and read back from there (one line and exit where it
/// cannot be).
fn reference_picture(
    cli: &Cli,
    shape: Shape,
    view: &ShapeView,
    medium: TranslucentMedium,
    light: Vec3,
    lighting: &str,
    name: &str,
) -> image::Rgb32FImage {
    let size = cli.size;
    let reference_path = cli.reference.clone().unwrap_or_else(|| {
        let dir = PathBuf::from("out/translucent_accuracy");
        std::fs::create_dir_all(&dir).unwrap_or_else(|e| fail(format!("cannot create {}: {e}", dir.display())));
        // The light tracer takes a directional or a point light: a uniform environment is
        // Mitsuba's, and so are a floor and an occluder. The ball's (the sphere) is
        // tools/translucent_light_tracer.py's, with a dielectric boundary if asked; a mesh's
        // is translucent_light_tracer.rs's, index-matched.
        let on_sphere = shape == Shape::Ball && !cli.pixels_on_mesh;
        let light_traced = cli.tracer == Tracer::Light && !cli.uniform && cli.floor.is_none() && !cli.occluder;
        // The light's direction in the name where it is not the default.
        let light_suffix =
            if cli.light.is_some() && !cli.uniform { format!("_{:.3}_{:.3}_{:.3}", light.x, light.y, light.z) } else { String::new() };
        if light_traced && !on_sphere {
            return light_traced_mesh(cli, shape, view, medium, light, &light_suffix, lighting, name, &dir);
        }
        // Named by renderer and version: the first Mitsuba references (in metres, `volpath`)
        // were dark by Mitsuba's ray offsets (tools/translucent_reference.py says why).
        let (tool, renderer, samples) = if light_traced {
            ("tools/translucent_light_tracer.py", "lighttraced", format!("--photons={}", cli.photons))
        } else {
            ("tools/translucent_reference.py", "volpathmis-mm", format!("--spp={}", cli.spp))
        };
        let path = dir.join(format!(
            "reference_{renderer}_{}{name}_{size}_{}{}{}.exr",
            match shape {
                Shape::Ball if on_sphere => String::new(),
                Shape::Ball => "ballmesh_".into(),
                _ => format!("{}_", shape.scene_name()),
            },
            samples.trim_start_matches("--spp=").trim_start_matches("--photons="),
            light_suffix,
            if cli.uniform || cli.eta != 1.0 || cli.point_light.is_some() || cli.floor.is_some() || cli.occluder {
                format!("_{lighting}")
            } else {
                String::new()
            },
        ));
        if !path.exists() {
            let list = |v: Vec3| format!("{},{},{}", v.x, v.y, v.z);
            // The ball is Mitsuba's own sphere; another shape (or the ball with its pixels on
            // its triangles), the very triangles the plugin's patches come from.
            let object = match shape {
                Shape::Ball if on_sphere => format!("--radius={RADIUS}"),
                _ => {
                    let obj = dir.join(format!("{}_{}.obj", shape.scene_name(), shape.size_name()));
                    write_obj(&obj, view).unwrap_or_else(|e| fail(format!("cannot write {}: {e}", obj.display())));
                    format!("--mesh={}", obj.display())
                }
            };
            let mut command = Command::new("python3");
            command.args([
                tool,
                &format!("--sigma-a={}", list(medium.absorption)),
                &format!("--sigma-s={}", list(medium.reduced_scattering)),
                &object,
                &format!("--eye={}", list(shape.eye())),
                &format!("--light={}", list(light)),
                &format!("--fov={}", FOV_Y.to_degrees()),
                &format!("--size={size}"),
                &format!("--eta={}", cli.eta),
                &samples,
                &format!("--out={}", path.display()),
            ]);
            if cli.uniform {
                command.arg("--uniform");
            }
            if let Some(distance) = cli.point_light {
                command.arg(format!("--point-light={distance}"));
            }
            if let Some(albedo) = cli.floor {
                let floor = Floor::under(&view.positions);
                let c = floor.centre;
                let albedo = cli.floor_albedo_in_reference.unwrap_or(albedo);
                command.arg(format!("--floor={},{},{},{},{albedo}", c.x, c.y, c.z, floor.half));
            }
            if cli.occluder {
                let Occluder { centre: c, u, v } = Occluder::shading(&view.positions, light);
                command.arg(format!("--occluder={},{},{},{},{},{},{},{},{}", c.x, c.y, c.z, u.x, u.y, u.z, v.x, v.y, v.z));
            }
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
        fail(format!(
            "{} is {}×{}, not {size}×{size}",
            reference_path.display(),
            reference.width(),
            reference.height()
        ));
    }

    reference
}

/// The plugin's variant `cli` asks for: its transport settings, gather, the CSV's method name
/// (each option off its default a suffix) and the oracles standing in for its stages.
fn method_of(cli: &Cli, shape: Shape) -> (TransportSettings, GatherMethod, String, Oracles) {
    let settings = TransportSettings {
        kernel: match cli.kernel {
            Kernel::Dipole => DiffusionKernel::Dipole,
            Kernel::Burley => DiffusionKernel::Burley,
            Kernel::ScaledDipole => DiffusionKernel::ScaledDipole,
        },
        object_exit_share: cli.object_exit_share,
        beam_incidence: cli.beam_incidence,
        shape_diffusion: cli.shape_diffusion,
        deep_exit_law: cli.deep_exit_law,
        exit_lobes: cli.exit_lobes,
        flow_law_takes_all: cli.flow_law_takes_all,
        tangential_flux: cli.tangential_flux,
        diffusion_energy_kept: cli.energy_kept,
        shape_energy_dropped: cli.shape_energy_dropped,
        ..default()
    };
    let (gather, gather_name) = match cli.gather {
        Gather::Interpolation => (GatherMethod::Interpolation, ""),
        Gather::Photons => (GatherMethod::PhotonDensity, "_photons"),
    };
    let slab = if cli.object_exit_share { "" } else { "_slab" };
    let diffuse = if cli.beam_incidence { "" } else { "_diffuse" };
    let oriented = if cli.oriented_dipole { "_oriented" } else { "" };
    let flat = if cli.shape_diffusion { "" } else { "_flat" };
    let lambert = if cli.deep_exit_law { "" } else { "_lambert" };
    let kept = if cli.energy_kept == TransportSettings::default().diffusion_energy_kept {
        String::new()
    } else {
        format!("_kept{}", cli.energy_kept)
    };
    let kept = if cli.shape_energy_dropped == TransportSettings::default().shape_energy_dropped {
        kept
    } else {
        format!("{kept}_shapedropped{}", cli.shape_energy_dropped)
    };
    // The oracles' walks (256 and 1024 unless given); the table's default to the plugin's.
    let (walks, late_walks) = (cli.walks.unwrap_or(256), cli.late_walks.unwrap_or(1024));
    let (source, walked) = match cli.scattering {
        Scattering::Profile => (ScatteringSource::Profile, String::new()),
        Scattering::Walks => (ScatteringSource::Walks(walks), format!("_walks{walks}")),
        Scattering::BeamTable => {
            let (cosines, azimuths) = cli.beam_table.unwrap_or((4, 8));
            let table = BeamTableSettings {
                cosines,
                azimuths,
                walks: cli.walks.unwrap_or(BeamTableSettings::default().walks),
                late_walks: cli.late_walks.unwrap_or(BeamTableSettings::default().late_walks),
                far_splits: cli.far_splits.unwrap_or(BeamTableSettings::default().far_splits),
                last_order: cli.beam_orders.map_or(BeamTableSettings::default().last_order, |(_, last)| last),
                max_last_order: cli.max_last_order.unwrap_or(BeamTableSettings::default().max_last_order),
                exit_directions: cli.exit_axis == Axis::Lobe,
                single_scattering_to_pixels: !cli.single_scattering_in_table,
                diffuse_columns_walked: cli.diffuse_columns_walked,
                seed: cli.table_seed,
                ..default()
            };
            (
                ScatteringSource::BeamTable(table),
                format!(
                    // `_pastterminator`: single scattering out past the terminator kept in
                    // the table (`law_gives_single_scattering`; rows before it lack it);
                    // `_lateheld`: the late light held to the light still inside (rows
                    // before it lack it).
                    "_beamtable{cosines}x{azimuths}_bilinear_pastterminator_lateheld_walks{}{}_late{}_orders{}{}{}{}",
                    table.walks,
                    if table.far_splits > 1 { format!("_far{}", table.far_splits) } else { String::new() },
                    table.late_walks,
                    table.last_order,
                    // `upto<most>`: walks in a barely absorbing medium go on past the last
                    // order (`BeamTableSettings::max_last_order`; rows before it lack it);
                    // `_lateperorder`: their late walks times `order/32` (`late_walks_for`;
                    // rows before 2026-12-07 lack it: `late6144` there is `late3072` here).
                    if table.max_last_order > table.last_order {
                        let per_order = if table.max_last_order > LATE_WALKS_ORDER { "_lateperorder" } else { "" };
                        format!("upto{}{per_order}", table.max_last_order)
                    } else {
                        String::new()
                    },
                    if table.seed == 0 { String::new() } else { format!("_seed{}", table.seed) },
                    match (table.single_scattering_to_pixels, cli.marched_single_scattering) {
                        (false, _) => String::new(),
                        (true, true) => "_ssmarched".into(),
                        // `_d<depths>`: the plugin's depths a channel (rows without it: 64);
                        // `_tangentbound`: the path under a lit surface at most its tangent
                        // plane's (`LightMaps::half_space_bound`; rows before it lack it);
                        // `_fitted`: each map fitted to its object's extent
                        // (`MapFrame::fitted_to`; rows before it took the bounding sphere).
                        (true, false) => format!(
                            "_ssmarched_tsm{}_d{PLUGIN_DEPTHS}_tangentbound_fitted",
                            cli.translucent_shadow_map.unwrap_or(PLUGIN_RESOLUTION)
                        ),
                    }
                ),
            )
        }
        Scattering::BeamWalks => match cli.beam_table {
            None => (ScatteringSource::BeamWalks(walks), format!("_beamwalks{walks}")),
            Some((cosines, azimuths)) => (
                ScatteringSource::BinnedBeamWalks {
                    walks,
                    cosines,
                    azimuths,
                    orders: cli.beam_orders.map_or(
                        ScatteringOrders { first: 1, last: u32::MAX },
                        |(first, last)| ScatteringOrders { first, last },
                    ),
                    late: match cli.late_light {
                        Late::Profile => LateLight::Profile,
                        Late::ProfileLessEarly => LateLight::ProfileLessEarly,
                        Late::Clamped => LateLight::ProfileLessEarlyClamped,
                    },
                    late_walks,
                    lit_face_single_to_law: cli.lit_face_single_scattering_law,
                },
                format!(
                    "_beamwalks{}_table{cosines}x{azimuths}{}",
                    walks,
                    cli.beam_orders.map_or(String::new(), |(f, l)| format!(
                        "_orders{f}to{l}{}_late{}",
                        if cli.lit_face_single_scattering_law { "_litfacelaw" } else { "" },
                        match cli.late_light {
                            Late::Profile => "profile".to_string(),
                            Late::ProfileLessEarly => format!("lessearly{late_walks}"),
                            Late::Clamped => format!("clamped{late_walks}"),
                        }
                    ))
                ),
            ),
        },
    };
    let ss_oracle = if cli.single_scattering_oracle { "_ssoracle" } else { "" };
    let table = cli.scattering == Scattering::BeamTable;
    let (exit_axis, exit_name) = match cli.exit_axis {
        Axis::Plugin => (ExitAxis::Plugin, match (table, cli.exit_lobes) {
            // `_raysback`: every ray started `rays::MIN_BACK_OFF` behind its origin (rows
            // before it lack it: their walks slipped out on flights under 0.1 mm);
            // `_latepermfp`: the late walks scaled by `(ℓ/h)²`, the patches in a square mean free path
            // (`beam_table::late_walks_for`; `late3072` is then the least a patch takes).
            (true, true) => "_exitlean_afar2mfp_raysback_latepermfp",
            (true, false) => "_exitflow",
            (false, _) => "",
        }),
        Axis::Normal => (ExitAxis::Normal, ""),
        Axis::NormalAll => (ExitAxis::NormalAll, "_exitnormalall"),
        Axis::FlowAll => (ExitAxis::FlowAll, "_exitflowall"),
        Axis::Lobe => (ExitAxis::Lobe, "_exitlobe"),
    };
    let flow_all = if table && cli.flow_law_takes_all && cli.exit_axis == Axis::Plugin { "_flowall" } else { "" };
    // `_centroid`: objects above 2048 patches solved on clusters collocated at their
    // area-weighted centres (before: at the member nearest it; the same below 2048), whatever
    // the exit law.
    let centroid = if table && cli.exit_axis == Axis::Plugin { "_centroid" } else { "" };
    // `_bouncedown`: the exit law takes a patch's bounced light as its own, as its direct
    // light (rows before it, and `--bounced-as-own false`, gave it out as light from elsewhere).
    let bounced = if cli.bounced_as_own { "_bouncedown" } else { "" };
    // `_litbounced`: the lit faces' single scattering (given per pixel) lights the other
    // patches through the first bounce (`DirectLight::lit_face_exitance`; rows before it
    // lacked that light), with the beam table.
    let lit_bounced = if table { "_litbounced" } else { "" };
    // `_projected`: a beam's walks enter by projected area, none lost at a sample facing away
    // (rows before it lost them where a patch curves away from the light).
    let projected = if table || cli.scattering == Scattering::BeamWalks { "_projected" } else { "" };
    // `_tangential`: the light leans down the exitance's gradient along the surface
    // (`--tangential-flux true`), with the table, the deep law and the interpolating gather.
    let tangential = if table && cli.tangential_flux && cli.deep_exit_law && matches!(cli.gather, Gather::Interpolation) {
        "_tangential"
    } else {
        ""
    };
    // `_gaussself`: the shape solve's self term from Gauss's identity on a closed object
    // (`shape_diffusion::boundary_correction`; rows before it took the curvature's `−ρH/4`).
    let gauss_self = if cli.shape_diffusion { "_gaussself" } else { "" };
    // `_diffusewalked`: diffuse light entering a tabled patch leaves by its late light's
    // diffuse walks (`--diffuse-columns-walked true`; rows before 2026-12-08 took `K`).
    let diffuse_walked = if table && cli.diffuse_columns_walked { "_diffusewalked" } else { "" };
    let bounces = cli.bounces.map_or(String::new(), |n| format!("_bounces{n}"));
    let method = format!(
        "patches_{:?}{gather_name}{slab}{diffuse}{oriented}{flat}{lambert}{kept}{walked}{ss_oracle}{exit_name}{flow_all}{centroid}{bounced}{lit_bounced}{projected}{tangential}{gauss_self}{diffuse_walked}{bounces}{}{}",
        cli.kernel,
        if cli.pixels_on_mesh && shape == Shape::Ball { "_onmesh" } else { "" },
        if cli.pixel_samples > 1 { format!("_px{}", cli.pixel_samples) } else { String::new() }
    )
    .to_lowercase();
    let oracles = Oracles {
        scattering: source,
        single_scattering_law: cli.single_scattering_oracle,
        exit_axis,
        shadow_map: if cli.marched_single_scattering { None } else { Some(cli.translucent_shadow_map.unwrap_or(PLUGIN_RESOLUTION)) },
        bounced_as_own: cli.bounced_as_own,
        bounces: cli.bounces,
    };
    (settings, gather, method, oracles)
}

/// NVIDIA FLIP's mean on `picture` against `reference` (both `size`², linear), both scaled by
/// the reference's brightest pixel and sRGB-encoded to 8 bits.
fn flip_mean(picture: &[Vec3], reference: &image::Rgb32FImage, size: u32) -> f32 {
    // FLIP on both scaled by the reference's brightest pixel (sRGB-encoded, 8 bits).
    let peak = reference
        .pixels()
        .flat_map(|p| p.0)
        .fold(0.0f32, f32::max)
        .max(1e-9);
    let encode = |value: &dyn Fn(u32, u32) -> [f32; 3]| -> Vec<u8> {
        (0..size * size)
            .flat_map(|i| value(i % size, i / size))
            .map(|v| {
                let c = (v / peak).clamp(0.0, 1.0);
                let s = if c <= 0.003_130_8 {
                    12.92 * c
                } else {
                    1.055 * c.powf(1.0 / 2.4) - 0.055
                };
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
    nv_flip::FlipPool::from_image(&flip_image).mean()
}

/// Appends `rows` to the CSV at `out`, `header` first if the file is new (one line and exit
/// where it cannot).
fn append_rows(out: &std::path::Path, header: &str, rows: &[String]) {
    let new = !out.exists();
    let written = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&out)
        .and_then(|mut f| {
            if new {
                writeln!(f, "{header}")?;
            }
            for row in rows {
                writeln!(f, "{row}")?;
            }
            Ok(())
        });
    if let Err(e) = written {
        fail(format!("cannot write {}: {e}", out.display()));
    }
}

/// The mesh light tracer's reference of `view`'s triangles (`translucent_light_tracer.rs`),
/// rendered into `dir` once and read back from there; index-matched only (one line and exit
/// otherwise).
#[allow(clippy::too_many_arguments)]
fn light_traced_mesh(
    cli: &Cli,
    shape: Shape,
    view: &ShapeView,
    medium: TranslucentMedium,
    light: Vec3,
    light_suffix: &str,
    lighting: &str,
    name: &str,
    dir: &std::path::Path,
) -> PathBuf {
    if cli.eta != 1.0 {
        fail("the mesh light tracer is index-matched: --eta above 1 takes the ball's sphere (drop --pixels-on-mesh)".into());
    }
    let size = cli.size;
    let path = dir.join(format!(
        "reference_lighttraced-mesh{}_{}_{name}_{size}_{}_seed{}{light_suffix}{}.exr",
        match cli.light_traced_part {
            Part::All => "",
            Part::Single => "-single",
            Part::LambertianExit => "-lambertianexit",
            Part::FirstExit => "-firstexit",
            Part::NoUncollidedReentry => "-nouncollidedreentry",
        },
        if shape == Shape::Ball { "ballmesh" } else { shape.scene_name() },
        cli.photons,
        cli.tracer_seed,
        if cli.point_light.is_some() { format!("_{lighting}") } else { String::new() },
    ));
    if path.exists() {
        return path;
    }
    let source = match cli.point_light {
        Some(distance) => Source::Point(-light.normalize() * distance),
        None => Source::Directional(light),
    };
    let camera = Pinhole { eye: shape.eye(), fov_y: FOV_Y, size };
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let start = Instant::now();
    let traced = light_trace(&view.positions, &view.indices, &medium, source, cli.light_traced_part, camera, cli.photons as usize, cli.tracer_seed, threads, None);
    let picture = image::Rgb32FImage::from_fn(size, size, |x, y| image::Rgb(traced.pixels[(y * size + x) as usize]));
    picture.save(&path).unwrap_or_else(|e| fail(format!("cannot write {}: {e}", path.display())));
    eprintln!(
        "light-traced the reference in {:.0} s: {} photons a channel, noise {:.4}, {} of {} crossings on the side the faces do not say",
        start.elapsed().as_secs_f32(),
        cli.photons,
        traced.noise,
        traced.side_disagreements,
        traced.crossings
    );
    path
}

/// An oracle's exitance of each of the object's patches (the rest zero): the mesh light
/// tracer's exits after a scattering or more, each on the patch of the sample nearest it
/// (facing its way), over the patch's area; per unit irradiance, as the plugin's.
fn exact_patch_exitance(
    cli: &Cli,
    view: &ShapeView,
    medium: TranslucentMedium,
    light: Vec3,
    patches: &Patches,
    photons: u64,
    reentering: Reentering,
) -> Vec<Vec3> {
    // Traced once per scene, patches and photons: other laws and gathers take it again
    // (delete the file to trace it again after a change to the tracer).
    let cache = PathBuf::from("out/translucent_accuracy").join(format!(
        "exact_exitance_{}_{:?}_{}_{}_{:.3}_{:.3}_{:.3}_{photons}_seed{}_after{}{}{}.bin",
        view.shape.scene_name(),
        cli.medium,
        cli.size,
        patches.patches.len(),
        light.x,
        light.y,
        light.z,
        cli.tracer_seed,
        cli.exact_exitance_after,
        if reentering == Reentering::All { "" } else { "_" },
        reentering.suffix()
    ));
    if let Ok(bytes) = std::fs::read(&cache)
        && bytes.len() == patches.patches.len() * 12
    {
        let values: Vec<f32> = bytes.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
        return values.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2])).collect();
    }
    let camera = Pinhole { eye: view.shape.eye(), fov_y: FOV_Y, size: cli.size };
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let start = Instant::now();
    let (exitance, unbinned) =
        patch_exitance(&view.positions, &view.indices, &medium, light, patches, camera, photons as usize, cli.tracer_seed, threads, cli.exact_exitance_after, reentering);
    eprintln!(
        "  exact exitance: {photons} photons a channel in {:.0} s; {:.1e} / {:.1e} / {:.1e} of the exits on no patch",
        start.elapsed().as_secs_f32(),
        unbinned.x,
        unbinned.y,
        unbinned.z
    );
    let bytes: Vec<u8> = exitance.iter().flat_map(|e| e.to_array()).flat_map(f32::to_le_bytes).collect();
    if let Err(e) = cache.parent().map_or(Ok(()), std::fs::create_dir_all).and_then(|_| std::fs::write(&cache, bytes)) {
        eprintln!("warning: cannot write {}: {e}", cache.display());
    }
    exitance
}

/// `stem.exr`, or where `stem.scored.png` would pass a file system's 255 bytes a name, its
/// first 200 bytes and a hash of the whole (the methods' names grow with their options).
fn picture_file_name(stem: &str) -> String {
    use std::hash::{Hash, Hasher};
    if stem.len() + ".scored.png".len() <= 255 {
        return format!("{stem}.exr");
    }
    let mut hasher = std::collections::hash_map::DefaultHasher::new();
    stem.hash(&mut hasher);
    let cut = (0..=200).rev().find(|&i| stem.is_char_boundary(i)).unwrap_or(0);
    format!("{}_{:016x}.exr", &stem[..cut], hasher.finish())
}

/// Writes `picture` for a look (linear EXR) at `path`, and beside it (`….scored.png`) the
/// pixels the score counts (white): where the error lies. A picture not written is a warning.
fn save_picture(path: &std::path::Path, picture: &[Vec3], view: &ShapeView) {
    let size = view.size;
    let exr = image::Rgb32FImage::from_fn(size, size, |x, y| image::Rgb(picture[(y * size + x) as usize].to_array()));
    let mask = image::GrayImage::from_fn(size, size, |x, y| {
        image::Luma([if view.scored[(y * size + x) as usize] { 255 } else { 0 }])
    });
    let written = path
        .parent()
        .map_or(Ok(()), std::fs::create_dir_all)
        .and_then(|_| exr.save(path).map_err(std::io::Error::other))
        .and_then(|_| mask.save(path.with_extension("scored.png")).map_err(std::io::Error::other));
    if let Err(e) = written {
        eprintln!("warning: cannot write {} or its mask: {e}", path.display());
    }
}

/// Writes `view`'s triangles as an OBJ in metres, for the reference renderer.
fn write_obj(path: &std::path::Path, view: &ShapeView) -> std::io::Result<()> {
    let mut text = String::new();
    for p in &view.positions {
        text += &format!("v {} {} {}\n", p.x, p.y, p.z);
    }
    for t in view.indices.chunks_exact(3) {
        text += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    std::fs::write(path, text)
}
