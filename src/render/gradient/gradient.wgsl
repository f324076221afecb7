// Gradient pass (paper §2.1): the MHGM. Per valid pixel the 8-neighbour connectivity (same
// object, on screen, no depth discontinuity), boundary flags, and the height gradient by central
// differences, one-sided where a neighbour is cut off, stored as the neighbour it points at
// (`common.wgsl`'s MHGM texel). Mirrors `reference::gradient_map`.

#import bevy_mesostructure::common::{
    MesostructureUniform, FLAG_VALID, FLAG_SCREEN_EDGE, FLAG_OBJECT_EDGE, FLAG_DEPTH_EDGE,
    CONNECTIVITY_SHIFT, ASCENT_SHIFT, NO_ASCENT, neighbour_offset, neighbour_index, on_screen,
    is_connected,
}

@group(0) @binding(0) var mhm: texture_2d<f32>;
@group(0) @binding(1) var mhgm: texture_storage_2d<rg32uint, write>;
@group(0) @binding(2) var<uniform> settings: MesostructureUniform;

// Index of the 8-neighbour nearest the gradient direction (22.5° sectors); NO_ASCENT for g = 0.
fn quantize_direction(g: vec2<f32>) -> u32 {
    let TAN_22_5 = 0.41421357;
    let a = abs(g);
    if a.x == 0.0 && a.y == 0.0 {
        return NO_ASCENT;
    }
    let s = vec2<i32>(
        select(0, i32(sign(g.x)), a.x > TAN_22_5 * a.y),
        select(0, i32(sign(g.y)), a.y > TAN_22_5 * a.x),
    );
    return neighbour_index(s);
}

fn axis_gradient(flags: u32, plus: u32, minus: u32, h0: f32, h_plus: f32, h_minus: f32) -> f32 {
    let cp = is_connected(flags, plus);
    let cm = is_connected(flags, minus);
    if cp && cm {
        return (h_plus - h_minus) * 0.5;
    } else if cp {
        return h_plus - h0;
    } else if cm {
        return h0 - h_minus;
    }
    return 0.0;
}

@compute @workgroup_size(8, 8, 1)
fn gradient(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = vec2<i32>(textureDimensions(mhm));
    let p = vec2<i32>(id.xy);
    if !on_screen(p, size) {
        return;
    }
    let c = textureLoad(mhm, p, 0);
    let object = c.z;
    if object == 0.0 {
        textureStore(mhgm, p, vec4<u32>(0u, NO_ASCENT << ASCENT_SHIFT, 0u, 0u));
        return;
    }
    let d0 = c.y;
    var flags = FLAG_VALID;
    var heights: array<f32, 8>;
    for (var dir = 0u; dir < 8u; dir++) {
        let o = neighbour_offset(dir);
        let q = p + o;
        heights[dir] = 0.0;
        if !on_screen(q, size) {
            flags |= FLAG_SCREEN_EDGE;
            continue;
        }
        let nq = textureLoad(mhm, q, 0);
        if nq.z != object {
            flags |= FLAG_OBJECT_EDGE;
            continue;
        }
        var tolerance = settings.depth_relative * d0;
        let r = p - o;
        if on_screen(r, size) {
            let nr = textureLoad(mhm, r, 0);
            if nr.z == object {
                tolerance = max(tolerance, settings.depth_slope_factor * abs(d0 - nr.y));
            }
        }
        if abs(nq.y - d0) > tolerance {
            flags |= FLAG_DEPTH_EDGE;
            continue;
        }
        flags |= 1u << (CONNECTIVITY_SHIFT + dir);
        heights[dir] = nq.x;
    }
    let h0 = c.x;
    let gx = axis_gradient(flags, 0u, 4u, h0, heights[0], heights[4]);
    let gy = axis_gradient(flags, 2u, 6u, h0, heights[2], heights[6]);
    // (h, flags | ascent direction): one 8-byte texel read gives the apex search all it needs.
    let ascent = quantize_direction(vec2(gx, gy)) << ASCENT_SHIFT;
    textureStore(mhgm, p, vec4<u32>(bitcast<u32>(h0), flags | ascent, 0u, 0u));
}
