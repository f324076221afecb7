//! `translucent_accuracy`'s command line: its options, their parsers, and the one-line
//! failures for options that do not go together.

use std::path::PathBuf;

use bevy::prelude::*;
use bevy_mesostructure::translucency::{TransportSettings, translucent_shadow_map::MAX_RESOLUTION};

use super::translucent_accuracy_scene::Shape;
use super::translucent_light_tracer::{Part, Reentering};

/// The translucency's picture of a ball, the bunny or a torus against a path tracer's, per patch
/// budget, into a CSV.
#[derive(clap::Parser)]
#[command(long_about = None)]
pub struct Cli {
    /// The object: the 1 cm ball, the Stanford bunny 4 cm long, or a torus (ring radius 1 cm,
    /// tube radius 3 mm); the bunny's and the torus's reference is light-traced on the very
    /// triangles, index-matched (or Mitsuba's: `--tracer mitsuba`)
    #[arg(long, value_enum, default_value_t = ShapeArg::Ball)]
    pub shape: ShapeArg,
    /// Jensen's medium
    #[arg(long, value_enum, default_value_t = Medium::Skin1)]
    pub medium: Medium,
    /// Patch budgets, comma-separated
    #[arg(long, value_delimiter = ',', default_value = "250,500,1000,2000",
          value_parser = clap::value_parser!(u32).range(16..=200_000))]
    pub budgets: Vec<u32>,
    /// Diffusion profile
    #[arg(long, value_enum, default_value_t = Kernel::ScaledDipole)]
    pub kernel: Kernel,
    /// Scale the transport by random walks in the ball against a slab
    /// (`TransportSettings::object_exit_share`; method suffix `_slab` when off)
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub object_exit_share: bool,
    /// The share of the profile's energy the sparse transport keeps
    /// (`TransportSettings::diffusion_energy_kept`; method suffix `_kept<value>` when not the
    /// default)
    #[arg(long, default_value_t = TransportSettings::default().diffusion_energy_kept)]
    pub energy_kept: f32,
    /// The share of a shape-solved column's energy its lightest entries may hold and be
    /// dropped (`TransportSettings::shape_energy_dropped`, 0 – 0.01; method suffix
    /// `_shapedropped<value>` when not the default)
    #[arg(long, default_value_t = TransportSettings::default().shape_energy_dropped)]
    pub shape_energy_dropped: f32,
    /// Weight each beam by its incidence (`TransportSettings::beam_incidence`; method suffix
    /// `_diffuse` when off)
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub beam_incidence: bool,
    /// Where the object's scattering `K` comes from: the plugin's diffusion profile, or as an
    /// oracle of it random walks from every patch (`--walks` a patch, shared by the channels; the references' own
    /// physics) entering diffusely as `K` assumes, or as the light's own beam (exact first
    /// flights: a bound on what a better beam model gains, not something a moving light can
    /// have; index-matched only). Method suffix `_walks<n>` / `_beamwalks<n>`
    #[arg(long, value_enum, default_value_t = Scattering::Profile)]
    pub scattering: Scattering,
    /// As an oracle of a gather that carries each beam's single scattering apart: re-shape
    /// each lit pixel's single scattering from Lambert's law into its own (index-matched,
    /// under the directional light; method suffix `_ssoracle`)
    #[arg(long)]
    pub single_scattering_oracle: bool,
    /// The axis the deep field's exit law is taken about: the plugin's (with the beam table
    /// the way each patch's light from elsewhere flows in, from each source's diffusion source
    /// weighted by what it gives — method suffix `_exitflow` —, else the normal), or as
    /// oracles the normal even with the table, and `-all`: all light from elsewhere takes the
    /// law, not the share `1 − ν` (suffixes `_exitnormalall`, `_exitflowall`)
    #[arg(long, value_enum, default_value_t = Axis::Plugin)]
    pub exit_axis: Axis,
    /// With the beam table, give each patch's light from afar out by a lobe leaning the way
    /// it travelled (`TransportSettings::exit_lobes`; method suffix
    /// `_exitlean_afar2mfp_raysback_latepermfp` on the plugin's axis, `_exitflow` when off)
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub exit_lobes: bool,
    /// With the beam table on the plugin's axis, all the light from elsewhere leaves by the
    /// law about its flow, not only the share `g` in the diffusion mode
    /// (`TransportSettings::flow_law_takes_all`; method suffix `_flowall` when on)
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub flow_law_takes_all: bool,
    /// With the beam table, lean the light a translucent pixel shows down the exitance's
    /// gradient along the surface (P1's flux along it; `TransportSettings::tangential_flux`,
    /// on by default; method suffix `_tangential` when on)
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub tangential_flux: bool,
    /// With `--scattering beam-table`, diffuse light entering a tabled patch (the light that
    /// left and came back in) leaves by the late light's own diffuse walks, not the profile's
    /// `K` (`BeamTableSettings::diffuse_columns_walked`, on by default; method suffix
    /// `_diffusewalked` when on)
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub diffuse_columns_walked: bool,
    /// Walks from each patch (shared by the channels) for `--scattering walks|beam-walks`
    /// (default 256), or a direction for `--scattering beam-table` (default the plugin's,
    /// `BeamTableSettings::default().walks`)
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=65536))]
    pub walks: Option<u32>,
    /// With `--scattering beam-walks`: snap each patch's beam to the nearest of a per-patch
    /// table's directions, COSINES incidence cosines × AZIMUTHS azimuths in the patch's frame
    /// (what precomputed beam columns looked up per frame would give; method suffix
    /// `_table<c>x<a>`)
    #[arg(long, value_name = "COSINES,AZIMUTHS", value_parser = parse_table)]
    pub beam_table: Option<(u32, u32)>,
    /// With `--beam-table`: the orders of scattering the beam walks carry, FIRST (2: single
    /// scattering is left to each pixel's own law) to LAST (walks still inside after it leave
    /// as the profile's diffuse light; method suffix `_orders<first>to<last>`)
    #[arg(long, value_name = "FIRST,LAST", value_parser = parse_orders)]
    pub beam_orders: Option<(u32, u32)>,
    /// With `--beam-orders`: how the light still inside after LAST leaves — as diffuse light
    /// entering the patch (`profile`: its column of the profile's `K`), as the late part of
    /// it (`profile-less-early`: that column less the early exits of `--late-walks` diffuse
    /// walks), or that without its negative entries (`clamped`). Method suffix `_late<name>`
    #[arg(long, value_enum, default_value_t = Late::Profile)]
    pub late_light: Late,
    /// Diffuse walks from each patch (shared by the channels) for `--late-light
    /// profile-less-early|clamped` (default 1024) and `--scattering beam-table` (default the
    /// plugin's, `BeamTableSettings::default().late_walks`; the table's are then scaled as the
    /// plugin's, `beam_table::late_walks_for`: times `order/32` in marble)
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=65536))]
    pub late_walks: Option<u32>,
    /// With `--scattering beam-table`: how many walks each beam walk becomes once it
    /// scatters more than two patch sizes from its entry (`BeamTableSettings::far_splits`;
    /// default the plugin's; 1: none). Method suffix `_far<n>` when above 1
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub far_splits: Option<u32>,
    /// With `--scattering beam-table`: the most scatterings a walk takes in a medium that
    /// loses less than half its light to absorption within the last order (16, or LAST of
    /// `--beam-orders`): it walks on until half would be lost
    /// (`BeamTableSettings::max_last_order`; default the plugin's; the last order: every
    /// medium stops there). Method suffix `_orders<last>upto<most>` when above the last order
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub max_last_order: Option<u32>,
    /// With `--scattering beam-table`: offset its walks' seeds (`BeamTableSettings::seed`; 0
    /// the documented tables). Runs over a few seeds show what a variant must beat: one seed
    /// moves the figures by ~±0.005 from the front. Method suffix `_seed<n>` when not 0
    #[arg(long, default_value_t = 0)]
    pub table_seed: u32,
    /// With `--beam-orders 1,..`: single scattering leaving by the lit face goes to each lit
    /// pixel's own law instead of the table (what leaves through a thin part's far side stays
    /// in it). Method suffix `_litfacelaw`
    #[arg(long)]
    pub lit_face_single_scattering_law: bool,
    /// With `--scattering beam-table`, index-matched under the directional light: each
    /// pixel's single scattering (all of it out of the table,
    /// `BeamTableSettings::single_scattering_to_pixels`, the default) marched by rays through
    /// the object against the light's path in it, 64 depths a channel — the oracle of the
    /// plugin's march against its maps. Method suffix `_ssmarched`
    #[arg(long)]
    pub marched_single_scattering: bool,
    /// The plugin's march (the default with `--scattering beam-table`) against each object's
    /// translucent shadow map of N² texels (default the plugin's, 256). Method suffix
    /// `_ssmarched_tsm<N>_d<depths>`
    #[arg(long, value_name = "N")]
    pub translucent_shadow_map: Option<u32>,
    /// With `--scattering beam-table`: single scattering in the table and the lit face's
    /// half-space law in the gather (`single_scattering_to_pixels` off: the defaults before
    /// the march). No suffix
    #[arg(long)]
    pub single_scattering_in_table: bool,
    /// A point light this far (metres) from the object's centre, back along the light's
    /// direction, of irradiance 1 across its rays at the centre, instead of the directional
    /// light: each patch's beam from it, each object's map in perspective from it.
    /// Index-matched, `--scattering beam-table` or `profile`; the ball's reference is made by
    /// `--tracer` (the light tracer by default), as are the other shapes'. Lighting suffix
    /// `_point<distance>`
    #[arg(long, value_name = "DISTANCE")]
    pub point_light: Option<f32>,
    /// A grey Lambertian floor of this albedo (0 – 1) under the object, 2 mm below its lowest
    /// point, square, twice the object's widest extent across: light that leaves the object,
    /// lights the floor and comes back, and the floor's light from the lamp, both carried by
    /// the form factors (the object's pixels are scored; the floor's are not). `0`: the floor
    /// is there for the reference but black in the plugin (what the bounce is worth). The
    /// reference is Mitsuba's (`--tracer mitsuba`). Lighting suffix `_floor<albedo>` (and
    /// method suffix `_floorblack` for `0`), with `--floor-albedo-in-reference`
    #[arg(long, value_name = "ALBEDO")]
    pub floor: Option<f32>,
    /// The gather's exit law takes each translucent patch's irradiance direct and bounced as
    /// its own light (the plugin's); `false`: its direct light alone, as before 2026-11-29,
    /// when light bounced onto a patch left by the law of the table's flow. Method suffix
    /// `_bouncedown` when on (rows without it were measured before)
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub bounced_as_own: bool,
    /// An oracle: the solve stops after this many bounces of light between patches (0: the
    /// light that got in leaves by the transport alone, none of what left comes back in;
    /// default: as many as its threshold takes). Method suffix `_bounces<n>`
    #[arg(long, value_name = "N")]
    pub bounces: Option<u32>,
    /// A black square plate between the light and the object, facing the light, its edge on
    /// the light's line through the object's centre: the object's upper half in its shadow,
    /// the shadow's edge across its middle (light carried under the surface into the shadow).
    /// The plate's patches shadow the transport as any `RadiosityReceiver` does; pixels it
    /// hides are not scored. Directional light; the reference is Mitsuba's. Lighting suffix
    /// `_occluded`
    #[arg(long)]
    pub occluder: bool,
    /// With `--floor 0`: the floor's albedo in the reference (the plugin's floor stays black)
    #[arg(long, value_name = "ALBEDO")]
    pub floor_albedo_in_reference: Option<f32>,
    /// The ball's pixels on its triangles (as the GPU's depth prepass puts them), not on the
    /// sphere its references are of: the march's maps are of the triangles too. Method suffix
    /// `_onmesh`
    #[arg(long)]
    pub pixels_on_mesh: bool,
    /// Take the dipole's flux along each exit patch's normal
    /// (`Translucent::oriented_dipole`; method suffix `_oriented` when on)
    #[arg(long, default_value_t = false, action = clap::ArgAction::Set)]
    pub oriented_dipole: bool,
    /// Solve the diffusion in the ball's own shape (`TransportSettings::shape_diffusion`;
    /// method suffix `_flat` when off)
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub shape_diffusion: bool,
    /// Let light from elsewhere leave translucent patches in the deep field's law
    /// (`TransportSettings::deep_exit_law`; method suffix `_lambert` when off)
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    pub deep_exit_law: bool,
    /// How the pixels take the patches' light: interpolated radiance (the plugin's default)
    /// or the seed's photons (density estimation)
    #[arg(long, value_enum, default_value_t = Gather::Interpolation)]
    pub gather: Gather,
    /// The direction the light travels, x,y,z (default -1,-0.2,-0.3: from the right, a
    /// little above and in front; 0.4,-0.2,1 lights the ball from behind)
    #[arg(long, value_parser = parse_direction, allow_negative_numbers = true)]
    pub light: Option<Vec3>,
    /// Light the ball by a uniform environment of radiance 1 (Bevy's ambient light) instead
    /// of the directional light; the reference is Mitsuba's (scene suffix `uniform`)
    #[arg(long)]
    pub uniform: bool,
    /// Index of refraction of the ball's boundary (1: index-matched, no Fresnel in either
    /// renderer). Above 1 under the directional light the reference is the light tracer's (a
    /// directional light cannot reach the camera through a smooth dielectric in Mitsuba);
    /// scene suffix `_eta<value>`
    #[arg(long, default_value_t = 1.0, value_parser = parse_eta)]
    pub eta: f32,
    /// Picture width = height
    #[arg(long, default_value_t = 96, value_parser = clap::value_parser!(u32).range(8..=1024))]
    pub size: u32,
    /// The plugin's picture averaged over N × N points a pixel (1: its centre), as the
    /// references' box filter averages each pixel's area; which pixels are scored stays by
    /// their centres. The documented figures take 1. Method suffix `_px<N>` above 1
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=8))]
    pub pixel_samples: u32,
    /// Which renderer makes the reference (when rendered here): the light tracer (converged
    /// lit from any side) or Mitsuba's volumetric path tracer (fireflies lit from behind)
    #[arg(long, value_enum, default_value_t = Tracer::Light)]
    pub tracer: Tracer,
    /// Samples per pixel of Mitsuba's reference
    #[arg(long, default_value_t = 1024, value_parser = clap::value_parser!(u32).range(1..))]
    pub spp: u32,
    /// Photons per channel of the light tracer's reference
    #[arg(long, default_value_t = 40_000_000, value_parser = clap::value_parser!(u64).range(1000..))]
    pub photons: u64,
    /// The seed of the mesh light tracer's photons (two seeds' pictures give its noise)
    #[arg(long, default_value_t = 1)]
    pub tracer_seed: u64,
    /// The bunny's, the torus's or (`--pixels-on-mesh`) the ball's light tracer renders this
    /// part of the light (an oracle against the whole): single scattering alone, the exact
    /// transport given out by Lambert's law, all but the light that left the mesh and came
    /// back in (each photon stopped at its first exit), or all but the light that crossed a
    /// thin part unscattered and came back in. Reference suffix `-single` /
    /// `-lambertianexit` / `-firstexit` / `-nouncollidedreentry`
    #[arg(long, value_enum, default_value_t = Part::All)]
    pub light_traced_part: Part,
    /// An oracle: the exact transport's exitance on the plugin's own patches, light-traced
    /// with this many photons a channel (each exit after a scattering or more tallied on the
    /// patch the plugin's walks would leave by), compared patch by patch with the plugin's (printed)
    /// and, with `--exact-exitance-gathered true` (the default), gathered by the plugin's
    /// laws in its place (single scattering in it: no march; with `--exact-exitance-after 1`
    /// or more the march gives it, as for the plugin's own). Index-matched, directional
    /// light; cached in out/translucent_accuracy/
    #[arg(long, value_name = "PHOTONS")]
    pub exact_exitance: Option<u64>,
    /// With `--exact-exitance`: gather the exact exitance (true) or only compare it with the
    /// plugin's, whose picture is then its own (false)
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set, requires = "exact_exitance")]
    pub exact_exitance_gathered: bool,
    /// With `--exact-exitance`: only the exits after more than this many scatterings (the
    /// light a method's late model carries past its walks' last order)
    #[arg(long, default_value_t = 0, requires = "exact_exitance")]
    pub exact_exitance_after: u32,
    /// With `--exact-exitance`: which of the light that left the object and came back in is
    /// followed — all, only what scattered before it left, or none (each photon stops at its
    /// first exit)
    #[arg(long, value_enum, default_value_t = Reentering::All, requires = "exact_exitance")]
    pub exact_exitance_reentering: Reentering,
    /// With `--exact-exitance`: the plugin's bounce alone — the exact exitance of light that
    /// never came back in (traced as with `--exact-exitance-reentering none`) as the solve's
    /// source in place of the plugin's own, bounced by its form factors and `K`, against the
    /// exact exitance (with `--exact-exitance-reentering`'s light that came back in)
    #[arg(long, requires = "exact_exitance")]
    pub exact_exitance_bounced: bool,
    /// A reference EXR made before (else it is rendered into out/translucent_accuracy/)
    #[arg(long)]
    pub reference: Option<PathBuf>,
    /// CSV to append rows to (header written if the file is new)
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Draw the main rows of `--out` into this PNG: relative L1 against patches for the
    /// skin1 and marble balls (defaults, the shape with Lambert's exit, the flat profile),
    /// Bevy's best fit as a dashed level
    #[arg(long, requires = "out")]
    pub chart: Option<PathBuf>,
    /// Also fit Bevy's own `diffuse_transmission` material to the reference (renders on the
    /// GPU or the software driver): the best base colour per channel for each transmission
    /// 0, 0.1, … 1 and thickness 0 or 2 cm
    #[arg(long)]
    pub bevy: bool,
}

#[derive(Clone, Copy, clap::ValueEnum, Debug)]
pub enum Medium {
    Skin1,
    Skin2,
    Marble,
    Ketchup,
    Apple,
}

#[derive(Clone, Copy, clap::ValueEnum, Debug, PartialEq)]
pub enum ShapeArg {
    Ball,
    Bunny,
    Torus,
}

/// `--exit-axis` ([`ExitAxis`]).
#[derive(Clone, Copy, clap::ValueEnum, Debug, PartialEq)]
pub enum Axis {
    Plugin,
    Normal,
    NormalAll,
    FlowAll,
    Lobe,
}

#[derive(Clone, Copy, clap::ValueEnum, Debug, PartialEq)]
pub enum Scattering {
    Profile,
    Walks,
    BeamWalks,
    BeamTable,
}

#[derive(Clone, Copy, clap::ValueEnum, Debug)]
pub enum Gather {
    Interpolation,
    Photons,
}

#[derive(Clone, Copy, clap::ValueEnum, Debug, PartialEq)]
pub enum Tracer {
    Light,
    Mitsuba,
}

#[derive(Clone, Copy, clap::ValueEnum, Debug)]
pub enum Kernel {
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
pub enum Late {
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

pub fn fail(message: String) -> ! {
    eprintln!("error: {message}");
    std::process::exit(1);
}

/// Fails with one line where the options asked for do not go together.
pub fn check_combinations(cli: &Cli, shape: Shape) {
    if cli.eta != 1.0 && !cli.uniform && cli.tracer == Tracer::Mitsuba && cli.reference.is_none() {
        fail("--eta above 1 under the directional light needs --tracer light: in Mitsuba a directional light cannot reach the camera through a smooth dielectric".into());
    }
    if shape != Shape::Ball && (cli.eta != 1.0 || cli.uniform) {
        fail("the bunny and the torus are index-matched under the directional light only (their reference is Mitsuba's; drop --eta and --uniform)".into());
    }
    if cli.exact_exitance.is_some() && (cli.eta != 1.0 || cli.uniform || cli.point_light.is_some() || cli.floor.is_some() || cli.occluder) {
        fail("--exact-exitance light-traces one index-matched object under the directional light (drop --eta, --uniform, --point-light, --floor and --occluder)".into());
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
    for (option, albedo) in [("--floor", cli.floor), ("--floor-albedo-in-reference", cli.floor_albedo_in_reference)] {
        if albedo.is_some_and(|a| !(0.0..=1.0).contains(&a)) {
            fail(format!("{option} takes an albedo in 0 – 1, not {}", albedo.unwrap_or_default()));
        }
    }
    if cli.floor_albedo_in_reference.is_some() && cli.floor != Some(0.0) {
        fail("--floor-albedo-in-reference gives a floor the plugin leaves black: it needs --floor 0".into());
    }
    if cli.occluder && (cli.uniform || cli.eta != 1.0 || cli.point_light.is_some() || cli.bevy || cli.pixel_samples > 1) {
        fail("--occluder takes the directional light on an index-matched object (drop --uniform, --eta, --point-light, --bevy, --pixel-samples)".into());
    }
    if cli.occluder && cli.marched_single_scattering {
        fail("--marched-single-scattering's rays see the object alone, not the occluder: drop one".into());
    }
    if cli.floor.is_some() {
        if cli.uniform || cli.eta != 1.0 || cli.point_light.is_some() || cli.bevy || cli.pixel_samples > 1 {
            fail("--floor takes the directional light on an index-matched object (drop --uniform, --eta, --point-light, --bevy, --pixel-samples)".into());
        }
        if !matches!(cli.scattering, Scattering::BeamTable | Scattering::Profile) || cli.marched_single_scattering {
            fail("--floor takes --scattering beam-table or profile, marched against the plugin's maps".into());
        }
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
