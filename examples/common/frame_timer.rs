//! GPU time of whole frames and of Bevy's deferred lighting, from raw timestamp queries.
//!
//! Bevy's diagnostic spans belong to one system on one thread, so none can bracket a frame
//! (they would also nest every other span under it and rename them). This plugin writes four
//! timestamps a frame into its own query set: before and after `camera_driver` (every camera's
//! schedule: shadows, prepass, lighting, post-processing), and around Bevy's `deferred_lighting`
//! system (the pass our lighting pass replaces for mesostructure pixels). The bench compares
//! the frame with the plugin on and off: what the plugin *adds*.
//!
//! Needs `TIMESTAMP_QUERY` and `TIMESTAMP_QUERY_INSIDE_ENCODERS` (Vulkan, DX12, Metal have
//! them); without, it records nothing and says so once.

use std::sync::{
    Arc, Mutex,
    atomic::{AtomicBool, Ordering},
};

use wgpu::{QuerySet, QuerySetDescriptor, QueryType};

use bevy::{
    core_pipeline::{
        Core3d, Core3dSystems, core_3d::main_opaque_pass_3d, schedule::camera_driver,
    },
    pbr::deferred::deferred_lighting,
    prelude::*,
    render::{
        RenderApp,
        render_resource::{Buffer, BufferDescriptor, BufferUsages, MapMode, WgpuFeatures},
        renderer::{RenderContext, RenderDevice, RenderGraph, RenderQueue},
    },
};

/// Timestamps a frame: frame begin, deferred lighting begin and end, frame end.
const TIMESTAMPS: u32 = 4;
/// Readback buffers in flight (a frame's results arrive a frame or two later).
const RING: usize = 4;

/// Per frame, in milliseconds: the whole frame's GPU time and Bevy's deferred lighting's, in
/// the order the frames finished. Shared by the main and the render world.
#[derive(Resource, Clone, Default)]
pub struct FrameGpuTimes(pub Arc<Mutex<FrameSeries>>);

/// The series of [`FrameGpuTimes`].
#[derive(Default)]
pub struct FrameSeries {
    pub frame_ms: Vec<f64>,
    pub deferred_lighting_ms: Vec<f64>,
}

/// Adds the timestamps; read them from [`FrameGpuTimes`] in the main world.
pub struct FrameTimerPlugin;

impl Plugin for FrameTimerPlugin {
    fn build(&self, app: &mut App) {
        let times = FrameGpuTimes::default();
        app.insert_resource(times.clone());
        let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
            return;
        };
        render_app
            .insert_resource(times)
            .add_systems(RenderGraph, (frame_begin.before(camera_driver), frame_end.after(camera_driver)))
            .add_systems(
                Core3d,
                (
                    deferred_lighting_begin
                        .in_set(Core3dSystems::MainPass)
                        .before(deferred_lighting)
                        .after(bevy_mesostructure::MesostructureSystems::Lighting),
                    deferred_lighting_end
                        .in_set(Core3dSystems::MainPass)
                        .after(deferred_lighting)
                        .before(main_opaque_pass_3d),
                ),
            );
    }

    fn finish(&self, app: &mut App) {
        let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
            return;
        };
        let device = render_app.world().resource::<RenderDevice>().clone();
        let needed = WgpuFeatures::TIMESTAMP_QUERY | WgpuFeatures::TIMESTAMP_QUERY_INSIDE_ENCODERS;
        if !device.features().contains(needed) {
            warn!("frame timer: the adapter cannot write timestamps inside encoders; no frame times");
            return;
        }
        let period_ns = render_app.world().resource::<RenderQueue>().get_timestamp_period();
        let bytes = TIMESTAMPS as u64 * 8;
        let query_set = device.wgpu_device().create_query_set(&QuerySetDescriptor {
            label: Some("frame_timer_queries"),
            ty: QueryType::Timestamp,
            count: TIMESTAMPS,
        });
        let resolve = device.create_buffer(&BufferDescriptor {
            label: Some("frame_timer_resolve"),
            size: bytes,
            usage: BufferUsages::QUERY_RESOLVE | BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let ring = (0..RING)
            .map(|_| Readback {
                buffer: device.create_buffer(&BufferDescriptor {
                    label: Some("frame_timer_readback"),
                    size: bytes,
                    usage: BufferUsages::MAP_READ | BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                }),
                state: Arc::new(Slot::default()),
            })
            .collect();
        render_app.insert_resource(FrameTimer {
            query_set,
            resolve,
            ring,
            next: 0,
            period_ns: period_ns as f64,
            written: [false; TIMESTAMPS as usize],
        });
    }
}

#[derive(Default)]
struct Slot {
    /// Copied into and mapping requested; not yet read.
    pending: AtomicBool,
    /// The map completed.
    mapped: AtomicBool,
    /// Bevy's deferred lighting ran in that frame (its two timestamps are real).
    deferred: AtomicBool,
}

struct Readback {
    buffer: Buffer,
    state: Arc<Slot>,
}

#[derive(Resource)]
struct FrameTimer {
    query_set: QuerySet,
    resolve: Buffer,
    ring: Vec<Readback>,
    next: usize,
    period_ns: f64,
    written: [bool; TIMESTAMPS as usize],
}

impl FrameTimer {
    fn write(&mut self, ctx: &mut RenderContext, index: u32) {
        ctx.command_encoder().write_timestamp(&self.query_set, index);
        self.written[index as usize] = true;
    }
}

/// Collects finished frames, then writes the frame's first timestamp.
fn frame_begin(timer: Option<ResMut<FrameTimer>>, times: Res<FrameGpuTimes>, mut ctx: RenderContext) {
    let Some(mut timer) = timer else {
        return;
    };
    let period_ms = timer.period_ns * 1e-6;
    for slot in &timer.ring {
        if !slot.state.mapped.load(Ordering::Acquire) {
            continue;
        }
        {
            let view = slot.buffer.slice(..).get_mapped_range();
            let ticks: &[u64] = bytemuck::cast_slice(&view);
            let mut series = times.0.lock().expect("frame timer lock");
            series.frame_ms.push(ticks[3].wrapping_sub(ticks[0]) as f64 * period_ms);
            if slot.state.deferred.load(Ordering::Acquire) {
                series.deferred_lighting_ms.push((ticks[2] - ticks[1]) as f64 * period_ms);
            }
        }
        slot.buffer.unmap();
        slot.state.mapped.store(false, Ordering::Release);
        slot.state.pending.store(false, Ordering::Release);
    }
    timer.written = [false; TIMESTAMPS as usize];
    timer.write(&mut ctx, 0);
}

fn deferred_lighting_begin(timer: Option<ResMut<FrameTimer>>, mut ctx: RenderContext) {
    if let Some(mut timer) = timer {
        timer.write(&mut ctx, 1);
    }
}

fn deferred_lighting_end(timer: Option<ResMut<FrameTimer>>, mut ctx: RenderContext) {
    if let Some(mut timer) = timer {
        timer.write(&mut ctx, 2);
    }
}

/// Writes the frame's last timestamp and copies the four out for reading once mapped.
fn frame_end(timer: Option<ResMut<FrameTimer>>, mut ctx: RenderContext) {
    let Some(mut timer) = timer else {
        return;
    };
    timer.write(&mut ctx, 3);
    let deferred = timer.written[1] && timer.written[2];
    if !deferred {
        // No deferred lighting this frame: every query resolved must have been written.
        timer.write(&mut ctx, 1);
        timer.write(&mut ctx, 2);
    }
    let index = timer.next;
    let timer = &mut *timer;
    let slot = &timer.ring[index];
    if slot.state.pending.load(Ordering::Acquire) {
        // Every readback buffer still in flight: skip this frame rather than stall.
        return;
    }
    let encoder = ctx.command_encoder();
    encoder.resolve_query_set(&timer.query_set, 0..TIMESTAMPS, &timer.resolve, 0);
    encoder.copy_buffer_to_buffer(&timer.resolve, 0, &slot.buffer, 0, None);
    slot.state.pending.store(true, Ordering::Release);
    slot.state.deferred.store(deferred, Ordering::Release);
    let state = slot.state.clone();
    encoder.map_buffer_on_submit(&slot.buffer, MapMode::Read, .., move |result| {
        if result.is_ok() {
            state.mapped.store(true, Ordering::Release);
        } else {
            state.pending.store(false, Ordering::Release);
        }
    });
    timer.next = (index + 1) % RING;
}
