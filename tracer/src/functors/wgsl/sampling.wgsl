// Module `tracer_sampling`: `cosine_hemisphere` of
// tracer/src/functors/occ_ray_gen/mod.rs (needs `tracer_vector`). Constants
// from Rust are prepended: TRACER_SAMPLING_TAU and TRACER_SAMPLING_PI (f32).

// A unit direction about unit `normal` with density `cos θ / π` (Malley's
// method on the frame of Duff et al. 2017).
fn tracer_cosine_hemisphere(normal: vec3<f32>, u1: f32, u2: f32) -> vec3<f32> {
    let radius = sqrt(u1);
    // sin and cos are periodic, and GPUs are accurate only within [-π, π]:
    // the same angle, brought into that range.
    var angle = TRACER_SAMPLING_TAU * u2;
    if (angle > TRACER_SAMPLING_PI) {
        angle = angle - TRACER_SAMPLING_TAU;
    }
    let sine = sin(angle);
    let cosine = cos(angle);
    let height = sqrt(max(1.0 - u1, 0.0));
    // `1.0.copysign(normal.z)`: the sign bit, so that -0 gives -1.
    let sign = select(1.0, -1.0, (bitcast<u32>(normal.z) & 0x80000000u) != 0u);
    let a = -1.0 / (sign + normal.z);
    let b = normal.x * normal.y * a;
    let tangent = vec3<f32>(1.0 + sign * normal.x * normal.x * a, sign * b, -sign * normal.x);
    let bitangent = vec3<f32>(b, sign + normal.y * normal.y * a, -normal.y);
    return tracer_normalize(tangent * (radius * cosine) + bitangent * (radius * sine) + normal * height);
}
