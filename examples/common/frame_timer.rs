//! GPU time of whole frames and of Bevy's deferred lighting, from raw timestamp queries.
//!
//! Bevy's diagnostic spans belong to one system on one thread, so none can bracket a frame
//! (they would also nest every other span under it and rename them). This plugin writes four
//! timestamps a frame into its own query set: before and after `camera_driver` (every camera's
//! schedule: shadows, prepass, lighting, post-processing), and around Bevy's `deferred_lighting`
//! system (the pass our lighting pass replaces for mesostructure pixels). The bench compares
//! the frame with the plugin on and off: what the plugin *adds*.
//!
//! Bevy submits each render system's commands when the system ends, so a GPU faster than the
//! CPU that records them idles between submissions, and a bracket around the frame would time
//! the CPU. So each frame begins with a *lead*: one GPU thread spinning for ~`LEAD_MS` (its
//! loop count adapted from its own measured time) before the first timestamp, during which the
//! CPU records and submits the whole frame; the GPU then runs the frame back to back and the
//! bracket holds GPU work alone (measured on an H100: without the lead, frames of ~2.5 ms of
//! passes read 7–12 ms).
//!
//! Needs `TIMESTAMP_QUERY` and `TIMESTAMP_QUERY_INSIDE_ENCODERS` (Vulkan, DX12, Metal have
//! them); without, it records nothing and says so once.

use std::sync::{
    Arc, Mutex,
    atomic::{AtomicBool, AtomicU32, Ordering},
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

/// Timestamps a frame: frame begin, deferred lighting begin and end, frame end, lead begin.
const TIMESTAMPS: u32 = 5;
/// How long the lead keeps the GPU busy while the CPU records the frame, in milliseconds: over
/// the CPU's time for a frame of the bench's scenes.
const LEAD_MS: f64 = 20.0;
/// The lead: one thread running a dependent integer chain `state[1]` steps long.
const LEAD_SHADER: &str = "
@group(0) @binding(0) var<storage, read_write> state: array<u32, 4>;
@compute @workgroup_size(1)
fn lead() {
    var x = state[0];
    let steps = state[1];
    for (var i = 0u; i < steps; i++) {
        x = x * 1664525u + 1013904223u;
    }
    state[2] = x;
}
";
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
    /// The lead before each frame (see the module's notes).
    pub lead_ms: Vec<f64>,
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
                        .after(bevy_mesostructure::MesostructureSystems::RasterLighting),
                    deferred_lighting_end
                        .in_set(Core3dSystems::MainPass)
                        .after(deferred_lighting)
                        .before(bevy_mesostructure::MesostructureSystems::ComputeLighting)
                        .before(main_opaque_pass_3d),
                ),
            );
    }

    fn finish(&self, app: &mut App) {
        let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
            return;
        };
        let device = render_app.world().resource::<RenderDevice>().clone();
        let lead = Lead::new(&device);
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
            lead,
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
    /// The lead's length in that frame.
    lead_steps: AtomicU32,
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
    lead: Lead,
}

/// The lead's pipeline, its state buffer and its current length.
struct Lead {
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    state: Buffer,
    steps: u32,
}

impl Lead {
    fn new(device: &RenderDevice) -> Self {
        let device = device.wgpu_device();
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("frame_timer_lead"),
            source: wgpu::ShaderSource::Wgsl(LEAD_SHADER.into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("frame_timer_lead"),
            layout: None,
            module: &module,
            entry_point: Some("lead"),
            compilation_options: Default::default(),
            cache: None,
        });
        let state = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("frame_timer_lead_state"),
            size: 16,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("frame_timer_lead"),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: state.as_entire_binding(),
            }],
        });
        Self {
            pipeline,
            bind_group,
            state: state.into(),
            steps: 1 << 16,
        }
    }

    /// Sets the length towards `LEAD_MS` from a measured lead of `steps` steps (not from the
    /// current length: results arrive frames late, and scaling the current length by them
    /// would overshoot).
    fn adapt(&mut self, measured_ms: f64, steps: u32) {
        if measured_ms > 0.0 {
            let scale = (LEAD_MS / measured_ms).clamp(0.25, 4.0);
            self.steps = (steps as f64 * scale).clamp(1024.0, 1.0e9) as u32;
        }
    }
}

impl FrameTimer {
    fn write(&mut self, ctx: &mut RenderContext, index: u32) {
        ctx.command_encoder().write_timestamp(&self.query_set, index);
        self.written[index as usize] = true;
    }
}

/// Collects finished frames, then writes the frame's first timestamp.
fn frame_begin(
    timer: Option<ResMut<FrameTimer>>,
    times: Res<FrameGpuTimes>,
    queue: Res<RenderQueue>,
    mut ctx: RenderContext,
) {
    let Some(mut timer) = timer else {
        return;
    };
    let period_ms = timer.period_ns * 1e-6;
    let mut lead = vec![];
    for slot in &timer.ring {
        if !slot.state.mapped.load(Ordering::Acquire) {
            continue;
        }
        {
            let view = slot.buffer.slice(..).get_mapped_range();
            let ticks: &[u64] = bytemuck::cast_slice(&view);
            let mut series = times.0.lock().expect("frame timer lock");
            series.frame_ms.push(ticks[3].wrapping_sub(ticks[0]) as f64 * period_ms);
            let lead_ms = ticks[0].wrapping_sub(ticks[4]) as f64 * period_ms;
            series.lead_ms.push(lead_ms);
            lead.push((lead_ms, slot.state.lead_steps.load(Ordering::Acquire)));
            if slot.state.deferred.load(Ordering::Acquire) {
                series.deferred_lighting_ms.push((ticks[2] - ticks[1]) as f64 * period_ms);
            }
        }
        slot.buffer.unmap();
        slot.state.mapped.store(false, Ordering::Release);
        slot.state.pending.store(false, Ordering::Release);
    }
    if let Some(&(ms, steps)) = lead.last() {
        timer.lead.adapt(ms, steps);
    }
    timer.written = [false; TIMESTAMPS as usize];
    // The lead, then the frame's first timestamp: the GPU spins while the CPU records the
    // frame (this system's commands are submitted as it ends).
    timer.write(&mut ctx, 4);
    queue.write_buffer(&timer.lead.state, 0, bytemuck::cast_slice(&[1u32, timer.lead.steps]));
    {
        let encoder = ctx.command_encoder();
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("frame_timer_lead"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&timer.lead.pipeline);
        pass.set_bind_group(0, &timer.lead.bind_group, &[]);
        pass.dispatch_workgroups(1, 1, 1);
    }
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
    slot.state.lead_steps.store(timer.lead.steps, Ordering::Release);
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
