// Module `tracer_surface`: what the twins that start rays from a `Surface`
// share (`SurfaceRecord`, `RayRecord::dead` and `scene_diagonal` in
// tracer/src/functors/mod.rs; needs `tracer_vector`). Constants from Rust are
// prepended: TRACER_SURFACE_EPSILON (f32).

// Whether the `scene.diagonal` uniform is positive and finite (the CPU's
// `scene_diagonal` check; the twins fail where it is not).
fn tracer_scene_diagonal_is_valid() -> bool {
    let diagonal = uniform_scene_diagonal();
    return tracer_is_finite(diagonal) && tracer_is_positive(diagonal);
}

// How far secondary rays start off the surface: a fraction of the scene diagonal.
fn tracer_surface_offset() -> f32 {
    return TRACER_SURFACE_EPSILON * uniform_scene_diagonal();
}

// `RayRecord::dead`: tmax 0, zero weight, a harmless unit direction.
fn tracer_dead_ray(sample: u32, depth: u32) -> Ray {
    return Ray(vec3<f32>(0.0), vec3<f32>(0.0, 0.0, 1.0), 0.0, sample, vec3<f32>(0.0), depth);
}

// `SurfaceRecord::offset_origin`: off the surface along the geometric normal.
fn tracer_offset_origin(surface: Surface, epsilon: f32) -> vec3<f32> {
    return surface.position + surface.geometric * epsilon;
}

// `SurfaceRecord::above_surface`: `dir` mirrored in the triangle's plane when
// it points into (or along) the surface.
fn tracer_above_surface(surface: Surface, dir: vec3<f32>) -> vec3<f32> {
    let below = tracer_dot(dir, surface.geometric);
    if (below > 0.0) {
        return dir;
    }
    return dir - 2.0 * below * surface.geometric;
}
