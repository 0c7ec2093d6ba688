// The WGSL twin of `cellRange` (mod.rs beside this file): (min, -max) of a
// cell's 8 corner values (module `tracer_volume`). `min`/`max` skip NaN as
// Rust's f32::min/max do only where the GPU keeps NaN; volumes are checked
// finite when loaded.
// Failure 0: the cell is out of range.

fn $FUNCTION(index: u32, cell: u32) -> vec2<f32> {
    if (cell >= tracer_volume_cell_count()) {
        $FUNCTION_fail(0u);
        return vec2<f32>(0.0);
    }
    var values = tracer_volume_corner_values(tracer_volume_cell_origin(cell));
    var lo = tracer_infinity();
    var hi = -tracer_infinity();
    for (var corner = 0u; corner < 8u; corner = corner + 1u) {
        lo = min(lo, values[corner]);
        hi = max(hi, values[corner]);
    }
    return vec2<f32>(lo, -hi);
}
