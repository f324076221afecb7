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
    let transport = EnergyTransport::build(&patches, &surfaces, &rays, &TransportSettings { beam_table: None, ..default() });
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

/// An index-matched skin cube 2 m wide (a slab to the walks), its rays, and an entry point on
/// its top face, away from its edges and from the diagonals its triangles share with the
/// bottom's (a ray along an edge may slip between two triangles).
fn skin_cube_top() -> (TranslucentMedium, SceneRays, [crate::translucency::random_walk::EntryPoint; 1]) {
    let medium = TranslucentMedium {
        index_of_refraction: 1.0,
        ..TranslucentPreset::Skin1.medium()
    };
    let cube = mesh_object(Cuboid::new(2.0, 2.0, 2.0).mesh().build(), Transform::IDENTITY);
    let rays = SceneRays::new(&views_of(std::slice::from_ref(&cube)));
    let cap = [crate::translucency::random_walk::EntryPoint {
        position: Vec3::new(0.123, 1.0, -0.217),
        normal: Vec3::Y,
        area: 1.0,
    }];
    (medium, rays, cap)
}

/// The shares of 4096 beam walks (seed 11, shared by the channels: `walk_ends`) travelling
/// along `beam` into [`skin_cube_top`]'s top that leave after `first` – `last` scatterings,
/// and that are still inside after `last`; `None` where nothing was walked.
fn beam_exits(beam: Vec3, first: u32, last: u32) -> Option<(Vec3, Vec3)> {
    beam_exits_split(beam, first, last, None).map(|e| (e.left, e.inside))
}

/// What [`beam_exits`] finds, and of what left, what left more than `FAR` from the entry and
/// in how many exits.
struct BeamExits {
    left: Vec3,
    inside: Vec3,
    far: Vec3,
    far_exits: usize,
}

/// Where [`beam_exits_split`] counts an exit far: 5 mm from the entry (the cube is in metres,
/// 1000 mm a unit), about four of skin's red reduced mean free paths.
const FAR: f32 = 0.005;

/// [`beam_exits`] with the walks split far from their entry by `split`.
fn beam_exits_split(
    beam: Vec3,
    first: u32,
    last: u32,
    split: Option<crate::translucency::random_walk::FarSplit>,
) -> Option<BeamExits> {
    let (_, _, cap) = skin_cube_top();
    beam_exits_from(&cap, beam, first, last, split)
}

/// [`beam_exits_split`] from `entries` on [`skin_cube_top`]'s cube (`FAR` measured from the
/// first).
fn beam_exits_from(
    entries: &[crate::translucency::random_walk::EntryPoint],
    beam: Vec3,
    first: u32,
    last: u32,
    split: Option<crate::translucency::random_walk::FarSplit>,
) -> Option<BeamExits> {
    use crate::translucency::random_walk::{
        ScatteringOrders, WALKS_PER_CHANNEL, WalkEnd, WalkLaunch, walk_ends,
    };
    let (medium, rays, _) = skin_cube_top();
    let share = 1.0 / WALKS_PER_CHANNEL as f32;
    let mut exits = BeamExits { left: Vec3::ZERO, inside: Vec3::ZERO, far: Vec3::ZERO, far_exits: 0 };
    walk_ends(
        &medium,
        0.001,
        entries,
        &rays,
        WALKS_PER_CHANNEL,
        11,
        WalkLaunch::Beam(beam),
        ScatteringOrders { first, last },
        split,
        |weight, end| match end {
            WalkEnd::Exit(exit) => {
                exits.left += weight * share;
                if exit.position.distance(entries[0].position) > FAR {
                    exits.far += weight * share;
                    exits.far_exits += 1;
                }
            }
            WalkEnd::Gap => exits.left += weight * share,
            WalkEnd::Remainder => exits.inside += weight * share,
        },
    )
    .then_some(exits)
}

/// Walks launched as a beam (`WalkLaunch::Beam`) give back what Chandrasekhar's plane albedo
/// says a half-space gives back of a collimated beam (`collimated_albedo`, Hapke's `H` within
/// 1 %): into the top of an index-matched skin cube 2 m wide (a slab to the walks), at
/// normal incidence 0.548 / 0.322 / 0.195 against 0.570 / 0.329 / 0.198, at 60° 0.643 /
/// 0.407 / 0.256 against 0.657 / 0.416 / 0.264; held within ±0.025 (~3 standard deviations
/// of 4096 walks shared by the channels, plus Hapke's 1 %; 262 144 of them gave 0.566 / 0.325
/// / 0.195 and 0.654 / 0.412 / 0.261: the hero channels' weights add no bias). A beam from
/// behind the face walks nothing.
#[test]
fn beam_walks_give_back_the_plane_albedo() {
    use crate::translucency::diffusion::collimated_albedo;
    let albedo = skin_cube_top().0.single_scattering_albedo();
    for mu in [1.0f32, 0.5] {
        let beam = Vec3::new((1.0 - mu * mu).sqrt(), -mu, 0.0);
        // Every order but the beam's uncollided light, which goes on along the beam.
        let (left, _) = beam_exits(beam, 1, u32::MAX).expect("walked");
        let expected = Vec3::from_array(albedo.map(|a| collimated_albedo(a, mu as f64) as f32));
        eprintln!("mu {mu}: walks {left}, plane albedo {expected}");
        assert!(
            (left - expected).abs().max_element() < 0.025,
            "mu {mu}: walks {left}, plane albedo {expected}"
        );
    }
    assert!(beam_exits(Vec3::Y, 1, u32::MAX).is_none(), "a beam from behind the faces entered");
}

/// A beam enters a patch that curves away from it only where it meets the patch's faces, by
/// their projected area: walked from [`skin_cube_top`]'s top and from an entry of equal area
/// on the cube's bottom, which the beam from above meets from behind, the walks give back
/// Chandrasekhar's plane albedo as from the top alone (0.548 / 0.322 / 0.195 against 0.570 /
/// 0.329 / 0.198, held within ±0.025 as in `beam_walks_give_back_the_plane_albedo`). Drawn by
/// area, half the walks started at the bottom and their share was lost: 0.285 / 0.166 / 0.100.
#[test]
fn a_beam_enters_a_patch_only_through_the_faces_it_meets() {
    use crate::translucency::{diffusion::collimated_albedo, random_walk::EntryPoint};
    let (medium, _, cap) = skin_cube_top();
    let entries = [cap[0], EntryPoint { position: Vec3::new(0.123, -1.0, -0.217), normal: Vec3::NEG_Y, area: 1.0 }];
    let left = beam_exits_from(&entries, Vec3::NEG_Y, 1, u32::MAX, None).expect("nothing walked").left;
    let albedo = medium.single_scattering_albedo();
    let expected = Vec3::from_array(albedo.map(|a| collimated_albedo(a, 1.0) as f32));
    assert!((left - expected).abs().max_element() < 0.025, "walks {left}, plane albedo {expected}");
}

/// Beam walks split far from their entry (`FarSplit`, what the beam table's walks do:
/// `BeamTableSettings::far_splits`) give back the same light as unsplit walks, and leave far
/// from the entry by more exits, each of a share: into the top of the skin cube of
/// `beam_walks_give_back_the_plane_albedo`, split into 4 once 2 mm from the entry, at normal
/// incidence 0.559 / 0.326 / 0.200 against Chandrasekhar's 0.570 / 0.329 / 0.198 (unsplit
/// 0.548 / 0.322 / 0.195), at 60° 0.649 / 0.415 / 0.269 against 0.657 / 0.416 / 0.264
/// (0.643 / 0.407 / 0.256); held within ±0.025 as the unsplit walks. What leaves more than
/// 5 mm away (red 0.064 split, 0.058 unsplit; at 60° 0.070 and 0.066) is held within ±0.01,
/// and it leaves by 596 exits against 140 (635 against 156), held at least 3×.
#[test]
fn beam_walks_split_far_from_their_entry_give_back_the_same_light_by_more_exits() {
    use crate::translucency::{diffusion::collimated_albedo, random_walk::FarSplit};
    let albedo = skin_cube_top().0.single_scattering_albedo();
    let split = FarSplit { beyond: 0.002, into: 4 };
    for mu in [1.0f32, 0.5] {
        let beam = Vec3::new((1.0 - mu * mu).sqrt(), -mu, 0.0);
        let whole = beam_exits_split(beam, 1, u32::MAX, None).expect("walked");
        let parts = beam_exits_split(beam, 1, u32::MAX, Some(split)).expect("walked");
        let expected = Vec3::from_array(albedo.map(|a| collimated_albedo(a, mu as f64) as f32));
        eprintln!(
            "mu {mu}: split {} (far {} by {} exits), unsplit {} (far {} by {} exits), plane albedo {expected}",
            parts.left, parts.far, parts.far_exits, whole.left, whole.far, whole.far_exits
        );
        assert!(
            (parts.left - expected).abs().max_element() < 0.025,
            "mu {mu}: split walks {}, plane albedo {expected}",
            parts.left
        );
        assert!(
            (parts.far - whole.far).abs().max_element() < 0.01,
            "mu {mu}: far light split {}, unsplit {}",
            parts.far,
            whole.far
        );
        assert!(
            parts.far_exits >= 3 * whole.far_exits,
            "mu {mu}: {} far exits split, {} unsplit",
            parts.far_exits,
            whole.far_exits
        );
    }
}

/// Walks split by their order of scattering (`walk_ends`, `ScatteringOrders`) give back
/// single scattering's closed form for a beam into a half-space, `α shape(μ₀)/2`
/// (`single_scattering_shape`): both as the walks that leave after one scattering or more less
/// those after two or more (the same walks from the same seed: only what is reported
/// differs), and as the walks stopped at their second scattering. Into the top of the
/// index-matched skin cube of `beam_walks_give_back_the_plane_albedo`, 4096 walks: at normal
/// incidence 0.143 / 0.125 / 0.103 (stopped: 0.152 / 0.136 / 0.112) against 0.147 / 0.129 /
/// 0.104, at 60° 0.213 / 0.182 / 0.144 (0.214 / 0.189 / 0.155) against 0.216 / 0.189 /
/// 0.153; held within ±0.02 (3 standard deviations).
#[test]
fn walks_split_by_order_give_single_scattering_its_closed_form() {
    use crate::translucency::diffusion::single_scattering_shape;
    let albedo = skin_cube_top().0.single_scattering_albedo();
    for mu in [1.0f32, 0.5] {
        let beam = Vec3::new((1.0 - mu * mu).sqrt(), -mu, 0.0);
        let exits = |first, last| beam_exits(beam, first, last).expect("walked");
        let expected = Vec3::from_array(
            albedo.map(|a| (a * single_scattering_shape(mu as f64) / 2.0) as f32),
        );
        let (all, _) = exits(1, u32::MAX);
        let (multiple, _) = exits(2, u32::MAX);
        let (stopped, inside) = exits(1, 1);
        let single = all - multiple;
        eprintln!(
            "mu {mu}: single scattering {single} (walks stopped at their second: {stopped}, \
             {inside} still inside), closed form {expected}"
        );
        for (what, measured) in [("orders 1.. less 2..", single), ("stopped at the second", stopped)] {
            assert!(
                (measured - expected).abs().max_element() < 0.02,
                "mu {mu}: {what} {measured}, closed form {expected}"
            );
        }
        // What the stopped walks leave inside has scattered twice: at most what entered less
        // what left after one.
        assert!(inside.cmple(Vec3::ONE - stopped).all(), "mu {mu}: {inside} inside");
    }
}

/// Every `SceneRays` query finds a face from just under it, where a random walk's collisions
/// near the surface start, however short the ray and whatever the scene's scale: from 1e-6 –
/// 1e-3 of its size under the top of a cube 2 units and 2 cm wide (a scene in metres), 2000
/// rays heading up (cosines 0.05 – 1) each meet the top face where it is (`first_hit_within`
/// and `first_hit`, to 1e-5 of the size: the coordinates' rounding over the cosine), none
/// within half its distance, and `free` says the same. Before every ray started
/// `MIN_BACK_OFF` behind its origin (the BVH, `obvhs`, takes no box nearer than 1e-4 world
/// units), under the 2 cm cube's face `first_hit_within` found it 0 / 0 / 0 / 238 times in
/// 2000 from 2e-8 / 2e-7 / 2e-6 / 2e-5 deep, `first_hit` 222 – 430 and `free` 0 – 229; under
/// the 2-unit cube's, whose rays started 3.5e-4 back, `first_hit_within` found it every time
/// but `first_hit` and `free` did not once from 2e-6 deep. The 1 cm ball of the accuracy
/// suite started them 3.5e-6 back: a fifth of marble's free flights, those under 0.1 mm,
/// went through its surface unseen.
#[test]
fn every_query_finds_a_face_from_just_under_it_at_any_scale() {
    for size in [2.0f32, 0.02] {
        let cube = mesh_object(Cuboid::new(size, size, size).mesh().build(), Transform::IDENTITY);
        let rays = SceneRays::new(&views_of(std::slice::from_ref(&cube)));
        let top = size / 2.0;
        for depth in [1e-6f32, 1e-5, 1e-4, 1e-3].map(|d| d * size) {
            let (mut found, mut unbounded, mut past, mut blocked) = (0, 0, 0, 0);
            for k in 0..2000 {
                let f = k as f32;
                let x = Vec3::new(0.0615 + (f * 0.37).sin() * 0.0005, 0.0, -0.1085 + (f * 0.91).cos() * 0.0005) * size
                    + Vec3::Y * (top - depth);
                let d = Vec3::new((f * 1.3).sin(), (f * 0.7).cos().abs() + 0.05, (f * 2.1).sin()).normalize();
                let reach = depth / d.y;
                let at_face = |hit: Option<(f32, Vec3)>| {
                    hit.is_some_and(|(t, n)| n.y.abs() > 0.99 && (t - reach).abs() <= 1e-3 * reach + 1e-5 * size)
                };
                found += usize::from(at_face(rays.first_hit_within(x, d, reach * 1.01 + 1e-5 * size)));
                unbounded += usize::from(at_face(rays.first_hit(x, d)));
                past += usize::from(rays.first_hit_within(x, d, reach * 0.5).is_some() || !rays.free(x, d, reach * 0.5));
                blocked += usize::from(!rays.free(x, d, reach * 1.01 + 1e-5 * size));
            }
            assert_eq!(
                (found, unbounded, past, blocked),
                (2000, 2000, 0, 2000),
                "{size}-unit cube, {depth} deep: found {found} (unbounded {unbounded}), before the face {past}, \
                 blocked {blocked}"
            );
        }
    }
}
