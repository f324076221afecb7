//! The volumetric spots' data on the render side: each camera's medium and the spots,
//! extracted with validation (bad values warn once and fall back), culled per view against its
//! frustum, and written into each view's uniform.

use bevy::{
    camera::Camera3d,
    pbr::GlobalClusterableObjectMeta,
    prelude::*,
    render::{
        Extract,
        render_resource::*,
        renderer::{RenderDevice, RenderQueue},
        sync_component::SyncComponent,
        sync_world::RenderEntity,
        view::Msaa,
    },
};

use super::{MAX_VOLUMETRIC_SPOTS, VolumetricMedium, VolumetricSpot, render::ViewVolumetricPipeline};
use crate::warn_once::WarnedOnce;

/// The render world's copy of a camera's medium, sanitized, and the camera's frustum (to cull
/// the spots whose cones it does not see).
#[derive(Component, Clone, Copy, Debug)]
pub struct ExtractedVolumetricMedium {
    /// The medium.
    pub medium: VolumetricMedium,
    /// The camera's view frustum.
    pub frustum: bevy::camera::primitives::Frustum,
    /// The camera's view-projection.
    pub clip_from_world: Mat4,
}

impl SyncComponent for VolumetricMedium {
    type Target = (
        ExtractedVolumetricMedium,
        ViewVolumetricPipeline,
        ViewVolumetricUniformOffset,
    );
}

/// One spot as the shader reads it.
#[derive(Clone, Copy, Debug, Default, ShaderType)]
pub struct GpuVolumetricSpot {
    /// Position, range.
    pub position_range: Vec4,
    /// Unit axis, samples.
    pub direction_samples: Vec4,
    /// Linear colour × intensity (candela) × `intensity_scale`.
    pub color: Vec4,
    /// cos(outer angle), Bevy's spot scale and offset, the light's index in Bevy's clustered
    /// lights where its shadow map is sampled (−1: no shadow map).
    pub cone: Vec4,
    /// The part of the view the cone can cover, in NDC: (min x, min y, max x, max y) — its
    /// bounding sphere's projection; pixels outside skip the spot.
    pub screen_rect: Vec4,
    /// A sphere around the cone out to its range (centre, radius): where the slicing planes
    /// go.
    pub bounds: Vec4,
}

/// One spot of this frame.
#[derive(Clone, Copy, Debug)]
pub struct ExtractedVolumetricSpot {
    /// What the shader reads (its shadow-map index still to be filled in).
    pub gpu: GpuVolumetricSpot,
    /// Its render-world entity.
    pub entity: Entity,
    /// Whether it casts shadows.
    pub shadows: bool,
    /// A sphere bounding its cone out to its range: views whose frustum misses it skip it.
    pub bounds: bevy::camera::primitives::Sphere,
}

/// The spots of this frame.
#[derive(Resource, Default)]
pub struct ExtractedVolumetricSpots(pub Vec<ExtractedVolumetricSpot>);

/// The NDC rectangle (min x, min y, max x, max y) that a sphere can cover in a view with
/// `clip_from_world`: the projections of its bounding box's corners; the whole view where a
/// corner lies behind the camera's plane.
pub fn screen_rect(sphere: &bevy::camera::primitives::Sphere, clip_from_world: Mat4) -> Vec4 {
    let whole = Vec4::new(-1.0, -1.0, 1.0, 1.0);
    let (mut lo, mut hi) = (Vec2::splat(f32::INFINITY), Vec2::splat(f32::NEG_INFINITY));
    let center = Vec3::from(sphere.center);
    for i in 0..8 {
        let corner = center
            + Vec3::new(
                if i & 1 == 0 { -1.0 } else { 1.0 },
                if i & 2 == 0 { -1.0 } else { 1.0 },
                if i & 4 == 0 { -1.0 } else { 1.0 },
            ) * sphere.radius;
        let clip = clip_from_world * corner.extend(1.0);
        if !(clip.w > 1e-6) {
            return whole;
        }
        let ndc = clip.truncate().truncate() / clip.w;
        lo = lo.min(ndc);
        hi = hi.max(ndc);
    }
    Vec4::new(lo.x.max(-1.0), lo.y.max(-1.0), hi.x.min(1.0), hi.y.min(1.0))
}

/// The smallest sphere around a cone of half-angle `angle` and length `length` from `apex`
/// along the unit `axis`: about the far disc's centre for wide cones, else through the apex and
/// the far rim.
pub fn cone_bounds(apex: Vec3, axis: Vec3, angle: f32, length: f32) -> bevy::camera::primitives::Sphere {
    let (center, radius) = if angle > std::f32::consts::FRAC_PI_4 {
        (apex + axis * length * angle.cos(), length * angle.sin())
    } else {
        let r = length / (2.0 * angle.cos() * angle.cos());
        (apex + axis * r, r)
    };
    bevy::camera::primitives::Sphere {
        center: center.into(),
        radius,
    }
}

/// What the shader reads for one view: the medium and the spots.
#[derive(Clone, Copy, ShaderType)]
pub struct VolumetricUniform {
    /// σs, σa, g, number of spots.
    pub medium: Vec4,
    /// The spots (the first `medium.w` are used).
    pub spots: [GpuVolumetricSpot; MAX_VOLUMETRIC_SPOTS],
}

/// The views' uniforms.
#[derive(Resource, Default)]
pub struct VolumetricUniforms(pub DynamicUniformBuffer<VolumetricUniform>);

/// Offset of a view's [`VolumetricUniform`], and how many spots the view sees.
#[derive(Component, Clone, Copy)]
pub struct ViewVolumetricUniformOffset {
    /// Dynamic offset.
    pub offset: u32,
    /// Spots whose cones are in the view's frustum.
    pub spots: u32,
    /// Whether the medium dims what lies behind it (σt > 0): then the pass runs even with no
    /// cone in view, so that surfaces do not brighten when the last spot leaves the view.
    pub dims: bool,
}

fn finite_at_least(v: f32, min: f32, default: f32) -> (f32, bool) {
    if v.is_finite() {
        (v.max(min), v < min)
    } else {
        (default, true)
    }
}

/// Copies each camera's medium after checking it; bad values get one warning and a sane
/// fallback (their defaults or the nearest valid value); MSAA turns the effect off for that
/// camera, with a warning.
pub fn extract_volumetric_cameras(
    mut commands: Commands,
    cameras: Extract<
        Query<
            (
                RenderEntity,
                Entity,
                &Camera,
                &VolumetricMedium,
                Option<&Msaa>,
                &bevy::camera::primitives::Frustum,
                &GlobalTransform,
            ),
            With<Camera3d>,
        >,
    >,
    mut warned: ResMut<WarnedOnce>,
) {
    for (render_entity, entity, camera, medium, msaa, frustum, transform) in &cameras {
        let Ok(mut target) = commands.get_entity(render_entity) else {
            continue;
        };
        let size = camera.physical_viewport_size();
        if !camera.is_active || size.is_none_or(|s| s.x == 0 || s.y == 0) {
            target.remove::<ExtractedVolumetricMedium>();
            continue;
        }
        if msaa.is_some_and(|m| *m != Msaa::Off) {
            warned.warn(format!("volumetric msaa {entity}"), || {
                format!("camera {entity} has VolumetricMedium but MSAA is on; the volumetric spots need Msaa::Off and are off until then")
            });
            target.remove::<ExtractedVolumetricMedium>();
            continue;
        }
        warned.forget(&format!("volumetric msaa {entity}"));
        let d = VolumetricMedium::default();
        let (scattering, bad_s) = finite_at_least(medium.scattering, 0.0, d.scattering);
        let (absorption, bad_a) = finite_at_least(medium.absorption, 0.0, d.absorption);
        let asymmetry = if medium.asymmetry.is_finite() {
            medium.asymmetry.clamp(-0.95, 0.95)
        } else {
            d.asymmetry
        };
        if bad_s || bad_a || asymmetry != medium.asymmetry {
            warned.warn(format!("volumetric medium {entity}"), || {
                format!(
                    "camera {entity}: VolumetricMedium {medium:?} has negative or non-finite \
                     coefficients or |g| > 0.95; using σs {scattering}, σa {absorption}, g {asymmetry}"
                )
            });
        }
        target.insert(ExtractedVolumetricMedium {
            medium: VolumetricMedium {
                scattering,
                absorption,
                asymmetry,
                resolution: medium.resolution,
                method: medium.method,
            },
            frustum: *frustum,
            clip_from_world: camera.clip_from_view() * transform.to_matrix().inverse(),
        });
    }
}

/// Collects the visible spots with [`VolumetricSpot`]; a cone angle of 0 (or NaN) drops the
/// spot, one of 90° or more is narrowed to 89°, other bad values fall back to the defaults —
/// each with one warning.
pub fn extract_volumetric_spots(
    lights: Extract<
        Query<(
            Entity,
            RenderEntity,
            &SpotLight,
            &GlobalTransform,
            &VolumetricSpot,
            Option<&ViewVisibility>,
        )>,
    >,
    mut spots: ResMut<ExtractedVolumetricSpots>,
    mut warned: ResMut<WarnedOnce>,
) {
    spots.0.clear();
    for (entity, render_entity, light, transform, volumetric, visibility) in &lights {
        if visibility.is_some_and(|v| !v.get()) || light.intensity <= 0.0 {
            continue;
        }
        let max_outer = 89f32.to_radians();
        let outer = light.outer_angle;
        if !(outer > 0.0) || !light.intensity.is_finite() || !light.range.is_finite() {
            warned.warn(format!("volumetric spot {entity}"), || {
                format!(
                    "spot light {entity}: outer angle {outer}, intensity {} or range {} cannot \
                     light a medium; its volumetric light is off",
                    light.intensity, light.range
                )
            });
            continue;
        }
        let outer = if outer >= max_outer {
            warned.warn(format!("volumetric spot angle {entity}"), || {
                format!(
                    "spot light {entity}: an outer angle of {:.1}° is not a cone; its \
                     volumetric light uses 89°",
                    outer.to_degrees()
                )
            });
            max_outer
        } else {
            outer
        };
        let inner = if light.inner_angle.is_finite() {
            light.inner_angle.clamp(0.0, outer)
        } else {
            0.0
        };
        let (scale, bad_scale) = finite_at_least(volumetric.intensity_scale, 0.0, 1.0);
        let samples = volumetric.samples.clamp(1, super::MAX_VOLUMETRIC_SAMPLES);
        if bad_scale || samples != volumetric.samples {
            warned.warn(format!("volumetric spot settings {entity}"), || {
                format!(
                    "spot light {entity}: VolumetricSpot {volumetric:?} out of range; using \
                     intensity_scale {scale}, samples {samples}"
                )
            });
        }
        if spots.0.len() == MAX_VOLUMETRIC_SPOTS {
            warned.warn("volumetric spot count", || {
                format!("more than {MAX_VOLUMETRIC_SPOTS} spots have VolumetricSpot; the rest are skipped")
            });
            break;
        }
        // As Bevy lights surfaces (`render/light.rs`): candela = lumens / 4π, and the spot
        // fall-off saturate(cos ψ · scale + offset)².
        let candela = light.intensity / (4.0 * std::f32::consts::PI) * scale;
        let color = light.color.to_linear().to_vec3() * candela;
        let cos_outer = outer.cos();
        let spot_scale = 1.0 / (inner.cos() - cos_outer).max(1e-4);
        let spot = GpuVolumetricSpot {
            position_range: transform.translation().extend(light.range.max(0.0)),
            direction_samples: transform.forward().as_vec3().extend(samples as f32),
            color: color.extend(0.0),
            cone: Vec4::new(cos_outer, spot_scale, -cos_outer * spot_scale, -1.0),
            // Per view, in `prepare_volumetric_uniforms`.
            screen_rect: Vec4::new(-1.0, -1.0, 1.0, 1.0),
            bounds: Vec4::ZERO,
        };
        let axis = transform.forward().as_vec3();
        spots.0.push(ExtractedVolumetricSpot {
            gpu: spot,
            entity: render_entity,
            shadows: light.shadow_maps_enabled,
            bounds: cone_bounds(transform.translation(), axis, outer, light.range.max(0.0)),
        });
    }
}

/// Writes each view's uniform, with each shadowed spot's index in Bevy's clustered lights (known
/// once Bevy has prepared its lights) for its shadow map.
pub fn prepare_volumetric_uniforms(
    mut commands: Commands,
    mut uniforms: ResMut<VolumetricUniforms>,
    spots: Res<ExtractedVolumetricSpots>,
    clusterables: Option<Res<GlobalClusterableObjectMeta>>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    views: Query<(Entity, &ExtractedVolumetricMedium)>,
) {
    let Some(mut writer) = uniforms.0.get_writer(views.iter().len(), &device, &queue) else {
        return;
    };
    for (entity, view) in &views {
        // The spots whose cones this camera sees (a bounding sphere against its frustum).
        let mut gpu_spots = [GpuVolumetricSpot::default(); MAX_VOLUMETRIC_SPOTS];
        let mut count = 0;
        for spot in &spots.0 {
            if !view.frustum.intersects_sphere(&spot.bounds, false) {
                continue;
            }
            let mut gpu = spot.gpu;
            gpu.screen_rect = screen_rect(&spot.bounds, view.clip_from_world);
            gpu.bounds = Vec3::from(spot.bounds.center).extend(spot.bounds.radius);
            if let Some(index) = clusterables
                .as_ref()
                .filter(|_| spot.shadows)
                .and_then(|c| c.entity_to_index.get(&spot.entity))
            {
                gpu.cone.w = *index as f32;
            }
            gpu_spots[count] = gpu;
            count += 1;
        }
        let m = view.medium;
        let offset = writer.write(&VolumetricUniform {
            medium: Vec4::new(m.scattering, m.absorption, m.asymmetry, count as f32),
            spots: gpu_spots,
        });
        commands.entity(entity).insert(ViewVolumetricUniformOffset {
            offset,
            spots: count as u32,
            dims: m.scattering + m.absorption > 0.0,
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_screen_rect_holds_the_sphere_and_falls_back_to_the_whole_view() {
        let clip_from_view = Mat4::perspective_infinite_reverse_rh(0.8, 1.5, 0.1);
        let view_from_world =
            Transform::from_xyz(0.0, 1.0, 6.0).looking_at(Vec3::ZERO, Vec3::Y).to_matrix().inverse();
        let clip_from_world = clip_from_view * view_from_world;
        let sphere = bevy::camera::primitives::Sphere {
            center: Vec3::new(0.5, 0.2, 0.0).into(),
            radius: 0.3,
        };
        let rect = screen_rect(&sphere, clip_from_world);
        assert!(rect.x < rect.z && rect.y < rect.w && rect.z - rect.x < 0.5, "{rect}");
        // Points of the sphere's surface project inside the rectangle.
        for i in 0..64 {
            let (a, b) = (i as f32 * 0.7, i as f32 * 1.3);
            let p = Vec3::from(sphere.center)
                + Vec3::new(a.cos() * b.sin(), a.sin() * b.sin(), b.cos()) * sphere.radius;
            let c = clip_from_world * p.extend(1.0);
            let ndc = c.truncate().truncate() / c.w;
            assert!(ndc.x >= rect.x && ndc.x <= rect.z && ndc.y >= rect.y && ndc.y <= rect.w);
        }
        // A sphere around the camera covers the whole view.
        let around = bevy::camera::primitives::Sphere {
            center: Vec3::new(0.0, 1.0, 6.0).into(),
            radius: 1.0,
        };
        assert_eq!(screen_rect(&around, clip_from_world), Vec4::new(-1.0, -1.0, 1.0, 1.0));
    }

    #[test]
    fn the_cone_bounds_hold_every_point_of_the_cone() {
        for angle_deg in [1.0f32, 20.0, 44.0, 46.0, 70.0, 89.0] {
            let angle = angle_deg.to_radians();
            let (apex, axis, length) = (Vec3::new(1.0, 2.0, 3.0), Vec3::new(0.0, -0.6, 0.8), 5.0);
            let bounds = cone_bounds(apex, axis, angle, length);
            let side = axis.any_orthonormal_vector();
            let other = axis.cross(side);
            for i in 0..=20 {
                for j in 0..16 {
                    // Points of the cone's surface (within the range sphere) and of its axis.
                    let t = length * i as f32 / 20.0;
                    let phi = j as f32 * std::f32::consts::TAU / 16.0;
                    let dir = (axis * angle.cos()
                        + (side * phi.cos() + other * phi.sin()) * angle.sin())
                    .normalize();
                    for p in [apex + dir * t, apex + axis * t] {
                        let d = (p - Vec3::from(bounds.center)).length();
                        assert!(d <= bounds.radius * 1.0001 + 1e-5, "{angle_deg}°: {d} > {}", bounds.radius);
                    }
                }
            }
        }
    }
}
