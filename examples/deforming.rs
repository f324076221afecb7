//! The main example: a mesostructure object morphing between a sphere and a cube and back (the
//! paper's Fig. 13), with a height map on it, a light circling it, and a ground.
//!
//! Where there is a display it opens a window with a tuning panel (every camera and material
//! setting, live; the frame time and the GPU time of each pass) and keys: O occlusion,
//! M micro-shadows, B bleeding, N bump mapping, V next debug view, Space pause. Where there is
//! none (or with `--headless`) it renders headless and writes PNG screenshots of the picture
//! and of each debug view.
//!
//! ```text
//! cargo run --example deforming -- [--frames N] [--out DIR] [--size WxH] [--headless]
//!     [--shape morph|sphere|cube|plane] [--height-map bricks|rivets|weave|sine|stone|cone]
//!     [--scale K] [--off occlusion,micro-shadows,bleeding,bump-mapping] [--light-height H]
//!     [--view none|height|gradient|apex-distance|apex-count|boundary|occlusion|
//!             micro-shadow|bleeding|all]
//! ```
//!
//! `--frames N` renders N frames, then the screenshots (in a window too, where they include the
//! panel), then exits; `--off` switches effects off (the file names get `_no-<effect>`);
//! `--light-height` sets how high the circling light stands (default 4; lower casts longer
//! micro-shadows). The object is two-tone: the raised parts of the height map in brick red, the
//! low parts in light grey, so that the bleeding of the red onto the grey shows.

#[path = "common/mod.rs"]
mod common;

use bevy::{
    asset::RenderAssetUsages,
    mesh::{Indices, PrimitiveTopology},
    prelude::*,
};
use bevy_mesostructure::prelude::*;

/// The effects `--off` can switch off.
const EFFECTS: [&str; 4] = ["occlusion", "micro-shadows", "bleeding", "bump-mapping"];

/// A sphere morphing into a cube with a height map, a circling light and a ground; a window
/// with the tuning panel, or headless PNGs of the picture and each debug view.
#[derive(clap::Parser)]
#[command(long_about = None)]
struct Cli {
    #[command(flatten)]
    common: common::CommonArgs,
    /// The object
    #[arg(long, default_value = "morph", value_parser = ["morph", "sphere", "cube", "plane"])]
    shape: String,
    /// A built-in height map (bricks, rivets, weave, sine, stone, cone)
    #[arg(long, default_value = "bricks", value_parser = HeightMap::NAMES)]
    height_map: String,
    /// Height of white in the height map, world units (> 0)
    #[arg(long, default_value_t = 0.08, value_parser = common::parse_positive)]
    scale: f32,
    /// Effects to switch off (comma-separated; the file names get `_no-<effect>`)
    #[arg(long, value_delimiter = ',', value_parser = EFFECTS)]
    off: Vec<String>,
    /// How high the circling light stands (lower casts longer micro-shadows)
    #[arg(long, default_value_t = 4.0, allow_negative_numbers = true)]
    light_height: f32,
    /// Debug view to write: none, height, gradient, apex-distance, apex-count, boundary,
    /// occlusion, micro-shadow, bleeding, or all
    #[arg(long, default_value = "all", value_parser = common::parse_views)]
    view: common::ViewList,
}

struct Args {
    common: common::ExampleArgs,
    off: Vec<String>,
    light_height: f32,
    shape: String,
    height_map: String,
    scale: f32,
    views: Vec<MesostructureDebugView>,
}

fn parse_args() -> Args {
    use clap::Parser;
    let cli = Cli::parse();
    Args {
        common: common::ExampleArgs::from_cli("deforming", cli.common),
        off: cli.off,
        light_height: cli.light_height,
        shape: cli.shape,
        height_map: cli.height_map,
        scale: cli.scale,
        views: cli.view.0,
    }
}

fn main() {
    let args = parse_args();
    let suffix: String = args.off.iter().map(|e| format!("_no-{e}")).collect();
    let shots = args
        .views
        .iter()
        .map(|&view| common::view_shot(&format!("{}{suffix}", args.shape), view))
        .collect();
    let mut app = common::app(&args.common, "bevy_mesostructure: deforming", shots);
    app.insert_resource(ClearColor(Color::srgb(0.55, 0.62, 0.72)))
        // A bright sky: ambient light is what the mesostructure occlusion darkens.
        .insert_resource(bevy::light::GlobalAmbientLight {
            brightness: 1500.0,
            ..default()
        })
        .insert_resource(LightHeight(args.light_height))
        .add_systems(Update, (morph, circle_light));
    setup(app.world_mut(), &args);
    common::run(app);
}

#[derive(Resource)]
struct LightHeight(f32);

fn setup(world: &mut World, args: &Args) {
    let target = world.resource::<common::Output>().target();
    let map = HeightMap::by_name(&args.height_map, 512).unwrap_or_else(|| {
        panic!(
            "unknown height map {}; one of {:?}",
            args.height_map,
            HeightMap::NAMES
        )
    });
    let height_map = world.resource_mut::<Assets<Image>>().add(map.to_image());
    let colours = world.resource_mut::<Assets<Image>>().add(common::two_tone(
        &map,
        [191, 97, 71],
        [217, 214, 207],
    ));

    world.spawn((
        Camera3d::default(),
        target,
        Msaa::Off,
        Mesostructure {
            occlusion: !args.off.iter().any(|e| e == "occlusion"),
            micro_shadows: !args.off.iter().any(|e| e == "micro-shadows"),
            bleeding: !args.off.iter().any(|e| e == "bleeding"),
            bump_mapping: !args.off.iter().any(|e| e == "bump-mapping"),
            ..default()
        },
        Transform::from_xyz(0.0, 1.3, 2.6).looking_at(Vec3::new(0.0, 0.1, 0.0), Vec3::Y),
    ));
    world.spawn((
        DirectionalLight {
            illuminance: 8000.0,
            shadow_maps_enabled: true,
            ..default()
        },
        Transform::from_xyz(2.0, args.light_height, 1.5).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    let ground = world
        .resource_mut::<Assets<Mesh>>()
        .add(Plane3d::default().mesh().size(8.0, 8.0));
    let ground_material = world
        .resource_mut::<Assets<StandardMaterial>>()
        .add(Color::srgb(0.35, 0.33, 0.3));
    world.spawn((
        Mesh3d(ground),
        MeshMaterial3d(ground_material),
        Transform::from_xyz(0.0, -0.85, 0.0),
    ));

    let bricks = world
        .resource_mut::<Assets<StandardMaterial>>()
        .add(StandardMaterial {
            base_color_texture: Some(colours),
            perceptual_roughness: 0.8,
            ..default()
        });
    let material = MesostructureMaterial {
        height_map,
        scale: args.scale,
        ..default()
    };
    let (mesh, transform, blend) = match args.shape.as_str() {
        "plane" => (
            Plane3d::default().mesh().size(2.4, 2.4).build(),
            Transform::from_xyz(0.0, -0.2, 0.0),
            None,
        ),
        "sphere" => (cube_sphere(24, 0.0), Transform::default(), None),
        "cube" => (cube_sphere(24, 1.0), Transform::default(), None),
        "morph" => (cube_sphere(24, 0.0), Transform::default(), Some(())),
        other => panic!("unknown shape {other}"),
    };
    let mesh = world.resource_mut::<Assets<Mesh>>().add(mesh);
    let mut entity = world.spawn((
        Mesh3d(mesh),
        MeshMaterial3d(bricks),
        material,
        transform.with_rotation(Quat::from_rotation_y(0.4)),
    ));
    if blend.is_some() {
        entity.insert(Morphing);
    }
}

/// The morphing object.
#[derive(Component)]
struct Morphing;

/// A sphere of radius 0.8 made of six subdivided cube faces (`n × n` quads each), blended by
/// `w` towards the cube of half-size 0.8 it projects onto. Each face has its own vertices and
/// UVs (0–1), so the cube's edges are mesh edges: at `w = 1` the faces are flat with hard
/// edges, at `w = 0` the duplicated edge vertices coincide and the sphere is smooth.
fn cube_sphere(n: u32, w: f32) -> Mesh {
    let mut positions = vec![];
    let mut normals = vec![];
    let mut uvs = vec![];
    let mut indices = vec![];
    for (face, up) in [
        Vec3::X,
        Vec3::NEG_X,
        Vec3::Y,
        Vec3::NEG_Y,
        Vec3::Z,
        Vec3::NEG_Z,
    ]
    .into_iter()
    .zip([Vec3::Y, Vec3::Y, Vec3::NEG_Z, Vec3::Z, Vec3::Y, Vec3::Y])
    {
        let right = up.cross(face);
        let base = positions.len() as u32;
        for j in 0..=n {
            for i in 0..=n {
                let (s, t) = (i as f32 / n as f32, j as f32 / n as f32);
                let cube = face + right * (2.0 * s - 1.0) + up * (1.0 - 2.0 * t);
                let (p, normal) = morph_point(cube, face, w);
                positions.push(p.to_array());
                normals.push(normal.to_array());
                uvs.push([s, t]);
            }
        }
        for j in 0..n {
            for i in 0..n {
                let a = base + j * (n + 1) + i;
                let (b, c, d) = (a + 1, a + n + 1, a + n + 2);
                indices.extend([a, c, b, b, c, d]);
            }
        }
    }
    Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::default(),
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions)
    .with_inserted_attribute(Mesh::ATTRIBUTE_NORMAL, normals)
    .with_inserted_attribute(Mesh::ATTRIBUTE_UV_0, uvs)
    .with_inserted_indices(Indices::U32(indices))
}

/// The point of the unit cube `cube` (on face `face`) on the blend from the sphere (w = 0) to
/// the cube (w = 1), radius/half-size 0.8, and its normal.
fn morph_point(cube: Vec3, face: Vec3, w: f32) -> (Vec3, Vec3) {
    let sphere = cube.normalize();
    let p = sphere.lerp(cube, w) * 0.8;
    (p, sphere.lerp(face, w).normalize())
}

fn morph(
    clock: Res<common::Clock>,
    objects: Query<&Mesh3d, With<Morphing>>,
    mut meshes: ResMut<Assets<Mesh>>,
) {
    let w = 0.5 - 0.5 * ((clock.t + 1.9) * 0.8).cos();
    for handle in &objects {
        let Some(mut mesh) = meshes.get_mut(&handle.0) else {
            continue;
        };
        // Positions and normals of the blend, recomputed from the cube point each vertex's UV
        // and face stand for.
        let Some(bevy::mesh::VertexAttributeValues::Float32x3(old)) =
            mesh.attribute(Mesh::ATTRIBUTE_NORMAL)
        else {
            continue;
        };
        let Some(bevy::mesh::VertexAttributeValues::Float32x2(uvs)) =
            mesh.attribute(Mesh::ATTRIBUTE_UV_0)
        else {
            continue;
        };
        let per_face = old.len() / 6;
        let (mut positions, mut normals) = (Vec::with_capacity(old.len()), vec![]);
        for (k, uv) in uvs.iter().enumerate() {
            let face = [
                Vec3::X,
                Vec3::NEG_X,
                Vec3::Y,
                Vec3::NEG_Y,
                Vec3::Z,
                Vec3::NEG_Z,
            ][k / per_face];
            let up = [Vec3::Y, Vec3::Y, Vec3::NEG_Z, Vec3::Z, Vec3::Y, Vec3::Y][k / per_face];
            let cube = face + up.cross(face) * (2.0 * uv[0] - 1.0) + up * (1.0 - 2.0 * uv[1]);
            let (p, n) = morph_point(cube, face, w);
            positions.push(p.to_array());
            normals.push(n.to_array());
        }
        mesh.insert_attribute(Mesh::ATTRIBUTE_POSITION, positions);
        mesh.insert_attribute(Mesh::ATTRIBUTE_NORMAL, normals);
    }
}

fn circle_light(
    clock: Res<common::Clock>,
    height: Res<LightHeight>,
    mut lights: Query<&mut Transform, With<DirectionalLight>>,
) {
    let (s, c) = (clock.t * 0.5).sin_cos();
    for mut light in &mut lights {
        *light = Transform::from_xyz(2.5 * c, height.0, 2.5 * s).looking_at(Vec3::ZERO, Vec3::Y);
    }
}
