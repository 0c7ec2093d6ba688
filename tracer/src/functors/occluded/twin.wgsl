// The WGSL twin of `occluded` (mod.rs beside this file): whether anything
// lies at 0 < t < ray.tmax, stopping at the first hit the CPU's traversal
// finds (module `tracer_bvh`); dead rays are never blocked.
// Failure 0: the traversal stack overflowed.

fn $FUNCTION(index: u32, ray: Ray) -> bool {
    if (!tracer_is_positive(ray.tmax)) {
        return false;
    }
    let hit = tracer_bvh_traverse(ray.origin, ray.dir, ray.tmax, true);
    if (hit.stack_overflow) {
        $FUNCTION_fail(0u);
        return false;
    }
    return hit.found;
}
