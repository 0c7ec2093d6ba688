// The WGSL twin of `skipEmpty` (mod.rs beside this file; `skip_block` in
// functors/volume_render/mod.rs): a live march in an empty block moved to
// t + n step, n >= 1 the fewest steps past the block's far side.
// Failure 0: size < 1. Failure 1: step is not a finite number above 0.

fn $FUNCTION(index: u32, march: March, empty: bool, size: i32, step: f32) -> March {
    var m = march;
    if (size < 1) {
        $FUNCTION_fail(0u);
        return m;
    }
    if (!(tracer_is_finite(step) && step > 0.0)) {
        $FUNCTION_fail(1u);
        return m;
    }
    if (!empty || !(m.t <= m.tEnd)) {
        return m;
    }
    let s = u32(size);
    let dims = tracer_volume_dims();
    let cells = max(dims, vec3<u32>(2u)) - vec3<u32>(1u);
    let blocks = (cells + vec3<u32>(s - 1u)) / s;
    let g = m.origin + m.dir * m.t;
    let b = min(vec3<u32>(max(g / f32(s), vec3<f32>(0.0))), blocks - vec3<u32>(1u));
    let last = vec3<f32>(max(dims, vec3<u32>(1u)) - vec3<u32>(1u));
    let low = vec3<f32>(b * s);
    let high = min(vec3<f32>((b + vec3<u32>(1u)) * s), last);
    var exit = tracer_infinity();
    for (var axis = 0u; axis < 3u; axis = axis + 1u) {
        if (m.dir[axis] != 0.0) {
            let t0 = (low[axis] - m.origin[axis]) / m.dir[axis];
            let t1 = (high[axis] - m.origin[axis]) / m.dir[axis];
            exit = min(exit, max(t0, t1));
        }
    }
    let steps = max(ceil((exit - m.t) / step), 1.0);
    m.t = m.t + steps * step;
    return m;
}
