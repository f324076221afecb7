// Lighting pass for mesostructure pixels: Bevy's deferred lighting (same G-buffer decoding,
// BRDF, shadow maps, clustered lights, environment light) with paper eq. (2)'s terms:
// the mesostructure ambient occlusion on ambient and environment light only (diffuse and
// specular occlusion, never direct light), multiplied with Bevy's SSAO when the camera has
// it, weighted by λa; each directional, point and spot light's direct light weighted by λs
// and its micro-shadow visibility, inside Bevy's one light loop. Draws a fullscreen
// triangle at the depth of our deferred lighting pass id, so only pixels of mesostructure
// materials are touched; or, in its compute form, runs on the pixels of that id. Writes each
// pixel's micro-shadow visibility for the debug view.

#import bevy_pbr::{
    prepass_utils,
    pbr_types::STANDARD_MATERIAL_FLAGS_UNLIT_BIT,
    pbr_functions,
    pbr_deferred_functions::pbr_input_from_deferred_gbuffer,
    lighting,
    mesh_view_bindings::{deferred_prepass_texture, lights, clustered_lights, view},
    shadows,
    ssao_utils::ssao_multibounce,
}
#import bevy_mesostructure::common::MesostructureUniform
#import bevy_mesostructure::surface
#import bevy_mesostructure::surface::{SECTORS, sector_position, wrap_sector, sector_sine}

#ifdef SCREEN_SPACE_AMBIENT_OCCLUSION
#import bevy_pbr::mesh_view_bindings::screen_space_ambient_occlusion_texture
#endif

@group(2) @binding(0) var mesostructure_occlusion: texture_2d<f32>;
@group(2) @binding(1) var mhm: texture_2d<f32>;
@group(2) @binding(2) var core_normal: texture_2d<f32>;
// The occlusion pass's sector record of each pixel (`surface.wgsl`).
@group(2) @binding(3) var sector_horizons: texture_2d<u32>;
@group(2) @binding(4) var<uniform> settings: MesostructureUniform;
@group(2) @binding(5) var bump_normal: texture_2d<f32>;
// (micro-shadow visibility for the debug view, the first directional light's shadow-map
// visibility for the bleeding pass's texture-space bounce of that light).
@group(2) @binding(6) var micro_shadow_out: texture_storage_2d<rg32float, write>;
// The height pass's texture-space visibility of the first directional light (−1: none).
@group(2) @binding(7) var texture_visibility: texture_2d<f32>;

// What the micro-shadow test needs of a pixel, whatever the light: its surface point, and the
// normal N' with the horizon of each azimuth sector, as the occlusion pass stored them.
struct Horizons {
    valid: bool,
    sp: vec3<f32>,
    n: vec3<f32>,
    record: vec4<u32>,
}

fn horizons(p: vec2<i32>) -> Horizons {
    var h: Horizons;
    h.valid = textureLoad(mhm, p, 0).z != 0.0;
    if !h.valid {
        return h;
    }
    h.sp = surface::surface_point(mhm, core_normal, view.world_from_clip, view.viewport, p);
    // Clamped: frames whose occlusion pass has not run bind a 1×1 record with every sector
    // open (no micro-shadow).
    let record_size = vec2<i32>(textureDimensions(sector_horizons));
    h.record = textureLoad(sector_horizons, min(p, record_size - 1), 0);
    h.n = surface::sector_normal(h.record);
    return h;
}

// Micro-shadow of the light coming from `to_light` (paper §3.2): the light's azimuth placed
// between the two nearest profiles [beyond: interpolated], and P in shadow where the light is
// lower above the tangent plane than that horizon; soft over `micro_shadow_softness` (in sine).
fn micro_shadow(h: Horizons, to_light: vec3<f32>) -> f32 {
    if !h.valid {
        return 1.0;
    }
    let sin_l = dot(to_light, h.n);
    if sin_l <= 0.0 {
        return 1.0;
    }
    // The light's azimuth on screen: project a step along its tangential direction.
    let tangential = to_light - h.n * sin_l;
    let c0 = view.clip_from_world * vec4(h.sp, 1.0);
    let c1 = view.clip_from_world * vec4(h.sp + tangential * 0.01, 1.0);
    let s = (c1.xy / c1.w - c0.xy / c0.w) * vec2(1.0, -1.0);
    if all(s == vec2(0.0)) {
        return 1.0;
    }
    let a = sector_position(s);
    let lower = floor(a);
    let i0 = wrap_sector(i32(lower));
    let horizon = mix(sector_sine(h.record, i0), sector_sine(h.record, (i0 + 1u) % SECTORS), a - lower);
    // The soft edge is never wider than the horizon itself: an open profile (horizon 0)
    // leaves every light above the tangent plane unshadowed.
    let w = min(settings.micro_shadow_softness, horizon);
    if w <= 0.0 {
        return select(0.0, 1.0, sin_l >= horizon);
    }
    return smoothstep(-w, w, sin_l - horizon);
}

// Eq. (2) inside Bevy's own light loop: `apply_pbr_lighting` evaluates each light once, and
// the overrides below (naga_oil `override fn`, this shader only) weight each light's direct
// light by λs and its micro-shadow visibility V. The shadow lookups only note the shadow map's
// value of the light being evaluated (Bevy fetches it just before the light's BRDF), for the
// lowest visibility the debug view shows and the first directional light's shadow the bleeding
// pass needs. State of the pixel being lit, set before `apply_pbr_lighting`:
var<private> pixel_horizons: Horizons;
// The surface point the light directions are taken from (P, or the core point's surface point).
var<private> light_origin: vec3<f32>;
// The height pass's texture-space visibility of the first directional light (−1: none).
var<private> texture_visible: f32;
// The shadow map's value for the light Bevy evaluates next (1 where it has none).
var<private> pending_shadow: f32 = 1.0;
// Lowest micro-shadow visibility over the lights that reach P (the debug view's V).
var<private> lowest_visibility: f32 = 1.0;
// The first directional light's shadow-map visibility at P (1 where it casts no shadow, P
// receives none, or there is no such light): the bleeding pass's bounce of that light reaches
// P only where the light does, and must not count the light twice in the gathered colours.
var<private> sun_shadow: f32 = 1.0;

// λs·V of one light, V from the light's direction; notes V for the debug view.
fn direct_weight(to_light: vec3<f32>, texture_space_visibility: f32) -> f32 {
    var visible = 1.0;
    if settings.micro_shadows != 0u {
        visible = micro_shadow(pixel_horizons, to_light);
        if texture_space_visibility >= 0.0 {
            visible = texture_space_visibility;
        }
    }
    if pending_shadow > 0.0 {
        lowest_visibility = min(lowest_visibility, visible);
    }
    pending_shadow = 1.0;
    return settings.weights.y * visible;
}

// Point lights, and spot lights (Bevy's `spot_light` is `point_light` times the cone).
override fn lighting::point_light(
    light_id: u32,
    input: ptr<function, lighting::LightingInput>,
    enable_diffuse: bool,
    enable_texture: bool,
) -> vec3<f32> {
    let to_light = normalize(clustered_lights.data[light_id].position_radius.xyz - light_origin);
    let weight = direct_weight(to_light, -1.0);
    return lighting::point_light(light_id, input, enable_diffuse, enable_texture) * weight;
}

override fn lighting::directional_light(
    light_id: u32,
    input: ptr<function, lighting::LightingInput>,
    enable_diffuse: bool,
) -> vec3<f32> {
    if light_id == 0u {
        sun_shadow = pending_shadow;
    }
    var texture_space_visibility = -1.0;
    if light_id == 0u && settings.texture_space_horizons != 0u {
        texture_space_visibility = texture_visible;
    }
    let weight = direct_weight(lights.directional_lights[light_id].direction_to_light, texture_space_visibility);
    return lighting::directional_light(light_id, input, enable_diffuse) * weight;
}

override fn shadows::fetch_point_shadow(
    light_id: u32,
    frag_position: vec4<f32>,
    surface_normal: vec3<f32>,
    frag_coord_xy: vec2<f32>,
) -> f32 {
    pending_shadow = shadows::fetch_point_shadow(light_id, frag_position, surface_normal, frag_coord_xy);
    return pending_shadow;
}

override fn shadows::fetch_spot_shadow(
    light_id: u32,
    frag_position: vec4<f32>,
    surface_normal: vec3<f32>,
    near_z: f32,
    frag_coord_xy: vec2<f32>,
) -> f32 {
    pending_shadow = shadows::fetch_spot_shadow(light_id, frag_position, surface_normal, near_z, frag_coord_xy);
    return pending_shadow;
}

override fn shadows::fetch_directional_shadow(
    light_id: u32,
    frag_position: vec4<f32>,
    surface_normal: vec3<f32>,
    view_z: f32,
    frag_coord_xy: vec2<f32>,
) -> f32 {
    pending_shadow = shadows::fetch_directional_shadow(light_id, frag_position, surface_normal, view_z, frag_coord_xy);
    return pending_shadow;
}

// Lights one pixel of a mesostructure material at `position` (the pixel's centre, as
// `@builtin(position)` gives it), and records its micro-shadow visibility; both entries below.
fn light_pixel(position: vec2<f32>) -> vec4<f32> {
    var frag_coord = vec4(position, 0.0, 0.0);
    let pixel = vec2<i32>(frag_coord.xy);
    let deferred_data = textureLoad(deferred_prepass_texture, pixel, 0);
#ifdef DEPTH_PREPASS
    frag_coord.z = prepass_utils::prepass_depth(frag_coord, 0u);
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
        // λa of eq. (2) scales ambient and environment light, which is all these two
        // factors reach.
        let ambient_weight = settings.weights.x;
        pbr_input.diffuse_occlusion = min(pbr_input.diffuse_occlusion, multibounce) * ambient_weight;
        let NdotV = max(dot(pbr_input.N, pbr_input.V), 0.0001);
        let roughness = lighting::perceptualRoughnessToRoughness(pbr_input.material.perceptual_roughness);
        pbr_input.specular_occlusion = min(
            pbr_input.specular_occlusion,
            saturate(pow(NdotV + ambient_visibility, exp2(-16.0 * roughness - 1.0)) - 1.0 + ambient_visibility),
        ) * ambient_weight;
        // Eq. (2): (λa La + λs Ls) V — λs and the micro-shadows (V) on each light's direct
        // light, by the overrides above. The horizons do not depend on the light: found once.
        if settings.micro_shadows != 0u {
            pixel_horizons = horizons(pixel);
        }
        light_origin = select(pbr_input.world_position.xyz, pixel_horizons.sp, pixel_horizons.valid);
        let visibility_size = vec2<i32>(textureDimensions(texture_visibility));
        texture_visible = textureLoad(texture_visibility, min(pixel, visibility_size - 1), 0).r;
        output_color = pbr_functions::apply_pbr_lighting(pbr_input);
        textureStore(micro_shadow_out, pixel, vec4(lowest_visibility, sun_shadow, 0.0, 0.0));
    } else {
        textureStore(micro_shadow_out, pixel, vec4(1.0));
        output_color = pbr_input.material.base_color;
    }
    return pbr_functions::main_pass_post_lighting_processing(pbr_input, output_color);
}

#ifdef COMPUTE_LIGHTING
// The compute form (where the view's main image takes storage writes): runs after Bevy's
// deferred lighting, which leaves the pixels of this pass's id untouched, and writes exactly
// those — the same pixels the raster form's id-depth test selects.
@group(2) @binding(8) var lit_out: texture_storage_2d<rgba16float, write>;
// Each pixel's deferred lighting pass id (Bevy's prepass).
@group(2) @binding(9) var lighting_pass_ids: texture_2d<u32>;

@compute @workgroup_size(8, 8, 1)
fn light_compute(@builtin(global_invocation_id) id: vec3<u32>) {
    if any(id.xy >= textureDimensions(lighting_pass_ids)) {
        return;
    }
    let pixel = vec2<i32>(id.xy);
    if textureLoad(lighting_pass_ids, pixel, 0).r != #{MESOSTRUCTURE_LIGHTING_PASS_ID}u {
        return;
    }
    textureStore(lit_out, pixel, light_pixel(vec2<f32>(id.xy) + 0.5));
}
#else
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

// Early depth testing forced: the id-depth test (only this pass's pixels) must reject the
// foreign pixels before the shader runs, which the storage write in `light_pixel` would
// otherwise prevent (the shader writes no depth, so the early test decides exactly as the late
// one would). `micro_shadow_out` is therefore written on mesostructure pixels only.
#ifdef EARLY_DEPTH_TEST
@early_depth_test(force)
#endif
@fragment
fn fragment(in: FullscreenVertexOutput) -> @location(0) vec4<f32> {
    return light_pixel(in.position.xy);
}
#endif
