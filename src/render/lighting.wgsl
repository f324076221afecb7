// Lighting pass for mesostructure pixels: Bevy's deferred lighting (same G-buffer decoding,
// BRDF, shadow maps, clustered lights, environment light) with the mesostructure ambient
// occlusion applied to ambient and environment light only — diffuse and specular occlusion,
// never direct light (paper eq. 2: La is the ambient term). Combined multiplicatively with
// Bevy's SSAO when the camera has it. Draws a fullscreen triangle at the depth of our
// deferred lighting pass id, so only pixels of mesostructure materials are touched.

#import bevy_pbr::{
    prepass_utils,
    pbr_types::STANDARD_MATERIAL_FLAGS_UNLIT_BIT,
    pbr_functions,
    pbr_deferred_functions::pbr_input_from_deferred_gbuffer,
    lighting,
    mesh_view_bindings::deferred_prepass_texture,
    ssao_utils::ssao_multibounce,
}

#ifdef SCREEN_SPACE_AMBIENT_OCCLUSION
#import bevy_pbr::mesh_view_bindings::screen_space_ambient_occlusion_texture
#endif

@group(2) @binding(0) var mesostructure_occlusion: texture_2d<f32>;

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
    } else {
        output_color = pbr_input.material.base_color;
    }
    return pbr_functions::main_pass_post_lighting_processing(pbr_input, output_color);
}
