use super::*;

fn area(object: &(Vec<Vec3>, Vec<u32>)) -> f64 {
    object
        .1
        .chunks(3)
        .map(|t| {
            let p = |k: usize| object.0[t[k] as usize];
            0.5 * (p(1) - p(0)).cross(p(2) - p(0)).length() as f64
        })
        .sum()
}

#[test]
fn patches_keep_the_area_and_fill_the_budget_evenly() {
    let sphere = mesh_object(Sphere::new(1.0).mesh().uv(64, 32), Transform::IDENTITY);
    let cube = mesh_object(
        Cuboid::new(2.0, 1.0, 0.5).mesh().build(),
        Transform::from_xyz(3.0, 0.0, 0.0),
    );
    let objects = [
        PatchObject {
            positions: &sphere.0,
            indices: &sphere.1,
        },
        PatchObject {
            positions: &cube.0,
            indices: &cube.1,
        },
    ];
    let area = area(&sphere) + area(&cube);
    for budget in [50, 500, 5000] {
        let patches = resample_into_patches(&objects, budget);
        let n = patches.patches.len();
        assert!(
            n <= budget && 4 * n >= 3 * budget,
            "budget {budget}: {n} patches"
        );
        let sum: f64 = patches.patches.iter().map(|p| p.area as f64).sum();
        assert!(
            (sum - area).abs() < 1e-4 * area,
            "budget {budget}: area {sum} of {area}"
        );
        // Near-uniform: the spread of patch areas (measured 0.3x at these budgets).
        let mean = sum / n as f64;
        let spread = (patches
            .patches
            .iter()
            .map(|p| (p.area as f64 - mean).powi(2))
            .sum::<f64>()
            / n as f64)
            .sqrt()
            / mean;
        eprintln!("budget {budget}: {n} patches, area spread {spread:.3}");
        assert!(spread < 0.5, "budget {budget}: spread {spread}");
        assert!(
            patches
                .patches
                .iter()
                .all(|p| p.normal.is_normalized() && p.area > 0.0)
        );
        // Objects in order, the sphere's normals outwards.
        assert!(
            patches
                .patches
                .windows(2)
                .all(|w| w[0].object <= w[1].object)
        );
        for p in patches.patches.iter().filter(|p| p.object == 0) {
            assert!(p.normal.dot(p.centre.normalize()) > 0.8);
        }
    }
}

#[test]
fn bad_triangles_are_skipped_and_counted() {
    let positions = [
        Vec3::ZERO,
        Vec3::X,
        Vec3::Y,
        Vec3::NAN,
        Vec3::new(2.0, 0.0, 0.0),
    ];
    // A good triangle, a NaN vertex, a degenerate one (collinear), an index out of range, a
    // dangling pair.
    let indices = [0, 1, 2, 0, 3, 1, 0, 1, 4, 0, 1, 99, 0, 1];
    let patches = resample_into_patches(
        &[PatchObject {
            positions: &positions,
            indices: &indices,
        }],
        10,
    );
    assert_eq!(patches.skipped_triangles, 4);
    let sum: f32 = patches.patches.iter().map(|p| p.area).sum();
    assert!((sum - 0.5).abs() < 1e-5);
    assert!(resample_into_patches(&[], 10).patches.is_empty());
    assert!(
        resample_into_patches(
            &[PatchObject {
                positions: &positions,
                indices: &indices
            }],
            0
        )
        .patches
        .is_empty()
    );
}
