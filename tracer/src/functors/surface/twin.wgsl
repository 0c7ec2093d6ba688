// The WGSL twin of `surface` (mod.rs beside this file): position, shading
// normal (bent towards the viewer up to MIN_VIEW_COSINE), view vector,
// scalar, material and geometric normal of a hit, as the CPU computes them.
// Failure 0: the hit names a triangle the scene does not have.

// `facing_the_viewer` of mod.rs.
fn $FUNCTION_facing_the_viewer(normal: vec3<f32>, view: vec3<f32>, geometric: vec3<f32>) -> vec3<f32> {
    let cosine = tracer_dot(normal, view);
    if (cosine >= $MIN_VIEW_COSINE || tracer_is_zero_vector(view)) {
        return normal;
    }
    let across = tracer_normalize_or_zero(normal - cosine * view);
    if (tracer_is_zero_vector(across)) {
        return geometric;
    }
    return tracer_normalize($MIN_VIEW_SINE * across + $MIN_VIEW_COSINE * view);
}

fn $FUNCTION(index: u32, ray: Ray, hit: Hit) -> Surface {
    let zero = vec3<f32>(0.0);
    if (!tracer_is_positive(ray.tmax)) {
        return Surface(zero, zero, zero, 0.0, 0u, false, ray.sample, zero, ray.depth, zero);
    }
    if (hit.prim == $MISS_PRIM) {
        return Surface(zero, zero, zero, 0.0, 0u, false, ray.sample, ray.weight, ray.depth, zero);
    }
    if (hit.prim >= tracer_mesh_triangle_count()) {
        $FUNCTION_fail(0u);
        return Surface(zero, zero, zero, 0.0, 0u, false, ray.sample, zero, ray.depth, zero);
    }
    let triangle = tracer_mesh_triangle(hit.prim);
    let u = hit.u;
    let v = hit.v;
    let w = 1.0 - u - v;
    let position = w * tracer_mesh_position(triangle.x) + u * tracer_mesh_position(triangle.y)
        + v * tracer_mesh_position(triangle.z);
    let view = -tracer_normalize_or_zero(ray.dir);
    // The geometric normal on the ray's side (the view vector for a degenerate triangle).
    let face = tracer_unit_or_zero(tracer_mesh_face_normal(hit.prim));
    var facing = face;
    if (tracer_is_zero_vector(face)) {
        facing = view;
    } else if (tracer_dot(face, ray.dir) > 0.0) {
        facing = -face;
    }
    let interpolated = tracer_normalize_or_zero(
        w * tracer_mesh_normal(triangle.x) + u * tracer_mesh_normal(triangle.y) + v * tracer_mesh_normal(triangle.z)
    );
    var normal = interpolated;
    if (tracer_is_zero_vector(interpolated)) {
        normal = facing;
    } else if (tracer_dot(interpolated, facing) < 0.0) {
        normal = -interpolated;
    }
    normal = $FUNCTION_facing_the_viewer(normal, view, facing);
    let scalar = w * tracer_mesh_scalar(triangle.x) + u * tracer_mesh_scalar(triangle.y)
        + v * tracer_mesh_scalar(triangle.z);
    return Surface(position, normal, view, scalar, triangle.w, true, ray.sample, ray.weight, ray.depth, facing);
}
