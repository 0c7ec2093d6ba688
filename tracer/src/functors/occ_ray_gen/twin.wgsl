// The WGSL twin of `occRayGen` (mod.rs beside this file), expand lane `lane`:
// a cosine-weighted direction about the shading normal from the same hashed
// random numbers as the CPU (module `tracer_random`), kept on the geometric
// normal's side, `range * scene.diagonal` long; dead for a miss or range <= 0.
// Failure 0: range is not finite. Failure 1: scene.diagonal is not positive.

fn $FUNCTION(source_index: u32, surf: Surface, lane: u32, k: u32, range: f32) -> Ray {
    let dead = tracer_dead_ray(surf.sample, surf.depth);
    if (!tracer_is_finite(range)) {
        $FUNCTION_fail(0u);
        return dead;
    }
    if (!tracer_scene_diagonal_is_valid()) {
        $FUNCTION_fail(1u);
        return dead;
    }
    let epsilon = tracer_surface_offset();
    let ray_length = range * uniform_scene_diagonal();
    if (!surf.hit || !tracer_is_positive(ray_length)) {
        return dead;
    }
    let random = tracer_random_pair(surf.sample, surf.depth, lane);
    let direction = tracer_above_surface(surf, tracer_cosine_hemisphere(surf.normal, random.x, random.y));
    return Ray(tracer_offset_origin(surf, epsilon), direction, ray_length, surf.sample, surf.weight, surf.depth);
}
