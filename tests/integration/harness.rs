//! A headless Bevy app on the software Vulkan driver, and helpers to read back what it drew.

use std::sync::{Arc, Mutex};

use bevy::{
    asset::RenderAssetUsages,
    camera::RenderTarget,
    image::Image,
    prelude::*,
    render::{
        RenderApp,
        render_resource::{TextureFormat, TextureUsages},
        view::screenshot::{Screenshot, ScreenshotCaptured},
    },
};
use bevy_mesostructure::{CapturedFrame, MesostructureCapture, MesostructureCaptures, prelude::*};

#[path = "../../examples/common/headless.rs"]
pub mod headless;

/// Whether the GPU tests run: always, unless `MESOSTRUCTURE_SKIP_GPU_TESTS=1` skips them on
/// purpose (with a message). A machine without a usable adapter fails them loudly — with this
/// message where no Vulkan driver is installed, with Bevy's "Unable to find a GPU" otherwise —
/// instead of passing them unseen.
pub fn gpu_or_skip() -> bool {
    if std::env::var("MESOSTRUCTURE_SKIP_GPU_TESTS").is_ok_and(|v| v == "1") {
        eprintln!("SKIPPED: MESOSTRUCTURE_SKIP_GPU_TESTS=1");
        return false;
    }
    if cfg!(target_os = "linux") {
        let has_driver = ["/usr/share/vulkan/icd.d", "/etc/vulkan/icd.d"]
            .iter()
            .any(|d| std::fs::read_dir(d).is_ok_and(|mut e| e.next().is_some()));
        assert!(
            has_driver,
            "no Vulkan driver: install one (e.g. `apt-get install mesa-vulkan-drivers`), or set \
             MESOSTRUCTURE_SKIP_GPU_TESTS=1 to skip the GPU tests"
        );
    }
    true
}

/// A headless app rendering to images, with the plugin. Logging stays off (one global logger
/// per process, many apps per test binary) unless `MESOSTRUCTURE_TEST_LOG` is set; warnings are
/// checked through [`warnings`].
pub fn app() -> App {
    app_with(|_| {})
}

/// [`app`], with more plugins added by `more` before the app is finished.
pub fn app_with(more: impl FnOnce(&mut App)) -> App {
    build_app(true, more)
}

/// The same headless app without the plugin, to compare with.
pub fn bare_app() -> App {
    build_app(false, |_| {})
}

/// [`bare_app`], with more plugins added by `more` before the app is finished.
pub fn bare_app_with(more: impl FnOnce(&mut App)) -> App {
    build_app(false, more)
}

/// [`app`] on a device created with `limits` as the upper bound of its limits (a smaller GPU).
pub fn app_with_limits(limits: bevy::render::settings::WgpuLimits) -> App {
    build_app_with(
        true,
        headless::headless_plugins().set(bevy::render::RenderPlugin {
            render_creation: bevy::render::settings::WgpuSettings {
                constrained_limits: Some(limits),
                ..default()
            }
            .into(),
            synchronous_pipeline_compilation: true,
            ..default()
        }),
        |_| {},
    )
}

fn build_app(plugin: bool, more: impl FnOnce(&mut App)) -> App {
    build_app_with(plugin, headless::headless_plugins(), more)
}

fn build_app_with(
    plugin: bool,
    plugins: bevy::app::PluginGroupBuilder,
    more: impl FnOnce(&mut App),
) -> App {
    let mut app = App::new();
    // The examples' headless plugin set: no event loop (their window support is compiled in).
    if std::env::var_os("MESOSTRUCTURE_TEST_LOG").is_some() {
        app.add_plugins(plugins);
    } else {
        app.add_plugins(plugins.disable::<bevy::log::LogPlugin>());
    }
    if plugin {
        app.add_plugins(MesostructurePlugin);
    }
    more(&mut app);
    app.finish();
    app.cleanup();
    app
}

/// A render-target image of `w × h`.
pub fn target(app: &mut App, w: u32, h: u32) -> Handle<Image> {
    let mut image = Image::new_target_texture(w, h, TextureFormat::Rgba8UnormSrgb, None);
    image.texture_descriptor.usage |= TextureUsages::COPY_SRC;
    image.asset_usage = RenderAssetUsages::default();
    app.world_mut().resource_mut::<Assets<Image>>().add(image)
}

/// A camera rendering into `target` with the effect and a capture.
pub fn camera(
    app: &mut App,
    target: &Handle<Image>,
    transform: Transform,
    settings: Mesostructure,
) -> Entity {
    app.world_mut()
        .spawn((
            Camera3d::default(),
            RenderTarget::Image(target.clone().into()),
            Msaa::Off,
            bevy::core_pipeline::tonemapping::Tonemapping::None,
            settings,
            MesostructureCapture,
            transform,
        ))
        .id()
}

/// Runs `n` frames, failing on any render error.
///
/// Frames while a height map's derived images are still being built in the background (its
/// mesh drawn without mesostructure) are not counted; the build may take a few seconds.
pub fn run(app: &mut App, n: usize) {
    let start = std::time::Instant::now();
    let mut done = 0;
    while done < n {
        app.update();
        if let Some(exit) = app.should_exit() {
            panic!("the app exited: {exit:?} (a wgpu error?)");
        }
        if !MesostructureStatus::building(app.world()) {
            done += 1;
        } else {
            assert!(
                start.elapsed().as_secs() < 120,
                "height maps still being built after two minutes"
            );
        }
    }
}

/// The main world's frame count: captures with a later `frame` show the world as it is now.
pub fn frame_count(app: &App) -> u32 {
    app.world().resource::<bevy::diagnostic::FrameCount>().0
}

/// Runs 4 frames (assets prepared, pipelines compiled), then until `camera` has a capture of a
/// frame rendered after that (at most `max` more frames); returns it. (Captures arrive a frame
/// or more late: one from the first frames may show a pass before its pipeline compiled.)
pub fn capture(app: &mut App, camera: Entity, max: usize) -> CapturedFrame {
    let captures = app.world().resource::<MesostructureCaptures>().clone();
    run(app, 4);
    assert_pipelines_ready(app);
    let since = frame_count(app);
    for _ in 0..max {
        if let Some(frame) = captures.take_after(camera, since) {
            return frame;
        }
        run(app, 1);
    }
    if let Some(frame) = captures.take_after(camera, since) {
        return frame;
    }
    panic!("no capture of camera {camera} after {max} frames: were the pipelines compiled?");
}

/// Runs frames until a screenshot of `target` arrives; returns its RGBA8 pixels.
pub fn screenshot(app: &mut App, target: &Handle<Image>) -> Image {
    let slot: Arc<Mutex<Option<Image>>> = Arc::default();
    let s = slot.clone();
    app.world_mut()
        .spawn(Screenshot::image(target.clone()))
        .observe(move |ev: On<ScreenshotCaptured>| {
            *s.lock().unwrap() = Some(ev.image.clone());
        });
    // (Usually 2–3 frames; with every test rendering at once on two cores a screenshot has
    // taken more than 10, more than 60 with two other processes busy on those cores, and more
    // than 240 beside a test's precompute busy on every core: frames run on while the
    // software driver waits its turn. So at least 240 frames and at least two minutes.)
    let start = std::time::Instant::now();
    let mut frames = 0;
    while frames < 240 || start.elapsed() < std::time::Duration::from_secs(120) {
        run(app, 1);
        frames += 1;
        if let Some(image) = slot.lock().unwrap().take() {
            return image;
        }
    }
    panic!("no screenshot after {frames} frames and {:.0} s", start.elapsed().as_secs_f32());
}

/// Keys of the one-time warnings given so far, main and render world together.
pub fn warnings(app: &App) -> Vec<String> {
    app.world()
        .resource::<bevy_mesostructure::MesostructureWarnings>()
        .causes()
}

/// A flat-shaded (unlit) material of one colour.
pub fn unlit(app: &mut App, color: Color) -> MeshMaterial3d<StandardMaterial> {
    MeshMaterial3d(
        app.world_mut()
            .resource_mut::<Assets<StandardMaterial>>()
            .add(StandardMaterial {
                base_color: color,
                unlit: true,
                ..default()
            }),
    )
}

/// Adds a mesh asset.
pub fn mesh(app: &mut App, mesh: impl Into<Mesh>) -> Mesh3d {
    Mesh3d(
        app.world_mut()
            .resource_mut::<Assets<Mesh>>()
            .add(mesh.into()),
    )
}

/// Adds an image asset.
pub fn image(app: &mut App, image: Image) -> Handle<Image> {
    app.world_mut().resource_mut::<Assets<Image>>().add(image)
}

/// The camera above the 2×2 plane, looking straight down, screen right = +x, screen down = +z,
/// and the world point under pixel `(px, py)` of a `size`² image (default 45° vertical fov).
pub const TOP_DOWN_HEIGHT: f32 = 2.0;

/// Transform of the top-down camera.
pub fn top_down() -> Transform {
    Transform::from_xyz(0.0, TOP_DOWN_HEIGHT, 0.0).looking_at(Vec3::ZERO, Vec3::NEG_Z)
}

/// UV of the 2×2 plane under the centre of pixel `(px, py)` of the top-down camera.
pub fn top_down_uv(px: u32, py: u32, size: u32) -> Vec2 {
    let t = (std::f32::consts::FRAC_PI_4 * 0.5).tan() * TOP_DOWN_HEIGHT;
    let ndc = |p: u32| ((p as f32 + 0.5) / size as f32) * 2.0 - 1.0;
    let (x, z) = (ndc(px) * t, ndc(py) * t);
    Vec2::new((x + 1.0) * 0.5, (z + 1.0) * 0.5)
}

/// Fails unless every pipeline of the plugin that was queued has compiled: a missing or broken
/// shader otherwise only shows as a pass that silently never runs.
pub fn assert_pipelines_ready(app: &App) {
    assert_pipelines_ready_with_prefix(app, "mesostructure");
}

/// [`assert_pipelines_ready`] for the pipelines whose labels start with `prefix`.
pub fn assert_pipelines_ready_with_prefix(app: &App, prefix: &str) {
    use bevy::render::render_resource::{CachedPipelineState, PipelineCache, PipelineDescriptor};
    let cache = app
        .get_sub_app(RenderApp)
        .unwrap()
        .world()
        .resource::<PipelineCache>();
    for pipeline in cache.pipelines() {
        let label = match &pipeline.descriptor {
            PipelineDescriptor::RenderPipelineDescriptor(d) => d.label.clone(),
            PipelineDescriptor::ComputePipelineDescriptor(d) => d.label.clone(),
        }
        .unwrap_or_default();
        if !label.starts_with(prefix) {
            continue;
        }
        match &pipeline.state {
            CachedPipelineState::Ok(_) => {}
            CachedPipelineState::Err(err) => panic!("pipeline {label} failed: {err}"),
            _ => panic!("pipeline {label} is still not compiled (a shader that never loads?)"),
        }
    }
}

/// Spawns a directional light of `illuminance` lux travelling along `direction` (any direction,
/// straight down included).
pub fn sun(app: &mut App, direction: Vec3, illuminance: f32) -> Entity {
    let up = if direction.cross(Vec3::Y).length() < 1e-3 {
        Vec3::Z
    } else {
        Vec3::Y
    };
    app.world_mut()
        .spawn((
            DirectionalLight {
                illuminance,
                ..default()
            },
            Transform::default().looking_to(direction, up),
        ))
        .id()
}

/// Spawns the 2 × 2 plane (XZ plane, centred at the origin, normal +Y; see [`top_down_uv`])
/// with `material` and `height_map` at scale `k`.
pub fn mesostructure_plane(
    app: &mut App,
    material: MeshMaterial3d<StandardMaterial>,
    height_map: Handle<Image>,
    k: f32,
) -> Entity {
    let plane = mesh(app, Plane3d::default().mesh().size(2.0, 2.0));
    app.world_mut()
        .spawn((
            plane,
            material,
            MesostructureMaterial {
                height_map,
                scale: k,
                ..default()
            },
        ))
        .id()
}
