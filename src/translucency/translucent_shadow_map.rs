//! A translucent object's depth towards one light, finely: its translucent shadow map
//! (Dachsbacher and Stamminger 2003), and single scattering marched per pixel against it.
//!
//! The plugin's single scattering at the lit face is each pixel's half-space law; past the
//! terminator and through thin parts the beam table carries it as whole patches' exitance.
//! Marched per pixel against the light's own path in the object instead, the torus's skin goes
//! 0.087 → 0.057 lit from the front and 0.224 → 0.095 from behind (`docs/translucent.md`,
//! "Single scattering marched per pixel"). The light's path needs the object's depth at a
//! fraction of a mean free path: the injection's maps (the whole scene at 512²) and Bevy's
//! cascades are centimetres wide in a room, so each object has a map of its own, over its
//! bounding sphere, along the light's travel.
//!
//! This is the CPU form, what a GPU term will be held to: each texel where the light enters
//! the object and where it first leaves it again, splatted from its surface samples as the
//! injection's `splat` does (a texel takes a sample's plane where its ray meets the plane
//! within 1.5 of the sample's disc radius, and the sample's own texel always, at its plane's
//! depth).

use bevy::prelude::*;

use super::{lights::PatchLight, medium::TranslucentMedium, patches::PatchSample, transport::PatchSurface};

/// A sample's splat radius against its disc's (the injection's `SPLAT_COVER` in
/// `inject.wgsl`: samples of ≤ h/2 sides do not tile as discs).
const SPLAT_COVER: f32 = 1.5;

/// How far from a sample its splat reaches (world units): [`SPLAT_COVER`] disc radii.
fn splat_cover(s: &PatchSample) -> f32 {
    SPLAT_COVER * (s.area.max(0.0) / std::f32::consts::PI).sqrt()
}

/// The widest splat in texels: a sample wider than this leaves gaps between its neighbours'
/// splats (a map far finer than the patches; at 512² over the bunny a sample is ~8 texels).
const MAX_SPLAT_TEXELS: f32 = 64.0;

/// The finest map [`TranslucentShadowMap::splat`] makes (4096², 128 MiB).
pub const MAX_RESOLUTION: u32 = 4096;

/// The plugin's maps' resolution: 0.18 mm texels on the 4 cm bunny, where the march scored
/// 0.054 / 0.157 (skin, front / behind) against 0.052 / 0.145 at 512² and 0.048 / 0.129 with
/// rays (`docs/translucent.md`, "Single scattering marched per pixel"); with today's table
/// and the tangent plane bounding the path under a lit surface, 0.144 from behind against
/// rays' 0.127 ("Single scattering under a grazing light"). Each map fitted to its object's
/// outline ([`MapFrame::fitted_to`]) makes the bunny's texels 0.16 mm from behind: 0.114 at
/// 4000 patches against 0.111 at 512² over the sphere and 0.100 with rays ("Each object's
/// map fitted to its extent").
pub const PLUGIN_RESOLUTION: u32 = 256;

/// The plugin's depths a channel (`MARCHED_DEPTHS` in `marched.wgsl`). On the bunny and the
/// torus 8 are as good as 64 (the bunny's skin from behind 0.160 against 0.157, 0.169 at 4);
/// on the ball's skin lit from the front they are not: 0.061 at 8, 0.052 at 16, 0.048 at 64.
pub const PLUGIN_DEPTHS: u32 = 16;

/// How a translucent object's map looks along its light's rays: across the light's travel for
/// a directional light (orthographic), from the light for a point or spot light (a
/// perspective map about the line from the light to the object's centre), so that each
/// texel's column is one of the light's own rays. With an orthographic map, a skin ball's
/// single scattering under a point light 10 radii away was 1.3 off rays lit from behind and
/// 0.078 from the front (relative L1): the parallel columns light the whole hemisphere, where
/// the light's own rays light a smaller cap; now 0.063 and 0.007, as under a directional light
/// (`orthographic_maps_miss_a_near_lights_own_rays`). `TranslucentFrame` in boundary.wgsl is
/// its twin, laid out by [`to_vec4s`](Self::to_vec4s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MapFrame {
    /// Orthographic: the object's centre, where depth 0 lies; perspective: the light.
    pub origin: Vec3,
    /// Half the map's width: world units (orthographic) or the tangent of its half-angle
    /// (perspective).
    pub width: f32,
    /// The map's first axis across.
    pub u: Vec3,
    /// Its second axis across.
    pub v: Vec3,
    /// The light's way to the object's centre.
    pub travel: Vec3,
    /// From a point (the light at `origin`), depth the distance from it.
    pub perspective: bool,
}

/// The nearest a point or spot light may be, in bounding radii, for one perspective map (its
/// half-angle then 76°): nearer, the light is about inside the object's bounds, and the object
/// gets a cube of six perspective maps about the light ([`MapFrame::frames_towards`]). Just
/// outside them one map still serves: a skin ball's single scattering under a point light 1.1
/// radii away is 0.12 off rays from the front and from behind, where an orthographic map was
/// 1.6 and 2.5·10³ off (`orthographic_maps_miss_a_near_lights_own_rays`).
pub const PERSPECTIVE_NEAREST: f32 = 1.05;

/// A cube face's half-width (the tangent of its half-angle): a little past 45°, so that a
/// point at a face's edge finds the four texels about it in that face (at 256², 2.6 texels
/// past the edge).
pub const CUBE_FACE_WIDTH: f32 = 1.02;

/// The cube face (+x, −x, +y, −y, +z, −z) that `local` (from the light) points into: its
/// largest axis (`cube_face` in boundary.wgsl, which the injection's own cube maps share, is
/// its twin).
pub fn cube_face(local: Vec3) -> usize {
    let a = local.abs();
    if a.x >= a.y && a.x >= a.z {
        if local.x >= 0.0 { 0 } else { 1 }
    } else if a.y >= a.z {
        if local.y >= 0.0 { 2 } else { 3 }
    } else if local.z >= 0.0 {
        4
    } else {
        5
    }
}

impl MapFrame {
    /// The frame of a map of the object in the sphere `centre`, `radius` (with 2 % to spare)
    /// for `light` (`None` for a light on the centre, or a non-finite or zero sphere).
    pub fn towards(light: &PatchLight, centre: Vec3, radius: f32) -> Option<Self> {
        let travel = light.travel_towards(centre)?;
        let from = match *light {
            PatchLight::Directional { .. } => None,
            PatchLight::Point { position, .. } | PatchLight::Spot { position, .. } => Some(position),
        };
        match from.map(|p| p.distance(centre)).filter(|&d| d > PERSPECTIVE_NEAREST * radius) {
            Some(distance) => {
                let sine = radius * 1.02 / distance;
                Self::new(from?, sine / (1.0 - sine * sine).max(1e-6).sqrt(), travel, true)
            }
            None => Self::new(centre, radius * 1.02, travel, false),
        }
    }

    /// The frames of the maps an object in the sphere `centre`, `radius` gets for `light`:
    /// [`towards`](Self::towards)'s one, or for a point or spot light within
    /// [`PERSPECTIVE_NEAREST`] bounding radii of the centre (about inside the object's bounds)
    /// a cube of six perspective faces about it, +x, −x, +y, −y, +z, −z ([`cube_face`]). One
    /// map cannot hold what lies round such a light on every side: the torus's skin with a
    /// point light in its hole scored 0.325 with the orthographic map it had
    /// (`docs/translucent.md`, "A light inside an object's bounds").
    pub fn frames_towards(light: &PatchLight, centre: Vec3, radius: f32) -> Vec<Self> {
        if let PatchLight::Point { position, .. } | PatchLight::Spot { position, .. } = *light
            && (radius > 0.0 && radius.is_finite() && centre.is_finite())
            && position.distance(centre) <= PERSPECTIVE_NEAREST * radius
        {
            return Self::cube_faces(position);
        }
        Self::towards(light, centre, radius).into_iter().collect()
    }

    /// The six faces of a cube of maps about `light_position` (none if it is not finite).
    pub fn cube_faces(light_position: Vec3) -> Vec<Self> {
        const AXES: [Vec3; 6] = [Vec3::X, Vec3::NEG_X, Vec3::Y, Vec3::NEG_Y, Vec3::Z, Vec3::NEG_Z];
        AXES.iter().filter_map(|&axis| Self::new(light_position, CUBE_FACE_WIDTH, axis, true)).collect()
    }

    /// [`frames_towards`](Self::frames_towards), the one map of an object (not a cube's
    /// faces) fitted to the object's own extent across the light's travel
    /// ([`fitted_to`](Self::fitted_to)).
    pub fn frames_fitted(light: &PatchLight, centre: Vec3, radius: f32, fit: &MapFit) -> Vec<Self> {
        let mut frames = Self::frames_towards(light, centre, radius);
        if let [one] = frames.as_mut_slice() {
            *one = one.fitted_to(fit);
        }
        frames
    }

    /// This frame narrowed to what `fit`'s object covers of it, never wider: orthographic,
    /// the square about the object's extent across the light's travel (its centre moved
    /// into the middle of it, depth unchanged); in perspective, the half-angle about the same
    /// axis out to the object's widest point. Over a bounding sphere about the samples' mean
    /// the bunny's maps used 0.65 – 0.69 of their width: fitted, the same texels are 1.45 –
    /// 1.54× finer, and its skin lit from behind scored 0.1187 → 0.1140 (`docs/translucent.md`,
    /// "Each object's map fitted to its extent"). A ball's square is its sphere's.
    pub fn fitted_to(&self, fit: &MapFit) -> Self {
        if fit.points.is_empty() {
            return *self;
        }
        let mut fitted = *self;
        if self.perspective {
            let (mut widest, mut nearest) = (0.0f32, f32::INFINITY);
            for &p in &fit.points {
                let r = p - self.origin;
                let z = r.dot(self.travel);
                if !(z > 0.0) {
                    // A point beside or behind the light: the sphere's frame holds.
                    return *self;
                }
                widest = widest.max((r.dot(self.u) / z).abs()).max((r.dot(self.v) / z).abs());
                nearest = nearest.min(z);
            }
            fitted.width = ((widest + fit.margin / nearest) * 1.02).min(self.width);
        } else {
            let (mut low, mut high) = (Vec2::splat(f32::INFINITY), Vec2::splat(f32::NEG_INFINITY));
            for &p in &fit.points {
                let r = p - self.origin;
                let at = Vec2::new(r.dot(self.u), r.dot(self.v));
                (low, high) = (low.min(at), high.max(at));
            }
            let width = ((high - low).max_element() / 2.0 + fit.margin) * 1.02;
            if width < self.width {
                let middle = (low + high) / 2.0;
                fitted.origin += self.u * middle.x + self.v * middle.y;
                fitted.width = width;
            }
        }
        if fitted.width > 0.0 && fitted.width.is_finite() && fitted.origin.is_finite() { fitted } else { *self }
    }

    fn new(origin: Vec3, width: f32, travel: Vec3, perspective: bool) -> Option<Self> {
        let travel = travel.try_normalize()?;
        (width > 0.0 && width.is_finite() && origin.is_finite()).then(|| {
            let (u, v) = travel.any_orthonormal_pair();
            Self { origin, width, u, v, travel, perspective }
        })
    }

    /// `x`'s place in a map of `resolution` texels a side: texel coordinates (continuous,
    /// centres at `k + ½`) and depth (along the travel from the centre's plane, or from the
    /// light); off the map for a point behind a perspective map's light.
    pub fn place(&self, x: Vec3, resolution: u32) -> (Vec2, f32) {
        let r = x - self.origin;
        let texel = 2.0 * self.width / resolution as f32;
        if !self.perspective {
            return ((Vec2::new(r.dot(self.u), r.dot(self.v)) + self.width) / texel, r.dot(self.travel));
        }
        let z = r.dot(self.travel);
        if !(z > 0.0) {
            return (Vec2::splat(-1e9), f32::INFINITY);
        }
        ((Vec2::new(r.dot(self.u), r.dot(self.v)) / z + self.width) / texel, r.length())
    }

    /// The ray at texel coordinates `at`: where depth 0 lies and the unit way depth grows.
    pub fn ray(&self, at: Vec2, resolution: u32) -> (Vec3, Vec3) {
        let across = at * (2.0 * self.width / resolution as f32) - self.width;
        if self.perspective {
            (self.origin, (self.travel + self.u * across.x + self.v * across.y).normalize())
        } else {
            (self.origin + self.u * across.x + self.v * across.y, self.travel)
        }
    }

    /// The frame as the GPU takes it (`translucent_frame_of` in boundary.wgsl): (origin,
    /// width), (u, `object`), (v, 1 if perspective), (travel, 1 + `light`).
    pub fn to_vec4s(&self, object: u32, light: u32) -> [[f32; 4]; 4] {
        [
            self.origin.extend(self.width).to_array(),
            self.u.extend(object as f32).to_array(),
            self.v.extend(if self.perspective { 1.0 } else { 0.0 }).to_array(),
            self.travel.extend(1.0 + light as f32).to_array(),
        ]
    }
}

/// Where a light enters one translucent object and where it first leaves it again, along its
/// rays: a map over a sphere about the object ([`MapFrame`]).
#[derive(Clone, Debug)]
pub struct TranslucentShadowMap {
    resolution: u32,
    frame: MapFrame,
    /// Per texel the depth along its ray ([`MapFrame::place`]) where the light first enters
    /// the object, and where it first leaves it after that (`+∞` where no sample covers it).
    near: Vec<f32>,
    far: Vec<f32>,
    /// Per texel the light inside the object along its column ([`entry_light`]): the light's
    /// irradiance across its travel there times what gets in, and in `w` what the light's
    /// path along `travel` is scaled by for its refraction; `(1, 1, 1, 1)` until
    /// [`light_texels`](Self::light_texels) sets it (unit irradiance, index-matched).
    light: Vec<Vec4>,
}

impl TranslucentShadowMap {
    /// The orthographic map of `samples` (one object's) at `resolution`² over the sphere
    /// `centre`, `radius`, for a light travelling along `travel`; `None` for a zero or
    /// non-finite direction or radius, or a resolution outside 1 – [`MAX_RESOLUTION`].
    pub fn splat<'a>(
        samples: impl IntoIterator<Item = &'a PatchSample>,
        travel: Vec3,
        centre: Vec3,
        radius: f32,
        resolution: u32,
    ) -> Option<Self> {
        Self::splat_in(samples, MapFrame::new(centre, radius * 1.02, travel, false)?, resolution)
    }

    /// The map of `samples` in `frame` at `resolution`² (`None` for a resolution outside 1 –
    /// [`MAX_RESOLUTION`]).
    pub fn splat_in<'a>(samples: impl IntoIterator<Item = &'a PatchSample>, frame: MapFrame, resolution: u32) -> Option<Self> {
        if !(1..=MAX_RESOLUTION).contains(&resolution) {
            return None;
        }
        let res = resolution as usize;
        let mut map = Self {
            resolution,
            frame,
            near: vec![f32::INFINITY; res * res],
            far: vec![f32::INFINITY; res * res],
            light: vec![Vec4::ONE; res * res],
        };
        let samples: Vec<&PatchSample> = samples.into_iter().collect();
        // Two passes: the nearest surface the light enters by (samples facing it), then the
        // first it leaves by behind that (samples facing away, deeper than the entry): the
        // object's first stretch along each of the light's rays, so that air between two
        // parts (an ear before the head) is not taken for the inside.
        for entering in [true, false] {
            for s in samples.iter() {
                let (at, depth) = map.frame.place(s.position, resolution);
                let (_, towards) = map.frame.ray(at, resolution);
                if depth.is_finite() && (s.normal.dot(towards) < 0.0) == entering {
                    map.splat_one(s, at, depth, entering);
                }
            }
        }
        Some(map)
    }

    /// One sample's splat (its place `at`, `depth` in the map): into `near` (`entering`) or
    /// into `far` where deeper than `near`.
    fn splat_one(&mut self, s: &PatchSample, at: Vec2, depth: f32, entering: bool) {
        let res = self.resolution as usize;
        let cover = splat_cover(s);
        let reach = (cover / self.texel_width_at(depth)).min(MAX_SPLAT_TEXELS);
        let own = (at.x.floor() as i64, at.y.floor() as i64);
        let (lo, hi) = ((at - reach).floor(), (at + reach).floor());
        for ty in (lo.y as i64).max(0)..=(hi.y as i64).min(res as i64 - 1) {
            for tx in (lo.x as i64).max(0)..=(hi.x as i64).min(res as i64 - 1) {
                // Where this texel's ray meets the sample's plane.
                let (origin, towards) = self.frame.ray(Vec2::new(tx as f32 + 0.5, ty as f32 + 0.5), self.resolution);
                let facing = s.normal.dot(towards);
                let d = if facing.abs() < 1e-4 { depth } else { s.normal.dot(s.position - origin) / facing };
                let is_own = (tx, ty) == own;
                if !is_own && (origin + towards * d).distance(s.position) > cover {
                    continue;
                }
                // Its own texel always (no sample falls through the map), at its plane's depth
                // there too (the injection takes the sample's own depth, half a texel's slope
                // off).
                let k = ty as usize * res + tx as usize;
                if entering {
                    self.near[k] = self.near[k].min(d);
                } else if d > self.near[k] {
                    self.far[k] = self.far[k].min(d);
                }
            }
        }
    }

    /// A texel's width (world units) at `depth`.
    fn texel_width_at(&self, depth: f32) -> f32 {
        let texel = 2.0 * self.frame.width / self.resolution as f32;
        if self.frame.perspective { texel * depth } else { texel }
    }

    /// The texel `(x, y)`'s entry and exit depths (clamped to the map's edge).
    fn depths(&self, x: i64, y: i64) -> (f32, f32) {
        let r = self.resolution as i64;
        let k = (y.clamp(0, r - 1) * r + x.clamp(0, r - 1)) as usize;
        (self.near[k], self.far[k])
    }

    /// The length of the light's path inside the object on its way to `x`: its depth below
    /// where the light enters the object there; `None` before that entry or beyond where the
    /// light first leaves it again (by more than a texel either way), or off the object. The
    /// depths are taken bilinearly where all four texels about `x`
    /// are covered, else from its own texel; where it leaves, from its own texel.
    pub fn path_inside(&self, x: Vec3) -> Option<f32> {
        self.lit_path_inside(x).map(|(path, _)| path)
    }

    /// [`path_inside`](Self::path_inside) and the light of `x`'s own texel.
    pub fn lit_path_inside(&self, x: Vec3) -> Option<(f32, Vec4)> {
        self.lit_path_inside_with(x, 0.0).map(|(path, light)| (path.max(0.0), light))
    }

    /// [`lit_path_inside`](Self::lit_path_inside), `x` taken as inside up to `before_entry`
    /// texel widths in front of where the light enters, the path signed (negative in front).
    fn lit_path_inside_with(&self, x: Vec3, before_entry: f32) -> Option<(f32, Vec4)> {
        let (at, depth) = self.frame.place(x, self.resolution);
        if !depth.is_finite() {
            return None;
        }
        let f = at - 0.5;
        let (x0, y0) = (f.x.floor() as i64, f.y.floor() as i64);
        let (s, t) = (f.x - x0 as f32, f.y - y0 as f32);
        let corners = [self.depths(x0, y0).0, self.depths(x0 + 1, y0).0, self.depths(x0, y0 + 1).0, self.depths(x0 + 1, y0 + 1).0];
        let own = self.index(at.x.floor() as i64, at.y.floor() as i64);
        // A texel inside the object's outline that no sample covered: the nearest covered of
        // the four about `x`, so that the march does not stop in the object's middle.
        let own = if self.near[own].is_finite() {
            own
        } else {
            [(x0, y0), (x0 + 1, y0), (x0, y0 + 1), (x0 + 1, y0 + 1)]
                .into_iter()
                .map(|(a, b)| (self.index(a, b), Vec2::new(a as f32, b as f32) + 0.5))
                .filter(|&(k, _)| self.near[k].is_finite())
                .min_by(|a, b| a.1.distance_squared(at).total_cmp(&b.1.distance_squared(at)))
                .map_or(own, |(k, _)| k)
        };
        let (own_near, far) = (self.near[own], self.far[own]);
        let near = if corners.iter().all(|c| c.is_finite()) {
            (corners[0] * (1.0 - s) + corners[1] * s) * (1.0 - t) + (corners[2] * (1.0 - s) + corners[3] * s) * t
        } else {
            own_near
        };
        // A texel's width of slack past where the light leaves: the pixels marched from lie on
        // the surface the map's texels and planes only approach. In front of where it enters,
        // `before_entry` texels (`marched_single_scattering` takes none below a surface that
        // does not face the light, and any below one that does, with the tangent plane's path).
        let texel = self.texel_width_at(depth);
        (near.is_finite() && depth >= near - before_entry * texel && depth <= far + texel).then(|| {
            // From a point, the light spreads on inside as outside (index-matched): its
            // irradiance at the entry times (entry distance / distance)².
            let spread = if self.frame.perspective && depth > near { (near / depth).powi(2) } else { 1.0 };
            let light = self.light[own];
            (depth - near, (light.truncate() * spread).extend(light.w))
        })
    }

    /// The texel `(x, y)`'s index (clamped to the map's edge).
    fn index(&self, x: i64, y: i64) -> usize {
        let r = self.resolution as i64;
        (y.clamp(0, r - 1) * r + x.clamp(0, r - 1)) as usize
    }

    /// Where the light enters the object in texel `k`'s column, and the cosine it enters at
    /// there: the surface's normal from the entry points of the texels either side, in both
    /// directions (one-sided beside an uncovered texel; across the map between two), against
    /// the texel's ray. `None` where it does not enter. `translucent_light` in `inject.wgsl`
    /// is its twin.
    pub fn entry(&self, k: usize) -> Option<(Vec3, f32)> {
        let near = *self.near.get(k)?;
        if !near.is_finite() {
            return None;
        }
        let res = self.resolution as i64;
        let (x, y) = ((k as i64) % res, (k as i64) / res);
        let point = |sx: i64, sy: i64, depth: f32| {
            let (origin, towards) = self.frame.ray(Vec2::new(sx as f32 + 0.5, sy as f32 + 0.5), self.resolution);
            origin + towards * depth
        };
        let entry_at = |sx: i64, sy: i64| {
            ((0..res).contains(&sx) && (0..res).contains(&sy))
                .then(|| self.near[(sy * res + sx) as usize])
                .filter(|d| d.is_finite())
                .map(|d| point(sx, sy, d))
        };
        let (origin, towards) = self.frame.ray(Vec2::new(x as f32 + 0.5, y as f32 + 0.5), self.resolution);
        let here = origin + towards * near;
        let tangent = |dx: i64, dy: i64, across: Vec3| match (entry_at(x - dx, y - dy), entry_at(x + dx, y + dy)) {
            (Some(a), Some(b)) => b - a,
            (None, Some(b)) => b - here,
            (Some(a), None) => here - a,
            (None, None) => across,
        };
        let cos = tangent(1, 0, self.frame.u)
            .cross(tangent(0, 1, self.frame.v))
            .try_normalize()
            .map_or(1.0, |n| n.dot(towards).abs());
        Some((here, cos))
    }

    /// Sets each covered texel's light from where the light enters the object in its column
    /// and the cosine it enters at ([`entry`](Self::entry)).
    pub fn light_texels(&mut self, mut light: impl FnMut(Vec3, f32) -> Vec4) {
        for k in 0..self.near.len() {
            self.light[k] = match self.entry(k) {
                Some((point, cos)) => light(point, cos),
                None => Vec4::ZERO,
            };
        }
    }
}

/// The maps an object has of one light: one, or a cube's six faces about a light inside its
/// bounds ([`MapFrame::frames_towards`]).
#[derive(Clone, Debug)]
pub struct LightMaps {
    /// One map, or six in [`cube_face`]'s order.
    pub faces: Vec<TranslucentShadowMap>,
}

impl From<TranslucentShadowMap> for LightMaps {
    fn from(map: TranslucentShadowMap) -> Self {
        Self { faces: vec![map] }
    }
}

impl LightMaps {
    /// Under a surface that faces the light, the light's path inside per unit length marched
    /// from its point `x` along `into`: `μ/μ₀` under its tangent plane (`μ = −into·n`, `μ₀`
    /// the light's cosine on it, `n` the unit outward `normal`). Near where light enters at a
    /// grazing angle a texel's entry depth is off by its width over `tan θ₀` (0.17 mm texels
    /// on the bunny: up to a millimetre), where the tangent plane is exact at the surface and
    /// an upper bound below a convex one. `None` where the surface faces away or the map does
    /// not see `x` lit through the object's first stretch (beyond its first exit): light that
    /// crossed another part of the object first, an ear's shadow on the head.
    pub fn half_space_bound(&self, x: Vec3, normal: Vec3, into: Vec3) -> Option<f32> {
        let face = self.face_of(x)?;
        let travel = if face.frame.perspective { (x - face.frame.origin).try_normalize()? } else { face.frame.travel };
        let (mu0, mu) = (normal.dot(-travel), -into.dot(normal));
        (mu0 > 1e-3 && mu > 0.0 && face.lit_path_inside_with(x, f32::INFINITY).is_some()).then(|| mu / mu0)
    }

    /// [`TranslucentShadowMap::lit_path_inside`] in the map that sees `x`: the one, or the
    /// cube face `x` lies in from the light.
    pub fn lit_path_inside(&self, x: Vec3) -> Option<(f32, Vec4)> {
        self.lit_path_inside_with(x, 0.0).map(|(path, light)| (path.max(0.0), light))
    }

    /// [`TranslucentShadowMap::lit_path_inside_with`] in the map that sees `x`.
    fn lit_path_inside_with(&self, x: Vec3, before_entry: f32) -> Option<(f32, Vec4)> {
        self.face_of(x)?.lit_path_inside_with(x, before_entry)
    }

    /// The map that sees `x`: the one, or the cube face `x` lies in from the light.
    fn face_of(&self, x: Vec3) -> Option<&TranslucentShadowMap> {
        match self.faces.as_slice() {
            [one] => Some(one),
            faces @ [first, ..] if faces.len() == 6 => Some(&faces[cube_face(x - first.frame.origin)]),
            _ => None,
        }
    }
}

/// The least scale [`entry_light`] puts on the light's path inside (`μ₀/μ₀′` is 0.84 at
/// 45° into η = 1.3, 0.67 at 60°). The half-space's scale holds where the surface is flat
/// along the path; at a grazing entry on a curved object it would go to 0 and leave the light
/// unattenuated through the whole object. Measured on the skin ball at η = 1.3 (relative L1,
/// front / behind): no floor 0.049 / 0.141, 0.5 0.046 / 0.135, **0.7 0.044 / 0.122**, no scale
/// (1) 0.057 / 0.115; the table's own single scattering 0.056 / 0.120.
pub const PATH_SCALE_FLOOR: f32 = 0.7;

/// The light inside a medium of index `eta` along a column of the map where a light of
/// `irradiance` across its travel enters at cosine `cos_entry`: `E T(μ₀) μ₀/μ₀′` (the flux
/// that gets in, across the refracted beam), and in `w` the scale `μ₀/μ₀′` of the path along
/// the light's travel to the refracted one's, at least [`PATH_SCALE_FLOOR`] (so that a
/// half-space lit within 58° of its normal gives the law `α E T(μ₀) T(μ) / (4π η² (μ₀′ +
/// μ′))` exactly). Index-matched: `(E, 1)`. `entry_light` in `inject.wgsl` is its twin.
pub fn entry_light(irradiance: Vec3, cos_entry: f32, eta: f32) -> Vec4 {
    let mu0 = cos_entry.clamp(1e-3, 1.0);
    let eta = eta.clamp(1.0, 3.0);
    let inside = (1.0 - (1.0 - mu0 * mu0) / (eta * eta)).max(0.0).sqrt();
    let transmitted = 1.0 - super::diffusion::fresnel_reflectance(mu0 as f64, eta as f64) as f32;
    let scale = mu0 / inside.max(1e-3);
    (irradiance * transmitted * scale).extend(scale.max(PATH_SCALE_FLOOR))
}

/// The `k`-th of `depths` optical depths at the midpoint quantiles of `e^{−τ}`: the mean of
/// `f(τ_k)` over `k` is `∫ e^{−τ} f(τ) dτ` (within 2e-4 for `f = e^{−aτ}`, `a ≤ 3.3`, at 64).
pub fn optical_depth_quantile(k: u32, depths: u32) -> f32 {
    -(1.0 - (k as f32 + 0.5) / depths as f32).ln()
}

/// Single scattering inside a translucent object at `x`, along the pixel's ray (`into`, the
/// unit direction it travels into the object), lit by the light `map` is of:
/// `α/(4π) ∫ e^{−τ} E e^{−σt s ℓ(τ)} dτ` over the optical depth `τ` along the ray where it is
/// inside the object as `map` sees it, `ℓ` the light's path inside
/// ([`LightMaps::lit_path_inside`]; under a surface of unit outward `normal` that faces the
/// light, at most the tangent plane's, [`LightMaps::half_space_bound`]), `E` and `s` its
/// texel's light and path scale
/// (1 until [`TranslucentShadowMap::light_texels`]: unit irradiance, index-matched). `depths` depths a channel
/// ([`optical_depth_quantile`]); `alpha` the single-scattering albedo and `sigma_t` the extinction per world unit.
pub fn marched_single_scattering(
    map: &LightMaps,
    alpha: Vec3,
    sigma_t: Vec3,
    x: Vec3,
    normal: Vec3,
    into: Vec3,
    depths: u32,
) -> Vec3 {
    let into = into.normalize_or_zero();
    if depths == 0 || into == Vec3::ZERO {
        return Vec3::ZERO;
    }
    let bound = map.half_space_bound(x, normal, into);
    // Under a lit surface a point in front of the map's entry takes the tangent plane's path
    // (the entry of a texel at a grazing angle lies up to millimetres deep); elsewhere it is
    // outside: taken as inside, with the light unattenuated, it was a bright speck (a texel's
    // slack there: the bunny's skin lit from behind 0.1436 → 0.1514, `docs/translucent.md`).
    let before_entry = if bound.is_some() { f32::INFINITY } else { 0.0 };
    Vec3::from_array(std::array::from_fn(|c| {
        if !(sigma_t[c] > 0.0) {
            return 0.0;
        }
        let (mut sum, mut entered) = (0.0, false);
        for k in 0..depths {
            let t = optical_depth_quantile(k, depths) / sigma_t[c];
            // Once the ray has left the object, nothing further along it scatters: what lies
            // beyond may be air between two parts in one of the light's columns.
            match map.lit_path_inside_with(x + into * t, before_entry) {
                Some((path, light)) => {
                    // In front of the map's entry under a lit surface: the tangent plane's.
                    let path = match bound {
                        Some(per_length) if path < 0.0 => t * per_length,
                        Some(per_length) => path.min(t * per_length),
                        None => path.max(0.0),
                    };
                    sum += light[c] * (-sigma_t[c] * path * light.w).exp();
                    entered = true;
                }
                None if entered => break,
                None => {}
            }
        }
        alpha[c] / (4.0 * std::f32::consts::PI) * sum / depths as f32
    }))
}

/// What single scattering marched per pixel needs of a translucent object's medium.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MarchedMedium {
    /// Extinction per world unit per channel.
    pub sigma_t: Vec3,
    /// Single-scattering albedo per channel.
    pub alpha: Vec3,
    /// Index of refraction.
    pub eta: f32,
}

impl MarchedMedium {
    /// `medium` in a scene of `world_units_per_mm`.
    pub fn new(medium: &TranslucentMedium, world_units_per_mm: f32) -> Self {
        Self {
            sigma_t: (medium.absorption + medium.reduced_scattering) / world_units_per_mm,
            alpha: Vec3::from_array(medium.single_scattering_albedo().map(|a| a as f32)),
            eta: medium.index_of_refraction,
        }
    }

    /// A translucent surface's (`None` for an opaque one).
    pub fn of(surface: &PatchSurface) -> Option<Self> {
        match surface {
            PatchSurface::Translucent { medium, world_units_per_mm, .. } => Some(Self::new(medium, *world_units_per_mm)),
            PatchSurface::Opaque { .. } => None,
        }
    }
}

/// One translucent object's single scattering marched per pixel, as the plugin takes it: its
/// medium and one map a light (the CPU twin of the GPU's, `translucent_maps` in `inject.wgsl`
/// and `marched_single_scattering` in `marched.wgsl`).
#[derive(Clone, Debug)]
pub struct MarchedObject {
    /// The medium.
    pub medium: MarchedMedium,
    /// Each light's maps ([`MapFrame::frames_fitted`]; none for a directional light of no
    /// direction).
    pub maps: Vec<LightMaps>,
}

/// The sphere the plugin's maps of an object see: about its samples' mean, out to the
/// farthest (`None` without samples).
pub fn object_bounds(samples: &[PatchSample]) -> Option<(Vec3, f32)> {
    if samples.is_empty() {
        return None;
    }
    let centre = samples.iter().fold(Vec3::ZERO, |a, s| a + s.position) / samples.len() as f32;
    let radius = samples.iter().map(|s| s.position.distance(centre)).fold(0.0, f32::max);
    Some((centre, radius.max(1e-6)))
}

/// The most of an object's samples a [`MapFit`] keeps as they are; of more, the occupied
/// cells of a grid (a frame is fitted to them on every light change: 32 768 points take tens
/// of microseconds).
const MAX_FIT_POINTS: usize = 32_768;

/// Cells along the longest side of the grid a [`MapFit`] of more than [`MAX_FIT_POINTS`]
/// samples keeps (at most ~6 × 48² occupied over a closed surface).
const FIT_GRID_CELLS: f32 = 48.0;

/// What an object's maps are fitted to ([`MapFrame::fitted_to`]): its samples' positions (or,
/// of more than [`MAX_FIT_POINTS`], the centres of the grid cells holding them) and how far
/// past them its splats reach (the widest sample's splat, and a cell's half-diagonal where
/// cells stand in for the samples), so that a fitted map covers every texel a splat writes.
#[derive(Clone, Debug, Default)]
pub struct MapFit {
    points: Vec<Vec3>,
    margin: f32,
}

impl MapFit {
    /// The fit of one object's `samples` (their non-finite positions left out).
    pub fn of(samples: &[PatchSample]) -> Self {
        let splat = samples
            .iter()
            .map(splat_cover)
            .filter(|r| r.is_finite())
            .fold(0.0, f32::max);
        let positions = samples.iter().map(|s| s.position).filter(|p| p.is_finite());
        if samples.len() <= MAX_FIT_POINTS {
            return Self { points: positions.collect(), margin: splat };
        }
        let (low, high) = positions
            .clone()
            .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(low, high), p| (low.min(p), high.max(p)));
        let cell = (high - low).max_element() / FIT_GRID_CELLS;
        if !(cell > 0.0 && cell.is_finite()) {
            return Self { points: positions.take(1).collect(), margin: splat };
        }
        let mut cells: Vec<IVec3> = positions.map(|p| ((p - low) / cell).floor().as_ivec3()).collect();
        cells.sort_unstable_by_key(|c| (c.x, c.y, c.z));
        cells.dedup();
        Self {
            points: cells.into_iter().map(|c| low + (c.as_vec3() + 0.5) * cell).collect(),
            margin: splat + cell * 3f32.sqrt() / 2.0,
        }
    }

    /// The points a frame is fitted to.
    pub fn points(&self) -> &[Vec3] {
        &self.points
    }
}

impl MarchedObject {
    /// The object of `samples` in `medium`, lit by `lights`: each light's maps
    /// ([`MapFrame::frames_fitted`]) at `resolution`, each texel's light that light's
    /// irradiance where it enters the object times `visible(entry point, light)`
    /// ([`entry_light`]).
    pub fn new(
        samples: &[PatchSample],
        medium: MarchedMedium,
        lights: &[PatchLight],
        resolution: u32,
        visible: impl Fn(Vec3, &PatchLight) -> f32,
    ) -> Self {
        let eta = medium.eta;
        let fit = MapFit::of(samples);
        let maps = object_bounds(samples)
            .map(|(centre, radius)| {
                lights
                    .iter()
                    .filter_map(|light| {
                        let faces: Vec<TranslucentShadowMap> = MapFrame::frames_fitted(light, centre, radius, &fit)
                            .into_iter()
                            .filter_map(|frame| {
                                let mut map = TranslucentShadowMap::splat_in(samples, frame, resolution)?;
                                map.light_texels(|entry, cos| {
                                    entry_light(light.irradiance_across(entry) * visible(entry, light), cos, eta)
                                });
                                Some(map)
                            })
                            .collect();
                        (!faces.is_empty()).then_some(LightMaps { faces })
                    })
                    .collect()
            })
            .unwrap_or_default();
        Self { medium, maps }
    }

    /// The single-scattered radiance leaving the object at `x` (unit normal `n`) towards the
    /// unit `towards`: the view ray refracted in, marched against each light's map at
    /// [`PLUGIN_DEPTHS`] depths a channel, out through the boundary (`T(μ)/η²`).
    pub fn radiance(&self, x: Vec3, n: Vec3, towards: Vec3) -> Vec3 {
        let mu = n.dot(towards);
        if !(mu > 0.0) {
            return Vec3::ZERO;
        }
        let MarchedMedium { sigma_t, alpha, eta } = self.medium;
        let eta = eta.clamp(1.0, 3.0);
        let inside = (1.0 - (1.0 - mu * mu) / (eta * eta)).max(0.0).sqrt();
        // Snell's law: the ray's part along the surface shrinks by η.
        let into = (-towards + n * mu) / eta - n * inside;
        let exit = (1.0 - super::diffusion::fresnel_reflectance(mu as f64, eta as f64) as f32) / (eta * eta);
        self.maps
            .iter()
            .map(|map| marched_single_scattering(map, alpha, sigma_t, x, n, into, PLUGIN_DEPTHS))
            .sum::<Vec3>()
            * exit
    }
}
