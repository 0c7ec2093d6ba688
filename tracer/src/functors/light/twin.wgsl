// The WGSL twin of `light` (mod.rs beside this file).
// Buffer tracer_lights: 2 vec4 per light, (position, intensity) and (colour, 0).
// Failure 0: the index is past the scene's lights.

fn $FUNCTION(index: u32, light: u32) -> Light {
    if (light >= arrayLength(&tracer_lights) / 2u) {
        $FUNCTION_fail(0u);
        return Light(vec3<f32>(0.0), 0.0, vec3<f32>(0.0));
    }
    let position_and_intensity = tracer_lights[2u * light];
    return Light(position_and_intensity.xyz, position_and_intensity.w, tracer_lights[2u * light + 1u].xyz);
}
