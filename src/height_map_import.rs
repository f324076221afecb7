//! Conversion of user height maps (any common format) into the `R32Float` mip chain that the
//! height pass samples with mip selection.

use bevy::{
    asset::RenderAssetUsages,
    image::Image,
    render::render_resource::{Extent3d, TextureDimension, TextureFormat},
};

/// Reads channel 0 of every texel of mip level 0 as `f32`: normalized formats map to `[0, 1]`,
/// float formats are taken as they are. sRGB-tagged data is read raw: a height map is data,
/// not colour. Returns the values and notes worth a one-time warning.
pub fn height_values(image: &Image) -> Result<(Vec<f32>, Vec<String>), String> {
    use TextureFormat as F;
    let format = image.texture_descriptor.format;
    let (w, h) = (image.width(), image.height());
    if w == 0 || h == 0 {
        return Err("the image is empty (0 texels)".into());
    }
    let data = image
        .data
        .as_ref()
        .ok_or("the image has no CPU-side data (RenderAssetUsages::RENDER_WORLD only?)")?;
    let n = (w * h) as usize;
    let mut notes = Vec::new();
    if format.is_srgb() {
        notes.push(format!(
            "{format:?} is sRGB-tagged; its values are used as linear heights (load height maps \
             with `is_srgb: false` to silence this)"
        ));
    }
    let unorm8 = |stride: usize, channel: usize| -> Vec<f32> {
        (0..n)
            .map(|i| data[i * stride + channel] as f32 / 255.0)
            .collect()
    };
    let u16_at = |o: usize| u16::from_le_bytes([data[o], data[o + 1]]);
    let unorm16 = |stride: usize| -> Vec<f32> {
        (0..n)
            .map(|i| u16_at(i * stride) as f32 / 65535.0)
            .collect()
    };
    let f16s =
        |stride: usize| -> Vec<f32> { (0..n).map(|i| half_to_f32(u16_at(i * stride))).collect() };
    let f32s = |stride: usize| -> Vec<f32> {
        (0..n)
            .map(|i| {
                let o = i * stride;
                f32::from_le_bytes([data[o], data[o + 1], data[o + 2], data[o + 3]])
            })
            .collect()
    };
    let bytes_per_texel = format
        .block_copy_size(None)
        .ok_or_else(|| format!("{format:?} is not a supported height-map format"))?
        as usize;
    if format.is_compressed() || data.len() < n * bytes_per_texel {
        return Err(format!("{format:?} is not a supported height-map format"));
    }
    let values = match format {
        F::R8Unorm | F::R8Uint | F::Rg8Unorm | F::Rgba8Unorm | F::Rgba8UnormSrgb => {
            unorm8(bytes_per_texel, 0)
        }
        F::Bgra8Unorm | F::Bgra8UnormSrgb => unorm8(4, 2),
        F::R16Unorm | F::R16Uint | F::Rg16Unorm | F::Rgba16Unorm | F::Rgba16Uint => {
            unorm16(bytes_per_texel)
        }
        F::R16Float | F::Rg16Float | F::Rgba16Float => f16s(bytes_per_texel),
        F::R32Float | F::Rg32Float | F::Rgba32Float => f32s(bytes_per_texel),
        other => return Err(format!("{other:?} is not a supported height-map format")),
    };
    let mut bad = 0;
    let values = values
        .into_iter()
        .map(|v| {
            if v.is_finite() {
                v
            } else {
                bad += 1;
                0.0
            }
        })
        .collect();
    if bad > 0 {
        notes.push(format!("{bad} texels are NaN or infinite; they read as 0"));
    }
    Ok((values, notes))
}

/// The height map as an `R32Float` image with a full box-filtered mip chain, so that the height
/// pass can choose the level that matches the pixel footprint (minification must not alias).
pub fn height_map_mip_chain(image: &Image) -> Result<(Image, Vec<String>), String> {
    let (values, notes) = height_values(image)?;
    Ok((mip_chain(values, image.width(), image.height()), notes))
}

/// The `R32Float` mip chain of level-0 heights `w × h`.
pub fn mip_chain(values: Vec<f32>, w: u32, h: u32) -> Image {
    let levels = 32 - w.max(h).leading_zeros();
    let mut data: Vec<u8> = bytemuck::cast_slice(&values).to_vec();
    let (mut level, mut lw, mut lh) = (values, w, h);
    for _ in 1..levels {
        let (next, nw, nh) = halve(&level, lw, lh);
        data.extend_from_slice(bytemuck::cast_slice(&next));
        (level, lw, lh) = (next, nw, nh);
    }
    let mut out = Image::new_uninit(
        Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        TextureFormat::R32Float,
        RenderAssetUsages::RENDER_WORLD,
    );
    out.texture_descriptor.mip_level_count = levels;
    out.data = Some(data);
    out
}

/// Azimuths of the texture-space horizon map: `i · 360° / 16`, in texel space (u, v). A
/// multiple of 4 (the map stores four a texel per block); 16 rather than 8, because the light's
/// horizon is interpolated between the two nearest, and at 45° apart that interpolation
/// stretched shadows sideways (docs/accuracy.md, "Unseen content").
pub const HORIZON_AZIMUTHS: usize = 16;
/// Distance bands of the horizon map: each keeps its own highest slope and where it is, so that
/// a curved core, which lowers far horizons more than near ones, can pick between them. One
/// band: two (out to 8 texels, then to 32) changed the unseen suite's micro-shadow recall by
/// +0.002 and precision by −0.003 at twice the memory (docs/accuracy.md).
pub const HORIZON_BANDS: usize = 1;
/// The outer limit of each band, in texels (the last one is [`HORIZON_RADIUS`]).
pub const HORIZON_BAND_LIMITS: [u32; HORIZON_BANDS] = [HORIZON_RADIUS];
/// Blocks of the horizon map's slope image: per band, its slopes four azimuths a block; then
/// the gradient. (The distances are a second image, [`HorizonMap::distance_image`], one byte
/// each: 18.9 MB for a 512² map in half floats, 14.7 MB so.)
pub const HORIZON_BLOCKS: usize = HORIZON_BANDS * (HORIZON_AZIMUTHS / 4) + 1;
/// Blocks of the horizon map's distance image: per band, four azimuths a block.
pub const HORIZON_DISTANCE_BLOCKS: usize = HORIZON_BANDS * (HORIZON_AZIMUTHS / 4);
/// Points per azimuth at which the texture-space bounce samples the surface between a texel
/// and its horizon (`texture_bounce` in `render/height/height.wgsl`, mirrored in
/// `reference::texture_space`): against the ray-traced truth on the photo-derived maps, 4
/// gave a relative error 0.17–0.39, 6 gave 0.13–0.29, 8 gave 0.12–0.25, every texel step
/// 0.11–0.24 (docs/accuracy.md).
pub const TEXTURE_BOUNCE_SAMPLES: u32 = 6;
/// The most light a pixel keeps, in percent, where the point test at a shadow edge finds it in
/// shadow (`point_light_visibility` in `render/height/height.wgsl`, mirrored in
/// `reference::texture_space`): the texels' mix shapes the edge's soft profile, and a
/// shadowed pixel stays below one half, lit ones at or above it, so that the point's decision
/// survives any threshold at one half.
pub const EDGE_SHADOWED_PERCENT: u32 = 49;
/// How far each horizon is searched, in texels of the horizon map's level: every texel out to
/// [`HORIZON_FINE_RADIUS`], then every 4th texel to twice that, every 8th to four times
/// ([`horizon_search_distances`]). The ray-traced truth sees occluders at any distance: at 32
/// texels, tall features further apart (rivets, sine crests 64 texels apart on 256² maps) were
/// missed, the AO too open by 0.15 at k 0.4 (docs/accuracy.md).
pub const HORIZON_RADIUS: u32 = 4 * HORIZON_FINE_RADIUS;
/// Out to this many texels each horizon is searched at every texel.
pub const HORIZON_FINE_RADIUS: u32 = 32;
// Each slope's distance is stored in texel steps, one byte each.
const _: () = assert!(HORIZON_RADIUS <= u8::MAX as u32);
/// The horizon map is built at the finest level of the mip chain at most this many texels wide
/// (and high): it serves minified surfaces, where finer detail is below a pixel anyway.
pub const HORIZON_MAX_SIZE: u32 = 512;

/// The texel steps at which a horizon is searched, out to `radius`: every one to
/// [`HORIZON_FINE_RADIUS`], every 4th to twice that, every 8th beyond — a far occluder subtends
/// less, and the search costs 48 samples instead of 128 (half as much again as the 32 texels
/// it searched before).
pub fn horizon_search_distances(radius: u32) -> impl Iterator<Item = u32> {
    (1..=radius).filter(|&d| {
        d <= HORIZON_FINE_RADIUS
            || (d <= 2 * HORIZON_FINE_RADIUS && d % 4 == 0)
            || d % 8 == 0
    })
}

/// The UV length of one texel step along horizon azimuth `i` on a `w × h` level.
pub fn horizon_step(i: usize, w: u32, h: u32) -> f32 {
    let [dx, dy] = horizon_direction(i);
    ((dx / w as f32).powi(2) + (dy / h as f32).powi(2)).sqrt()
}

/// The unit texel-space direction of horizon azimuth `i`.
pub fn horizon_direction(i: usize) -> [f32; 2] {
    let a = i as f32 * std::f32::consts::TAU / HORIZON_AZIMUTHS as f32;
    [a.cos(), a.sin()]
}

/// The tangent of the horizon's elevation above the core's tangent plane, from a horizon-map
/// `slope` reached at UV `distance`, on a surface of scale `k` whose UV unit spans `reach`
/// world units along the azimuth and whose core bends with normal curvature `curvature`
/// (1/world units, positive where convex) along it: `k · slope / reach − κ D / 2` with
/// `D = distance · reach` (the core falls `κ D² / 2` below its tangent plane at distance `D`).
/// The mirror of `horizon_tangent` in `render/height/height.wgsl`.
pub fn horizon_tangent(slope: f32, distance: f32, k: f32, reach: f32, curvature: f32) -> f32 {
    k * slope / reach - 0.5 * curvature * distance * reach
}

/// A texture-space horizon map of a height map (built once per map at load; in texture space,
/// so it stays valid on deforming meshes): per texel, for each azimuth the highest slope
/// `max_d (h(p + d) − h(p)) / |d|` towards it (heights in `[0, 1]` per UV unit of distance,
/// negative where the surface only falls away), and the height gradient `(∂h/∂u, ∂h/∂v)` per UV
/// unit. On a surface of scale `k` whose UV unit spans `L` world units along an azimuth, the
/// horizon elevation there is `atan(k · slope / L)`: one map serves every scale and every
/// mesh. With each slope the UV distance at which it is reached: on a curved core the surface
/// at world distance `D` lies `κ D² / 2` below the tangent plane (κ the core's normal curvature
/// along the azimuth), so the horizon's tangent drops by `κ D / 2` there (`horizon_tangent`).
#[derive(Clone, Debug)]
pub struct HorizonMap {
    /// Texels across.
    pub width: u32,
    /// Texels down.
    pub height: u32,
    /// Per texel, row-major, per distance band: the highest slope towards each azimuth.
    pub slopes: Vec<[[f32; HORIZON_AZIMUTHS]; HORIZON_BANDS]>,
    /// Per texel, per band: the texel steps along the azimuth (1 … [`HORIZON_RADIUS`]) at which
    /// each of those slopes is reached; times [`horizon_step`], the UV distance.
    pub distances: Vec<[[u8; HORIZON_AZIMUTHS]; HORIZON_BANDS]>,
    /// Per texel: `(∂h/∂u, ∂h/∂v)`.
    pub gradient: Vec<[f32; 2]>,
    /// The heights of the level the map is built at (the mip level of the GPU's height chain
    /// that is `width` texels wide), row-major: the texture-space bounce walks them.
    pub heights: Vec<f32>,
}

impl HorizonMap {
    /// Builds the map from level-0 heights (`w × h`, row-major), box-filtered down to at most
    /// [`HORIZON_MAX_SIZE`] texels a side first.
    pub fn new(values: &[f32], w: u32, h: u32) -> Self {
        let (mut level, mut lw, mut lh) = (values.to_vec(), w, h);
        while lw.max(lh) > HORIZON_MAX_SIZE {
            (level, lw, lh) = halve(&level, lw, lh);
        }
        let at = |x: i64, y: i64| {
            level[(y.rem_euclid(lh as i64) * lw as i64 + x.rem_euclid(lw as i64)) as usize]
        };
        let bilinear = |x: f32, y: f32| {
            let (x0, y0) = (x.floor(), y.floor());
            let (fx, fy) = (x - x0, y - y0);
            let (x0, y0) = (x0 as i64, y0 as i64);
            let top = at(x0, y0) * (1.0 - fx) + at(x0 + 1, y0) * fx;
            let bottom = at(x0, y0 + 1) * (1.0 - fx) + at(x0 + 1, y0 + 1) * fx;
            top * (1.0 - fy) + bottom * fy
        };
        let radius = HORIZON_RADIUS.min(lw.max(lh) / 2).max(1);
        let texel = |x: u32, y: u32| {
            let (fx, fy) = (x as f32, y as f32);
            let h0 = at(x as i64, y as i64);
            let mut slopes = [[0.0; HORIZON_AZIMUTHS]; HORIZON_BANDS];
            let mut distances = [[0u8; HORIZON_AZIMUTHS]; HORIZON_BANDS];
            for i in 0..HORIZON_AZIMUTHS {
                let [dx, dy] = horizon_direction(i);
                let step = horizon_step(i, lw, lh);
                let mut inner = 1;
                for band in 0..HORIZON_BANDS {
                    let outer = HORIZON_BAND_LIMITS[band].min(radius);
                    if inner > outer {
                        // A map too small for this band: the previous band's horizon.
                        slopes[band][i] = slopes[band - 1][i];
                        distances[band][i] = distances[band - 1][i];
                        continue;
                    }
                    let (mut best, mut at_distance) = (f32::MIN, inner);
                    for d in horizon_search_distances(outer).filter(|&d| d >= inner) {
                        let t = d as f32;
                        let slope = (bilinear(fx + t * dx, fy + t * dy) - h0) / (t * step);
                        if slope > best {
                            (best, at_distance) = (slope, d);
                        }
                    }
                    slopes[band][i] = best;
                    distances[band][i] = at_distance as u8;
                    inner = outer + 1;
                }
            }
            let gradient = [
                (at(x as i64 + 1, y as i64) - at(x as i64 - 1, y as i64)) * 0.5 * lw as f32,
                (at(x as i64, y as i64 + 1) - at(x as i64, y as i64 - 1)) * 0.5 * lh as f32,
            ];
            (slopes, distances, gradient)
        };
        // Rows on every core: a 512² map is ~70 M height samples.
        let rows: Vec<u32> = (0..lh).collect();
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
        let chunk = rows.len().div_ceil(threads).max(1);
        type Bands<T> = [[T; HORIZON_AZIMUTHS]; HORIZON_BANDS];
        type Texel = (Bands<f32>, Bands<u8>, [f32; 2]);
        let texels: Vec<Texel> = std::thread::scope(|scope| {
            let handles: Vec<_> = rows
                .chunks(chunk)
                .map(|part| {
                    scope.spawn(|| {
                        part.iter()
                            .flat_map(|&y| (0..lw).map(move |x| (x, y)))
                            .map(|(x, y)| texel(x, y))
                            .collect::<Vec<_>>()
                    })
                })
                .collect();
            handles
                .into_iter()
                .flat_map(|h| h.join().expect("a horizon-map thread panicked"))
                .collect()
        });
        Self {
            width: lw,
            height: lh,
            slopes: texels.iter().map(|t| t.0).collect(),
            distances: texels.iter().map(|t| t.1).collect(),
            gradient: texels.iter().map(|t| t.2).collect(),
            heights: level,
        }
    }

    /// The highest horizon tangent of azimuth `i` at texel `index` over the bands
    /// ([`horizon_tangent`] of each; exact where the core is flat, a lower bound where it is
    /// curved).
    pub fn tangent(&self, index: usize, i: usize, k: f32, reach: f32, curvature: f32) -> f32 {
        let step = horizon_step(i, self.width, self.height);
        (0..HORIZON_BANDS)
            .map(|b| {
                let distance = self.distances[index][b][i] as f32 * step;
                horizon_tangent(self.slopes[index][b][i], distance, k, reach, curvature)
            })
            .fold(f32::MIN, f32::max)
    }

    /// The slopes as an `Rgba16Float` image [`HORIZON_BLOCKS`] blocks wide: per band `b`, the
    /// slopes of azimuths `4j … 4j + 3` in block `b A/4 + j` (A = [`HORIZON_AZIMUTHS`]); the
    /// gradient (in `xy`) in the last block.
    pub fn to_image(&self) -> Image {
        let quarter = HORIZON_AZIMUTHS / 4;
        self.blocks_image(HORIZON_BLOCKS, TextureFormat::Rgba16Float, |data, i, block| {
            let v = if block + 1 < HORIZON_BLOCKS {
                let (band, j) = (block / quarter, block % quarter);
                let v = &self.slopes[i][band][4 * j..4 * j + 4];
                [v[0], v[1], v[2], v[3]]
            } else {
                [self.gradient[i][0], self.gradient[i][1], 0.0, 0.0]
            };
            for c in v {
                data.extend(half::f16::from_f32(c).to_le_bytes());
            }
        })
    }

    /// The distances as an `Rgba8Uint` image [`HORIZON_DISTANCE_BLOCKS`] blocks wide, laid out
    /// as the slopes: in texel steps along the azimuth (1 … [`HORIZON_RADIUS`]); the UV
    /// distance is that times the UV length of one step ([`horizon_step`]).
    pub fn distance_image(&self) -> Image {
        let quarter = HORIZON_AZIMUTHS / 4;
        self.blocks_image(HORIZON_DISTANCE_BLOCKS, TextureFormat::Rgba8Uint, |data, i, block| {
            let (band, j) = (block / quarter, block % quarter);
            data.extend_from_slice(&self.distances[i][band][4 * j..4 * j + 4]);
        })
    }

    /// An image `blocks` copies of the map wide, row by row: `texel(data, i, block)` appends
    /// texel `i`'s value in block `block`.
    fn blocks_image(
        &self,
        blocks: usize,
        format: TextureFormat,
        mut texel: impl FnMut(&mut Vec<u8>, usize, usize),
    ) -> Image {
        let (w, h) = (self.width, self.height);
        let bytes = format.block_copy_size(None).unwrap_or(0) as usize;
        let mut data = Vec::with_capacity(w as usize * blocks * h as usize * bytes);
        for y in 0..h {
            for block in 0..blocks {
                for x in 0..w {
                    texel(&mut data, (y * w + x) as usize, block);
                }
            }
        }
        Image::new(
            Extent3d {
                width: w * blocks as u32,
                height: h,
                depth_or_array_layers: 1,
            },
            TextureDimension::D2,
            data,
            format,
            RenderAssetUsages::RENDER_WORLD,
        )
    }
}

/// One box-filtered level down.
fn halve(level: &[f32], lw: u32, lh: u32) -> (Vec<f32>, u32, u32) {
    let (nw, nh) = ((lw / 2).max(1), (lh / 2).max(1));
    let mut next = Vec::with_capacity((nw * nh) as usize);
    for y in 0..nh {
        for x in 0..nw {
            let at = |dx: u32, dy: u32| {
                let sx = (2 * x + dx).min(lw - 1);
                let sy = (2 * y + dy).min(lh - 1);
                level[(sy * lw + sx) as usize]
            };
            next.push(0.25 * (at(0, 0) + at(1, 0) + at(0, 1) + at(1, 1)));
        }
    }
    (next, nw, nh)
}

/// IEEE 754 binary16 → f32.
pub(crate) fn half_to_f32(h: u16) -> f32 {
    let sign = if h & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exp = (h >> 10) & 0x1f;
    let frac = (h & 0x3ff) as f32;
    match exp {
        0 => sign * frac * 2f32.powi(-24),
        31 => {
            if frac == 0.0 {
                sign * f32::INFINITY
            } else {
                f32::NAN
            }
        }
        e => sign * (1.0 + frac / 1024.0) * 2f32.powi(e as i32 - 15),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(format: TextureFormat, w: u32, h: u32, data: Vec<u8>) -> Image {
        Image::new(
            Extent3d {
                width: w,
                height: h,
                depth_or_array_layers: 1,
            },
            TextureDimension::D2,
            data,
            format,
            RenderAssetUsages::default(),
        )
    }

    #[test]
    fn reads_gray_rgba_16_bit_and_float_formats() {
        let g8 = image(TextureFormat::R8Unorm, 2, 1, vec![0, 255]);
        assert_eq!(height_values(&g8).unwrap().0, vec![0.0, 1.0]);
        let rgba = image(TextureFormat::Rgba8UnormSrgb, 1, 1, vec![51, 0, 0, 255]);
        let (v, notes) = height_values(&rgba).unwrap();
        assert_eq!(v, vec![0.2]);
        assert_eq!(notes.len(), 1, "sRGB data is noted, not decoded");
        let g16 = image(
            TextureFormat::R16Unorm,
            1,
            1,
            65535u16.to_le_bytes().to_vec(),
        );
        assert_eq!(height_values(&g16).unwrap().0, vec![1.0]);
        let h16 = image(
            TextureFormat::R16Float,
            1,
            1,
            0x3800u16.to_le_bytes().to_vec(),
        );
        assert_eq!(height_values(&h16).unwrap().0, vec![0.5]);
        let f = image(
            TextureFormat::R32Float,
            2,
            1,
            bytemuck::cast_slice(&[0.25f32, f32::NAN]).to_vec(),
        );
        let (v, notes) = height_values(&f).unwrap();
        assert_eq!(v, vec![0.25, 0.0]);
        assert_eq!(notes.len(), 1);
        let bad = image(TextureFormat::Depth32Float, 1, 1, vec![0; 4]);
        assert!(height_values(&bad).is_err());
    }

    #[test]
    fn mip_chain_of_a_non_square_map() {
        let values: Vec<f32> = (0..8 * 2).map(|i| (i % 2) as f32).collect();
        let img = image(
            TextureFormat::R32Float,
            8,
            2,
            bytemuck::cast_slice(&values).to_vec(),
        );
        let (mips, _) = height_map_mip_chain(&img).unwrap();
        assert_eq!(mips.texture_descriptor.mip_level_count, 4); // 8×2, 4×1, 2×1, 1×1
        let data: &[f32] = bytemuck::cast_slice(mips.data.as_ref().unwrap());
        assert_eq!(data.len(), 16 + 4 + 2 + 1);
        assert!(
            data[16..].iter().all(|v| (v - 0.5).abs() < 1e-6),
            "box filter averages"
        );
    }

    #[test]
    fn horizon_images_lay_out_slopes_and_distances() {
        // Flat at 0 but for a wall of height 1 at x = 24 … 27 on a 64² map.
        let values: Vec<f32> = (0..64 * 64)
            .map(|i| if (24..28).contains(&(i % 64)) { 1.0 } else { 0.0 })
            .collect();
        let map = HorizonMap::new(&values, 64, 64);
        let (slopes, distances) = (map.to_image(), map.distance_image());
        assert_eq!(slopes.width(), 64 * HORIZON_BLOCKS as u32);
        assert_eq!(distances.width(), 64 * HORIZON_DISTANCE_BLOCKS as u32);
        // Texel (16, 7), azimuth 0 (block 0, channel 0): the wall 8 texel steps away.
        let d = distances.data.as_ref().unwrap();
        let row = 64 * HORIZON_DISTANCE_BLOCKS * 4;
        assert_eq!(d[7 * row + 16 * 4], 8);
        let s = slopes.data.as_ref().unwrap();
        let at = 7 * (64 * HORIZON_BLOCKS * 8) + 16 * 8;
        let slope = half_to_f32(u16::from_le_bytes([s[at], s[at + 1]]));
        assert!((slope - 64.0 / 8.0).abs() < 0.01, "slope {slope}");
    }
}
