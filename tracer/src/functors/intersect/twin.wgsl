// The WGSL twin of `intersect` (mod.rs beside this file): the closest hit
// with 0 < t < ray.tmax through the CPU's traversal (module `tracer_bvh`);
// dead rays (tmax <= 0 or NaN) miss without one.
// Failure 0: the traversal stack overflowed.

fn $FUNCTION(index: u32, ray: Ray) -> Hit {
    let miss = Hit(tracer_infinity(), $MISS_PRIM, 0.0, 0.0);
    if (!tracer_is_positive(ray.tmax)) {
        return miss;
    }
    let hit = tracer_bvh_traverse(ray.origin, ray.dir, ray.tmax, false);
    if (hit.stack_overflow) {
        $FUNCTION_fail(0u);
        return miss;
    }
    if (!hit.found) {
        return miss;
    }
    return Hit(hit.t, hit.prim, hit.u, hit.v);
}
