//! The render world's side of the camera settings: [`ViewSettings`], one camera's
//! [`Mesostructure`] resolved (quality, debug view, baseline) and sanitized, the "which passes
//! run" logic, and the uniform the shaders read. `settings.rs` keeps only the public components.

use bevy::{prelude::*, render::render_resource::ShaderType};

use crate::{
    reference::{DepthContinuity, OcclusionForm, sample_directions},
    settings::{
        HorizonSearchBaseline, Mesostructure, MesostructureDebugView, WorkingResolution,
    },
};

/// The settings of one view as the render world uses them ([`ViewSettings::resolve`]): the
/// quality's values, the debug view and the baseline in one flat, sanitized struct. Its fields
/// are those of [`Mesostructure`], [`crate::MesostructureCost`], [`MesostructureDebugView`] and
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
    pub texture_space_bounce: bool,
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
    /// The settings one view of a camera with `m` renders with: the quality resolved, the camera's debug view and
    /// horizon-search baseline merged in, every field inside its documented range; the names
    /// of the fields that had to be changed.
    pub fn resolve(
        m: &Mesostructure,
        debug_view: MesostructureDebugView,
        baseline: Option<HorizonSearchBaseline>,
    ) -> (Self, Vec<&'static str>) {
        let d = Mesostructure::default();
        let cost = m.quality.cost();
        let mut s = Self {
            debug_view,
            apex_directions: cost.apex_directions,
            max_ascent_steps: cost.max_ascent_steps,
            max_sample_radius: cost.max_sample_radius,
            working_resolution: cost.working_resolution,
            depth_discontinuity: m.depth_discontinuity,
            occlusion: m.occlusion,
            occlusion_form: m.occlusion_form,
            horizon_search_steps: baseline.map_or(0, |b| b.steps),
            coarse_occlusion: m.coarse_occlusion,
            texture_space_horizons: m.texture_space_horizons,
            texture_space_bounce: m.texture_space_bounce,
            micro_shadows: m.micro_shadows,
            micro_shadow_softness: m.micro_shadow_softness,
            bump_mapping: m.bump_mapping,
            bleeding: m.bleeding,
            bleeding_samples: cost.bleeding_samples,
            ambient_weight: m.ambient_weight,
            direct_weight: m.direct_weight,
            bleeding_weight: m.bleeding_weight,
        };
        let mut changed = Vec::new();
        let mut clamp_u32 = |v: &mut u32, name: &'static str| {
            let (lo, hi) = Mesostructure::range(name).expect("a documented range");
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
            let (lo, hi) = Mesostructure::range(name).expect("a documented range");
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

    /// Whether the lighting (micro-shadows) or the bleeding pass reads the sector records,
    /// which the occlusion pass then stores.
    pub fn needs_sector_horizons(&self) -> bool {
        self.micro_shadows || self.bleeding_runs()
    }

    /// Whether the occlusion pass runs: for the ambient occlusion or the sector records.
    pub fn occlusion_pass_runs(&self) -> bool {
        self.occlusion || self.needs_sector_horizons()
    }

    /// Whether the settings ask for bleeding at all (a zero weight costs nothing either).
    pub fn bleeding_runs(&self) -> bool {
        self.bleeding && self.bleeding_weight > 0.0
    }

    /// Whether the first directional light's bounce comes from texture space: asked for, and
    /// both the texture-space horizons and the bleeding run.
    pub fn texture_space_bounce_runs(&self) -> bool {
        self.texture_space_bounce && self.texture_space_horizons && self.bleeding_runs()
    }

    /// The depth-continuity test these settings describe.
    pub fn depth_continuity(&self) -> DepthContinuity {
        DepthContinuity {
            relative: self.depth_discontinuity,
            ..default()
        }
    }
}

/// Render-world copy of a camera's resolved settings ([`ViewSettings::resolve`]).
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
    /// Whether the first directional light's bounce comes from texture space (1) or not (0).
    pub texture_space_bounce: u32,
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
            texture_space_bounce: s.texture_space_bounce_runs() as u32,
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
        crate::render::ViewMesostructureUniformOffset,
        crate::render::CaptureComponents,
        (
            crate::render::lighting::ViewLightingPipeline,
            crate::render::lighting::compute::ViewComputeLighting,
        ),
        // Each pass's images and bind groups.
        crate::render::height::ViewHeightTextures,
        (
            crate::render::gradient::ViewGradientMap,
            crate::render::gradient::ViewGradientBindGroup,
        ),
        (
            crate::render::apex::ViewApexSets,
            crate::render::apex::ViewApexBindGroup,
        ),
        (
            crate::render::occlusion::ViewOcclusionTextures,
            crate::render::occlusion::ViewOcclusionBindGroup,
        ),
        crate::render::lighting::ViewMicroShadowTexture,
        crate::render::bleeding::ViewBleedingTexture,
        crate::render::debug_view::ViewDebugViewBindGroup,
    );
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{MesostructureCost, MesostructureQuality, reference::MAX_APEX_DIRECTIONS};

    fn resolved(m: &Mesostructure) -> (ViewSettings, Vec<&'static str>) {
        ViewSettings::resolve(m, MesostructureDebugView::None, None)
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
        let (baseline, changed) = ViewSettings::resolve(
            &Mesostructure::default(),
            MesostructureDebugView::None,
            Some(HorizonSearchBaseline { steps: 0 }),
        );
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
