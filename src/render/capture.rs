//! Reading the working images back to the CPU: for tests, tools and the accuracy measurements
//! (the `oracle` feature). A capture stalls the frame while it waits for the GPU; leave it off
//! in a game.

use std::sync::{Arc, Mutex};

use bevy::{
    platform::collections::HashMap,
    prelude::*,
    render::{
        Extract,
        render_resource::*,
        renderer::{RenderContext, RenderDevice, ViewQuery},
        sync_world::RenderEntity,
    },
};

use super::{
    apex::ViewApexSets,
    bleeding::BLEEDING_FORMAT,
    gradient::{MHGM_FORMAT, ViewGradientMap},
    height::{
        BUMP_NORMAL_FORMAT, CORE_NORMAL_FORMAT, MHM_FORMAT, TEXTURE_VISIBILITY_FORMAT,
        ViewHeightTextures,
    },
    lighting::{MICRO_SHADOW_FORMAT, ViewMicroShadowTexture},
    occlusion::{OCCLUSION_FORMAT, ViewOcclusionTextures},
};
use crate::reference::{
    ASCENT_SHIFT, ApexSet, FLAG_VALID, GradientMap, ScreenHeightMap, ViewGeometry, unpack_apex_set,
};

/// Registers the captures' resources and systems: the copies after the passes whose images
/// they read, the mapping after the frame is submitted.
pub(super) fn build(app: &mut App) {
    use bevy::{
        core_pipeline::{
            Core3d,
            core_3d::main_opaque_pass_3d,
        },
        render::{Render, RenderApp, RenderSystems},
    };
    let captures = MesostructureCaptures::default();
    app.insert_resource(captures.clone());
    let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
        return;
    };
    render_app
        .insert_resource(captures)
        .init_resource::<PendingCaptures>()
        .add_systems(ExtractSchedule, extract_capture_requests)
        .add_systems(
            Render,
            map_captures
                .after(RenderSystems::Render)
                .before(RenderSystems::Cleanup),
        )
        .add_systems(
            Core3d,
            copy_capture
                .after(super::occlusion::occlusion_pass)
                .before(main_opaque_pass_3d),
        )
        .add_systems(
            Core3d,
            copy_lighting_capture
                .after(main_opaque_pass_3d)
                .before(super::bleeding::bleeding_pass),
        );
}

/// Put on a camera with [`Mesostructure`](crate::Mesostructure) to read its working images back
/// every frame into [`MesostructureCaptures`].
#[derive(Component, Clone, Copy, Debug, Default)]
pub struct MesostructureCapture;

/// The working images of one camera in one frame, read back from the GPU.
#[derive(Clone, Debug, Default)]
pub struct CapturedFrame {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// MHM: (height·k, NDC depth, object id, dis) per pixel, row-major.
    pub mhm: Vec<[f32; 4]>,
    /// Core normal n0 (world space) and the height pass's parameter set of the pixel.
    pub core_normal: Vec<[f32; 4]>,
    /// MHGM: (height as f32 bits, flags | ascent direction << [`crate::reference::ASCENT_SHIFT`]).
    pub mhgm: Vec<[u32; 2]>,
    /// Apex sets, `apex_stride` words per `apex_block`² block of pixels.
    pub apex_sets: Vec<u32>,
    /// Words per apex set in `apex_sets`.
    pub apex_stride: u32,
    /// Side of the pixel block that shares one apex set (1 at full working resolution).
    pub apex_block: u32,
    /// Apex-pass counters: apex searches (one per mesostructure pixel, or per block at a reduced
    /// working resolution), searches that hit the step bound,
    /// ascent steps in all.
    pub apex_stats: [u32; 3],
    /// Mesostructure ambient occlusion per pixel (1 = open; 1 where not computed).
    pub occlusion: Vec<f32>,
    /// Bump-mapped shading normal per pixel (world space; zero where the material has a
    /// normal map or there is no mesostructure).
    pub bump_normal: Vec<[f32; 4]>,
    /// Micro-shadow visibility per mesostructure pixel, the lowest over the lights (1 = lit);
    /// empty if the lighting pass did not run.
    pub micro_shadow: Vec<f32>,
    /// The first directional light's shadow-map visibility per mesostructure pixel (1 where it
    /// has no shadow map or there is none); empty if the lighting pass did not run.
    pub sun_shadow: Vec<f32>,
    /// The height pass's texture-space terms of the first directional light per pixel: its
    /// visibility and its one bounce relative to E0 (−1 where not computed).
    pub texture_terms: Vec<[f32; 2]>,
    /// The lit opaque image the bleeding gathers from (linear RGBA, exposure applied), before
    /// the bleeding is added; empty if its format cannot be read back.
    pub lit: Vec<[f32; 4]>,
    /// The bleeding radiance added to each pixel (λd · ρ / π · E); empty if bleeding is off.
    pub bleeding: Vec<[f32; 4]>,
    /// How pixels map back to the world in this frame.
    pub view: ViewGeometry,
}

impl Default for ViewGeometry {
    fn default() -> Self {
        Self {
            world_from_clip: Mat4::IDENTITY,
            viewport: Vec4::ZERO,
        }
    }
}

impl CapturedFrame {
    /// The MHM in the form the CPU oracle takes.
    pub fn screen_height_map(&self) -> ScreenHeightMap {
        ScreenHeightMap {
            width: self.width,
            height: self.height,
            heights: self.mhm.iter().map(|t| t[0]).collect(),
            objects: self.mhm.iter().map(|t| t[2] as u32).collect(),
            depths: self.mhm.iter().map(|t| t[1]).collect(),
        }
    }

    /// The MHGM in the form the CPU oracle produces.
    pub fn gradient_map(&self) -> GradientMap {
        GradientMap {
            width: self.width,
            height: self.height,
            ascent: self.mhgm.iter().map(|t| (t[1] >> ASCENT_SHIFT) as u8).collect(),
            flags: self.mhgm.iter().map(|t| t[1] & 0xffff).collect(),
        }
    }

    /// The apex set of pixel `(x, y)`: at a reduced working resolution, that of its block (as
    /// searched from the block's first mesostructure pixel).
    pub fn apex_set(&self, x: u32, y: u32) -> ApexSet {
        let i = (y * self.width + x) as usize;
        if self.mhgm[i][1] & FLAG_VALID == 0 {
            return ApexSet::default();
        }
        let (s, b) = (self.apex_stride as usize, self.apex_block.max(1));
        let block = ((y / b) * self.width.div_ceil(b) + x / b) as usize;
        let words = &self.apex_sets[block * s..(block + 1) * s];
        let corner = ((x / b * b) as i32, (y / b * b) as i32);
        unpack_apex_set(words, crate::reference::packed::origin(words[0], corner))
    }

    /// The normal each pixel faces with in the bleeding gather: its bump-mapped normal, or n0
    /// where it has none.
    pub fn facing_normals(&self) -> Vec<Vec3> {
        self.bump_normal
            .iter()
            .zip(&self.core_normal)
            .map(|(b, n)| {
                let b = Vec3::new(b[0], b[1], b[2]);
                if b.length_squared() > 0.5 {
                    b.normalize()
                } else {
                    Vec3::new(n[0], n[1], n[2])
                }
            })
            .collect()
    }

    /// The core normals n0 as vectors.
    pub fn normals(&self) -> Vec<Vec3> {
        self.core_normal
            .iter()
            .map(|n| Vec3::new(n[0], n[1], n[2]))
            .collect()
    }

    /// Number of pixels that carry a mesostructure surface.
    pub fn mesostructure_pixels(&self) -> usize {
        self.mhm.iter().filter(|t| t[2] != 0.0).count()
    }
}

/// The newest [`CapturedFrame`] of each camera with [`MesostructureCapture`].
#[derive(Resource, Clone, Default)]
pub struct MesostructureCaptures(Arc<Mutex<HashMap<Entity, CapturedFrame>>>);

impl MesostructureCaptures {
    /// Takes the newest capture of `camera`, if one arrived since the last call.
    pub fn take(&self, camera: Entity) -> Option<CapturedFrame> {
        self.0.lock().ok()?.remove(&camera)
    }
}

/// Render-world marker: read this view back; the main-world camera it belongs to.
#[derive(Component, Clone, Copy)]
pub struct ExtractedCapture(pub Entity);

/// Marks the render views whose camera asks for a capture.
pub fn extract_capture_requests(
    mut commands: Commands,
    cameras: Extract<
        Query<(RenderEntity, Entity, Has<MesostructureCapture>), With<crate::Mesostructure>>,
    >,
) {
    for (render_entity, entity, capture) in &cameras {
        let Ok(mut target) = commands.get_entity(render_entity) else {
            continue;
        };
        if capture {
            target.insert(ExtractedCapture(entity));
        } else {
            target.remove::<ExtractedCapture>();
        }
    }
}

struct Readback {
    buffer: Buffer,
    padded_row: u32,
    row: u32,
}

struct PendingCapture {
    camera: Entity,
    size: UVec2,
    apex_stride: u32,
    apex_block: u32,
    view: ViewGeometry,
    readbacks: Vec<Readback>,
    micro_shadow: Option<Readback>,
    lit: Option<(Readback, TextureFormat)>,
    bleeding: Option<Readback>,
}

/// Copies submitted this frame, mapped after submission.
#[derive(Resource, Default)]
pub struct PendingCaptures(Vec<PendingCapture>);

fn copy_texture(
    ctx: &mut RenderContext,
    device: &RenderDevice,
    texture: &Texture,
    format: TextureFormat,
) -> Readback {
    let size = texture.size();
    let row = size.width * format.block_copy_size(None).unwrap();
    let padded_row = RenderDevice::align_copy_bytes_per_row(row as usize) as u32;
    let buffer = device.create_buffer(&BufferDescriptor {
        label: Some("mesostructure_capture"),
        size: padded_row as u64 * size.height as u64,
        usage: BufferUsages::MAP_READ | BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    ctx.command_encoder().copy_texture_to_buffer(
        texture.as_image_copy(),
        TexelCopyBufferInfo {
            buffer: &buffer,
            layout: TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(padded_row),
                rows_per_image: None,
            },
        },
        size,
    );
    Readback {
        buffer,
        padded_row,
        row,
    }
}

fn copy_buffer(ctx: &mut RenderContext, device: &RenderDevice, source: &Buffer) -> Readback {
    let buffer = device.create_buffer(&BufferDescriptor {
        label: Some("mesostructure_capture"),
        size: source.size(),
        usage: BufferUsages::MAP_READ | BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    ctx.command_encoder()
        .copy_buffer_to_buffer(source, 0, &buffer, 0, source.size());
    Readback {
        buffer,
        padded_row: source.size() as u32,
        row: source.size() as u32,
    }
}

/// Core3d system after the apex pass: copies the working images into mappable buffers.
/// Views without a mesostructure surface this frame are not captured (their images are stale).
pub fn copy_capture(
    view: ViewQuery<(
        (&ViewHeightTextures, &ViewGradientMap, &ViewApexSets, &ViewOcclusionTextures),
        &ExtractedCapture,
        &bevy::render::view::ExtractedView,
        &crate::render::view_settings::ExtractedMesostructure,
    )>,
    phases: Res<bevy::render::render_phase::ViewSortedRenderPhases<super::height::HeightPhaseItem>>,
    device: Res<RenderDevice>,
    mut pending: ResMut<PendingCaptures>,
    mut ctx: RenderContext,
) {
    let ((height, mhgm, apex, occlusion), capture, extracted_view, settings) = view.into_inner();
    if !settings.0.needs_gradient_map() || !super::view_has_mesostructure(&phases, extracted_view) {
        return;
    }
    let readbacks = vec![
        copy_texture(&mut ctx, &device, &height.mhm.texture, MHM_FORMAT),
        copy_texture(&mut ctx, &device, &height.core_normal.texture, CORE_NORMAL_FORMAT),
        copy_texture(&mut ctx, &device, &mhgm.0.texture, MHGM_FORMAT),
        copy_buffer(&mut ctx, &device, &apex.sets),
        copy_buffer(&mut ctx, &device, &apex.stats),
        copy_texture(&mut ctx, &device, &occlusion.occlusion.texture, OCCLUSION_FORMAT),
        copy_texture(&mut ctx, &device, &height.bump_normal.texture, BUMP_NORMAL_FORMAT),
        copy_texture(
            &mut ctx,
            &device,
            &height.texture_visibility.texture,
            TEXTURE_VISIBILITY_FORMAT,
        ),
    ];
    let world_from_clip =
        extracted_view.world_from_view.to_matrix() * extracted_view.clip_from_view.inverse();
    pending.0.push(PendingCapture {
        camera: capture.0,
        size: height.size,
        apex_stride: apex.stride,
        apex_block: apex.block,
        view: ViewGeometry {
            world_from_clip,
            viewport: extracted_view.viewport.as_vec4(),
        },
        readbacks,
        micro_shadow: None,
        lit: None,
        bleeding: None,
    });
}

/// Core3d system after Bevy's opaque pass: copies the micro-shadow visibility and the lit
/// opaque image of views whose working images were captured this frame.
pub fn copy_lighting_capture(
    view: ViewQuery<(
        &ViewMicroShadowTexture,
        &ExtractedCapture,
        &bevy::render::view::ViewTarget,
    )>,
    device: Res<RenderDevice>,
    mut pending: ResMut<PendingCaptures>,
    mut ctx: RenderContext,
) {
    let (micro_shadow, capture, target) = view.into_inner();
    let Some(entry) = pending.0.iter_mut().rev().find(|p| p.camera == capture.0) else {
        return;
    };
    if entry.micro_shadow.is_some() {
        return;
    }
    entry.micro_shadow = Some(copy_texture(
        &mut ctx,
        &device,
        &micro_shadow.0.texture,
        MICRO_SHADOW_FORMAT,
    ));
    let format = target.main_texture_format();
    if matches!(
        format,
        TextureFormat::Rgba16Float | TextureFormat::Rgba8UnormSrgb | TextureFormat::Rgba8Unorm
    ) {
        entry.lit = Some((
            copy_texture(&mut ctx, &device, target.main_texture(), format),
            format,
        ));
    }
}

/// The bleeding pass's captures: the captured views and the copies pending this frame.
pub(crate) type BleedingCaptures<'w, 's> =
    (Query<'w, 's, &'static ExtractedCapture>, ResMut<'w, PendingCaptures>);

/// After the bleeding gather (called by the bleeding pass, the only place that knows the
/// gather ran this frame): copies the bleeding of a captured view.
pub(crate) fn copy_bleeding(
    ctx: &mut RenderContext,
    captures: &mut BleedingCaptures,
    view: Entity,
    bleeding: &bevy::render::texture::CachedTexture,
) {
    let (captured, pending) = captures;
    let Ok(capture) = captured.get(view) else {
        return;
    };
    if let Some(entry) = pending.0.iter_mut().rev().find(|p| p.camera == capture.0) {
        let device = ctx.render_device().clone();
        entry.bleeding = Some(copy_texture(ctx, &device, &bleeding.texture, BLEEDING_FORMAT));
    }
}

fn read(device: &RenderDevice, r: &Readback, rows: u32) -> Vec<u8> {
    let slice = r.buffer.slice(..);
    slice.map_async(MapMode::Read, |result| {
        if let Err(err) = result {
            error!("bevy_mesostructure: capture readback failed: {err}");
        }
    });
    let _ = device.poll(PollType::wait_indefinitely());
    let data = slice.get_mapped_range();
    let mut out = Vec::with_capacity((r.row * rows) as usize);
    for y in 0..rows as usize {
        let start = y * r.padded_row as usize;
        out.extend_from_slice(&data[start..start + r.row as usize]);
    }
    drop(data);
    r.buffer.unmap();
    out
}

/// After the frame is submitted: waits for the copies and hands the results to the main world.
pub fn map_captures(
    mut pending: ResMut<PendingCaptures>,
    device: Res<RenderDevice>,
    captures: Res<MesostructureCaptures>,
) {
    for PendingCapture {
        camera,
        size,
        apex_stride,
        apex_block,
        view,
        readbacks,
        micro_shadow,
        lit,
        bleeding,
    } in pending.0.drain(..)
    {
        let half4 = |bytes: Vec<u8>| -> Vec<[f32; 4]> {
            let halves: Vec<u16> = bytemuck::cast_slice(&bytes).to_vec();
            halves
                .chunks_exact(4)
                .map(|c| std::array::from_fn(|i| crate::height_map_import::half_to_f32(c[i])))
                .collect()
        };
        let lit = lit.map_or_else(Vec::new, |(r, format)| {
            let bytes = read(&device, &r, size.y);
            match format {
                TextureFormat::Rgba16Float => half4(bytes),
                _ => bytes
                    .chunks_exact(4)
                    .map(|c| {
                        std::array::from_fn(|i| {
                            let v = c[i] as f32 / 255.0;
                            if i < 3 && format == TextureFormat::Rgba8UnormSrgb {
                                srgb_to_linear(v)
                            } else {
                                v
                            }
                        })
                    })
                    .collect(),
            }
        });
        let floats = |bytes: Vec<u8>| -> Vec<[f32; 4]> { bytemuck::cast_slice(&bytes).to_vec() };
        // (micro-shadow visibility, the first directional light's shadow-map visibility)
        let micro_shadows: Vec<[f32; 2]> = micro_shadow.map_or_else(Vec::new, |r| {
            bytemuck::cast_slice(&read(&device, &r, size.y)).to_vec()
        });
        let stats: Vec<u32> = bytemuck::cast_slice(&read(&device, &readbacks[4], 1)).to_vec();
        let frame = CapturedFrame {
            width: size.x,
            height: size.y,
            mhm: floats(read(&device, &readbacks[0], size.y)),
            core_normal: floats(read(&device, &readbacks[1], size.y)),
            mhgm: bytemuck::cast_slice(&read(&device, &readbacks[2], size.y)).to_vec(),
            apex_sets: bytemuck::cast_slice(&read(&device, &readbacks[3], 1)).to_vec(),
            apex_stride,
            apex_block,
            apex_stats: [stats[0], stats[1], stats[2]],
            occlusion: bytemuck::cast_slice(&read(&device, &readbacks[5], size.y)).to_vec(),
            bump_normal: half4(read(&device, &readbacks[6], size.y)),
            micro_shadow: micro_shadows.iter().map(|v| v[0]).collect(),
            sun_shadow: micro_shadows.iter().map(|v| v[1]).collect(),
            texture_terms: bytemuck::cast_slice(&read(&device, &readbacks[7], size.y)).to_vec(),
            lit,
            bleeding: bleeding.map_or_else(Vec::new, |r| half4(read(&device, &r, size.y))),
            view,
        };
        if let Ok(mut map) = captures.0.lock() {
            map.insert(camera, frame);
        }
    }
}

fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}
