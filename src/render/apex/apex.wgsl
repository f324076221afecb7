// Apex pass (paper §2.2): the local apex set f(P) of every mesostructure pixel — the direct
// apex by gradient ascent from P, and for each of `apex_directions` directions the apex of that
// direction (walk to the valley, climb along the direction to the steepest rise), boundary
// points where a climb would leave the visible region.
// Work per pixel is bounded by `max_ascent_steps + 2 × apex_directions × max_sample_radius`
// texel reads. At a reduced working resolution one invocation searches for a block of
// `apex_block`² pixels, from its first mesostructure pixel (the others share that set).
// Mirrors `reference::apex_set`.

#import bevy_mesostructure::common::{
    MesostructureUniform, FLAG_VALID, APEX_DIRECT_PRESENT, APEX_TRUNCATED, APEX_BOUNDARY_SHIFT,
    APEX_MIN_RISE, APEX_ORIGIN_SHIFT, neighbour_offset, neighbour_index, on_screen, is_connected, pack_offset,
    sample_direction, apex_base, mhgm_height, mhgm_flags, mhgm_ascent,
}

@group(0) @binding(0) var mhm: texture_2d<f32>;
@group(0) @binding(1) var mhgm: texture_2d<u32>;
@group(0) @binding(2) var<storage, read_write> apex_sets: array<u32>;
// [mesostructure pixels, pixels whose search hit the step bound, ascent steps, unused]
@group(0) @binding(3) var<storage, read_write> stats: array<atomic<u32>, 4>;
@group(0) @binding(4) var<uniform> settings: MesostructureUniform;

const CLIMB_FLATNESS: f32 = 1.0e-4;
const KIND_LOCAL: u32 = 0u;
const KIND_BOUNDARY: u32 = 1u;
const KIND_TRUNCATED: u32 = 2u;

fn height_at(p: vec2<i32>) -> f32 {
    return mhgm_height(textureLoad(mhgm, p, 0));
}

fn flags_at(p: vec2<i32>) -> u32 {
    return mhgm_flags(textureLoad(mhgm, p, 0));
}

struct Ascent {
    apex: vec2<i32>,
    kind: u32,
    steps: u32,
}

fn ascend(start: vec2<i32>) -> Ascent {
    var cur = start;
    for (var steps = 0u; steps < settings.max_ascent_steps; steps++) {
        let t = textureLoad(mhgm, cur, 0);
        let flags = mhgm_flags(t);
        let h = mhgm_height(t);
        var next = 8u;
        let dir = mhgm_ascent(t);
        if dir < 8u {
            if !is_connected(flags, dir) {
                return Ascent(cur, KIND_BOUNDARY, steps);
            }
            if height_at(cur + neighbour_offset(dir)) > h {
                next = dir;
            }
        }
        if next == 8u {
            // Ridges: the quantized direction misses; take the highest higher neighbour.
            var best = h;
            for (var d = 0u; d < 8u; d++) {
                if is_connected(flags, d) {
                    let hd = height_at(cur + neighbour_offset(d));
                    if hd > best {
                        best = hd;
                        next = d;
                    }
                }
            }
        }
        if next == 8u {
            return Ascent(cur, KIND_LOCAL, steps);
        }
        cur += neighbour_offset(next);
    }
    return Ascent(cur, KIND_TRUNCATED, settings.max_ascent_steps);
}

fn line_point(p: vec2<i32>, d: vec2<f32>, t: u32) -> vec2<i32> {
    return p + vec2<i32>(floor(f32(t) * d + 0.5));
}

// Start of the indirect sample of direction d: walk from P while the height does not rise,
// start at the first pixel higher than the one before; (x, y, t), or t = 0 when the walk
// leaves the visible region or finds nothing rising within max_walk pixels.
// See `reference::valley_walk`.
fn valley_walk(p: vec2<i32>, d: vec2<f32>) -> vec3<i32> {
    var prev = p;
    var previous = height_at(p);
    for (var t = 1u; t <= settings.max_walk; t++) {
        let q = line_point(p, d, t);
        if all(q == prev) {
            continue;
        }
        let dir = neighbour_index(q - prev);
        if dir == 8u || !is_connected(flags_at(prev), dir) {
            return vec3(0);
        }
        let h = height_at(q);
        if h > previous {
            return vec3(q, i32(t));
        }
        prev = q;
        previous = h;
    }
    return vec3(0);
}

// The apex of direction d: climb along the line from the walk's start while the height
// rises; keep the pixel of steepest rise (h − h0) / t. See `reference::line_climb`.
fn line_climb(p: vec2<i32>, h0: f32, d: vec2<f32>, start: vec3<i32>) -> Ascent {
    var cur = start.xy;
    let t0 = u32(start.z);
    var previous = height_at(cur);
    var best = cur;
    var best_rise = (previous - h0) / f32(t0);
    var kind = KIND_LOCAL;
    for (var t = t0 + 1u; t <= t0 + settings.max_walk; t++) {
        let q = line_point(p, d, t);
        if all(q == cur) {
            continue;
        }
        let dir = neighbour_index(q - cur);
        if dir == 8u {
            break;
        }
        if !is_connected(flags_at(cur), dir) {
            if all(best == cur) {
                kind = KIND_BOUNDARY;
            }
            break;
        }
        let h = height_at(q);
        if h <= previous + CLIMB_FLATNESS * abs(previous) {
            break;
        }
        let rise = (h - h0) / f32(t);
        if rise > best_rise {
            best = q;
            best_rise = rise;
        }
        cur = q;
        previous = h;
    }
    return Ascent(best, kind, t0);
}

@compute @workgroup_size(8, 8, 1)
fn apex(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = vec2<i32>(textureDimensions(mhgm));
    let b = settings.apex_block;
    let corner = vec2<i32>(id.xy * b);
    if !on_screen(corner, size) {
        return;
    }
    let base = apex_base(settings, corner, size);
    // The block's origin: its first mesostructure pixel in row order.
    var p = vec2(-1);
    for (var i = 0u; i < b * b; i++) {
        let q = corner + vec2<i32>(vec2(i % b, i / b));
        if on_screen(q, size) && (flags_at(q) & FLAG_VALID) != 0u {
            p = q;
            break;
        }
    }
    if p.x < 0 {
        apex_sets[base] = 0u;
        return;
    }
    let h0 = height_at(p);
    let inside = vec2<u32>(p - corner);
    var header = (inside.x << APEX_ORIGIN_SHIFT) | (inside.y << (APEX_ORIGIN_SHIFT + 2u));
    var count = 0u;
    var truncated = false;

    let direct = ascend(p);
    var steps = direct.steps;
    truncated = direct.kind == KIND_TRUNCATED;
    if height_at(direct.apex) > h0 + APEX_MIN_RISE {
        apex_sets[base + 1u] = pack_offset(direct.apex - p);
        header |= APEX_DIRECT_PRESENT;
        if direct.kind == KIND_BOUNDARY {
            header |= 1u << APEX_BOUNDARY_SHIFT;
        }
        count = 1u;
    }

    for (var i = 0u; i < settings.apex_directions; i++) {
        let d = sample_direction(settings, i);
        let s = valley_walk(p, d);
        if s.z == 0 {
            continue;
        }
        let a = line_climb(p, h0, d, s);
        steps += a.steps;
        if !(height_at(a.apex) > h0 + APEX_MIN_RISE) {
            continue;
        }
        let packed = pack_offset(a.apex - p);
        var duplicate = false;
        for (var j = 0u; j < count; j++) {
            if apex_sets[base + 1u + j] == packed {
                duplicate = true;
                break;
            }
        }
        if duplicate {
            continue;
        }
        apex_sets[base + 1u + count] = packed;
        if a.kind == KIND_BOUNDARY {
            header |= 1u << (APEX_BOUNDARY_SHIFT + count);
        }
        count += 1u;
    }

    header |= count;
#ifdef STATISTICS
    // Only in the variant for captured views: three global atomics per pixel are contended
    // work that nothing reads otherwise (the debug view reads APEX_TRUNCATED from the header).
    atomicAdd(&stats[0], 1u);
    atomicAdd(&stats[2], steps);
    if truncated {
        atomicAdd(&stats[1], 1u);
    }
#endif
    if truncated {
        header |= APEX_TRUNCATED;
    }
    apex_sets[base] = header;
}
