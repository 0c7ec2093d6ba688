// The WGSL twin of `clipRay` (mod.rs beside this file): the ray ending at `t`
// where that is nearer (a comparison, not `min`, whose NaN is unspecified).

fn $FUNCTION(index: u32, ray: Ray, t: f32) -> Ray {
    var out = ray;
    if (t < ray.tmax) {
        out.tmax = t;
    }
    return out;
}
