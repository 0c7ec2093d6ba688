// The WGSL twin of `cubeCase` (mod.rs beside this file): the marching-cubes
// case of a cell of the run's volume (module `tracer_volume`): bit n set when
// corner n is below `level`.
// Failure 0: level is not finite. Failure 1: the cell is out of range.

fn $FUNCTION(index: u32, cell: u32, level: f32) -> u32 {
    if (!tracer_is_finite(level)) {
        $FUNCTION_fail(0u);
        return 0u;
    }
    if (cell >= tracer_volume_cell_count()) {
        $FUNCTION_fail(1u);
        return 0u;
    }
    let origin = tracer_volume_cell_origin(cell);
    return tracer_volume_case_index(tracer_volume_corner_values(origin), level);
}
