// Lighting pass for mesostructure pixels: Bevy's deferred lighting (same G-buffer decoding,
// BRDF, shadow maps, clustered lights, environment light) with paper eq. (2)'s terms:
// the mesostructure ambient occlusion on ambient and environment light only (diffuse and
// specular occlusion, never direct light), multiplied with Bevy's SSAO when the camera has
// it, weighted by λa; the micro-shadows of every directional, point and spot light, taken
// off that light's own contribution; direct light weighted by λs. Draws a fullscreen
// triangle at the depth of our deferred lighting pass id, so only pixels of mesostructure
// materials are touched. Writes each pixel's micro-shadow visibility for the debug view.

#import bevy_pbr::{
    prepass_utils,
    pbr_types::{PbrInput, STANDARD_MATERIAL_FLAGS_UNLIT_BIT},
    pbr_functions,
    clustered_forward as clustering,
    pbr_deferred_functions::pbr_input_from_deferred_gbuffer,
    lighting,
    mesh_view_bindings::{deferred_prepass_texture, lights, clustered_lights, view},
    mesh_view_types::{DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT, POINT_LIGHT_FLAGS_SHADOWS_ENABLED_BIT},
    mesh_types::MESH_FLAGS_SHADOW_RECEIVER_BIT,
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

// Bevy's lighting input for one pixel, as `apply_pbr_lighting` builds it (base layer).
fn lighting_input(in: PbrInput) -> lighting::LightingInput {
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
    return input;
}

// The direct light of a pixel as eq. (2) splits it: `all`, Bevy's direct light of every light
// (BRDF × shadow map), only summed when λs ≠ 1; `shadowed`, the part of it the micro-shadows
// take away; `visibility`, the lowest micro-shadow visibility over the lights that reach P.
struct DirectTerms {
    all: vec3<f32>,
    shadowed: vec3<f32>,
    visibility: f32,
    // The first directional light's shadow-map visibility at P (1 where it casts no shadow, P
    // receives none, or there is no such light), fetched where the texture-space bounce needs
    // it: the bleeding pass's bounce of that light reaches P only where the light does, and
    // must not count the light twice in the gathered colours.
    sun_shadow: f32,
}

fn add_light(terms: ptr<function, DirectTerms>, contribution: vec3<f32>, shadow: f32, visible: f32) {
    (*terms).all += contribution * shadow;
    (*terms).shadowed += (1.0 - visible) * shadow * contribution;
    if shadow > 0.0 {
        (*terms).visibility = min((*terms).visibility, visible);
    }
}

// The same lights, shadow maps and BRDF as Bevy's light loop (`apply_pbr_lighting`), evaluated
// again only for the lights a micro-shadow dims (or all of them when λs ≠ 1), so that the rest
// of Bevy's loop stays untouched.
fn direct_terms(in: PbrInput, p: vec2<i32>) -> DirectTerms {
    var terms: DirectTerms;
    terms.visibility = 1.0;
    terms.sun_shadow = 1.0;
    let micro = settings.micro_shadows != 0u;
    let every_light = settings.weights.y != 1.0;
    let sun_shadow = settings.texture_space_bounce != 0u;
    if !micro && !every_light && !sun_shadow {
        return terms;
    }
    var input = lighting_input(in);
    let receiver = (in.flags & MESH_FLAGS_SHADOW_RECEIVER_BIT) != 0u;
    let view_z = dot(vec4<f32>(
        view.view_from_world[0].z, view.view_from_world[1].z,
        view.view_from_world[2].z, view.view_from_world[3].z), in.world_position);
    // The horizons do not depend on the light: found once, tested against each light.
    var h: Horizons;
    if micro {
        h = horizons(p);
    }
    let sp = select(in.world_position.xyz, h.sp, h.valid);

    let cluster = clustering::view_fragment_cluster_index(in.frag_coord.xy, view_z, in.is_orthographic);
    let ranges = clustering::unpack_clusterable_object_index_ranges(cluster);
    for (var i = ranges.first_point_light_index_offset; i < ranges.first_spot_light_index_offset; i++) {
        let id = clustering::get_clusterable_object_id(i);
        let light = &clustered_lights.data[id];
        let visible = micro_shadow(h, normalize((*light).position_radius.xyz - sp));
        if visible >= 1.0 && !every_light {
            continue;
        }
        var shadow = 1.0;
        if receiver && ((*light).flags & POINT_LIGHT_FLAGS_SHADOWS_ENABLED_BIT) != 0u {
            shadow = shadows::fetch_point_shadow(id, in.world_position, in.world_normal, in.frag_coord.xy);
        }
        add_light(&terms, lighting::point_light(id, &input, true, true), shadow, visible);
    }
    for (var i = ranges.first_spot_light_index_offset; i < ranges.first_reflection_probe_index_offset; i++) {
        let id = clustering::get_clusterable_object_id(i);
        let light = &clustered_lights.data[id];
        let visible = micro_shadow(h, normalize((*light).position_radius.xyz - sp));
        if visible >= 1.0 && !every_light {
            continue;
        }
        var shadow = 1.0;
        if receiver && ((*light).flags & POINT_LIGHT_FLAGS_SHADOWS_ENABLED_BIT) != 0u {
            shadow = shadows::fetch_spot_shadow(
                id, in.world_position, in.world_normal, (*light).shadow_map_near_z, in.frag_coord.xy);
        }
        add_light(&terms, lighting::spot_light(id, &input, true), shadow, visible);
    }
    // The height pass's texture-space visibility of the first directional light (−1: none).
    let visibility_size = vec2<i32>(textureDimensions(texture_visibility));
    let texture_visible = textureLoad(texture_visibility, min(p, visibility_size - 1), 0).r;
    for (var i = 0u; i < lights.n_directional_lights; i++) {
        var visible = micro_shadow(h, lights.directional_lights[i].direction_to_light);
        if micro && i == 0u && settings.texture_space_horizons != 0u && texture_visible >= 0.0 {
            visible = texture_visible;
        }
        let skip = visible >= 1.0 && !every_light;
        if skip && !(sun_shadow && i == 0u) {
            continue;
        }
        var shadow = 1.0;
        if receiver && (lights.directional_lights[i].flags & DIRECTIONAL_LIGHT_FLAGS_SHADOWS_ENABLED_BIT) != 0u {
            shadow = shadows::fetch_directional_shadow(i, in.world_position, in.world_normal, view_z, in.frag_coord.xy);
        }
        if i == 0u {
            terms.sun_shadow = shadow;
        }
        if skip {
            continue;
        }
        add_light(&terms, lighting::directional_light(i, &input, true), shadow, visible);
    }
    terms.all *= view.exposure;
    terms.shadowed *= view.exposure;
    return terms;
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

// Early depth testing forced: the id-depth test (only this pass's pixels) must reject the
// foreign pixels before the shader runs, which the storage write below would otherwise prevent
// (the shader writes no depth, so the early test decides exactly as the late one would).
// `micro_shadow_out` is therefore written on mesostructure pixels only.
#ifdef EARLY_DEPTH_TEST
@early_depth_test(force)
#endif
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
        output_color = pbr_functions::apply_pbr_lighting(pbr_input);
        // Eq. (2): (λa La + λs Ls) V — the micro-shadows (V) and λs on direct light.
        let direct = direct_terms(pbr_input, pixel);
        let direct_weight = settings.weights.y;
        output_color = vec4(
            max(output_color.rgb + (direct_weight - 1.0) * direct.all - direct_weight * direct.shadowed, vec3(0.0)),
            output_color.a,
        );
        textureStore(micro_shadow_out, pixel, vec4(direct.visibility, direct.sun_shadow, 0.0, 0.0));
    } else {
        textureStore(micro_shadow_out, pixel, vec4(1.0));
        output_color = pbr_input.material.base_color;
    }
    return pbr_functions::main_pass_post_lighting_processing(pbr_input, output_color);
}
