// The WGSL twin of `globalId` (mod.rs beside this file): the id of triangle
// `prim` in the whole data set, from the scene's table.
//
// Buffer (the scene's, `TraceScene::global_id_gpu_buffer`):
// - tracer_global_ids: array<u32>, word 0 is 1 when the scene has a table
//   (0 without one), then the id of each triangle.
// Failure 0: with a table, `prim` names a triangle the scene does not have.

fn $FUNCTION(index: u32, prim: u32) -> u32 {
    if (prim == $MISS_PRIM || tracer_global_ids[0] == 0u) {
        return prim;
    }
    if (prim >= arrayLength(&tracer_global_ids) - 1u) {
        $FUNCTION_fail(0u);
        return $MISS_PRIM;
    }
    return tracer_global_ids[prim + 1u];
}
