//! `translucent_accuracy --bevy`: Bevy's `diffuse_transmission`, fitted to the same reference
//! by a grid search, as the yardstick the issue measures against.

use std::sync::{Arc, Mutex};

use bevy::prelude::*;

use super::{
    headless, meshes,
    translucent_accuracy_scene::{self, BUNNY_LENGTH, FOV_Y, RADIUS, Shape, ShapeView},
};

/// Renders the ball with Bevy's `StandardMaterial` (white, no specular) for each diffuse
/// transmission and thickness of the grid, fits the base colour per channel (the weighted
/// median of reference / render: the L1-best scale, as Bevy's light is linear in it) and
/// returns the best relative L1 with its transmission, thickness and colour.
pub fn bevy_best_fit(
    reference: &image::Rgb32FImage,
    view: &ShapeView,
    light: Vec3,
) -> Result<(f64, f32, f32, [f32; 3]), String> {
    let size = view.size;
    let scored = |x: u32, y: u32, _: u32| view.scored[(y * size + x) as usize];
    use bevy::{
        camera::{Exposure, RenderTarget},
        core_pipeline::tonemapping::Tonemapping,
        render::{
            render_resource::{TextureFormat, TextureUsages},
            view::screenshot::{Screenshot, ScreenshotCaptured},
        },
    };
    let mut app = App::new();
    app.add_plugins(headless::headless_plugins().disable::<bevy::log::LogPlugin>());
    app.finish();
    app.cleanup();
    app.insert_resource(bevy::light::GlobalAmbientLight {
        brightness: 0.0,
        ..default()
    });
    // Irradiance × exposure: a white Lambertian facing the light reads 0.85.
    let exposure = Exposure { ev100: 0.0 };
    let illuminance = 0.85 * std::f32::consts::PI / exposure.exposure();
    app.world_mut().spawn((
        DirectionalLight {
            illuminance,
            ..default()
        },
        Transform::default().looking_to(light, Vec3::Y),
    ));
    let mut image = Image::new_target_texture(size, size, TextureFormat::Rgba8UnormSrgb, None);
    image.texture_descriptor.usage |= TextureUsages::COPY_SRC;
    let target = app.world_mut().resource_mut::<Assets<Image>>().add(image);
    app.world_mut().spawn((
        Camera3d::default(),
        Projection::Perspective(PerspectiveProjection {
            fov: FOV_Y,
            near: 0.0005,
            ..default()
        }),
        RenderTarget::Image(target.clone().into()),
        Msaa::Off,
        Tonemapping::None,
        exposure,
        Transform::from_translation(view.shape.eye()).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    // The shape as a game would load it: the ico sphere, or the bunny's OBJ with smooth
    // normals and UVs (as the `translucent` example's; a mesh without UVs rendered black
    // here), scaled as the accuracy scene scales it.
    let shape_mesh = match view.shape {
        Shape::Ball => Sphere::new(RADIUS).mesh().ico(5).expect("a valid subdivision"),
        Shape::Bunny => meshes::obj_mesh(&meshes::asset_path("meshes/bunny.obj"), 1.0)
            .scaled_by(Vec3::splat(BUNNY_LENGTH / 1.6)),
        Shape::Torus => translucent_accuracy_scene::torus_mesh(),
    };
    let mesh = app.world_mut().resource_mut::<Assets<Mesh>>().add(shape_mesh);
    let material = app
        .world_mut()
        .resource_mut::<Assets<StandardMaterial>>()
        .add(StandardMaterial {
            base_color: Color::WHITE,
            perceptual_roughness: 1.0,
            reflectance: 0.0,
            ..default()
        });
    app.world_mut()
        .spawn((Mesh3d(mesh), MeshMaterial3d(material.clone())));
    let decode = |s: f32| {
        if s <= 0.04045 {
            s / 12.92
        } else {
            ((s + 0.055) / 1.055).powf(2.4)
        }
    };
    let mut best = (f64::INFINITY, 0.0, 0.0, [0.0; 3]);
    for thickness in [0.0, 0.02] {
        for step in 0..=10 {
            let transmission = step as f32 / 10.0;
            if let Some(mut m) = app
                .world_mut()
                .resource_mut::<Assets<StandardMaterial>>()
                .get_mut(&material)
            {
                m.diffuse_transmission = transmission;
                m.thickness = thickness;
            }
            for _ in 0..3 {
                app.update();
            }
            let slot: Arc<Mutex<Option<Image>>> = Arc::default();
            let s = slot.clone();
            app.world_mut()
                .spawn(Screenshot::image(target.clone()))
                .observe(move |ev: On<ScreenshotCaptured>| {
                    *s.lock().unwrap() = Some(ev.image.clone())
                });
            let shot = (0..20).find_map(|_| {
                app.update();
                slot.lock().unwrap().take()
            });
            let Some(shot) = shot else {
                return Err("Bevy's picture never came back".into());
            };
            // Radiance per unit irradiance of the white ball, per pixel and channel.
            let white: Vec<[f32; 3]> = (0..size * size)
                .map(|i| {
                    let c = shot
                        .get_color_at(i % size, i / size)
                        .map(|c| c.to_srgba())
                        .unwrap_or(Srgba::BLACK);
                    [c.red, c.green, c.blue]
                        .map(|v| decode(v) / (illuminance * exposure.exposure()))
                })
                .collect();
            let mut colour = [0.0f32; 3];
            let mut error = 0.0f64;
            let mut total = 0.0f64;
            for c in 0..3 {
                // Weighted median of reference / render, weights the render.
                let mut pairs: Vec<(f32, f32)> = (0..size * size)
                    .filter(|&i| scored(i % size, i / size, size))
                    .filter_map(|i| {
                        let f = white[i as usize][c];
                        let m = reference.get_pixel(i % size, i / size).0[c];
                        (f > 1e-4 && m > 0.0).then_some((m / f, f))
                    })
                    .collect();
                pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
                let half = pairs.iter().map(|p| p.1).sum::<f32>() / 2.0;
                let mut acc = 0.0;
                colour[c] = pairs
                    .iter()
                    .find(|p| {
                        acc += p.1;
                        acc >= half
                    })
                    .map_or(0.0, |p| p.0.clamp(0.0, 1.0));
                for i in (0..size * size).filter(|&i| scored(i % size, i / size, size)) {
                    let m = reference.get_pixel(i % size, i / size).0[c];
                    error += (colour[c] * white[i as usize][c] - m).abs() as f64;
                    total += m as f64;
                }
            }
            let relative = error / total;
            if relative < best.0 {
                best = (relative, transmission, thickness, colour);
            }
        }
    }
    Ok(best)
}
