//! CPU tests of the translucency precompute and iteration, by stage: the profiles against
//! their closed forms ([`profiles`]), the patches' areas and count ([`patches`]), the form
//! factors' reciprocity, energy in a closed box and the iteration against a dense solve
//! ([`energy`]), media and the random walks ([`media`]), the cache and the gather's grid
//! ([`cache_and_gather`]), the beam table ([`beam_table`]), the translucent shadow map and
//! single scattering marched against it ([`shadow_map`]), the solve in an object's shape and
//! the laws light leaves a patch by ([`shape_and_exits`]).

mod beam_table;
mod cache_and_gather;
mod energy;
mod lights;
mod media;
mod patches;
mod profiles;
mod shadow_map;
mod shape_and_exits;

use bevy::prelude::*;
use std::f64::consts::PI;

use super::{
    diffusion::{
        DiffusionKernel, DiffusionProfile, diffuse_fresnel_reflectance,
        jensen_internal_diffuse_reflectance,
    },
    medium::{TranslucentMedium, TranslucentPreset},
    patches::{PatchObject, resample_into_patches, world_triangles},
    transport::{
        EnergyTransport, PatchLight, PatchSurface, SceneRays, TransportSettings, direct_irradiance,
    },
};
use crate::volumetric::reference::gauss_legendre_64;

fn mesh_object(mesh: Mesh, transform: Transform) -> (Vec<Vec3>, Vec<u32>) {
    world_triangles(&mesh, &GlobalTransform::from(transform)).expect("a triangle list")
}

/// The objects as the patch resampler takes them.
fn views_of(objects: &[(Vec<Vec3>, Vec<u32>)]) -> Vec<PatchObject<'_>> {
    objects
        .iter()
        .map(|o| PatchObject {
            positions: &o.0,
            indices: &o.1,
        })
        .collect()
}

fn inside_out(mut object: (Vec<Vec3>, Vec<u32>)) -> (Vec<Vec3>, Vec<u32>) {
    for t in object.1.chunks_mut(3) {
        t.swap(1, 2);
    }
    object
}
