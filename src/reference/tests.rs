//! Known answers for the gradient map and the apex search on synthetic images.

use super::*;

fn run(mhm: &ScreenHeightMap, search: &ApexSearch) -> (GradientMap, Vec<ApexSet>) {
    let mhgm = gradient_map(mhm, DepthContinuity::default());
    let sets = apex_sets(mhm, &mhgm, search);
    (mhgm, sets)
}

#[test]
fn cone_has_one_apex_at_its_tip_from_every_pixel() {
    // Tip at pixel (20, 20): the height peaks at that pixel's centre.
    let mhm = ScreenHeightMap::from_fn(41, 41, |x, y| {
        let r = ((x - 20.5).powi(2) + (y - 20.5).powi(2)).sqrt();
        0.1 * (1.0 - r / 40.0)
    });
    let (_, sets) = run(
        &mhm,
        &ApexSearch {
            max_steps: 200,
            ..default_search()
        },
    );
    for y in 0..41 {
        for x in 0..41 {
            let set = &sets[mhm.index(x, y)];
            if (x, y) == (20, 20) {
                assert!(set.is_empty(), "the tip itself has nothing above it");
                continue;
            }
            let direct = set.direct.expect("every other pixel ascends to the tip");
            assert_eq!((direct.x, direct.y), (20, 20), "from ({x}, {y})");
            assert_eq!(direct.kind, ApexKind::Local);
            assert!(set.iter().all(|a| (a.x, a.y) == (20, 20)), "one apex only");
            assert!(!set.truncated);
        }
    }
}

fn default_search() -> ApexSearch {
    ApexSearch::default()
}

#[test]
fn grid_of_bumps_has_apexes_at_the_peaks() {
    // 4 × 4 bumps of period 16 px, peaks at pixel centres (8 + 16i, 8 + 16j).
    let mhm = ScreenHeightMap::from_fn(64, 64, |x, y| {
        let (cx, cy) = ((x - 0.5) % 16.0 - 8.0, (y - 0.5) % 16.0 - 8.0);
        0.05 * (-(cx * cx + cy * cy) / 20.0).exp()
    });
    let (_, sets) = run(&mhm, &default_search());
    let is_peak = |a: &Apex| (a.x - 8) % 16 == 0 && (a.y - 8) % 16 == 0;
    let mut with_direct = 0;
    for y in 0..64 {
        for x in 0..64 {
            let set = &sets[mhm.index(x, y)];
            for a in set.iter() {
                assert!(is_peak(a), "apex {a:?} of ({x}, {y}) is not a peak");
            }
            if let Some(d) = set.direct {
                with_direct += 1;
                // The direct apex is the peak of the pixel's own bump (nearest peak).
                let (px, py) = (x as i32 / 16 * 16 + 8, y as i32 / 16 * 16 + 8);
                assert_eq!((d.x, d.y), (px, py), "direct apex of ({x}, {y})");
            }
        }
    }
    assert_eq!(
        with_direct,
        64 * 64 - 16,
        "all but the 16 peaks have a direct apex"
    );
    // A pixel in the valley between four bumps sees several of them.
    let valley = &sets[mhm.index(16, 16)];
    assert!(valley.len() >= 3, "valley apex set {valley:?}");
}

#[test]
fn flat_map_has_no_apex_and_zero_gradient() {
    let mhm = ScreenHeightMap::from_fn(32, 24, |_, _| 0.3);
    let (mhgm, sets) = run(&mhm, &default_search());
    assert!(mhgm.gradients.iter().all(|g| *g == [0.0, 0.0]));
    assert!(sets.iter().all(ApexSet::is_empty));
}

#[test]
fn ramp_that_leaves_the_region_ends_in_boundary_points() {
    // Rising towards +x, cut by the screen edge at x = 31.
    let mhm = ScreenHeightMap::from_fn(32, 16, |x, _| 0.01 * x);
    let (mhgm, sets) = run(
        &mhm,
        &ApexSearch {
            max_steps: 64,
            ..default_search()
        },
    );
    for y in 0..16 {
        assert!(mhgm.is_boundary(mhm.index(31, y)));
        for x in 0..31 {
            let d = sets[mhm.index(x, y)]
                .direct
                .expect("uphill pixels have a direct apex");
            assert_eq!((d.x, d.kind), (31, ApexKind::Boundary), "from ({x}, {y})");
        }
    }
    // The same ramp cut by another object at x = 20: boundary points on the object edge.
    let mut cut = mhm.clone();
    for y in 0..16 {
        for x in 21..32 {
            let i = cut.index(x, y);
            cut.objects[i] = 2;
        }
    }
    let (cut_mhgm, cut_sets) = run(&cut, &default_search());
    assert_ne!(cut_mhgm.flags[cut.index(20, 5)] & FLAG_OBJECT_EDGE, 0);
    let d = cut_sets[cut.index(3, 5)].direct.unwrap();
    assert_eq!((d.x, d.kind), (20, ApexKind::Boundary));
}

#[test]
fn gradient_uses_one_sided_differences_at_depth_discontinuities() {
    let mut mhm = ScreenHeightMap::from_fn(16, 8, |x, _| 0.01 * x);
    // Right half much closer to the camera: a depth edge between x = 7 and x = 8.
    for y in 0..8 {
        for x in 8..16 {
            let i = mhm.index(x, y);
            mhm.depths[i] = 0.9;
            mhm.heights[i] += 5.0;
        }
    }
    let mhgm = gradient_map(&mhm, DepthContinuity::default());
    let i = mhm.index(7, 3);
    assert_ne!(mhgm.flags[i] & FLAG_DEPTH_EDGE, 0);
    assert!(!mhgm.connected(i, 0));
    assert!(
        (mhgm.gradients[i][0] - 0.01).abs() < 1e-6,
        "one-sided, not across the edge"
    );
    // Interior: central differences.
    let j = mhm.index(3, 3);
    assert_eq!(mhgm.flags[j] & FLAG_BOUNDARY, 0);
    assert!((mhgm.gradients[j][0] - 0.01).abs() < 1e-6);
    // A plane seen at a grazing angle (depth affine in x, steep) stays connected.
    let mut grazing = ScreenHeightMap::from_fn(16, 8, |_, _| 0.0);
    for y in 0..8 {
        for x in 0..16 {
            let i = grazing.index(x, y);
            grazing.depths[i] = 0.1 + 0.04 * x as f32;
        }
    }
    let g = gradient_map(&grazing, DepthContinuity::default());
    assert_eq!(g.flags[grazing.index(5, 4)] & FLAG_DEPTH_EDGE, 0);
}

#[test]
fn step_bound_is_reported() {
    let mhm = ScreenHeightMap::from_fn(64, 4, |x, _| 0.001 * x);
    let (_, sets) = run(
        &mhm,
        &ApexSearch {
            max_steps: 8,
            ..default_search()
        },
    );
    assert!(sets[mhm.index(0, 1)].truncated);
    assert!(!sets[mhm.index(60, 1)].truncated);
}

#[test]
fn quantized_directions_cover_the_octants() {
    assert_eq!(quantize_direction([1.0, 0.0]), Some(0));
    assert_eq!(quantize_direction([1.0, 1.0]), Some(1));
    assert_eq!(quantize_direction([0.0, 2.0]), Some(2));
    assert_eq!(quantize_direction([-1.0, 0.1]), Some(4));
    assert_eq!(quantize_direction([0.3, -1.0]), Some(6));
    assert_eq!(quantize_direction([0.0, 0.0]), None);
}

#[test]
fn packed_apex_sets_round_trip() {
    let words = [
        2 | packed::DIRECT_PRESENT | (1 << (packed::BOUNDARY_SHIFT + 1)),
        (3u32 & 0xffff) | ((-2i16 as u16 as u32) << 16),
        (-5i16 as u16 as u32) | (7 << 16),
        0,
    ];
    let set = unpack_apex_set(&words, (10, 10));
    assert_eq!(
        set.direct,
        Some(Apex {
            x: 13,
            y: 8,
            kind: ApexKind::Local
        })
    );
    assert_eq!(
        set.indirect,
        vec![Apex {
            x: 5,
            y: 17,
            kind: ApexKind::Boundary
        }]
    );
}
