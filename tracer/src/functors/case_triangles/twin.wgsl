// The WGSL twin of `caseTriangles` (mod.rs beside this file): the number of
// triangles (0 to 5) of a marching-cubes case, from the generated tables
// (module `tracer_marching_cubes`).
// Failure 0: the case is not 0 to 255.

fn $FUNCTION(index: u32, cube_case: u32) -> u32 {
    if (cube_case > 255u) {
        $FUNCTION_fail(0u);
        return 0u;
    }
    return tracer_mc_triangle_count(cube_case);
}
