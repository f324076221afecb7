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

/// Whether `app` is still settling: a height map still being built (its meshes are drawn
/// without the effect) or a pipeline still compiling (a pass that needs it is skipped or runs
/// in its other form — the lighting pass is raster until its compute form has compiled).
/// Frames meant to show or time the effect wait for neither. (Not every file that includes
/// this one needs it.)
#[allow(dead_code)]
pub fn settling(app: &App) -> bool {
    use bevy::render::render_resource::{CachedPipelineState, PipelineCache};
    let compiling = app.get_sub_app(bevy::render::RenderApp).is_some_and(|render| {
        render.world().get_resource::<PipelineCache>().is_some_and(|cache| {
            cache.pipelines().any(|p| {
                !matches!(p.state, CachedPipelineState::Ok(_) | CachedPipelineState::Err(_))
            })
        })
    });
    compiling || bevy_mesostructure::MesostructureStatus::building(app.world())
}
