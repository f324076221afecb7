#define_import_path bevy_mesostructure::translucency::boundary

// What the translucency's shaders share about a medium's boundary: imported by the gather
// (a Bevy shader), appended to the raw wgpu shaders of the injection (`with_boundary` in
// translucency/mod.rs, this file's first line taken out).

// `fresnel_reflectance` (diffusion.rs): unpolarised, light arriving at cos_i onto index eta.
fn fresnel_reflectance(cos_i: f32, eta: f32) -> f32 {
    let sin_t2 = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin_t2 >= 1.0 {
        return 1.0;
    }
    let cos_t = sqrt(1.0 - sin_t2);
    let rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    return 0.5 * (rs * rs + rp * rp);
}
