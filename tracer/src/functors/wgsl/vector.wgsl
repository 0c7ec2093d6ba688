// Module `tracer_vector`: float tests on bits and the vector operations of
// glam (tracer/src/functors/*/mod.rs use glam), written out in glam's order of
// operations so that the GPU rounds where the CPU does. WGSL implementations
// may assume that no float is NaN or infinite, so NaN and infinity tests look
// at the bits instead of comparing.

fn tracer_infinity() -> f32 {
    return bitcast<f32>(0x7f800000u);
}

fn tracer_is_nan(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7fffffffu) > 0x7f800000u;
}

fn tracer_is_finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) != 0x7f800000u;
}

// `x > 0.0` as the CPU evaluates it: false for NaN and zeros, true for
// subnormals and +inf (the bits 1 ..= 0x7f800000).
fn tracer_is_positive(x: f32) -> bool {
    return bitcast<u32>(x) - 1u < 0x7f800000u;
}

// glam's `dot`: `(x * x') + (y * y') + (z * z')`, left to right.
fn tracer_dot(a: vec3<f32>, b: vec3<f32>) -> f32 {
    return a.x * b.x + a.y * b.y + a.z * b.z;
}

// glam's `cross`.
fn tracer_cross(a: vec3<f32>, b: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(a.y * b.z - b.y * a.z, a.z * b.x - b.z * a.x, a.x * b.y - b.x * a.y);
}

// glam's `length`: the square root of `dot(v, v)`.
fn tracer_length(v: vec3<f32>) -> f32 {
    return sqrt(tracer_dot(v, v));
}

// glam's `normalize`: `v * (1 / length)` (not WGSL's `normalize`, which may
// use a less precise inverse square root).
fn tracer_normalize(v: vec3<f32>) -> vec3<f32> {
    return v * (1.0 / tracer_length(v));
}

// glam's `normalize_or_zero`: zero where `1 / length` is not finite and positive.
fn tracer_normalize_or_zero(v: vec3<f32>) -> vec3<f32> {
    let reciprocal = 1.0 / tracer_length(v);
    if (tracer_is_finite(reciprocal) && tracer_is_positive(reciprocal)) {
        return v * reciprocal;
    }
    return vec3<f32>(0.0);
}

// `crate::vector::unit_or_zero`: `tracer_normalize_or_zero`, except that a
// nonzero finite vector whose squared length overflows or underflows is first
// multiplied by the power of two that brings its largest component into 1 .. 2.
fn tracer_unit_or_zero(v: vec3<f32>) -> vec3<f32> {
    let unit = tracer_normalize_or_zero(v);
    if (!tracer_is_zero_vector(unit) || tracer_is_zero_vector(v)
        || !(tracer_is_finite(v.x) && tracer_is_finite(v.y) && tracer_is_finite(v.z))) {
        return unit;
    }
    let largest = max(max(abs(v.x), abs(v.y)), abs(v.z));
    let biased_exponent = i32((bitcast<u32>(largest) >> 23u) & 0xffu);
    let scale = bitcast<f32>(u32(clamp(254 - biased_exponent, 1, 254)) << 23u);
    return tracer_normalize_or_zero(v * scale);
}

fn tracer_is_zero_vector(v: vec3<f32>) -> bool {
    return v.x == 0.0 && v.y == 0.0 && v.z == 0.0;
}
