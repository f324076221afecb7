// Lighting pass for mesostructure pixels: Bevy's deferred lighting (same G-buffer decoding,
// BRDF, shadow maps, clustered lights, environment light) with the mesostructure ambient
// occlusion applied to ambient and environment light only — diffuse and specular occlusion,
// never direct light (paper eq. 2: La is the ambient term). Combined multiplicatively with
// Bevy's SSAO when the camera has it. Draws a fullscreen triangle at the depth of our
// deferred lighting pass id, so only pixels of mesostructure materials are touched.

#import bevy_pbr::{
    prepass_utils,
    pbr_types::{PbrInput, STANDARD_MATERIAL_FLAGS_UNLIT_BIT},
    pbr_functions,
    pbr_deferred_functions::pbr_input_from_deferred_gbuffer,
    lighting,
    mesh_view_bindings::{deferred_prepass_texture, lights, view},
    mesh_view_types::DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT,
    mesh_types::MESH_FLAGS_SHADOW_RECEIVER_BIT,
    shadows,
    ssao_utils::ssao_multibounce,
}
#import bevy_mesostructure::common::{
    MesostructureUniform, APEX_COUNT_MASK, unpack_offset, is_connected,
}

#ifdef SCREEN_SPACE_AMBIENT_OCCLUSION
#import bevy_pbr::mesh_view_bindings::screen_space_ambient_occlusion_texture
#endif

@group(2) @binding(0) var mesostructure_occlusion: texture_2d<f32>;
@group(2) @binding(1) var mhm: texture_2d<f32>;
@group(2) @binding(2) var core_normal: texture_2d<f32>;
@group(2) @binding(3) var mhgm: texture_2d<f32>;
@group(2) @binding(4) var<storage, read> apex_sets: array<u32>;
@group(2) @binding(5) var<uniform> settings: MesostructureUniform;
@group(2) @binding(6) var bump_normal: texture_2d<f32>;

const SECTORS: u32 = 8u;
const TAU: f32 = 6.283185307;

fn surface_point(p: vec2<i32>) -> vec3<f32> {
    let m = textureLoad(mhm, p, 0);
    let uv = (vec2<f32>(p) + 0.5 - view.viewport.xy) / view.viewport.zw;
    let world = view.world_from_clip * vec4<f32>(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, m.y, 1.0);
    return world.xyz / world.w + textureLoad(core_normal, p, 0).xyz * m.x;
}

fn surface_derivative(p: vec2<i32>, sp: vec3<f32>, flags: u32, plus: u32, minus: u32, o: vec2<i32>) -> vec4<f32> {
    let cp = is_connected(flags, plus);
    let cm = is_connected(flags, minus);
    if cp && cm {
        return vec4((surface_point(p + o) - surface_point(p - o)) * 0.5, 1.0);
    } else if cp {
        return vec4(surface_point(p + o) - sp, 1.0);
    } else if cm {
        return vec4(sp - surface_point(p - o), 1.0);
    }
    return vec4(0.0);
}

// N' of the mesostructure surface (as in occlusion.wgsl).
fn mesostructure_normal(p: vec2<i32>, sp: vec3<f32>, n0: vec3<f32>) -> vec3<f32> {
    let flags = u32(textureLoad(mhgm, p, 0).w);
    let dx = surface_derivative(p, sp, flags, 0u, 4u, vec2(1, 0));
    let dy = surface_derivative(p, sp, flags, 2u, 6u, vec2(0, 1));
    if dx.w == 0.0 || dy.w == 0.0 {
        return n0;
    }
    let n = cross(dx.xyz, dy.xyz);
    let len = length(n);
    if !(len > 0.0) {
        return n0;
    }
    return select(n / len, -n / len, dot(n, n0) < 0.0);
}

fn screen_angle(o: vec2<f32>) -> f32 {
    return atan2(o.y, o.x) / TAU * f32(SECTORS);
}

// Micro-shadow of the light coming from `to_light` (paper §3.2): the horizons of the apex set
// per azimuth sector (the profiles through P and each apex), the light's azimuth placed between
// the two nearest profiles [beyond: interpolated], and P in shadow where the light is lower
// above the tangent plane than that horizon; soft over `micro_shadow_softness` (in sine).
fn micro_shadow(p: vec2<i32>, to_light: vec3<f32>) -> f32 {
    if textureLoad(mhm, p, 0).z == 0.0 {
        return 1.0;
    }
    let size = vec2<i32>(textureDimensions(mhm));
    let base = (u32(p.y) * u32(size.x) + u32(p.x)) * settings.apex_stride;
    let count = apex_sets[base] & APEX_COUNT_MASK;
    let sp = surface_point(p);
    let n = mesostructure_normal(p, sp, textureLoad(core_normal, p, 0).xyz);
    let sin_l = dot(to_light, n);
    if sin_l <= 0.0 {
        return 1.0;
    }
    var sin_h = array<f32, 8>(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for (var i = 0u; i < count; i++) {
        let o = unpack_offset(apex_sets[base + 1u + i]);
        let d = surface_point(p + o) - sp;
        let len = length(d);
        if len <= 0.0 {
            continue;
        }
        let a = screen_angle(vec2<f32>(o));
        let sector = u32(((i32(floor(a + 0.5)) % 8) + 8) % 8);
        sin_h[sector] = max(sin_h[sector], clamp(dot(d, n) / len, 0.0, 1.0));
    }
    // The light's azimuth on screen: project a step along its tangential direction.
    let tangential = to_light - n * sin_l;
    let c0 = view.clip_from_world * vec4(sp, 1.0);
    let c1 = view.clip_from_world * vec4(sp + tangential * 0.01, 1.0);
    let s = (c1.xy / c1.w - c0.xy / c0.w) * vec2(1.0, -1.0);
    if all(s == vec2(0.0)) {
        return 1.0;
    }
    let a = screen_angle(s);
    let lower = floor(a);
    let f = a - lower;
    let i0 = u32(((i32(lower) % 8) + 8) % 8);
    let horizon = mix(sin_h[i0], sin_h[(i0 + 1u) % 8u], f);
    let w = settings.micro_shadow_softness;
    if w <= 0.0 {
        return select(0.0, 1.0, sin_l >= horizon);
    }
    return smoothstep(-w, w, sin_l - horizon);
}

// The part of the directional lights' direct light that the micro-shadows take away, with
// Bevy's own BRDF and shadow maps (so that the rest of Bevy's light loop stays untouched).
fn micro_shadowed_light(in: PbrInput, p: vec2<i32>) -> vec3<f32> {
    var input: lighting::LightingInput;
    let roughness = lighting::perceptualRoughnessToRoughness(in.material.perceptual_roughness);
    input.layers[lighting::LAYER_BASE].NdotV = max(dot(in.N, in.V), 0.0001);
    input.layers[lighting::LAYER_BASE].N = in.N;
    input.layers[lighting::LAYER_BASE].R = reflect(-in.V, in.N);
    input.layers[lighting::LAYER_BASE].perceptual_roughness = in.material.perceptual_roughness;
    input.layers[lighting::LAYER_BASE].roughness = roughness;
    input.P = in.world_position.xyz;
    input.V = in.V;
    input.diffuse_color = pbr_functions::calculate_diffuse_color(
        in.material.base_color.rgb, in.material.metallic,
        in.material.specular_transmission, in.material.diffuse_transmission);
    input.metallic = in.material.metallic;
    input.F0_dielectric = pbr_functions::calculate_F0_dielectric(in.material.reflectance);
    input.F0_metallic = in.material.base_color.rgb;
    input.F_ab = lighting::F_AB(in.material.perceptual_roughness, input.layers[lighting::LAYER_BASE].NdotV);
    let view_z = dot(vec4<f32>(
        view.view_from_world[0].z, view.view_from_world[1].z,
        view.view_from_world[2].z, view.view_from_world[3].z), in.world_position);
    var removed = vec3(0.0);
    for (var i = 0u; i < lights.n_directional_lights; i++) {
        let to_light = lights.directional_lights[i].direction_to_light;
        let visible = micro_shadow(p, to_light);
        if visible >= 1.0 {
            continue;
        }
        var shadow = 1.0;
        if (in.flags & MESH_FLAGS_SHADOW_RECEIVER_BIT) != 0u
                && (lights.directional_lights[i].flags & DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT) != 0u {
            shadow = shadows::fetch_directional_shadow(i, in.world_position, in.world_normal, view_z, in.frag_coord.xy);
        }
        removed += (1.0 - visible) * shadow * lighting::directional_light(i, &input, true);
    }
    return removed * view.exposure;
}

struct FullscreenVertexOutput {
    @builtin(position) position: vec4<f32>,
    @location(0) uv: vec2<f32>,
};

@vertex
fn vertex(@builtin(vertex_index) vertex_index: u32) -> FullscreenVertexOutput {
    let uv = vec2<f32>(f32(vertex_index >> 1u), f32(vertex_index & 1u)) * 2.0;
    // The id-depth texture stores the lighting pass id as unorm depth id / 255.
    let clip_position = vec4<f32>(
        uv * vec2<f32>(2.0, -2.0) + vec2<f32>(-1.0, 1.0),
        f32(#{MESOSTRUCTURE_LIGHTING_PASS_ID}u) / 255.0,
        1.0
    );
    return FullscreenVertexOutput(clip_position, uv);
}

@fragment
fn fragment(in: FullscreenVertexOutput) -> @location(0) vec4<f32> {
    var frag_coord = vec4(in.position.xy, 0.0, 0.0);
    let pixel = vec2<i32>(frag_coord.xy);
    let deferred_data = textureLoad(deferred_prepass_texture, pixel, 0);
#ifdef DEPTH_PREPASS
    frag_coord.z = prepass_utils::prepass_depth(in.position, 0u);
#endif
    var pbr_input = pbr_input_from_deferred_gbuffer(frag_coord, deferred_data);
    var output_color = vec4(0.0);
    // The shading normal of the mesostructure surface (Blinn bump mapping in the height pass),
    // where the material has no normal map of its own.
    let bump_size = vec2<i32>(textureDimensions(bump_normal));
    let bumped = textureLoad(bump_normal, min(pixel, bump_size - 1), 0).xyz;
    if settings.bump_mapping != 0u && dot(bumped, bumped) > 0.5 {
        pbr_input.N = normalize(bumped);
    }

    if ((pbr_input.material.flags & STANDARD_MATERIAL_FLAGS_UNLIT_BIT) == 0u) {
        // Clamped: frames without an occlusion pass bind a 1×1 "open" image.
        let occlusion_size = vec2<i32>(textureDimensions(mesostructure_occlusion));
        var ambient_visibility = textureLoad(mesostructure_occlusion, min(pixel, occlusion_size - 1), 0).r;
#ifdef SCREEN_SPACE_AMBIENT_OCCLUSION
        ambient_visibility *= textureLoad(screen_space_ambient_occlusion_texture, pixel, 0).r;
#endif
        // As Bevy does for SSAO: multi-bounce diffuse occlusion, and specular occlusion from
        // it (Lagarde and Rousiers 2014).
        let multibounce = ssao_multibounce(ambient_visibility, pbr_input.material.base_color.rgb);
        pbr_input.diffuse_occlusion = min(pbr_input.diffuse_occlusion, multibounce);
        let NdotV = max(dot(pbr_input.N, pbr_input.V), 0.0001);
        let roughness = lighting::perceptualRoughnessToRoughness(pbr_input.material.perceptual_roughness);
        pbr_input.specular_occlusion = min(
            pbr_input.specular_occlusion,
            saturate(pow(NdotV + ambient_visibility, exp2(-16.0 * roughness - 1.0)) - 1.0 + ambient_visibility),
        );
        output_color = pbr_functions::apply_pbr_lighting(pbr_input);
        if settings.micro_shadows != 0u {
            output_color = vec4(max(output_color.rgb - micro_shadowed_light(pbr_input, pixel), vec3(0.0)), output_color.a);
        }
    } else {
        output_color = pbr_input.material.base_color;
    }
    return pbr_functions::main_pass_post_lighting_processing(pbr_input, output_color);
}
