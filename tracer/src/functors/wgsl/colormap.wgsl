// Module `tracer_colormap`: `ColorMap::linear_at` of
// tracer/src/shading/colormap.rs on the same table. Needs `tracer_vector`.
//
// Buffer tracer_colormap: array<vec4<f32>>, the linear-RGB lookup table (256
// entries, (r, g, b, opacity)) sampled at i / 255; the opacity is for volumes.

// The colour at `t` in [0, 1] (clamped; NaN reads as 0), interpolated
// linearly between entries as glam's `lerp` does.
fn tracer_colormap_linear_at(t: f32) -> vec3<f32> {
    var clamped = 0.0;
    if (!tracer_is_nan(t)) {
        clamped = clamp(t, 0.0, 1.0);
    }
    let entries = arrayLength(&tracer_colormap);
    let x = clamped * f32(entries - 1u);
    let low = min(u32(x), entries - 2u);
    let fraction = x - f32(low);
    return tracer_colormap[low].xyz * (1.0 - fraction) + tracer_colormap[low + 1u].xyz * fraction;
}
