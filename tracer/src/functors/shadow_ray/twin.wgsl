// The WGSL twin of `shadowRay` (mod.rs beside this file), expand lane `lane`:
// the ray from the surface point, offset along the geometric normal, towards
// light `lane` (buffer tracer_lights, 2 per light: (position, intensity),
// (colour, 0)), ending `epsilon` short of it; dead for a miss or a light
// behind the shading normal.
// Failure 0: the fanout is not the number of lights. Failure 1: scene.diagonal
// is not positive.

fn $FUNCTION(source_index: u32, surf: Surface, lane: u32, k: u32) -> Ray {
    let dead = tracer_dead_ray(surf.sample, surf.depth);
    if (k != arrayLength(&tracer_lights) / 2u) {
        $FUNCTION_fail(0u);
        return dead;
    }
    if (!tracer_scene_diagonal_is_valid()) {
        $FUNCTION_fail(1u);
        return dead;
    }
    if (!surf.hit) {
        return dead;
    }
    let epsilon = tracer_surface_offset();
    let origin = tracer_offset_origin(surf, epsilon);
    let to_light = tracer_lights[2u * lane].xyz - origin;
    let distance = tracer_length(to_light);
    let tmax = distance - epsilon;
    // False for NaN too, as on the CPU.
    if (tracer_dot(surf.normal, to_light) > 0.0 && tmax > 0.0) {
        return Ray(origin, to_light / distance, tmax, surf.sample, surf.weight, surf.depth);
    }
    return dead;
}
