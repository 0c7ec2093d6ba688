// The WGSL twin of `marchBlock` (mod.rs beside this file; `point_block` and
// `block_index` in functors/volume_render/mod.rs): the block of g(t),
// clamped into the grid of blocks; 0 for a march that is not live.
// Failure 0: size < 1.

fn $FUNCTION(index: u32, march: March, size: i32) -> u32 {
    if (size < 1) {
        $FUNCTION_fail(0u);
        return 0u;
    }
    if (!(march.t <= march.tEnd)) {
        return 0u;
    }
    let s = u32(size);
    let cells = max(tracer_volume_dims(), vec3<u32>(2u)) - vec3<u32>(1u);
    let blocks = (cells + vec3<u32>(s - 1u)) / s;
    let g = march.origin + march.dir * march.t;
    let b = min(vec3<u32>(max(g / f32(s), vec3<f32>(0.0))), blocks - vec3<u32>(1u));
    return b.x + blocks.x * (b.y + blocks.y * b.z);
}
