//! The iteration's per-frame side: the render-world system that records a solve when the
//! lights changed (and in the settling frames after), and the read-back of how many products
//! the last solve took, which sizes the next one.

use bevy::{
    ecs::system::{Res, ResMut},
    render::{
        diagnostic::RecordDiagnostics,
        render_resource::{Buffer, BufferDescriptor, BufferUsages, CommandEncoder},
        renderer::{RenderContext, RenderDevice, ViewQuery},
    },
};
use std::sync::{
    Arc,
    atomic::{AtomicBool, AtomicU64, Ordering},
};

use super::{GpuTransport, ITERATIONS_OFFSET};
use crate::translucency::{
    gather::{TranslucencyCamera, TranslucencyGpu},
    plugin::TranslucencyFrame,
};

/// The products the last solve took, read back from the GPU without waiting for it: a copy of
/// the iteration's `iterations` after a solve, mapped once the frame is submitted and read a
/// frame or more later. Each recorded product costs its four dispatches (~22 µs on an H100)
/// even after the stop, so the next warm solve records one more than the last one took, and
/// all of its cap where the last one used every product it was given or none was read back
/// yet. One copy at a time: solves while it is in flight are not read.
pub struct ProductsReadback {
    buffer: Buffer,
    /// A copy was recorded and not yet read.
    in_flight: Arc<AtomicBool>,
    /// The copy's frame was submitted: map it.
    to_map: bool,
    /// The products recorded and taken by the solve read last (`recorded << 32 | taken`);
    /// `u64::MAX` before the first.
    last: Arc<AtomicU64>,
    /// The products recorded by the solve whose copy is in flight.
    recorded: u32,
}

impl ProductsReadback {
    /// Nothing read back yet: the next solve records its whole cap.
    pub fn new(device: &RenderDevice) -> Self {
        Self {
            buffer: device.create_buffer(&BufferDescriptor {
                label: Some("translucency_products_readback"),
                size: 4,
                usage: BufferUsages::MAP_READ | BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            in_flight: Arc::new(AtomicBool::new(false)),
            to_map: false,
            last: Arc::new(AtomicU64::new(u64::MAX)),
            recorded: 0,
        }
    }

    /// How many products the next solve should record, of a cap of `cap`.
    pub fn products_to_record(&self, cap: u32) -> u32 {
        let last = self.last.load(Ordering::Acquire);
        if last == u64::MAX {
            return cap;
        }
        next_products(cap, (last >> 32) as u32, last as u32)
    }

    /// After a solve recorded with `recorded` products: copies its `iterations` out, unless a
    /// copy is still in flight.
    pub fn copy(&mut self, encoder: &mut CommandEncoder, transport: &GpuTransport, recorded: u32) {
        if self.in_flight.swap(true, Ordering::AcqRel) {
            return;
        }
        encoder.copy_buffer_to_buffer(transport.state(), ITERATIONS_OFFSET, &self.buffer, 0, 4);
        self.recorded = recorded;
        self.to_map = true;
    }

    /// Once the frame holding the copy was submitted (render `Cleanup`): maps it; the value
    /// lands when the GPU is done, read by [`products_to_record`](Self::products_to_record).
    pub fn map(&mut self) {
        if !std::mem::take(&mut self.to_map) {
            return;
        }
        let (buffer, in_flight, last) = (self.buffer.clone(), self.in_flight.clone(), self.last.clone());
        let recorded = self.recorded;
        self.buffer.slice(..).map_async(bevy::render::render_resource::MapMode::Read, move |result| {
            if result.is_ok() {
                let taken = {
                    let data = buffer.slice(..).get_mapped_range();
                    u32::from_le_bytes([data[0], data[1], data[2], data[3]])
                };
                buffer.unmap();
                last.store((u64::from(recorded) << 32) | u64::from(taken), Ordering::Release);
            }
            in_flight.store(false, Ordering::Release);
        });
    }
}

/// The products to record after a solve that took `taken` of the `recorded` it was given:
/// one more than it took, or the whole `cap` where it took them all (it may have needed more).
pub fn next_products(cap: u32, recorded: u32, taken: u32) -> u32 {
    if taken >= recorded {
        cap
    } else {
        (taken + 1).clamp(1, cap.max(1))
    }
}

/// Core3d system before the opaque pass: iterates the transport when the lights changed (the
/// first view of the frame does it; from the last solution where
/// [`TranslucencySettings::warm_start`](crate::translucency::TranslucencySettings::warm_start) and there is
/// one), and warm in the few frames after they stopped (`settle_frames`), timed as
/// `translucency/iteration`.
pub fn translucency_iteration_pass(
    _view: ViewQuery<&TranslucencyCamera>,
    frame: Res<TranslucencyFrame>,
    mut gpu: ResMut<TranslucencyGpu>,
    mut ctx: RenderContext,
) {
    let Some(max_iterations) = gpu.transport.as_ref().map(GpuTransport::max_iterations) else {
        return;
    };
    let warm = gpu.solved && frame.settings.warm_start;
    if gpu.iteration_pending {
        // As many as the transport's own cap (the settings' when it was uploaded).
        gpu.settle_frames = if warm { crate::translucency::transport::settle_frames(max_iterations) } else { 0 };
    } else if warm && gpu.settle_frames > 0 {
        gpu.settle_frames -= 1;
    } else {
        return;
    }
    let gpu = &mut *gpu;
    let Some(transport) = &gpu.transport else {
        return;
    };
    // A warm solve records one product more than the last solve took (read back), a cold
    // one its whole cap.
    let asked = match (&gpu.products, warm) {
        (Some(products), true) => products.products_to_record(transport.recorded_products(true, u32::MAX)),
        _ => u32::MAX,
    };
    let recorded = transport.recorded_products(warm, asked);
    let diagnostics = ctx.diagnostic_recorder();
    let diagnostics = diagnostics.as_deref();
    let span = diagnostics.time_span(ctx.command_encoder(), "translucency/iteration");
    transport.record_timed(ctx.command_encoder(), warm, recorded, &diagnostics);
    span.end(ctx.command_encoder());
    if let Some(products) = &mut gpu.products {
        products.copy(ctx.command_encoder(), transport, recorded);
    }
    gpu.iteration_pending = false;
    gpu.solved = true;
}

/// Render `Cleanup`, after the frame's submission: maps the read-back of the products the
/// frame's solve took ([`ProductsReadback`]).
pub fn map_products_readback(mut gpu: ResMut<TranslucencyGpu>) {
    if let Some(products) = &mut gpu.products {
        products.map();
    }
}
