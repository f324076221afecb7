// Adds the gathered bleeding to the view's lit colour (additive blending), on mesostructure
// pixels only.

#import bevy_core_pipeline::fullscreen_vertex_shader::FullscreenVertexOutput

@group(0) @binding(0) var bleeding: texture_2d<f32>;
@group(0) @binding(1) var mhm: texture_2d<f32>;

@fragment
fn composite(in: FullscreenVertexOutput) -> @location(0) vec4<f32> {
    let p = vec2<i32>(floor(in.position.xy));
    if any(p >= vec2<i32>(textureDimensions(mhm))) || textureLoad(mhm, p, 0).z == 0.0 {
        discard;
    }
    return vec4(textureLoad(bleeding, p, 0).rgb, 0.0);
}
