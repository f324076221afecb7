//! Volumetric spot lights (issue 12): the GPU pass against the exact CPU reference and its CPU
//! mirror, and bad input.

use bevy::{
    camera::{Exposure, RenderTarget},
    core_pipeline::tonemapping::Tonemapping,
    light::GlobalAmbientLight,
    prelude::*,
    render::render_resource::{TextureFormat, TextureUsages},
};
use bevy_mesostructure::volumetric::{
    VolumetricMedium, VolumetricResolution, VolumetricSpot, VolumetricSpotsPlugin,
    reference::{self, Sampling},
};

use crate::harness::*;

const W: u32 = 64;
const H: u32 = 48;
/// The medium's asymmetry in these tests.
const G: f32 = 0.6;

#[path = "../../examples/common/spot_scene.rs"]
mod spot_scene;
use spot_scene::{EV100, red, relative_l1};

/// The reference set-up, scaled down: a spot at (0, 4, 0) aimed at (0.5, 0, 0), outer
/// 30°, inner 20°, 20 000 lm, range 100, over a black floor; σs 0.10, σa 0.01, g 0.6; seen by
/// a camera at `view`.
fn spot_scene(
    spot: SpotLight,
    settings: VolumetricSpot,
    view: Transform,
) -> (App, Entity, Handle<Image>) {
    spot_scene_with(spot, settings, view, false)
}

/// [`spot_scene`], with the reference set-up's 1 m cube at (0, 2.5, 0) when `cube` (black; it
/// casts the spot's shadow).
fn spot_scene_with(
    spot: SpotLight,
    settings: VolumetricSpot,
    view: Transform,
    cube: bool,
) -> (App, Entity, Handle<Image>) {
    let mut app = app_with(|app| {
        app.add_plugins((
            VolumetricSpotsPlugin,
            bevy::render::diagnostic::RenderDiagnosticsPlugin,
        ));
    });
    app.insert_resource(GlobalAmbientLight {
        brightness: 0.0,
        ..default()
    })
    .insert_resource(ClearColor(Color::BLACK));
    let black = unlit(&mut app, Color::BLACK);
    let plane = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(Plane3d::default().mesh().size(20.0, 20.0));
    app.world_mut().spawn((Mesh3d(plane), black.clone()));
    if cube {
        let mesh = app
            .world_mut()
            .resource_mut::<Assets<Mesh>>()
            .add(Cuboid::new(1.0, 1.0, 1.0));
        app.world_mut()
            .spawn((Mesh3d(mesh), black, Transform::from_xyz(0.0, 2.5, 0.0)));
    }
    app.world_mut().spawn((
        spot,
        settings,
        spot_scene::spot_transform(),
    ));
    let mut image = Image::new_target_texture(W, H, TextureFormat::Rgba16Float, None);
    image.texture_descriptor.usage |= TextureUsages::COPY_SRC;
    let target = app.world_mut().resource_mut::<Assets<Image>>().add(image);
    let camera = app
        .world_mut()
        .spawn((
            Camera3d::default(),
            RenderTarget::Image(target.clone().into()),
            Msaa::Off,
            Tonemapping::None,
            bevy::camera::Hdr,
            bevy::core_pipeline::tonemapping::DebandDither::Disabled,
            Exposure { ev100: EV100 },
            VolumetricMedium {
                scattering: spot_scene::SCATTERING,
                absorption: spot_scene::ABSORPTION,
                asymmetry: G,
                ..default()
            },
            view,
        ))
        .id();
    (app, camera, target)
}

fn reference_spot() -> SpotLight {
    spot_scene::bevy_spot(false)
}

/// Per pixel of `camera`'s view: the exact in-scatter with `occluders`, the `n`-sample
/// estimate with `sampling`, and the pixels within 15° of the light.
fn expected_with(
    app: &mut App,
    camera: Entity,
    n: u32,
    sampling: Sampling,
    occluders: &[reference::Occluder],
) -> spot_scene::Truth {
    let world = app.world_mut();
    let (cam, transform) = world
        .query::<(&Camera, &GlobalTransform)>()
        .get(world, camera)
        .unwrap();
    spot_scene::truth(
        transform.to_matrix(),
        cam.clip_from_view(),
        UVec2::new(W, H),
        G,
        occluders,
        None,
        Some((sampling, n)),
    )
}

/// The scores of one view: the GPU against the exact reference (all, and within 15° of the
/// light), against its CPU mirror, the mirror's own error, and what equal depths would give
/// near the tip.
struct Scores {
    exact: f64,
    tip: f64,
    tip_pixels: usize,
    mirror: f64,
    mirror_own: f64,
    equal_depth_tip: f64,
}

/// Which form of the full-resolution pass a view gets.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Form {
    /// The compute pass (the camera's main images take storage writes, as the plugin asks).
    Compute,
    /// The fullscreen fragment pass: the camera's usages reset without `STORAGE_BINDING`
    /// after the plugin asked, as a user's own usages would.
    Raster,
}

/// Runs `app` until the pass of `form` has run (pipelines compile in the background), asserting
/// that the other form did not.
fn run_form(app: &mut App, camera: Entity, form: Form) {
    if form == Form::Raster {
        run(app, 1);
        app.world_mut()
            .entity_mut(camera)
            .insert(bevy::camera::CameraMainTextureUsages::default());
    }
    let mut frames = 0;
    while !span_ran(app, form.span()) && frames < 40 {
        run(app, 1);
        frames += 1;
    }
    run(app, 2);
    assert!(span_ran(app, form.span()), "the {form:?} pass did not run");
    let other = match form {
        Form::Compute => Form::Raster,
        Form::Raster => Form::Compute,
    };
    // (A form that ran once keeps its last measurement; a fresh app has none.)
    if form == Form::Compute {
        assert!(!span_ran(app, other.span()), "the {other:?} pass ran too");
    }
}

impl Form {
    fn span(self) -> &'static str {
        match self {
            Form::Compute => "volumetric/spots_compute",
            Form::Raster => "volumetric/spots",
        }
    }
}

fn scores(view: Transform) -> Scores {
    scores_of(view, Form::Compute).0
}

/// The scores of one view in `form`, and its picture.
fn scores_of(view: Transform, form: Form) -> (Scores, Vec<f32>) {
    let (mut app, camera, target) = spot_scene(reference_spot(), VolumetricSpot::default(), view);
    run_form(&mut app, camera, form);
    let gpu = red(&screenshot(&mut app, &target));
    let angles = expected_with(&mut app, camera, 16, Sampling::EqualAngle, &[]);
    let depths = expected_with(&mut app, camera, 16, Sampling::EqualDepth, &[]);
    let (exact, tip) = (&angles.exact, Some(angles.tip.as_slice()));
    assert!(exact.iter().cloned().fold(0.0, f64::max) > 0.05, "the beam is visible");
    let s = Scores {
        exact: relative_l1(&gpu, exact, None),
        tip: relative_l1(&gpu, exact, tip),
        tip_pixels: angles.tip.iter().filter(|&&t| t).count(),
        mirror: relative_l1(&gpu, &angles.estimate, None),
        mirror_own: relative_l1(&angles.estimate, exact, None),
        equal_depth_tip: relative_l1(&depths.estimate, exact, tip),
    };
    eprintln!(
        "rel L1: GPU/exact {:.4} (tip {:.4}, {} px), GPU/mirror {:.4}, mirror/exact {:.4}, \
         equal depths at the tip {:.4}",
        s.exact, s.tip, s.tip_pixels, s.mirror, s.mirror_own, s.equal_depth_tip
    );
    (s, gpu)
}

#[test]
fn an_unshadowed_spot_matches_the_reference_at_16_equal_angle_samples() {
    if !gpu_or_skip() {
        return;
    }
    // The camera: across the room, the light in view near the top.
    let across = scores(
        Transform::from_xyz(0.0, 1.6, 7.0).looking_at(Vec3::new(0.0, 1.5, 0.0), Vec3::Y),
    );
    // From inside the beam, looking up at the light: rays run along the cone to its tip, where
    // equal depths miss the 1/d² spike.
    let up_the_beam = scores(
        Transform::from_xyz(0.45, 0.3, 0.25).looking_at(Vec3::new(0.0, 4.0, 0.0), Vec3::X),
    );
    // Measured on llvmpipe (across / up the beam): against the exact reference 0.0017 / 0.0010,
    // within 15° of the light 0.0016 / 0.0009 (the goals: 0.01 and 0.02); against the
    // CPU mirror of the pass 0.0004 / 0.0003 (f32 against f64, f16 output). Margins 0.002 and
    // 0.001. Equal depths would give 0.019 near the tip up the beam: this test fails if the
    // pass samples so.
    for (name, s) in [("across", &across), ("up the beam", &up_the_beam)] {
        assert!(s.tip_pixels > 20, "{name}: the light is in view ({} px)", s.tip_pixels);
        assert!(s.exact <= 0.0037, "{name}: GPU against the exact reference {:.4}", s.exact);
        assert!(s.tip <= 0.0036, "{name}: near the tip {:.4}", s.tip);
        assert!(s.mirror <= 0.0014, "{name}: GPU against its CPU mirror {:.4}", s.mirror);
    }
}

/// Seed 004's slicing planes (`VolumetricMethod::SlicingPlanes`, 16 per spot) against their
/// CPU mirror (`reference::Sampling::SlicingPlanes`) and the exact reference, across the room
/// and up the beam: the GPU follows the mirror; across the room they are near the reference,
/// up the beam, where the rays run along the cone to its tip, they miss much of it (the
/// planes are shared by the view's pixels, not spaced about each ray).
#[test]
fn slicing_planes_match_their_cpu_mirror_and_miss_the_tip() {
    if !gpu_or_skip() {
        return;
    }
    use bevy_mesostructure::volumetric::{VolumetricMethod, reference::SlicingPlanes};
    let mut measured = vec![];
    for view in [
        Transform::from_xyz(0.0, 1.6, 7.0).looking_at(Vec3::new(0.0, 1.5, 0.0), Vec3::Y),
        Transform::from_xyz(0.45, 0.3, 0.25).looking_at(Vec3::new(0.0, 4.0, 0.0), Vec3::X),
    ] {
        let (mut app, camera, target) = spot_scene(reference_spot(), VolumetricSpot::default(), view);
        app.world_mut().entity_mut(camera).insert(VolumetricMedium {
            scattering: spot_scene::SCATTERING,
            absorption: spot_scene::ABSORPTION,
            asymmetry: G,
            method: VolumetricMethod::SlicingPlanes,
            ..default()
        });
        run(&mut app, 3);
        let gpu = red(&screenshot(&mut app, &target));
        let light = spot_scene::reference_light();
        // Bevy's default perspective near plane.
        let planes = SlicingPlanes::for_light(
            view.translation.as_dvec3(),
            view.forward().as_dvec3(),
            &light,
            0.1,
        );
        let t = expected_with(&mut app, camera, 16, Sampling::SlicingPlanes(planes), &[]);
        let tip = Some(t.tip.as_slice());
        let s = (
            relative_l1(&gpu, &t.estimate, None),
            relative_l1(&gpu, &t.exact, None),
            relative_l1(&gpu, &t.exact, tip),
        );
        eprintln!(
            "slicing planes: GPU/mirror {:.4}, GPU/exact {:.4}, within 15° of the light {:.4}",
            s.0, s.1, s.2
        );
        measured.push(s);
    }
    // Measured on llvmpipe (across / up the beam): against the mirror 0.0010 / 0.0005 (f32
    // against f64, f16 output; margin 0.001); against the exact reference 0.239 / 1.351, within
    // 15° of the light 0.370 / 1.494 (16 per-ray equal angles: 0.0017 / 0.0010 and 0.0016 /
    // 0.0009); held to ±10 %.
    let (across, up) = (measured[0], measured[1]);
    assert!(across.0 <= 0.0020 && up.0 <= 0.0015, "GPU against its mirror: {:.4}, {:.4}", across.0, up.0);
    for (name, got, want) in [
        ("across the room", across.1, 0.239),
        ("across the room, near the light", across.2, 0.370),
        ("up the beam", up.1, 1.351),
        ("up the beam, near the light", up.2, 1.494),
    ] {
        assert!((got / want - 1.0).abs() <= 0.1, "{name}: {got:.4} against the exact reference, measured {want}");
    }
}

#[test]
fn bad_spots_and_media_warn_once_and_render() {
    if !gpu_or_skip() {
        return;
    }
    let view = Transform::from_xyz(0.0, 1.6, 7.0).looking_at(Vec3::new(0.0, 1.5, 0.0), Vec3::Y);
    let (mut app, camera, image) = spot_scene(
        SpotLight {
            // Not a cone: narrowed to 89°.
            outer_angle: 95f32.to_radians(),
            inner_angle: f32::NAN,
            ..reference_spot()
        },
        VolumetricSpot {
            intensity_scale: f32::NAN,
            samples: 0,
        },
        view,
    );
    // A spot with no cone at all: dropped.
    app.world_mut().spawn((
        SpotLight {
            outer_angle: 0.0,
            inner_angle: 0.0,
            ..reference_spot()
        },
        VolumetricSpot::default(),
        Transform::from_xyz(1.0, 3.0, 0.0).looking_at(Vec3::ZERO, Vec3::Z),
    ));
    app.world_mut().entity_mut(camera).insert(VolumetricMedium {
        scattering: -1.0,
        absorption: f32::NAN,
        asymmetry: 2.0,
        ..default()
    });
    // A second camera with MSAA: the volumetric spots are off there, with a warning.
    let t2 = target(&mut app, 32, 32);
    app.world_mut().spawn((
        Camera3d::default(),
        RenderTarget::Image(t2.into()),
        Camera {
            order: 1,
            ..default()
        },
        Msaa::Sample4,
        VolumetricMedium::default(),
        view,
    ));
    run(&mut app, 3);
    let gpu = red(&screenshot(&mut app, &image));
    assert!(gpu.iter().all(|v| v.is_finite()), "no NaN on screen");
    let w = warnings(&app);
    for key in [
        "volumetric spot angle",
        "volumetric spot settings",
        "volumetric medium",
        "volumetric msaa",
    ] {
        assert!(w.iter().any(|k| k.starts_with(key)), "a warning about {key}: {w:?}");
    }
    let dropped = |k: &String| {
        k.strip_prefix("volumetric spot ")
            .is_some_and(|rest| rest.starts_with(|c: char| c.is_ascii_digit()))
    };
    assert!(w.iter().any(dropped), "a warning about the spot without a cone: {w:?}");
    // One-time: running on adds none.
    let count = w.len();
    run(&mut app, 2);
    assert_eq!(warnings(&app).len(), count);
}

#[test]
fn a_box_casts_a_shaft_through_the_beam() {
    if !gpu_or_skip() {
        return;
    }
    let view = Transform::from_xyz(0.0, 1.6, 7.0).looking_at(Vec3::new(0.0, 1.5, 0.0), Vec3::Y);
    let spot = SpotLight {
        shadow_maps_enabled: true,
        ..reference_spot()
    };
    let (mut app, camera, target) = spot_scene_with(spot, VolumetricSpot::default(), view, true);
    run_form(&mut app, camera, Form::Compute);
    let gpu = red(&screenshot(&mut app, &target));
    let cube = spot_scene::cube();
    let with_cube = expected_with(&mut app, camera, 16, Sampling::EqualAngle, &[cube]);
    let (shadowed, mirror) = (&with_cube.exact, &with_cube.estimate);
    // The same rays without the cube's shadow: how much the shaft takes. (These rays pass the
    // cube; only the pixels it covers differ, and there both are 0 past its face.)
    let open = expected_with(&mut app, camera, 16, Sampling::EqualAngle, &[]).exact;
    let error = relative_l1(&gpu, shadowed, None);
    let mirror_error = relative_l1(mirror, shadowed, None);
    let taken = 1.0 - shadowed.iter().sum::<f64>() / open.iter().sum::<f64>();
    let gpu_taken = 1.0 - gpu.iter().map(|&v| v as f64).sum::<f64>() / open.iter().sum::<f64>();
    eprintln!(
        "shadowed rel L1: GPU/exact {error:.4}, mirror/exact {mirror_error:.4}; the shaft \
         takes {taken:.4} of the in-scatter (GPU {gpu_taken:.4})"
    );
    // Measured on llvmpipe (compute form, one 2×2 PCF tap per sample): 0.0025 against the
    // exact reference (0.0023 with Bevy's Gaussian filter; the goal for shadowed
    // spots: 0.03; the 16 samples' own error is 0.0025), the shaft taking 0.6357 of the
    // in-scatter against the reference's 0.6358 (Bevy's spot shadow map, 1024², read at every
    // sample). Margins 0.002 and 0.01.
    assert!(error <= 0.0043, "GPU against the exact shadowed reference: {error:.4}");
    assert!((gpu_taken - taken).abs() <= 0.01, "the shaft takes {gpu_taken:.4}, not {taken:.4}");
}

/// The across-the-room view of the reference spot with what `scene` adds, in the compute form
/// and in the fragment form (each once `ready` says the scene's own passes have run), and
/// their relative L1.
fn compute_against_fragment(
    scene: impl Fn(&mut App, Entity),
    ready: impl Fn(&App) -> bool,
) -> (f64, Vec<f64>) {
    let view = Transform::from_xyz(0.0, 1.6, 7.0).looking_at(Vec3::new(0.0, 1.5, 0.0), Vec3::Y);
    let picture = |form| {
        let (mut app, camera, target) =
            spot_scene_with(reference_spot(), VolumetricSpot::default(), view, false);
        scene(&mut app, camera);
        run_form(&mut app, camera, form);
        // The scene's other passes may compile later than the volumetric one (seen under the
        // whole suite's load): frames until they have run too.
        let mut frames = 0;
        while !ready(&app) && frames < 40 {
            run(&mut app, 1);
            frames += 1;
        }
        assert!(ready(&app), "the scene's own passes did not run in 40 more frames ({form:?})");
        red(&screenshot(&mut app, &target))
    };
    let compute = picture(Form::Compute);
    let fragment: Vec<f64> = picture(Form::Raster).iter().map(|&v| v as f64).collect();
    (relative_l1(&compute, &fragment, None), fragment)
}

/// The compute pass's per-tile culling (each tile keeps the spots whose screen rectangle
/// overlaps it and whose bounding sphere begins in front of its farthest surface) changes
/// nothing on screen: three spots, two of short range, one of them hidden behind a box near
/// the camera over part of the view, give the picture of the fragment pass, which culls per
/// pixel by the rectangle alone.
#[test]
fn tile_culling_keeps_the_fragment_pass_picture() {
    if !gpu_or_skip() {
        return;
    }
    let (between, fragment) = compute_against_fragment(
        |app, _| {
            let white = unlit(app, Color::WHITE);
            let box_mesh = mesh(app, Cuboid::new(1.2, 1.2, 0.2));
            // Near the camera, over the left half of the beam.
            app.world_mut()
                .spawn((box_mesh, white, Transform::from_xyz(-0.5, 1.9, 5.0)));
            for (x, z, range) in [(-2.5, -2.0, 5.0), (2.0, -1.0, 6.0)] {
                app.world_mut().spawn((
                    SpotLight {
                        range,
                        ..reference_spot()
                    },
                    VolumetricSpot::default(),
                    Transform::from_xyz(x, 3.0, z).looking_at(Vec3::new(x, 0.0, z + 0.5), Vec3::Z),
                ));
            }
        },
        |_| true,
    );
    let lit = fragment.iter().filter(|&&v| v > 0.01).count();
    eprintln!("tile culling: compute against fragment {between:.6} over {lit} lit pixels");
    // Measured on llvmpipe: identical (0.000000) over 1656 lit pixels. Margin 0.0005 (f16
    // rounding of a different summation).
    assert!(lit > 500, "the beams are in view ({lit} px)");
    assert!(between <= 0.0005, "compute and fragment pictures differ by {between:.6}");
}

/// With the mesostructure plugin on the same camera, whose colour bleeding also writes the
/// view's other main image in compute, the compute form gives the fragment form's picture
/// (before the passes were ordered, the two flips of the main images could reach the GPU in
/// either order, and the frame came out black).
#[test]
fn the_compute_pass_composes_with_the_mesostructure_passes() {
    if !gpu_or_skip() {
        return;
    }
    let (between, fragment) = compute_against_fragment(
        |app, camera| {
            let grey = app
                .world_mut()
                .resource_mut::<Assets<StandardMaterial>>()
                .add(Color::srgb(0.6, 0.6, 0.6));
            let bricks = image(
                app,
                bevy_mesostructure::height_maps::HeightMap::bricks(128, 4, 0.15).to_image(),
            );
            let plane = mesostructure_plane(app, MeshMaterial3d(grey), bricks, 0.1);
            app.world_mut()
                .entity_mut(plane)
                .insert(Transform::from_xyz(0.5, 0.01, 0.0).with_scale(Vec3::splat(2.0)));
            app.world_mut()
                .entity_mut(camera)
                .insert(bevy_mesostructure::Mesostructure::default());
        },
        // The bleeding pass is the last of the plugin's before the volumetric one.
        |app| span_ran(app, "mesostructure/bleeding"),
    );
    let mean = fragment.iter().sum::<f64>() / fragment.len() as f64;
    eprintln!("with the mesostructure passes: compute against fragment {between:.6}, mean {mean:.4}");
    // Measured on llvmpipe: identical (0.000000); with the passes unordered, 1.81. Margin
    // 0.0005.
    assert!(mean > 0.01, "the frame is lit ({mean})");
    assert!(between <= 0.0005, "compute and fragment pictures differ by {between:.6}");
}

/// Rays passing within millimetres of a shadowed spot (a 0.5° view of the light, ~1 mm per
/// pixel there) get their in-scatter: points nearer the light than its shadow map's near plane
/// are not shadowed by the map (Bevy's lookup, with its depth bias, put them behind the light
/// and read them as shadowed: 0.52 off here, and at 1080p the whole picture's 2.3 % error),
/// and the cone is clipped about the ray's point closest to the light (about the camera, f32
/// lost the few millimetres of cone the rays cross: 0.058 off with the shadows fixed).
#[test]
fn rays_grazing_a_shadowed_light_are_not_shadowed_by_its_own_map() {
    if !gpu_or_skip() {
        return;
    }
    let eye = Vec3::new(0.0, 1.6, 7.0);
    let view = Transform::from_translation(eye).looking_at(spot_scene::SPOT_POSITION, Vec3::Y);
    let spot = SpotLight {
        shadow_maps_enabled: true,
        ..reference_spot()
    };
    let (mut app, camera, target) = spot_scene_with(spot, VolumetricSpot::default(), view, false);
    app.world_mut().entity_mut(camera).insert(Projection::Perspective(PerspectiveProjection {
        fov: 0.5f32.to_radians(),
        ..default()
    }));
    run_form(&mut app, camera, Form::Compute);
    let gpu = red(&screenshot(&mut app, &target));
    let t = expected_with(&mut app, camera, 16, Sampling::EqualAngle, &[]);
    let error = relative_l1(&gpu, &t.exact, None);
    let mirror = relative_l1(&t.estimate, &t.exact, None);
    let ratio = gpu.iter().map(|&v| v as f64).sum::<f64>() / t.exact.iter().sum::<f64>();
    eprintln!("grazing the light: GPU/exact {error:.4} (mean {ratio:.4}), mirror/exact {mirror:.4}");
    // Measured on llvmpipe: 0.0019 (mean 0.9992 of the reference; the CPU mirror of 16
    // samples 0.0018). Margin 0.002.
    assert!(error <= 0.0039, "GPU against the exact reference near the light: {error:.4}");
}

/// Whether a pass recorded its span `name`.
fn span_ran(app: &App, name: &str) -> bool {
    let store = app.world().resource::<bevy::diagnostic::DiagnosticsStore>();
    let path = bevy::diagnostic::DiagnosticPath::new(format!("render/{name}/elapsed_cpu"));
    store.get(&path).and_then(|d| d.measurement()).is_some()
}

/// Whether the volumetric pass (either form) recorded its span.
fn volumetric_pass_ran(app: &App) -> bool {
    span_ran(app, Form::Compute.span()) || span_ran(app, Form::Raster.span())
}

/// The fullscreen fragment pass, which runs where the camera's main images take no storage
/// writes (a user's own `CameraMainTextureUsages`, a non-HDR camera), gives the compute pass's
/// picture.
#[test]
fn the_raster_fallback_gives_the_compute_pass_picture() {
    if !gpu_or_skip() {
        return;
    }
    let across = Transform::from_xyz(0.0, 1.6, 7.0).looking_at(Vec3::new(0.0, 1.5, 0.0), Vec3::Y);
    let (compute, compute_picture) = scores_of(across, Form::Compute);
    let (raster, raster_picture) = scores_of(across, Form::Raster);
    let between = relative_l1(&raster_picture, &compute_picture.iter().map(|&v| v as f64).collect::<Vec<_>>(), None);
    eprintln!("raster against compute: {between:.6}");
    // Measured on llvmpipe: the two pictures identical (0.000000); both 0.0017 against the
    // exact reference. Margin 0.0005 between them (f16 rounding of a different summation).
    assert!(between <= 0.0005, "raster and compute differ by {between:.6}");
    assert!((raster.exact - compute.exact).abs() <= 0.0005);
}

#[test]
fn surfaces_are_dimmed_by_the_medium_with_or_without_a_cone_in_view() {
    if !gpu_or_skip() {
        return;
    }
    // A spot whose range ends at the floor (its cone's bounding sphere stays near it), and a
    // camera looking away from it at a white (unlit) wall 6 m away.
    let short = SpotLight {
        range: 6.0,
        ..reference_spot()
    };
    let away = Transform::from_xyz(0.0, 1.6, 7.0).looking_at(Vec3::new(0.0, 1.6, 20.0), Vec3::Y);
    let (mut app, _, target) = spot_scene(short, VolumetricSpot::default(), away);
    let white = unlit(&mut app, Color::WHITE);
    let wall = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .add(Plane3d::new(Vec3::NEG_Z, Vec2::splat(20.0)).mesh());
    app.world_mut()
        .spawn((Mesh3d(wall), white, Transform::from_xyz(0.0, 1.6, 13.0)));
    run(&mut app, 3);
    let gpu = red(&screenshot(&mut app, &target));
    // The centre pixel looks straight at the wall: 6 m of medium, σt = 0.11.
    let centre = gpu[((H / 2) * W + W / 2) as usize];
    let expected = (-(spot_scene::SCATTERING + spot_scene::ABSORPTION) * 6.0).exp();
    // Measured 0.5166 against 0.5169 (f16 output); margin 0.002.
    assert!(
        (centre - expected).abs() < 0.002,
        "the wall is dimmed to {centre}, not e^(−σt·6) = {expected}"
    );
    assert!(volumetric_pass_ran(&app), "the pass dims with no cone in view");
    // A transparent medium and no cone in view: nothing to do, no pass.
    let (mut app, camera, _) = spot_scene(short, VolumetricSpot::default(), away);
    app.world_mut().entity_mut(camera).insert(VolumetricMedium {
        scattering: 0.0,
        absorption: 0.0,
        ..default()
    });
    run(&mut app, 5);
    assert!(!volumetric_pass_ran(&app), "the pass ran with nothing to add or dim");
    // Looking at the cone: it runs.
    let towards = Transform::from_xyz(0.0, 1.6, 7.0).looking_at(Vec3::new(0.0, 1.5, 0.0), Vec3::Y);
    let (mut app, _, _) = spot_scene(short, VolumetricSpot::default(), towards);
    // (Its pipeline compiles in the background: on a loaded machine that can take more than a
    // few frames.)
    let mut frames = 0;
    while !volumetric_pass_ran(&app) && frames < 40 {
        run(&mut app, 1);
        frames += 1;
    }
    assert!(volumetric_pass_ran(&app), "the pass did not run with the cone in view");
}

#[test]
fn reduced_resolutions_upsample_close_to_the_reference() {
    if !gpu_or_skip() {
        return;
    }
    let view = Transform::from_xyz(0.0, 1.6, 7.0).looking_at(Vec3::new(0.0, 1.5, 0.0), Vec3::Y);
    let mut errors = vec![];
    for resolution in [VolumetricResolution::Half, VolumetricResolution::Quarter] {
        let spot = SpotLight {
            shadow_maps_enabled: true,
            ..reference_spot()
        };
        let (mut app, camera, target) = spot_scene_with(spot, VolumetricSpot::default(), view, true);
        let mut medium = *app.world().get::<VolumetricMedium>(camera).unwrap();
        medium.resolution = resolution;
        app.world_mut().entity_mut(camera).insert(medium);
        run(&mut app, 3);
        let gpu = red(&screenshot(&mut app, &target));
        let cube = spot_scene::cube();
        let exact = expected_with(&mut app, camera, 16, Sampling::EqualAngle, &[cube]).exact;
        errors.push(relative_l1(&gpu, &exact, None));
    }
    eprintln!("rel L1 at half and quarter resolution (shadowed): {errors:?}");
    // Measured at 64×48 (the worst case: the light's tip, where the in-scatter peaks, spans a
    // few pixels): 0.199 and 0.294; at 256×144 the bench measures 0.063 and 0.161 (full
    // resolution: 0.0023). Margins 0.02 and 0.03.
    assert!(errors[0] <= 0.22 && errors[1] <= 0.32, "{errors:?}");
}
