//! Reading the working images back to the CPU: for tests, tools and the accuracy measurements
//! (the `oracle` feature). Leave it off in a game: it copies every working image every frame.
//!
//! The readback itself is Bevy's [`Readback`]: each captured camera owns one [`ShaderBuffer`]
//! (resized to what its view needs) and a reader entity with `Readback::buffer` on it. During
//! the frame the capture systems copy the working images into that buffer, each where its image
//! holds what the oracle compares (the MHM to the occlusion after the occlusion pass, the lit
//! image before the bleeding is added, the bleeding after its gather), behind a header that says
//! where each one lies and which frame it is; Bevy copies the buffer out after the frame and
//! hands it back in [`ReadbackComplete`], where it is cut up into a [`CapturedFrame`]. One
//! buffer, so the images of a capture always come from one frame.

use std::sync::{Arc, Mutex};

use bevy::{
    diagnostic::FrameCount,
    image::ToExtents,
    platform::collections::HashMap,
    prelude::*,
    render::{
        Extract,
        gpu_readback::{Readback, ReadbackComplete},
        render_asset::RenderAssets,
        render_resource::*,
        renderer::{RenderContext, RenderDevice, RenderQueue, ViewQuery},
        storage::{GpuShaderBuffer, ShaderBuffer},
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

/// Registers the captures' resources and systems: the readback buffers in the main world; in
/// the render world the copies after the passes whose images they read.
pub(super) fn build(app: &mut App) {
    use bevy::{
        core_pipeline::{Core3d, core_3d::main_opaque_pass_3d},
        render::RenderApp,
    };
    let captures = MesostructureCaptures::default();
    app.insert_resource(captures.clone())
        .add_systems(PostUpdate, sync_capture_buffers);
    let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
        return;
    };
    render_app
        .insert_resource(captures)
        .add_systems(ExtractSchedule, extract_capture_requests)
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
/// every frame into [`MesostructureCaptures`] (through Bevy's [`Readback`], a frame or more
/// later).
#[derive(Component, Clone, Copy, Debug, Default)]
pub struct MesostructureCapture;

/// The working images of one camera in one frame, read back from the GPU.
#[derive(Clone, Debug, Default)]
pub struct CapturedFrame {
    /// The [`FrameCount`] of the frame these images were rendered in (the value the main world
    /// holds after that frame's update): a capture with `frame > n` shows the world as it was
    /// after update `n`. Readbacks arrive a frame or more late, so compare with this rather than
    /// counting frames.
    pub frame: u32,
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
pub struct MesostructureCaptures(Arc<Mutex<CaptureState>>);

#[derive(Default)]
struct CaptureState {
    /// The newest capture of each camera not yet taken.
    frames: HashMap<Entity, CapturedFrame>,
    /// The newest frame delivered per camera: Bevy reads the buffer back every frame, also
    /// in frames that copied nothing into it.
    delivered: HashMap<Entity, u32>,
    /// Bytes each camera's capture buffer needs (set by the render world).
    needed: HashMap<Entity, u64>,
}

impl MesostructureCaptures {
    /// Takes the newest capture of `camera`, if one arrived since the last call.
    pub fn take(&self, camera: Entity) -> Option<CapturedFrame> {
        self.0.lock().ok()?.frames.remove(&camera)
    }

    /// Takes the newest capture of `camera` if it was rendered after the main world's update
    /// number `frame` ([`FrameCount`] read after that update, before changing the world);
    /// older captures are dropped.
    pub fn take_after(&self, camera: Entity, frame: u32) -> Option<CapturedFrame> {
        self.take(camera).filter(|f| f.frame > frame)
    }

    fn receive(&self, camera: Entity, data: &[u8]) {
        let Some(frame) = parse(data) else {
            return;
        };
        let Ok(mut state) = self.0.lock() else {
            return;
        };
        if state.delivered.get(&camera).is_some_and(|&d| d >= frame.frame) {
            return;
        }
        state.delivered.insert(camera, frame.frame);
        state.frames.insert(camera, frame);
    }
}

/// Main-world: the capture buffer of a camera and the entity reading it back.
#[derive(Component)]
struct CaptureBuffer {
    buffer: Handle<ShaderBuffer>,
    reader: Entity,
}

/// Main-world: on the entity that carries the [`Readback`] of a camera's capture buffer.
#[derive(Component)]
struct CaptureReaderOf(Entity);

/// Main-world system: gives each captured camera its buffer and reader, grows the buffer to
/// what the render world asked for, and removes both when the capture (or camera) goes.
fn sync_capture_buffers(
    mut commands: Commands,
    new: Query<Entity, (With<MesostructureCapture>, Without<CaptureBuffer>)>,
    cameras: Query<(Entity, &CaptureBuffer, Has<MesostructureCapture>)>,
    readers: Query<(Entity, &CaptureReaderOf)>,
    mut buffers: ResMut<Assets<ShaderBuffer>>,
    captures: Res<MesostructureCaptures>,
) {
    for camera in &new {
        // The header alone until the render world knows the view's size.
        let buffer = buffers.add(ShaderBuffer::with_size(
            HEADER_BYTES as usize,
            bevy::asset::RenderAssetUsages::default(),
        ));
        let receiver = captures.clone();
        let reader = commands
            .spawn((Readback::buffer(buffer.clone()), CaptureReaderOf(camera)))
            .observe(move |readback: On<ReadbackComplete>| {
                receiver.receive(camera, &readback.data)
            })
            .id();
        commands
            .entity(camera)
            .insert(CaptureBuffer { buffer, reader });
    }
    let needed = captures
        .0
        .lock()
        .map(|s| s.needed.clone())
        .unwrap_or_default();
    let forget = |camera: Entity| {
        if let Ok(mut state) = captures.0.lock() {
            state.needed.remove(&camera);
            state.delivered.remove(&camera);
        }
    };
    for (camera, capture, wanted) in &cameras {
        if !wanted {
            commands.entity(capture.reader).despawn();
            commands.entity(camera).remove::<CaptureBuffer>();
            forget(camera);
            continue;
        }
        let Some(&bytes) = needed.get(&camera) else {
            continue;
        };
        if let Some(mut buffer) = buffers.get_mut(&capture.buffer)
            && buffer.buffer_description.size != bytes
        {
            buffer.buffer_description.size = bytes;
        }
    }
    for (reader, of) in &readers {
        if cameras.get(of.0).is_err() {
            commands.entity(reader).despawn();
            forget(of.0);
        }
    }
}

/// Render-world marker: read this view back; the main-world camera it belongs to and its
/// capture buffer.
#[derive(Component, Clone)]
pub struct ExtractedCapture {
    camera: Entity,
    buffer: AssetId<ShaderBuffer>,
}

/// Marks the render views whose camera asks for a capture.
fn extract_capture_requests(
    mut commands: Commands,
    cameras: Extract<
        Query<
            (RenderEntity, Entity, Option<&CaptureBuffer>),
            With<crate::Mesostructure>,
        >,
    >,
) {
    for (render_entity, entity, capture) in &cameras {
        let Ok(mut target) = commands.get_entity(render_entity) else {
            continue;
        };
        match capture {
            Some(capture) => {
                target.insert(ExtractedCapture {
                    camera: entity,
                    buffer: capture.buffer.id(),
                });
            }
            None => {
                target.remove::<ExtractedCapture>();
            }
        }
    }
}

/// The images of a capture, in the order of [`CaptureHeader::parts`].
#[derive(Clone, Copy)]
enum Part {
    Mhm,
    CoreNormal,
    Mhgm,
    ApexSets,
    ApexStats,
    Occlusion,
    BumpNormal,
    TextureTerms,
    MicroShadow,
    Lit,
    Bleeding,
}
const PARTS: usize = 11;

/// Where one image lies in the capture buffer; `rows == 0`: not copied this frame.
#[repr(C)]
#[derive(Clone, Copy, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct PartPlace {
    offset: u32,
    padded_row: u32,
    row: u32,
    rows: u32,
    /// The lit image's format ([`LIT_FORMATS`] index + 1); 0 for the others.
    format: u32,
    _pad: u32,
}

/// The start of a capture buffer.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct CaptureHeader {
    magic: u32,
    /// [`FrameCount`] + 1 (0: never written).
    frame: u32,
    width: u32,
    height: u32,
    apex_stride: u32,
    apex_block: u32,
    _pad: [u32; 2],
    world_from_clip: [f32; 16],
    viewport: [f32; 4],
    parts: [PartPlace; PARTS],
}

const MAGIC: u32 = u32::from_le_bytes(*b"MSCP");
/// Bytes kept for the header (the images start aligned after it).
const HEADER_BYTES: u64 = 512;
const _: () = assert!(size_of::<CaptureHeader>() as u64 <= HEADER_BYTES);
/// The lit image's formats a capture reads (others are skipped).
const LIT_FORMATS: [TextureFormat; 3] = [
    TextureFormat::Rgba16Float,
    TextureFormat::Rgba8UnormSrgb,
    TextureFormat::Rgba8Unorm,
];
/// Bytes per pixel kept for the lit image: the widest of [`LIT_FORMATS`].
const LIT_BYTES: u32 = 8;

fn texture_place(offset: u64, size: UVec2, bytes_per_pixel: u32) -> PartPlace {
    let row = size.x * bytes_per_pixel;
    PartPlace {
        offset: offset as u32,
        padded_row: RenderDevice::align_copy_bytes_per_row(row as usize) as u32,
        row,
        rows: size.y,
        ..default()
    }
}

fn bytes_per_pixel(format: TextureFormat) -> u32 {
    format.block_copy_size(None).unwrap_or(16)
}

/// The places of all images of a view of `size` with `apex_bytes` of apex sets and
/// `stats_bytes` of counters; the buffer's length.
fn layout(size: UVec2, apex_bytes: u64, stats_bytes: u64) -> ([PartPlace; PARTS], u64) {
    let mut parts = [PartPlace::default(); PARTS];
    let mut offset = HEADER_BYTES;
    let sizes: [(Part, Option<TextureFormat>, u64); PARTS] = [
        (Part::Mhm, Some(MHM_FORMAT), 0),
        (Part::CoreNormal, Some(CORE_NORMAL_FORMAT), 0),
        (Part::Mhgm, Some(MHGM_FORMAT), 0),
        (Part::ApexSets, None, apex_bytes),
        (Part::ApexStats, None, stats_bytes),
        (Part::Occlusion, Some(OCCLUSION_FORMAT), 0),
        (Part::BumpNormal, Some(BUMP_NORMAL_FORMAT), 0),
        (Part::TextureTerms, Some(TEXTURE_VISIBILITY_FORMAT), 0),
        (Part::MicroShadow, Some(MICRO_SHADOW_FORMAT), 0),
        (Part::Lit, None, 0),
        (Part::Bleeding, Some(BLEEDING_FORMAT), 0),
    ];
    for (part, format, bytes) in sizes {
        let place = match (part, format) {
            (Part::Lit, _) => texture_place(offset, size, LIT_BYTES),
            (_, Some(format)) => texture_place(offset, size, bytes_per_pixel(format)),
            (_, None) => PartPlace {
                offset: offset as u32,
                padded_row: bytes as u32,
                row: bytes as u32,
                rows: 1,
                ..default()
            },
        };
        parts[part as usize] = place;
        offset += (place.padded_row as u64 * place.rows as u64).next_multiple_of(256);
    }
    // Copied later in the frame, where they run: marked absent until then.
    for part in [Part::MicroShadow, Part::Lit, Part::Bleeding] {
        parts[part as usize].rows = 0;
    }
    (parts, offset)
}

/// Copies `texture` into the capture buffer at `place`.
fn copy_texture(ctx: &mut RenderContext, texture: &Texture, buffer: &Buffer, place: &PartPlace) {
    ctx.command_encoder().copy_texture_to_buffer(
        texture.as_image_copy(),
        TexelCopyBufferInfo {
            buffer,
            layout: TexelCopyBufferLayout {
                offset: place.offset as u64,
                bytes_per_row: Some(place.padded_row),
                rows_per_image: None,
            },
        },
        texture.size(),
    );
}

/// Writes one part's place into the header of `buffer` (a queue write: it lands before this
/// frame's copies are read back, and after the previous frame's were).
fn write_place(queue: &RenderQueue, buffer: &Buffer, part: Part, place: &PartPlace) {
    let at = std::mem::offset_of!(CaptureHeader, parts) + part as usize * size_of::<PartPlace>();
    queue.write_buffer(buffer, at as u64, bytemuck::bytes_of(place));
}

/// The capture buffer of a view, if it is there and large enough for `bytes`; otherwise asks
/// the main world for one that is.
fn capture_buffer<'a>(
    capture: &ExtractedCapture,
    buffers: &'a RenderAssets<GpuShaderBuffer>,
    captures: &MesostructureCaptures,
    bytes: u64,
) -> Option<&'a Buffer> {
    let buffer = buffers.get(capture.buffer).map(|b| &b.buffer);
    if buffer.is_some_and(|b| b.size() >= bytes) {
        return buffer;
    }
    if let Ok(mut state) = captures.0.lock() {
        state.needed.insert(capture.camera, bytes);
    }
    None
}

/// Core3d system after the occlusion pass: copies the working images into the view's capture
/// buffer and writes its header. Views without a mesostructure surface this frame are not
/// captured (their images are stale).
fn copy_capture(
    view: ViewQuery<(
        (&ViewHeightTextures, &ViewGradientMap, &ViewApexSets, &ViewOcclusionTextures),
        &ExtractedCapture,
        &bevy::render::view::ExtractedView,
        &crate::render::view_settings::ExtractedMesostructure,
    )>,
    phases: Res<bevy::render::render_phase::ViewSortedRenderPhases<super::height::HeightPhaseItem>>,
    buffers: Res<RenderAssets<GpuShaderBuffer>>,
    captures: Res<MesostructureCaptures>,
    queue: Res<RenderQueue>,
    frame_count: Option<Res<FrameCount>>,
    mut ctx: RenderContext,
) {
    let ((height, mhgm, apex, occlusion), capture, extracted_view, settings) = view.into_inner();
    if !settings.0.needs_gradient_map() || !super::view_has_mesostructure(&phases, extracted_view) {
        return;
    }
    let (parts, bytes) = layout(height.size, apex.sets.size(), apex.stats.size());
    let Some(buffer) = capture_buffer(capture, &buffers, &captures, bytes) else {
        return;
    };
    let textures = [
        (Part::Mhm, &height.mhm.texture),
        (Part::CoreNormal, &height.core_normal.texture),
        (Part::Mhgm, &mhgm.0.texture),
        (Part::Occlusion, &occlusion.occlusion.texture),
        (Part::BumpNormal, &height.bump_normal.texture),
        (Part::TextureTerms, &height.texture_visibility.texture),
    ];
    for (part, texture) in textures {
        copy_texture(&mut ctx, texture, buffer, &parts[part as usize]);
    }
    for (part, source) in [(Part::ApexSets, &apex.sets), (Part::ApexStats, &apex.stats)] {
        let place = &parts[part as usize];
        ctx.command_encoder().copy_buffer_to_buffer(
            source,
            0,
            buffer,
            place.offset as u64,
            source.size(),
        );
    }
    let world_from_clip =
        extracted_view.world_from_view.to_matrix() * extracted_view.clip_from_view.inverse();
    let header = CaptureHeader {
        magic: MAGIC,
        frame: frame_count.map_or(0, |f| f.0).wrapping_add(1).max(1),
        width: height.size.x,
        height: height.size.y,
        apex_stride: apex.stride,
        apex_block: apex.block,
        _pad: [0; 2],
        world_from_clip: world_from_clip.to_cols_array(),
        viewport: extracted_view.viewport.as_vec4().to_array(),
        parts,
    };
    queue.write_buffer(buffer, 0, bytemuck::bytes_of(&header));
}

/// Core3d system after Bevy's opaque pass: copies the micro-shadow visibility and the lit
/// opaque image (before the bleeding is added) of the views captured this frame.
fn copy_lighting_capture(
    view: ViewQuery<(
        &ViewMicroShadowTexture,
        &ViewHeightTextures,
        &ViewApexSets,
        &ExtractedCapture,
        &bevy::render::view::ViewTarget,
        &bevy::render::view::ExtractedView,
        &crate::render::view_settings::ExtractedMesostructure,
    )>,
    phases: Res<bevy::render::render_phase::ViewSortedRenderPhases<super::height::HeightPhaseItem>>,
    buffers: Res<RenderAssets<GpuShaderBuffer>>,
    captures: Res<MesostructureCaptures>,
    queue: Res<RenderQueue>,
    mut ctx: RenderContext,
) {
    let (micro_shadow, height, apex, capture, target, extracted_view, settings) =
        view.into_inner();
    // Only where `copy_capture` ran this frame (the same conditions).
    if !settings.0.needs_gradient_map() || !super::view_has_mesostructure(&phases, extracted_view) {
        return;
    }
    let (parts, bytes) = layout(height.size, apex.sets.size(), apex.stats.size());
    let Some(buffer) = capture_buffer(capture, &buffers, &captures, bytes) else {
        return;
    };
    if micro_shadow.0.texture.size() == height.size.to_extents() {
        let place = PartPlace {
            rows: height.size.y,
            ..parts[Part::MicroShadow as usize]
        };
        copy_texture(&mut ctx, &micro_shadow.0.texture, buffer, &place);
        write_place(&queue, buffer, Part::MicroShadow, &place);
    }
    let format = target.main_texture_format();
    let lit = target.main_texture();
    if let Some(index) = LIT_FORMATS.iter().position(|&f| f == format)
        && lit.size() == height.size.to_extents()
    {
        let place = PartPlace {
            format: index as u32 + 1,
            ..texture_place(
                parts[Part::Lit as usize].offset as u64,
                height.size,
                bytes_per_pixel(format),
            )
        };
        copy_texture(&mut ctx, lit, buffer, &place);
        write_place(&queue, buffer, Part::Lit, &place);
    }
}

/// The bleeding pass's captures: the captured views and their buffers.
pub(crate) type BleedingCaptures<'w, 's> = (
    Query<'w, 's, (&'static ExtractedCapture, &'static ViewApexSets)>,
    Res<'w, RenderAssets<GpuShaderBuffer>>,
    Res<'w, MesostructureCaptures>,
    Res<'w, RenderQueue>,
);

/// After the bleeding gather (called by the bleeding pass, the only place that knows the
/// gather ran this frame): copies the bleeding of a captured view.
pub(crate) fn copy_bleeding(
    ctx: &mut RenderContext,
    captures: &BleedingCaptures,
    view: Entity,
    size: UVec2,
    bleeding: &bevy::render::texture::CachedTexture,
) {
    let (captured, buffers, state, queue) = captures;
    let Ok((capture, apex)) = captured.get(view) else {
        return;
    };
    let (parts, bytes) = layout(size, apex.sets.size(), apex.stats.size());
    let Some(buffer) = capture_buffer(capture, buffers, state, bytes) else {
        return;
    };
    if bleeding.texture.size() != size.to_extents() {
        return;
    }
    let place = PartPlace {
        rows: size.y,
        ..parts[Part::Bleeding as usize]
    };
    copy_texture(ctx, &bleeding.texture, buffer, &place);
    write_place(queue, buffer, Part::Bleeding, &place);
}

/// The bytes of one part without the row padding; empty if it was not copied.
fn part_bytes(data: &[u8], place: &PartPlace) -> Option<Vec<u8>> {
    if place.rows == 0 {
        return Some(Vec::new());
    }
    let start = place.offset as usize;
    let end = start + place.padded_row as usize * (place.rows as usize - 1) + place.row as usize;
    let bytes = data.get(start..end)?;
    Some(
        (0..place.rows as usize)
            .flat_map(|y| {
                let at = y * place.padded_row as usize;
                &bytes[at..at + place.row as usize]
            })
            .copied()
            .collect(),
    )
}

/// A capture buffer as read back; `None` if it was never written or is cut short (a resize in
/// flight).
fn parse(data: &[u8]) -> Option<CapturedFrame> {
    let header: CaptureHeader =
        bytemuck::pod_read_unaligned(data.get(..size_of::<CaptureHeader>())?);
    if header.magic != MAGIC || header.frame == 0 {
        return None;
    }
    let part = |p: Part| part_bytes(data, &header.parts[p as usize]);
    let floats = |bytes: Vec<u8>| -> Vec<[f32; 4]> { bytemuck::pod_collect_to_vec(&bytes) };
    let half4 = |bytes: Vec<u8>| -> Vec<[f32; 4]> {
        let halves: Vec<u16> = bytemuck::pod_collect_to_vec(&bytes);
        halves
            .chunks_exact(4)
            .map(|c| std::array::from_fn(|i| crate::height_map_import::half_to_f32(c[i])))
            .collect()
    };
    let lit_place = &header.parts[Part::Lit as usize];
    let lit = part(Part::Lit)?;
    let lit = match LIT_FORMATS.get((lit_place.format as usize).wrapping_sub(1)) {
        Some(TextureFormat::Rgba16Float) => half4(lit),
        Some(&format) => lit
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
        None => Vec::new(),
    };
    // (micro-shadow visibility, the first directional light's shadow-map visibility)
    let micro_shadows: Vec<[f32; 2]> = bytemuck::pod_collect_to_vec(&part(Part::MicroShadow)?);
    let stats: Vec<u32> = bytemuck::pod_collect_to_vec(&part(Part::ApexStats)?);
    Some(CapturedFrame {
        frame: header.frame - 1,
        width: header.width,
        height: header.height,
        mhm: floats(part(Part::Mhm)?),
        core_normal: floats(part(Part::CoreNormal)?),
        mhgm: bytemuck::pod_collect_to_vec(&part(Part::Mhgm)?),
        apex_sets: bytemuck::pod_collect_to_vec(&part(Part::ApexSets)?),
        apex_stride: header.apex_stride,
        apex_block: header.apex_block,
        apex_stats: [0, 1, 2].map(|i| stats.get(i).copied().unwrap_or(0)),
        occlusion: bytemuck::pod_collect_to_vec(&part(Part::Occlusion)?),
        bump_normal: half4(part(Part::BumpNormal)?),
        micro_shadow: micro_shadows.iter().map(|v| v[0]).collect(),
        sun_shadow: micro_shadows.iter().map(|v| v[1]).collect(),
        texture_terms: bytemuck::pod_collect_to_vec(&part(Part::TextureTerms)?),
        lit,
        bleeding: half4(part(Part::Bleeding)?),
        view: ViewGeometry {
            world_from_clip: Mat4::from_cols_array(&header.world_from_clip),
            viewport: Vec4::from_array(header.viewport),
        },
    })
}

fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}
