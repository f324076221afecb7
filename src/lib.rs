//! # bevy_mesostructure
//!
//! Real-time lighting of the detailed surface that a low-polygon mesh with a height map stands
//! for: ambient occlusion among the bumps, their shadows and one-bounce colour bleeding, on
//! dynamic and deforming meshes, with no precomputation. It implements Wang, Yang, Ma and Zhao,
//! "Real-Time Global Illumination Rendering for Mesostructure Surface Based on Gradient Map"
//! (Journal of Software 22(10), 2011): a screen-space height map (MHM), its gradient map (MHGM)
//! and per-pixel local apex sets, from which the lighting terms follow.
//!
//! ## Quick start
//! ```no_run
//! use bevy::prelude::*;
//! use bevy_mesostructure::prelude::*;
//!
//! fn main() {
//!     App::new()
//!         .add_plugins((DefaultPlugins, MesostructurePlugin))
//!         .add_systems(Startup, setup)
//!         .run();
//! }
//!
//! fn setup(
//!     mut commands: Commands,
//!     mut meshes: ResMut<Assets<Mesh>>,
//!     mut materials: ResMut<Assets<StandardMaterial>>,
//!     asset_server: Res<AssetServer>,
//! ) {
//!     commands.spawn((
//!         Camera3d::default(),
//!         Msaa::Off,
//!         Mesostructure::default(),
//!         Transform::from_xyz(0.0, 2.0, 3.0).looking_at(Vec3::ZERO, Vec3::Y),
//!     ));
//!     commands.spawn((
//!         Mesh3d(meshes.add(Sphere::new(1.0))),
//!         MeshMaterial3d(materials.add(Color::WHITE)),
//!         MesostructureMaterial {
//!             height_map: asset_server.load("height_maps/bricks.png"),
//!             scale: 0.1,
//!             ..default()
//!         },
//!     ));
//! }
//! ```
//!
//! ## What runs
//! Per camera with [`Mesostructure`], between Bevy's prepass and its main pass: the height pass
//! (only meshes with [`MesostructureMaterial`]), the gradient pass, the apex pass and the
//! occlusion pass; in the main pass, a deferred lighting pass of the plugin's own for the
//! mesostructure pixels (Bevy's BRDF, shadow maps and lights, with the occlusion on ambient light
//! and the micro-shadows on each light) and, after the opaque pass, the bleeding pass. See
//! `src/render/` (a folder per pass). [`reference`](mod@reference) is the same method in plain
//! Rust, the oracle of the GPU tests.
//!
//! ## Sub-plugins
//! [`volumetric::VolumetricSpotsPlugin`]: spot lights seen in a homogeneous medium, by
//! equal-angle single scattering (seed 004), with or without the mesostructure plugin.
//! [`translucency::TranslucencyPlugin`]: translucent objects lit globally by seed 001's
//! radiosity with subsurface transport (patches precomputed for static scenes, the iteration on
//! the GPU when a light changes, a per-pixel gather), with or without the mesostructure plugin.
//!
//! ## Bad input
//! Missing or still-loading height maps, unsupported formats, meshes without UVs or normals,
//! scales that are not finite and positive, MSAA on the camera, zero-sized viewports: each gets
//! one warning, and the mesh or camera renders as it would without the plugin. The causes
//! reported so far are listed by the [`MesostructureWarnings`] resource.
//!
//! ## Settings
//! [`Mesostructure::quality`] sets what trades cost for accuracy ([`MesostructureQuality`]:
//! the presets `Low`, `Medium`, `High` = default, `Ultra`, or `Custom` values of
//! [`MesostructureCost`]); among them [`WorkingResolution`], which searches the apex sets — the
//! largest pass — once per pixel or once per 2×2 or 4×4 block. `docs/accuracy.md` and
//! `docs/bench.md` give each preset's error and GPU time. A [`MesostructureDebugView`] next to
//! the camera's [`Mesostructure`] shows an intermediate image instead of the lit scene.
//!
//! Every field of [`Mesostructure`] and [`MesostructureMaterial`] is documented with its unit and
//! range ([`Mesostructure::RANGES`], [`MesostructureCost::RANGES`]); each effect switches off by itself and then costs nothing
//! (with every term off and no bump mapping, no pass runs at all). The weights λa, λs, λd of the
//! paper's eq. (2) are `ambient_weight`, `direct_weight` and `bleeding_weight`.
//!
//! ## Limits
//! Silhouettes are not displaced; near the screen edge and behind other objects the occluders
//! of a point may be out of sight and the effect fades; horizons are measured from the local
//! tangent plane, so structures as large as the core's curvature over-darken; structures
//! narrower than about two pixels fade to the filtered height map. The README says what to do
//! about each; `docs/accuracy.md` has the measured errors.

#![deny(missing_docs)]
// Bevy's system parameters and queries are long types and many arguments by nature (Bevy
// allows both lints itself), and `!(x > 0.0)` is how this crate rejects NaN with the rest.
#![allow(
    clippy::type_complexity,
    clippy::too_many_arguments,
    clippy::neg_cmp_op_on_partial_ord
)]

pub mod height_map_import;
pub mod height_maps;
pub mod material;
pub mod reference;
mod render;
pub mod settings;
pub mod translucency;
pub mod volumetric;
mod warn_once;

pub use warn_once::MesostructureWarnings;

use bevy::{
    prelude::*,
    render::{extract_component::ExtractComponentPlugin, sync_component::SyncComponentPlugin},
};

pub use material::{MesostructureMaterial, MesostructureStatus};
pub use render::{MesostructureSystems, lighting::MESOSTRUCTURE_LIGHTING_PASS_ID};
#[cfg(feature = "oracle")]
pub use render::capture::{CapturedFrame, MesostructureCapture, MesostructureCaptures};
pub use settings::{
    HorizonSearchBaseline, Mesostructure, MesostructureCost, MesostructureDebugView,
    MesostructureQuality, WorkingResolution,
};

/// Everything an app needs.
pub mod prelude {
    pub use crate::{
        Mesostructure, MesostructureCost, MesostructureDebugView, MesostructureMaterial,
        MesostructurePlugin, MesostructureQuality, MesostructureStatus, WorkingResolution,
        height_maps::HeightMap,
    };
}

/// Adds mesostructure lighting: put [`Mesostructure`] on a camera and
/// [`MesostructureMaterial`] on meshes.
#[derive(Default)]
pub struct MesostructurePlugin;

impl Plugin for MesostructurePlugin {
    fn build(&self, app: &mut App) {
        // One set of warning causes for both worlds, readable as `MesostructureWarnings`.
        warn_once::install(app);
        app.register_type::<Mesostructure>()
            .register_type::<MesostructureQuality>()
            .register_type::<MesostructureCost>()
            .register_type::<MesostructureDebugView>()
            .register_type::<HorizonSearchBaseline>()
            .register_type::<MesostructureMaterial>()
            .init_resource::<material::HeightMapMips>()
            .init_resource::<MesostructureStatus>()
            .init_resource::<material::AdaptedMaterials>()
            .add_plugins((
                SyncComponentPlugin::<Mesostructure>::default(),
                ExtractComponentPlugin::<material::PreparedMesostructure>::default(),
            ))
            .add_systems(
                PostUpdate,
                (
                    (
                        material::prepare_mesostructure_materials,
                        material::adapt_standard_materials,
                    )
                        .chain(),
                    render::request_storage_main_textures::<Mesostructure>,
                ),
            );
        render::build(app);
    }
}
