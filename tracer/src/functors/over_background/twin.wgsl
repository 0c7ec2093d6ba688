// The WGSL twin of `overBackground` (mod.rs beside this file): color +
// background * (1 - alpha). Buffer tracer_shading_constants: entry 1 is
// (background, 0) in linear RGB.

fn $FUNCTION(index: u32, color: vec3<f32>, alpha: f32) -> vec3<f32> {
    return color + tracer_shading_constants[1].xyz * (1.0 - alpha);
}
