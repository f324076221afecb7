//! The translucency accuracy scenes, shared by `examples/translucent_accuracy.rs` and the
//! integration test that holds the plugin to path-traced references: one object of one
//! medium, index-matched or behind a dielectric boundary, lit by one directional light of
//! irradiance 1 or a uniform environment of radiance 1 — a ball of radius 1 cm (Bevy's ico
//! sphere, 720 triangles) seen from 4 cm, or the Stanford bunny 4 cm long seen from above
//! and aside (`Shape`) — the plugin's picture computed on the CPU by the same patches,
//! transport, iteration and gather as the passes, and its score against a reference picture.
#![allow(dead_code)] // The example reads every field; the test only the picture and its score.

use std::{collections::BTreeMap, time::Instant};

use bevy::prelude::*;
use bevy_mesostructure::translucency::{
    beam_table::{
        BeamTable, ExitPatches, BeamTableSettings, bin_direction, direction_bin, direction_weights,
        law_gives_single_scattering, single_scattering_radiance,
    },
    DirectLight, EnergyTransport, GatherMethod, PatchLight, PatchObject, PatchSurface,
    SceneRays, SparseMatrix, TranslucentMedium, TransportSettings, direct_light,
    diffusion::{diffuse_fresnel_reflectance, single_scattering_shape},
    gather::{BeamSingleScattering, gathered_radiance},
    patches::Patches,
    random_walk::{EntryPoint, ScatteringOrders, WalkEnd, WalkLaunch, walk_ends},
    resample_into_patches,
    translucent_shadow_map::{
        MarchedMedium, MarchedObject, PLUGIN_RESOLUTION, optical_depth_quantile,
    },
};

#[path = "translucent_accuracy_oracles.rs"]
mod oracles;
#[path = "translucent_accuracy_surroundings.rs"]
mod surroundings;
#[path = "translucent_accuracy_view.rs"]
mod view;
pub use view::*;
pub use surroundings::{Floor, Occluder};
pub use oracles::marched_single_scattering;
use oracles::{single_scattering_law, walked_scattering};

/// The scenes are in metres.
const WORLD_UNITS_PER_MM: f32 = 0.001;

/// The plugin's picture of a shape and what it cost.
pub struct ShapePicture {
    /// Linear radiance per pixel, row by row.
    pub pixels: Vec<Vec3>,
    /// The scene's patches (the object's and the floor's).
    pub patches: usize,
    /// The object's own.
    pub object_patches: usize,
    /// Patches and transport, seconds.
    pub precompute_s: f32,
    /// The sparse matrices' bytes.
    pub memory_bytes: usize,
    pub iterations: u32,
}

/// How the object is lit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SceneLighting {
    /// A directional light of irradiance 1 travelling along this (unit) direction.
    Directional(Vec3),
    /// A point light at this position, of irradiance 1 across its rays at the origin (the
    /// object's centre).
    Point(Vec3),
    /// A uniform environment of radiance 1: Bevy's ambient light, irradiance π on every
    /// translucent patch, as the plugin injects it.
    Uniform,
}

impl SceneLighting {
    /// The way the light travels at `x` (unit): a directional light's everywhere, a point
    /// light's from it; none for uniform light (or at the point light itself).
    pub fn travel_at(&self, x: Vec3) -> Option<Vec3> {
        match *self {
            SceneLighting::Directional(travel) => travel.try_normalize(),
            SceneLighting::Point(position) => (x - position).try_normalize(),
            SceneLighting::Uniform => None,
        }
    }
}

/// Where the translucent object's scattering `K` comes from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ScatteringSource {
    /// The plugin's: the diffusion profile of `TransportSettings`.
    Profile,
    /// An oracle of the profile: this many random walks a channel from each patch
    /// (`random_walk::walk_ends`, the references' own physics), entering diffusely as `K`
    /// assumes, each exit counted on the patch it leaves by. What is left against the
    /// reference is the rest of the pipeline's: the beam's incidence weight, the patches'
    /// resolution, the exit law, the gather.
    Walks(u32),
    /// As `Walks`, entering as the directional light's own beam (exact first flights, every
    /// order of scattering; no incidence weight, no separate single scattering): not
    /// something a moving light could have, but a bound on what a better beam model gains.
    BeamWalks(u32),
    /// As `BeamWalks`, each patch's beam snapped to the nearest of a table's directions in the
    /// patch's own frame (`cosines` incidence cosines, `(k + ½)/cosines`, times `azimuths`
    /// azimuths about its normal): what a per-patch table of beam columns, precomputed for
    /// any light and looked up (nearest, not interpolated) per frame, would give.
    BinnedBeamWalks {
        walks: u32,
        cosines: u32,
        azimuths: u32,
        /// The orders of scattering the walks carry: where `orders.first` is 2, single
        /// scattering is each lit pixel's own, `α E/(4π(μ₀ + μ))`; walks still inside after
        /// `orders.last` scatterings leave by `late`.
        orders: ScatteringOrders,
        /// How the light still inside after `orders.last` leaves.
        late: LateLight,
        /// Diffuse walks a channel from each patch for [`LateLight::ProfileLessEarly`] and
        /// the others that subtract the early exits.
        late_walks: u32,
        /// Single scattering that leaves by the lit face (an exit normal within 60° of the
        /// patch's) is each lit pixel's own law's, not the walks': what leaves after one
        /// scattering through the far side of a thin part stays in the table.
        lit_face_single_to_law: bool,
    },
    /// The plugin's beam table (`TransportSettings::beam_table`): for the directional light,
    /// each patch's nearest table direction's column (only that one walked: the same
    /// columns as the whole table's), single scattering by the lit face in its own law in
    /// the gather.
    BeamTable(BeamTableSettings),
}

/// How a beam's light still inside after the walks' last order leaves, per unit of it: the
/// variants measured against `beam_table`'s (the profile's column with its near field scaled
/// down, [`ScatteringSource::BeamTable`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LateLight {
    /// As diffuse light entering the patch does: the profile's column.
    Profile,
    /// As the late part of diffuse light entering the patch: the profile's column less
    /// the exits of diffuse walks within the same orders, per unit of their own remainder.
    ProfileLessEarly,
    /// [`ProfileLessEarly`](Self::ProfileLessEarly) without its negative entries (where the
    /// profile holds less near the entry than the walks' early exits), rescaled to the same
    /// flux.
    ProfileLessEarlyClamped,
}

/// `beam` (a unit travel direction) snapped to the nearest of `cosines` × `azimuths`
/// directions in the frame of `normal`: incidence cosines `(k + ½)/cosines`, azimuths
/// `2π m/azimuths` from a tangent fixed by the normal alone. A beam from behind the surface
/// stays as it is (it enters nowhere).
pub fn binned_beam(beam: Vec3, normal: Vec3, cosines: u32, azimuths: u32) -> Vec3 {
    direction_bin(beam, normal, cosines, azimuths)
        .map_or(beam, |bin| bin_direction(bin, normal, cosines, azimuths))
}

/// What the accuracy scene swaps in for the plugin's own stages, as oracles of them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Oracles {
    /// Where `K` comes from.
    pub scattering: ScatteringSource,
    /// Index-matched under the directional light: re-shape each lit pixel's single scattering
    /// from Lambert's law (the patches' `B/π`) into its own, `α E / (4π(μ₀ + μ))`, by
    /// `α E/(4π) (1/(μ₀ + μ) − 2 shape(μ₀))` with the pixel's own `μ₀ = n·l`, shadow ray and
    /// exit cosine `μ` — what a gather carrying each beam's single scattering apart would
    /// give, per pixel.
    pub single_scattering_law: bool,
    /// The axis of the deep field's exit law (`ExitLaw::flow`).
    pub exit_axis: ExitAxis,
    /// With single scattering marched per pixel (`BeamTableSettings::
    /// single_scattering_to_pixels`, the default): the plugin's march against each object's
    /// map of this many texels a side (`MarchedObject`, the twin of the GPU's); `None`: by
    /// rays, the oracle.
    pub shadow_map: Option<u32>,
    /// The gather's exit law takes each patch's irradiance direct and bounced as its own
    /// light (the plugin's, since 2026-11-29); `false`: its direct light alone, so that light
    /// bounced onto a translucent patch leaves by the law of light from elsewhere in the
    /// object (the plugin before).
    pub bounced_as_own: bool,
    /// The solve stops after this many bounces between patches (`None`: as many as its
    /// threshold takes; 0: none of the light that left comes back in).
    pub bounces: Option<u32>,
}

impl Oracles {
    /// The plugin's own stages throughout.
    pub const NONE: Self = Self {
        scattering: ScatteringSource::Profile,
        single_scattering_law: false,
        exit_axis: ExitAxis::Plugin,
        shadow_map: Some(PLUGIN_RESOLUTION),
        bounced_as_own: true,
        bounces: None,
    };
}

/// About which axis light from elsewhere leaves a translucent patch in the deep field's law.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExitAxis {
    /// The plugin's: with the beam table, the way the table's light flows in
    /// (`EnergyTransport::exit_laws_along_flow`: each source's contribution to the patch's
    /// exitance times the unit direction from its diffusion source, a reduced mean free path
    /// under its entry patch, summed); the normal without one. Weighted by `g = 1 − ν`.
    Plugin,
    /// The patch's normal, even with the table (the table's law before the flow).
    Normal,
    /// The normal, all light from elsewhere (`g = 1`).
    NormalAll,
    /// The table's flow, all light from elsewhere.
    FlowAll,
    /// With the beam table, a lobe fitted to the mean direction the table's early light
    /// leaves along (`EnergyTransport::exit_laws_along_lobes`).
    Lobe,
}

/// The plugin's picture of `view`'s shape of `medium` lit by `lighting`, at `budget`
/// patches, with `oracles` in place of its own stages; over a Lambertian floor of albedo
/// `floor` ([`Floor::under`] the shape) where given: patches of their own, the form factors
/// carrying light between it and the object both ways.
#[allow(clippy::too_many_arguments)]
pub fn plugin_picture(
    view: &ShapeView,
    medium: TranslucentMedium,
    oriented_dipole: bool,
    settings: &TransportSettings,
    gather: GatherMethod,
    budget: u32,
    lighting: SceneLighting,
    oracles: Oracles,
    floor: Option<f32>,
    occluder: Option<Occluder>,
    exact_exitance: Option<ExactExitance>,
) -> ShapePicture {
    let (floor_positions, floor_indices) = floor.map(|_| Floor::under(&view.positions).triangles()).unwrap_or_default();
    let (plate_positions, plate_indices) = occluder.map(|o| o.triangles()).unwrap_or_default();
    let mut views = vec![PatchObject {
        positions: &view.positions,
        indices: &view.indices,
    }];
    let mut surfaces = vec![PatchSurface::Translucent {
        medium,
        world_units_per_mm: WORLD_UNITS_PER_MM,
        oriented_dipole,
    }];
    if let Some(albedo) = floor {
        views.push(PatchObject {
            positions: &floor_positions,
            indices: &floor_indices,
        });
        surfaces.push(PatchSurface::Opaque { albedo: Vec3::splat(albedo) });
    }
    if occluder.is_some() {
        views.push(PatchObject {
            positions: &plate_positions,
            indices: &plate_indices,
        });
        surfaces.push(PatchSurface::Opaque { albedo: Vec3::ZERO });
    }
    // The object's patches and samples come first (patches are grouped by object).
    let surface_albedo = |q: &bevy_mesostructure::translucency::Patch| match surfaces[q.object as usize] {
        PatchSurface::Opaque { albedo } => albedo,
        PatchSurface::Translucent { .. } => Vec3::ZERO,
    };
    let (lights, ambient) = match lighting {
        SceneLighting::Directional(direction) => (
            vec![PatchLight::Directional {
                direction,
                illuminance: Vec3::ONE,
            }],
            Vec3::ZERO,
        ),
        SceneLighting::Point(position) => (
            vec![PatchLight::Point {
                position,
                intensity: Vec3::splat(position.length_squared()),
                range: 1e3,
            }],
            Vec3::ZERO,
        ),
        SceneLighting::Uniform => (Vec::new(), Vec3::splat(std::f32::consts::PI)),
    };
    let start = Instant::now();
    let patches = resample_into_patches(&views, budget as usize);
    let rays = SceneRays::new(&views);
    // The beam table is the oracles' to build (`ScatteringSource::BeamTable`: only the lit
    // patches' directions walked), whatever `settings` asks.
    let settings = &TransportSettings { beam_table: None, ..*settings };
    let mut transport = EnergyTransport::build(&patches, &surfaces, &rays, settings);
    // Each patch's launch: diffuse, the light's beam, or its beam snapped to a table's.
    // The walk oracles' one beam for every patch (a point light's beams differ by patch: the
    // table's alone take them, `beam_of`).
    // Light from everywhere has no one beam: diffuse walks.
    let beam = match lighting {
        SceneLighting::Directional(_) => lighting.travel_at(Vec3::ZERO),
        SceneLighting::Uniform | SceneLighting::Point(_) => None,
    };
    let beam_of = |q: &bevy_mesostructure::translucency::Patch| lighting.travel_at(q.centre);
    let walked = match (oracles.scattering, beam) {
        (ScatteringSource::Walks(walks), _)
        | (ScatteringSource::BeamWalks(walks), None)
        | (ScatteringSource::BinnedBeamWalks { walks, .. }, None) => Some((walks, None)),
        (ScatteringSource::BeamWalks(walks), Some(beam)) => Some((walks, Some((beam, None)))),
        (ScatteringSource::BinnedBeamWalks { walks, cosines, azimuths, .. }, Some(beam)) => {
            Some((walks, Some((beam, Some((cosines, azimuths))))))
        }
        (ScatteringSource::Profile, _) | (ScatteringSource::BeamTable(_), _) => None,
    };
    if let Some((walks, beam)) = walked {
        let p = &patches.patches;
        let launch = |j: usize| match beam {
            None => WalkLaunch::Diffuse,
            Some((beam, None)) => WalkLaunch::Beam(beam),
            Some((beam, Some((cosines, azimuths)))) => {
                WalkLaunch::Beam(binned_beam(beam, p[j].normal, cosines, azimuths))
            }
        };
        let (orders, late) = match oracles.scattering {
            ScatteringSource::BinnedBeamWalks { orders, late, late_walks, lit_face_single_to_law, .. }
                if beam.is_some() =>
            {
                (orders, (late, late_walks, lit_face_single_to_law))
            }
            // Every order: nothing is left inside.
            _ if beam.is_some() => (ScatteringOrders { first: 1, last: u32::MAX }, (LateLight::Profile, 0, false)),
            _ => (ScatteringOrders { first: 0, last: u32::MAX }, (LateLight::Profile, 0, false)),
        };
        let start = Instant::now();
        transport.scattering = walked_scattering(
            &patches,
            medium,
            WORLD_UNITS_PER_MM,
            &rays,
            walks,
            launch,
            orders,
            late,
            &transport.scattering,
        );
        let walked_patches = patches
            .patches
            .iter()
            .enumerate()
            .filter(|&(j, q)| match launch(j) {
                WalkLaunch::Beam(direction) => q.normal.dot(direction) < 0.0,
                WalkLaunch::Diffuse => true,
            })
            .count();
        eprintln!(
            "  walks: {walked_patches} patches facing their launch, {:.2} s on one thread",
            start.elapsed().as_secs_f32()
        );
        if beam.is_some() {
            // The beam's walks hold its incidence and its single scattering already.
            transport.incidence.iter_mut().for_each(|w| *w = None);
            transport.single_scattering.iter_mut().for_each(|s| *s = Vec3::ZERO);
        }
    }
    let table = match oracles.scattering {
        ScatteringSource::BeamTable(table_settings) if lighting != SceneLighting::Uniform => {
            // The walks hold the beam's incidence: no incidence weight on the object.
            transport.incidence.iter_mut().for_each(|w| *w = None);
            let only: Vec<Vec<u32>> = patches
                .patches
                .iter()
                .map(|q| {
                    // The floor's patches are opaque: the table walks the object's only.
                    if q.object != 0 {
                        return Vec::new();
                    }
                    let Some(travel) = beam_of(q) else { return Vec::new() };
                    let weights = direction_weights(travel, q.normal, table_settings.cosines, table_settings.azimuths);
                    let mut bins: Vec<u32> = weights.into_iter().flatten().filter(|&(_, w)| w > 0.0).map(|(b, _)| b).collect();
                    bins.sort_unstable();
                    bins.dedup();
                    bins
                })
                .collect();
            let (table, diffuse) =
                BeamTable::build_walked(&patches, &surfaces, &rays, &transport.scattering, table_settings, Some(&only));
            // As the plugin's transport: diffuse light entering a tabled patch by its walks
            // (`K` unchanged with `diffuse_columns_walked` off).
            transport.scattering = diffuse.scattering(&table, &transport.scattering);
            eprintln!("  beam table: {} patch-directions walked in {:.2} s", only.iter().map(Vec::len).sum::<usize>(), table.seconds);
            // From here on the plugin's own CPU oracle: the direct light into the table, the
            // solve, the gather with single scattering's law.
            transport.beam_table = Some(table);
            true
        }
        _ => false,
    };
    let precompute_s = start.elapsed().as_secs_f32();
    let mut direct = direct_light(&patches, Some(&transport), &lights, &rays);
    let media = transport.beam_table.as_ref().map(|t| t.patch_media()).unwrap_or_default();
    // All single scattering left out of the table for the pixels' own, marched (an oracle
    // of a per-pixel term): the half-space law at the lit face is not given as well.
    let marched = match (oracles.scattering, lighting) {
        (ScatteringSource::BeamTable(t), SceneLighting::Directional(travel)) if table && t.single_scattering_to_pixels => {
            Some(travel.normalize())
        }
        // The map's march only (`--marched-single-scattering`'s rays take a directional light).
        (ScatteringSource::BeamTable(t), SceneLighting::Point(position)) if table && t.single_scattering_to_pixels => {
            Some(-position.normalize_or_zero())
        }
        _ => None,
    };
    let single = (table && marched.is_none()).then(|| BeamSingleScattering {
        irradiance: &direct.beam_irradiance,
        direction: &direct.beam_direction,
        media: &media,
    });
    for e in &mut direct.irradiance {
        *e += ambient;
    }
    let bounces = oracles.bounces.unwrap_or(256);
    let mut solution = match exact_exitance.as_ref().and_then(|o| o.bounced_source) {
        // The plugin's bounce alone: the exact light that never came back in as `S⁰`, no
        // light into `K` or the table, bounced by the plugin's `F` and `K`.
        Some(source) => {
            let source = source(&patches);
            let unreturned = DirectLight { irradiance: vec![Vec3::ZERO; source.len()], exitance: source, ..default() };
            transport.solve_with(&unreturned, 1e-4, bounces)
        }
        None => transport.solve_with(&direct, 1e-4, bounces),
    };
    // An oracle: the exact transport's exitance on the plugin's own patches (single
    // scattering in it), compared with the plugin's and perhaps gathered in its place.
    let exact = exact_exitance.as_ref().map(|o| (o.trace)(&patches));
    let gathered = exact_exitance.as_ref().is_some_and(|o| o.gathered);
    if let Some(exact) = &exact {
        compare_exitance(&patches, &direct.irradiance, &solution.exitance, exact, view.shape.eye());
        if gathered {
            solution.exitance.copy_from_slice(exact);
        }
    }
    let single = if gathered { None } else { single };
    let albedo: Vec<Vec3> = patches.patches.iter().map(surface_albedo).collect();
    // The oracles of other axes keep the share `g` in the mode, as they were measured.
    let law_settings = TransportSettings {
        flow_law_takes_all: settings.flow_law_takes_all && matches!(oracles.exit_axis, ExitAxis::Plugin | ExitAxis::FlowAll),
        ..*settings
    };
    let mut exit_laws = transport.exit_laws(&patches, &surfaces, &law_settings);
    if matches!(oracles.exit_axis, ExitAxis::NormalAll | ExitAxis::FlowAll) {
        // All light from elsewhere takes the law, not the share `g` in the mode.
        for law in &mut exit_laws {
            law.channels.iter_mut().filter(|c| **c != Vec4::ZERO).for_each(|c| c.w = 1.0);
        }
    }
    let depths = EnergyTransport::source_depths(&patches, &surfaces);
    if matches!(oracles.exit_axis, ExitAxis::Plugin | ExitAxis::FlowAll | ExitAxis::Lobe) {
        exit_laws = transport.exit_laws_along_flow(&patches, &exit_laws, &direct, &depths);
    }
    if oracles.exit_axis == ExitAxis::Lobe {
        exit_laws = transport.exit_laws_along_lobes(&patches, &exit_laws, &direct, &solution.exitance, &depths);
    }
    let eye = view.shape.eye();
    // With a map: the plugin's own march (`MarchedObject`, in the gather's twin), unshadowed
    // (one object).
    // The exact exitance holds single scattering unless it was tallied after the first
    // scattering only: then the march gives it, as for the plugin's own `B`.
    let marched = if gathered && !exact_exitance.as_ref().is_some_and(|o| o.without_single_scattering) { None } else { marched };
    let marched_objects: Option<Vec<Option<MarchedObject>>> = marched.zip(oracles.shadow_map).map(|(_, resolution)| {
        let object_patches = patches.patches.iter().take_while(|q| q.object == 0).count();
        let object_samples = &patches.samples[..patches.sample_offsets[object_patches] as usize];
        // Each texel's light shadowed by the scene where an occluder can shadow it (as the
        // GPU's injection map does), else unshadowed (one object). The entry is the object's
        // first along the light's ray: lifted 1 mm towards the light, the ray is the same line.
        let visible = |entry: Vec3, light: &PatchLight| match (occluder, light) {
            (Some(_), PatchLight::Directional { direction, .. }) => {
                let to_light = -direction.normalize_or_zero();
                if rays.first_hit(entry + to_light * 1e-3, to_light).is_none() { 1.0 } else { 0.0 }
            }
            _ => 1.0,
        };
        vec![Some(MarchedObject::new(object_samples, MarchedMedium::new(&medium, WORLD_UNITS_PER_MM), &lights, resolution, visible))]
    });
    let pixels: Vec<Vec3> = view
        .hits
        .iter()
        .map(|hit| {
            hit.and_then(|hit| {
                gathered_radiance(
                    gather,
                    &patches,
                    &albedo,
                    &exit_laws,
                    &direct.irradiance,
                    if oracles.bounced_as_own { &solution.irradiance } else { &direct.irradiance },
                    &solution.exitance,
                    single.as_ref(),
                    marched_objects.as_deref(),
                    eye,
                    hit.point,
                    hit.normal,
                )
            })
            .unwrap_or(Vec3::ZERO)
        })
        .collect();
    let pixels: Vec<Vec3> = match (marched, &marched_objects) {
        (Some(_), Some(_)) | (None, _) => pixels,
        (Some(travel), None) => pixels
            .into_iter()
            .zip(&view.hits)
            .map(|(pixel, hit)| match hit {
                Some(hit) => pixel + marched_single_scattering(view.shape, &rays, medium, travel, hit),
                None => pixel,
            })
            .collect(),
    };
    let pixels = match lighting {
        SceneLighting::Directional(travel)
            if oracles.single_scattering_law && medium.index_of_refraction == 1.0 =>
        {
            single_scattering_law(&view.hits, pixels, medium, travel, &rays, true)
        }
        SceneLighting::Directional(travel)
            if matches!(oracles.scattering, ScatteringSource::BinnedBeamWalks { orders, lit_face_single_to_law, .. }
                if orders.first >= 2 || lit_face_single_to_law)
                && medium.index_of_refraction == 1.0 =>
        {
            single_scattering_law(&view.hits, pixels, medium, travel, &rays, false)
        }
        _ => pixels,
    };
    let n = patches.patches.len();
    ShapePicture {
        pixels,
        patches: n,
        object_patches: patches.patches.iter().filter(|q| q.object == 0).count(),
        precompute_s,
        memory_bytes: 8 * (2 * (n + 1))
            + 8 * transport.form_factors.entries()
            + 16 * transport.scattering.entries(),
        iterations: solution.iterations,
    }
}

/// Prints the plugin's exitance `plugin` over the exact one `exact`, patch by patch on the
/// first object, area-weighted: the transport alone, before any exit law or gather. Over
/// all its patches, and over those the light does not reach (`direct` zero) that face the
/// camera at `eye` — the light that crossed the object. The plugin's `B` leaves out the lit
/// face's single scattering, which its gather gives per pixel, so only the second compares
/// like with like.
fn compare_exitance(patches: &Patches, direct: &[Vec3], plugin: &[Vec3], exact: &[Vec3], eye: Vec3) {
    for (label, unlit_facing) in [("all", false), ("unlit, facing the camera", true)] {
        let (mut ours, mut theirs, mut apart) = (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
        for (i, q) in patches.patches.iter().enumerate() {
            if q.object != 0 || (unlit_facing && (direct[i] != Vec3::ZERO || q.normal.dot(eye - q.centre) <= 0.0)) {
                continue;
            }
            ours += q.area * plugin[i];
            theirs += q.area * exact[i];
            apart += q.area * (plugin[i] - exact[i]).abs();
        }
        let ratio = ours / theirs;
        eprintln!(
            "  the plugin's exitance over the exact, {label}: {:.3} / {:.3} / {:.3}, relative L1 {:.4}",
            ratio.x,
            ratio.y,
            ratio.z,
            apart.element_sum() / theirs.element_sum()
        );
    }
}

/// An oracle's exitance on the plugin's patches (`--exact-exitance`): how to trace it for
/// the patches, and whether the picture gathers it in place of the plugin's own or only
/// compares the two (printed).
pub struct ExactExitance<'a> {
    pub trace: PatchExitanceOracle<'a>,
    pub gathered: bool,
    /// It was tallied after more than one scattering (`--exact-exitance-after` ≥ 1): single
    /// scattering is the march's, as in the plugin's `B`, where the table leaves it to the
    /// pixels.
    pub without_single_scattering: bool,
    /// The exact exitance of light that never came back in, as the solve's source in place
    /// of the plugin's (`--exact-exitance-bounced`): the plugin's bounce alone against `trace`.
    pub bounced_source: Option<PatchExitanceOracle<'a>>,
}

/// An oracle's exitance on the plugin's patches, traced for them.
pub type PatchExitanceOracle<'a> = &'a dyn Fn(&Patches) -> Vec<Vec3>;

/// A picture against the reference over the scored pixels.
pub struct ShapeScore {
    /// `Σ|plugin − reference| / Σ reference`, all channels.
    pub rel_l1: f64,
    /// Mean plugin / mean reference per channel (a scale error shows here first).
    pub ratio: [f64; 3],
}

/// Scores `pixels` against `reference` over `view`'s scored pixels (both `view.size`²,
/// linear).
pub fn score(pixels: &[Vec3], reference: &image::Rgb32FImage, view: &ShapeView) -> ShapeScore {
    let (mut difference, mut total) = (0.0f64, 0.0f64);
    let mut sums = [[0.0f64; 2]; 3];
    let size = view.size;
    for i in (0..view.scored.len()).filter(|&i| view.scored[i]) {
        let (x, y) = (i as u32 % size, i as u32 / size);
        let ours = pixels[i];
        let theirs = reference.get_pixel(x, y).0;
        for c in 0..3 {
            difference += (ours[c] - theirs[c]).abs() as f64;
            total += theirs[c] as f64;
            sums[c][0] += ours[c] as f64;
            sums[c][1] += theirs[c] as f64;
        }
    }
    ShapeScore {
        rel_l1: difference / total.max(1e-30),
        ratio: sums.map(|[a, b]| a / b.max(1e-30)),
    }
}
