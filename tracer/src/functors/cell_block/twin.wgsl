// The WGSL twin of `cellBlock` (mod.rs beside this file): the skipping block
// (size³ cells, x fastest) of a cell's lowest sample (module `tracer_volume`).
// Failure 0: size < 1. Failure 1: the cell is out of range.

fn $FUNCTION(index: u32, cell: u32, size: i32) -> u32 {
    if (size < 1) {
        $FUNCTION_fail(0u);
        return 0u;
    }
    if (cell >= tracer_volume_cell_count()) {
        $FUNCTION_fail(1u);
        return 0u;
    }
    let s = u32(size);
    let cells = max(tracer_volume_dims(), vec3<u32>(2u)) - vec3<u32>(1u);
    let blocks = (cells + vec3<u32>(s - 1u)) / s;
    let b = min(tracer_volume_cell_origin(cell) / s, blocks - vec3<u32>(1u));
    return b.x + blocks.x * (b.y + blocks.y * b.z);
}
