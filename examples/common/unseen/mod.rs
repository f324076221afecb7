//! The unseen-content accuracy suite: height maps derived from photographs, curved cores, and
//! the views games show (close-up, oblique, grazing, top-down, far), scored per pixel at the
//! pixel's own UV against a CPU ray caster on the *displaced* mesh.
//!
//! Shared by the `accuracy` example (`--suite unseen`) and the integration tests
//! (`tests/integration/unseen.rs` includes this file by path).
//!
//! Ground truth: the rendered core mesh (Bevy's plane, UV sphere or torus) is subdivided until
//! each small triangle spans at most one height-map texel, each vertex lifted along the
//! interpolated vertex normal by `k · dis(uv)` (bilinear, wrapped: the plugin's eq. 7 surface),
//! and put in a BVH (`obvhs`). Per scored pixel: the camera ray hits the core mesh at `uv`;
//! the true surface point is the displaced mesh's point above it (a ray down the core
//! normal). There:
//! - AO: cosine-weighted about the true (facet) normal, 16 × 16 stratified rays, infinite
//!   radius — every part of the object occludes, the core's own shape included.
//! - light visibility: one ray towards the light from the point.
//! - one bounce, relative to the irradiance E0 of a surface facing the light, every surface
//!   white: the mean over the AO rays of `max(0, N_S · l) · V(S)` at each hit point S.
//!
//! Scores per scene: AO MAE and bias (mean of method − truth); micro-shadow recall and
//! precision on light-facing pixels whose *core* is not shadowed by the core itself (those are
//! Bevy's shadow maps' job, not the micro-shadows'); bounce relative MAE (Σ|b − t| / Σt) and
//! mean ratio (Σb / Σt).

#![allow(dead_code)]

use std::path::Path;

use bevy::{
    camera::{Hdr, RenderTarget},
    core_pipeline::tonemapping::Tonemapping,
    diagnostic::{DiagnosticPath, DiagnosticsStore},
    math::Affine2,
    mesh::{Indices, VertexAttributeValues},
    prelude::*,
    render::{
        diagnostic::RenderDiagnosticsPlugin,
        render_resource::{TextureFormat, TextureUsages},
    },
};
use bevy_mesostructure::{
    CapturedFrame, MesostructureCapture, MesostructureCaptures, prelude::*,
    reference::ground_truth::HeightField,
};
use obvhs::{
    BvhBuildParams,
    cwbvh::{CwBvh, builder::build_cwbvh_from_tris},
    ray::{Ray, RayHit},
    triangle::Triangle,
};
use obvhs_glam::Vec3A;

mod scores;
mod truth;
pub use scores::*;
pub use truth::*;

/// The core mesh under the height map.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Core {
    /// Bevy's `Plane3d`, 2 × 2 in XZ, normal +Y, UV (0, 0) at (−1, 0, −1).
    Plane,
    /// Bevy's UV sphere, radius 1, 64 × 32 segments: poles on ±Z (v = 0 at +Z), u = azimuth
    /// from +X towards +Y over 2π.
    Sphere,
    /// Bevy's `Torus::new(0.5, 1.0)`: major radius 0.75, minor 0.25, around +Y; u around the
    /// ring from +X towards +Z, v around the tube from the outer equator towards +Y.
    Torus,
}

impl Core {
    /// The name in scene names and CSVs.
    pub fn name(self) -> &'static str {
        match self {
            Core::Plane => "plane",
            Core::Sphere => "sphere",
            Core::Torus => "torus",
        }
    }

    /// The mesh the plugin renders.
    pub fn mesh(self) -> Mesh {
        match self {
            Core::Plane => Plane3d::default().mesh().size(2.0, 2.0).build(),
            Core::Sphere => Sphere::new(1.0).mesh().uv(64, 32),
            Core::Torus => Torus::new(0.5, 1.0)
                .mesh()
                .major_resolution(64)
                .minor_resolution(32)
                .build(),
        }
    }
}

/// One scene of the suite.
#[derive(Clone, Debug)]
pub struct Scene {
    /// `core/map/view/light`.
    pub name: String,
    pub core: Core,
    /// A file under `assets/height_maps/photo/` without `.png`, or a built-in generator.
    pub map: &'static str,
    /// Height of white, world units.
    pub scale: f32,
    /// Repeats of the height map over the core's UV square.
    pub tiles: Vec2,
    pub eye: Vec3,
    pub target: Vec3,
    /// What kind of view (close-up, oblique, grazing, top-down, far).
    pub view: &'static str,
    /// Light elevation above the core's tangent plane at the target, degrees.
    pub light_elevation: f32,
    /// Light azimuth about the target's normal, degrees from the camera's heading (0 = the
    /// light behind the camera, 90 = from the right).
    pub light_azimuth: f32,
}

/// The suite: every core, view kind and light elevation the issue names, with the four
/// photo-derived maps (and one generator), 12 scenes.
pub fn scenes() -> Vec<Scene> {
    let s = |core: Core,
             map: &'static str,
             scale: f32,
             tiles: f32,
             view: &'static str,
             eye: [f32; 3],
             target: [f32; 3],
             light_elevation: f32,
             light_azimuth: f32| {
        let tiles = match core {
            Core::Plane => Vec2::splat(tiles),
            Core::Sphere => Vec2::new(2.0 * tiles, tiles),
            Core::Torus => Vec2::new(4.0 * tiles, tiles),
        };
        Scene {
            name: format!("{}/{map}/{view}/light{light_elevation}", core.name()),
            core,
            map,
            scale,
            tiles,
            eye: Vec3::from(eye),
            target: Vec3::from(target),
            view,
            light_elevation,
            light_azimuth,
        }
    };
    use Core::*;
    vec![
        s(Plane, "pebbles", 0.05, 2.0, "top-down", [0.1, 0.6, 0.12], [0.1, 0.0, 0.1], 35.0, 100.0),
        s(Plane, "cracked", 0.05, 2.0, "oblique", [0.0, 1.6, 2.4], [0.0, 0.0, 0.0], 15.0, 80.0),
        s(Plane, "bark", 0.04, 2.0, "grazing", [0.0, 0.25, 1.2], [0.0, 0.0, 0.0], 60.0, 120.0),
        s(Plane, "rock", 0.06, 2.0, "close-up", [0.2, 0.2, 0.32], [0.2, 0.0, 0.1], 35.0, 90.0),
        s(Plane, "pebbles", 0.05, 1.0, "far", [0.0, 3.0, 2.0], [0.0, 0.0, 0.0], 15.0, 100.0),
        s(Plane, "stone", 0.05, 2.0, "oblique", [0.3, 1.0, 1.6], [0.0, 0.0, 0.0], 35.0, 60.0),
        s(Sphere, "cracked", 0.06, 2.0, "oblique", [2.2, 1.5, 2.0], [0.0, 0.0, 0.0], 35.0, 90.0),
        s(Sphere, "rock", 0.06, 2.0, "close-up", [0.05, 1.3, 0.18], [0.0, 1.0, 0.0], 60.0, 90.0),
        s(Sphere, "pebbles", 0.06, 2.0, "far", [0.0, 2.2, 1.65], [0.0, 0.0, 0.0], 35.0, 110.0),
        s(Torus, "bark", 0.04, 1.0, "oblique", [0.0, 1.5, 1.9], [0.0, 0.0, 0.0], 35.0, 90.0),
        s(Torus, "pebbles", 0.04, 1.0, "top-down", [0.75, 0.9, 0.02], [0.75, 0.0, 0.0], 60.0, 100.0),
        s(Torus, "cracked", 0.04, 1.0, "grazing", [-1.2, 0.5, 0.75], [0.0, 0.25, 0.75], 15.0, 90.0),
    ]
}

/// The height map of a scene: a photo-derived PNG under `assets/height_maps/photo/`, box-filtered
/// to 256² (the size the ground-truth mesh is built at), or a generator at 256².
pub fn height_map(name: &str) -> HeightMap {
    if let Some(map) = HeightMap::by_name(name, 256) {
        return map;
    }
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("assets/height_maps/photo")
        .join(format!("{name}.png"));
    let grey = image::open(&path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()))
        .to_luma16();
    let (w, h) = grey.dimensions();
    let f = (w / 256).max(1);
    HeightMap::from_fn(w / f, h / f, |u, v| {
        let (x0, y0) = ((u * (w / f) as f32) as u32 * f, (v * (h / f) as f32) as u32 * f);
        let mut sum = 0.0;
        for y in y0..y0 + f {
            for x in x0..x0 + f {
                sum += grey.get_pixel(x, y)[0] as f32 / 65535.0;
            }
        }
        sum / (f * f) as f32
    })
}

/// Unit vector towards the light of `scene`, given the core normal at its target.
pub fn to_light(scene: &Scene, normal: Vec3) -> Vec3 {
    let heading = scene.target - scene.eye;
    let mut t1 = (heading - normal * heading.dot(normal)).normalize_or_zero();
    if t1 == Vec3::ZERO {
        t1 = normal.any_orthonormal_vector();
    }
    // The light comes from behind the camera at azimuth 0: the direction towards it is −t1.
    let t2 = normal.cross(t1);
    let (e, az) = (scene.light_elevation.to_radians(), scene.light_azimuth.to_radians());
    (-(t1 * az.cos()) + t2 * az.sin()) * e.cos() + normal * e.sin()
}

/// The camera ray through the centre of pixel `(x, y)` of a captured frame (from its
/// `world_from_clip`, so it is exactly the rendered one).
pub fn camera_ray(frame: &CapturedFrame, x: u32, y: u32) -> (Vec3, Vec3) {
    let near = frame.view.core_point(x, y, 1.0);
    let far = frame.view.core_point(x, y, 0.01);
    (near, (far - near).normalize())
}

/// A camera's settings for one scored variant: the component, and the horizon-search baseline
/// where the variant is that baseline.
#[derive(Clone, Default)]
pub struct Variant {
    pub settings: Mesostructure,
    pub baseline: Option<bevy_mesostructure::HorizonSearchBaseline>,
}

impl From<Mesostructure> for Variant {
    fn from(settings: Mesostructure) -> Self {
        Self {
            settings,
            baseline: None,
        }
    }
}

/// Renders `scene` once with `variant` and returns the capture and the median GPU time of the
/// plugin's passes but the lighting pass (which replaces Bevy's own).
pub fn render(
    plugins: bevy::app::PluginGroupBuilder,
    scene: &Scene,
    map: &HeightMap,
    variant: Variant,
    size: u32,
    to_light: Vec3,
) -> Option<(CapturedFrame, f64)> {
    let (mut app, target) = measuring_app(plugins, size);
    let world = app.world_mut();
    let forward = (scene.target - scene.eye).normalize();
    let up = if forward.cross(Vec3::Y).length() < 1e-3 { Vec3::NEG_Z } else { Vec3::Y };
    let camera = world
        .spawn((
            Camera3d::default(),
            RenderTarget::Image(target.into()),
            Msaa::Off,
            Hdr,
            Tonemapping::None,
            Transform::from_translation(scene.eye).looking_at(scene.target, up),
            variant.settings,
            MesostructureCapture,
        ))
        .id();
    if let Some(baseline) = variant.baseline {
        world.entity_mut(camera).insert(baseline);
    }
    world.insert_resource(bevy::light::GlobalAmbientLight {
        brightness: 0.0,
        ..default()
    });
    let light_up = if to_light.cross(Vec3::Y).length() < 1e-3 { Vec3::Z } else { Vec3::Y };
    world.spawn((
        DirectionalLight {
            illuminance: 3000.0,
            shadow_maps_enabled: true,
            ..default()
        },
        Transform::default().looking_to(-to_light, light_up),
    ));
    let material = world
        .resource_mut::<Assets<StandardMaterial>>()
        .add(StandardMaterial {
            perceptual_roughness: 1.0,
            reflectance: 0.0,
            ..default()
        });
    let mesh = world.resource_mut::<Assets<Mesh>>().add(scene.core.mesh());
    let height_map = world.resource_mut::<Assets<Image>>().add(map.to_image());
    world.spawn((
        Mesh3d(mesh),
        MeshMaterial3d(material),
        MesostructureMaterial {
            height_map,
            scale: scene.scale,
            uv_transform: Affine2::from_scale(scene.tiles),
        },
    ));
    if !wait_for_pipelines(&mut app) {
        return None;
    }
    let captured = take_capture(&mut app, camera);
    let gpu_ms = ADDED_PASSES
        .iter()
        .map(|p| median_gpu_ms(&app, &format!("mesostructure/{p}")))
        .sum();
    captured.map(|f| (f, gpu_ms))
}

/// A headless app with the plugin and GPU time spans (logging off), finished, and a `size`²
/// sRGB image its camera can render into and be read back from: what each measured render of
/// the accuracy suites starts from.
pub fn measuring_app(plugins: bevy::app::PluginGroupBuilder, size: u32) -> (App, Handle<Image>) {
    let mut app = App::new();
    app.add_plugins(plugins.disable::<bevy::log::LogPlugin>())
        .add_plugins((MesostructurePlugin, RenderDiagnosticsPlugin));
    app.finish();
    app.cleanup();
    let mut image = Image::new_target_texture(size, size, TextureFormat::Rgba8UnormSrgb, None);
    image.texture_descriptor.usage |= TextureUsages::COPY_SRC;
    let target = app.world_mut().resource_mut::<Assets<Image>>().add(image);
    (app, target)
}

/// The plugin's passes but the lighting pass (which replaces Bevy's own deferred lighting for
/// these pixels): what it adds to a frame's GPU time.
pub const ADDED_PASSES: [&str; 6] =
    ["height", "gradient", "apex", "occlusion", "bleeding", "bleeding_composite"];

/// Updates `app` until every pipeline has compiled and every height map is built, 12 frames at least (a pass whose pipeline is
/// not ready does not run, and its image is not this frame's; on a busy machine compiling can
/// take more than a few frames). False if some are still compiling after 600 frames.
pub fn wait_for_pipelines(app: &mut App) -> bool {
    for frame in 0..=600 {
        app.update();
        if frame >= 12 && !super::headless::settling(app) {
            return true;
        }
    }
    false
}

/// The next capture of `camera` rendered after this call, within 10 frames.
pub fn take_capture(app: &mut App, camera: Entity) -> Option<CapturedFrame> {
    let captures = app.world().resource::<MesostructureCaptures>().clone();
    let since = app.world().resource::<bevy::diagnostic::FrameCount>().0;
    (0..10).find_map(|_| {
        app.update();
        captures.take_after(camera, since)
    })
}

/// Median of the GPU time span `render/{span}/elapsed_gpu` over the frames the diagnostics
/// keep, ms; 0 where the span was never recorded.
pub fn median_gpu_ms(app: &App, span: &str) -> f64 {
    let path = DiagnosticPath::new(format!("render/{span}/elapsed_gpu"));
    let mut v: Vec<f64> = app
        .world()
        .resource::<DiagnosticsStore>()
        .get(&path)
        .map(|d| d.values().copied().collect())
        .unwrap_or_default();
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(0.0)
}

/// The lit radiance of a white surface facing the light (ρE0/π, exposure applied), the unit of
/// the captured bleeding: the plane with a flat map, lit from the zenith, seen from above.
pub fn radiance_unit(plugins: bevy::app::PluginGroupBuilder, size: u32) -> f32 {
    let scene = Scene {
        name: "calibration".into(),
        core: Core::Plane,
        map: "flat",
        scale: 0.05,
        tiles: Vec2::ONE,
        eye: Vec3::new(0.0, 2.0, 0.01),
        target: Vec3::ZERO,
        view: "top-down",
        light_elevation: 90.0,
        light_azimuth: 0.0,
    };
    let flat = HeightMap::from_fn(16, 16, |_, _| 0.5);
    let (frame, _) = render(plugins, &scene, &flat, Mesostructure::default().into(), size, Vec3::Y)
        .expect("the flat plane renders");
    let (mut sum, mut n) = (0.0, 0);
    for y in size / 4..3 * size / 4 {
        for x in size / 4..3 * size / 4 {
            sum += frame.lit[(y * size + x) as usize][1];
            n += 1;
        }
    }
    sum / n as f32
}

/// `f` over `items` on every core.
pub fn par_map<I: Sync, T: Send>(items: &[I], f: impl Fn(&I) -> T + Sync) -> Vec<T> {
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let chunk = items.len().div_ceil(threads).max(1);
    std::thread::scope(|scope| {
        let handles: Vec<_> = items
            .chunks(chunk)
            .map(|part| scope.spawn(|| part.iter().map(&f).collect::<Vec<T>>()))
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().expect("a ground-truth thread panicked"))
            .collect()
    })
}

/// One scene end to end: the truth at every `step`-th pixel the core covers, the plugin's
/// terms there (`settings`), and the scores of the plugin and of no effect.
pub struct SceneResult {
    pub plugin: Scores,
    pub none: Scores,
    pub gpu_ms: f64,
    /// Seconds spent on the ground truth.
    pub truth_seconds: f32,
}

/// Runs one scene: renders it, casts the truth at every `step`-th covered pixel. With
/// `UNSEEN_DUMP=DIR` in the environment it also writes each scene's micro-shadow confusion map
/// (true positives green, false positives red, misses blue), AO error map (`_ao`: red too
/// open, blue too dark, full colour at ±0.25) and bounce error map (`_bounce`: red too strong,
/// blue too weak, full colour at ±0.1 of E0) to `DIR`.
pub fn run_scene(
    plugins: impl Fn() -> bevy::app::PluginGroupBuilder,
    scene: &Scene,
    settings: impl Into<Variant>,
    size: u32,
    step: u32,
    unit: f32,
    rings: u32,
) -> Option<SceneResult> {
    let map = height_map(scene.map);
    let truth = GroundTruth::new(scene.core, map.clone(), scene.scale, scene.tiles);
    let normal = truth.normal_towards(scene.eye, scene.target);
    let light = to_light(scene, normal);
    let (frame, gpu_ms) = render(plugins(), scene, &map, settings.into(), size, light)?;
    let pixels: Vec<(u32, u32)> = (0..size / step)
        .flat_map(|j| (0..size / step).map(move |i| (i * step + step / 2, j * step + step / 2)))
        .filter(|&(x, y)| frame.mhm[(y * size + x) as usize][2] != 0.0)
        .collect();
    let clock = std::time::Instant::now();
    let truths: Vec<Option<Truth>> = par_map(&pixels, |&(x, y)| {
        let (o, d) = camera_ray(&frame, x, y);
        truth.at(o, d, light, rings, rings)
    });
    let truth_seconds = clock.elapsed().as_secs_f32();
    let (mut kept, mut estimates, mut texels) = (vec![], vec![], vec![]);
    for (&(x, y), t) in pixels.iter().zip(&truths) {
        let Some(t) = t else { continue };
        let i = (y * size + x) as usize;
        kept.push(*t);
        estimates.push(Estimate {
            ao: frame.occlusion[i],
            shadowed: frame.micro_shadow.get(i).is_some_and(|&v| v < 0.5),
            bounce: frame.bleeding.get(i).map_or(0.0, |b| b[1] / unit),
        });
        // Texel footprint: the UV of the next pixel to the right.
        if x + 1 < size {
            let (o, d) = camera_ray(&frame, x + 1, y);
            if let Some(next) = truth.core_hit(o, d) {
                texels.push(truth.texels_per_pixel(t.uv, next.uv));
            }
        }
    }
    if let Some(dir) = std::env::var_os("UNSEEN_DUMP") {
        // Micro-shadow confusion map: true positive green, false positive red, false negative
        // blue, agreeing lit grey (only light-facing pixels with a lit core are coloured); AO
        // error map: red where the method is too open, blue where too dark (full at ±0.25).
        let mut shadows = image::RgbImage::new(size / step, size / step);
        let mut ao = image::RgbImage::new(size / step, size / step);
        let mut bounce = image::RgbImage::new(size / step, size / step);
        let scored = pixels.iter().zip(&truths).filter_map(|(p, t)| Some((p, t.as_ref()?)));
        for ((&(x, y), t), e) in scored.zip(&estimates) {
            let colour = if !t.facing || t.core_shadowed {
                [0, 0, 0]
            } else {
                match (!t.lit, e.shadowed) {
                    (true, true) => [0, 200, 0],
                    (false, true) => [255, 0, 0],
                    (true, false) => [0, 80, 255],
                    _ => [128, 128, 128],
                }
            };
            shadows.put_pixel(x / step, y / step, image::Rgb(colour));
            // Red where the method is above the truth, blue below, full at ±`full`.
            let error_colour = |method: f32, truth: f32, full: f32| {
                let error = ((method - truth) / full).clamp(-1.0, 1.0);
                let fade = |e: f32| (255.0 * (1.0 - e.max(0.0))) as u8;
                image::Rgb([fade(-error), fade(error.abs()), fade(error)])
            };
            ao.put_pixel(x / step, y / step, error_colour(e.ao, t.ao, 0.25));
            bounce.put_pixel(x / step, y / step, error_colour(e.bounce, t.bounce, 0.1));
        }
        let name = scene.name.replace('/', "_");
        for (image, file) in [
            (shadows, format!("{name}.png")),
            (ao, format!("{name}_ao.png")),
            (bounce, format!("{name}_bounce.png")),
        ] {
            image.save(Path::new(&dir).join(file)).expect("cannot write the dump");
        }
    }
    texels.sort_by(f32::total_cmp);
    let tpp = texels.get(texels.len() / 2).copied().unwrap_or(0.0);
    let none: Vec<Estimate> = kept
        .iter()
        .map(|_| Estimate { ao: 1.0, shadowed: false, bounce: 0.0 })
        .collect();
    Some(SceneResult {
        plugin: score(&kept, &estimates, tpp),
        none: score(&kept, &none, tpp),
        gpu_ms,
        truth_seconds,
    })
}
