//! GPU contract of the translucency transport: the iteration in `iterate.wgsl` against
//! `EnergyTransport::solve`, the CPU oracle, on the same matrices.

use bevy::{
    prelude::*,
    render::{
        RenderApp,
        render_resource::{
            BufferDescriptor, BufferUsages, CommandEncoderDescriptor, MapMode, PollType,
        },
        renderer::{RenderDevice, RenderQueue},
    },
};
use bevy_mesostructure::translucency::{
    DiffusionKernel, EnergyTransport, PatchLight, PatchObject, PatchSurface, SceneRays,
    TranslucentPreset, TransportSettings, direct_light, patch_albedos,
    iteration::{FlowFrame, GpuTransport, IterationLimits, ProductsReadback, RowLanes},
    Patches,
    injection::{GpuInjection, MAX_INJECTED_LIGHTS},
    resample_into_patches_with_caps, translucent_patch_cap,
    patches::world_triangles,
    resample_into_patches,
};

use crate::harness::*;

fn object(mesh: Mesh, transform: Transform) -> (Vec<Vec3>, Vec<u32>) {
    world_triangles(&mesh, &GlobalTransform::from(transform)).expect("a triangle list")
}

/// The app's render device and queue.
fn device_and_queue(app: &App) -> (RenderDevice, RenderQueue) {
    let render = app.sub_app(RenderApp).world();
    (
        render.resource::<RenderDevice>().clone(),
        render.resource::<RenderQueue>().clone(),
    )
}

/// Reads `size` bytes of `buffer` at `offset` back to the CPU.
fn read_back(
    device: &RenderDevice,
    queue: &RenderQueue,
    buffer: &bevy::render::render_resource::Buffer,
    offset: u64,
    size: u64,
) -> Vec<u8> {
    let staging = device.create_buffer(&BufferDescriptor {
        label: Some("readback"),
        size,
        usage: BufferUsages::MAP_READ | BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = device.create_command_encoder(&CommandEncoderDescriptor::default());
    encoder.copy_buffer_to_buffer(buffer, offset, &staging, 0, size);
    queue.submit([encoder.finish()]);
    let slice = staging.slice(..);
    device.map_buffer(&slice, MapMode::Read, |r| r.expect("the readback maps"));
    device
        .poll(PollType::wait_indefinitely())
        .expect("the GPU finishes");
    let bytes = slice.get_mapped_range().to_vec();
    staging.unmap();
    bytes
}

/// A marble ball (5 cm, metres) on a white floor beside a red wall: its objects.
fn marble_ball_objects() -> [(Vec<Vec3>, Vec<u32>); 3] {
    [
        object(
            Sphere::new(0.05).mesh().ico(3).unwrap(),
            Transform::from_xyz(0.0, 0.05, 0.0),
        ),
        object(
            Plane3d::new(Vec3::Y, Vec2::splat(0.2)).mesh().build(),
            Transform::IDENTITY,
        ),
        object(
            Plane3d::new(Vec3::X, Vec2::splat(0.2)).mesh().build(),
            Transform::from_xyz(-0.1, 0.1, 0.0),
        ),
    ]
}

/// [`marble_ball_objects`] in 600 patches, their albedos (zero on the ball), transport and
/// rays.
/// The surfaces of `marble_ball_objects`: the marble ball, a white floor, a red wall.
fn marble_ball_surfaces() -> [PatchSurface; 3] {
    [
        PatchSurface::Translucent {
            medium: TranslucentPreset::Marble.medium(),
            world_units_per_mm: 0.001,
            oriented_dipole: false,
        },
        PatchSurface::Opaque {
            albedo: Vec3::splat(0.8),
        },
        PatchSurface::Opaque {
            albedo: Vec3::new(0.8, 0.1, 0.1),
        },
    ]
}

fn marble_ball_on_a_floor(
    settings: TransportSettings,
) -> (Patches, Vec<Vec3>, EnergyTransport, SceneRays) {
    let objects = marble_ball_objects();
    let views: Vec<PatchObject> = objects
        .iter()
        .map(|o| PatchObject {
            positions: &o.0,
            indices: &o.1,
        })
        .collect();
    let patches = resample_into_patches(&views, 600);
    let rays = SceneRays::new(&views);
    let surfaces = marble_ball_surfaces();
    let transport = EnergyTransport::build(&patches, &surfaces, &rays, &settings);
    let albedo = patch_albedos(&patches, &surfaces);
    (patches, albedo, transport, rays)
}

/// A spot above and beside [`marble_ball_objects`]' ball, aimed at it.
fn spot_on_the_ball() -> PatchLight {
    spot_round_the_ball(0.0)
}

/// [`spot_on_the_ball`] turned `angle` radians about the vertical through the ball.
fn spot_round_the_ball(angle: f32) -> PatchLight {
    let position = Quat::from_rotation_y(angle) * Vec3::new(0.15, 0.25, 0.1);
    PatchLight::Spot {
        position,
        direction: (Vec3::new(0.0, 0.05, 0.0) - position).normalize(),
        intensity: Vec3::splat(10.0),
        inner_angle: 0.4,
        outer_angle: 0.6,
        range: 10.0,
    }
}

/// `cpu`'s brightest channel, the worst channel of `gpu`'s exitance against it, and how many
/// patches `gpu` holds.
fn peak_and_worst(
    device: &RenderDevice,
    queue: &RenderQueue,
    gpu: &GpuTransport,
    cpu: &[Vec3],
) -> (f32, f32, usize) {
    let (buffer, range) = gpu.exitance();
    let bytes = read_back(device, queue, buffer, range.start, range.end - range.start);
    let exitance: &[[f32; 4]] = bytemuck::cast_slice(&bytes);
    let peak = cpu.iter().map(|b| b.max_element()).fold(0.0, f32::max);
    let worst = exitance
        .iter()
        .zip(cpu)
        .map(|(g, c)| (Vec3::new(g[0], g[1], g[2]) - *c).abs().max_element())
        .fold(0.0, f32::max);
    (peak, worst, exitance.len())
}

#[test]
fn the_gpu_iteration_matches_the_cpu_oracle() {
    if !gpu_or_skip() {
        return;
    }
    let app = bare_app();
    let (device, queue) = device_and_queue(&app);

    // The dipole: its single-scattering term exercises the first bounce's extra exitance.
    let (patches, _, transport, rays) = marble_ball_on_a_floor(TransportSettings {
        kernel: DiffusionKernel::Dipole,
        beam_table: None,
        ..default()
    });
    assert!(transport.report.clusters > 0, "the far field takes part");
    let lights = [spot_on_the_ball()];
    // With the single-scattering exitance of the marble's direct light (the first bounce's
    // extra term).
    let direct = direct_light(&patches, Some(&transport), &lights, &rays);
    assert!(direct.exitance.iter().any(|s| *s != Vec3::ZERO));
    let n = patches.patches.len();

    // Converged (the loop stops on the GPU), and stopped by the cap; each row summed by 32
    // lanes (a GPU's products) and by one (a CPU driver's).
    let limit_sets = [
        IterationLimits {
            threshold: 1e-4,
            max_iterations: 60,
        },
        IterationLimits {
            threshold: 1e-9,
            max_iterations: 3,
        },
    ];
    for (limits, row_lanes) in limit_sets
        .into_iter()
        .flat_map(|l| [(l, RowLanes::Gpu), (l, RowLanes::Cpu)])
    {
        let cpu = transport.solve_with(&direct, limits.threshold, limits.max_iterations);
        let gpu = GpuTransport::new(&device, &transport, limits, row_lanes);
        gpu.write_direct(&queue, &direct);
        let mut encoder = device.create_command_encoder(&CommandEncoderDescriptor::default());
        gpu.record(&mut encoder, false);
        queue.submit([encoder.finish()]);

        let state = read_back(&device, &queue, gpu.state(), 0, 56);
        let iterations = u32::from_le_bytes(state[24..28].try_into().unwrap());
        assert_eq!(iterations, cpu.iterations, "{limits:?}");
        // The geometric tail's ratio (clamped where it is used).
        let tail_ratio = f32::from_le_bytes(state[52..56].try_into().unwrap())
            .clamp(0.0, bevy_mesostructure::translucency::transport::MAX_TAIL_RATIO);
        assert!(cpu.tail_ratio > 0.0, "{limits:?}");
        assert!(
            (tail_ratio - cpu.tail_ratio).abs() <= 1e-5,
            "{limits:?}: tail ratio {tail_ratio} on the GPU, {} on the CPU",
            cpu.tail_ratio
        );
        let (peak, worst, len) = peak_and_worst(&device, &queue, &gpu, &cpu.exitance);
        assert_eq!(len, n);
        eprintln!(
            "{limits:?} {row_lanes:?}: {iterations} iterations, worst |GPU − CPU| {:.2e} of peak {peak:.3e}",
            worst / peak
        );
        // One lane a row: the same arithmetic in the same order (measured bit-identical on the
        // software driver); 32 lanes sum each row in another order (2.4e-7 of the peak there);
        // another device may fuse or reorder too: within 1e-5 of the peak.
        assert!(
            peak > 0.0 && worst <= 1e-5 * peak,
            "{limits:?} {row_lanes:?}: worst {worst} of {peak}"
        );
    }

    // A warm start (`record(.., true)`): the spot moved 0.75° after a cold solve, from the
    // exitance the cold one left, against `solve_from` — the same products, tail ratio and
    // exitance, and the state says it was warm.
    let moved = direct_light(&patches, Some(&transport), &[spot_round_the_ball(0.013)], &rays);
    for row_lanes in [RowLanes::Gpu, RowLanes::Cpu] {
        let limits = IterationLimits { threshold: 1e-2, max_iterations: 16 };
        let cold = transport.solve_with(&direct, limits.threshold, limits.max_iterations);
        let cpu = transport.solve_from(
            &moved,
            limits.threshold,
            bevy_mesostructure::translucency::transport::warm_iterations(limits.max_iterations),
            Some(&cold),
        );
        let gpu = GpuTransport::new(&device, &transport, limits, row_lanes);
        for (light, warm) in [(&direct, false), (&moved, true)] {
            gpu.write_direct(&queue, light);
            let mut encoder = device.create_command_encoder(&CommandEncoderDescriptor::default());
            gpu.record(&mut encoder, warm);
            queue.submit([encoder.finish()]);
        }
        let state = read_back(&device, &queue, gpu.state(), 0, 60);
        let iterations = u32::from_le_bytes(state[24..28].try_into().unwrap());
        let tail_ratio = f32::from_le_bytes(state[52..56].try_into().unwrap())
            .clamp(0.0, bevy_mesostructure::translucency::transport::MAX_TAIL_RATIO);
        assert_eq!(u32::from_le_bytes(state[56..60].try_into().unwrap()), 1, "warm");
        assert_eq!(iterations, cpu.iterations, "{row_lanes:?}");
        assert!(
            (tail_ratio - cpu.tail_ratio).abs() <= 1e-4,
            "{row_lanes:?}: tail ratio {tail_ratio} on the GPU, {} on the CPU",
            cpu.tail_ratio
        );
        let (peak, worst, _) = peak_and_worst(&device, &queue, &gpu, &cpu.exitance);
        eprintln!(
            "warm {row_lanes:?}: {iterations} iterations (cold {}), worst |GPU − CPU| {:.2e} of peak {peak:.3e}",
            cold.iterations,
            worst / peak
        );
        assert!(peak > 0.0 && worst <= 1e-5 * peak, "warm {row_lanes:?}: worst {worst} of {peak}");

        // The plugin's read-back of the products a solve took (`ProductsReadback`): after
        // this warm solve it asks for one more than it took, and the next warm solve (the
        // spot moved on) recorded with just that many matches `solve_from` with that cap.
        let cap = gpu.recorded_products(true, u32::MAX);
        let mut readback = ProductsReadback::new(&device);
        assert_eq!(readback.products_to_record(cap), cap, "nothing read back yet: the cap");
        let mut encoder = device.create_command_encoder(&CommandEncoderDescriptor::default());
        readback.copy(&mut encoder, &gpu, cap);
        queue.submit([encoder.finish()]);
        readback.map();
        device.poll(PollType::wait_indefinitely()).expect("the GPU finishes");
        let asked = readback.products_to_record(cap);
        assert_eq!(asked, (cpu.iterations + 1).min(cap), "{row_lanes:?}: one more than the {} taken", cpu.iterations);
        let further = direct_light(&patches, Some(&transport), &[spot_round_the_ball(0.026)], &rays);
        let cpu_further = transport.solve_from(&further, limits.threshold, asked, Some(&cpu));
        gpu.write_direct(&queue, &further);
        let mut encoder = device.create_command_encoder(&CommandEncoderDescriptor::default());
        gpu.record_at_most(&mut encoder, true, asked);
        queue.submit([encoder.finish()]);
        let state = read_back(&device, &queue, gpu.state(), 0, 28);
        let taken = u32::from_le_bytes(state[24..28].try_into().unwrap());
        assert_eq!(taken, cpu_further.iterations, "{row_lanes:?}");
        let (peak, worst, _) = peak_and_worst(&device, &queue, &gpu, &cpu_further.exitance);
        eprintln!("read back: {asked} products asked, {taken} taken; worst |GPU − CPU| {:.2e} of peak", worst / peak);
        assert!(peak > 0.0 && worst <= 1e-5 * peak, "read back {row_lanes:?}: worst {worst} of {peak}");
    }
}

/// A warm start (`EnergyTransport::solve_from`, what the plugin does when a light changes):
/// a spot circling the marble ball by a floor 0.75° a frame (the `translucent` example's
/// swing at 60 frames a second), each frame's solve from the last one's, at the defaults
/// (1e-2, at most 16): every frame takes fewer products than a cold start (in all at most
/// 0.7×) and comes closer to the converged exitance (within 5e-4 in relative L1); switched
/// off, the light's exitance dies away (1e-3 of it left at most).
#[test]
fn a_warm_start_follows_a_moving_spot_in_fewer_products() {
    use bevy_mesostructure::translucency::transport::{settle_frames, warm_iterations};
    let (patches, _, transport, rays) = marble_ball_on_a_floor(TransportSettings { beam_table: None, ..default() });
    let relative_l1 = |a: &[Vec3], b: &[Vec3]| {
        let difference: Vec<Vec3> = a.iter().zip(b).map(|(x, y)| *x - *y).collect();
        transport.absolute_flux(&difference) / transport.flux(b)
    };
    let mut last = None;
    let (mut worst_warm, mut worst_cold, mut warm_products, mut cold_products) = (0.0f32, 0.0f32, 0, 0);
    for frame in 0..8 {
        let direct = direct_light(&patches, Some(&transport), &[spot_round_the_ball(frame as f32 * 0.013)], &rays);
        let exact = transport.solve_with(&direct, 1e-7, 500);
        let cold = transport.solve_with(&direct, 1e-2, 16);
        // As the plugin: the first solve cold, the others warm and capped.
        let most = if last.is_some() { warm_iterations(16) } else { 16 };
        let warm = transport.solve_from(&direct, 1e-2, most, last.as_ref());
        if frame > 0 {
            let (w, c) = (relative_l1(&warm.exitance, &exact.exitance), relative_l1(&cold.exitance, &exact.exitance));
            eprintln!("frame {frame}: warm {} products, {w:.2e} off; cold {}, {c:.2e}", warm.iterations, cold.iterations);
            assert!(warm.iterations < cold.iterations, "frame {frame}: {} against {}", warm.iterations, cold.iterations);
            (worst_warm, worst_cold) = (worst_warm.max(w), worst_cold.max(c));
            warm_products += warm.iterations;
            cold_products += cold.iterations;
        }
        last = Some(warm);
    }
    eprintln!("7 frames: {warm_products} products warm, {cold_products} cold; worst {worst_warm:.2e} and {worst_cold:.2e} from the converged B");
    // Measured: 17 products against 28, 3.4e-4 against 2.0e-3 at worst (a warm start stops
    // at a tenth of the threshold).
    assert!(worst_warm <= 5e-4 && worst_warm <= worst_cold, "{worst_warm} against {worst_cold}");
    assert!(warm_products * 10 <= cold_products * 7, "{warm_products} against {cold_products}");
    // Switched off: what is left of the last frame's light.
    let off = bevy_mesostructure::translucency::DirectLight {
        irradiance: vec![Vec3::ZERO; patches.patches.len()],
        ..default()
    };
    let last = last.unwrap();
    // As the plugin does: a warm start of at most `WARM_MAX_ITERATIONS` products, then its
    // settling frames, each warm from the one before.
    let mut dark = transport.solve_from(&off, 1e-2, warm_iterations(16), Some(&last));
    let mut products = dark.iterations;
    for _ in 0..settle_frames(16) {
        dark = transport.solve_from(&off, 1e-2, warm_iterations(16), Some(&dark));
        products += dark.iterations;
    }
    let left = transport.absolute_flux(&dark.exitance) / transport.flux(&last.exitance);
    eprintln!("switched off: {products} products over {} frames, {left:.2e} of the light left", 1 + settle_frames(16));
    // Measured: 19 products over 4 frames, 1.6e-7 left.
    assert!(left <= 1e-3, "{left}");
}

/// The beam table on the GPU (`TransportSettings::beam_table`; a marble ball by a floor and a
/// wall, 600 patches, a small table of 16 walks): (1) the iteration from the CPU's direct
/// light — the table's products (`table_late`, `table_rows`) and `K` on the rest of `E⁰` —
/// against `solve_with`; (2) the injection's beams (each patch's table direction, the
/// boundary's transmittance) and what the iteration makes of them against the CPU's shadow
/// rays, as the injection's own test holds them.
#[test]
fn the_gpu_beam_table_matches_the_cpu_oracle() {
    if !gpu_or_skip() {
        return;
    }
    let app = bare_app();
    let (device, queue) = device_and_queue(&app);
    let table = bevy_mesostructure::translucency::beam_table::BeamTableSettings {
        walks: 16,
        late_walks: 64,
        ..default()
    };
    let (patches, albedo, transport, rays) =
        marble_ball_on_a_floor(TransportSettings { beam_table: Some(table), ..default() });
    let lights = [spot_on_the_ball()];
    let direct = direct_light(&patches, Some(&transport), &lights, &rays);
    assert!(direct.beam_light.iter().any(|e| *e != Vec3::ZERO), "the table carries the spot");
    let n = patches.patches.len();
    let limits = IterationLimits { threshold: 1e-4, max_iterations: 60 };
    let exitance_of = |gpu: &GpuTransport| -> Vec<Vec3> {
        let (buffer, range) = gpu.exitance();
        let bytes = read_back(&device, &queue, buffer, range.start, range.end - range.start);
        bytemuck::cast_slice::<u8, [f32; 4]>(&bytes).iter().map(|g| Vec3::new(g[0], g[1], g[2])).collect()
    };
    let cpu = transport.solve_with(&direct, limits.threshold, limits.max_iterations);
    let peak = cpu.exitance.iter().map(|b| b.max_element()).fold(0.0, f32::max);
    // The worst channel of `gpu`'s exitance against a CPU solution's.
    let worst_against = |gpu: &GpuTransport, cpu: &[Vec3]| {
        exitance_of(gpu).iter().zip(cpu).map(|(g, c)| (*g - *c).abs().max_element()).fold(0.0, f32::max)
    };

    // (1) The CPU's direct light, iterated on the GPU, with the table's light flow.
    let settings = TransportSettings { beam_table: Some(table), ..default() };
    let surfaces = marble_ball_surfaces();
    let exit_laws = transport.exit_laws(&patches, &surfaces, &settings);
    let depths = EnergyTransport::source_depths(&patches, &surfaces);
    let frames = FlowFrame::of(&patches, &exit_laws, &depths);
    let gpu = GpuTransport::with_flow(&device, &transport, limits, RowLanes::Cpu, &frames);
    gpu.write_direct(&queue, &direct);
    let mut encoder = device.create_command_encoder(&CommandEncoderDescriptor::default());
    gpu.record(&mut encoder, false);
    queue.submit([encoder.finish()]);
    let worst = worst_against(&gpu, &cpu.exitance);
    eprintln!("iteration with the table: worst |GPU − CPU| {:.2e} of the peak", worst / peak);
    assert_eq!(exitance_of(&gpu).len(), n);
    assert!(peak > 0.0 && worst <= 1e-5 * peak, "worst {worst} of {peak}");
    // And warm-started after the spot moved 0.75° (`solve_from`: the table's light is not
    // `K`'s in the warm start's first bounce either).
    let moved = direct_light(&patches, Some(&transport), &[spot_round_the_ball(0.013)], &rays);
    let warm_cpu = transport.solve_from(
        &moved,
        limits.threshold,
        bevy_mesostructure::translucency::transport::warm_iterations(limits.max_iterations),
        Some(&cpu),
    );
    let warm_gpu = GpuTransport::with_flow(&device, &transport, limits, RowLanes::Cpu, &frames);
    for (light, warm) in [(&direct, false), (&moved, true)] {
        warm_gpu.write_direct(&queue, light);
        let mut encoder = device.create_command_encoder(&CommandEncoderDescriptor::default());
        warm_gpu.record(&mut encoder, warm);
        queue.submit([encoder.finish()]);
    }
    let worst = worst_against(&warm_gpu, &warm_cpu.exitance);
    eprintln!(
        "warm with the table: {} iterations (cold {}), worst |GPU − CPU| {:.2e} of the peak",
        warm_cpu.iterations,
        cpu.iterations,
        worst / peak
    );
    assert!(worst <= 1e-5 * peak, "warm: worst {worst} of {peak}");
    // Each patch's flow (`table_rows`) against `exit_laws_along_flow`: the axis and its 1/N.
    let flow_at = gpu.flow_offset().expect("the table's flow") as u64 * 16;
    let bytes = read_back(&device, &queue, gpu.vectors(), flow_at, 3 * n as u64 * 16);
    let gpu_flows = bytemuck::cast_slice::<u8, [f32; 4]>(&bytes);
    let cpu_laws = transport.exit_laws_along_flow(&patches, &exit_laws, &direct, &depths);
    let (mut flowing, mut worst_axis, mut worst_norm) = (0, 0.0f32, 0.0f32);
    for (i, law) in cpu_laws.iter().enumerate() {
        for c in 0..3 {
            let (g, want) = (Vec4::from_array(gpu_flows[3 * i + c]), law.flow[c]);
            worst_axis = worst_axis.max((g.truncate() - want.truncate()).abs().max_element());
            if want != Vec4::ZERO {
                flowing += 1;
                worst_norm = worst_norm.max((g.w / want.w - 1.0).abs());
            } else {
                assert_eq!(g.w, 0.0, "patch {i} channel {c}: a flow where the CPU has none");
            }
        }
    }
    eprintln!("flow: {flowing} patch channels; worst axis |GPU − CPU| {worst_axis:.1e}, 1/N {worst_norm:.1e}");
    assert!(flowing >= 100 && worst_axis <= 1e-4 && worst_norm <= 1e-4, "{flowing}: {worst_axis}, {worst_norm}");

    // (2) Injected on the GPU from the spot's view.
    let gpu = GpuTransport::new(&device, &transport, limits, RowLanes::Cpu);
    let mut injection = GpuInjection::new(&device, &patches, &transport, &albedo, &gpu, 512, &[]);
    let ((agree, flux), _) = injection_against_shadow_rays(
        (&device, &queue),
        &mut injection,
        &gpu,
        (&patches, &albedo, &transport, &rays),
        &lights,
        Vec3::ZERO,
        "beam table, spot",
    );
    let mut encoder = device.create_command_encoder(&CommandEncoderDescriptor::default());
    gpu.record(&mut encoder, false);
    queue.submit([encoder.finish()]);
    let exitance = exitance_of(&gpu);
    let off: f32 = exitance.iter().zip(&cpu.exitance).zip(&transport.areas).map(|((g, c), a)| (*g - *c).abs().element_sum() * a).sum();
    let total: f32 = cpu.exitance.iter().zip(&transport.areas).map(|(c, a)| c.element_sum() * a).sum();
    eprintln!("injected: E⁰ within 2 % on {:.1} %, flux L1 {flux:.4}; B flux relative L1 {:.4}", 100.0 * agree, off / total);
    assert!(agree >= 0.98 && flux <= 0.01, "E⁰: {agree}, {flux}");
    assert!(off / total <= 0.01, "B: {}", off / total);
    // The lit faces' single scattering the first bounce gathers (`lit_face_exitance`),
    // injected per light, against the CPU's: its flux within 1 % (the shadow map's edges).
    let lit_at = gpu.beam_offsets().lit_face as u64 * 16;
    let bytes = read_back(&device, &queue, gpu.vectors(), lit_at, n as u64 * 16);
    let gpu_lit: Vec<Vec3> = bytemuck::cast_slice::<u8, [f32; 4]>(&bytes).iter().map(|g| Vec3::new(g[0], g[1], g[2])).collect();
    let lit_off: f32 = gpu_lit.iter().zip(&direct.lit_face_exitance).zip(&transport.areas).map(|((g, c), a)| (*g - *c).abs().element_sum() * a).sum();
    let lit_total: f32 = direct.lit_face_exitance.iter().zip(&transport.areas).map(|(c, a)| c.element_sum() * a).sum();
    eprintln!("lit faces' single scattering: flux relative L1 {:.4} of {lit_total:.3e}", lit_off / lit_total);
    assert!(lit_total > 0.0 && lit_off / lit_total <= 0.01, "lit faces: {lit_off} of {lit_total}");

    // (3) Each patch's exit lobes (`table_lobes_of`) against `ExitLaw::set_far_lobes`: the
    // light from afar, and each lobe's axis, κ and norm. Marble's 16 scatterings stay within
    // two of this ball's patches, so the ball is skin here, 2.5 mm across in its medium's
    // terms (a lobe whose mean falls within rounding of the fit table's cell boundary may
    // take the next cell: counted, not compared).
    let mut surfaces = marble_ball_surfaces();
    surfaces[0] = PatchSurface::Translucent {
        medium: TranslucentPreset::Skin1.medium(),
        world_units_per_mm: 0.02,
        oriented_dipole: false,
    };
    let rays = SceneRays::new(&marble_ball_objects().iter().map(|o| PatchObject { positions: &o.0, indices: &o.1 }).collect::<Vec<_>>());
    let transport = EnergyTransport::build(&patches, &surfaces, &rays, &settings);
    let direct = direct_light(&patches, Some(&transport), &lights, &rays);
    let exit_laws = transport.exit_laws(&patches, &surfaces, &settings);
    let depths = EnergyTransport::source_depths(&patches, &surfaces);
    let gpu = GpuTransport::with_flow(&device, &transport, limits, RowLanes::Cpu, &FlowFrame::of(&patches, &exit_laws, &depths));
    gpu.write_direct(&queue, &direct);
    let mut encoder = device.create_command_encoder(&CommandEncoderDescriptor::default());
    gpu.record(&mut encoder, false);
    queue.submit([encoder.finish()]);
    let cpu_laws = transport.exit_laws_along_flow(&patches, &exit_laws, &direct, &depths);
    let lobes_at = gpu.lobes_offset().expect("the table's lobes") as u64 * 16;
    let bytes = read_back(&device, &queue, gpu.vectors(), lobes_at, 5 * n as u64 * 16);
    let gpu_lobes = bytemuck::cast_slice::<u8, [f32; 4]>(&bytes);
    let (mut lobed, mut other_cell, mut worst_far, mut worst_lobe) = (0, 0, 0.0f32, 0.0f32);
    let far_peak = cpu_laws.iter().map(|l| l.lobe_exitance.max_element()).fold(0.0, f32::max);
    for (i, law) in cpu_laws.iter().enumerate() {
        let (norms, far) = (Vec4::from_array(gpu_lobes[5 * i + 3]), Vec4::from_array(gpu_lobes[5 * i + 4]));
        worst_far = worst_far.max((far.truncate() - law.lobe_exitance).abs().max_element() / far_peak);
        for c in 0..3 {
            let (g, want) = (Vec4::from_array(gpu_lobes[5 * i + c]), law.lobes[c]);
            if want.norm == 0.0 {
                assert_eq!(norms[c], 0.0, "patch {i} channel {c}: a lobe where the CPU has none");
                continue;
            }
            lobed += 1;
            if (g.w - want.sharpness).abs() > 1e-4 * want.sharpness.max(1.0) {
                other_cell += 1;
                continue;
            }
            let off = (g.truncate() - want.axis).abs().max_element().max((norms[c] / want.norm - 1.0).abs());
            worst_lobe = worst_lobe.max(off);
        }
    }
    eprintln!(
        "exit lobes: {lobed} patch channels, {other_cell} in a neighbouring cell; light from afar within \
         {worst_far:.1e} of its peak, axis and norm within {worst_lobe:.1e}"
    );
    assert!(lobed >= 50 && far_peak > 0.0, "{lobed} lobes, peak {far_peak}");
    assert!(other_cell * 100 <= lobed && worst_far <= 1e-5 && worst_lobe <= 1e-4, "{other_cell}, {worst_far}, {worst_lobe}");
}

/// Whether the translucency's precompute is ready.
/// How far the GPU's injection is from the CPU's shadow rays: the share of the patches the
/// light reaches (either way) that agree within 2 % of the brightest patch's irradiance, and
/// the relative L1 of the flux `Σ |E_gpu − E_cpu| A / Σ E_cpu A` (irradiance, then exitance
/// `S⁰`).
fn injection_error(
    gpu: &[[f32; 4]],
    cpu: &[Vec3],
    areas: &[f32],
) -> (f32, f32) {
    let peak = cpu.iter().map(|e| e.max_element()).fold(0.0, f32::max);
    let (mut lit, mut agree, mut off, mut total) = (0, 0, 0.0, 0.0);
    for ((g, c), a) in gpu.iter().zip(cpu).zip(areas) {
        let g = Vec3::new(g[0], g[1], g[2]);
        if g.max_element() > 0.0 || c.max_element() > 0.0 {
            lit += 1;
            if (g - *c).abs().max_element() <= 0.02 * peak {
                agree += 1;
            }
        }
        off += (g - *c).abs().element_sum() * a;
        total += c.abs().element_sum() * a;
    }
    (agree as f32 / lit.max(1) as f32, off / total)
}

#[test]
fn the_gpu_light_injection_matches_the_shadow_rays() {
    if !gpu_or_skip() {
        return;
    }
    let app = bare_app();
    let (device, queue) = device_and_queue(&app);

    // The scaled dipole weighs each beam by its incidence; the dipole adds single scattering.
    for kernel in [DiffusionKernel::ScaledDipole, DiffusionKernel::Dipole] {
        let (patches, albedo, transport, rays) =
            marble_ball_on_a_floor(TransportSettings { kernel, beam_table: None, ..default() });
        let gpu_transport = GpuTransport::new(
            &device,
            &transport,
            IterationLimits {
                threshold: 1e-3,
                max_iterations: 8,
            },
            RowLanes::Gpu,
        );
        let cases: [(&str, Vec<PatchLight>); 5] = [
            ("ambient alone", vec![]),
            (
                "directional",
                vec![PatchLight::Directional {
                    direction: Vec3::new(-0.5, -1.0, -0.3).normalize(),
                    illuminance: Vec3::new(1000.0, 900.0, 800.0),
                }],
            ),
            (
                "point",
                vec![PatchLight::Point {
                    position: Vec3::new(0.12, 0.18, -0.05),
                    intensity: Vec3::splat(50.0),
                    range: 1.0,
                }],
            ),
            (
                "spot",
                vec![spot_on_the_ball()],
            ),
            (
                "all three and ambient",
                vec![
                    PatchLight::Directional {
                        direction: Vec3::new(-0.5, -1.0, -0.3).normalize(),
                        illuminance: Vec3::new(1000.0, 900.0, 800.0),
                    },
                    PatchLight::Point {
                        position: Vec3::new(0.12, 0.18, -0.05),
                        intensity: Vec3::splat(50.0),
                        range: 1.0,
                    },
                    spot_on_the_ball(),
                ],
            ),
        ];
        for resolution in [256, 512] {
            let mut injection = GpuInjection::new(
                &device,
                &patches,
                &transport,
                &albedo,
                &gpu_transport,
                resolution,
                &[],
            );
            for (name, lights) in &cases {
                let ambient = if name.contains("ambient") { Vec3::splat(20.0) } else { Vec3::ZERO };
                let label = format!("{kernel:?} {resolution}² {name}");
                let (e, s) = injection_against_shadow_rays(
                    (&device, &queue),
                    &mut injection,
                    &gpu_transport,
                    (&patches, &albedo, &transport, &rays),
                    lights,
                    ambient,
                    &label,
                );
                // Measured: all the patches agree but for a few at shadow edges, where a patch
                // takes a share of 3×3 texels and a ray from its centre all or nothing — at
                // 512² 98.9–99.7 % of them (flux 0.09–0.23 % apart), at 256² 97.7–99.4 %
                // (0.17–0.67 %); with Bevy's ambient alone, all of them to 1e-6.
                let (least, most) = if resolution >= 512 { (0.98, 0.004) } else { (0.96, 0.01) };
                assert!(e.0 >= least && e.1 <= most, "{label}: {e:?}");
                // S⁰: measured 1e-4 (the incidence table's interpolation; the ball is
                // unshadowed); all zero with no light.
                if let Some(s) = s {
                    assert!(lights.is_empty() || (s.0 >= 0.99 && s.1 <= 1e-3), "S⁰ {label}: {s:?}");
                }
            }
        }
    }
}

/// One injection on the GPU against [`direct_light`]'s shadow rays (plus the ambient on
/// translucent patches): [`injection_error`] of `E⁰`, and of `S⁰` where there is one.
#[allow(clippy::type_complexity)]
fn injection_against_shadow_rays(
    (device, queue): (&RenderDevice, &RenderQueue),
    injection: &mut GpuInjection,
    gpu_transport: &GpuTransport,
    (patches, albedo, transport, rays): (&Patches, &[Vec3], &EnergyTransport, &SceneRays),
    lights: &[PatchLight],
    ambient: Vec3,
    label: &str,
) -> ((f32, f32), Option<(f32, f32)>) {
    let n = patches.patches.len();
    assert!(lights.len() <= MAX_INJECTED_LIGHTS);
    injection.write_lights(device, queue, lights, ambient);
    let mut encoder = device.create_command_encoder(&CommandEncoderDescriptor::default());
    injection.record(&mut encoder);
    queue.submit([encoder.finish()]);

    let mut cpu = direct_light(patches, Some(transport), lights, rays);
    for (e, a) in cpu.irradiance.iter_mut().zip(albedo) {
        if *a == Vec3::ZERO {
            *e += ambient;
        }
    }
    let (direct, direct_exitance) = gpu_transport.direct_offsets();
    let (buffer, _) = gpu_transport.exitance();
    let read = |at: u32| {
        let bytes = read_back(device, queue, buffer, at as u64 * 16, n as u64 * 16);
        bytemuck::cast_slice::<u8, [f32; 4]>(&bytes).to_vec()
    };
    let e = injection_error(&read(direct), &cpu.irradiance, &transport.areas);
    eprintln!(
        "{label}: E⁰ agrees within 2 % of the peak on {:.1} % of the lit patches; flux relative L1 {:.4}",
        100.0 * e.0,
        e.1
    );
    let s = (!cpu.exitance.is_empty()).then(|| {
        let s = injection_error(&read(direct_exitance), &cpu.exitance, &transport.areas);
        eprintln!(
            "    S⁰: within 2 % of the peak on {:.1} %; relative L1 {:.4}",
            100.0 * s.0,
            s.1
        );
        s
    });
    (e, s)
}

// Only `translucent_room` is used here.
#[allow(dead_code)]
#[path = "../../examples/common/translucent_scene.rs"]
mod translucent_scene;

#[test]
fn the_gpu_light_injection_matches_the_shadow_rays_in_the_examples_room() {
    if !gpu_or_skip() {
        return;
    }
    let app = bare_app();
    let (device, queue) = device_and_queue(&app);
    // The `translucent` example's closed room: a marble bunny (its ears shadow its back) and a
    // skin sphere on the floor, coloured walls, 4000 patches as the plugin makes them.
    let scene =
        translucent_scene::translucent_room(&crate::meshes::asset_path("meshes/bunny.obj"));
    let views: Vec<PatchObject> = scene.iter().map(|o| o.view()).collect();
    let surfaces: Vec<PatchSurface> = scene.iter().map(|o| o.surface).collect();
    let settings = TransportSettings { beam_table: None, ..default() };
    let caps: Vec<Option<f32>> = surfaces
        .iter()
        .map(|s| translucent_patch_cap(s, &settings))
        .collect();
    let patches = resample_into_patches_with_caps(&views, &caps, 4000);
    let rays = SceneRays::new(&views);
    let mut transport = EnergyTransport::build(&patches, &surfaces, &rays, &settings);
    transport.incidence = EnergyTransport::incidence_weights(&surfaces, &settings);
    let albedo = patch_albedos(&patches, &surfaces);
    let gpu_transport = GpuTransport::new(
        &device,
        &transport,
        IterationLimits {
            threshold: 1e-3,
            max_iterations: 8,
        },
        RowLanes::Gpu,
    );
    let mut injection =
        GpuInjection::new(&device, &patches, &transport, &albedo, &gpu_transport, 512, &[]);
    // The example's spot in front of the objects, beside them and behind them (aimed as the
    // example aims it), and a point light under the ceiling.
    let spot = |s: f32| {
        let angle = s * std::f32::consts::PI;
        let position = Vec3::new(0.25 * angle.sin(), 0.2, 0.25 * angle.cos());
        PatchLight::Spot {
            position,
            direction: (Vec3::new(0.0, 0.04, 0.0) - position).normalize(),
            intensity: Vec3::splat(800.0 / (4.0 * std::f32::consts::PI)),
            inner_angle: 0.3,
            outer_angle: 0.5,
            range: 5.0,
        }
    };
    let point = PatchLight::Point {
        position: Vec3::new(0.1, 0.5, -0.1),
        intensity: Vec3::splat(30.0),
        range: 5.0,
    };
    for (name, lights) in [
        ("spot in front", vec![spot(0.0)]),
        ("spot beside", vec![spot(0.5)]),
        ("spot behind", vec![spot(1.0)]),
        ("point under the ceiling", vec![point]),
    ] {
        let (e, s) = injection_against_shadow_rays(
            (&device, &queue),
            &mut injection,
            &gpu_transport,
            (&patches, &albedo, &transport, &rays),
            &lights,
            Vec3::ZERO,
            &format!("room, {name}"),
        );
        // Measured 98.7–100 % of the lit patches within 2 % of the peak, the flux
        // 0.0002–0.0082 apart (the spot's shadow edges on the floor and the bunny).
        assert!(e.0 >= 0.98 && e.1 <= 0.015, "{name}: {e:?}");
        assert!(s.is_none(), "the scaled dipole has no single-scattering term");
    }
}


fn ready(app: &App) -> bool {
    matches!(
        app.world()
            .resource::<bevy_mesostructure::translucency::TranslucencyStatus>(),
        bevy_mesostructure::translucency::TranslucencyStatus::Ready { .. }
    )
}

/// Runs frames until the precompute (a background task) is ready; fails after 600.
fn run_until_ready(app: &mut App) {
    for _ in 0..600 {
        run(app, 1);
        if ready(app) {
            return;
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    panic!("the precompute never finished");
}

/// sRGB-encoded 8-bit value of a linear one.
fn srgb8(linear: f32) -> f32 {
    let c = linear.clamp(0.0, 1.0);
    let s = if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    s * 255.0
}

/// White, rough and without specular (F0 = 0): the picture is the patches' light alone.
fn matte_white(app: &mut App) -> Handle<StandardMaterial> {
    app.world_mut()
        .resource_mut::<Assets<StandardMaterial>>()
        .add(StandardMaterial {
            base_color: Color::WHITE,
            reflectance: 0.0,
            perceptual_roughness: 1.0,
            ..default()
        })
}

/// An HDR camera showing the translucency into `image` from `eye`, untonemapped: the plugin
/// lets its main images take storage writes, so the gather runs in its compute form.
fn hdr_translucency_camera(app: &mut App, image: &Handle<Image>, eye: Transform) -> Entity {
    let camera = translucency_camera(app, image, eye);
    app.world_mut().entity_mut(camera).insert(bevy::camera::Hdr);
    camera
}

/// A translucency camera drawing into `image` from `eye`, untonemapped, without MSAA.
fn translucency_camera(app: &mut App, image: &Handle<Image>, eye: Transform) -> Entity {
    use bevy::{camera::RenderTarget, core_pipeline::tonemapping::Tonemapping};
    app.world_mut()
        .spawn((
            Camera3d::default(),
            RenderTarget::Image(image.clone().into()),
            Msaa::Off,
            Tonemapping::None,
            bevy_mesostructure::translucency::TranslucencyCamera,
            eye,
        ))
        .id()
}

/// The largest difference (of 255) between `computed`, the picture `camera` took with the
/// gather's compute form, and the one its fragment form draws once the camera's main images
/// take no storage writes (left so).
fn fragment_gather_difference(
    app: &mut App,
    camera: Entity,
    image: &Handle<Image>,
    computed: &Image,
) -> u8 {
    use bevy::{camera::CameraMainTextureUsages, render::render_resource::TextureUsages};
    let usages = app.world().get::<CameraMainTextureUsages>(camera).unwrap().0;
    assert!(usages.contains(TextureUsages::STORAGE_BINDING), "the plugin asks for storage");
    app.world_mut()
        .entity_mut(camera)
        .insert(CameraMainTextureUsages::default());
    run(app, 2);
    let fragment = screenshot(app, image);
    let (a, b) = (computed.data.as_ref().unwrap(), fragment.data.as_ref().unwrap());
    a.iter().zip(b).map(|(p, q)| p.abs_diff(*q)).max().unwrap()
}

/// An app for the GPU's march against its twin (`None` where there is no GPU to skip on):
/// the translucency plugin, no ambient light, every pixel gathered as the twin does, and a
/// beam table that leaves single scattering to the march, of few walks (the GPU and its twin
/// share the table, and a full one would keep both cores from the tests rendering beside
/// this one for ~20 s).
fn marching_app() -> Option<App> {
    use bevy::light::GlobalAmbientLight;
    use bevy_mesostructure::translucency::{
        GatherResolution, TranslucencyPlugin, TranslucencySettings, beam_table::BeamTableSettings,
    };
    if !gpu_or_skip() {
        return None;
    }
    let mut app = bare_app_with(|app| {
        app.add_plugins(TranslucencyPlugin);
    });
    app.insert_resource(GlobalAmbientLight { brightness: 0.0, ..default() });
    app.insert_resource(TranslucencySettings {
        patch_budget: 500,
        gather_resolution: GatherResolution::Full,
        transport: TransportSettings {
            beam_table: Some(BeamTableSettings { walks: 32, late_walks: 128, ..default() }),
            ..default()
        },
        ..default()
    });
    Some(app)
}

/// The pixels of `camera`'s `size`² view whose ray `hit` meets something (the point, its unit
/// normal towards the camera) facing the camera at a cosine of 0.3 or more (the outline's
/// grazing ones left out): (x, y, the point, the normal), and where the camera stands.
fn pixels_seen(
    app: &mut App,
    camera: Entity,
    size: u32,
    hit: impl Fn(Vec3, Vec3) -> Option<(Vec3, Vec3)>,
) -> (Vec<(u32, u32, Vec3, Vec3)>, Vec3) {
    let (camera_component, camera_transform) = app
        .world_mut()
        .query::<(&Camera, &GlobalTransform)>()
        .get(app.world(), camera)
        .map(|(c, t)| (c.clone(), *t))
        .expect("the camera");
    let pixels = (0..size * size)
        .filter_map(|k| {
            let (x, y) = (k % size, k / size);
            let ray = camera_component.viewport_to_world(&camera_transform, Vec2::new(x as f32 + 0.5, y as f32 + 0.5)).ok()?;
            let (point, n) = hit(ray.origin, *ray.direction)?;
            (n.dot(-*ray.direction) >= 0.3).then_some((x, y, point, n))
        })
        .collect();
    (pixels, camera_transform.translation())
}

/// The pixels of `camera`'s `size`² view that see the mesh `positions`, `indices` at a
/// cosine of 0.3 or more (where the facets and their smooth normals part): (x, y, the point,
/// its face's normal towards the camera), and where the camera stands, for
/// [`marched_against_its_twin`].
fn pixels_facing_the_camera(app: &mut App, camera: Entity, size: u32, positions: &[Vec3], indices: &[u32]) -> (Vec<(u32, u32, Vec3, Vec3)>, Vec3) {
    use bevy_mesostructure::translucency::{PatchObject, SceneRays};
    let rays = SceneRays::new(&[PatchObject { positions, indices }]);
    pixels_seen(app, camera, size, |o, d| {
        let (t, normal) = rays.first_hit(o, d)?;
        Some((o + d * t, if normal.dot(d) < 0.0 { normal } else { -normal }))
    })
}

/// The pixels of `camera`'s `size`² view that see a ball of `radius` about the origin (the
/// sphere, not its mesh) at a cosine of 0.3 or more, the rim left out where the mesh and the
/// sphere part: (x, y, the view ray's hit on the sphere, its normal), and where the camera
/// stands.
fn ball_pixels_seen(app: &mut App, camera: Entity, size: u32, radius: f32) -> (Vec<(u32, u32, Vec3, Vec3)>, Vec3) {
    pixels_seen(app, camera, size, |o, d| {
        let b = o.dot(d);
        let disc = b * b - (o.length_squared() - radius * radius);
        let hit = (disc > 0.0).then(|| o + d * (-b - disc.sqrt()))?;
        Some((hit, hit.normalize()))
    })
}

/// The GPU's picture of `image` with single scattering marched per pixel against its CPU twin
/// (`MarchedObject` in `gathered_radiance`), the scene's first object marching, over `pixels`
/// (x, y, the view ray's hit, its normal) seen from `eye`: (pixels, mean |GPU − CPU|, worst,
/// pixels the march gives more than 2/255).
fn marched_against_its_twin(app: &mut App, image: &Handle<Image>, pixels: &[(u32, u32, Vec3, Vec3)], eye: Vec3) -> (usize, f32, f32, usize) {
    use bevy::camera::Exposure;
    use bevy_mesostructure::translucency::{
        GatherMethod, TranslucencyFrame, direct_light,
        gather::gathered_radiance,
        translucent_shadow_map::{MarchedObject, PLUGIN_RESOLUTION},
    };
    let exposure = Exposure::default().exposure();
    let frame = app.world().resource::<TranslucencyFrame>().clone();
    let (_, scene) = frame.scene.expect("a scene");
    let table = scene.transport.beam_table.as_ref().expect("the scene has its beam table");
    assert!(table.settings.single_scattering_to_pixels, "the table leaves single scattering to the pixels");
    let (_, lights) = frame.lights.expect("the GPU injects the light");
    let direct = direct_light(&scene.patches, Some(&scene.transport), &lights.lights, &scene.rays);
    let solution = scene.transport.solve_with(&direct, frame.settings.iteration_threshold, frame.settings.max_iterations);
    let exit_laws = scene.transport.exit_laws_along_flow(&scene.patches, &scene.exit_laws, &direct, &scene.source_depths);
    let medium = scene.marched.first().copied().flatten().expect("the object marches");
    let objects = [Some(MarchedObject::new(&scene.patches.samples, medium, &lights.lights, PLUGIN_RESOLUTION, |_, _| 1.0))];
    let shot = screenshot(app, image);
    let (mut compared, mut sum_error, mut worst, mut marching) = (0, 0.0f32, 0.0f32, 0);
    for &(x, y, hit, n) in pixels {
        let twin = |marched: Option<&[Option<MarchedObject>]>| {
            gathered_radiance(
                GatherMethod::Interpolation,
                &scene.patches,
                &scene.albedo,
                &exit_laws,
                &direct.irradiance,
                &solution.irradiance,
                &solution.exitance,
                None,
                marched,
                eye,
                hit,
                n,
            )
            .map_or(0.0, |l| l.x * exposure)
        };
        let expected = twin(Some(&objects));
        let error = (shot.get_color_at(x, y).unwrap().to_srgba().red * 255.0 - srgb8(expected)).abs();
        compared += 1;
        sum_error += error;
        worst = worst.max(error);
        // Where the march gives a pixel light of its own.
        if srgb8(expected) - srgb8(twin(None)) > 2.0 {
            marching += 1;
        }
    }
    (compared, sum_error / compared.max(1) as f32, worst, marching)
}

/// `marching_app`'s settings for a GPU gather against its CPU twin: the CPU's shadow rays (no
/// maps, no march: the twin iterates their very `E⁰`) and a smaller beam table, so that the
/// patches' light from elsewhere flows and leaves by its law.
fn shadow_rays_and_a_small_table(app: &mut App) {
    use bevy_mesostructure::translucency::{LightInjection, TranslucencySettings, beam_table::BeamTableSettings};
    let mut settings = app.world_mut().resource_mut::<TranslucencySettings>();
    settings.patch_budget = 600;
    settings.light_injection = LightInjection::ShadowRays;
    settings.transport.beam_table = Some(BeamTableSettings { walks: 16, late_walks: 64, ..default() });
}

/// The GPU's picture `shot` against the gather's CPU twin (interpolated, the lit face's single
/// scattering, no march) over `pixels` seen from `eye`, in red: the twin with the exit `laws`,
/// each patch's own light `received` and its `exitance`. |GPU − twin| in 8-bit sRGB: (mean,
/// worst).
#[allow(clippy::too_many_arguments)]
fn gathered_against_twin(
    shot: &Image,
    scene: &bevy_mesostructure::translucency::TranslucencyScene,
    laws: &[bevy_mesostructure::translucency::ExitLaw],
    direct: &bevy_mesostructure::translucency::DirectLight,
    received: &[Vec3],
    exitance: &[Vec3],
    pixels: &[(u32, u32, Vec3, Vec3)],
    eye: Vec3,
) -> (f32, f32) {
    use bevy::camera::Exposure;
    use bevy_mesostructure::translucency::{GatherMethod, gather::{BeamSingleScattering, gathered_radiance}};
    let table = scene.transport.beam_table.as_ref().expect("the scene has its beam table");
    let media = table.patch_media();
    let single = BeamSingleScattering { irradiance: &direct.beam_irradiance, direction: &direct.beam_direction, media: &media };
    let exposure = Exposure::default().exposure();
    let (mut sum, mut worst) = (0.0f32, 0.0f32);
    for &(x, y, hit, n) in pixels {
        let expected = gathered_radiance(
            GatherMethod::Interpolation,
            &scene.patches,
            &scene.albedo,
            laws,
            &direct.irradiance,
            received,
            exitance,
            Some(&single),
            None,
            eye,
            hit,
            n,
        )
        .map_or(0.0, |l| l.x * exposure);
        let error = (shot.get_color_at(x, y).unwrap().to_srgba().red * 255.0 - srgb8(expected)).abs();
        sum += error;
        worst = worst.max(error);
    }
    (sum / pixels.len().max(1) as f32, worst)
}

/// `app`'s 64² HDR frame from `eye` once its translucency is ready (the gather's pipelines
/// built), and what the gather drew from: the scene, the frame's direct light, the transport
/// solved for it, and the pixels of the ball of `radius` at the origin with the eye.
struct GatheredFrame {
    shot: Image,
    scene: std::sync::Arc<bevy_mesostructure::translucency::TranslucencyScene>,
    direct: std::sync::Arc<bevy_mesostructure::translucency::DirectLight>,
    solution: bevy_mesostructure::translucency::transport::TransportSolution,
    ball_pixels: Vec<(u32, u32, Vec3, Vec3)>,
    eye: Vec3,
}

fn gathered_frame(app: &mut App, eye: Transform, radius: f32) -> GatheredFrame {
    use bevy_mesostructure::translucency::TranslucencyFrame;
    let size = 64;
    let image = target(app, size, size);
    let camera = hdr_translucency_camera(app, &image, eye);
    run_until_ready(app);
    run(app, 3);
    assert_pipelines_ready_with_prefix(app, "translucency_gather");
    let shot = screenshot(app, &image);
    let frame = app.world().resource::<TranslucencyFrame>().clone();
    let (_, scene) = frame.scene.expect("a scene");
    let (_, direct) = frame.direct.expect("the light injected");
    let solution = scene.transport.solve_with(&direct, frame.settings.iteration_threshold, frame.settings.max_iterations);
    let (ball_pixels, eye) = ball_pixels_seen(app, camera, size, radius);
    GatheredFrame { shot, scene, direct, solution, ball_pixels, eye }
}

/// Light bounced onto a translucent object leaves it as its own light does, on the GPU as in
/// its CPU twin: a ball 1 cm above a white floor, the sun from above, so the floor lights the
/// ball's underside. The gather's exit law takes each patch's irradiance direct and bounced
/// (the iteration's `E`, `GatherParams::irradiance`) as the patch's own; before 2026-11-29 it
/// took the direct light alone, and gave the bounced light out by the law of the light that
/// flowed from elsewhere in the object (docs/translucent.md, "Over a floor"). The twin with
/// the direct light alone is held away from the GPU's picture, so the test sees which one
/// the GPU reads.
#[test]
fn light_bounced_onto_a_translucent_object_leaves_as_its_own_on_the_gpu() {
    use bevy_mesostructure::translucency::Translucent;
    let Some(mut app) = marching_app() else {
        return;
    };
    shadow_rays_and_a_small_table(&mut app);
    let light_travel = Vec3::new(-0.5, -1.0, -0.3).normalize();
    sun(&mut app, light_travel, 2_000.0);
    let radius = 0.05;
    let ball = mesh(&mut app, Sphere::new(radius).mesh().uv(64, 32));
    let material = matte_white(&mut app);
    app.world_mut().spawn((ball, MeshMaterial3d(material.clone()), Translucent::default(), Transform::IDENTITY));
    let floor = mesh(&mut app, Plane3d::default().mesh().size(0.4, 0.4));
    app.world_mut().spawn((
        floor,
        MeshMaterial3d(material),
        bevy_mesostructure::translucency::RadiosityReceiver,
        Transform::from_xyz(0.0, -radius - 0.01, 0.0),
    ));
    let eye = Transform::from_xyz(0.0, -0.03, 0.25).looking_at(Vec3::new(0.0, -0.03, 0.0), Vec3::Y);
    let GatheredFrame { shot, scene, direct, solution, ball_pixels, eye } = gathered_frame(&mut app, eye, radius);
    let exit_laws = scene.transport.exit_laws_along_flow(&scene.patches, &scene.exit_laws, &direct, &scene.source_depths);
    // Translucent patches that take more from the floor than from the sun.
    let bounced = (0..scene.patches.patches.len())
        .filter(|&i| scene.albedo[i] == Vec3::ZERO && solution.irradiance[i].x > 2.0 * direct.irradiance[i].x + 1e-3)
        .count();
    // |GPU − twin| over the ball's pixels, the twin's exit law taking `received` as each
    // patch's own light: (mean, worst).
    let against = |received: &[Vec3]| {
        gathered_against_twin(&shot, &scene, &exit_laws, &direct, received, &solution.exitance, &ball_pixels, eye)
    };
    let (mean, worst) = against(&solution.irradiance);
    let (direct_mean, direct_worst) = against(&direct.irradiance);
    eprintln!(
        "{} pixels, {bounced} translucent patches lit mostly by the floor: |GPU − twin| mean {mean:.2}/255, worst {worst:.1}/255; \
         against the twin taking the direct light alone {direct_mean:.2}/255, worst {direct_worst:.1}/255",
        ball_pixels.len()
    );
    assert!(ball_pixels.len() > 500 && bounced > 20, "{} pixels, {bounced} patches lit by the floor", ball_pixels.len());
    // Measured 0.27/255 mean, 1.2/255 worst (249 patches); the twin taking the direct light
    // alone 2.28 / 9.4 (2.29 / 9.7 before the shape solve's self term from Gauss's identity). With the GPU reading `E⁰` instead (checked by hand, not kept) the test
    // fails: 2.26 / 9.8 against this twin.
    assert!(mean <= 1.0 && worst <= 3.0, "mean {mean}, worst {worst}");
    assert!(direct_worst >= 2.0 * worst.max(3.0), "the twins are too alike to tell apart: worst {direct_worst} against {worst}");
}

/// The flux along the surface (`TransportSettings::tangential_flux`, on by default) on the GPU: a
/// marble ball lit from behind and the side, its gather (the compute form, every pixel)
/// against the CPU twin with the lean and without it. The GPU draws the twin with it; the
/// twin without it is held away from the GPU's picture, so the test sees that the GPU leans.
#[test]
fn the_flux_along_the_surface_leans_the_gpus_gather_as_its_twin_does() {
    use bevy_mesostructure::translucency::{ExitLaw, TranslucencySettings, Translucent};
    let Some(mut app) = marching_app() else {
        return;
    };
    shadow_rays_and_a_small_table(&mut app);
    app.world_mut().resource_mut::<TranslucencySettings>().transport.tangential_flux = true;
    // From behind and the right: the light crosses the ball towards the camera and flows
    // along its surface about the silhouette.
    let light_travel = Vec3::new(-0.6, -0.2, 0.8).normalize();
    sun(&mut app, light_travel, 2_000.0);
    let radius = 0.05;
    let ball = mesh(&mut app, Sphere::new(radius).mesh().uv(64, 32));
    let material = matte_white(&mut app);
    // A ball 1 cm across in the medium's millimetres (5 world millimetres to one): marble's
    // light then flows along its surface over a few of its patches.
    let translucent = Translucent { world_units_per_mm: 0.005, ..default() };
    app.world_mut().spawn((ball, MeshMaterial3d(material), translucent, Transform::IDENTITY));
    let eye = Transform::from_xyz(0.0, 0.0, 0.25).looking_at(Vec3::ZERO, Vec3::Y);
    let GatheredFrame { shot, scene, direct, solution, ball_pixels, eye } = gathered_frame(&mut app, eye, radius);
    let leaning = scene.transport.exit_laws_along_flow(&scene.patches, &scene.exit_laws, &direct, &scene.source_depths);
    assert!(leaning.iter().any(|law| law.tangential != Vec3::ZERO), "no patch takes the flux along the surface");
    let plain: Vec<_> = leaning.iter().map(|law| ExitLaw { tangential: Vec3::ZERO, ..*law }).collect();
    // |GPU − twin| over the ball's pixels: (mean, worst).
    let against = |laws: &[ExitLaw]| {
        gathered_against_twin(&shot, &scene, laws, &direct, &solution.irradiance, &solution.exitance, &ball_pixels, eye)
    };
    let (mean, worst) = against(&leaning);
    let (plain_mean, plain_worst) = against(&plain);
    eprintln!(
        "{} pixels: |GPU − twin| mean {mean:.2}/255, worst {worst:.1}/255; against the twin without the lean {plain_mean:.2}/255, worst {plain_worst:.1}/255",
        ball_pixels.len()
    );
    assert!(ball_pixels.len() > 500, "{} pixels", ball_pixels.len());
    // Measured 0.29/255 mean, 1.4/255 worst (1.3 before the shape solve's self term from
    // Gauss's identity); the twin without the lean 0.61 / 5.8.
    assert!(mean <= 1.0 && worst <= 3.0, "mean {mean}, worst {worst}");
    assert!(
        plain_worst >= 2.0 * worst.max(2.0) && plain_mean >= 1.5 * mean,
        "the twins are too alike to tell apart: {plain_mean} / {plain_worst} against {mean} / {worst}"
    );
}

#[test]
fn a_translucent_ball_shows_the_light_its_patches_carry() {
    use bevy::{camera::Exposure, light::GlobalAmbientLight};
    use bevy_mesostructure::translucency::{
        TranslucencyFrame, TranslucencyPlugin, TranslucencySettings,
        Translucent, GatherMethod, GatherResolution, LightInjection, DirectLight, ExitLaw,
        gather::{BeamSingleScattering, gathered_radiance},
        transport::TransportSolution,
    };
    if !gpu_or_skip() {
        return;
    }
    let mut app = bare_app_with(|app| {
        app.add_plugins(TranslucencyPlugin);
    });
    app.insert_resource(GlobalAmbientLight {
        brightness: 0.0,
        ..default()
    });
    // The CPU's shadow rays first: the oracle below iterates their very `E⁰`.
    // Every pixel gathered: the CPU twin below gathers every pixel.
    app.insert_resource(TranslucencySettings {
        patch_budget: 600,
        light_injection: LightInjection::ShadowRays,
        gather_resolution: GatherResolution::Full,
        // The diffusion profile alone (the beam table's own tests are below).
        transport: TransportSettings { beam_table: None, ..default() },
        ..default()
    });
    // Sunlight from the right: the left of the ball is lit only through the marble.
    let light_travel = Vec3::new(-1.0, -0.2, -0.3).normalize();
    let sun_light = sun(&mut app, light_travel, 2_000.0);
    let radius = 0.05;
    let ball = mesh(&mut app, Sphere::new(radius).mesh().uv(64, 32));
    let material = matte_white(&mut app);
    app.world_mut().spawn((
        ball,
        MeshMaterial3d(material),
        Translucent::default(),
        Transform::IDENTITY,
    ));
    let size = 64;
    let image = target(&mut app, size, size);
    let eye = Transform::from_xyz(0.0, 0.0, 0.25).looking_at(Vec3::ZERO, Vec3::Y);
    // The gather's compute form (compared with the fragment form below).
    let camera = hdr_translucency_camera(&mut app, &image, eye);
    run_until_ready(&mut app);
    run(&mut app, 3);
    assert_pipelines_ready_with_prefix(&app, "translucency_gather");
    let shot = screenshot(&mut app, &image);

    // The oracle: the CPU iteration of the same transport and light, gathered per pixel as
    // the shader does it.
    let frame = app.world().resource::<TranslucencyFrame>().clone();
    let (_, scene) = frame.scene.expect("a scene");
    let (_, direct) = frame.direct.expect("the light injected");
    let solution = scene.transport.solve_with(
        &direct,
        frame.settings.iteration_threshold,
        frame.settings.max_iterations,
    );
    let exposure = Exposure::default().exposure();
    let (ball_pixels, eye) = ball_pixels_seen(&mut app, camera, size, radius);
    // |GPU − CPU| over the ball's pixels for a gather method: (pixels compared, mean, worst,
    // pixels lit past the terminator).
    let compare = |shot: &Image,
                   method,
                   (direct, solution, single, exit_laws): (
                       &DirectLight,
                       &TransportSolution,
                       Option<&BeamSingleScattering>,
                       &[ExitLaw],
                   )| {
        let (mut compared, mut sum_error, mut worst, mut glowing_in_shade) = (0, 0.0f32, 0.0f32, 0);
        for &(x, y, hit, n) in &ball_pixels {
            let expected = gathered_radiance(
                method,
                &scene.patches,
                &scene.albedo,
                exit_laws,
                &direct.irradiance,
                &solution.irradiance,
                &solution.exitance,
                single,
                None,
                eye,
                hit,
                n,
            )
            .map_or(0.0, |l| l.x * exposure);
            let pixel = shot.get_color_at(x, y).unwrap().to_srgba().red * 255.0;
            let error = (pixel - srgb8(expected)).abs();
            compared += 1;
            sum_error += error;
            worst = worst.max(error);
            if n.dot(-light_travel) < 0.0 && pixel >= 3.0 {
                glowing_in_shade += 1;
            }
        }
        (compared, sum_error / compared.max(1) as f32, worst, glowing_in_shade)
    };
    let (compared, mean, worst, glowing_in_shade) =
        compare(&shot, GatherMethod::Interpolation, (&direct, &solution, None, &scene.exit_laws));
    eprintln!(
        "{compared} pixels: mean |GPU − CPU| {mean:.2}/255, worst {worst:.1}/255; {glowing_in_shade} lit pixels in the shade"
    );
    assert!(compared > 500);
    // Measured 0.26/255 mean and 0.8/255 worst (2.7 worst before the grid walked a bucket
    // that two cells share once only; 0.24 and 0.7 before this round's geometric tail and
    // threshold of 1e-2).
    assert!(mean <= 1.0 && worst <= 2.0, "mean {mean}, worst {worst}");
    // Light carried under the surface past the terminator, where Bevy's own shading is
    // black: measured 95 pixels at ≥ 3/255 (68 before the geometric tail and 1e-2).
    assert!(glowing_in_shade >= 34, "{glowing_in_shade}");

    // The fragment form (a camera whose main images take no storage writes) draws the same.
    use bevy::{camera::CameraMainTextureUsages, render::render_resource::TextureUsages};
    let differ = fragment_gather_difference(&mut app, camera, &image, &shot);
    eprintln!("compute against fragment gather: largest difference {differ}/255");
    assert!(differ <= 1, "the two forms of the gather differ by {differ}/255");

    // The seed's photons (density estimation) against their CPU twin, in the compute form.
    app.world_mut()
        .entity_mut(camera)
        .insert(CameraMainTextureUsages::default().with(TextureUsages::STORAGE_BINDING));
    app.world_mut().resource_mut::<TranslucencySettings>().gather = GatherMethod::PhotonDensity;
    run(&mut app, 3);
    assert_pipelines_ready_with_prefix(&app, "translucency_gather");
    let photons = screenshot(&mut app, &image);
    let (compared, mean, worst, glowing_in_shade) =
        compare(&photons, GatherMethod::PhotonDensity, (&direct, &solution, None, &scene.exit_laws));
    eprintln!(
        "photons: {compared} pixels: mean |GPU − CPU| {mean:.2}/255, worst {worst:.1}/255; {glowing_in_shade} lit pixels in the shade"
    );
    // Measured 0.26/255 mean and 1.2/255 worst (19/255 before the grid walked a bucket
    // that two cells share once only: the photons there counted twice).
    assert!(mean <= 1.0 && worst <= 3.0, "photons: mean {mean}, worst {worst}");
    let a = shot.data.as_ref().unwrap();
    let moved = a
        .iter()
        .zip(photons.data.as_ref().unwrap())
        .filter(|(p, q)| p.abs_diff(**q) > 2)
        .count();
    assert!(moved > 100, "the photons' picture is another ({moved} values moved)");

    // The GPU's light injection (the default) through the whole plugin: the same picture as
    // the shadow rays' to within what the two injections differ by on a lone ball (the
    // incidence table's interpolation, the terminator's texels).
    {
        let mut settings = app.world_mut().resource_mut::<TranslucencySettings>();
        settings.gather = GatherMethod::Interpolation;
        settings.light_injection = LightInjection::default();
    }
    run(&mut app, 3);
    let frame = app.world().resource::<TranslucencyFrame>();
    assert!(frame.direct.is_none() && frame.lights.is_some(), "the GPU injects the light");
    let injected = screenshot(&mut app, &image);
    let b = injected.data.as_ref().unwrap();
    let (mut worst, mut sum) = (0u8, 0u64);
    for (p, q) in a.iter().zip(b) {
        worst = worst.max(p.abs_diff(*q));
        sum += p.abs_diff(*q) as u64;
    }
    let mean = sum as f32 / a.len() as f32;
    eprintln!("GPU injection against shadow rays: mean {mean:.3}/255, worst {worst}/255");
    // Measured 0.000/255 mean, 1/255 worst.
    assert!(mean <= 0.05 && worst <= 2, "mean {mean}, worst {worst}");

    // With a beam table (a small one: 16 walks), the shadow rays' light again: the gather's
    // single scattering by the lit face against its CPU twin (`BeamSingleScattering`).
    {
        let mut settings = app.world_mut().resource_mut::<TranslucencySettings>();
        settings.light_injection = LightInjection::ShadowRays;
        settings.transport.beam_table = Some(bevy_mesostructure::translucency::beam_table::BeamTableSettings {
            walks: 16,
            late_walks: 64,
            ..default()
        });
    }
    run(&mut app, 2);
    run_until_ready(&mut app);
    run(&mut app, 3);
    let frame = app.world().resource::<TranslucencyFrame>().clone();
    let (_, tabled_scene) = frame.scene.expect("a scene");
    let table = tabled_scene.transport.beam_table.as_ref().expect("the scene has its beam table");
    assert_eq!(tabled_scene.patches.patches, scene.patches.patches, "the same patches");
    let (_, direct) = frame.direct.expect("the light injected");
    assert!(direct.beam_irradiance.iter().any(|e| *e != Vec3::ZERO), "the table carries the sun");
    let solution = tabled_scene.transport.solve_with(&direct, frame.settings.iteration_threshold, frame.settings.max_iterations);
    let media = table.patch_media();
    let single = BeamSingleScattering {
        irradiance: &direct.beam_irradiance,
        direction: &direct.beam_direction,
        media: &media,
    };
    // The deep law about the table's light flow, as the GPU's `table_rows` gives it.
    let exit_laws = tabled_scene.transport.exit_laws_along_flow(
        &tabled_scene.patches,
        &tabled_scene.exit_laws,
        &direct,
        &tabled_scene.source_depths,
    );
    let flowing = exit_laws.iter().flat_map(|l| l.flow).filter(|f| *f != Vec4::ZERO).count();
    // And its exit lobes (`TransportSettings::exit_lobes`, on by default).
    let lobed = exit_laws.iter().flat_map(|l| l.lobes).filter(|l| l.norm > 0.0).count();
    let tabled = screenshot(&mut app, &image);
    let (compared, mean, worst, _) =
        compare(&tabled, GatherMethod::Interpolation, (&direct, &solution, Some(&single), &exit_laws));
    let moved = ball_pixels
        .iter()
        .filter(|&&(x, y, _, _)| {
            let at = |i: &Image| i.get_color_at(x, y).unwrap().to_srgba().red * 255.0;
            (at(&tabled) - at(&shot)).abs() > 2.0
        })
        .count();
    eprintln!("beam table: {compared} pixels: mean |GPU − CPU| {mean:.2}/255, worst {worst:.1}/255; {moved} moved from the profile's picture; {flowing} patch channels with a flow, {lobed} with an exit lobe");
    assert!(compared > 500 && moved > 50 && flowing > 0 && lobed > 0, "{compared} compared, {moved} moved, {flowing} flowing, {lobed} lobed");
    assert!(mean <= 1.0 && worst <= 3.0, "beam table: mean {mean}, worst {worst}");

    // Single scattering marched per pixel against the GPU's translucent maps (the GPU
    // injection's), against its CPU twin (`MarchedObject`): the table without single
    // scattering, the lit face's law not given, the CPU's shadow rays for `E⁰` (the same
    // picture as the GPU's on a lone ball, above).
    {
        let mut settings = app.world_mut().resource_mut::<TranslucencySettings>();
        settings.light_injection = LightInjection::default();
        if let Some(table) = settings.transport.beam_table.as_mut() {
            table.single_scattering_to_pixels = true;
        }
    }
    run(&mut app, 2);
    run_until_ready(&mut app);
    run(&mut app, 3);
    // |GPU − CPU twin| over the ball's pixels with the march: (pixels, mean, worst, pixels the
    // march gives more than 2/255).
    let compare_marched = |app: &mut App| marched_against_its_twin(app, &image, &ball_pixels, eye);
    let (compared, mean, worst, marching) = compare_marched(&mut app);
    eprintln!("marched: {compared} pixels: mean |GPU − CPU| {mean:.2}/255, worst {worst:.1}/255; the march gives {marching} more than 2/255");
    // Measured 0.66/255 mean and 2.8/255 worst (the lit face towards the terminator: the GPU
    // marches from the mesh's facets, the twin from the sphere); the march gives 402 pixels
    // more than 2/255.
    assert!(compared > 500 && marching > 100, "{compared} compared, {marching} marching");
    assert!(mean <= 1.0 && worst <= 3.0, "marched: mean {mean}, worst {worst}");

    // A spot light instead of the sun, from the front right, 20 cm away: its maps in
    // perspective from it, each texel's light its fall-off and cone where it enters, spreading
    // on inside as (entry distance / distance)².
    app.world_mut().despawn(sun_light);
    app.world_mut().spawn((
        SpotLight {
            intensity: 600.0,
            outer_angle: 0.4,
            inner_angle: 0.2,
            ..default()
        },
        Transform::from_xyz(0.15, 0.05, 0.12).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    run(&mut app, 3);
    let (compared, mean, worst, marching) = compare_marched(&mut app);
    eprintln!("marched under a spot: {compared} pixels: mean |GPU − CPU| {mean:.2}/255, worst {worst:.1}/255; the march gives {marching} more than 2/255");
    // Measured 0.63/255 mean and 2.4/255 worst; 417 pixels marching. With orthographic maps
    // along the line from the spot (before): 1.15 / 5.2 and 584 (the parallel columns lit
    // more of the ball than the spot's own rays), the GPU shadowing the light's grazing
    // entries a little by its scene map (texels 0.8 mm at 20 cm), the twin not at all.
    assert!(compared > 500 && marching > 100, "spot: {compared} compared, {marching} marching");
    assert!(mean <= 1.0 && worst <= 3.0, "marched under a spot: mean {mean}, worst {worst}");
}

#[test]
fn bad_translucency_input_warns_once_and_falls_back_to_bevys_shading() {
    use bevy_mesostructure::translucency::{
        LightInjection, MAX_MARCHED_OBJECTS, TranslucencyCamera, TranslucencyFrame, TranslucencyPlugin,
        TranslucencySettings, Translucent, TranslucentMaterials, TranslucentMedium,
    };
    if !gpu_or_skip() {
        return;
    }
    let mut app = bare_app_with(|app| {
        app.add_plugins(TranslucencyPlugin);
    });
    // A budget below the least (16); a beam table asking for the CPU oracle's exit
    // directions (and single scattering left to the pixels under the CPU's shadow rays: no
    // maps to march on, so the table keeps it, quietly), for a scene of more translucent
    // patches than it allows (one); a NaN medium, a zero scale and a good one.
    let mut settings = TranslucencySettings {
        patch_budget: 0,
        light_injection: bevy_mesostructure::translucency::LightInjection::ShadowRays,
        ..default()
    };
    settings.transport.beam_table = Some(bevy_mesostructure::translucency::beam_table::BeamTableSettings {
        walks: 4,
        late_walks: 4,
        exit_directions: true,
        single_scattering_to_pixels: true,
        max_patches: 1,
        ..default()
    });
    // And a NaN share of a solved column's energy to drop.
    settings.transport.shape_energy_dropped = f32::NAN;
    app.insert_resource(settings);
    sun(&mut app, Vec3::new(-1.0, -1.0, -1.0), 2000.0);
    let ball = mesh(&mut app, Sphere::new(0.05).mesh().ico(2).unwrap());
    let material = app
        .world_mut()
        .resource_mut::<Assets<StandardMaterial>>()
        .add(Color::WHITE);
    let nan = TranslucentMedium {
        absorption: Vec3::new(f32::NAN, 0.1, 0.1),
        ..default()
    };
    let bad = app
        .world_mut()
        .spawn((
            ball.clone(),
            MeshMaterial3d(material.clone()),
            Translucent {
                medium: nan,
                ..default()
            },
            Transform::from_xyz(-0.2, 0.0, 0.0),
        ))
        .id();
    app.world_mut().spawn((
        ball.clone(),
        MeshMaterial3d(material.clone()),
        Translucent {
            world_units_per_mm: 0.0,
            ..default()
        },
        Transform::from_xyz(0.2, 0.0, 0.0),
    ));
    let good = app
        .world_mut()
        .spawn((
            ball,
            MeshMaterial3d(material.clone()),
            Translucent::default(),
            Transform::IDENTITY,
        ))
        .id();
    let image = target(&mut app, 32, 32);
    app.world_mut().spawn((
        Camera3d::default(),
        bevy::camera::RenderTarget::Image(image.into()),
        Msaa::Off,
        TranslucencyCamera,
        Transform::from_xyz(0.0, 0.0, 0.6).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    // A second camera with MSAA on: a warning, no gather, no wgpu error.
    let other = target(&mut app, 32, 32);
    app.world_mut().spawn((
        Camera3d::default(),
        bevy::camera::RenderTarget::Image(other.into()),
        Msaa::Sample4,
        TranslucencyCamera,
        Transform::from_xyz(0.0, 0.0, 0.6).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    run_until_ready(&mut app);
    let causes = warnings(&app);
    assert!(
        causes.iter().any(|c| c.starts_with("translucency: ") && c.contains("max_patches (1)")),
        "no warning of the beam table's patch limit: {causes:?}"
    );
    for key in [
        "translucency-budget",
        &format!("translucency-medium-{bad}"),
        "translucency-units-",
        "translucency-msaa",
        "translucency-exit-directions",
        "translucency-shape-energy-dropped",
    ] {
        assert!(
            causes.iter().any(|c| c.starts_with(key)),
            "no warning {key}: {causes:?}"
        );
    }
    assert_eq!(
        app.world().resource::<TranslucencySettings>().patch_budget,
        16
    );
    assert_eq!(
        app.world().resource::<TranslucencySettings>().transport.shape_energy_dropped,
        bevy_mesostructure::translucency::TransportSettings::default().shape_energy_dropped
    );
    assert_eq!(
        app.world().resource::<TranslucencySettings>().transport.beam_table.map(|t| (t.exit_directions, t.single_scattering_to_pixels)),
        Some((false, true))
    );
    // The good ball shows its copy without diffuse; the bad one keeps its own material.
    let shown = |app: &mut App, e: Entity| {
        app.world()
            .get::<MeshMaterial3d<StandardMaterial>>(e)
            .unwrap()
            .0
            .clone()
    };
    let good_materials = app
        .world()
        .get::<TranslucentMaterials>(good)
        .unwrap()
        .clone();
    assert_eq!(shown(&mut app, good), good_materials.without_diffuse);
    assert_eq!(shown(&mut app, bad), material);

    // The game's own edit (a transport setting): rebuilt, with no warning that a mesh moved.
    app.world_mut().resource_mut::<TranslucencySettings>().transport.form_factor_cutoff *= 2.0;
    run(&mut app, 1);
    assert!(!ready(&app), "a changed setting did not rebuild the transport");
    run_until_ready(&mut app);
    assert!(
        !warnings(&app).iter().any(|c| c == "translucency-moved"),
        "a changed setting warned that a mesh moved"
    );

    // Moving a participant: one warning, Bevy's shading while it moves, rebuilt once still.
    for step in 0..5 {
        app.world_mut()
            .get_mut::<Transform>(good)
            .unwrap()
            .translation
            .y = 0.01 * (step + 1) as f32;
        run(&mut app, 1);
        assert!(!ready(&app));
        assert_eq!(shown(&mut app, good), good_materials.original);
    }
    assert!(warnings(&app).iter().any(|c| c == "translucency-moved"));
    run_until_ready(&mut app);
    assert_eq!(shown(&mut app, good), good_materials.without_diffuse);

    // Deforming its mesh in place, under the same handle: Bevy's shading again, rebuilt once
    // still.
    let handle = app.world().get::<Mesh3d>(good).unwrap().0.clone();
    {
        let mut meshes = app.world_mut().resource_mut::<Assets<Mesh>>();
        let mut deformed = meshes.get_mut(&handle).expect("the ball's mesh");
        if let Some(bevy::mesh::VertexAttributeValues::Float32x3(positions)) =
            deformed.attribute_mut(Mesh::ATTRIBUTE_POSITION)
        {
            positions.iter_mut().for_each(|p| p[1] *= 1.2);
        }
    }
    run(&mut app, 1);
    assert!(!ready(&app), "a mesh deformed in place kept its transport");
    assert_eq!(shown(&mut app, good), good_materials.original);
    run_until_ready(&mut app);
    assert_eq!(shown(&mut app, good), good_materials.without_diffuse);

    // A skinned translucent mesh deforms on the GPU under an unchanged `Mesh`: it takes no
    // part, with a warning, and keeps its own material.
    let skinned = app
        .world_mut()
        .spawn((
            Mesh3d(handle.clone()),
            MeshMaterial3d(material.clone()),
            Translucent::default(),
            bevy::mesh::skinning::SkinnedMesh::default(),
            Transform::from_xyz(0.0, 0.3, 0.0),
        ))
        .id();
    run(&mut app, 1);
    run_until_ready(&mut app);
    assert!(
        warnings(&app).iter().any(|c| *c == format!("translucency-animated-{skinned}")),
        "no warning of the skinned mesh: {:?}",
        warnings(&app)
    );
    assert_eq!(shown(&mut app, skinned), material);
    assert_eq!(shown(&mut app, good), good_materials.without_diffuse);
    app.world_mut().despawn(skinned);

    // A light-view resolution out of range: a warning, clamped (the table built again: it
    // would leave single scattering to the pixels' march now that there are maps, but there
    // are more translucent objects than march — eight more balls, nine good ones —: a
    // warning; `of_more_translucent_objects_than_march_the_largest_do…`).
    let more = mesh(&mut app, Sphere::new(0.05).mesh().ico(2).unwrap());
    for i in 0..MAX_MARCHED_OBJECTS {
        app.world_mut().spawn((
            more.clone(),
            MeshMaterial3d(material.clone()),
            Translucent::default(),
            Transform::from_xyz(-0.4 + 0.12 * i as f32, 0.3, -0.3),
        ));
    }
    app.world_mut()
        .resource_mut::<TranslucencySettings>()
        .light_injection = LightInjection::LightViewMaps { resolution: 0 };
    run(&mut app, 2);
    run_until_ready(&mut app);
    run(&mut app, 2);
    assert!(warnings(&app).iter().any(|c| c == "translucency-marched-objects"), "{:?}", warnings(&app));
    assert!(warnings(&app).iter().any(|c| c == "translucency-injection-resolution"));
    let frame = app.world().resource::<TranslucencyFrame>();
    assert_eq!(frame.lights.as_ref().map(|l| l.1.resolution), Some(32));
    // More lights in reach than the GPU injection takes: a warning, and it takes the
    // brightest that many (`lights_out_of_reach_are_left_out_and_the_brightest_eight_are_taken`).
    for i in 0..=MAX_INJECTED_LIGHTS {
        app.world_mut().spawn((
            PointLight::default(),
            Transform::from_xyz(0.1 * i as f32, 0.3, 0.3),
        ));
    }
    run(&mut app, 2);
    assert!(warnings(&app).iter().any(|c| c == "translucency-injection-lights"));
    let frame = app.world().resource::<TranslucencyFrame>();
    assert!(frame.direct.is_none());
    assert_eq!(frame.lights.as_ref().map(|l| l.1.lights.len()), Some(MAX_INJECTED_LIGHTS));
}

#[test]
fn a_kept_transport_is_read_back_instead_of_built_again() {
    use bevy_mesostructure::translucency::{
        TranslucencyCamera, TranslucencyFrame, TranslucencyPlugin, TranslucencySettings,
        Translucent,
    };
    if !gpu_or_skip() {
        return;
    }
    let dir = std::env::temp_dir().join(format!("bevy_mesostructure_kept_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let build = |dir: &std::path::Path| {
        let mut app = bare_app_with(|app| {
            app.add_plugins(TranslucencyPlugin);
        });
        app.insert_resource(TranslucencySettings {
            patch_budget: 300,
            cache_dir: Some(dir.to_path_buf()),
            // The profile alone: the cache's round trip of a table is `cache_and_gather`'s.
            transport: TransportSettings { beam_table: None, ..default() },
            ..default()
        });
        sun(&mut app, Vec3::new(-1.0, -1.0, -1.0), 2000.0);
        let ball = mesh(&mut app, Sphere::new(0.05).mesh().ico(3).unwrap());
        let material = app
            .world_mut()
            .resource_mut::<Assets<StandardMaterial>>()
            .add(Color::WHITE);
        app.world_mut().spawn((
            ball,
            MeshMaterial3d(material),
            Translucent::default(),
            Transform::IDENTITY,
        ));
        let image = target(&mut app, 16, 16);
        app.world_mut().spawn((
            Camera3d::default(),
            bevy::camera::RenderTarget::Image(image.into()),
            Msaa::Off,
            TranslucencyCamera,
            Transform::from_xyz(0.0, 0.0, 0.4).looking_at(Vec3::ZERO, Vec3::Y),
        ));
        run_until_ready(&mut app);
        let (_, scene) = app
            .world()
            .resource::<TranslucencyFrame>()
            .scene
            .clone()
            .unwrap();
        let from_cache = match app.world().resource::<bevy_mesostructure::translucency::TranslucencyStatus>() {
            bevy_mesostructure::translucency::TranslucencyStatus::Ready { from_cache, .. } => *from_cache,
            other => panic!("not ready: {other:?}"),
        };
        (
            scene.transport.report.clone(),
            scene.patches.patches.len(),
            scene.transport.incidence.clone(),
            from_cache,
        )
    };
    let (first, patches, incidence, first_from_cache) = build(&dir);
    assert!(!first_from_cache, "the first app builds the transport");
    assert!(
        matches!(incidence[..], [Some(_)]),
        "the ball's beams weighted by their incidence: {incidence:?}"
    );
    let files: Vec<_> = std::fs::read_dir(&dir).unwrap().collect();
    assert_eq!(files.len(), 1, "one kept transport");
    // A second app with the same scene reads it: the same report, its build time included
    // (a rebuild would measure its own).
    let (second, patches_again, incidence_again, second_from_cache) = build(&dir);
    assert!(second_from_cache, "the second app says it loaded the kept transport");
    assert_eq!(second, first);
    assert_eq!(patches_again, patches);
    // The incidence weights are not kept in the file: set again from the scene on load.
    assert_eq!(incidence_again, incidence);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Settings that only shape how the patches' light leaves them and how a beam enters
/// (`TransportSettings::derived`) are derived again on the transport already built when they
/// change: the same transport (its report, build time included), no frame back to Bevy's
/// shading, and the laws a build with those settings derives.
#[test]
fn exit_law_settings_are_derived_again_without_a_precompute() {
    use bevy_mesostructure::translucency::{
        TranslucencyFrame, TranslucencyPlugin, TranslucencySettings, TranslucencyStatus, transport::ExitLaw,
    };
    if !gpu_or_skip() {
        return;
    }
    let app_with = |deep_exit_law: bool, beam_incidence: bool| {
        let mut app = bare_app_with(|app| {
            app.add_plugins(TranslucencyPlugin);
        });
        small_translucent_ball(&mut app, 16);
        let mut settings = app.world_mut().resource_mut::<TranslucencySettings>();
        settings.transport.deep_exit_law = deep_exit_law;
        settings.transport.beam_incidence = beam_incidence;
        sun(&mut app, Vec3::new(-1.0, -1.0, -1.0), 2000.0);
        run_until_ready(&mut app);
        app
    };
    let scene_of = |app: &App| app.world().resource::<TranslucencyFrame>().scene.clone().expect("a scene");
    let mut app = app_with(false, true);
    let (generation, built) = scene_of(&app);
    assert!(built.exit_laws.iter().all(|l| *l == ExitLaw::default()), "Lambert's law without the deep law");
    assert!(built.transport.incidence.iter().all(Option::is_some), "the ball's beams weighted by their incidence");
    {
        let mut settings = app.world_mut().resource_mut::<TranslucencySettings>();
        settings.transport.deep_exit_law = true;
        settings.transport.beam_incidence = false;
    }
    for frame in 0..3 {
        run(&mut app, 1);
        assert!(
            matches!(app.world().resource::<TranslucencyStatus>(), TranslucencyStatus::Ready { .. }),
            "frame {frame}: still ready, not back to Bevy's shading for a precompute"
        );
    }
    let (generation_after, derived) = scene_of(&app);
    assert!(generation_after > generation, "a new generation of the scene for the GPU to take");
    assert_eq!(derived.transport.report, built.transport.report, "the same transport, not built again");
    assert!(derived.transport.incidence.iter().all(Option::is_none), "no incidence weight with beam_incidence off");
    assert!(derived.exit_laws.iter().any(|l| *l != ExitLaw::default()), "the deep law on the ball's patches");
    // What a build with those settings derives, to the bit.
    let fresh = app_with(true, false);
    let (_, fresh) = scene_of(&fresh);
    assert_eq!(derived.exit_laws, fresh.exit_laws);
    assert_eq!(derived.transport.incidence, fresh.transport.incidence);
}

/// An app with the translucency plugin (300 patches, no beam table) and a white 5 cm
/// translucent ball at the origin, seen from 25 cm by a `size`² HDR-less, untonemapped
/// camera: the target it draws to.
fn small_translucent_ball(app: &mut App, size: u32) -> Handle<Image> {
    use bevy_mesostructure::translucency::{TranslucencySettings, Translucent};
    app.insert_resource(TranslucencySettings {
        patch_budget: 300,
        transport: TransportSettings { beam_table: None, ..default() },
        ..default()
    });
    let ball = mesh(app, Sphere::new(0.05).mesh().uv(48, 24));
    let material = matte_white(app);
    app.world_mut().spawn((ball, MeshMaterial3d(material), Translucent::default(), Transform::IDENTITY));
    let image = target(app, size, size);
    translucency_camera(app, &image, Transform::from_xyz(0.0, 0.0, 0.25).looking_at(Vec3::ZERO, Vec3::Y));
    image
}

#[test]
fn ambient_light_reaches_translucent_objects() {
    use bevy::light::GlobalAmbientLight;
    use bevy_mesostructure::translucency::{TranslucencyFrame, TranslucencyPlugin};
    if !gpu_or_skip() {
        return;
    }
    let mut app = bare_app_with(|app| {
        app.add_plugins(TranslucencyPlugin);
    });
    // No light but Bevy's ambient: the ball's material shows no diffuse of its own, so without
    // the ambient entering its patches it would be black.
    let brightness = 400.0;
    app.insert_resource(GlobalAmbientLight {
        brightness,
        ..default()
    });
    let size = 32;
    let image = small_translucent_ball(&mut app, size);
    run_until_ready(&mut app);
    run(&mut app, 3);
    // Injected by the GPU (the default), which adds it to the translucent patches.
    let (_, lights) = app
        .world()
        .resource::<TranslucencyFrame>()
        .lights
        .clone()
        .expect("injected");
    let expected = std::f32::consts::PI * brightness;
    assert!(lights.lights.is_empty() && (lights.ambient.x - expected).abs() < 1e-3 * expected);
    let shot = screenshot(&mut app, &image);
    // After the screenshot, whose own readback this one would otherwise race.
    {
        let render = app.sub_app(RenderApp).world();
        let device = render.resource::<RenderDevice>();
        let queue = render.resource::<RenderQueue>();
        let gpu = render
            .resource::<bevy_mesostructure::translucency::gather::TranslucencyGpu>()
            .transport()
            .expect("uploaded");
        let (buffer, range) = gpu.exitance();
        let (direct, _) = gpu.direct_offsets();
        let n = (range.end - range.start) / 16;
        let bytes = read_back(device, queue, buffer, direct as u64 * 16, n * 16);
        let e: &[[f32; 4]] = bytemuck::cast_slice(&bytes);
        // The GPU injected it into every patch (all translucent).
        assert!(
            e.iter().all(|e| (e[0] - expected).abs() < 1e-3 * expected),
            "{:?}",
            &e[..4]
        );
    }
    let centre = shot
        .get_color_at(size / 2, size / 2)
        .unwrap()
        .to_srgba()
        .red
        * 255.0;
    eprintln!("ambient-lit centre: {centre:.1}/255");
    // Exitance ≈ A · π L (marble's red A ≈ 0.9) → radiance ≈ 0.9 × 400 × exposure (≈ 1e-3):
    // about 0.36 linear, 160/255 in sRGB; measured 158.
    assert!((130.0..=185.0).contains(&centre), "{centre}");
}

#[test]
fn lights_out_of_reach_are_left_out_and_the_brightest_eight_are_taken() {
    use bevy_mesostructure::translucency::{TranslucencyFrame, TranslucencyPlugin, injection::MAX_INJECTED_LIGHTS};
    if !gpu_or_skip() {
        return;
    }
    let mut app = bare_app_with(|app| {
        app.add_plugins(TranslucencyPlugin);
    });
    small_translucent_ball(&mut app, 32);
    // A level's lights: one spot on the ball, twelve lamps elsewhere whose range ends well
    // short of it, and a spot beside it aimed away.
    app.world_mut().spawn((
        SpotLight { intensity: 4e4, range: 2.0, outer_angle: 0.4, inner_angle: 0.3, shadow_maps_enabled: false, ..default() },
        Transform::from_xyz(0.0, 0.0, 0.5).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    for k in 0..12 {
        let angle = k as f32 * std::f32::consts::TAU / 12.0;
        app.world_mut().spawn((
            PointLight { intensity: 1e6, range: 1.0, shadow_maps_enabled: false, ..default() },
            Transform::from_xyz(3.0 * angle.cos(), 1.0, 3.0 * angle.sin()),
        ));
    }
    app.world_mut().spawn((
        SpotLight { intensity: 1e6, range: 5.0, outer_angle: 0.3, inner_angle: 0.2, shadow_maps_enabled: false, ..default() },
        Transform::from_xyz(0.0, 0.3, 0.0).looking_at(Vec3::new(0.0, 1.0, 0.0), Vec3::Z),
    ));
    run_until_ready(&mut app);
    run(&mut app, 2);
    let taken = |app: &App| {
        let (_, lights) = app.world().resource::<TranslucencyFrame>().lights.clone().expect("injected on the GPU");
        lights.lights.clone()
    };
    // Fourteen lights, one of them reaching the ball: the GPU injects (and marches) it alone,
    // where before more than eight lights sent every one to the CPU.
    let lights = taken(&app);
    assert!(
        matches!(lights.as_slice(), [PatchLight::Spot { range, .. }] if *range == 2.0),
        "{lights:?}"
    );
    let left_out = "translucency-injection-lights".to_string();
    assert!(!warnings(&app).contains(&left_out), "{:?}", warnings(&app));
    // Nine more lamps in reach, the k-th (2 + k)·10 cm away, all dimmer at the ball than the
    // spot: of the ten lights that reach it, the eight brightest are taken.
    for k in 0..9 {
        app.world_mut().spawn((
            PointLight { intensity: 1e3, range: 5.0, shadow_maps_enabled: false, ..default() },
            Transform::from_xyz(0.0, 0.2 + 0.1 * k as f32, 0.0),
        ));
    }
    run(&mut app, 2);
    let lights = taken(&app);
    assert_eq!(lights.len(), MAX_INJECTED_LIGHTS);
    let heights: Vec<f32> = lights
        .iter()
        .filter_map(|l| match l {
            PatchLight::Point { position, .. } => Some(position.y),
            _ => None,
        })
        .collect();
    assert!(lights.iter().any(|l| matches!(l, PatchLight::Spot { range, .. } if *range == 2.0)), "{lights:?}");
    assert_eq!(heights.len(), 7, "{lights:?}");
    assert!(heights.iter().all(|&y| y < 0.2 + 0.1 * 6.5), "the two farthest lamps are left out: {heights:?}");
    // Said once.
    assert!(warnings(&app).contains(&left_out), "{:?}", warnings(&app));
}

#[test]
fn of_more_translucent_objects_than_march_the_largest_do_and_the_rest_keep_single_scattering() {
    use bevy_mesostructure::translucency::{
        MAX_MARCHED_OBJECTS, TranslucencyFrame, TranslucencyPlugin, TranslucencySettings, Translucent,
        beam_table::BeamTableSettings,
    };
    if !gpu_or_skip() {
        return;
    }
    let mut app = bare_app_with(|app| {
        app.add_plugins(TranslucencyPlugin);
    });
    let mut settings = TranslucencySettings { patch_budget: 900, ..default() };
    // Marble (the default medium) walked to 32 scatterings: at 16 walks a direction the
    // default 64's noise put the middle's two pictures 0.126 apart (its green; 0.079 at 32),
    // and what is held here is which objects march, not the walks' length.
    settings.transport.beam_table = Some(BeamTableSettings { walks: 16, late_walks: 16, max_last_order: 32, ..default() });
    app.insert_resource(settings);
    sun(&mut app, Vec3::new(-0.3, -0.3, -1.0), 1000.0);
    let material = matte_white(&mut app);
    // Nine marble balls in a 3 × 3 grid, the smallest (1 cm) in the middle, the others 1.1 –
    // 1.8 cm.
    let mut balls = Vec::new();
    for k in 0..9 {
        let (radius, at) = match k {
            0 => (0.01, Vec3::ZERO),
            _ => {
                let cell = if k <= 4 { k - 1 } else { k };
                (0.01 + 0.001 * k as f32, Vec3::new(0.05 * (cell % 3) as f32 - 0.05, 0.05 * (cell / 3) as f32 - 0.05, 0.0))
            }
        };
        let ball = mesh(&mut app, Sphere::new(radius).mesh().ico(3).unwrap());
        balls.push(app.world_mut().spawn((ball, MeshMaterial3d(material.clone()), Translucent::default(), Transform::from_translation(at))).id());
    }
    let size = 128;
    let image = target(&mut app, size, size);
    translucency_camera(&mut app, &image, Transform::from_xyz(0.0, 0.0, 0.25).looking_at(Vec3::ZERO, Vec3::Y));
    // The smallest ball's middle: the 7 × 7 pixels about the picture's centre (its disc is
    // about 12 pixels across).
    let middle = |app: &mut App| {
        run(app, 2);
        let shot = screenshot(app, &image);
        let mut sum = Vec3::ZERO;
        for y in size / 2 - 3..=size / 2 + 3 {
            for x in size / 2 - 3..=size / 2 + 3 {
                let c = shot.get_color_at(x, y).unwrap().to_linear();
                sum += Vec3::new(c.red, c.green, c.blue);
            }
        }
        sum / 49.0
    };
    run_until_ready(&mut app);
    let marched = |app: &App| {
        let (_, scene) = app.world().resource::<TranslucencyFrame>().scene.clone().expect("a scene");
        scene.entities.iter().zip(&scene.marched).filter(|(_, m)| m.is_some()).map(|(e, _)| *e).collect::<Vec<Entity>>()
    };
    // Nine: the eight largest march; the smallest's single scattering stays in the table,
    // and the gather gives it by the lit face's law.
    let of_nine = marched(&app);
    assert_eq!(of_nine.len(), MAX_MARCHED_OBJECTS);
    assert!(!of_nine.contains(&balls[0]), "the smallest does not march");
    let kept = middle(&mut app);
    // Eight: every one marches, the smallest too.
    app.world_mut().despawn(balls[8]);
    run(&mut app, 2);
    run_until_ready(&mut app);
    assert!(marched(&app).contains(&balls[0]));
    let its_own = middle(&mut app);
    let apart = ((kept - its_own).abs() / its_own).max_element();
    eprintln!("the smallest ball's middle: table and lit-face law {kept}, marched {its_own}: {apart:.3} apart");
    // Measured 0.079 (the table's and the law's 0.92 – 0.97 of the march's; 16 walks a
    // direction here). Without the lit face's law for the object that does not march (its
    // single scattering by the lit face lost) it was 0.149.
    assert!(its_own.min_element() > 0.1 && apart < 0.11, "{kept} against {its_own}");
}

#[path = "../../examples/common/translucent_accuracy_scene.rs"]
mod translucent_accuracy_scene;

/// The reference picture of `medium`'s ball lit `lighting` (tests/data/translucent): lit by
/// the directional light, made by tools/translucent_light_tracer.py with 4·10⁷ photons a
/// channel index-matched (its own noise 0.006–0.032 in relative L1; Mitsuba's `volpathmis`
/// agrees with it to 0.2 % in the mean on skin), 3·10⁶ behind a dielectric boundary (noise
/// 0.017–0.034); under the uniform environment behind a dielectric boundary, by
/// tools/translucent_reference.py (Mitsuba, 16 384 samples a pixel); the bunny's
/// (`bunny_<medium>`) and the torus's (`torus_<medium>`), Mitsuba's of the very triangles
/// (`translucent_accuracy --shape bunny|torus`), but the bunny's marble lit from behind, which
/// Mitsuba does not converge: the mesh light tracer's (`common/translucent_light_tracer.rs`).
fn reference_picture(medium: &str, lighting: &str) -> image::Rgb32FImage {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/translucent");
    let path = ["lighttraced", "mitsuba"]
        .map(|renderer| dir.join(format!("{medium}_{lighting}_{renderer}.exr")))
        .into_iter()
        .find(|p| p.exists())
        .unwrap_or_else(|| panic!("no reference for {medium} {lighting} in {}", dir.display()));
    image::open(&path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb32f()
}

/// The issue's accuracy figure, held: the plugin's picture of a 1 cm ball (960 patches, the
/// defaults — solved in its shape, the deep field's exit law — and each step back to the flat
/// profile with Lambert's exit, alone and with the opt-in oriented dipole) against a converged
/// reference — light
/// traced, index-matched, lit by a directional light; Mitsuba, behind a dielectric boundary
/// (η 1.3, the presets'), lit by a uniform environment — relative L1 over the ball and the
/// mean ratio per channel, each within 0.01 of what docs/translucent.md gives for it.
#[test]
fn translucent_balls_match_a_light_traced_reference_as_documented() {
    use translucent_accuracy_scene::{
        BACK_LIGHT, FRONT_LIGHT, SceneLighting, Shape, ShapeView,
    };
    let (front, back) = (
        SceneLighting::Directional(FRONT_LIGHT.normalize()),
        SceneLighting::Directional(BACK_LIGHT.normalize()),
    );
    let uniform = SceneLighting::Uniform;
    let view = ShapeView::new(Shape::Ball, 96);
    // (medium, lighting, how, η, solved in its shape, the deep field's exit law, oriented
    // dipole, relative L1, mean ratio r/g/b): measured.
    let cases = [
        (TranslucentPreset::Skin1, "skin1", "front", front, 1.0, true, true, false, 0.0757, [0.974, 0.980, 0.983]),
        (TranslucentPreset::Marble, "marble", "front", front, 1.0, true, true, false, 0.0450, [0.982, 0.975, 0.980]),
        // Lit from behind skin gives too little still: near the terminator the light enters
        // at a grazing angle and goes on towards the camera before it scatters, which sources
        // under the entry point do not carry.
        (TranslucentPreset::Skin1, "skin1", "back", back, 1.0, true, true, false, 0.4338, [0.595, 0.251, 0.215]),
        (TranslucentPreset::Marble, "marble", "back", back, 1.0, true, true, false, 0.0614, [1.025, 1.041, 1.080]),
        // Each step from the defaults before: solved in the shape with Lambert's exit, and
        // the flat profile with it (the defaults before), alone and with the oriented dipole.
        (TranslucentPreset::Skin1, "skin1", "back", back, 1.0, true, false, false, 0.4223, [0.610, 0.277, 0.217]),
        (TranslucentPreset::Marble, "marble", "back", back, 1.0, true, false, false, 0.1411, [1.030, 1.055, 1.109]),
        (TranslucentPreset::Skin1, "skin1", "back", back, 1.0, false, false, false, 0.6119, [0.400, 0.254, 0.254]),
        (TranslucentPreset::Marble, "marble", "back", back, 1.0, false, false, false, 0.2775, [0.869, 0.733, 0.678]),
        (TranslucentPreset::Skin1, "skin1", "back", back, 1.0, false, false, true, 0.3083, [0.765, 0.348, 0.290]),
        (TranslucentPreset::Marble, "marble", "back", back, 1.0, false, false, true, 0.6316, [1.698, 1.582, 1.504]),
        // Behind the presets' dielectric boundary, in Bevy's ambient light: the walks carry
        // the boundary's internal reflection (1.28–1.70× too bright before).
        (TranslucentPreset::Skin1, "skin1", "uniform_eta1.3", uniform, 1.3, true, true, false, 0.0287, [0.978, 1.000, 0.994]),
        (TranslucentPreset::Marble, "marble", "uniform_eta1.3", uniform, 1.3, true, true, false, 0.0554, [1.005, 0.987, 0.989]),
        // Behind the dielectric boundary under the directional light (the light tracer's
        // refracted connection to the eye; marble's connected at a share of its collisions,
        // noise 0.050 front, 0.057 back): the exit law with the boundary's Fresnel and
        // internal reflection; marble from behind, solved with Lambert's exit and the
        // defaults before.
        (TranslucentPreset::Skin1, "skin1", "front_eta1.3", front, 1.3, true, true, false, 0.0744, [0.955, 0.972, 0.973]),
        (TranslucentPreset::Skin1, "skin1", "back_eta1.3", back, 1.3, true, true, false, 0.4740, [0.540, 0.200, 0.149]),
        (TranslucentPreset::Marble, "marble", "front_eta1.3", front, 1.3, true, true, false, 0.0754, [0.959, 0.956, 0.954]),
        (TranslucentPreset::Marble, "marble", "back_eta1.3", back, 1.3, true, true, false, 0.0864, [0.954, 0.941, 0.946]),
        (TranslucentPreset::Marble, "marble", "back_eta1.3", back, 1.3, true, false, false, 0.0915, [0.940, 0.931, 0.941]),
        (TranslucentPreset::Marble, "marble", "back_eta1.3", back, 1.3, false, false, false, 0.3576, [0.714, 0.584, 0.516]),
    ];
    for (preset, name, lighting, how, eta, shape_diffusion, deep_exit_law, oriented_dipole, rel_l1, ratio) in cases {
        let medium = bevy_mesostructure::translucency::TranslucentMedium {
            index_of_refraction: eta,
            ..preset.medium()
        };
        let label = format!(
            "{name}{}{}{}",
            if shape_diffusion { "" } else { " (flat profile)" },
            if deep_exit_law { "" } else { " (Lambert's exit)" },
            if oriented_dipole { " (oriented dipole)" } else { "" },
        );
        let settings = TransportSettings {
            shape_diffusion,
            deep_exit_law,
            ..default()
        };
        let reference = reference_picture(name, lighting);
        holds_as_documented(&view, &label, lighting, medium, oriented_dipole, &settings, how, translucent_accuracy_scene::Oracles::NONE, &reference, rel_l1, ratio, None);
    }
    // The beam table (`TransportSettings::beam_table`, its default 4 × 8 directions;
    // index-matched): each lit patch's column for its table direction, single scattering
    // marched per pixel against the plugin's 256² maps (`translucent_accuracy --scattering
    // beam-table`; with single scattering in the table and the lit face's law in the gather,
    // the defaults before: skin 0.0424 / 0.1323, marble 0.0441 / 0.0616, behind the
    // dielectric skin 0.0562 / 0.1199, marble 0.0687 / 0.0761).
    let table = translucent_accuracy_scene::Oracles {
        scattering: translucent_accuracy_scene::ScatteringSource::BeamTable(default()),
        ..translucent_accuracy_scene::Oracles::NONE
    };
    // The rows below each measure another part with single scattering in the table and the
    // lit face's law in the gather (`--single-scattering-in-table`, the defaults before the
    // march).
    let in_table = bevy_mesostructure::translucency::beam_table::BeamTableSettings {
        single_scattering_to_pixels: false,
        ..default()
    };
    let table_ss = translucent_accuracy_scene::Oracles {
        scattering: translucent_accuracy_scene::ScatteringSource::BeamTable(in_table),
        ..table
    };
    // The table with the law about the normal (`translucent_accuracy --exit-axis normal`):
    // light that crossed the ball leaves towards the camera, which the normal's law misses.
    let table_normal = translucent_accuracy_scene::Oracles {
        exit_axis: translucent_accuracy_scene::ExitAxis::Normal,
        ..table_ss
    };
    // Exit lobes (`translucent_accuracy --exit-axis lobe --walks 1024 --far-splits 1`, an
    // oracle of the CPU path): a table of 1024 unsplit walks a direction keeping the mean direction each entry's light
    // leaves along, each patch's light from farther than two patch sizes (and two transport
    // mean free paths, `lobe_source_distance`) given out by the
    // von Mises–Fisher lobe of its mean; the same table with the plugin's flow law beside it.
    let table_1024 = translucent_accuracy_scene::Oracles {
        scattering: translucent_accuracy_scene::ScatteringSource::BeamTable(
            bevy_mesostructure::translucency::beam_table::BeamTableSettings { walks: 1024, far_splits: 1, exit_directions: true, ..in_table },
        ),
        ..table
    };
    let table_lobe = translucent_accuracy_scene::Oracles {
        exit_axis: translucent_accuracy_scene::ExitAxis::Lobe,
        ..table_1024
    };
    // Behind the presets' dielectric boundary too (η 1.3: the walks refract in and reflect
    // inside, each beam weighted by its transmittance, the law with Fresnel both ways).
    // With the table, the deep field's law is taken about the way each patch's light flows
    // in (`ExitLaw::set_flow`; before it, about the normal — held below —, and with each beam
    // at its nearest table direction: skin from behind 0.3435, marble 0.0782, behind the
    // dielectric skin 0.0821 / 0.2197, marble 0.0699 / 0.0812), and the light from afar leaves by lobes leaning the way it travelled
    // (`TransportSettings::exit_lobes`, on by default; `false` here: the flow's law alone,
    // `translucent_accuracy --exit-lobes false`). Each beam is spread over the four table
    // directions about it (`direction_weights`). Single scattering that a grazing beam sends
    // out past the terminator, by a face turned from the light, stays in the table
    // (`law_gives_single_scattering`: the gather's law gives none there). Skin from behind
    // has blue 1.39× with this table's seed, behind the dielectric 1.58×: a few far walks in
    // a channel the reference barely has there. All the light from elsewhere leaves by the
    // flow's law (`TransportSettings::flow_law_takes_all`; with the mode's share `g` alone,
    // skin 0.0466 / 0.1003, marble 0.0631 from behind, behind the dielectric skin 0.0460 /
    // 0.1105, marble 0.0768 from behind). The walks are shared by the channels (hero
    // channels, `random_walk::walk_ends`; 256 beam walks, each split in 4 two patch sizes
    // (and two transport mean free paths: `lobe_source_distance`; before that floor, skin's
    // rows were 0.0475 / 0.1107 and 0.0439 / 0.1080 behind the dielectric) from its entry
    // (`BeamTableSettings::far_splits`), and 3072 late walks by default;
    // before, 384 unsplit: 0.0518, 0.1323, 0.0449, 0.0617 in the first four rows, 0.1214
    // behind the dielectric). Walks in marble go on to 64 scatterings on twice the late walks
    // since 2026-12-07 (`BeamTableSettings::max_last_order`, `late_walks_for`; at 32 marble's
    // rows were 0.0447 / 0.0629, behind the dielectric 0.0642 / 0.0760, about the normal
    // 0.0844), before they leave as late light (at 16, marble's rows were 0.0417 /
    // 0.0619, behind the dielectric 0.0672 / 0.0778, and about the normal 0.0778). Each beam
    // walk splits in 16 far from its entry since 2026-11-29 (in 4 before: skin 0.0475 /
    // 0.0943, marble 0.0425 / 0.0606, behind the dielectric skin 0.0436 / 0.1008, marble
    // 0.0639 / 0.0767; the flow's law alone, skin 0.0568 / 0.2261; about the normal, skin
    // 0.3081, marble 0.0794). The flux along the surface in marble (`tangential_flux`, on
    // by default since 2026-12-07, late; skin takes none of it): before, marble's rows were
    // 0.0414 / 0.0579, behind the dielectric 0.0626 / 0.0780, about the normal 0.0796.
    let (lean, flow) = (true, false);
    let table_cases = [
        ((table, "beam table"), lean, TranslucentPreset::Skin1, "skin1", "front", front, 1.0, 0.0567, [1.049, 1.045, 1.073]),
        ((table, "beam table"), lean, TranslucentPreset::Skin1, "skin1", "back", back, 1.0, 0.0780, [1.023, 0.957, 1.217]),
        ((table, "beam table"), lean, TranslucentPreset::Marble, "marble", "front", front, 1.0, 0.0410, [1.029, 1.025, 1.034]),
        ((table, "beam table"), lean, TranslucentPreset::Marble, "marble", "back", back, 1.0, 0.0567, [0.997, 0.979, 0.976]),
        ((table, "beam table"), lean, TranslucentPreset::Skin1, "skin1", "front_eta1.3", front, 1.3, 0.0404, [0.985, 0.987, 0.989]),
        ((table, "beam table"), lean, TranslucentPreset::Skin1, "skin1", "back_eta1.3", back, 1.3, 0.0806, [0.948, 1.058, 1.613]),
        ((table, "beam table"), lean, TranslucentPreset::Marble, "marble", "front_eta1.3", front, 1.3, 0.0624, [0.993, 0.986, 0.979]),
        ((table, "beam table"), lean, TranslucentPreset::Marble, "marble", "back_eta1.3", back, 1.3, 0.0782, [1.044, 1.005, 0.992]),
        ((table_ss, "beam table, the flow's law"), flow, TranslucentPreset::Skin1, "skin1", "front", front, 1.0, 0.0452, [0.988, 0.966, 0.969]),
        ((table_ss, "beam table, the flow's law"), flow, TranslucentPreset::Skin1, "skin1", "back", back, 1.0, 0.2312, [0.801, 0.570, 0.637]),
        ((table_normal, "beam table, the normal's law"), flow, TranslucentPreset::Skin1, "skin1", "back", back, 1.0, 0.3112, [0.717, 0.431, 0.611]),
        ((table_normal, "beam table, the normal's law"), flow, TranslucentPreset::Marble, "marble", "back", back, 1.0, 0.0663, [0.961, 0.944, 0.935]),
        ((table_lobe, "beam table, 1024 walks, exit lobes"), flow, TranslucentPreset::Skin1, "skin1", "back", back, 1.0, 0.1493, [1.001, 0.951, 1.335]),
        ((table_lobe, "beam table, 1024 walks, exit lobes"), flow, TranslucentPreset::Skin1, "skin1", "front", front, 1.0, 0.0381, [0.990, 0.968, 0.967]),
        ((table_1024, "beam table, 1024 walks, the flow's law"), flow, TranslucentPreset::Skin1, "skin1", "back", back, 1.0, 0.2353, [0.804, 0.561, 0.617]),
    ];
    for ((oracles, named), exit_lobes, preset, name, lighting, how, eta, rel_l1, ratio) in table_cases {
        let medium = bevy_mesostructure::translucency::TranslucentMedium {
            index_of_refraction: eta,
            ..preset.medium()
        };
        let reference = reference_picture(name, lighting);
        let label = format!("{name} ({named})");
        // The rows without the lobes are the flow's law as it was measured, with only the
        // mode's share `g` of the light from elsewhere in it.
        let settings = TransportSettings { exit_lobes, flow_law_takes_all: exit_lobes, ..default() };
        holds_as_documented(&view, &label, lighting, medium, false, &settings, how, oracles, &reference, rel_l1, ratio, None);
    }
}

/// The ball as the plugin draws it: pixels on its 720 triangles (where the depth prepass puts
/// them, `translucent_accuracy --pixels-on-mesh`) against the mesh light tracer on the very
/// triangles (index-matched; marble 8·10⁶ photons a channel, noise 0.014; skin 1.6·10⁷, noise
/// 0.010 from the front and 0.020 from behind). The suite's ball is the sphere's, and a
/// triangle's middle lies up to 0.07 mm inside it: lit from the front the table's ball was
/// 1.04 – 1.07× bright against the sphere (marble 0.0451, skin 0.0569), 1.00 – 1.03× against
/// its own triangles (docs/translucent.md, "The ball's front is the sphere's, not the
/// plugin's").
#[test]
fn the_ball_of_triangles_matches_its_own_light_traced_reference_as_documented() {
    use translucent_accuracy_scene::{BACK_LIGHT, FRONT_LIGHT, SceneLighting, Shape, ShapeView};
    let view = ShapeView::on_mesh(Shape::Ball, 96);
    let (front, back) = (
        SceneLighting::Directional(FRONT_LIGHT.normalize()),
        SceneLighting::Directional(BACK_LIGHT.normalize()),
    );
    // (medium, lighting, how, relative L1, mean ratio r/g/b): measured.
    let cases = [
        // Marble at 64 scatterings since 2026-12-07 (at 32: 0.0430, [1.002, 0.990, 0.992]),
        // with the flux along the surface since 2026-12-07, late (without: 0.0406, [0.993,
        // 0.984, 0.988]).
        (TranslucentPreset::Marble, "marble", "front", front, 0.0393, [0.995, 0.986, 0.990]),
        (TranslucentPreset::Skin1, "skin1", "front", front, 0.0375, [1.028, 1.005, 1.003]),
        (TranslucentPreset::Skin1, "skin1", "back", back, 0.0804, [0.999, 0.912, 1.123]),
    ];
    table_holds_as_documented(&view, "ballmesh", "the ball's triangles,", cases);
}

/// Each of `cases` — (medium, lighting, how, relative L1, mean ratio r/g/b) — index-matched
/// with the defaults' beam table, against the reference `{scene}_{medium}_{lighting}`,
/// labelled `{shown} {medium} (the beam table)`: [`holds_as_documented`].
fn table_holds_as_documented(
    view: &translucent_accuracy_scene::ShapeView,
    scene: &str,
    shown: &str,
    cases: impl IntoIterator<Item = (TranslucentPreset, &'static str, &'static str, translucent_accuracy_scene::SceneLighting, f64, [f64; 3])>,
) {
    use translucent_accuracy_scene::{Oracles, ScatteringSource};
    let table = Oracles { scattering: ScatteringSource::BeamTable(default()), ..Oracles::NONE };
    for (preset, name, lighting, how, rel_l1, ratio) in cases {
        let medium = bevy_mesostructure::translucency::TranslucentMedium {
            index_of_refraction: 1.0,
            ..preset.medium()
        };
        let reference = reference_picture(&format!("{scene}_{name}"), lighting);
        let label = format!("{shown} {name} (the beam table)");
        holds_as_documented(view, &label, lighting, medium, false, &TransportSettings::default(), how, table, &reference, rel_l1, ratio, None);
    }
}

/// The plugin's picture of `view`'s shape (960 patches on the ball, 904 on the bunny, 920 on
/// the torus: a budget of 1000) against `reference`: relative L1 and each channel's mean ratio within 0.01
/// of the documented `rel_l1` and `ratio`.
#[allow(clippy::too_many_arguments)]
fn holds_as_documented(
    view: &translucent_accuracy_scene::ShapeView,
    label: &str,
    lighting: &str,
    medium: bevy_mesostructure::translucency::TranslucentMedium,
    oriented_dipole: bool,
    settings: &TransportSettings,
    how: translucent_accuracy_scene::SceneLighting,
    oracles: translucent_accuracy_scene::Oracles,
    reference: &image::Rgb32FImage,
    rel_l1: f64,
    ratio: [f64; 3],
    floor: Option<f32>,
) {
    let picture = translucent_accuracy_scene::plugin_picture(
        view,
        medium,
        oriented_dipole,
        settings,
        bevy_mesostructure::translucency::GatherMethod::Interpolation,
        1000,
        how,
        oracles,
        floor,
        None,
        None,
    );
    let measured = translucent_accuracy_scene::score(&picture.pixels, reference, view);
    eprintln!(
        "{label} {lighting}: {} patches, relative L1 {:.4}, mean ratio {:.3?}",
        picture.patches, measured.rel_l1, measured.ratio
    );
    assert!(
        (measured.rel_l1 - rel_l1).abs() < 0.01,
        "{label} {lighting}: relative L1 {:.4}, documented {rel_l1}",
        measured.rel_l1
    );
    for (c, (&ours, &documented)) in measured.ratio.iter().zip(&ratio).enumerate() {
        assert!(
            (ours - documented).abs() < 0.01,
            "{label} {lighting}: channel {c} mean ratio {ours:.3}, documented {documented}"
        );
    }
}

/// The same figures on a shape like a game's (docs/translucent.md, "On the Stanford bunny"):
/// the bunny 4 cm long — thin ears, creases, a thick body — index-matched, lit from the front
/// and from behind, its pixels shaded by the mesh's smooth normals as the GPU's prepass gives
/// them (since 2026-11-29; by the faces' normals, the defaults scored 0.0589 / 0.1411 / 0.0737
/// with each map over the bunny's bounding sphere, 0.0582 / 0.1332 / 0.0731 with it fitted to
/// the bunny's extent), against Mitsuba (`volpathmis`, the very triangles; 8192 samples a pixel
/// for skin, noise 0.007 front and 0.014 back; 16 384 for marble from the front, noise 0.018;
/// marble from behind does not converge in Mitsuba: its reference is the mesh light
/// tracer's, `tests/data/translucent/bunny_marble_back_lighttraced.exr`). The ball-tuned
/// defaults do much worse here: the object's
/// walks raise every column by the whole bunny's share (1.18 / 1.16 / 1.14 for skin), which
/// its thin ears earn and its thick body does not; without them skin from the front is
/// closer and from behind further. With `K` from random walks (the references' physics, as
/// an oracle; 256 walks a patch shared by the channels) skin from the front is still 0.154
/// and 1.12× too bright: the profile is not what is left; with walks entering as the light's
/// own beam, 0.109 and 0.285 from behind; with single scattering leaving in its own law as
/// well, 0.082 from the front; with the beam
/// snapped to a per-patch table of 6 × 12 directions, 0.084.
#[test]
fn a_translucent_bunny_matches_mitsuba_as_documented() {
    use bevy_mesostructure::translucency::random_walk::ScatteringOrders;
    use translucent_accuracy_scene::{
        BACK_LIGHT, ExitAxis, FRONT_LIGHT, LateLight, Oracles, ScatteringSource, SceneLighting,
        Shape, ShapeView,
    };
    let view = ShapeView::new(Shape::Bunny, 96);
    let (front, back) = (
        SceneLighting::Directional(FRONT_LIGHT.normalize()),
        SceneLighting::Directional(BACK_LIGHT.normalize()),
    );
    let own = Oracles::NONE;
    let (walks, beam_walks) = (
        Oracles { scattering: ScatteringSource::Walks(256), ..own },
        Oracles { scattering: ScatteringSource::BeamWalks(256), ..own },
    );
    let beam_walks_and_law = Oracles { single_scattering_law: true, ..beam_walks };
    // The beam snapped to the nearest of 6 incidence cosines × 12 azimuths in each patch's
    // frame: what a per-patch table of beam columns would give.
    let beam_table_and_law = Oracles {
        scattering: ScatteringSource::BinnedBeamWalks {
            walks: 256,
            cosines: 6,
            azimuths: 12,
            orders: ScatteringOrders { first: 1, last: u32::MAX },
            late: LateLight::Profile,
            late_walks: 0,
            lit_face_single_to_law: false,
        },
        ..beam_walks_and_law
    };
    // The beam table (`TransportSettings::beam_table`, default settings: 4 × 8 directions,
    // walks stopped at their 17th scattering, the rest the profile's late light, single
    // scattering marched per pixel against 256² maps; before the march, in the table and the
    // lit face's law in the gather: 0.0594, 0.2181, 0.0756).
    let beam_table = Oracles { scattering: ScatteringSource::BeamTable(default()), ..own };
    // The normal's law was measured with single scattering in the table (the defaults before
    // the march).
    let beam_table_normal = Oracles {
        scattering: ScatteringSource::BeamTable(bevy_mesostructure::translucency::beam_table::BeamTableSettings {
            single_scattering_to_pixels: false,
            ..default()
        }),
        exit_axis: ExitAxis::Normal,
        ..beam_table
    };
    // (medium, lighting, how, the object's walks, oracles, relative L1, mean ratio r/g/b):
    // measured. The last four put oracles in for the plugin's own stages: `K` from 256 random
    // walks a patch, shared by the channels (the references' own physics), entering diffusely as `K`
    // assumes or as the light's own beam, and single scattering leaving each lit pixel in its
    // own law — what the profile, the beam's incidence model and the exit law cost
    // (`docs/translucent.md`).
    let cases = [
        (TranslucentPreset::Skin1, "skin1", "front", front, true, own, 0.1597, [1.093, 1.096, 1.099]),
        (TranslucentPreset::Skin1, "skin1", "back", back, true, own, 0.3481, [0.891, 0.784, 0.810]),
        (TranslucentPreset::Marble, "marble", "front", front, true, own, 0.0891, [1.014, 1.004, 0.993]),
        (TranslucentPreset::Skin1, "skin1", "front", front, false, own, 0.1195, [0.921, 0.944, 0.965]),
        (TranslucentPreset::Skin1, "skin1", "back", back, false, own, 0.3884, [0.740, 0.669, 0.707]),
        (TranslucentPreset::Skin1, "skin1", "front", front, true, walks, 0.1535, [1.114, 1.127, 1.134]),
        (TranslucentPreset::Skin1, "skin1", "front", front, true, beam_walks, 0.1131, [1.047, 1.071, 1.090]),
        (TranslucentPreset::Skin1, "skin1", "back", back, true, beam_walks, 0.2608, [0.845, 0.862, 0.874]),
        (TranslucentPreset::Skin1, "skin1", "front", front, true, beam_walks_and_law, 0.0807, [1.010, 1.018, 1.020]),
        (TranslucentPreset::Skin1, "skin1", "front", front, true, beam_table_and_law, 0.0821, [1.016, 1.018, 1.022]),
        // With its exit lobes (`TransportSettings::exit_lobes`) and each beam spread over the
        // four table directions about it (`direction_weights`; the nearest direction and the
        // flow's law alone: 0.0802, 0.2581, 0.0763), single scattering past the terminator
        // kept in the table (`law_gives_single_scattering`; before: 0.0720, 0.2360, 0.0749).
        // Walks shared by the channels, 384 and 3072 late (before, 256 and 1024 a channel:
        // 0.0713, 0.2204, 0.0749). The late light held to the light still inside after the
        // last order (before: 0.0758, 0.2171, 0.0755; the ears gave out up to 10⁴× what they
        // held). 256 beam walks split in 4 far from their entry (before, 384 unsplit: 0.0535,
        // 0.1582, 0.0753), in 16 since 2026-11-29 (in 4: 0.0609, 0.1436, 0.0713 with marble's
        // walks to 32 scatterings; about the normal 0.2751).
        // Light that came back in leaves by the patches' diffuse walks since 2026-12-08
        // (`BeamTableSettings::diffuse_columns_walked`; by the profile's `K`: 0.0620, [1.032,
        // 1.029, 1.022]; 0.1261, [0.988, 0.962, 1.012]; 0.0715, [0.998, 0.999, 0.993]; marble
        // from behind 0.1069, [0.998, 0.977, 0.962]; about the normal 0.2607, [0.881, 0.840,
        // 0.813]).
        (TranslucentPreset::Skin1, "skin1", "front", front, true, beam_table, 0.0620, [1.034, 1.030, 1.022]),
        (TranslucentPreset::Skin1, "skin1", "back", back, true, beam_table, 0.1290, [1.002, 0.983, 1.030]),
        (TranslucentPreset::Marble, "marble", "front", front, true, beam_table, 0.0716, [0.999, 1.000, 0.995]),
        // Marble lit from behind, against the mesh light tracer (two renders of 3.2·10⁷
        // photons a channel, seeds 1 and 2: a pair differs by 0.031): short of the issue's
        // 0.08 and too dark, most on the ears and the head (the exact transport given out by
        // Lambert's law is 0.86 of the reference here; docs/translucent.md, "The marble
        // bunny lit from behind"). Since 2026-12-06 the lit faces' single scattering lights
        // the other patches (`DirectLight::lit_face_exitance`; before: 0.1497, [0.955, 0.909,
        // 0.875]): light that left the bunny and came back in is a sixth of this picture.
        // Marble's walks go on to 64 scatterings on twice the late walks since 2026-12-07
        // (at 32: 0.1204, [0.978, 0.946, 0.919]; front 0.0736); the flux along the surface
        // in marble since 2026-12-07, late (without: 0.1133, [0.983, 0.962, 0.946]; front
        // 0.0733).
        (TranslucentPreset::Marble, "marble", "back", back, true, beam_table, 0.1040, [1.000, 0.983, 0.970]),
        // The table with the deep law about the normal, as before the flow.
        (TranslucentPreset::Skin1, "skin1", "back", back, true, beam_table_normal, 0.2640, [0.896, 0.861, 0.829]),
    ];
    for (preset, name, lighting, how, object_exit_share, oracles, rel_l1, ratio) in cases {
        let label = format!(
            "bunny {name}{}{}{}{}",
            if object_exit_share { "" } else { " (without the object's walks)" },
            match oracles.scattering {
                ScatteringSource::Profile => String::new(),
                ScatteringSource::Walks(n) => format!(" (K from {n} diffuse walks a patch)"),
                ScatteringSource::BeamWalks(n) => format!(" (K from {n} beam walks a patch)"),
                ScatteringSource::BinnedBeamWalks { walks, cosines, azimuths, orders, .. } => format!(
                    " (K from {walks} beam walks a patch, beams snapped to {cosines}×{azimuths}, \
                     orders {}–{})",
                    orders.first,
                    if orders.last == u32::MAX { "all".to_string() } else { orders.last.to_string() }
                ),
                ScatteringSource::BeamTable(t) => format!(
                    " (the beam table, {}×{}, {} walks)",
                    t.cosines, t.azimuths, t.walks
                ),
            },
            if oracles.single_scattering_law { " (single scattering in its own law)" } else { "" },
            if oracles.exit_axis == ExitAxis::Normal { " (the deep law about the normal)" } else { "" },
        );
        let settings = TransportSettings {
            object_exit_share,
            ..default()
        };
        let reference = reference_picture(&format!("bunny_{name}"), lighting);
        // Index-matched, as Mitsuba's `null` boundary.
        let medium = bevy_mesostructure::translucency::TranslucentMedium {
            index_of_refraction: 1.0,
            ..preset.medium()
        };
        holds_as_documented(&view, &label, lighting, medium, false, &settings, how, oracles, &reference, rel_l1, ratio, None);
    }
}

/// Content none of the defaults were chosen on: a torus lying flat (ring radius 1 cm, tube
/// radius 3 mm: a part thinner than skin's red light travels, curved both ways, with a
/// hole), index-matched, lit from the front and from behind, against Mitsuba (`volpathmis`
/// on the very triangles, 8192 samples a pixel; noise 0.007 for skin from the front, by a
/// second render of another seed; marble from behind is the mean of four renders, seeds
/// 0 – 3, noise 0.025 (0.033 for one)). The defaults (the beam table, single scattering
/// marched per pixel against 256² maps, seed 0): both fronts within the issue's 0.08 (skin
/// 0.062, marble 0.051); from behind skin 0.091, marble 0.128 and 0.92 / 0.89 / 0.88× (walks
/// in marble go on to 32 scatterings, `BeamTableSettings::max_last_order`; at 16, 0.142
/// against one render; with each beam walk split in 4 far from its entry instead of 16,
/// skin 0.057 / 0.093, marble 0.049 / 0.128, under the point light 0.059 / 0.099, in the
/// hole 0.091). Earlier figures, against one render: with `K` from the light's own
/// beam walks (an oracle) marble from behind was 0.83× the reference; single scattering in
/// the table and the lit face's law in the gather (the defaults before): 0.086, 0.220,
/// 0.062, 0.182; the diffusion profile alone (the defaults before the table): 0.160, 0.330,
/// 0.079, 0.238. Under a point light 5 cm from its centre (3.8 of its
/// bounding radii; Mitsuba's `point`, irradiance 1 across its rays at the centre) the skin
/// scores 0.060 from the front and 0.106 from behind, its maps in perspective from the light;
/// with orthographic maps along the line to the centre (before) 0.114 and 0.111.
#[test]
fn a_translucent_torus_matches_mitsuba_as_documented() {
    use translucent_accuracy_scene::{BACK_LIGHT, FRONT_LIGHT, SceneLighting, Shape, ShapeView};
    let view = ShapeView::new(Shape::Torus, 96);
    let (front, back) = (
        SceneLighting::Directional(FRONT_LIGHT.normalize()),
        SceneLighting::Directional(BACK_LIGHT.normalize()),
    );
    // A point light 5 cm back along a directional light's travel.
    let point = |travel: Vec3| SceneLighting::Point(-travel.normalize() * 0.05);
    // (medium, lighting, how, relative L1, mean ratio r/g/b): measured. Since 2026-12-06 the
    // lit faces' single scattering lights the other patches, across the hole (before:
    // 0.0609, 0.0901, 0.0501, 0.1323, 0.0637, 0.0965, 0.0852). Marble at 64 scatterings on
    // twice the late walks since 2026-12-07 (at 32: 0.0506, [1.005, 1.008, 1.008]; 0.1133,
    // [0.938, 0.909, 0.902]); the flux along the surface in marble since 2026-12-07, late
    // (without: 0.0538, [1.003, 1.004, 1.005]; 0.1063, [0.946, 0.918, 0.905]). Light that
    // came back in across the hole leaves by the patches' diffuse walks since 2026-12-08
    // (`BeamTableSettings::diffuse_columns_walked`; by the profile's `K`: 0.0546, 0.0921,
    // 0.0480, 0.0910, 0.0554, 0.0993, 0.0709).
    let cases = [
        (TranslucentPreset::Skin1, "skin1", "front", front, 0.0546, [0.976, 0.994, 1.007]),
        (TranslucentPreset::Skin1, "skin1", "back", back, 0.0928, [1.021, 1.012, 0.995]),
        (TranslucentPreset::Marble, "marble", "front", front, 0.0480, [0.997, 0.998, 0.999]),
        (TranslucentPreset::Marble, "marble", "back", back, 0.0900, [0.961, 0.935, 0.922]),
        (TranslucentPreset::Skin1, "skin1", "front_point0.05", point(FRONT_LIGHT), 0.0553, [0.980, 0.994, 1.004]),
        (TranslucentPreset::Skin1, "skin1", "back_point0.05", point(BACK_LIGHT), 0.0996, [1.003, 0.999, 0.989]),
        // A point light in the hole, 3 mm above the middle (inside the bounds: a cube of
        // maps; 0.325 with the one orthographic map before).
        (TranslucentPreset::Skin1, "skin1", "hole_point0.003", SceneLighting::Point(Vec3::new(0.0, 0.003, 0.0)), 0.0709, [0.977, 0.997, 1.014]),
    ];
    table_holds_as_documented(&view, "torus", "torus", cases);
}

/// Light bounced between objects, against a path tracer (docs/translucent.md, "Over a
/// floor"): the 1 cm ball 2 mm above a grey Lambertian floor of albedo 0.8 (4 cm square),
/// lit from above, in front and to the right, so that the floor lights the ball's lower half.
/// The floor's patches, its light and the form factors carry the bounce both ways; the
/// ball's 496 of the scene's 980 patches are scored against Mitsuba (`volpathmis`; skin 2 ×
/// 4096 samples a pixel, noise 0.007; marble 4 × 4096, noise 0.021 from its fireflies). The
/// floor gives the ball 28 – 30 % of its light; left black in the plugin under the same
/// reference, the ball is 0.28 / 0.30 off (the second rows: what the bounce is worth).
/// Before 2026-11-29 the gather gave all light from elsewhere in a translucent patch out by
/// the law of the table's flow (the direct light's way through the object), bounced light
/// included: 0.083 (skin) and 0.080 (marble), the skin's bounce 0.85 / 0.69 / 0.57 of the
/// reference's.
#[test]
fn a_translucent_ball_over_a_floor_matches_mitsuba_as_documented() {
    use translucent_accuracy_scene::{Oracles, ScatteringSource, SceneLighting, Shape, ShapeView};
    let view = ShapeView::new(Shape::Ball, 96);
    let above = SceneLighting::Directional(Vec3::new(-1.0, -1.0, -0.3).normalize());
    let table = Oracles { scattering: ScatteringSource::BeamTable(default()), ..Oracles::NONE };
    // (medium, the plugin's floor albedo, relative L1, mean ratio r/g/b): measured (marble at
    // 64 scatterings since 2026-12-07; at 32: 0.0600, [1.028, 1.027, 1.026]; 0.2914, [0.732,
    // 0.731, 0.731]; the flux along the surface in marble since 2026-12-07, late: without it
    // 0.0624, [1.031, 1.031, 1.031]; 0.2901, [0.735, 0.736, 0.736]). The floor's light
    // enters the ball by its patches' diffuse walks since 2026-12-08
    // (`BeamTableSettings::diffuse_columns_walked`; by the profile's `K`: skin 0.0381,
    // [0.994, 1.003, 1.031], marble 0.0649, [1.036, 1.036, 1.035]).
    let cases = [
        (TranslucentPreset::Skin1, "skin1", 0.8, 0.0391, [0.998, 1.015, 1.051]),
        (TranslucentPreset::Skin1, "skin1", 0.0, 0.2728, [0.718, 0.742, 0.778]),
        (TranslucentPreset::Marble, "marble", 0.8, 0.0658, [1.038, 1.038, 1.037]),
        (TranslucentPreset::Marble, "marble", 0.0, 0.2904, [0.737, 0.738, 0.739]),
    ];
    for (preset, name, floor, rel_l1, ratio) in cases {
        let reference = reference_picture(name, "front_floor0.8");
        let medium = bevy_mesostructure::translucency::TranslucentMedium { index_of_refraction: 1.0, ..preset.medium() };
        let label = format!("ball {name} over a floor of albedo {floor} (the reference's 0.8)");
        holds_as_documented(&view, &label, "front_floor0.8", medium, false, &TransportSettings::default(), above, table, &reference, rel_l1, ratio, Some(floor));
    }
}

// Only the directional light and the whole picture are used here.
#[allow(dead_code)]
#[path = "../../examples/common/translucent_light_tracer.rs"]
mod translucent_light_tracer;

/// The mesh light tracer (`translucent_accuracy`'s reference for a mesh lit from behind,
/// where Mitsuba's walks from the camera do not converge) against Mitsuba where Mitsuba
/// does: the bunny's skin lit from the front (8192 samples a pixel, noise 0.007). 250 000
/// photons a channel here (noise ~0.13 in relative L1; in the mean, under 1 %); at 1.6·10⁷,
/// 0.018 and 1.000 / 1.001 / 1.001 (docs/translucent.md, "A light tracer for meshes").
#[test]
fn the_mesh_light_tracer_matches_mitsuba_where_mitsuba_converges() {
    use translucent_accuracy_scene::{FOV_Y, FRONT_LIGHT, Shape, ShapeView, score};
    use translucent_light_tracer::{Part, Pinhole, Source, light_trace};
    let view = ShapeView::new(Shape::Bunny, 96);
    let medium = bevy_mesostructure::translucency::TranslucentMedium { index_of_refraction: 1.0, ..TranslucentPreset::Skin1.medium() };
    let camera = Pinhole { eye: Shape::Bunny.eye(), fov_y: FOV_Y, size: 96 };
    let traced = light_trace(&view.positions, &view.indices, &medium, Source::Directional(FRONT_LIGHT), Part::All, camera, 250_000, 1, 2, None);
    let pixels: Vec<Vec3> = traced.pixels.iter().map(|p| Vec3::from_array(*p)).collect();
    let measured = score(&pixels, &reference_picture("bunny_skin1", "front"), &view);
    eprintln!(
        "mesh light tracer, bunny skin1 front: relative L1 {:.4} (its own noise {:.4}), mean ratio {:.3?}; {} of {} crossings against the faces' side",
        measured.rel_l1, traced.noise, measured.ratio, traced.side_disagreements, traced.crossings
    );
    // Measured 0.1243 (1.6·10⁷ photons: 0.018), 0.998 / 1.002 / 0.999 in the mean.
    assert!((measured.rel_l1 - 0.1243).abs() < 0.01, "relative L1 {:.4}, documented 0.1243", measured.rel_l1);
    for (c, ratio) in measured.ratio.iter().enumerate() {
        assert!((ratio - 1.0).abs() < 0.015, "channel {c}: mean ratio {ratio:.4}");
    }
    assert!(traced.side_disagreements * 1000 < traced.crossings);
}

/// The exact transport's exitance on the plugin's own patches (`patch_exitance`, the
/// accuracy tool's `--exact-exitance` oracle): every exit after a scattering lands on a
/// patch, and what the patches hold is the light that left. A marble ball of 720 triangles
/// 1 cm in radius lit from the front, index-matched, a budget of 1000 (960 patches),
/// 200 000 photons a channel: no exit on no patch; what left, `Σ a B` over the light on the
/// sphere's disc `πr²`, measured 0.965 / 0.946 / 0.924 in red / green / blue (one less what
/// marble absorbs on the way), held within 0.01. The lit pole's patches (normals within 25°
/// of the light) hold more than twice the far hemisphere's mean in each channel.
#[test]
fn the_exact_exitance_on_the_patches_is_the_light_that_left() {
    use bevy_mesostructure::translucency::{PatchObject, TranslucentMedium};
    use translucent_accuracy_scene::{FOV_Y, FRONT_LIGHT, RADIUS, Shape, ShapeView};
    use translucent_light_tracer::{Pinhole, Reentering, patch_exitance};
    let view = ShapeView::on_mesh(Shape::Ball, 32);
    let medium = TranslucentMedium { index_of_refraction: 1.0, ..TranslucentPreset::Marble.medium() };
    let patches = resample_into_patches(&[PatchObject { positions: &view.positions, indices: &view.indices }], 1000);
    let camera = Pinhole { eye: Shape::Ball.eye(), fov_y: FOV_Y, size: 32 };
    let light = FRONT_LIGHT.normalize();
    let (exitance, unbinned) = patch_exitance(&view.positions, &view.indices, &medium, light, &patches, camera, 200_000, 1, 2, 0, Reentering::All);
    let left: Vec3 = patches.patches.iter().zip(&exitance).map(|(q, b)| q.area * *b).sum();
    let share = left / (std::f32::consts::PI * RADIUS * RADIUS);
    eprintln!("exact exitance on {} patches: left {share:.4?} of the light on the disc, {unbinned:?} of the exits on no patch", patches.patches.len());
    assert!(unbinned.max_element() < 1e-4, "exits on no patch: {unbinned:?}");
    for (c, measured) in [0.965, 0.946, 0.924].into_iter().enumerate() {
        assert!((share[c] - measured).abs() < 0.01, "channel {c}: {:.4} left, measured {measured}", share[c]);
    }
    let mean_of = |keep: &dyn Fn(f32) -> bool| {
        let (sum, area) = patches
            .patches
            .iter()
            .zip(&exitance)
            .filter(|(q, _)| keep(q.normal.dot(-light)))
            .fold((Vec3::ZERO, 0.0), |(s, a), (q, b)| (s + q.area * *b, a + q.area));
        sum / area
    };
    let (pole, far) = (mean_of(&|c| c > 25f32.to_radians().cos()), mean_of(&|c| c < 0.0));
    assert!(pole.cmpgt(2.0 * far).all(), "lit pole {pole:?} against the far side {far:?}");
}

/// Single scattering marched per pixel (`BeamTableSettings::single_scattering_to_pixels`, on
/// by default): every pixel's single scattering along its ray through the object against
/// the light's own path in it, in place of the half-space law at the lit face and the
/// table's single scattering past it; by rays, the oracle of the plugin's march.
/// - The term alone against Mitsuba's single scattering (`max_depth` 2, 8192 samples a pixel;
///   a second seed differs by 0.022 for skin, 0.020 for marble) on the torus lit from behind.
/// - With the beam table (seed 0), the torus's skin lit from the front within the issue's
///   0.08 (0.086 with the half-space law) and from behind 0.093 (0.220); the plugin's march
///   against its 256² maps (`MarchedObject`, the GPU's twin) instead of rays, 0.060 and 0.097.
#[test]
fn single_scattering_marched_per_pixel_holds_as_documented() {
    use bevy_mesostructure::translucency::{PatchObject, SceneRays, beam_table::BeamTableSettings};
    use translucent_accuracy_scene::{BACK_LIGHT, FRONT_LIGHT, Oracles, ScatteringSource, SceneLighting, Shape, ShapeView};
    let view = ShapeView::new(Shape::Torus, 96);
    let rays = SceneRays::new(&[PatchObject { positions: &view.positions, indices: &view.indices }]);
    let travel = BACK_LIGHT.normalize();
    // (medium, relative L1, mean ratio r/g/b): measured.
    for (preset, name, rel_l1, ratio) in [
        (TranslucentPreset::Skin1, "skin1", 0.0275, [0.997, 0.998, 0.996]),
        (TranslucentPreset::Marble, "marble", 0.0466, [0.996, 0.997, 0.998]),
    ] {
        let medium = bevy_mesostructure::translucency::TranslucentMedium { index_of_refraction: 1.0, ..preset.medium() };
        let pixels: Vec<Vec3> = view
            .hits
            .iter()
            .map(|hit| {
                hit.as_ref().map_or(Vec3::ZERO, |hit| {
                    translucent_accuracy_scene::marched_single_scattering(Shape::Torus, &rays, medium, travel, hit)
                })
            })
            .collect();
        let reference = reference_picture(&format!("torus_{name}"), "back_single");
        let measured = translucent_accuracy_scene::score(&pixels, &reference, &view);
        eprintln!("torus {name} back, single scattering marched: relative L1 {:.4}, mean ratio {:.3?}", measured.rel_l1, measured.ratio);
        assert!((measured.rel_l1 - rel_l1).abs() < 0.01, "{name}: relative L1 {:.4}, documented {rel_l1}", measured.rel_l1);
        for c in 0..3 {
            assert!((measured.ratio[c] - ratio[c]).abs() < 0.01, "{name}: mean ratio {:.3?}, documented {ratio:?}", measured.ratio);
        }
    }
    // By rays (the oracle), and against the plugin's 256² maps at its 16 depths a channel.
    let mapped = Oracles {
        scattering: ScatteringSource::BeamTable(BeamTableSettings { single_scattering_to_pixels: true, ..default() }),
        ..Oracles::NONE
    };
    let marched = Oracles { shadow_map: None, ..mapped };
    let medium = bevy_mesostructure::translucency::TranslucentMedium { index_of_refraction: 1.0, ..TranslucentPreset::Skin1.medium() };
    for (oracles, label, lighting, how, rel_l1, ratio) in [
        (marched, "rays", "front", SceneLighting::Directional(FRONT_LIGHT.normalize()), 0.0529, [0.976, 0.994, 1.006]),
        (marched, "rays", "back", SceneLighting::Directional(travel), 0.0887, [1.017, 1.009, 0.994]),
        (mapped, "a 256² map", "front", SceneLighting::Directional(FRONT_LIGHT.normalize()), 0.0546, [0.976, 0.993, 1.007]),
        (mapped, "a 256² map", "back", SceneLighting::Directional(travel), 0.0921, [1.020, 1.011, 0.996]),
    ] {
        let reference = reference_picture("torus_skin1", lighting);
        let label = format!("torus skin1 (the table, single scattering marched against {label})");
        holds_as_documented(&view, &label, lighting, medium, false, &TransportSettings::default(), how, oracles, &reference, rel_l1, ratio, None);
    }
}

/// The gather's compute form culls the patches per 8×8 tile and lets a tile over a depth edge
/// walk the grids pixel by pixel; both must draw what the fragment form draws. A marble ball
/// before a white wall that takes part (`RadiosityReceiver`), seen so that the ball's outline
/// crosses the wall: the tiles on the outline span both depths (a box of many cells of the
/// ball's fine grid: they walk pixel by pixel), the rest take their tile's list. Then the
/// half-resolution gather (`GatherResolution::Half`, the default) against the full one on the
/// same view, outline included: its pixels that no sample of their own surface serves gather
/// themselves.
#[test]
fn the_tiled_gather_draws_what_the_fragment_gather_does_across_depth_edges() {
    use bevy::light::GlobalAmbientLight;
    use bevy_mesostructure::translucency::{
        GatherResolution, RadiosityReceiver, TranslucencyPlugin, TranslucencySettings, Translucent,
    };
    if !gpu_or_skip() {
        return;
    }
    let mut app = bare_app_with(|app| {
        app.add_plugins(TranslucencyPlugin);
    });
    app.insert_resource(GlobalAmbientLight {
        brightness: 0.0,
        ..default()
    });
    app.insert_resource(TranslucencySettings {
        patch_budget: 600,
        gather_resolution: GatherResolution::Full,
        transport: TransportSettings { beam_table: None, ..default() },
        ..default()
    });
    sun(&mut app, Vec3::new(-1.0, -0.4, -0.6).normalize(), 2_000.0);
    let white = matte_white(&mut app);
    let ball = mesh(&mut app, Sphere::new(0.05).mesh().uv(48, 24));
    app.world_mut().spawn((
        ball,
        MeshMaterial3d(white.clone()),
        Translucent::default(),
        Transform::IDENTITY,
    ));
    let wall = mesh(&mut app, Cuboid::new(0.6, 0.6, 0.02));
    app.world_mut().spawn((
        wall,
        MeshMaterial3d(white),
        RadiosityReceiver,
        Transform::from_xyz(0.0, 0.0, -0.12),
    ));
    let size = 64;
    let image = target(&mut app, size, size);
    let eye = Transform::from_xyz(0.05, 0.03, 0.3).looking_at(Vec3::ZERO, Vec3::Y);
    let camera = hdr_translucency_camera(&mut app, &image, eye);
    run_until_ready(&mut app);
    run(&mut app, 3);
    assert_pipelines_ready_with_prefix(&app, "translucency_gather");
    let tiled = screenshot(&mut app, &image);

    // The half-resolution gather against the full one (the compute form's both).
    app.world_mut().resource_mut::<TranslucencySettings>().gather_resolution = GatherResolution::Half;
    run(&mut app, 3);
    assert_pipelines_ready_with_prefix(&app, "translucency_gather");
    let half = screenshot(&mut app, &image);
    let (a, b) = (tiled.data.as_ref().unwrap(), half.data.as_ref().unwrap());
    let (mut worst, mut sum, mut moved) = (0u8, 0u64, 0usize);
    for (p, q) in a.chunks(4).zip(b.chunks(4)) {
        let d = (0..3).map(|c| p[c].abs_diff(q[c])).max().unwrap();
        worst = worst.max(d);
        sum += d as u64;
        moved += usize::from(d > 0);
    }
    let mean = sum as f32 / (size * size) as f32;
    eprintln!("half against full gather: mean {mean:.3}/255, worst {worst}/255, {moved} pixels differ");
    // Measured 0.146/255 mean, 16/255 worst, 272 of 4096 pixels differing: at 64 × 64 a
    // patch's reach is ~4 pixels, the samples 2 apart (at 960 × 540 in the example's room
    // 0.019/255 mean, 47 pixels of 518 400 off by more than 8).
    assert!(mean <= 0.25 && worst <= 24, "half against full: mean {mean}, worst {worst}");
    // (The same picture would mean that the half-resolution passes did not run.)
    assert!(moved > 0, "the half-resolution gather drew the full one's picture to the bit");
    app.world_mut().resource_mut::<TranslucencySettings>().gather_resolution = GatherResolution::Full;
    run(&mut app, 3);

    let differ = fragment_gather_difference(&mut app, camera, &image, &tiled);
    let lit = tiled.data.as_ref().unwrap().chunks(4).filter(|p| p[0] >= 3).count();
    eprintln!("tiled against fragment gather across the ball's outline: largest difference {differ}/255; {lit} pixels lit");
    assert!(lit > (size * size / 2) as usize, "the ball and the wall show their light: {lit} pixels");
    assert!(differ <= 1, "the two forms of the gather differ by {differ}/255");
}

/// A point light inside a translucent object's bounds: a torus of skin with the light in its
/// hole, lighting the ring's inner side. Its maps are a cube of six faces about the light
/// (`MapFrame::frames_towards`), each depth of the march looking in the face it lies in
/// (one map along the line to the centre scored 0.325 against a path tracer here, the cube
/// 0.091 – 0.101: `docs/translucent.md`). The GPU's maps and march against their CPU twin
/// (`MarchedObject`) over the torus's pixels, as `a_translucent_ball_shows_the_light_its_patches_carry`
/// holds the ball's under the sun and a spot.
#[test]
fn a_light_inside_a_translucent_objects_bounds_marches_against_a_cube_of_maps() {
    use bevy_mesostructure::translucency::{TranslucencyFrame, Translucent, translucent_shadow_map::MapFrame};
    let Some(mut app) = marching_app() else {
        return;
    };
    let torus = Torus::new(0.02, 0.04);
    let (positions, indices) = object(torus.mesh().build(), Transform::IDENTITY);
    let mesh3d = mesh(&mut app, torus.mesh().build());
    let material = matte_white(&mut app);
    app.world_mut().spawn((
        mesh3d,
        MeshMaterial3d(material),
        Translucent { medium: TranslucentPreset::Skin1.medium(), ..default() },
        Transform::IDENTITY,
    ));
    // In the hole, 5 mm above the ring's middle plane: 0.13 of the bounding radius from its
    // centre.
    let light_at = Vec3::new(0.0, 0.005, 0.0);
    app.world_mut().spawn((PointLight { intensity: 2.0, range: 1.0, ..default() }, Transform::from_translation(light_at)));
    let size = 64;
    let image = target(&mut app, size, size);
    // From above and in front: the ring's inner side beyond the hole faces the camera.
    let eye = Transform::from_xyz(0.0, 0.11, 0.07).looking_at(Vec3::ZERO, Vec3::Y);
    let camera = hdr_translucency_camera(&mut app, &image, eye);
    run_until_ready(&mut app);
    run(&mut app, 3);
    let frame = app.world().resource::<TranslucencyFrame>().clone();
    let (_, scene) = frame.scene.expect("a scene");
    let (_, lights) = frame.lights.expect("the GPU injects the light");
    let (centre, radius) = scene.bounds;
    let faces = MapFrame::frames_towards(&lights.lights[0], centre, radius);
    assert_eq!(faces.len(), 6, "a light {} bounding radii from the centre takes a cube", light_at.distance(centre) / radius);
    let (pixels, eye) = pixels_facing_the_camera(&mut app, camera, size, &positions, &indices);
    let (compared, mean, worst, marching) = marched_against_its_twin(&mut app, &image, &pixels, eye);
    eprintln!("a light in the torus's hole: {compared} pixels: mean |GPU − CPU| {mean:.2}/255, worst {worst:.1}/255; the march gives {marching} more than 2/255");
    assert!(compared > 500 && marching > 100, "{compared} compared, {marching} marching");
    assert!(mean <= 1.0 && worst <= 3.0, "a light in the torus's hole: mean {mean}, worst {worst}");
    assert!(!warnings(&app).iter().any(|c| c == "translucency-cube-maps"));

    // More lights inside objects' bounds than take a cube (`MAX_CUBE_MAPS`, 8): a small ball
    // in the hole and five lights about it, each inside both the ball's bounds and the
    // torus's (with the first light, eleven pairs). The three past the cap keep one map, with
    // one warning.
    let ball = mesh(&mut app, Sphere::new(0.006).mesh().ico(3).expect("a sphere"));
    let material = matte_white(&mut app);
    app.world_mut().spawn((
        ball,
        MeshMaterial3d(material),
        Translucent { medium: TranslucentPreset::Skin1.medium(), ..default() },
        Transform::from_xyz(0.0, 0.012, 0.0),
    ));
    for k in 0..4 {
        let angle = k as f32 * std::f32::consts::FRAC_PI_2;
        let at = Vec3::new(angle.cos(), 0.3, angle.sin()).normalize() * 0.0062 + Vec3::new(0.0, 0.012, 0.0);
        app.world_mut().spawn((PointLight { intensity: 1.0, range: 1.0, ..default() }, Transform::from_translation(at)));
    }
    app.world_mut().spawn((PointLight { intensity: 1.0, range: 1.0, ..default() }, Transform::from_xyz(0.0, 0.0182, 0.0)));
    run_until_ready(&mut app);
    run(&mut app, 3);
    assert!(
        warnings(&app).iter().any(|c| c == "translucency-cube-maps"),
        "eleven lights and objects inside bounds, past the cap: {:?}",
        warnings(&app)
    );
}

/// A translucent object whose maps are fitted to it (`MapFrame::fitted_to`): a skin cube under
/// the sun and a point light above it. Each light's map covers the cube's outline across the
/// light, narrower than its bounding sphere's (whose radius is half the cube's diagonal), and
/// the GPU's maps and march, fitted alike, hold to their CPU twin (`MarchedObject`) over the
/// cube's pixels as the ball's and the torus's do.
#[test]
fn a_translucent_cube_marches_against_maps_fitted_to_it() {
    use bevy_mesostructure::translucency::{
        TranslucencyFrame, Translucent,
        translucent_shadow_map::{MapFit, MapFrame, object_bounds},
    };
    let Some(mut app) = marching_app() else {
        return;
    };
    let cuboid = Cuboid::new(0.03, 0.03, 0.03);
    let (positions, indices) = object(cuboid.mesh().build(), Transform::IDENTITY);
    let mesh3d = mesh(&mut app, cuboid.mesh().build());
    let material = matte_white(&mut app);
    app.world_mut().spawn((
        mesh3d,
        MeshMaterial3d(material),
        Translucent { medium: TranslucentPreset::Skin1.medium(), ..default() },
        Transform::IDENTITY,
    ));
    app.world_mut().spawn((
        DirectionalLight { illuminance: 2_000.0, ..default() },
        Transform::default().looking_to(Vec3::new(0.3, -1.0, 0.2), Vec3::Z),
    ));
    app.world_mut().spawn((PointLight { intensity: 2_000.0, range: 1.0, ..default() }, Transform::from_xyz(-0.02, 0.12, 0.03)));
    let size = 64;
    let image = target(&mut app, size, size);
    let eye = Transform::from_xyz(0.03, 0.08, 0.09).looking_at(Vec3::ZERO, Vec3::Y);
    let camera = hdr_translucency_camera(&mut app, &image, eye);
    run_until_ready(&mut app);
    run(&mut app, 3);
    let frame = app.world().resource::<TranslucencyFrame>().clone();
    let (_, scene) = frame.scene.expect("a scene");
    let (_, lights) = frame.lights.expect("the GPU injects the light");
    assert_eq!(lights.lights.len(), 2);
    // The cube's maps' sphere and fit, as the plugin makes them of its one object.
    let (centre, radius) = object_bounds(&scene.patches.samples).expect("the cube's samples");
    let fit = MapFit::of(&scene.patches.samples);
    for light in &lights.lights {
        let (sphere, fitted) = (MapFrame::frames_towards(light, centre, radius), MapFrame::frames_fitted(light, centre, radius, &fit));
        assert_eq!((sphere.len(), fitted.len()), (1, 1));
        eprintln!("the cube's map: {:.3} of its sphere's width", fitted[0].width / sphere[0].width);
        assert!(fitted[0].width < 0.9 * sphere[0].width, "{:?} against {:?}", fitted[0], sphere[0]);
    }
    let (pixels, eye) = pixels_facing_the_camera(&mut app, camera, size, &positions, &indices);
    let (compared, mean, worst, marching) = marched_against_its_twin(&mut app, &image, &pixels, eye);
    eprintln!("a cube under two lights: {compared} pixels: mean |GPU − CPU| {mean:.2}/255, worst {worst:.1}/255; the march gives {marching} more than 2/255");
    // Measured 0.13/255 mean, 0.8/255 worst, 258 pixels marching; with the GPU's maps left
    // over the sphere while the twin's are fitted, 0.16 and 2.7: held tighter than the ball's
    // and the torus's 1.0 and 3.0, so that maps fitted on one side only show.
    assert!(compared > 500 && marching > 100, "{compared} compared, {marching} marching");
    assert!(mean <= 0.5 && worst <= 1.5, "a cube under two lights: mean {mean}, worst {worst}");
}
