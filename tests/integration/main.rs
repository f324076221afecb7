//! The one integration-test binary (each test binary links all of Bevy): GPU contract tests
//! against the CPU oracle, deformation, and bad input, all headless on the software driver.

mod bad_input;
mod bleeding;
mod closed_forms;
mod coarse;
mod contract;
mod deformation;
mod files;
mod harness;
mod lighting;
// The examples' mesh loading (the translucent room's bunny).
#[path = "../../examples/common/meshes.rs"]
#[allow(dead_code)]
mod meshes;
mod micro_shadows;
mod stability;
mod unseen;
mod translucency;
mod volumetric;
