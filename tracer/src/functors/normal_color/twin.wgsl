// The WGSL twin of `normalColor` (mod.rs beside this file): the hit
// triangle's geometric normal turned to face the viewer, as `n * 0.5 + 0.5`;
// the background on a miss.
// Failure 0: the hit names a triangle the scene does not have.

fn $FUNCTION(index: u32, ray: Ray, hit: Hit) -> vec3<f32> {
    if (hit.prim == $MISS_PRIM) {
        return $BACKGROUND;
    }
    if (hit.prim >= tracer_mesh_triangle_count()) {
        $FUNCTION_fail(0u);
        return vec3<f32>(0.0);
    }
    let normal = tracer_unit_or_zero(tracer_mesh_face_normal(hit.prim));
    var facing = normal;
    if (tracer_dot(normal, ray.dir) > 0.0) {
        facing = -normal;
    }
    return facing * 0.5 + 0.5;
}
