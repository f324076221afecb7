//! The plugin set of a headless run, shared by the examples (`common`) and the integration
//! tests (`tests/integration/harness.rs` includes this file by path).

use bevy::{
    prelude::*,
    render::{RenderPlugin, pipelined_rendering::PipelinedRenderingPlugin},
    window::ExitCondition,
};

/// Bevy's plugins for a run without a window: no event loop (there may be no display to
/// connect to), frames driven one by one by the caller, pipelines compiled before the first
/// frame that needs them.
pub fn headless_plugins() -> bevy::app::PluginGroupBuilder {
    DefaultPlugins
        .set(WindowPlugin {
            primary_window: None,
            exit_condition: ExitCondition::DontExit,
            ..default()
        })
        .set(RenderPlugin {
            synchronous_pipeline_compilation: true,
            ..default()
        })
        .disable::<bevy::winit::WinitPlugin>()
        .disable::<PipelinedRenderingPlugin>()
}
