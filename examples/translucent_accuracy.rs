//! Accuracy of the translucency transport against a path tracer: a ball of one of Jensen's
//! media (radius 1 cm, an index-matched boundary so that the picture is the light diffused
//! out of the medium alone) lit by one directional light, seen from 4 cm, or (`--shape
//! bunny`) the Stanford bunny 4 cm long — thin ears, creases, flat flanks — seen from above
//! and aside, against Mitsuba rendering the very same triangles. The plugin's picture
//! is computed on the CPU with the same patches, transport, iteration and gather as the GPU
//! passes (`translucency::gather::gathered_radiance`, the oracle the GPU tests hold the passes
//! to: within 0.24/255 mean of it); the reference is a light tracer of the same scene
//! (`tools/translucent_light_tracer.py`, numpy: converged lit from any side, no fireflies) or
//! Mitsuba 3's volumetric path tracing (`tools/translucent_reference.py`; the two agree to
//! 0.2 % in the mean, `docs/translucent.md`); the example runs them where `python3` has
//! `numpy` and `mitsuba`, or reads one with `--reference`.
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
//!     [--size 96] [--tracer light|mitsuba] [--spp 1024] [--photons 40000000]
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
#[path = "common/translucent_accuracy_scene.rs"]
mod translucent_accuracy_scene;
#[path = "common/translucent_bevy_fit.rs"]
mod translucent_bevy_fit;

use std::{
    io::Write,
    path::PathBuf,
    process::Command,
    time::Instant,
};

use bevy::prelude::*;
use bevy_mesostructure::translucency::{
    DiffusionKernel, GatherMethod, TranslucentPreset, TransportSettings, beam_table::BeamTableSettings,
    random_walk::ScatteringOrders, translucent_shadow_map::{MAX_RESOLUTION, PLUGIN_DEPTHS, PLUGIN_RESOLUTION},
};
use translucent_accuracy_scene::{
    ExitAxis, FOV_Y, FRONT_LIGHT, LateLight, Oracles, RADIUS, ScatteringSource, SceneLighting, Shape,
    ShapeView, plugin_picture, score,
};

/// The translucency's picture of a ball, the bunny or a torus against a path tracer's, per patch
/// budget, into a CSV.
#[derive(clap::Parser)]
#[command(long_about = None)]
struct Cli {
    /// The object: the 1 cm ball, the Stanford bunny 4 cm long, or a torus (ring radius 1 cm,
    /// tube radius 3 mm); the bunny's and the torus's reference is Mitsuba's, index-matched
    /// (the light tracer traces the ball only)
    #[arg(long, value_enum, default_value_t = ShapeArg::Ball)]
    shape: ShapeArg,
    /// Jensen's medium
    #[arg(long, value_enum, default_value_t = Medium::Skin1)]
    medium: Medium,
    /// Patch budgets, comma-separated
    #[arg(long, value_delimiter = ',', default_value = "250,500,1000,2000",
          value_parser = clap::value_parser!(u32).range(16..=200_000))]
    budgets: Vec<u32>,
    /// Diffusion profile
    #[arg(long, value_enum, default_value_t = Kernel::ScaledDipole)]
    kernel: Kernel,
    /// Scale the transport by random walks in the ball against a slab
    /// (`TransportSettings::object_exit_share`; method suffix `_slab` when off)
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    object_exit_share: bool,
    /// The share of the profile's energy the sparse transport keeps
    /// (`TransportSettings::diffusion_energy_kept`; method suffix `_kept<value>` when not the
    /// default)
    #[arg(long, default_value_t = TransportSettings::default().diffusion_energy_kept)]
    energy_kept: f32,
    /// The share of a shape-solved column's energy its lightest entries may hold and be
    /// dropped (`TransportSettings::shape_energy_dropped`, 0 – 0.01; method suffix
    /// `_shapedropped<value>` when not the default)
    #[arg(long, default_value_t = TransportSettings::default().shape_energy_dropped)]
    shape_energy_dropped: f32,
    /// Weight each beam by its incidence (`TransportSettings::beam_incidence`; method suffix
    /// `_diffuse` when off)
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    beam_incidence: bool,
    /// Where the object's scattering `K` comes from: the plugin's diffusion profile, or as an
    /// oracle of it random walks from every patch (`--walks` a patch, shared by the channels; the references' own
    /// physics) entering diffusely as `K` assumes, or as the light's own beam (exact first
    /// flights: a bound on what a better beam model gains, not something a moving light can
    /// have; index-matched only). Method suffix `_walks<n>` / `_beamwalks<n>`
    #[arg(long, value_enum, default_value_t = Scattering::Profile)]
    scattering: Scattering,
    /// As an oracle of a gather that carries each beam's single scattering apart: re-shape
    /// each lit pixel's single scattering from Lambert's law into its own (index-matched,
    /// under the directional light; method suffix `_ssoracle`)
    #[arg(long)]
    single_scattering_oracle: bool,
    /// The axis the deep field's exit law is taken about: the plugin's (with the beam table
    /// the way each patch's light from elsewhere flows in, from each source's diffusion source
    /// weighted by what it gives — method suffix `_exitflow` —, else the normal), or as
    /// oracles the normal even with the table, and `-all`: all light from elsewhere takes the
    /// law, not the share `1 − ν` (suffixes `_exitnormalall`, `_exitflowall`)
    #[arg(long, value_enum, default_value_t = Axis::Plugin)]
    exit_axis: Axis,
    /// With the beam table, give each patch's light from afar out by a lobe leaning the way
    /// it travelled (`TransportSettings::exit_lobes`; method suffix
    /// `_exitlean_afar2mfp_raysback_latepermfp` on the plugin's axis, `_exitflow` when off)
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    exit_lobes: bool,
    /// With the beam table on the plugin's axis, all the light from elsewhere leaves by the
    /// law about its flow, not only the share `g` in the diffusion mode
    /// (`TransportSettings::flow_law_takes_all`; method suffix `_flowall` when on)
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    flow_law_takes_all: bool,
    /// Walks from each patch (shared by the channels) for `--scattering walks|beam-walks`
    /// (default 256), or a direction for `--scattering beam-table` (default the plugin's,
    /// `BeamTableSettings::default().walks`)
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=65536))]
    walks: Option<u32>,
    /// With `--scattering beam-walks`: snap each patch's beam to the nearest of a per-patch
    /// table's directions, COSINES incidence cosines × AZIMUTHS azimuths in the patch's frame
    /// (what precomputed beam columns looked up per frame would give; method suffix
    /// `_table<c>x<a>`)
    #[arg(long, value_name = "COSINES,AZIMUTHS", value_parser = parse_table)]
    beam_table: Option<(u32, u32)>,
    /// With `--beam-table`: the orders of scattering the beam walks carry, FIRST (2: single
    /// scattering is left to each pixel's own law) to LAST (walks still inside after it leave
    /// as the profile's diffuse light; method suffix `_orders<first>to<last>`)
    #[arg(long, value_name = "FIRST,LAST", value_parser = parse_orders)]
    beam_orders: Option<(u32, u32)>,
    /// With `--beam-orders`: how the light still inside after LAST leaves — as diffuse light
    /// entering the patch (`profile`: its column of the profile's `K`), as the late part of
    /// it (`profile-less-early`: that column less the early exits of `--late-walks` diffuse
    /// walks), or that without its negative entries (`clamped`). Method suffix `_late<name>`
    #[arg(long, value_enum, default_value_t = Late::Profile)]
    late_light: Late,
    /// Diffuse walks from each patch (shared by the channels) for `--late-light
    /// profile-less-early|clamped` (default 1024) and `--scattering beam-table` (default the
    /// plugin's, `BeamTableSettings::default().late_walks`)
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=65536))]
    late_walks: Option<u32>,
    /// With `--scattering beam-table`: how many walks each beam walk becomes once it
    /// scatters more than two patch sizes from its entry (`BeamTableSettings::far_splits`;
    /// default the plugin's; 1: none). Method suffix `_far<n>` when above 1
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=64))]
    far_splits: Option<u32>,
    /// With `--scattering beam-table`: offset its walks' seeds (`BeamTableSettings::seed`; 0
    /// the documented tables). Runs over a few seeds show what a variant must beat: one seed
    /// moves the figures by ~±0.005 from the front. Method suffix `_seed<n>` when not 0
    #[arg(long, default_value_t = 0)]
    table_seed: u32,
    /// With `--beam-orders 1,..`: single scattering leaving by the lit face goes to each lit
    /// pixel's own law instead of the table (what leaves through a thin part's far side stays
    /// in it). Method suffix `_litfacelaw`
    #[arg(long)]
    lit_face_single_scattering_law: bool,
    /// With `--scattering beam-table`, index-matched under the directional light: each
    /// pixel's single scattering (all of it out of the table,
    /// `BeamTableSettings::single_scattering_to_pixels`, the default) marched by rays through
    /// the object against the light's path in it, 64 depths a channel — the oracle of the
    /// plugin's march against its maps. Method suffix `_ssmarched`
    #[arg(long)]
    marched_single_scattering: bool,
    /// The plugin's march (the default with `--scattering beam-table`) against each object's
    /// translucent shadow map of N² texels (default the plugin's, 256). Method suffix
    /// `_ssmarched_tsm<N>_d<depths>`
    #[arg(long, value_name = "N")]
    translucent_shadow_map: Option<u32>,
    /// With `--scattering beam-table`: single scattering in the table and the lit face's
    /// half-space law in the gather (`single_scattering_to_pixels` off: the defaults before
    /// the march). No suffix
    #[arg(long)]
    single_scattering_in_table: bool,
    /// A point light this far (metres) from the object's centre, back along the light's
    /// direction, of irradiance 1 across its rays at the centre, instead of the directional
    /// light: each patch's beam from it, each object's map in perspective from it.
    /// Index-matched, `--scattering beam-table` or `profile`; the ball's reference is made by
    /// `--tracer` (the light tracer by default), the other shapes' by Mitsuba. Lighting suffix
    /// `_point<distance>`
    #[arg(long, value_name = "DISTANCE")]
    point_light: Option<f32>,
    /// The ball's pixels on its triangles (as the GPU's depth prepass puts them), not on the
    /// sphere its references are of: the march's maps are of the triangles too. Method suffix
    /// `_onmesh`
    #[arg(long)]
    pixels_on_mesh: bool,
    /// Take the dipole's flux along each exit patch's normal
    /// (`Translucent::oriented_dipole`; method suffix `_oriented` when on)
    #[arg(long, default_value_t = false, action = clap::ArgAction::Set)]
    oriented_dipole: bool,
    /// Solve the diffusion in the ball's own shape (`TransportSettings::shape_diffusion`;
    /// method suffix `_flat` when off)
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    shape_diffusion: bool,
    /// Let light from elsewhere leave translucent patches in the deep field's law
    /// (`TransportSettings::deep_exit_law`; method suffix `_lambert` when off)
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    deep_exit_law: bool,
    /// How the pixels take the patches' light: interpolated radiance (the plugin's default)
    /// or the seed's photons (density estimation)
    #[arg(long, value_enum, default_value_t = Gather::Interpolation)]
    gather: Gather,
    /// The direction the light travels, x,y,z (default -1,-0.2,-0.3: from the right, a
    /// little above and in front; 0.4,-0.2,1 lights the ball from behind)
    #[arg(long, value_parser = parse_direction, allow_negative_numbers = true)]
    light: Option<Vec3>,
    /// Light the ball by a uniform environment of radiance 1 (Bevy's ambient light) instead
    /// of the directional light; the reference is Mitsuba's (scene suffix `uniform`)
    #[arg(long)]
    uniform: bool,
    /// Index of refraction of the ball's boundary (1: index-matched, no Fresnel in either
    /// renderer). Above 1 under the directional light the reference is the light tracer's (a
    /// directional light cannot reach the camera through a smooth dielectric in Mitsuba);
    /// scene suffix `_eta<value>`
    #[arg(long, default_value_t = 1.0, value_parser = parse_eta)]
    eta: f32,
    /// Picture width = height
    #[arg(long, default_value_t = 96, value_parser = clap::value_parser!(u32).range(8..=1024))]
    size: u32,
    /// Which renderer makes the reference (when rendered here): the light tracer (converged
    /// lit from any side) or Mitsuba's volumetric path tracer (fireflies lit from behind)
    #[arg(long, value_enum, default_value_t = Tracer::Light)]
    tracer: Tracer,
    /// Samples per pixel of Mitsuba's reference
    #[arg(long, default_value_t = 1024, value_parser = clap::value_parser!(u32).range(1..))]
    spp: u32,
    /// Photons per channel of the light tracer's reference
    #[arg(long, default_value_t = 40_000_000, value_parser = clap::value_parser!(u64).range(1000..))]
    photons: u64,
    /// A reference EXR made before (else it is rendered into out/translucent_accuracy/)
    #[arg(long)]
    reference: Option<PathBuf>,
    /// CSV to append rows to (header written if the file is new)
    #[arg(long)]
    out: Option<PathBuf>,
    /// Draw the main rows of `--out` into this PNG: relative L1 against patches for the
    /// skin1 and marble balls (defaults, the shape with Lambert's exit, the flat profile),
    /// Bevy's best fit as a dashed level
    #[arg(long, requires = "out")]
    chart: Option<PathBuf>,
    /// Also fit Bevy's own `diffuse_transmission` material to the reference (renders on the
    /// GPU or the software driver): the best base colour per channel for each transmission
    /// 0, 0.1, … 1 and thickness 0 or 2 cm
    #[arg(long)]
    bevy: bool,
}

#[derive(Clone, Copy, clap::ValueEnum, Debug)]
enum Medium {
    Skin1,
    Skin2,
    Marble,
    Ketchup,
    Apple,
}

#[derive(Clone, Copy, clap::ValueEnum, Debug, PartialEq)]
enum ShapeArg {
    Ball,
    Bunny,
    Torus,
}

/// `--exit-axis` ([`ExitAxis`]).
#[derive(Clone, Copy, clap::ValueEnum, Debug, PartialEq)]
enum Axis {
    Plugin,
    Normal,
    NormalAll,
    FlowAll,
    Lobe,
}

#[derive(Clone, Copy, clap::ValueEnum, Debug, PartialEq)]
enum Scattering {
    Profile,
    Walks,
    BeamWalks,
    BeamTable,
}

#[derive(Clone, Copy, clap::ValueEnum, Debug)]
enum Gather {
    Interpolation,
    Photons,
}

#[derive(Clone, Copy, clap::ValueEnum, Debug, PartialEq)]
enum Tracer {
    Light,
    Mitsuba,
}

#[derive(Clone, Copy, clap::ValueEnum, Debug)]
enum Kernel {
    Dipole,
    Burley,
    ScaledDipole,
}

fn parse_direction(s: &str) -> Result<Vec3, String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|c| {
            c.trim()
                .parse::<f32>()
                .map_err(|_| format!("{s:?} is not three numbers x,y,z"))
        })
        .collect::<Result<_, _>>()?;
    match v[..] {
        [x, y, z] if Vec3::new(x, y, z).length() > 0.0 && Vec3::new(x, y, z).is_finite() => {
            Ok(Vec3::new(x, y, z).normalize())
        }
        _ => Err(format!("{s:?} is not a direction x,y,z")),
    }
}

/// `--late-light`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum Late {
    Profile,
    ProfileLessEarly,
    Clamped,
}

fn parse_orders(s: &str) -> Result<(u32, u32), String> {
    match s.split(',').map(|p| p.trim().parse::<u32>()).collect::<Vec<_>>()[..] {
        [Ok(first), Ok(last)] if first <= 2 && last >= first.max(1) => Ok((first, last)),
        _ => Err(format!("expected FIRST,LAST: FIRST 0 – 2, LAST ≥ FIRST and ≥ 1, got {s:?}")),
    }
}

fn parse_table(s: &str) -> Result<(u32, u32), String> {
    let parts: Vec<&str> = s.split(',').collect();
    let [Ok(cosines), Ok(azimuths)] = [parts.first(), parts.get(1)].map(|p| {
        p.ok_or(())?.trim().parse::<u32>().map_err(|_| ())
    }) else {
        return Err(format!("expected COSINES,AZIMUTHS (two whole numbers), got {s:?}"));
    };
    if parts.len() != 2 || !(1..=64).contains(&cosines) || !(1..=64).contains(&azimuths) {
        return Err(format!("expected two numbers in 1 – 64, got {s:?}"));
    }
    Ok((cosines, azimuths))
}

fn parse_eta(s: &str) -> Result<f32, String> {
    match s.parse::<f32>() {
        Ok(eta) if (1.0..=3.0).contains(&eta) => Ok(eta),
        _ => Err(format!("{s:?} is not an index of refraction in 1 – 3")),
    }
}

fn fail(message: String) -> ! {
    eprintln!("error: {message}");
    std::process::exit(1);
}

/// Fails with one line where the options asked for do not go together.
fn check_combinations(cli: &Cli, shape: Shape) {
    if cli.eta != 1.0 && !cli.uniform && cli.tracer == Tracer::Mitsuba && cli.reference.is_none() {
        fail("--eta above 1 under the directional light needs --tracer light: in Mitsuba a directional light cannot reach the camera through a smooth dielectric".into());
    }
    if shape != Shape::Ball && (cli.eta != 1.0 || cli.uniform) {
        fail("the bunny and the torus are index-matched under the directional light only (their reference is Mitsuba's; drop --eta and --uniform)".into());
    }
    if cli.scattering == Scattering::BeamWalks && (cli.eta != 1.0 || cli.uniform) {
        fail("--scattering beam-walks takes the directional light into an index-matched object only (drop --eta and --uniform)".into());
    }
    if cli.beam_orders.is_some() && cli.beam_table.is_none() && cli.scattering != Scattering::BeamTable {
        fail("--beam-orders limits the table's beam walks: it needs --beam-table".into());
    }
    if cli.lit_face_single_scattering_law && cli.beam_orders.is_none_or(|(first, _)| first != 1) {
        fail("--lit-face-single-scattering-law takes single scattering out of the table's walks: it needs --beam-orders 1,LAST".into());
    }
    if cli.single_scattering_oracle
        && (cli.lit_face_single_scattering_law || cli.beam_orders.is_some_and(|(first, _)| first >= 2))
    {
        fail("--beam-orders 2,.. and --lit-face-single-scattering-law give single scattering in its own law already: drop --single-scattering-oracle".into());
    }
    if cli.beam_table.is_some() && !matches!(cli.scattering, Scattering::BeamWalks | Scattering::BeamTable) {
        fail("--beam-table snaps the beam walks' directions: it needs --scattering beam-walks or beam-table".into());
    }
    if cli.translucent_shadow_map.is_some_and(|n| !(1..=MAX_RESOLUTION).contains(&n)) {
        fail(format!("--translucent-shadow-map takes 1 – {MAX_RESOLUTION} texels a side"));
    }
    if [cli.marched_single_scattering, cli.translucent_shadow_map.is_some(), cli.single_scattering_in_table]
        .iter()
        .filter(|&&on| on)
        .count()
        > 1
    {
        fail("--marched-single-scattering (rays), --translucent-shadow-map (the plugin's maps) and --single-scattering-in-table are one choice each".into());
    }
    // The rays' march is index-matched; the map's is the plugin's, through the boundary.
    if cli.marched_single_scattering && (cli.scattering != Scattering::BeamTable || cli.uniform || cli.eta != 1.0) {
        fail("--marched-single-scattering takes --scattering beam-table under the directional light, index-matched (drop --eta and --uniform)".into());
    }
    if cli.scattering == Scattering::BeamTable && (cli.uniform || cli.single_scattering_oracle) {
        fail("--scattering beam-table carries the directional light's beams and gives single scattering its own law already (drop --uniform, --single-scattering-oracle)".into());
    }
    if cli.single_scattering_oracle && (cli.eta != 1.0 || cli.uniform) {
        fail("--single-scattering-oracle takes the directional light on an index-matched object only (drop --eta and --uniform)".into());
    }
    if cli.uniform && cli.bevy {
        fail("--bevy fits Bevy's material under the directional light only (drop --uniform)".into());
    }
    if let Some(distance) = cli.point_light {
        if !(distance > 0.0 && distance.is_finite()) {
            fail(format!("--point-light takes a positive distance in metres, not {distance}"));
        }
        if cli.uniform || cli.eta != 1.0 || cli.bevy || cli.marched_single_scattering || cli.single_scattering_oracle {
            fail("--point-light takes an index-matched object (drop --uniform, --eta, --bevy, --marched-single-scattering, --single-scattering-oracle)".into());
        }
        if !matches!(cli.scattering, Scattering::BeamTable | Scattering::Profile) {
            fail("--point-light takes --scattering beam-table or profile (the walk oracles launch one beam for all patches)".into());
        }
    }
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
    // Index-matched by default: no Fresnel at the boundary, in either renderer.
    let medium = bevy_mesostructure::translucency::TranslucentMedium {
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
    } + &cli.point_light.map_or(String::new(), |d| format!("_point{d}"));
    let name = format!("{:?}", cli.medium).to_lowercase();
    let size = cli.size;
    let view = if cli.pixels_on_mesh { ShapeView::on_mesh(shape, size) } else { ShapeView::new(shape, size) };
    let reference_path = cli.reference.clone().unwrap_or_else(|| {
        let dir = PathBuf::from("out/translucent_accuracy");
        std::fs::create_dir_all(&dir).unwrap_or_else(|e| fail(format!("cannot create {}: {e}", dir.display())));
        // The light tracer takes a directional or a point light: a uniform environment is
        // Mitsuba's. It traces the ball (the sphere) only.
        let on_sphere = shape == Shape::Ball && !cli.pixels_on_mesh;
        let light_traced = cli.tracer == Tracer::Light && !cli.uniform && on_sphere;
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
            if cli.light.is_some() && !cli.uniform { format!("_{:.3}_{:.3}_{:.3}", light.x, light.y, light.z) } else { String::new() },
            if cli.uniform || cli.eta != 1.0 || cli.point_light.is_some() { format!("_{lighting}") } else { String::new() },
        ));
        if !path.exists() {
            let list = |v: Vec3| format!("{},{},{}", v.x, v.y, v.z);
            // The ball is Mitsuba's own sphere; another shape (or the ball with its pixels on
            // its triangles), the very triangles the plugin's patches come from.
            let object = match shape {
                Shape::Ball if on_sphere => format!("--radius={RADIUS}"),
                _ => {
                    let obj = dir.join(format!("{}_{}.obj", shape.scene_name(), shape.size_name()));
                    write_obj(&obj, &view).unwrap_or_else(|e| fail(format!("cannot write {}: {e}", obj.display())));
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
                last_order: cli.beam_orders.map_or(16, |(_, last)| last),
                exit_directions: cli.exit_axis == Axis::Lobe,
                single_scattering_to_pixels: !cli.single_scattering_in_table,
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
                    "_beamtable{cosines}x{azimuths}_bilinear_pastterminator_lateheld_walks{}{}_late{}_orders{}{}{}",
                    table.walks,
                    if table.far_splits > 1 { format!("_far{}", table.far_splits) } else { String::new() },
                    table.late_walks,
                    table.last_order,
                    if table.seed == 0 { String::new() } else { format!("_seed{}", table.seed) },
                    match (table.single_scattering_to_pixels, cli.marched_single_scattering) {
                        (false, _) => String::new(),
                        (true, true) => "_ssmarched".into(),
                        // `_d<depths>`: the plugin's depths a channel (rows without it: 64);
                        // `_tangentbound`: the path under a lit surface at most its tangent
                        // plane's (`LightMaps::half_space_bound`; rows before it lack it).
                        (true, false) => format!(
                            "_ssmarched_tsm{}_d{PLUGIN_DEPTHS}_tangentbound",
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
    let method = format!(
        "patches_{:?}{gather_name}{slab}{diffuse}{oriented}{flat}{lambert}{kept}{walked}{ss_oracle}{exit_name}{flow_all}{centroid}{}",
        cli.kernel,
        if cli.pixels_on_mesh && shape == Shape::Ball { "_onmesh" } else { "" }
    )
    .to_lowercase();
    let oracles = Oracles {
        scattering: source,
        single_scattering_law: cli.single_scattering_oracle,
        exit_axis,
        shadow_map: if cli.marched_single_scattering { None } else { Some(cli.translucent_shadow_map.unwrap_or(PLUGIN_RESOLUTION)) },
    };
    let header = "scene,method,setting,patches,width,height,gpu_ms,precompute_s,memory_mb,rel_l1,flip,adapter";
    let mut rows = Vec::new();
    for &budget in &cli.budgets {
        let result = plugin_picture(
            &view,
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
        );
        let picture = &result.pixels;
        let scores = score(picture, &reference, &view);
        let rel_l1 = scores.rel_l1;
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
        let flip = nv_flip::FlipPool::from_image(&flip_image).mean();
        let n = result.patches;
        let bytes = result.memory_bytes;
        let precompute = result.precompute_s;
        eprintln!(
            "{name} {budget}: {n} patches, rel L1 {rel_l1:.4}, FLIP {flip:.4}, mean ratio r {:.3} g {:.3} b {:.3}, {} iterations",
            scores.ratio[0], scores.ratio[1], scores.ratio[2], result.iterations
        );
        rows.push(format!(
            "{}_{name}_{}_{lighting},{method},{budget},{n},{size},{size},,{precompute:.3},{:.3},{rel_l1:.4},{flip:.4},cpu oracle of the GPU passes",
            shape.scene_name(),
            shape.size_name(),
            bytes as f32 / 1e6
        ));
        let path = PathBuf::from("out/translucent_accuracy")
            .join(format!("plugin_{}_{name}_{lighting}_{method}_{budget}.exr", shape.scene_name()));
        save_picture(&path, &picture, &view);
    }
    if cli.bevy {
        let (best, transmission, thickness, colour) =
            translucent_bevy_fit::bevy_best_fit(&reference, &view, light).unwrap_or_else(|e| fail(e));
        eprintln!(
            "{name} Bevy diffuse_transmission best fit: rel L1 {best:.4} at transmission {transmission}, thickness {thickness} m, base colour {colour:?}"
        );
        rows.push(format!(
            "{}_{name}_{}_{lighting},bevy_diffuse_transmission,transmission {transmission} thickness {thickness} base {:.3} {:.3} {:.3},,{size},{size},,,,{best:.4},,Bevy 0.19.1 on the software driver, best of a grid",
            shape.scene_name(),
            shape.size_name(),
            colour[0], colour[1], colour[2]
        ));
    }
    println!("{header}");
    for row in &rows {
        println!("{row}");
    }
    if let Some(out) = cli.out {
        let new = !out.exists();
        let written = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&out)
            .and_then(|mut f| {
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
        if let Some(path) = &cli.chart {
            translucent_accuracy_chart::draw_chart(&out, path).unwrap_or_else(|e| fail(e));
        }
    }
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
