// Module `tracer_random`: the stateless random numbers of `occRayGen`
// (`pcg_hash` and `random_pair` in tracer/src/functors/occ_ray_gen/mod.rs),
// bit for bit: u32 arithmetic wraps in WGSL as `wrapping_*` does on the CPU,
// and 24-bit integers convert to f32 exactly.

// The PCG hash (Jarzynski and Olano, "Hash Functions for GPU Rendering", 2020).
fn tracer_pcg_hash(value: u32) -> u32 {
    let state = value * 747796405u + 2891336453u;
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

// Two numbers in [0, 1) (24 bits each) from `(sample, depth, lane)`.
fn tracer_random_pair(sample: u32, depth: u32, lane: u32) -> vec2<f32> {
    let first = tracer_pcg_hash(sample ^ tracer_pcg_hash(depth ^ tracer_pcg_hash(lane)));
    let second = tracer_pcg_hash(first);
    // 2^-24, exact.
    let unit = 1.0 / 16777216.0;
    return vec2<f32>(f32(first >> 8u) * unit, f32(second >> 8u) * unit);
}
