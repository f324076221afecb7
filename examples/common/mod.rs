//! Shared by the examples: a window with a tuning panel where there is a display, headless PNG
//! screenshots where there is none; `--frames N --out DIR` in both; keys; on-screen timings.
//!
//! Each example includes it with `#[path = "common/mod.rs"] mod common;`.

#![allow(dead_code)] // Each example uses its own part of it.

pub mod chart;
pub mod headless;
pub mod meshes;
pub mod panel;
pub mod unseen;

pub use headless::headless_plugins;

use std::path::PathBuf;

use bevy::{
    app::AppExit,
    camera::RenderTarget,
    diagnostic::FrameTimeDiagnosticsPlugin,
    prelude::*,
    render::{
        RenderPlugin,
        diagnostic::RenderDiagnosticsPlugin,
        render_resource::{TextureFormat, TextureUsages},
        view::screenshot::{Screenshot, ScreenshotCaptured, save_to_disk},
    },
    window::{ExitCondition, WindowResolution},
};
use bevy_mesostructure::prelude::*;

/// The options every example takes, as parsed (`#[command(flatten)]` in each example's
/// arguments).
#[derive(clap::Args, Clone, Debug, Default)]
pub struct CommonArgs {
    /// Frames to render before the screenshots; in a window, take them and exit after
    #[arg(long)]
    pub frames: Option<u32>,
    /// Folder for the screenshots [default: out/<example>]
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Picture size, N or WxH [default: 512x384 headless, 1280x720 in a window]
    #[arg(long, value_parser = parse_size)]
    pub size: Option<UVec2>,
    /// Render without a window even where there is a display
    #[arg(long)]
    pub headless: bool,
}

/// Exits with one line and code 2, as clap does for a bad argument (no panic, no backtrace).
#[allow(dead_code)]
pub fn fail(message: impl std::fmt::Display) -> ! {
    eprintln!("error: {message}");
    std::process::exit(2);
}

/// `N` or `WxH`, each at least 1.
pub fn parse_size(s: &str) -> Result<UVec2, String> {
    let (w, h) = s.split_once('x').unwrap_or((s, s));
    let n = |t: &str| match t.trim().parse::<u32>() {
        Ok(v) if v > 0 => Ok(v),
        _ => Err(format!("expected N or WxH with positive whole numbers, got {s:?}")),
    };
    Ok(UVec2::new(n(w)?, n(h)?))
}

/// `x,y,z` (negative numbers allowed: pass them as `--eye=-1,2,3` or `--eye -1,2,3`).
pub fn parse_vec3(s: &str) -> Result<Vec3, String> {
    let v: Result<Vec<f32>, _> = s.split(',').map(|x| x.trim().parse::<f32>()).collect();
    match v {
        Ok(v) if v.len() == 3 && v.iter().all(|x| x.is_finite()) => Ok(Vec3::new(v[0], v[1], v[2])),
        _ => Err(format!("expected three finite numbers x,y,z, got {s:?}")),
    }
}

/// A finite number above 0.
pub fn parse_positive(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("expected a finite number above 0, got {s:?}")),
    }
}

/// The debug views to write (`--view NAME` or `--view all`).
#[derive(Clone, Debug)]
pub struct ViewList(pub Vec<MesostructureDebugView>);

/// A debug view's name, or `all`.
pub fn parse_views(s: &str) -> Result<ViewList, String> {
    if s == "all" {
        return Ok(ViewList(MesostructureDebugView::ALL.to_vec()));
    }
    MesostructureDebugView::from_name(s)
        .map(|v| ViewList(vec![v]))
        .ok_or_else(|| {
            let names: Vec<&str> = MesostructureDebugView::ALL.iter().map(|v| v.name()).collect();
            format!("unknown view {s:?}; one of {}, all", names.join(", "))
        })
}

/// The options every example takes, resolved.
pub struct ExampleArgs {
    /// Frames to render before the screenshots; `None` in a window = run until closed.
    pub frames: Option<u32>,
    /// Where the screenshots go.
    pub out: PathBuf,
    /// Picture size in pixels (`--size`; default 512×384 headless, 1280×720 in a window).
    pub size: UVec2,
    /// Whether `--size` was given.
    pub sized: bool,
    /// Render without a window even where there is a display.
    pub headless: bool,
}

impl ExampleArgs {
    /// The defaults: 512×384 into `out/<name>/`.
    pub fn new(name: &str) -> Self {
        Self::from_cli(name, CommonArgs::default())
    }

    /// The parsed options of example `name`, defaults filled in.
    pub fn from_cli(name: &str, cli: CommonArgs) -> Self {
        Self {
            frames: cli.frames,
            out: cli.out.unwrap_or_else(|| PathBuf::from("out").join(name)),
            size: cli.size.unwrap_or(UVec2::new(512, 384)),
            sized: cli.size.is_some(),
            headless: cli.headless,
        }
    }

    /// Whether this run opens a window.
    pub fn windowed(&self) -> bool {
        !self.headless && display_available()
    }

    /// Frames before the first screenshot.
    pub fn warm_up(&self) -> u32 {
        self.frames.unwrap_or(30)
    }
}

/// Whether a window can be opened here: an X11 or Wayland display is named.
pub fn display_available() -> bool {
    ["DISPLAY", "WAYLAND_DISPLAY"]
        .iter()
        .any(|v| std::env::var(v).is_ok_and(|s| !s.is_empty()))
}

/// Where the camera renders: the window, or an image that the screenshots read.
#[derive(Resource, Clone)]
pub struct Output(pub Option<Handle<Image>>);

impl Output {
    /// The render target for the example's camera.
    pub fn target(&self) -> RenderTarget {
        match &self.0 {
            Some(image) => RenderTarget::Image(image.clone().into()),
            None => RenderTarget::default(),
        }
    }
}

/// One scripted screenshot: `apply` changes the world, two frames later the picture is saved
/// as `file` (in `--out`).
pub struct Shot {
    /// File name.
    pub file: String,
    /// What to change before it.
    pub apply: Box<dyn Fn(&mut World) + Send + Sync>,
}

/// The screenshots to take after the warm-up, and where the script is.
#[derive(Resource)]
pub struct Script {
    shots: Vec<Shot>,
    frame: u32,
    warm_up: u32,
    next: usize,
    wait: u32,
    exit_when_done: bool,
    pub(crate) out: PathBuf,
    /// When the script first found a height map or the translucency transport building.
    settling_since: Option<std::time::Instant>,
    settle_limit_reached: bool,
    translucency_printed: bool,
    /// Shots written to disk so far, and frames waited for the last ones after the script's
    /// end: the app exits once every shot is written (a screenshot arrives some frames after
    /// it is asked for; exiting before dropped them and crashed the NVIDIA driver's teardown
    /// at times), or after `SHOT_WAIT_LIMIT` frames.
    saved: usize,
    waited_for_shots: u32,
}

/// How many frames the script waits at its end for the shots still on their way.
const SHOT_WAIT_LIMIT: u32 = 600;

/// The app: Bevy with a window (and the tuning panel) or headless, the plugin, timing
/// diagnostics, and the screenshot script.
pub fn app(args: &ExampleArgs, title: &str, shots: Vec<Shot>) -> App {
    std::fs::create_dir_all(&args.out).expect("cannot create the output folder");
    let windowed = args.windowed();
    let size = if windowed && !args.sized {
        UVec2::new(1280, 720)
    } else {
        args.size
    };
    let mut app = App::new();
    let window = WindowPlugin {
        primary_window: windowed.then(|| Window {
            title: title.into(),
            resolution: WindowResolution::new(size.x, size.y),
            ..default()
        }),
        exit_condition: if windowed {
            ExitCondition::OnPrimaryClosed
        } else {
            ExitCondition::DontExit
        },
        ..default()
    };
    let plugins = DefaultPlugins.set(window).set(RenderPlugin {
        synchronous_pipeline_compilation: !windowed,
        ..default()
    });
    if windowed {
        app.add_plugins(plugins);
    } else {
        app.add_plugins(headless_plugins());
    }
    app.add_plugins((
        MesostructurePlugin,
        FrameTimeDiagnosticsPlugin::default(),
        RenderDiagnosticsPlugin,
    ));
    let output = if windowed {
        panel::add(&mut app);
        println!(
            "{title}: window {}×{}; keys: O occlusion, M micro-shadows, B bleeding, N bump \
             mapping, V next debug view, Space pause, F12 screenshot (into {})",
            size.x,
            size.y,
            args.out.display()
        );
        Output(None)
    } else {
        println!(
            "{title}: no display (or --headless): rendering {} frames headless, writing PNGs to {}",
            args.warm_up(),
            args.out.display()
        );
        let mut image = Image::new_target_texture(
            args.size.x,
            args.size.y,
            TextureFormat::Rgba8UnormSrgb,
            None,
        );
        image.texture_descriptor.usage |= TextureUsages::COPY_SRC;
        Output(Some(
            app.world_mut().resource_mut::<Assets<Image>>().add(image),
        ))
    };
    app.insert_resource(output)
        .insert_resource(Script {
            shots,
            frame: 0,
            warm_up: args.warm_up(),
            next: 0,
            wait: 0,
            exit_when_done: !windowed || args.frames.is_some(),
            out: args.out.clone(),
            settling_since: None,
            settle_limit_reached: false,
            translucency_printed: false,
            saved: 0,
            waited_for_shots: 0,
        })
        .init_resource::<Clock>()
        .add_systems(Update, advance_clock)
        .add_systems(Last, run_script);
    app
}

/// Updates `app` `n` times, not counting the frames while it is [`headless::settling`] (for at most 600
/// frames: a pipeline whose shader never loads would wait forever).
pub fn update_when_ready(app: &mut App, n: usize) {
    let (mut done, mut waited) = (0, 0);
    while done < n {
        app.update();
        if !headless::settling(app) || waited >= 600 {
            done += 1;
        } else {
            waited += 1;
        }
    }
}

/// Runs the app: the window's event loop, or frame by frame until the script is done.
pub fn run(mut app: App) {
    if app.world().resource::<Output>().0.is_some() {
        app.finish();
        app.cleanup();
        while app.should_exit().is_none() {
            app.update();
        }
        panel::print_timings(app.world());
    } else {
        app.run();
    }
}

/// Animation time: 1/30 s per frame (so that screenshots do not depend on the frame rate),
/// stopped while paused.
#[derive(Resource, Default)]
pub struct Clock {
    /// Seconds of animation.
    pub t: f32,
    /// Space toggles it.
    pub paused: bool,
}

fn advance_clock(mut clock: ResMut<Clock>) {
    if !clock.paused {
        clock.t += 1.0 / 30.0;
    }
}

/// How long the script waits for a height map or a translucency precompute before it goes on
/// (a mesh that never stays still keeps the precompute waiting).
const SETTLE_LIMIT: std::time::Duration = std::time::Duration::from_secs(120);

fn run_script(world: &mut World) {
    let building = MesostructureStatus::building(world)
        || bevy_mesostructure::translucency::TranslucencyStatus::building(world);
    // The precompute's outcome, printed once.
    let ready = (!world.resource::<Script>().translucency_printed)
        .then(|| panel::translucency_ready(world))
        .flatten();
    let mut script = world.resource_mut::<Script>();
    if let Some(line) = ready {
        println!("translucency: {line}");
        script.translucency_printed = true;
    }
    if building {
        let since = *script.settling_since.get_or_insert_with(std::time::Instant::now);
        if since.elapsed() < SETTLE_LIMIT {
            return;
        }
        if !script.settle_limit_reached {
            script.settle_limit_reached = true;
            eprintln!(
                "warning: still building after {} s; going on without waiting",
                SETTLE_LIMIT.as_secs()
            );
        }
    } else {
        script.settling_since = None;
    }
    script.frame += 1;
    if script.frame < script.warm_up || !script.exit_when_done {
        return;
    }
    if script.wait > 0 {
        script.wait -= 1;
        return;
    }
    let index = script.next / 2;
    let stage = script.next % 2;
    if index >= script.shots.len() {
        if script.saved < script.shots.len() && script.waited_for_shots < SHOT_WAIT_LIMIT {
            script.waited_for_shots += 1;
            return;
        }
        if script.saved < script.shots.len() {
            eprintln!(
                "warning: {} of {} shots written after {SHOT_WAIT_LIMIT} frames; exiting",
                script.saved,
                script.shots.len()
            );
        }
        world.write_message(AppExit::Success);
        return;
    }
    script.next += 1;
    if stage == 0 {
        // Change the world, let two frames pass.
        let shot = std::mem::replace(&mut script.shots[index].apply, Box::new(|_: &mut World| {}));
        script.wait = 2;
        shot(world);
    } else {
        let path = script.out.join(&script.shots[index].file);
        script.wait = 3;
        let screenshot = match &world.resource::<Output>().0 {
            Some(image) => Screenshot::image(image.clone()),
            None => Screenshot::primary_window(),
        };
        world
            .spawn(screenshot)
            .observe(save_to_disk(path.clone()))
            .observe(move |_: On<ScreenshotCaptured>, mut script: ResMut<Script>| {
                script.saved += 1;
                println!("wrote {}", path.display());
            });
    }
}

/// A shot of the camera's debug view `view` (after the other settings of `apply`), named
/// `<prefix>_<view>.png`.
pub fn view_shot(prefix: &str, view: MesostructureDebugView) -> Shot {
    Shot {
        file: format!("{prefix}_{}.png", view.name()),
        apply: Box::new(move |world: &mut World| {
            let mut q = world.query_filtered::<Entity, With<Mesostructure>>();
            let cameras: Vec<Entity> = q.iter(world).collect();
            for camera in cameras {
                world.entity_mut(camera).insert(view);
            }
        }),
    }
}

/// A repeating sRGB colour texture over `map`: `high` where the height map is above 0.1 (the
/// bumps and their walls), `low` on the floor between them.
pub fn two_tone(map: &HeightMap, high: [u8; 3], low: [u8; 3]) -> Image {
    let data = map
        .values
        .iter()
        .flat_map(|&v| {
            let c = if v > 0.1 { high } else { low };
            [c[0], c[1], c[2], 255]
        })
        .collect();
    use bevy::{
        asset::RenderAssetUsages,
        image::{ImageAddressMode, ImageSampler, ImageSamplerDescriptor},
        render::render_resource::{Extent3d, TextureDimension},
    };
    let mut image = Image::new(
        Extent3d {
            width: map.width,
            height: map.height,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        data,
        TextureFormat::Rgba8UnormSrgb,
        RenderAssetUsages::RENDER_WORLD,
    );
    image.sampler = ImageSampler::Descriptor(ImageSamplerDescriptor {
        address_mode_u: ImageAddressMode::Repeat,
        address_mode_v: ImageAddressMode::Repeat,
        ..ImageSamplerDescriptor::linear()
    });
    image
}
