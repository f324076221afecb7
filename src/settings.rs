//! The per-camera settings component.

use bevy::{
    camera::Hdr,
    core_pipeline::prepass::{DeferredPrepass, DepthPrepass},
    prelude::*,
};

use crate::reference::{
    ApexSearch, DepthContinuity, MAX_APEX_DIRECTIONS, OcclusionForm,
};

/// Mesostructure lighting for a 3D camera: add it next to [`Camera3d`].
///
/// Every mesh with a [`MesostructureMaterial`](crate::MesostructureMaterial) that this camera
/// sees gets a screen-space height map (MHM), its gradient map (MHGM) and per-pixel local apex
/// sets (paper §2), from which the lighting terms are computed.
///
/// Needs [`Msaa::Off`] (like Bevy's SSAO and deferred rendering): Bevy itself turns MSAA off,
/// with a warning, on cameras with a deferred prepass, which this component pulls in; should
/// MSAA still be on, the effect is off for that camera with a one-time warning. Pulls in the depth and
/// deferred prepasses: mesostructure meshes are rendered deferred and lit by a lighting pass of
/// the plugin's own (their `StandardMaterial` is swapped for a copy with its own deferred
/// lighting pass id; other meshes keep forward or deferred as they were). A second camera
/// with a deferred prepass but without this component leaves those meshes unlit.
///
/// Also pulls in [`Hdr`]: the bleeding is gathered from, and added to, linear radiance before
/// tonemapping (without `Hdr`, Bevy tonemaps inside the lighting shaders).
///
/// Out-of-range values are clamped to their documented range and non-finite ones replaced by the
/// default, with a one-time warning; they never reach the GPU.
#[derive(Component, Reflect, Clone, Debug, PartialEq)]
#[reflect(Component, Default, Clone, Debug, PartialEq)]
#[require(DepthPrepass, DeferredPrepass, Hdr)]
pub struct Mesostructure {
    /// Cost against accuracy: a preset ([`MesostructureQuality::High`] by default) or
    /// [`MesostructureQuality::Custom`] values of the apex search and the bleeding gather
    /// ([`MesostructureCost`]). `docs/accuracy.md` and `docs/bench.md` give each preset's error
    /// and GPU time.
    pub quality: MesostructureQuality,
    /// Relative depth jump (fraction of NDC depth, 0.0001–1) above which two neighbouring pixels
    /// of the same object count as separated (a depth discontinuity ends the visible region).
    pub depth_discontinuity: f32,
    /// Compute the mesostructure ambient occlusion from the apex sets (paper §3.1).
    pub occlusion: bool,
    /// The integral that turns horizon angles into occlusion: the physically based
    /// cosine-weighted form (default) or the paper's eq. (6).
    pub occlusion_form: OcclusionForm,
    /// Multiply the mesostructure occlusion with a coarse horizon-based AO on the depth buffer
    /// (Bavoil et al. 2008), whose step is the adaptive `(min + max) / 2` of the pixel's apex
    /// distances (paper §3.1): the occlusion of the core geometry around the bumps. Pixels
    /// without apexes get none, so a flat height map stays neutral.
    pub coarse_occlusion: bool,
    /// Use the texture-space horizon map (built once per height map at load; in texture space,
    /// so it holds on deforming meshes) for the ambient occlusion — of the true surface about
    /// its true normal, the mean over each pixel's footprint where the map is minified — for
    /// the micro-shadows of the first directional light, and for the solid angle the bounce
    /// gather stands for. Off: the paper's screen-space terms from the apex sets alone, which
    /// the filtered heights of minified, oblique and grazing views flatten (docs/accuracy.md,
    /// "Unseen content").
    pub texture_space_horizons: bool,
    /// With `texture_space_horizons` and `bleeding`: the first directional light's one bounce
    /// from the texture-space horizon map (16 azimuths × 6 points of the true surface a pixel;
    /// view-independent, so it holds where the view is minified or oblique), the screen-space
    /// gather keeping the other lights' bounce. Relative error on the unseen-content suite
    /// 0.37 against 0.58 for the gather alone; it is most of the height pass's cost (2.9× the
    /// passes' time on the software driver), so it can be turned off on its own
    /// (docs/accuracy.md, "The bounce from texture space").
    pub texture_space_bounce: bool,
    /// Shadows of the bumps on the surface from directional, point and spot lights (paper
    /// §3.2), inside the regions Bevy's shadow maps light.
    pub micro_shadows: bool,
    /// Width of the micro-shadow edge, as a difference of sines of elevation (0–0.5): 0 is the
    /// paper's hard test; a little softness hides aliasing of the horizon. Never wider than the
    /// horizon itself, so that an open profile leaves grazing light unshadowed.
    pub micro_shadow_softness: f32,
    /// Shade mesostructure surfaces with the normal of the height map (Blinn bump mapping)
    /// where their material has no normal map of its own.
    pub bump_mapping: bool,
    /// One-bounce colour bleeding (paper §3.3, eq. 8): light reflected by the directly lit
    /// bumps onto their neighbours.
    pub bleeding: bool,
    /// λa of paper eq. (2): weight of ambient and environment light (0–4; 1 = physical).
    pub ambient_weight: f32,
    /// λs of paper eq. (2): weight of direct light from directional, point and spot lights
    /// (0–4; 1 = physical).
    pub direct_weight: f32,
    /// λd of paper eq. (2): weight of the one-bounce bleeding (0–4; 1 = physical).
    pub bleeding_weight: f32,
}

impl Default for Mesostructure {
    /// The `High` preset (see [`MesostructureCost`]), a 2 % depth jump, which keeps planes at
    /// grazing angles connected (the slope test covers them) but separates overlapping parts
    /// of one object. Every effect on; weights 1 (eq. 2 with physical weights: the result
    /// approximates a path tracer's one-bounce image).
    fn default() -> Self {
        Self {
            quality: MesostructureQuality::High,
            depth_discontinuity: 0.02,
            occlusion: true,
            occlusion_form: OcclusionForm::CosineWeighted,
            coarse_occlusion: true,
            texture_space_horizons: true,
            texture_space_bounce: true,
            micro_shadows: true,
            micro_shadow_softness: 0.05,
            bump_mapping: true,
            bleeding: true,
            ambient_weight: 1.0,
            direct_weight: 1.0,
            bleeding_weight: 1.0,
        }
    }
}

/// What a quality level sets: the size of the apex search and of the bleeding gather (see
/// [`MesostructureQuality`]). The work of one apex search is at most
/// `max_ascent_steps + 2 × apex_directions × max_sample_radius` texel reads, once per
/// `working_resolution` block.
#[derive(Reflect, Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[reflect(Default, Clone, Debug, PartialEq, Hash)]
pub struct MesostructureCost {
    /// The resolution the apex sets are searched at: every pixel (`Full`, the paper's), or once
    /// per 2×2 (`Half`) or 4×4 (`Quarter`) block of pixels, whose pixels then share that set
    /// (the apex search is the largest pass; it costs about a quarter or a sixteenth). The
    /// occlusion, micro-shadows and bleeding stay per pixel: each measures its own horizons
    /// against the shared apexes. Pixels across a depth jump or on another object than the
    /// block's searched pixel get no apexes.
    pub working_resolution: WorkingResolution,
    /// Indirect sample directions around each pixel for its apex set (0–16). More directions
    /// find more of the apexes that occlude a pixel, at a cost linear in the count.
    pub apex_directions: u32,
    /// Bound on the steps (one pixel each) of the gradient ascent to the direct apex (1–512).
    /// Where it is hit the pixel reached stands in for the apex; the `ApexCount` debug view
    /// shows those pixels in magenta.
    pub max_ascent_steps: u32,
    /// How far, in pixels (1–256), each direction's walk from the pixel goes looking for the
    /// valley beyond which something stands up, and how far the climb along the direction then
    /// goes to that structure's apex. Both stop on their own (where the height first rises,
    /// where it stops rising), so the apex set adapts to the size of the structures; this only
    /// bounds them.
    pub max_sample_radius: u32,
    /// Samples (1–16) along the path from a pixel to each apex of its set that the bleeding
    /// gathers from. Cost is linear in the count.
    pub bleeding_samples: u32,
}

impl Default for MesostructureCost {
    /// The `High` preset's: 8 directions (the paper's "several directions", one per
    /// 8-neighbour direction), 64 ascent steps (enough for structures up to ~64 px across, a
    /// quarter of a 256² texture cache), walks of up to 32 px, apex sets per pixel, 4 bleeding
    /// samples per apex path (which resolve the walls of a groove to a few percent of a
    /// 16-sample gather).
    fn default() -> Self {
        MesostructureQuality::High.cost()
    }
}

impl MesostructureCost {
    /// The valid range of each field, `(name, min, max)`: what the plugin clamps to, and what
    /// an inspector's sliders should offer.
    pub const RANGES: [(&'static str, f32, f32); 4] = [
        ("apex_directions", 0.0, MAX_APEX_DIRECTIONS as f32),
        ("max_ascent_steps", 1.0, 512.0),
        ("max_sample_radius", 1.0, 256.0),
        ("bleeding_samples", 1.0, 16.0),
    ];
}

/// A brute-force horizon search instead of the apex sets for the occlusion — `steps` samples
/// (1–64) along each of `apex_directions` directions out to `max_sample_radius` pixels: a
/// fixed-radius baseline for comparisons (the `accuracy` example), not a quality setting. Add
/// it to a camera next to [`Mesostructure`].
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq, Eq)]
#[reflect(Component, Clone, Debug, PartialEq)]
pub struct HorizonSearchBaseline {
    /// Samples per direction (1–64).
    pub steps: u32,
}

/// The resolution the apex sets are searched at (see [`MesostructureCost::working_resolution`]).
#[derive(Reflect, Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[reflect(Default, Clone, Debug, PartialEq, Hash)]
pub enum WorkingResolution {
    /// One apex set per pixel (the paper's).
    #[default]
    Full,
    /// One apex set per 2×2 pixels.
    Half,
    /// One apex set per 4×4 pixels.
    Quarter,
}

impl WorkingResolution {
    /// All of them, finest first.
    pub const ALL: [Self; 3] = [Self::Full, Self::Half, Self::Quarter];

    /// Side, in pixels, of the block that shares one apex set.
    pub fn block(self) -> u32 {
        match self {
            Self::Full => 1,
            Self::Half => 2,
            Self::Quarter => 4,
        }
    }

    /// The name in lower case (`half`), for command lines and file names.
    pub fn name(self) -> &'static str {
        match self {
            Self::Full => "full",
            Self::Half => "half",
            Self::Quarter => "quarter",
        }
    }
}

/// Quality levels: the settings that trade cost for accuracy ([`MesostructureCost`]),
/// together — four presets, or `Custom` values. `docs/accuracy.md` charts each preset's error
/// and GPU time.
#[derive(Reflect, Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[reflect(Default, Clone, Debug, PartialEq, Hash)]
pub enum MesostructureQuality {
    /// Apex sets per 4×4 pixels, 4 directions, walks of 16 px, 32 ascent steps, 2 bleeding
    /// samples.
    Low,
    /// Apex sets per 2×2 pixels, otherwise as `High`.
    Medium,
    /// The default: apex sets per pixel, 8 directions, walks of 32 px, 64 ascent steps, 4
    /// bleeding samples.
    #[default]
    High,
    /// Apex sets per pixel, 16 directions, walks of 64 px, 128 ascent steps, 8 bleeding samples.
    Ultra,
    /// Values of your own (clamped to [`MesostructureCost::RANGES`]).
    Custom(MesostructureCost),
}

impl MesostructureQuality {
    /// The presets, cheapest first.
    pub const ALL: [Self; 4] = [Self::Low, Self::Medium, Self::High, Self::Ultra];

    /// What this level sets.
    pub fn cost(self) -> MesostructureCost {
        let (working_resolution, apex_directions, max_ascent_steps, max_sample_radius, bleeding_samples) =
            match self {
                Self::Low => (WorkingResolution::Quarter, 4, 32, 16, 2),
                Self::Medium => (WorkingResolution::Half, 8, 64, 32, 4),
                Self::High => (WorkingResolution::Full, 8, 64, 32, 4),
                Self::Ultra => (WorkingResolution::Full, 16, 128, 64, 8),
                Self::Custom(cost) => return cost,
            };
        MesostructureCost {
            working_resolution,
            apex_directions,
            max_ascent_steps,
            max_sample_radius,
            bleeding_samples,
        }
    }

    /// `Custom` values: this level's, changed by `change` (e.g. `High.custom(|c|
    /// c.apex_directions = 16)`).
    pub fn custom(self, change: impl FnOnce(&mut MesostructureCost)) -> Self {
        let mut cost = self.cost();
        change(&mut cost);
        Self::Custom(cost)
    }

    /// The name in lower case (`medium`; `custom`), for command lines and file names.
    pub fn name(self) -> &'static str {
        match self {
            Self::Low => "low",
            Self::Medium => "medium",
            Self::High => "high",
            Self::Ultra => "ultra",
            Self::Custom(_) => "custom",
        }
    }

    /// The preset of a [`Self::name`] (`custom` names no preset).
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|q| q.name() == name)
    }
}

/// Which image a camera with [`Mesostructure`] shows instead of (or over) the lit scene: add
/// it to the camera (absent: the normal picture).
#[derive(Component, Reflect, Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[reflect(Component, Default, Clone, Debug, PartialEq, Hash)]
pub enum MesostructureDebugView {
    /// The normal picture.
    #[default]
    None,
    /// The height-map value `dis ∈ [0, 1]` seen through the UVs, grey.
    Height,
    /// The gradient direction as red/green (0.5 = 0), grey where it is zero.
    Gradient,
    /// Distance to the direct apex, in pixels: dark blue (near) to yellow (32 px and more);
    /// black where the pixel is itself at an apex.
    ApexDistance,
    /// Number of apexes in the set: dark (1) to white (all directions); black for none;
    /// magenta where an ascent hit `max_ascent_steps`.
    ApexCount,
    /// Boundary points: red at silhouettes and other objects, green at depth discontinuities,
    /// blue at the screen edge; dark grey inside the visible region.
    Boundary,
    /// The mesostructure ambient occlusion, grey (white = open, black = closed).
    Occlusion,
    /// The micro-shadow visibility, grey (white = lit, black = shadowed by the bumps), the
    /// lowest over the lights.
    MicroShadow,
    /// The one-bounce bleeding added to the picture, ×4 so that it shows.
    Bleeding,
}

impl MesostructureDebugView {
    /// All views, in the order a key cycles them.
    pub const ALL: [Self; 9] = [
        Self::None,
        Self::Height,
        Self::Gradient,
        Self::ApexDistance,
        Self::ApexCount,
        Self::Boundary,
        Self::Occlusion,
        Self::MicroShadow,
        Self::Bleeding,
    ];

    /// The next view in [`Self::ALL`], wrapping around.
    pub fn next(self) -> Self {
        let i = Self::ALL.iter().position(|v| *v == self).unwrap_or(0);
        Self::ALL[(i + 1) % Self::ALL.len()]
    }

    /// The view's name in kebab case (`apex-distance`), for command lines and file names.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::Height => "height",
            Self::Gradient => "gradient",
            Self::ApexDistance => "apex-distance",
            Self::ApexCount => "apex-count",
            Self::Boundary => "boundary",
            Self::Occlusion => "occlusion",
            Self::MicroShadow => "micro-shadow",
            Self::Bleeding => "bleeding",
        }
    }

    /// The view of a [`Self::name`].
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|v| v.name() == name)
    }

    /// Shader-side code of the view.
    pub(crate) fn code(self) -> u32 {
        Self::ALL.iter().position(|v| *v == self).unwrap_or(0) as u32
    }
}

impl Mesostructure {
    /// The valid range of each numeric field, `(name, min, max)`: what the plugin clamps to,
    /// and what an inspector's sliders should offer (the quality's own in
    /// [`MesostructureCost::RANGES`]).
    pub const RANGES: [(&'static str, f32, f32); 5] = [
        ("depth_discontinuity", 0.0001, 1.0),
        ("micro_shadow_softness", 0.0, 0.5),
        ("ambient_weight", 0.0, 4.0),
        ("direct_weight", 0.0, 4.0),
        ("bleeding_weight", 0.0, 4.0),
    ];

    /// The valid range of the numeric field `name` of these settings or of their
    /// [`MesostructureCost`] (see [`Self::RANGES`]).
    pub fn range(name: &str) -> Option<(f32, f32)> {
        Self::RANGES
            .iter()
            .chain(MesostructureCost::RANGES.iter())
            .chain([("horizon_search_steps", 1.0, 64.0)].iter())
            .find(|(n, _, _)| *n == name)
            .map(|&(_, lo, hi)| (lo, hi))
    }

    /// The apex search these settings describe (for the CPU oracle).
    pub fn apex_search(&self) -> ApexSearch {
        let cost = self.quality.cost();
        ApexSearch {
            directions: cost.apex_directions,
            max_steps: cost.max_ascent_steps,
            max_walk: cost.max_sample_radius,
        }
    }

    /// The depth-continuity test these settings describe (for the CPU oracle).
    pub fn depth_continuity(&self) -> DepthContinuity {
        DepthContinuity {
            relative: self.depth_discontinuity,
            ..default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_range_names_a_field_and_holds_its_default() {
        use bevy::reflect::{Reflect, structs::Struct};
        let number = |value: &dyn PartialReflect, name: &str| {
            value
                .try_downcast_ref::<f32>()
                .copied()
                .or(value.try_downcast_ref::<u32>().map(|&u| u as f32))
                .unwrap_or_else(|| panic!("{name} is not a number"))
        };
        let d = Mesostructure::default();
        let cost = MesostructureCost::default();
        for (name, lo, hi) in Mesostructure::RANGES {
            let v = number(d.field(name).unwrap_or_else(|| panic!("no field {name}")), name);
            assert!((lo..=hi).contains(&v), "default {name} = {v} outside {lo}..={hi}");
        }
        for (name, lo, hi) in MesostructureCost::RANGES {
            let v = number(cost.field(name).unwrap_or_else(|| panic!("no field {name}")), name);
            assert!((lo..=hi).contains(&v), "default {name} = {v} outside {lo}..={hi}");
        }
        let _ = d.as_reflect();
    }

    #[test]
    fn presets_and_custom_values() {
        assert_eq!(MesostructureCost::default(), MesostructureQuality::High.cost());
        assert_eq!(Mesostructure::default().quality, MesostructureQuality::High);
        for q in MesostructureQuality::ALL {
            assert_eq!(MesostructureQuality::from_name(q.name()), Some(q));
        }
        let custom = MesostructureQuality::Low.custom(|c| c.apex_directions = 6);
        assert_eq!(custom.cost().working_resolution, WorkingResolution::Quarter);
        assert_eq!((custom.cost().apex_directions, custom.name()), (6, "custom"));
        assert_eq!(MesostructureQuality::from_name("custom"), None);
        assert_eq!(
            MesostructureDebugView::Bleeding.next(),
            MesostructureDebugView::None
        );
        for view in MesostructureDebugView::ALL {
            assert_eq!(MesostructureDebugView::from_name(view.name()), Some(view));
        }
    }
}
