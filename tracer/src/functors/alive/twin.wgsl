// The WGSL twin of `alive` (mod.rs beside this file): `tmax > 0`, false for
// NaN (tested on the bits: WGSL may assume there is no NaN).

fn $FUNCTION(index: u32, ray: Ray) -> bool {
    return tracer_is_positive(ray.tmax);
}
