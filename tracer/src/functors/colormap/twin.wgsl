// The WGSL twin of `colormap` (mod.rs beside this file): the lookup of the
// `shader` twin's `base`. Buffer tracer_shading_constants: word 0 is
// (min, max, 1 / (max - min), 0) of the scalar range, computed on the CPU.

fn $FUNCTION(index: u32, scalar: f32) -> vec3<f32> {
    let range = tracer_shading_constants[0];
    return tracer_colormap_linear_at((scalar - range.x) * range.z);
}
