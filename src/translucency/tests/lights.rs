use super::*;
use crate::translucency::transport::lights_reaching;

/// A point `k` of `n` spread through the unit ball (a Fibonacci sphere of cube-root radii).
fn in_unit_ball(k: usize, n: usize) -> Vec3 {
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    let z = 1.0 - 2.0 * (k as f32 + 0.5) / n as f32;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = golden * k as f32;
    let shell = ((k * 7919 % n) as f32 + 0.5) / n as f32;
    Vec3::new(r * phi.cos(), r * phi.sin(), z) * shell.cbrt()
}

fn spot(position: Vec3, direction: Vec3, outer_angle: f32, range: f32) -> PatchLight {
    PatchLight::Spot {
        position,
        direction,
        intensity: Vec3::new(1000.0, 800.0, 600.0),
        inner_angle: outer_angle * 0.6,
        outer_angle,
        range,
    }
}

fn point(position: Vec3, intensity: f32, range: f32) -> PatchLight {
    PatchLight::Point { position, intensity: Vec3::splat(intensity), range }
}

#[test]
fn a_lights_bound_holds_everywhere_in_the_sphere() {
    let (centre, radius) = (Vec3::new(0.2, -0.1, 0.3), 0.5);
    let mut lights = Vec::new();
    for k in 0..24 {
        let at = centre + in_unit_ball(k, 24).normalize() * radius * (1.2 + 0.4 * k as f32);
        let towards = (centre - at).normalize();
        // Spots aimed at, beside and past the sphere, narrow and wide; ranges that reach
        // into it and beyond it.
        let aside = towards.any_orthonormal_vector() * (0.15 * (k % 5) as f32);
        let range = (at - centre).length() - radius * (0.5 - 0.1 * (k % 4) as f32);
        lights.push(spot(at, (towards + aside).normalize(), 0.2 + 0.1 * (k % 6) as f32, range));
        lights.push(point(at, 500.0, range));
    }
    let mut lit = 0;
    for light in &lights {
        let bound = light.irradiance_bound(centre, radius);
        let mut most = Vec3::ZERO;
        for k in 0..4000 {
            let e = light.irradiance_across(centre + in_unit_ball(k, 4000) * radius);
            assert!(e.cmple(bound * (1.0 + 1e-4) + 1e-9).all(), "{light:?}: {e} above its bound {bound}");
            most = most.max(e);
        }
        if most.max_element() > 0.0 {
            lit += 1;
        }
        // A point light's bound is its light at the sphere's nearest point.
        if let PatchLight::Point { position, .. } = *light {
            let nearest = centre + (position - centre).normalize() * radius;
            let e = light.irradiance_across(nearest);
            assert!((bound - e).abs().max_element() <= 1e-4 * bound.max_element(), "{bound} against {e}");
        }
    }
    // The set has lights that light the sphere and lights that cannot.
    assert!(lit > 10 && lit < lights.len(), "{lit} of {}", lights.len());
}

#[test]
fn lights_that_cannot_reach_the_patches_are_left_out() {
    let (centre, radius) = (Vec3::ZERO, 1.0);
    let sun = PatchLight::Directional { direction: Vec3::NEG_Y, illuminance: Vec3::splat(1e4) };
    let near = point(Vec3::new(0.0, 3.0, 0.0), 100.0, 20.0);
    let short = point(Vec3::new(0.0, 3.0, 0.0), 100.0, 1.9);
    let inside = point(Vec3::new(0.0, 0.5, 0.0), 100.0, 0.1);
    let away = spot(Vec3::new(0.0, 3.0, 0.0), Vec3::Y, 0.5, 20.0);
    // Its cone's edge 0.5 rad from the axis; the sphere's edge asin(1/3) = 0.34 rad from the
    // line to its centre: aimed 0.8 rad off it, the cone still takes in the sphere's rim.
    let grazing = spot(Vec3::new(0.0, 3.0, 0.0), Vec3::new(0.8f32.sin(), -0.8f32.cos(), 0.0), 0.5, 20.0);
    let missing = spot(Vec3::new(0.0, 3.0, 0.0), Vec3::new(0.9f32.sin(), -0.9f32.cos(), 0.0), 0.5, 20.0);
    let dark = point(Vec3::new(0.0, 3.0, 0.0), 0.0, 20.0);
    let broken = point(Vec3::new(f32::NAN, 3.0, 0.0), 100.0, 20.0);
    let unbounded = point(Vec3::new(0.0, 30.0, 0.0), 100.0, f32::INFINITY);
    let all = [sun, near, short, inside, away, grazing, missing, dark, broken, unbounded];
    let reaching = lights_reaching(&all, centre, radius, usize::MAX);
    assert_eq!(reaching.lights, vec![sun, near, inside, grazing, unbounded]);
    assert_eq!((reaching.unreachable, reaching.left_out, reaching.left_out_share), (5, 0, 0.0));
    assert!(inside.irradiance_bound(centre, radius).x.is_infinite());
    // The grazing spot does light the sphere's rim; the one aimed further off does not.
    let lights_some = |l: &PatchLight| (0..20000).any(|k| l.irradiance_across(centre + in_unit_ball(k, 20000) * radius).x > 0.0);
    assert!(lights_some(&grazing) && !lights_some(&missing));
}

#[test]
fn of_more_lights_than_taken_the_brightest_are_kept_in_their_order() {
    let (centre, radius) = (Vec3::ZERO, 1.0);
    // Ten equal point lights at 2 – 11 from the centre, given out of order.
    let order = [3, 9, 0, 6, 1, 8, 4, 7, 2, 5];
    let lights: Vec<PatchLight> = order.iter().map(|&d| point(Vec3::new(0.0, 0.0, 2.0 + d as f32), 100.0, 100.0)).collect();
    let reaching = lights_reaching(&lights, centre, radius, 8);
    let kept: Vec<PatchLight> = order.iter().filter(|&&d| d < 8).map(|&d| point(Vec3::new(0.0, 0.0, 2.0 + d as f32), 100.0, 100.0)).collect();
    assert_eq!(reaching.lights, kept);
    assert_eq!((reaching.unreachable, reaching.left_out), (0, 2));
    // The two farthest's share of the bounds (1/d² at 1 + d, range window aside).
    let share = |d: f32| {
        let window = (1.0 - ((1.0 + d) / 100.0).powi(4)).powi(2);
        window / (1.0 + d).powi(2)
    };
    let expected = (share(8.0) + share(9.0)) / (0..10).map(|d| share(d as f32)).sum::<f32>();
    assert!((reaching.left_out_share - expected).abs() < 1e-4 * expected, "{} against {expected}", reaching.left_out_share);
}
