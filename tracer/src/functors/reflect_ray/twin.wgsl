// The WGSL twin of `reflectRay` (mod.rs beside this file): the mirror ray of a
// reflective hit (buffer tracer_materials, 2 per material: (Kd, Ns), (Ks,
// reflectivity)), off the surface along the geometric normal, with weight *
// reflectivity and depth + 1; dead for misses, dull materials and at maxDepth.
// Failure 0: scene.diagonal is not positive. Failure 1: unknown material.

fn $FUNCTION(index: u32, surf: Surface, maxDepth: i32) -> Ray {
    // `saturating_add(1)`.
    let depth = select(surf.depth + 1u, surf.depth, surf.depth == 0xffffffffu);
    let dead = tracer_dead_ray(surf.sample, depth);
    if (!tracer_scene_diagonal_is_valid()) {
        $FUNCTION_fail(0u);
        return dead;
    }
    // `depth >= maxDepth` compared as integers of any size.
    let too_deep = maxDepth < 0 || depth >= u32(maxDepth);
    if (!surf.hit || too_deep) {
        return dead;
    }
    if (surf.material >= arrayLength(&tracer_materials) / 2u) {
        $FUNCTION_fail(1u);
        return dead;
    }
    let reflectivity = tracer_materials[2u * surf.material + 1u].w;
    if (reflectivity <= 0.0) {
        return dead;
    }
    let incoming = -surf.view;
    var direction = incoming - 2.0 * tracer_dot(incoming, surf.normal) * surf.normal;
    if (tracer_dot(direction, surf.geometric) <= 0.0) {
        direction = incoming - 2.0 * tracer_dot(incoming, surf.geometric) * surf.geometric;
    }
    return Ray(
        tracer_offset_origin(surf, tracer_surface_offset()),
        tracer_normalize_or_zero(direction),
        tracer_infinity(),
        surf.sample,
        surf.weight * reflectivity,
        depth
    );
}
