// The WGSL twin of `volumeEntry` (mod.rs beside this file; the definition in
// functors/volume_render/mod.rs): the ray in the volume's sample coordinates,
// clipped to the box of the samples (slabs) and to 0 <= t <= tmax; jittered
// by a hashed fraction of a step. Volume through module `tracer_volume`.
// Failure 0: step is not a finite number above 0.

fn $FUNCTION(index: u32, ray: Ray, step: f32, jitter: bool) -> March {
    let origin = bitcast<vec3<f32>>(tracer_volume_grid[1].xyz);
    let spacing = bitcast<vec3<f32>>(tracer_volume_grid[2].xyz);
    let first = vec3<f32>(tracer_volume_grid[3].xyz);
    let o = (ray.origin - origin) / spacing - first;
    let d = ray.dir / spacing;
    let missed = March(o, d, tracer_infinity(), -tracer_infinity(), vec3<f32>(0.0), 0.0, ray.sample);
    if (!(tracer_is_finite(step) && step > 0.0)) {
        $FUNCTION_fail(0u);
        return missed;
    }
    let last = vec3<f32>(max(tracer_volume_dims(), vec3<u32>(1u)) - vec3<u32>(1u));
    var near = 0.0;
    var far = ray.tmax;
    for (var axis = 0u; axis < 3u; axis = axis + 1u) {
        if (d[axis] == 0.0) {
            if (!(o[axis] >= 0.0 && o[axis] <= last[axis])) {
                return missed;
            }
            continue;
        }
        let t0 = (0.0 - o[axis]) / d[axis];
        let t1 = (last[axis] - o[axis]) / d[axis];
        near = max(near, min(t0, t1));
        far = min(far, max(t0, t1));
    }
    if (!(near <= far)) {
        return missed;
    }
    var offset = 0.0;
    if (jitter) {
        // 2^-24, exact.
        offset = f32(tracer_pcg_hash(ray.sample) >> 8u) * (1.0 / 16777216.0) * step;
    }
    return March(o, d, near + offset, far, vec3<f32>(0.0), 0.0, ray.sample);
}
