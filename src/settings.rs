//! The per-camera settings component.

use bevy::{
    camera::Hdr,
    core_pipeline::prepass::{DeferredPrepass, DepthPrepass},
    prelude::*,
    render::render_resource::ShaderType,
};

use crate::reference::{
    ApexSearch, DepthContinuity, MAX_APEX_DIRECTIONS, OcclusionForm, sample_directions,
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

/// The resolution the apex sets are searched at (see [`Mesostructure::working_resolution`]).
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

    /// The settings one view renders with: the quality resolved, the camera's debug view and
    /// horizon-search baseline merged in, every field inside its documented range; the names
    /// of the fields that had to be changed.
    pub fn resolve(
        &self,
        debug_view: MesostructureDebugView,
        baseline: Option<HorizonSearchBaseline>,
    ) -> (ViewSettings, Vec<&'static str>) {
        let d = Self::default();
        let cost = self.quality.cost();
        let mut s = ViewSettings {
            debug_view,
            apex_directions: cost.apex_directions,
            max_ascent_steps: cost.max_ascent_steps,
            max_sample_radius: cost.max_sample_radius,
            working_resolution: cost.working_resolution,
            depth_discontinuity: self.depth_discontinuity,
            occlusion: self.occlusion,
            occlusion_form: self.occlusion_form,
            horizon_search_steps: baseline.map_or(0, |b| b.steps),
            coarse_occlusion: self.coarse_occlusion,
            texture_space_horizons: self.texture_space_horizons,
            micro_shadows: self.micro_shadows,
            micro_shadow_softness: self.micro_shadow_softness,
            bump_mapping: self.bump_mapping,
            bleeding: self.bleeding,
            bleeding_samples: cost.bleeding_samples,
            ambient_weight: self.ambient_weight,
            direct_weight: self.direct_weight,
            bleeding_weight: self.bleeding_weight,
        };
        let mut changed = Vec::new();
        let mut clamp_u32 = |v: &mut u32, name: &'static str| {
            let (lo, hi) = Self::range(name).expect("a documented range");
            let (lo, hi) = (lo as u32, hi as u32);
            if *v < lo || *v > hi {
                *v = (*v).clamp(lo, hi);
                changed.push(name);
            }
        };
        clamp_u32(&mut s.apex_directions, "apex_directions");
        clamp_u32(&mut s.max_ascent_steps, "max_ascent_steps");
        clamp_u32(&mut s.max_sample_radius, "max_sample_radius");
        clamp_u32(&mut s.bleeding_samples, "bleeding_samples");
        if baseline.is_some() {
            clamp_u32(&mut s.horizon_search_steps, "horizon_search_steps");
        }
        let mut clamp_f32 = |v: &mut f32, default: f32, name: &'static str| {
            let (lo, hi) = Self::range(name).expect("a documented range");
            if !v.is_finite() {
                *v = default;
                changed.push(name);
            } else if !(lo..=hi).contains(v) {
                *v = v.clamp(lo, hi);
                changed.push(name);
            }
        };
        clamp_f32(&mut s.ambient_weight, d.ambient_weight, "ambient_weight");
        clamp_f32(&mut s.direct_weight, d.direct_weight, "direct_weight");
        clamp_f32(&mut s.bleeding_weight, d.bleeding_weight, "bleeding_weight");
        clamp_f32(
            &mut s.micro_shadow_softness,
            d.micro_shadow_softness,
            "micro_shadow_softness",
        );
        clamp_f32(
            &mut s.depth_discontinuity,
            d.depth_discontinuity,
            "depth_discontinuity",
        );
        (s, changed)
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

/// The settings of one view as the render world uses them ([`Mesostructure::resolve`]): the
/// quality's values, the debug view and the baseline in one flat, sanitized struct. Its fields
/// are those of [`Mesostructure`], [`MesostructureCost`], [`MesostructureDebugView`] and
/// [`HorizonSearchBaseline`].
#[derive(Clone, Debug, PartialEq)]
#[allow(missing_docs)]
pub struct ViewSettings {
    pub debug_view: MesostructureDebugView,
    pub apex_directions: u32,
    pub max_ascent_steps: u32,
    pub max_sample_radius: u32,
    pub working_resolution: WorkingResolution,
    pub depth_discontinuity: f32,
    pub occlusion: bool,
    pub occlusion_form: OcclusionForm,
    /// 0: the apex sets.
    pub horizon_search_steps: u32,
    pub coarse_occlusion: bool,
    pub texture_space_horizons: bool,
    pub micro_shadows: bool,
    pub micro_shadow_softness: f32,
    pub bump_mapping: bool,
    pub bleeding: bool,
    pub bleeding_samples: u32,
    pub ambient_weight: f32,
    pub direct_weight: f32,
    pub bleeding_weight: f32,
}

impl ViewSettings {
    /// Whether a frame needs the gradient map and the apex sets: a lighting term or a debug
    /// view reads them. With none, the gradient and apex passes do not run.
    pub fn needs_apex_sets(&self) -> bool {
        (self.occlusion && self.horizon_search_steps == 0)
            || self.micro_shadows
            || self.bleeding_runs()
            || self.debug_view != MesostructureDebugView::None
    }

    /// Whether a frame needs the height pass: the apex sets or the bump-mapped normal read its
    /// images. With neither, no mesostructure pass runs and the surfaces are lit as by Bevy.
    pub fn needs_height_map(&self) -> bool {
        self.needs_gradient_map() || self.bump_mapping
    }

    /// Whether a frame needs the gradient map (its connectivity flags give the surface normal
    /// N'): the apex sets, or the brute-force horizon search.
    pub fn needs_gradient_map(&self) -> bool {
        self.needs_apex_sets() || self.occlusion
    }

    /// Whether the settings ask for bleeding at all (a zero weight costs nothing either).
    pub fn bleeding_runs(&self) -> bool {
        self.bleeding && self.bleeding_weight > 0.0
    }

    /// The depth-continuity test these settings describe.
    pub fn depth_continuity(&self) -> DepthContinuity {
        DepthContinuity {
            relative: self.depth_discontinuity,
            ..default()
        }
    }
}

/// Render-world copy of a camera's resolved settings ([`Mesostructure::resolve`]).
#[derive(Component, Clone, Debug)]
pub struct ExtractedMesostructure(pub ViewSettings);

/// The camera settings as the shaders see them (`MesostructureUniform` in `common.wgsl`).
#[derive(Clone, Copy, Debug, ShaderType)]
pub struct MesostructureUniform {
    /// Indirect sample directions.
    pub apex_directions: u32,
    /// Step bound of one ascent.
    pub max_ascent_steps: u32,
    /// Longest valley walk, pixels.
    pub max_walk: u32,
    /// Steps of the brute-force horizon search (0 = apex sets).
    pub horizon_search_steps: u32,
    /// Relative depth jump of a discontinuity.
    pub depth_relative: f32,
    /// Slope factor of the depth-continuity test.
    pub depth_slope_factor: f32,
    /// `MesostructureDebugView` code.
    pub debug_view: u32,
    /// Words per pixel in the apex buffer.
    pub apex_stride: u32,
    /// `OcclusionForm` code.
    pub occlusion_form: u32,
    /// Whether the occlusion pass runs (1) or not (0).
    pub occlusion_enabled: u32,
    /// Whether micro-shadows are applied (1) or not (0).
    pub micro_shadows: u32,
    /// Softness of the micro-shadow edge, in sine of elevation.
    pub micro_shadow_softness: f32,
    /// Whether the bump-mapped normal shades the surface (1) or not (0).
    pub bump_mapping: u32,
    /// Whether the bleeding pass runs (1) or not (0).
    pub bleeding_enabled: u32,
    /// Samples per apex path of the bleeding gather.
    pub bleeding_samples: u32,
    /// Whether the coarse depth-buffer AO multiplies the occlusion (1) or not (0).
    pub coarse_occlusion: u32,
    /// Whether the texture-space horizon map's terms are used (1) or not (0).
    pub texture_space_horizons: u32,
    /// Side of the pixel block sharing one apex set (the working resolution).
    pub apex_block: u32,
    /// λa, λs, λd of eq. (2), and one spare float.
    pub weights: Vec4,
    /// `(cos θ_i, sin θ_i)` of the sample directions, two per vector.
    pub directions: [Vec4; 8],
}

impl From<&ViewSettings> for MesostructureUniform {
    fn from(s: &ViewSettings) -> Self {
        let table = sample_directions(s.apex_directions);
        let mut directions = [Vec4::ZERO; 8];
        for (i, d) in table.iter().enumerate() {
            let v = &mut directions[i / 2];
            if i % 2 == 0 {
                v.x = d[0];
                v.y = d[1];
            } else {
                v.z = d[0];
                v.w = d[1];
            }
        }
        let continuity = s.depth_continuity();
        Self {
            apex_directions: s.apex_directions,
            max_ascent_steps: s.max_ascent_steps,
            max_walk: s.max_sample_radius,
            horizon_search_steps: s.horizon_search_steps,
            depth_relative: continuity.relative,
            depth_slope_factor: continuity.slope_factor,
            debug_view: s.debug_view.code(),
            apex_stride: crate::reference::packed::stride(s.apex_directions),
            occlusion_form: s.occlusion_form.code(),
            occlusion_enabled: s.occlusion as u32,
            micro_shadows: s.micro_shadows as u32,
            micro_shadow_softness: s.micro_shadow_softness,
            bump_mapping: s.bump_mapping as u32,
            bleeding_enabled: s.bleeding_runs() as u32,
            bleeding_samples: s.bleeding_samples,
            coarse_occlusion: s.coarse_occlusion as u32,
            texture_space_horizons: s.texture_space_horizons as u32,
            apex_block: s.working_resolution.block(),
            weights: Vec4::new(s.ambient_weight, s.direct_weight, s.bleeding_weight, 0.0),
            directions,
        }
    }
}

/// Extraction runs our own system (validation, one-time warnings); this impl only lets
/// `SyncComponentPlugin` remove the render-world components with the main one.
impl bevy::render::sync_component::SyncComponent for Mesostructure {
    type Target = (
        ExtractedMesostructure,
        crate::render::ViewMesostructureTextures,
        crate::render::ViewMesostructureBindGroups,
        crate::render::ViewMesostructureUniformOffset,
        crate::render::capture::ExtractedCapture,
        crate::render::lighting::ViewLightingPipeline,
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    fn resolved(m: &Mesostructure) -> (ViewSettings, Vec<&'static str>) {
        m.resolve(MesostructureDebugView::None, None)
    }

    #[test]
    fn sanitize_replaces_nan_and_clamps() {
        let bad = Mesostructure {
            quality: MesostructureQuality::High.custom(|c| {
                c.apex_directions = 99;
                c.max_ascent_steps = 0;
                c.max_sample_radius = 0;
                c.bleeding_samples = 0;
            }),
            depth_discontinuity: f32::NAN,
            bleeding_weight: f32::INFINITY,
            direct_weight: -1.0,
            ..default()
        };
        let (s, changed) = resolved(&bad);
        assert_eq!(s.apex_directions, MAX_APEX_DIRECTIONS);
        assert_eq!(s.max_ascent_steps, 1);
        assert_eq!(s.max_sample_radius, 1);
        assert_eq!(s.depth_discontinuity, 0.02);
        assert!(changed.contains(&"depth_discontinuity"));
        assert_eq!((s.bleeding_weight, s.direct_weight), (1.0, 0.0));
        assert_eq!(s.bleeding_samples, 1);
        assert!(resolved(&Mesostructure::default()).1.is_empty());
        let (baseline, changed) = Mesostructure::default()
            .resolve(MesostructureDebugView::None, Some(HorizonSearchBaseline { steps: 0 }));
        assert_eq!((baseline.horizon_search_steps, changed), (1, vec!["horizon_search_steps"]));
    }

    #[test]
    fn presets_stay_in_range_and_high_is_the_default() {
        assert_eq!(MesostructureCost::default(), MesostructureQuality::High.cost());
        assert_eq!(Mesostructure::default().quality, MesostructureQuality::High);
        let mut previous_cost = 0;
        for q in MesostructureQuality::ALL {
            let m = Mesostructure {
                quality: q,
                micro_shadows: false,
                ..default()
            };
            let (s, changed) = resolved(&m);
            assert!(changed.is_empty(), "{q:?} leaves a range");
            assert!(!s.micro_shadows, "a preset touched an effect switch");
            assert_eq!(MesostructureQuality::from_name(q.name()), Some(q));
            // The bound on texel reads of one apex search, per pixel.
            let block = s.working_resolution.block();
            let cost = (s.max_ascent_steps + 2 * s.apex_directions * s.max_sample_radius) * 16
                / (block * block);
            assert!(
                cost > previous_cost,
                "{q:?} is not dearer than the preset before"
            );
            previous_cost = cost;
        }
        let custom = MesostructureQuality::Low.custom(|c| c.apex_directions = 6);
        assert_eq!(custom.cost().working_resolution, WorkingResolution::Quarter);
        assert_eq!((custom.cost().apex_directions, custom.name()), (6, "custom"));
        assert_eq!(MesostructureQuality::from_name("custom"), None);
        let low = Mesostructure {
            quality: MesostructureQuality::Low,
            ..default()
        };
        assert_eq!(MesostructureUniform::from(&resolved(&low).0).apex_block, 4);
    }

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
    fn uniform_carries_the_direction_table() {
        let m = Mesostructure {
            quality: MesostructureQuality::High.custom(|c| c.apex_directions = 4),
            ..default()
        };
        let u = MesostructureUniform::from(&resolved(&m).0);
        assert!((u.directions[0].x - 1.0).abs() < 1e-6);
        assert!((u.directions[0].w - 1.0).abs() < 1e-6); // θ_1 = 90°
        assert_eq!(u.apex_stride, 6);
        assert_eq!(
            MesostructureDebugView::Bleeding.next(),
            MesostructureDebugView::None
        );
        for view in MesostructureDebugView::ALL {
            assert_eq!(MesostructureDebugView::from_name(view.name()), Some(view));
        }
    }
}
