//! The synthetic top-down suite's scene: the plane rendered with each method, the pictures
//! and the error measures.

use super::*;

pub(crate) const HEIGHT: f32 = 2.0;

/// What one render gives back.
pub(crate) struct Render {
    pub(crate) frame: Option<CapturedFrame>,
    /// Green channel of the lit picture, linear (from the capture's opaque image).
    pub(crate) gpu_ms: f64,
}

/// Renders the plane top-down once: with the plugin (and `settings`) on the flat plane with
/// `map`, or as real geometry (`grid`) with or without SSAO. Lights: `elevation` (None =
/// ambient only).
pub(crate) fn render(
    map: &HeightMap,
    k: f32,
    size: u32,
    settings: Option<common::unseen::Variant>,
    ssao: bool,
    elevation: Option<f32>,
) -> (Render, Vec<f32>) {
    let (mut app, target) = common::unseen::measuring_app(common::headless_plugins(), size);
    let world = app.world_mut();
    let mut camera = world.spawn((
        Camera3d::default(),
        RenderTarget::Image(target.clone().into()),
        Msaa::Off,
        Hdr,
        Tonemapping::None,
        Transform::from_xyz(0.0, HEIGHT, 0.0).looking_at(Vec3::ZERO, Vec3::NEG_Z),
    ));
    if let Some(v) = settings.clone() {
        camera.insert((v.settings, MesostructureCapture));
        if let Some(baseline) = v.baseline {
            camera.insert(baseline);
        }
    }
    if ssao {
        camera.insert(ScreenSpaceAmbientOcclusion::default());
    }
    let camera = camera.id();
    world.insert_resource(bevy::light::GlobalAmbientLight {
        brightness: if elevation.is_some() { 0.0 } else { 2000.0 },
        ..default()
    });
    if let Some(e) = elevation {
        let e = e.to_radians();
        world.spawn((
            DirectionalLight {
                illuminance: 3000.0,
                ..default()
            },
            Transform::default().looking_to(Vec3::new(e.cos(), -e.sin(), 0.0), Vec3::Y),
        ));
    }
    let material = world
        .resource_mut::<Assets<StandardMaterial>>()
        .add(StandardMaterial {
            perceptual_roughness: 1.0,
            reflectance: 0.0,
            ..default()
        });
    if settings.is_some() {
        let plane = world
            .resource_mut::<Assets<Mesh>>()
            .add(Plane3d::default().mesh().size(2.0, 2.0));
        let height_map = world.resource_mut::<Assets<Image>>().add(map.to_image());
        world.spawn((
            Mesh3d(plane),
            MeshMaterial3d(material),
            MesostructureMaterial {
                height_map,
                scale: k,
                ..default()
            },
        ));
    } else {
        let grid = world
            .resource_mut::<Assets<Mesh>>()
            .add(map.displaced_plane(k, 256));
        world.spawn((Mesh3d(grid), MeshMaterial3d(material)));
    }
    use common::unseen::{ADDED_PASSES, median_gpu_ms, take_capture, wait_for_pipelines};
    assert!(
        wait_for_pipelines(&mut app),
        "pipelines still compiling after 600 frames"
    );
    let frame = take_capture(&mut app, camera);
    let gpu_ms = if ssao {
        median_gpu_ms(&app, "ssao")
    } else if settings.is_some() {
        ADDED_PASSES
            .iter()
            .map(|p| median_gpu_ms(&app, &format!("mesostructure/{p}")))
            .sum()
    } else {
        0.0
    };
    // The picture, linear green (Tonemapping::None onto an sRGB target).
    app.world_mut()
        .spawn(bevy::render::view::screenshot::Screenshot::image(
            target.clone(),
        ))
        .observe(
            |shot: On<bevy::render::view::screenshot::ScreenshotCaptured>,
             mut out: ResMut<Picture>| {
                out.0 = shot.image.data.clone().unwrap_or_default();
            },
        );
    app.init_resource::<Picture>();
    for _ in 0..3 {
        app.update();
    }
    let picture = app
        .world()
        .resource::<Picture>()
        .0
        .chunks_exact(4)
        .map(|c| srgb(c[1]))
        .collect();
    (Render { frame, gpu_ms }, picture)
}

#[derive(Resource, Default)]
pub(crate) struct Picture(Vec<u8>);

pub(crate) fn srgb(v: u8) -> f32 {
    let v = v as f32 / 255.0;
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// UV of the plane under pixel (x, y) of the top-down camera.
pub(crate) fn uv(x: u32, y: u32, size: u32) -> Vec2 {
    let t = std::f32::consts::FRAC_PI_8.tan() * HEIGHT;
    let ndc = |p: u32| ((p as f32 + 0.5) / size as f32) * 2.0 - 1.0;
    Vec2::new((ndc(x) * t + 1.0) * 0.5, (ndc(y) * t + 1.0) * 0.5)
}

pub(crate) fn errors(values: &[f32], truth: &[f32]) -> (f32, f32) {
    let n = values.len().max(1) as f32;
    let mae = values
        .iter()
        .zip(truth)
        .map(|(v, t)| (v - t).abs())
        .sum::<f32>()
        / n;
    let rmse = (values
        .iter()
        .zip(truth)
        .map(|(v, t)| (v - t).powi(2))
        .sum::<f32>()
        / n)
        .sqrt();
    (mae, rmse)
}

pub(crate) struct Row {
    pub(crate) scene: String,
    pub(crate) method: String,
    pub(crate) setting: String,
    pub(crate) gpu_ms: f64,
    pub(crate) ao: (f32, f32),
    pub(crate) shadow: f32,
    pub(crate) bounce: f32,
    pub(crate) flip: f32,
}

/// The radiance of the FLIP pictures, in units of a surface facing the light: an ambient light
/// of a quarter of the sun times AO, the direct term, the bounce.
pub(crate) fn shade(ao: f32, lit: f32, bounce: f32) -> f32 {
    0.25 * ao + lit + bounce
}

/// Mean FLIP error of `test` against `reference`, both `w` × `w` radiances shaded by [`shade`],
/// shown ×0.75 as sRGB grey.
pub(crate) fn flip_mean(reference: &[f32], test: &[f32], w: u32) -> f32 {
    let encode = |values: &[f32]| -> Vec<u8> {
        values
            .iter()
            .flat_map(|&v| {
                let v = (0.75 * v).clamp(0.0, 1.0);
                let s = if v <= 0.0031308 {
                    12.92 * v
                } else {
                    1.055 * v.powf(1.0 / 2.4) - 0.055
                };
                [(s * 255.0).round() as u8; 3]
            })
            .collect()
    };
    let error = nv_flip::flip(
        nv_flip::FlipImageRgb8::with_data(w, w, &encode(reference)),
        nv_flip::FlipImageRgb8::with_data(w, w, &encode(test)),
        nv_flip::DEFAULT_PIXELS_PER_DEGREE,
    );
    nv_flip::FlipPool::from_image(&error).mean()
}
