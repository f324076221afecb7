//! Skinned, morph-target and CPU-deformed meshes: the height pass must land exactly where the
//! mesh is drawn (the prepass depth), frame after frame.

use bevy::{
    asset::RenderAssetUsages,
    mesh::{
        Indices, PrimitiveTopology, VertexAttributeValues,
        morph::{MeshMorphWeights, MorphAttributes},
        skinning::{SkinnedMesh, SkinnedMeshInverseBindposes},
    },
    prelude::*,
};
use bevy_mesostructure::prelude::*;

use crate::harness::*;

const W: u32 = 160;
const H: u32 = 96;

/// A vertical grid of `n × n` quads, `size` wide, facing +z, centred at the origin.
fn grid(n: u32, size: f32) -> (Vec<[f32; 3]>, Vec<[f32; 2]>, Vec<u32>) {
    let (mut p, mut uv, mut idx) = (vec![], vec![], vec![]);
    for j in 0..=n {
        for i in 0..=n {
            let (u, v) = (i as f32 / n as f32, j as f32 / n as f32);
            p.push([(u - 0.5) * size, (0.5 - v) * size, 0.0]);
            uv.push([u, v]);
        }
    }
    for j in 0..n {
        for i in 0..n {
            let a = j * (n + 1) + i;
            idx.extend([a, a + n + 1, a + 1, a + 1, a + n + 1, a + n + 2]);
        }
    }
    (p, uv, idx)
}

fn grid_mesh(n: u32, size: f32, usage: RenderAssetUsages) -> Mesh {
    let (p, uv, idx) = grid(n, size);
    let count = p.len();
    Mesh::new(PrimitiveTopology::TriangleList, usage)
        .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, p)
        .with_inserted_attribute(Mesh::ATTRIBUTE_UV_0, uv)
        .with_inserted_attribute(Mesh::ATTRIBUTE_NORMAL, vec![[0.0, 0.0, 1.0]; count])
        .with_inserted_indices(Indices::U32(idx))
}

fn wave(mesh: &mut Mesh, phase: f32) {
    let (base, _, _) = grid(8, 0.8);
    if let Some(VertexAttributeValues::Float32x3(p)) = mesh.attribute_mut(Mesh::ATTRIBUTE_POSITION)
    {
        for (q, b) in p.iter_mut().zip(base) {
            q[0] = b[0] * (1.0 + 0.3 * (phase + b[1] * 4.0).sin());
            q[1] = b[1] + 0.1 * (phase + b[0] * 5.0).sin();
        }
    }
}

#[test]
fn skinned_morphed_and_cpu_deformed_meshes_line_up_with_the_prepass() {
    if !gpu_or_skip() {
        return;
    }
    let mut app = app();
    app.insert_resource(ClearColor(Color::BLACK));
    let target = target(&mut app, W, H);
    let camera = camera(
        &mut app,
        &target,
        Transform::from_xyz(0.0, 0.0, 3.0).looking_at(Vec3::ZERO, Vec3::Y),
        Mesostructure::default(),
    );
    let map = image(&mut app, HeightMap::rivets(64, 4, 0.3).to_image());
    let red = unlit(&mut app, Color::srgb(1.0, 0.0, 0.0));
    let meso = || MesostructureMaterial {
        height_map: map.clone(),
        scale: 0.1,
        ..default()
    };

    // 1. Skinned: a strip bent by its second joint.
    let (p, uv, idx) = grid(4, 0.8);
    let weights: Vec<[f32; 4]> = p
        .iter()
        .map(|q| {
            let t = (0.5 - q[1] / 0.8).clamp(0.0, 1.0); // 0 at the top, 1 at the bottom
            [1.0 - t, t, 0.0, 0.0]
        })
        .collect();
    let count = p.len();
    let skinned = Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::RENDER_WORLD,
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, p)
    .with_inserted_attribute(Mesh::ATTRIBUTE_UV_0, uv)
    .with_inserted_attribute(Mesh::ATTRIBUTE_NORMAL, vec![[0.0, 0.0, 1.0]; count])
    .with_inserted_attribute(
        Mesh::ATTRIBUTE_JOINT_INDEX,
        VertexAttributeValues::Uint16x4(vec![[0, 1, 0, 0]; count]),
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_JOINT_WEIGHT, weights)
    .with_inserted_indices(Indices::U32(idx));
    let skinned = mesh(&mut app, skinned);
    let bindposes = app
        .world_mut()
        .resource_mut::<Assets<SkinnedMeshInverseBindposes>>()
        .add(vec![
            Mat4::IDENTITY,
            Mat4::from_translation(Vec3::new(0.0, 0.4, 0.0)),
        ]);
    let joint_0 = app
        .world_mut()
        .spawn(Transform::from_xyz(-1.0, 0.0, 0.0))
        .id();
    let joint_1 = app
        .world_mut()
        .spawn(Transform::from_xyz(0.0, -0.4, 0.0).with_rotation(Quat::from_rotation_z(0.7)))
        .id();
    app.world_mut().entity_mut(joint_0).add_children(&[joint_1]);
    app.world_mut().spawn((
        skinned,
        red.clone(),
        meso(),
        SkinnedMesh {
            inverse_bindposes: bindposes,
            joints: vec![joint_0, joint_1],
        },
        Transform::from_xyz(-1.0, 0.0, 0.0),
    ));

    // 2. Morph target: the base grid, displaced sideways and sheared by one target at weight 1.
    let (p, _, _) = grid(8, 0.8);
    let targets: Vec<MorphAttributes> = p
        .iter()
        .map(|q| MorphAttributes {
            position: Vec3::new(0.25 * q[1], 0.15, 0.0),
            ..default()
        })
        .collect();
    let morphed = mesh(
        &mut app,
        grid_mesh(8, 0.8, RenderAssetUsages::RENDER_WORLD).with_morph_targets(targets),
    );
    app.world_mut().spawn((
        morphed,
        red.clone(),
        meso(),
        MeshMorphWeights::Value { weights: vec![1.0] },
        Transform::from_xyz(0.0, 0.0, 0.0),
    ));

    // 3. Deformed on the CPU every frame.
    let deformed = mesh(&mut app, grid_mesh(8, 0.8, RenderAssetUsages::default()));
    app.world_mut().spawn((
        deformed.clone(),
        red,
        meso(),
        Transform::from_xyz(1.0, 0.0, 0.0),
    ));

    let before = capture(&mut app, camera, 20);
    for frame in 0..4 {
        let mut meshes = app.world_mut().resource_mut::<Assets<Mesh>>();
        wave(
            &mut meshes.get_mut(&deformed.0).unwrap(),
            1.0 + frame as f32,
        );
        run(&mut app, 1);
    }
    let shot = screenshot(&mut app, &target);
    let after = capture(&mut app, camera, 5);

    let data = shot.data.as_ref().unwrap();
    let drawn = |x: u32, y: u32| data[((y * W + x) * 4) as usize] > 128;
    let meso_px = |f: &bevy_mesostructure::CapturedFrame, x: u32, y: u32| {
        f.mhm[(y * W + x) as usize][2] != 0.0
    };
    let (mut both, mut either, mut changed) = (0, 0, 0);
    for y in 0..H {
        for x in 0..W {
            let (d, m) = (drawn(x, y), meso_px(&after, x, y));
            both += (d && m) as u32;
            either += (d || m) as u32;
            changed += (m != meso_px(&before, x, y)) as u32;
        }
    }
    let iou = both as f32 / either.max(1) as f32;
    assert!(either > 1500, "the three meshes cover {either} pixels");
    assert!(
        iou > 0.99,
        "height-pass coverage vs drawn pixels: IoU {iou} ({both}/{either})"
    );
    assert!(
        changed > 50,
        "the CPU deformation shows in the MHM ({changed} pixels changed)"
    );
    let ids: std::collections::BTreeSet<u32> = after
        .mhm
        .iter()
        .map(|t| t[2] as u32)
        .filter(|&i| i != 0)
        .collect();
    assert_eq!(ids.len(), 3, "one object id per mesh: {ids:?}");
}

/// A grid of `n × n` quads, `size` wide, bent by a travelling wave of `phase`: each vertex
/// moves in x, y and z, so the height map slides, stretches and tilts under the pixels.
fn bent_grid(mesh: &mut Mesh, n: u32, size: f32, phase: f32) {
    let (base, _, _) = grid(n, size);
    if let Some(VertexAttributeValues::Float32x3(p)) = mesh.attribute_mut(Mesh::ATTRIBUTE_POSITION)
    {
        for (q, b) in p.iter_mut().zip(base) {
            q[0] = b[0] * (1.0 + 0.15 * (phase + b[1] * 3.0).sin());
            q[1] = b[1] + 0.05 * (phase + b[0] * 4.0).sin();
            q[2] = 0.2 * (phase + b[0] * 3.0).sin();
        }
    }
    mesh.compute_smooth_normals();
}

/// Pops: between two frames of a slowly deforming mesh, pixels whose surface barely changed
/// (height-map value within 0.01) but whose occlusion or micro-shadow jumps. Counted at every
/// pixel of both frames, with a low light so that the micro-shadows are many.
#[test]
fn a_deforming_mesh_shows_no_pops_between_frames() {
    if !gpu_or_skip() {
        return;
    }
    let (n, size) = (24, 2.0);
    let mut app = app();
    let target = target(&mut app, W, H);
    let camera = camera(
        &mut app,
        &target,
        Transform::from_xyz(0.0, 0.0, 2.6).looking_at(Vec3::ZERO, Vec3::Y),
        Mesostructure::default(),
    );
    sun(&mut app, Vec3::new(1.0, -0.35, -0.6), 3000.0);
    let map = image(&mut app, HeightMap::bricks(256, 4, 0.12).to_image());
    let material = MeshMaterial3d(
        app.world_mut()
            .resource_mut::<Assets<StandardMaterial>>()
            .add(StandardMaterial {
                perceptual_roughness: 1.0,
                ..default()
            }),
    );
    let mut grid = grid_mesh(n, size, RenderAssetUsages::default());
    bent_grid(&mut grid, n, size, 0.0);
    let deformed = mesh(&mut app, grid);
    app.world_mut().spawn((
        deformed.clone(),
        material,
        MesostructureMaterial {
            height_map: map,
            scale: 0.08,
            ..default()
        },
    ));
    let mut frames = vec![capture(&mut app, camera, 20)];
    // 0.03 rad a frame: the wave crosses the grid in ~200 frames, a few pixels a frame.
    for step in 1..=6 {
        let mut meshes = app.world_mut().resource_mut::<Assets<Mesh>>();
        bent_grid(
            &mut meshes.get_mut(&deformed.0).unwrap(),
            n,
            size,
            0.03 * step as f32,
        );
        frames.push(capture(&mut app, camera, 20));
    }
    let (mut steady, mut ao_pops, mut shadow_pops, mut moved) = (0u32, 0u32, 0u32, 0u32);
    let mut ao_change = 0.0f32;
    for pair in frames.windows(2) {
        let (a, b) = (&pair[0], &pair[1]);
        for i in 0..(W * H) as usize {
            if a.mhm[i][2] == 0.0 || b.mhm[i][2] == 0.0 {
                continue;
            }
            moved += (a.mhm[i][3] != b.mhm[i][3]) as u32;
            if (a.mhm[i][3] - b.mhm[i][3]).abs() > 0.01 {
                continue;
            }
            steady += 1;
            let d = (a.occlusion[i] - b.occlusion[i]).abs();
            ao_change += d;
            ao_pops += (d > 0.2) as u32;
            let shadow = |f: &bevy_mesostructure::CapturedFrame| {
                f.micro_shadow.get(i).copied().unwrap_or(1.0)
            };
            let s = (shadow(a) - shadow(b)).abs();
            shadow_pops += (s > 0.5) as u32;
        }
    }
    let mean = ao_change / steady.max(1) as f32;
    let (ao_share, shadow_share) = (
        ao_pops as f32 / steady.max(1) as f32,
        shadow_pops as f32 / steady.max(1) as f32,
    );
    eprintln!(
        "deforming mesh, 6 frame pairs: {steady} steady pixel pairs ({moved} moved at all); AO \
         jumps > 0.2: {ao_pops} ({:.3} %), mean AO change {mean:.4}; micro-shadow jumps > 0.5: \
         {shadow_pops} ({:.3} %)",
        100.0 * ao_share,
        100.0 * shadow_share
    );
    assert!(
        steady > 20_000,
        "the grid covers the view: {steady} steady pairs"
    );
    assert!(moved > 1000, "the deformation moves the surface: {moved}");
    assert!(ao_share <= 0.005, "AO pops on {ao_pops} of {steady} pixels");
    assert!(
        shadow_share <= 0.005,
        "micro-shadow pops on {shadow_pops} of {steady} pixels"
    );
}
