// Seed 001's gather as a fullscreen fragment pass, added to the lit view by additive blending
// (times the view's exposure, as Bevy's lighting is): the fallback where the view's main
// images take no storage writes (`gather_compute.wgsl` otherwise). What it gathers:
// `gathered.wgsl`.

#import bevy_core_pipeline::fullscreen_vertex_shader::FullscreenVertexOutput
#import bevy_mesostructure::translucency::gathered::{gathered, pixel_surface}

@fragment
fn gather(in: FullscreenVertexOutput) -> @location(0) vec4<f32> {
    let added = gathered(pixel_surface(vec2<i32>(floor(in.position.xy)), in.position.xy));
    if added.w == 0.0 {
        discard;
    }
    return vec4(added.rgb, 0.0);
}
