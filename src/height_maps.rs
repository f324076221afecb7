//! Deterministic height-map generators (values in `[0, 1]`, 1 = highest), usable from code and
//! as [`Image`]s.

use bevy::{
    asset::RenderAssetUsages,
    image::Image,
    render::render_resource::{Extent3d, TextureDimension, TextureFormat},
};

/// A generated height map: `width × height` values in `[0, 1]`, row-major, row 0 at `v = 0`.
#[derive(Clone, Debug, PartialEq)]
pub struct HeightMap {
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// Heights in `[0, 1]`.
    pub values: Vec<f32>,
}

impl HeightMap {
    /// Samples `f(u, v)` at texel centres, `u, v ∈ (0, 1)`.
    pub fn from_fn(width: u32, height: u32, f: impl Fn(f32, f32) -> f32) -> Self {
        let mut values = Vec::with_capacity((width * height) as usize);
        for y in 0..height {
            for x in 0..width {
                let u = (x as f32 + 0.5) / width as f32;
                let v = (y as f32 + 0.5) / height as f32;
                values.push(f(u, v).clamp(0.0, 1.0));
            }
        }
        Self {
            width,
            height,
            values,
        }
    }

    /// Running bond bricks: `rows` courses of bricks twice as wide as tall, mortar grooves of
    /// relative width `mortar`, bevelled brick edges.
    pub fn bricks(size: u32, rows: u32, mortar: f32) -> Self {
        let rows = rows.max(1) as f32;
        Self::from_fn(size, size, |u, v| {
            let row = (v * rows).floor();
            let fv = v * rows - row;
            let shift = if row as i32 % 2 == 0 { 0.0 } else { 0.5 };
            let fu = (u * rows * 0.5 + shift).fract();
            // Distance to the nearest brick edge, in brick heights.
            let edge = fv.min(1.0 - fv).min(2.0 * fu.min(1.0 - fu));
            smoothstep(mortar * 0.5, mortar * 0.5 + 0.08, edge)
        })
    }

    /// A grid of `n × n` round rivets (spherical caps) on a flat plate.
    pub fn rivets(size: u32, n: u32, radius: f32) -> Self {
        let n = n.max(1) as f32;
        Self::from_fn(size, size, |u, v| {
            let (cu, cv) = ((u * n).fract() - 0.5, (v * n).fract() - 0.5);
            let r = (cu * cu + cv * cv).sqrt() / radius.max(1e-3);
            if r < 1.0 { (1.0 - r * r).sqrt() } else { 0.0 }
        })
    }

    /// Separable sinusoid `(0.5 + 0.5 sin 2πfu)(0.5 + 0.5 sin 2πfv)`-like egg crate with `periods`
    /// periods across the map.
    pub fn sine(size: u32, periods: u32) -> Self {
        let f = periods.max(1) as f32 * std::f32::consts::TAU;
        Self::from_fn(size, size, |u, v| {
            0.25 * ((f * u).sin() + (f * v).sin()) + 0.5
        })
    }

    /// Plain-weave pattern: over-under threads, `threads` per side.
    pub fn weave(size: u32, threads: u32) -> Self {
        let n = threads.max(1) as f32;
        Self::from_fn(size, size, |u, v| {
            let (cu, cv) = (u * n, v * n);
            let (iu, iv) = (cu.floor() as i32, cv.floor() as i32);
            let (fu, fv) = (cu.fract(), cv.fract());
            let warp_on_top = (iu + iv) % 2 == 0;
            let across = |f: f32| (std::f32::consts::PI * f).sin();
            let along = |f: f32| 0.5 + 0.5 * (std::f32::consts::TAU * (f - 0.25)).sin();
            let warp = across(fu)
                * if warp_on_top {
                    along(fv * 0.5 + 0.25)
                } else {
                    0.6
                };
            let weft = across(fv)
                * if warp_on_top {
                    0.6
                } else {
                    along(fu * 0.5 + 0.25)
                };
            warp.max(weft)
        })
    }

    /// Fractal value noise ("stone"), tileable, `octaves` octaves from `base` cells per side.
    pub fn noise(size: u32, base: u32, octaves: u32, seed: u32) -> Self {
        Self::from_fn(size, size, |u, v| {
            let (mut sum, mut amp, mut norm, mut cells) = (0.0, 1.0, 0.0, base.max(1));
            for o in 0..octaves.max(1) {
                sum += amp * value_noise(u, v, cells, seed.wrapping_add(o * 7919));
                norm += amp;
                amp *= 0.5;
                cells *= 2;
            }
            sum / norm
        })
    }

    /// A single cone with its tip at the centre, height 1 there and 0 at `radius` (in `uv`).
    pub fn cone(size: u32, radius: f32) -> Self {
        Self::from_fn(size, size, |u, v| {
            1.0 - ((u - 0.5).powi(2) + (v - 0.5).powi(2)).sqrt() / radius
        })
    }

    /// The map as a 16-bit grey [`Image`] (`R16Unorm`), as a PNG height map would load.
    pub fn to_image(&self) -> Image {
        let data: Vec<u8> = self
            .values
            .iter()
            .flat_map(|v| ((v * 65535.0).round() as u16).to_le_bytes())
            .collect();
        Image::new(
            Extent3d {
                width: self.width,
                height: self.height,
                depth_or_array_layers: 1,
            },
            TextureDimension::D2,
            data,
            TextureFormat::R16Unorm,
            RenderAssetUsages::default(),
        )
    }

    /// The map as real geometry, for methods that only see the depth buffer (Bevy's SSAO in
    /// the comparisons): the 2 × 2 plane of `Plane3d` (XZ, normal +Y) as a grid of `n`² vertices,
    /// each lifted by `k · dis` at its UV (nearest texel), with smooth normals.
    pub fn displaced_plane(&self, k: f32, n: u32) -> bevy::mesh::Mesh {
        use bevy::{
            math::primitives::Plane3d,
            mesh::{Mesh, MeshBuilder, Meshable, VertexAttributeValues},
        };
        let mut mesh = Plane3d::default()
            .mesh()
            .size(2.0, 2.0)
            .subdivisions(n.max(2) - 1)
            .build();
        let Some(VertexAttributeValues::Float32x2(uvs)) =
            mesh.attribute(Mesh::ATTRIBUTE_UV_0).cloned()
        else {
            unreachable!("a plane has UVs")
        };
        if let Some(VertexAttributeValues::Float32x3(positions)) =
            mesh.attribute_mut(Mesh::ATTRIBUTE_POSITION)
        {
            for (p, uv) in positions.iter_mut().zip(&uvs) {
                let x = ((uv[0] * self.width as f32) as u32).min(self.width - 1);
                let y = ((uv[1] * self.height as f32) as u32).min(self.height - 1);
                p[1] = k * self.values[(y * self.width + x) as usize];
            }
        }
        mesh.compute_smooth_normals();
        mesh
    }

    /// The map as an 8-bit grey [`Image`] (`R8Unorm`), e.g. to save as PNG.
    pub fn to_image_gray8(&self) -> Image {
        Image::new(
            Extent3d {
                width: self.width,
                height: self.height,
                depth_or_array_layers: 1,
            },
            TextureDimension::D2,
            self.values
                .iter()
                .map(|v| (v * 255.0).round() as u8)
                .collect(),
            TextureFormat::R8Unorm,
            RenderAssetUsages::default(),
        )
    }

    /// A generator by name: `bricks`, `rivets`, `weave`, `sine`, `stone` or `cone`, at `size`².
    pub fn by_name(name: &str, size: u32) -> Option<Self> {
        Some(match name {
            "bricks" => Self::bricks(size, 8, 0.12),
            "rivets" => Self::rivets(size, 6, 0.32),
            "weave" => Self::weave(size, 8),
            "sine" => Self::sine(size, 6),
            "stone" => Self::noise(size, 6, 5, 7),
            "cone" => Self::cone(size, 0.5),
            _ => return None,
        })
    }

    /// The names [`Self::by_name`] knows.
    pub const NAMES: [&'static str; 6] = ["bricks", "rivets", "weave", "sine", "stone", "cone"];
}

fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

fn hash(x: u32, y: u32, seed: u32) -> f32 {
    let mut h =
        x.wrapping_mul(0x8da6_b343) ^ y.wrapping_mul(0xd816_3841) ^ seed.wrapping_mul(0xcb1a_b31f);
    h ^= h >> 13;
    h = h.wrapping_mul(0x5bd1_e995);
    h ^= h >> 15;
    (h & 0x00ff_ffff) as f32 / 16_777_215.0
}

fn value_noise(u: f32, v: f32, cells: u32, seed: u32) -> f32 {
    let (x, y) = (u * cells as f32, v * cells as f32);
    let (ix, iy) = (x.floor() as u32, y.floor() as u32);
    let (fx, fy) = (x.fract(), y.fract());
    let s = |t: f32| t * t * (3.0 - 2.0 * t);
    let at = |a: u32, b: u32| hash(a % cells, b % cells, seed);
    let top = at(ix, iy) + (at(ix + 1, iy) - at(ix, iy)) * s(fx);
    let bottom = at(ix, iy + 1) + (at(ix + 1, iy + 1) - at(ix, iy + 1)) * s(fx);
    top + (bottom - top) * s(fy)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn generators_are_deterministic_and_in_range() {
        for map in [
            HeightMap::bricks(64, 4, 0.1),
            HeightMap::rivets(64, 4, 0.3),
            HeightMap::sine(64, 4),
            HeightMap::weave(64, 4),
            HeightMap::noise(64, 4, 4, 1),
        ] {
            assert_eq!(map.values.len(), 64 * 64);
            assert!(map.values.iter().all(|v| (0.0..=1.0).contains(v)));
            let spread = map.values.iter().cloned().fold(f32::MIN, f32::max)
                - map.values.iter().cloned().fold(f32::MAX, f32::min);
            assert!(
                spread > 0.5,
                "a height map with relief, got spread {spread}"
            );
        }
        assert_eq!(HeightMap::noise(32, 4, 3, 9), HeightMap::noise(32, 4, 3, 9));
        assert_ne!(
            HeightMap::noise(32, 4, 3, 9),
            HeightMap::noise(32, 4, 3, 10)
        );
    }
}
