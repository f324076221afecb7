//! The translucent shadow map: the light's path inside a box against its closed form, and
//! single scattering marched against it on a thick slab against the half-space law.

use super::*;
use crate::translucency::translucent_shadow_map::{TranslucentShadowMap, marched_single_scattering};

/// A 2 × 1 × 2 box's patches (its top face at y = 0.5) and its map for a light along `travel`,
/// 256² over the box's bounding sphere.
fn box_map(travel: Vec3) -> TranslucentShadowMap {
    let object = mesh_object(Cuboid::new(2.0, 1.0, 2.0).mesh().build(), Transform::IDENTITY);
    let patches = resample_into_patches(&views_of(std::slice::from_ref(&object)), 400);
    TranslucentShadowMap::splat(&patches.samples, travel, Vec3::ZERO, 1.5, 256).expect("a map")
}

/// Inside the box, the light's path to a point is its distance to the face the light enters
/// by, along the light: measured within 1.5e-7 of the box's height of 1 (float rounding; each
/// texel takes the face's plane), held within 1e-5; in front of that face, behind the far one
/// and beside the box, there is none.
#[test]
fn a_translucent_shadow_map_gives_the_lights_path_inside_a_box() {
    for travel in [Vec3::NEG_Y, Vec3::new(0.3, -1.0, 0.2).normalize()] {
        let map = box_map(travel);
        let mut worst = 0.0f32;
        for i in 0..9 {
            for k in 0..9 {
                for j in 1..10 {
                    let x = Vec3::new(-0.6 + 0.15 * i as f32, 0.5 - 0.1 * j as f32, -0.6 + 0.15 * k as f32);
                    // Back along the light to the top face (the points lie where it is the
                    // top face the light crosses).
                    let exact = (0.5 - x.y) / -travel.y;
                    let got = map.path_inside(x).unwrap_or_else(|| panic!("no path to {x} along {travel}"));
                    worst = worst.max((got - exact).abs());
                }
            }
        }
        eprintln!("along {travel}: the light's path off by {worst} at most");
        assert!(worst < 1e-5, "along {travel}: off by {worst}");
        assert_eq!(map.path_inside(Vec3::new(0.0, 0.6, 0.0)), None, "in front of the box");
        assert_eq!(map.path_inside(Vec3::new(0.0, -0.6, 0.0)), None, "behind the box");
        assert_eq!(map.path_inside(Vec3::new(0.0, 0.0, 1.45)), None, "beside the box");
    }
}

/// On a slab many mean free paths thick, single scattering marched against the map is the
/// half-space law `α μ₀/(4π(μ₀ + μ))` (unit irradiance across the light): measured within
/// 0.035 % (the 64 quantiles alone are within 2e-4 of the integral), held within 0.1 %.
#[test]
fn marched_single_scattering_on_a_thick_slab_is_the_half_space_law() {
    let (alpha, sigma_t) = (Vec3::new(0.9, 0.5, 0.2), Vec3::new(200.0, 400.0, 800.0));
    for mu0 in [1.0f32, 0.6, 0.3] {
        let travel = Vec3::new((1.0 - mu0 * mu0).sqrt(), -mu0, 0.0);
        let map = box_map(travel);
        for mu in [1.0f32, 0.5] {
            let into = Vec3::new(0.0, -mu, (1.0 - mu * mu).sqrt());
            let got = marched_single_scattering(&map.clone().into(), alpha, sigma_t, Vec3::new(0.1, 0.5, -0.1), Vec3::Y, into, 64);
            let law = alpha * mu0 / (4.0 * std::f32::consts::PI * (mu0 + mu));
            let off = (got / law - Vec3::ONE).abs().max_element();
            eprintln!("μ₀ {mu0}, μ {mu}: {off:.5} off the law");
            assert!(off < 0.001, "μ₀ {mu0}, μ {mu}: {got} against the law's {law}");
        }
    }
}

/// Through a boundary of η = 1.3, the plugin's march (`MarchedObject::radiance`: the view ray
/// refracted in, each texel's light `E T(μ₀) μ₀/μ₀′` and path scale, out by `T(μ)/η²`, at its
/// 8 depths a channel) on the thick slab is the half-space law with the boundary,
/// `α E T(μ₀) T(μ) / (4π η² (μ₀′ + μ′))`, wherever the light enters within 58° of the normal
/// (above `PATH_SCALE_FLOOR`): measured within 0.17 % (the 8 quantiles' own error), held
/// within 0.5 %.
#[test]
fn the_plugins_march_through_a_boundary_is_the_half_space_law() {
    use crate::translucency::{
        PatchLight,
        beam_table::single_scattering_radiance,
        translucent_shadow_map::{MarchedMedium, MarchedObject, PLUGIN_RESOLUTION},
    };
    let medium = MarchedMedium { sigma_t: Vec3::new(200.0, 400.0, 800.0), alpha: Vec3::new(0.9, 0.5, 0.2), eta: 1.3 };
    let object = mesh_object(Cuboid::new(2.0, 1.0, 2.0).mesh().build(), Transform::IDENTITY);
    let patches = resample_into_patches(&views_of(std::slice::from_ref(&object)), 400);
    let mut worst = 0.0f32;
    for mu0 in [1.0f32, 0.8, 0.6] {
        let travel = Vec3::new((1.0 - mu0 * mu0).sqrt(), -mu0, 0.0);
        let light = PatchLight::Directional { direction: travel, illuminance: Vec3::new(2.0, 1.0, 0.5) };
        let marched = MarchedObject::new(&patches.samples, medium, &[light], PLUGIN_RESOLUTION, |_, _| 1.0);
        for mu in [1.0f32, 0.5] {
            let towards = Vec3::new(0.0, mu, -(1.0 - mu * mu).sqrt());
            let got = marched.radiance(Vec3::new(0.1, 0.5, -0.1), Vec3::Y, towards);
            let law = single_scattering_radiance(medium.alpha, medium.eta, Vec3::new(2.0, 1.0, 0.5) * mu0, mu0, mu);
            let off = (got / law - Vec3::ONE).abs().max_element();
            eprintln!("μ₀ {mu0}, μ {mu}: {off:.4} off the law");
            worst = worst.max(off);
        }
    }
    assert!(worst < 0.005, "{worst} off the law");
}

/// Single scattering inside a unit ball lit by `light`, marched by rays: at each of the
/// plugin's depths along the ray into the ball from `x` (index-matched), the light's path
/// inside from the point straight towards the light, and its irradiance at the point.
fn ball_single_scattering_by_rays(light: &crate::translucency::PatchLight, alpha: Vec3, sigma_t: Vec3, x: Vec3, into: Vec3) -> Vec3 {
    use crate::translucency::{PatchLight, translucent_shadow_map::{PLUGIN_DEPTHS, optical_depth_quantile}};
    // The length of the chord from `p` (inside the unit ball) along the unit `d`.
    let chord = |p: Vec3, d: Vec3| {
        let b = p.dot(d);
        -b + (b * b - (p.length_squared() - 1.0)).max(0.0).sqrt()
    };
    Vec3::from_array(std::array::from_fn(|c| {
        let mut sum = 0.0;
        for k in 0..PLUGIN_DEPTHS {
            let p = x + into * optical_depth_quantile(k, PLUGIN_DEPTHS) / sigma_t[c];
            if p.length_squared() > 1.0 {
                break;
            }
            let towards_light = match *light {
                PatchLight::Directional { direction, .. } => -direction,
                PatchLight::Point { position, .. } | PatchLight::Spot { position, .. } => (position - p).normalize(),
            };
            sum += light.irradiance_across(p)[c] * (-sigma_t[c] * chord(p, towards_light)).exp();
        }
        alpha[c] / (4.0 * std::f32::consts::PI) * sum / PLUGIN_DEPTHS as f32
    }))
}

/// Under a point light, the plugin's map (perspective from the light, the light spreading
/// inside as `(entry distance / distance)²`) gives a skin ball's single scattering as rays do,
/// from 1.5 to 10 radii away, as it does under a directional light (the map's own error: its
/// texels and the ball's facets). Relative L1 against rays over the ball's face to the camera,
/// measured: lit from the front 0.0053 (directional) and at most 0.0066 (point), from behind
/// 0.0420 and at most 0.0568 (before the tangent plane's bound under lit surfaces: 0.0062,
/// 0.0083, 0.0613, 0.0625); held within 0.015 and 0.08. At 1.1 radii, just outside the
/// ball's bounds, 0.071 and 0.068 (were 0.125 and 0.119), held within 0.2 (orthographic
/// there: 1.6 and 2.5·10³). An
/// orthographic map along the line
/// from the light, with the light's irradiance where it enters (the frame before), was 0.078 /
/// 0.16 / 0.30 / 0.51 / 0.80 off from the front at 10 / 5 / 3 / 2 / 1.5 radii, and 1.3 / 5.0
/// / 18 / 77 / 353 from behind: the parallel columns light the whole hemisphere, where the
/// light's own rays light a smaller cap.
#[test]
fn orthographic_maps_miss_a_near_lights_own_rays() {
    use crate::translucency::{PatchLight, translucent_shadow_map::{MarchedMedium, MarchedObject, PLUGIN_RESOLUTION}};
    // Skin1 in a ball of 1 cm radius, per unit radius.
    let medium = MarchedMedium { sigma_t: Vec3::new(7.72, 10.5, 14.9), alpha: Vec3::new(0.959, 0.838, 0.678), eta: 1.0 };
    let object = mesh_object(Sphere::new(1.0).mesh().ico(20).unwrap(), Transform::IDENTITY);
    let patches = resample_into_patches(&views_of(std::slice::from_ref(&object)), 1000);
    let towards = Vec3::Z;
    let points: Vec<Vec3> = (0..48 * 48)
        .filter_map(|i| {
            let (x, y) = (((i % 48) as f32 + 0.5) / 24.0 - 1.0, ((i / 48) as f32 + 0.5) / 24.0 - 1.0);
            let z2 = 1.0 - x * x - y * y;
            (z2 >= 0.09).then(|| Vec3::new(x, y, z2.sqrt()))
        })
        .collect();
    for (side, from, held) in [("front", Vec3::new(0.4, 0.2, 1.0), 0.015), ("behind", Vec3::new(-0.4, 0.2, -1.0), 0.08)] {
        let from = from.normalize();
        for distance in [0.0f32, 10.0, 5.0, 3.0, 2.0, 1.5, 1.1] {
            let light = if distance == 0.0 {
                PatchLight::Directional { direction: -from, illuminance: Vec3::ONE }
            } else {
                PatchLight::Point { position: from * distance, intensity: Vec3::splat(distance * distance), range: 1e6 }
            };
            let marched = MarchedObject::new(&patches.samples, medium, &[light], PLUGIN_RESOLUTION, |_, _| 1.0);
            let (mut diff, mut total) = (0.0f32, 0.0f32);
            for &x in &points {
                let got = marched.radiance(x, x, towards);
                let want = ball_single_scattering_by_rays(&light, medium.alpha, medium.sigma_t, x, -towards);
                diff += (got - want).abs().element_sum();
                total += want.element_sum();
            }
            let off = diff / total;
            eprintln!("lit from {side}, {}: {off:.4} off rays", if distance == 0.0 { "directional".into() } else { format!("a point {distance} radii away") });
            // Just outside the ball's bounds the texels near the map's edge are wide and the
            // entries grazing.
            let held = if distance < 1.5 { 0.2 } else { held };
            assert!(off < held, "lit from {side}, light {distance} radii away: {off} off rays");
        }
    }
}

/// Where the light reaches a skin ball at a grazing angle (`μ₀` 0.02 – 0.2 on the face towards
/// the camera), a texel's entry lies up to its width over `tan θ₀` off the surface, and the
/// march against the map alone sees light cross skin right under the lit surface. With the
/// tangent plane's bound (`LightMaps::half_space_bound`: the path at most `t μ/μ₀`) the
/// march follows rays more closely there. Relative L1 against rays over those points
/// (818 of them), measured: 0.024 with the bound, 0.035 with the map alone (the same march
/// with the bound withheld: the normal turned away from the light); held within 0.03 and
/// below 0.8 of the map's. The bound is none for a surface facing away and for a point beyond
/// the object's first stretch.
#[test]
fn the_march_under_a_grazing_light_follows_the_tangent_plane() {
    use crate::translucency::{
        PatchLight,
        translucent_shadow_map::{LightMaps, MarchedMedium, MarchedObject, PLUGIN_DEPTHS, PLUGIN_RESOLUTION},
    };
    let medium = MarchedMedium { sigma_t: Vec3::new(7.72, 10.5, 14.9), alpha: Vec3::new(0.959, 0.838, 0.678), eta: 1.0 };
    let object = mesh_object(Sphere::new(1.0).mesh().ico(20).unwrap(), Transform::IDENTITY);
    let patches = resample_into_patches(&views_of(std::slice::from_ref(&object)), 1000);
    let light = PatchLight::Directional { direction: Vec3::NEG_X, illuminance: Vec3::ONE };
    let marched = MarchedObject::new(&patches.samples, medium, &[light], PLUGIN_RESOLUTION, |_, _| 1.0);
    let towards = Vec3::Z;
    let (mut bounded, mut alone, mut total, mut points) = (0.0f32, 0.0f32, 0.0f32, 0);
    for i in 0..96 * 96 {
        let (x, y) = (((i % 96) as f32 + 0.5) / 48.0 - 1.0, ((i / 96) as f32 + 0.5) / 48.0 - 1.0);
        let z2 = 1.0 - x * x - y * y;
        if z2 < 0.09 || !(0.02..0.2).contains(&x) {
            continue;
        }
        let p = Vec3::new(x, y, z2.sqrt());
        let want = ball_single_scattering_by_rays(&light, medium.alpha, medium.sigma_t, p, -towards);
        bounded += (marched.radiance(p, p, towards) - want).abs().element_sum();
        let map_alone = marched_single_scattering(&marched.maps[0], medium.alpha, medium.sigma_t, p, -p, -towards, PLUGIN_DEPTHS);
        alone += (map_alone - want).abs().element_sum();
        total += want.element_sum();
        points += 1;
    }
    let (bounded, alone) = (bounded / total, alone / total);
    eprintln!("{points} points lit at a grazing angle: {bounded:.3} off rays with the bound, {alone:.3} with the map alone");
    assert!(points > 50, "{points} points");
    assert!(bounded < 0.03 && bounded < 0.8 * alone, "{bounded} with the bound, {alone} alone");
    // None facing away, none beyond the object, μ/μ₀ on the lit face.
    let maps: &LightMaps = &marched.maps[0];
    let lit = Vec3::new(0.6, 0.0, 0.8);
    let got = maps.half_space_bound(lit, lit, -Vec3::Z).expect("a lit surface");
    assert!((got - 0.8 / 0.6).abs() < 1e-4, "{got}");
    assert_eq!(maps.half_space_bound(-lit, -lit, Vec3::Z), None, "facing away");
    assert_eq!(maps.half_space_bound(Vec3::new(-1.5, 0.0, 0.0), Vec3::X, Vec3::NEG_X), None, "beyond the ball");
}

/// A map's frame for each kind of light: a directional light's orthographic; a point light's
/// in perspective from it beyond `PERSPECTIVE_NEAREST` bounding radii (its half-angle's
/// tangent `sin/cos` of the sphere's, with 2 % to spare), orthographic nearer; none for a
/// light on the centre or a non-finite one, and never a panic. The maps an object gets
/// (`frames_towards`): that one, or nearer a cube of six perspective faces about the light,
/// the centre included, each face the one `cube_face` names for its own axis. A point's place
/// and its texel's ray agree: the ray at a point's texel coordinates, out to its depth, is
/// the point.
#[test]
fn a_maps_frame_follows_its_light() {
    use crate::translucency::{
        PatchLight,
        translucent_shadow_map::{CUBE_FACE_WIDTH, MapFrame, PERSPECTIVE_NEAREST, cube_face},
    };
    let point = |position: Vec3| PatchLight::Point { position, intensity: Vec3::ONE, range: 10.0 };
    let directional = PatchLight::Directional { direction: Vec3::NEG_Y, illuminance: Vec3::ONE };
    let f = MapFrame::towards(&directional, Vec3::ZERO, 1.0).expect("a frame");
    assert!(!f.perspective && (f.width - 1.02).abs() < 1e-6 && f.travel == Vec3::NEG_Y);
    let f = MapFrame::towards(&point(Vec3::new(0.0, 4.0, 0.0)), Vec3::ZERO, 1.0).expect("a frame");
    let sine = 1.02f32 / 4.0;
    assert!(f.perspective && (f.width - sine / (1.0 - sine * sine).sqrt()).abs() < 1e-6, "{f:?}");
    let near = MapFrame::towards(&point(Vec3::new(0.0, PERSPECTIVE_NEAREST * 0.99, 0.0)), Vec3::ZERO, 1.0).expect("a frame");
    assert!(!near.perspective, "{near:?}");
    assert_eq!(MapFrame::towards(&point(Vec3::ZERO), Vec3::ZERO, 1.0), None);
    assert_eq!(MapFrame::towards(&point(Vec3::splat(f32::NAN)), Vec3::ZERO, 1.0), None);
    assert_eq!(MapFrame::towards(&directional, Vec3::ZERO, f32::NAN), None);
    assert_eq!(MapFrame::frames_towards(&directional, Vec3::ZERO, 1.0), vec![MapFrame::towards(&directional, Vec3::ZERO, 1.0).unwrap()]);
    assert_eq!(MapFrame::frames_towards(&point(Vec3::new(0.0, 4.0, 0.0)), Vec3::ZERO, 1.0), vec![f]);
    let inside = Vec3::new(0.0, PERSPECTIVE_NEAREST * 0.99, 0.0);
    for light in [inside, Vec3::ZERO] {
        let cube = MapFrame::frames_towards(&point(light), Vec3::ZERO, 1.0);
        assert_eq!(cube.len(), 6, "{cube:?}");
        for (face, frame) in cube.iter().enumerate() {
            assert!(frame.perspective && frame.origin == light && frame.width == CUBE_FACE_WIDTH, "{frame:?}");
            assert_eq!(cube_face(frame.travel), face, "{frame:?}");
        }
    }
    assert!(MapFrame::frames_towards(&point(Vec3::splat(f32::NAN)), Vec3::ZERO, 1.0).is_empty());
    assert!(MapFrame::frames_towards(&point(inside), Vec3::ZERO, f32::NAN).is_empty());
    let cube = MapFrame::frames_towards(&point(inside), Vec3::ZERO, 1.0);
    for frame in [Some(f), Some(near), None] {
        for x in [Vec3::new(0.3, 0.2, -0.5), Vec3::new(-0.7, -0.4, 0.1), Vec3::new(0.2, 1.3, 0.1), Vec3::new(0.1, 1.0, 0.9)] {
            // The cube: the face the point lies in from the light, inside its texels.
            let frame = frame.unwrap_or(cube[cube_face(x - inside)]);
            let (at, depth) = frame.place(x, 256);
            assert!(frame != cube[cube_face(x - inside)] || at.cmpge(Vec2::ZERO).all() && at.cmple(Vec2::splat(256.0)).all(), "{x} at {at}");
            let (origin, towards) = frame.ray(at, 256);
            let back = origin + towards * depth;
            assert!(back.distance(x) < 1e-5, "{x} came back as {back} ({frame:?})");
        }
    }
    // Behind a perspective map's light: off the map.
    assert_eq!(f.place(Vec3::new(0.0, 5.0, 0.0), 256).1, f32::INFINITY);
}

/// An object's maps fitted to its own extent across the light (`MapFrame::fitted_to`): a
/// cube's samples (their mean at its centre, so its bounding sphere's radius is `√3/2` of
/// its side) seen along a face's normal fill a square of half its side: the fitted
/// orthographic map is 0.5 + the splats' reach wide against the sphere's 0.88 (measured
/// 0.61 of it), its centre moved to the middle of the cube's outline (here where it was)
/// and for a cube shifted off the samples' mean (a lump on one side) as far as the outline
/// moved; a point light's map in perspective narrows to the cube's widest point about its
/// axis. Every sample's splat lands inside the fitted map, for a fit of the samples and of
/// the grid cells standing in for more than 32 768 of them. A ball's fit is its sphere's
/// (never wider); a cube of six maps is left as it is; no points, or a point behind a
/// perspective map's light, keep the sphere's frame.
#[test]
fn a_maps_frame_is_fitted_to_its_objects_extent() {
    use crate::translucency::{
        PatchLight,
        patches::PatchSample,
        translucent_shadow_map::{MapFit, MapFrame, object_bounds},
    };
    // Samples over a unit cube's faces (plus an optional lump of them at one corner), `n` a
    // side a face, each a square piece's area.
    let cube = |n: usize, lump: bool| -> Vec<PatchSample> {
        let mut samples = Vec::new();
        let area = 1.0 / (n * n) as f32;
        for axis in 0..3 {
            for side in [-0.5f32, 0.5] {
                for i in 0..n {
                    for j in 0..n {
                        let (a, b) = ((i as f32 + 0.5) / n as f32 - 0.5, (j as f32 + 0.5) / n as f32 - 0.5);
                        let mut p = [a, b, a];
                        p[axis] = side;
                        p[(axis + 1) % 3] = a;
                        p[(axis + 2) % 3] = b;
                        let mut normal = Vec3::ZERO;
                        normal[axis] = side.signum();
                        samples.push(PatchSample { position: Vec3::from_array(p), normal, area });
                    }
                }
            }
        }
        if lump {
            // Many samples near one corner pull the mean (the sphere's centre) off the cube's.
            samples.extend((0..4000).map(|k| PatchSample {
                position: Vec3::new(0.5, 0.5 - 0.2 * (k % 40) as f32 / 40.0, 0.5 - 0.2 * (k / 40) as f32 / 100.0),
                normal: Vec3::X,
                area: 1e-5,
            }));
        }
        samples
    };
    let directional = PatchLight::Directional { direction: Vec3::NEG_Y, illuminance: Vec3::ONE };
    let point = PatchLight::Point { position: Vec3::new(0.0, 6.0, 0.0), intensity: Vec3::ONE, range: 100.0 };
    let covers = |frame: &MapFrame, samples: &[PatchSample]| {
        samples.iter().all(|s| {
            let reach = 1.5 * (s.area / std::f32::consts::PI).sqrt() * 0.999;
            let (at, _) = frame.place(s.position, 256);
            let texel = 2.0 * frame.width / 256.0 * if frame.perspective { (s.position - frame.origin).length() } else { 1.0 };
            let r = reach / texel;
            at.x - r >= 0.0 && at.y - r >= 0.0 && at.x + r <= 256.0 && at.y + r <= 256.0
        })
    };
    for (n, lump) in [(24, false), (80, false), (24, true)] {
        let samples = cube(n, lump);
        let fit = MapFit::of(&samples);
        assert_eq!(fit.points().len() < samples.len(), samples.len() > 32_768, "{n}: a grid past 32 768 samples");
        let (centre, radius) = object_bounds(&samples).expect("bounds");
        let sphere = MapFrame::towards(&directional, centre, radius).expect("a frame");
        let fitted = sphere.fitted_to(&fit);
        let splat = 1.5 * (1.0 / (n * n) as f32 / std::f32::consts::PI).sqrt();
        eprintln!("{n} a side{}: fitted {} against the sphere's {} ({:.3})", if lump { ", a lump" } else { "" }, fitted.width, sphere.width, fitted.width / sphere.width);
        assert!(fitted.width <= sphere.width && fitted.width >= 0.5 * 1.02, "{fitted:?}");
        if !lump && n < 80 {
            assert!((fitted.width - (0.5 + splat) * 1.02).abs() < 1e-4, "{fitted:?}");
        }
        // Depth is along the light from the same plane; across, the outline's middle (within
        // a cell's half-diagonal across where cells stand in for the samples: 1/48 of a side).
        let moved = fitted.origin - centre;
        let off = if fit.points().len() < samples.len() { 0.75 / 48.0 } else { 2e-3 };
        assert!(moved.dot(fitted.travel).abs() < 1e-5 && Vec2::new(fitted.origin.x, fitted.origin.z).length() < off, "{fitted:?} about {centre}");
        assert!(covers(&fitted, &samples), "{n}: a splat off the fitted map");
        let perspective = MapFrame::towards(&point, centre, radius).expect("a frame");
        let narrowed = perspective.fitted_to(&fit);
        assert!(narrowed.perspective && narrowed.width < 0.8 * perspective.width && narrowed.origin == perspective.origin, "{narrowed:?}");
        assert!(covers(&narrowed, &samples), "{n}: a splat off the fitted perspective map");
        assert_eq!(MapFrame::frames_fitted(&directional, centre, radius, &fit), vec![fitted]);
    }
    // A ball: the square about its outline is its sphere's disc and more, so the sphere holds.
    let ball: Vec<PatchSample> = (0..2000)
        .map(|k| {
            let z = 1.0 - 2.0 * (k as f32 + 0.5) / 2000.0;
            let phi = k as f32 * 2.399_963;
            let p = Vec3::new((1.0 - z * z).sqrt() * phi.cos(), z, (1.0 - z * z).sqrt() * phi.sin());
            PatchSample { position: p, normal: p, area: 4.0 * std::f32::consts::PI / 2000.0 }
        })
        .collect();
    let (centre, radius) = object_bounds(&ball).expect("bounds");
    let sphere = MapFrame::towards(&directional, centre, radius).expect("a frame");
    assert_eq!(sphere.fitted_to(&MapFit::of(&ball)), sphere);
    // A cube of maps about a light inside the bounds, no points, a point behind the light.
    let inside = PatchLight::Point { position: Vec3::new(0.1, 0.0, 0.0), intensity: Vec3::ONE, range: 10.0 };
    let samples = cube(24, false);
    let fit = MapFit::of(&samples);
    assert_eq!(MapFrame::frames_fitted(&inside, Vec3::ZERO, 0.9, &fit), MapFrame::frames_towards(&inside, Vec3::ZERO, 0.9));
    assert_eq!(sphere.fitted_to(&MapFit::of(&[])), sphere);
    let behind = MapFrame::towards(&PatchLight::Point { position: Vec3::new(0.0, 0.2, 0.0), intensity: Vec3::ONE, range: 10.0 }, Vec3::new(0.0, -2.0, 0.0), 1.0)
        .expect("a frame");
    assert!(behind.perspective);
    assert_eq!(behind.fitted_to(&fit), behind, "points beside the light");
}
