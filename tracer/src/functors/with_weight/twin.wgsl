// The WGSL twin of `withWeight` (mod.rs beside this file): the ray with
// another colour weight.

fn $FUNCTION(index: u32, ray: Ray, weight: vec3<f32>) -> Ray {
    var out = ray;
    out.weight = weight;
    return out;
}
