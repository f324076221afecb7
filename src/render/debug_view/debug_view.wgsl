// Debug views of the intermediate images, drawn over the camera's output after tonemapping so
// that a screenshot shows them. Pixels without a mesostructure surface keep the scene.

#import bevy_core_pipeline::fullscreen_vertex_shader::FullscreenVertexOutput
#import bevy_mesostructure::common::{
    MesostructureUniform, FLAG_VALID, FLAG_SCREEN_EDGE, FLAG_OBJECT_EDGE, FLAG_DEPTH_EDGE,
    FLAG_BOUNDARY, APEX_COUNT_MASK, APEX_DIRECT_PRESENT, APEX_TRUNCATED, unpack_offset, apex_base,
    apex_set_of, mhgm_flags, mhgm_ascent, neighbour_offset, NO_ASCENT,
}

@group(0) @binding(0) var mhm: texture_2d<f32>;
@group(0) @binding(1) var mhgm: texture_2d<u32>;
@group(0) @binding(2) var<storage, read> apex_sets: array<u32>;
@group(0) @binding(3) var<uniform> settings: MesostructureUniform;
@group(0) @binding(4) var occlusion: texture_2d<f32>;
@group(0) @binding(5) var micro_shadow: texture_2d<f32>;
@group(0) @binding(6) var bleeding: texture_2d<f32>;

const VIEW_HEIGHT: u32 = 1u;
const VIEW_GRADIENT: u32 = 2u;
const VIEW_APEX_DISTANCE: u32 = 3u;
const VIEW_APEX_COUNT: u32 = 4u;
const VIEW_BOUNDARY: u32 = 5u;
const VIEW_OCCLUSION: u32 = 6u;
const VIEW_MICRO_SHADOW: u32 = 7u;
const VIEW_BLEEDING: u32 = 8u;

// Dark blue → teal → yellow.
fn ramp(t: f32) -> vec3<f32> {
    let x = clamp(t, 0.0, 1.0);
    return mix(mix(vec3(0.05, 0.05, 0.35), vec3(0.1, 0.6, 0.55), min(x * 2.0, 1.0)),
               vec3(1.0, 0.9, 0.1), max(x * 2.0 - 1.0, 0.0));
}

@fragment
fn fragment(in: FullscreenVertexOutput) -> @location(0) vec4<f32> {
    let p = vec2<i32>(floor(in.position.xy));
    let size = vec2<i32>(textureDimensions(mhgm));
    if any(p >= size) {
        discard;
    }
    let g = textureLoad(mhgm, p, 0);
    let flags = mhgm_flags(g);
    if (flags & FLAG_VALID) == 0u {
        discard;
    }
    let base = apex_base(settings, p, size);
    let header = apex_sets[base];
    let apexes = apex_set_of(mhm, settings, p, header, base);
    var color = vec3<f32>(0.0);
    switch settings.debug_view {
        case VIEW_HEIGHT: {
            color = vec3(textureLoad(mhm, p, 0).w);
        }
        case VIEW_GRADIENT: {
            // The gradient's direction as the MHGM keeps it (the ascent's next neighbour).
            let ascent = mhgm_ascent(g);
            let d = normalize(vec2<f32>(neighbour_offset(ascent)));
            color = select(vec3(0.5 + 0.5 * d, 0.25), vec3(0.5), ascent >= NO_ASCENT);
        }
        case VIEW_APEX_DISTANCE: {
            if (header & APEX_DIRECT_PRESENT) != 0u && apexes.count > 0u {
                let d = length(vec2<f32>(unpack_offset(apex_sets[apexes.first]) + apexes.shift));
                color = ramp(d / 32.0);
            }
        }
        case VIEW_APEX_COUNT: {
            let count = apexes.count;
            if (header & APEX_TRUNCATED) != 0u {
                color = vec3(1.0, 0.0, 1.0);
            } else if count > 0u {
                color = vec3(0.15 + 0.85 * f32(count) / f32(settings.apex_directions + 1u));
            }
        }
        case VIEW_BOUNDARY: {
            color = vec3(0.15);
            if (flags & FLAG_BOUNDARY) != 0u {
                color = vec3(
                    select(0.0, 1.0, (flags & FLAG_OBJECT_EDGE) != 0u),
                    select(0.0, 1.0, (flags & FLAG_DEPTH_EDGE) != 0u),
                    select(0.0, 1.0, (flags & FLAG_SCREEN_EDGE) != 0u),
                );
            }
        }
        case VIEW_OCCLUSION: {
            color = vec3(select(0.0, textureLoad(occlusion, p, 0).r, settings.occlusion_enabled != 0u));
        }
        case VIEW_MICRO_SHADOW: {
            color = vec3(select(1.0, textureLoad(micro_shadow, p, 0).r, settings.micro_shadows != 0u));
        }
        case VIEW_BLEEDING: {
            color = select(vec3(0.0), 4.0 * textureLoad(bleeding, p, 0).rgb, settings.bleeding_enabled != 0u);
        }
        default: {
            discard;
        }
    }
    return vec4<f32>(color, 1.0);
}
