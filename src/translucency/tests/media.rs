use super::*;

#[test]
fn invalid_media_scatter_nothing_and_say_why() {
    let mut medium = TranslucentMedium::default();
    assert!(medium.invalid_reason().is_none());
    medium.absorption.x = f32::NAN;
    assert!(medium.invalid_reason().unwrap().contains("finite"));
    medium = TranslucentMedium {
        reduced_scattering: Vec3::ZERO,
        ..default()
    };
    assert!(medium.invalid_reason().unwrap().contains("positive"));
    let ball = mesh_object(Sphere::new(1.0).mesh().ico(2).unwrap(), Transform::IDENTITY);
    let views = [PatchObject {
        positions: &ball.0,
        indices: &ball.1,
    }];
    let patches = resample_into_patches(&views, 100);
    let rays = SceneRays::new(&views);
    let surfaces = [PatchSurface::Translucent {
        medium,
        world_units_per_mm: 1.0,
        oriented_dipole: false,
    }];
    let transport = EnergyTransport::build(&patches, &surfaces, &rays, &default());
    assert_eq!(transport.scattering.entries(), 0);
    let solution = transport.solve(&vec![Vec3::ONE; patches.patches.len()], 1e-4, 10);
    assert!(solution.exitance.iter().all(|b| *b == Vec3::ZERO));
}

/// The random walks behind `TransportSettings::object_exit_share`: of the light entering a ball
/// of skin 1 cm in radius, 0.743 / 0.438 / 0.266 leaves it again, against 0.623 / 0.389 / 0.242
/// for a slab (an independent walk in an analytic sphere and half-space, numpy, 20 000 walks a
/// channel); in a ball 100 times larger the two agree (the slab's limit). Held within ±0.025
/// (3 standard deviations of 4096 walks; ±0.035 for a difference of two).
#[test]
fn random_walks_find_a_small_ball_gives_off_more_than_a_slab() {
    use crate::translucency::random_walk::{
        EntryPoint, WALKS_PER_CHANNEL, object_exit_share, slab_exit_share,
    };
    let medium = TranslucentMedium {
        index_of_refraction: 1.0,
        ..TranslucentPreset::Skin1.medium()
    };
    let slab_expected = Vec3::new(0.623, 0.389, 0.242);
    for radius in [0.01f32, 1.0] {
        let ball = mesh_object(Sphere::new(radius).mesh().ico(5).unwrap(), Transform::IDENTITY);
        let rays = SceneRays::new(&views_of(std::slice::from_ref(&ball)));
        let entries: Vec<EntryPoint> = ball
            .1
            .chunks_exact(3)
            .map(|t| {
                let (a, b, c) = (ball.0[t[0] as usize], ball.0[t[1] as usize], ball.0[t[2] as usize]);
                let cross = (b - a).cross(c - a);
                EntryPoint {
                    position: (a + b + c) / 3.0,
                    normal: cross.normalize(),
                    area: 0.5 * cross.length(),
                }
            })
            .collect();
        let ball_share =
            object_exit_share(&medium, 0.001, &entries, &rays, WALKS_PER_CHANNEL, 7).unwrap();
        let slab_share = slab_exit_share(&medium, 0.001, WALKS_PER_CHANNEL, 7).unwrap();
        eprintln!("radius {radius}: ball {ball_share}, slab {slab_share}");
        assert!(
            (slab_share - slab_expected).abs().max_element() < 0.025,
            "slab {slab_share}"
        );
        let (expected, margin) = if radius < 0.1 {
            (Vec3::new(0.743, 0.438, 0.266), 0.025)
        } else {
            (slab_share, 0.035)
        };
        assert!(
            (ball_share - expected).abs().max_element() < margin,
            "radius {radius}: ball {ball_share}, expected {expected}"
        );
    }
}

/// Walks launched as a beam (`WalkLaunch::Beam`) give back what Chandrasekhar's plane albedo
/// says a half-space gives back of a collimated beam (`collimated_albedo`, Hapke's `H` within
/// 1 %): into the top of an index-matched skin cube 2 m wide (a slab to the walks), at
/// normal incidence 0.557 / 0.323 / 0.195 against 0.570 / 0.329 / 0.198, at 60° 0.648 /
/// 0.407 / 0.266 against 0.657 / 0.416 / 0.264; held within ±0.025 (3 standard deviations of
/// 4096 walks, plus Hapke's 1 %). A beam from behind the face walks nothing.
#[test]
fn beam_walks_give_back_the_plane_albedo() {
    use crate::translucency::diffusion::collimated_albedo;
    use crate::translucency::random_walk::{EntryPoint, WALKS_PER_CHANNEL, WalkLaunch, walk_exits};
    let medium = TranslucentMedium {
        index_of_refraction: 1.0,
        ..TranslucentPreset::Skin1.medium()
    };
    let cube = mesh_object(Cuboid::new(2.0, 2.0, 2.0).mesh().build(), Transform::IDENTITY);
    let rays = SceneRays::new(&views_of(std::slice::from_ref(&cube)));
    // Entered on the top face, away from its edges and from the diagonals its triangles share
    // with the bottom's (a ray along an edge may slip between two triangles).
    let cap = [EntryPoint {
        position: Vec3::new(0.123, 1.0, -0.217),
        normal: Vec3::Y,
        area: 1.0,
    }];
    let albedo = medium.single_scattering_albedo();
    for mu in [1.0f32, 0.5] {
        let beam = Vec3::new((1.0 - mu * mu).sqrt(), -mu, 0.0);
        let mut left = Vec3::ZERO;
        let walked = walk_exits(
            &medium,
            0.001,
            &cap,
            &rays,
            WALKS_PER_CHANNEL,
            11,
            WalkLaunch::Beam(beam),
            |c, _| left[c] += 1.0 / WALKS_PER_CHANNEL as f32,
        );
        assert!(walked);
        let expected = Vec3::from_array(albedo.map(|a| collimated_albedo(a, mu as f64) as f32));
        eprintln!("mu {mu}: walks {left}, plane albedo {expected}");
        assert!(
            (left - expected).abs().max_element() < 0.025,
            "mu {mu}: walks {left}, plane albedo {expected}"
        );
    }
    let mut any = false;
    walk_exits(&medium, 0.001, &cap, &rays, 64, 11, WalkLaunch::Beam(Vec3::Y), |_, _| {
        any = true
    });
    assert!(!any, "a beam from behind the faces entered");
}
