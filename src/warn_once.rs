//! One-time warnings: bad input is reported once per cause, then handled quietly.

use std::sync::{Arc, Mutex, PoisonError};

use bevy::{platform::collections::HashSet, prelude::*};

/// The causes reported so far, shared by the main and the render world.
type Causes = Arc<Mutex<HashSet<String>>>;

/// Gives each warning once per cause (main world and render world each hold one handle on the
/// same set of causes).
#[derive(Resource, Default, Clone)]
pub(crate) struct WarnedOnce(Causes);

impl WarnedOnce {
    /// Logs `message` as a warning the first time `key` is seen; returns whether it did.
    pub fn warn(&mut self, key: impl Into<String>, message: impl FnOnce() -> String) -> bool {
        let new = self
            .0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .insert(key.into());
        if new {
            warn!("bevy_mesostructure: {}", message());
        }
        new
    }

    /// Forgets `key`, so that the cause is reported again if it comes back.
    pub fn forget(&mut self, key: &str) {
        self.0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .remove(key);
    }
}

/// Installs one [`WarnedOnce`] shared by the main and render worlds, and its public view
/// [`MesostructureWarnings`], unless an earlier plugin of this crate did.
pub(crate) fn install(app: &mut App) {
    if app.world().contains_resource::<WarnedOnce>() {
        return;
    }
    let warned = WarnedOnce::default();
    app.insert_resource(MesostructureWarnings::of(&warned))
        .insert_resource(warned.clone());
    if let Some(render_app) = app.get_sub_app_mut(bevy::render::RenderApp) {
        render_app.insert_resource(warned);
    }
}

/// The causes of the plugin's one-time warnings given so far (bad settings, unusable height
/// maps or meshes, cameras the effect cannot run on), main and render world together: each is
/// a short key naming the cause and the entity or asset, e.g. `"msaa 12v0"`. A cause that goes
/// away (the camera's MSAA turned off) is forgotten, so that it is reported again if it comes
/// back. For a debug overlay, or a test that bad input was reported.
#[derive(Resource, Clone)]
pub struct MesostructureWarnings(Causes);

impl MesostructureWarnings {
    pub(crate) fn of(warned: &WarnedOnce) -> Self {
        Self(warned.0.clone())
    }

    /// The causes reported so far and not forgotten, sorted.
    pub fn causes(&self) -> Vec<String> {
        let mut causes: Vec<String> = self
            .0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .iter()
            .cloned()
            .collect();
        causes.sort();
        causes
    }
}
