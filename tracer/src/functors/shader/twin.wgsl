// The WGSL twin of `shader` (mod.rs beside this file): Blinn-Phong in linear
// RGB as the CPU computes it. Buffers: tracer_shading_constants ((min, max,
// 1 / (max - min), 0) of the scalar range, (background, 0)), tracer_materials
// (2 per material: (Kd, Ns), (Ks, reflectivity)), tracer_lights (2 per light:
// (position, intensity), (colour, 0)); the colour map through `tracer_colormap`.
// Failure 0: ambient is not finite. Failure 1: falloff is not finite.
// Failure 2: scene.diagonal is not positive. Failure 3: unknown material.

// `powf` for the specular term: WGSL's `pow` is `exp2(y * log2(x))`, NaN for
// 0^0 where Rust gives 1 (x >= 0 here).
fn $FUNCTION_power(x: f32, y: f32) -> f32 {
    if (y == 0.0) {
        return 1.0;
    }
    if (x == 0.0) {
        return 0.0;
    }
    return pow(x, y);
}

fn $FUNCTION(index: u32, surf: Surface, occlusion: f32, visible: u32, ambient: f32, falloff: f32) -> vec3<f32> {
    if (!tracer_is_finite(ambient)) {
        $FUNCTION_fail(0u);
        return vec3<f32>(0.0);
    }
    if (!tracer_is_finite(falloff)) {
        $FUNCTION_fail(1u);
        return vec3<f32>(0.0);
    }
    if (!tracer_scene_diagonal_is_valid()) {
        $FUNCTION_fail(2u);
        return vec3<f32>(0.0);
    }
    let inverse_diagonal = 1.0 / uniform_scene_diagonal();
    let scalar_range = tracer_shading_constants[0];
    if (!surf.hit) {
        return tracer_shading_constants[1].xyz * surf.weight;
    }
    if (surf.material >= arrayLength(&tracer_materials) / 2u) {
        $FUNCTION_fail(3u);
        return vec3<f32>(0.0);
    }
    let diffuse_and_shininess = tracer_materials[2u * surf.material];
    let specular_and_reflectivity = tracer_materials[2u * surf.material + 1u];
    let kd = diffuse_and_shininess.xyz;
    let ns = diffuse_and_shininess.w;
    let ks = specular_and_reflectivity.xyz;
    let reflectivity = specular_and_reflectivity.w;
    let base = tracer_colormap_linear_at((surf.scalar - scalar_range.x) * scalar_range.z) * kd;
    // Rust's `clamp` keeps a NaN occlusion, which makes every component NaN;
    // WGSL's `clamp` of NaN is any value in the range.
    if (tracer_is_nan(occlusion)) {
        return vec3<f32>(bitcast<f32>(0x7fc00000u));
    }
    let open = 1.0 - clamp(occlusion, 0.0, 1.0);
    var local = ambient * open * base;
    let normal = surf.normal;
    let sees_viewer = tracer_dot(normal, surf.view) > 0.0;
    let lights = min(arrayLength(&tracer_lights) / 2u, $MAX_LIGHTS);
    for (var light = 0u; light < lights; light = light + 1u) {
        if ((visible & (1u << light)) == 0u) {
            continue;
        }
        let position_and_intensity = tracer_lights[2u * light];
        let color = tracer_lights[2u * light + 1u].xyz;
        let to_light = position_and_intensity.xyz - surf.position;
        let distance = tracer_length(to_light);
        let direction = to_light / distance;
        let diffuse = tracer_dot(normal, direction);
        // Only lights in front; false for NaN too (a light exactly at the point).
        if (diffuse > 0.0) {
            let scaled = distance * inverse_diagonal;
            let attenuation = position_and_intensity.w / (1.0 + falloff * scaled * scaled);
            var specular = 0.0;
            if (sees_viewer) {
                let half_vector = tracer_normalize_or_zero(direction + surf.view);
                specular = $FUNCTION_power(max(tracer_dot(normal, half_vector), 0.0), ns);
            }
            local = local + attenuation * color * (base * diffuse + ks * specular);
        }
    }
    return local * (1.0 - reflectivity) * surf.weight;
}
