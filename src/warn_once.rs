//! One-time warnings: bad input is reported once per cause, then handled quietly.

use bevy::{platform::collections::HashSet, prelude::*};

/// Keys of the warnings already given (main world and render world each have one).
#[derive(Resource, Default)]
pub struct WarnedOnce(HashSet<String>);

impl WarnedOnce {
    /// Logs `message` as a warning the first time `key` is seen; returns whether it did.
    pub fn warn(&mut self, key: impl Into<String>, message: impl FnOnce() -> String) -> bool {
        if self.0.insert(key.into()) {
            warn!("bevy_mesostructure: {}", message());
            true
        } else {
            false
        }
    }

    /// The keys of the warnings given so far (for tests: each names its cause).
    pub fn keys(&self) -> impl Iterator<Item = String> + '_ {
        self.0.iter().cloned()
    }

    /// Forgets `key`, so that the cause is reported again if it comes back.
    pub fn forget(&mut self, key: &str) {
        self.0.remove(key);
    }
}
