//! Translucent objects lit globally: seed 001's radiosity with dipole subsurface transport
//! (Wang, Shi, Wang and Zhao, patent CN102819860, 2012).
//!
//! The method, in three steps:
//! 1. **Precompute**, once per static scene: resample every object into near-uniform patches
//!    ([`patches`]); build a sparse energy-transport operator — the dipole diffusion profile
//!    between patches of one translucent object ([`diffusion`]) and radiosity form factors
//!    between patches that see each other ([`transport`]).
//! 2. **Per frame**: inject the lights' direct irradiance into the patches, then iterate
//!    `B ← K E⁰ + K F B` (the seed's `L = (S F)^N S L`) until the energy still moving falls
//!    below a threshold.
//! 3. Turn each patch's exitance into the picture.
//!
//! What exists so far is the CPU side of steps 1 and 2 — patches, profiles, the sparse
//! operators and their iteration, the direct light with ray-traced visibility — tested against
//! the profiles' closed forms, reciprocity, energy conservation in a closed box and a dense
//! solve. The GPU injection and iteration, the step into Bevy's lighting and the
//! `TranslucencyPlugin` are not built yet (`docs/translucent.md` says what is measured).

pub mod diffusion;
pub mod medium;
pub mod patches;
pub mod transport;

#[cfg(test)]
mod tests;

pub use diffusion::{DiffusionKernel, DiffusionProfile};
pub use medium::{TranslucentMedium, TranslucentPreset};
pub use patches::{Patch, PatchObject, Patches, resample_into_patches};
pub use transport::{
    EnergyTransport, PatchLight, PatchSurface, SceneRays, SparseMatrix, TransportReport,
    TransportSettings, TransportSolution, direct_irradiance,
};
