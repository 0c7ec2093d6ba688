// The WGSL twin of `cubeTriangle` (mod.rs beside this file): triangle `lane`
// of a cell's marching-cubes surface at `level`, its corners on the cell's
// edges with gradient normals and interpolated scalars, as `edge_vertex` in
// tracer/src/functors/isosurface/mod.rs computes them (modules
// `tracer_volume`, `tracer_marching_cubes`).
// Failure 0: level is not finite. Failure 1: the cell is out of range.
// Failure 2: the cell has no triangle `lane` at this level.

struct $FUNCTION_Vertex {
    position: vec3<f32>,
    normal: vec3<f32>,
    scalar: f32,
}

fn $FUNCTION_edge_vertex(origin: vec3<u32>, corner_values: array<f32, 8>, edge: u32, level: f32) -> $FUNCTION_Vertex {
    var values = corner_values;
    let corners = tracer_mc_edge_endpoints(edge);
    let v0 = values[corners.x];
    let v1 = values[corners.y];
    // Clamped to [0, 1]; NaN (a flat edge at the level) is the middle.
    var t = (level - v0) / (v1 - v0);
    if (tracer_is_nan(t)) {
        t = 0.5;
    } else {
        t = clamp(t, 0.0, 1.0);
    }
    let s0 = tracer_volume_corner_sample(origin, corners.x);
    let s1 = tracer_volume_corner_sample(origin, corners.y);
    let p0 = tracer_volume_position(s0);
    let p1 = tracer_volume_position(s1);
    let g0 = tracer_volume_gradient(s0);
    let g1 = tracer_volume_gradient(s1);
    return $FUNCTION_Vertex(p0 + (p1 - p0) * t, tracer_normalize_or_zero(g0 + (g1 - g0) * t), v0 + (v1 - v0) * t);
}

fn $FUNCTION(index: u32, cell: u32, lane: u32, level: f32) -> Triangle {
    let zero = vec3<f32>(0.0);
    let nothing = Triangle(zero, zero, zero, zero, zero, zero, 0.0, 0.0, 0.0);
    if (!tracer_is_finite(level)) {
        $FUNCTION_fail(0u);
        return nothing;
    }
    if (cell >= tracer_volume_cell_count()) {
        $FUNCTION_fail(1u);
        return nothing;
    }
    let origin = tracer_volume_cell_origin(cell);
    let values = tracer_volume_corner_values(origin);
    let cube_case = tracer_volume_case_index(values, level);
    if (lane >= tracer_mc_triangle_count(cube_case)) {
        $FUNCTION_fail(2u);
        return nothing;
    }
    let edges = tracer_mc_triangle_edges(cube_case, lane);
    let a = $FUNCTION_edge_vertex(origin, values, edges.x, level);
    let b = $FUNCTION_edge_vertex(origin, values, edges.y, level);
    let c = $FUNCTION_edge_vertex(origin, values, edges.z, level);
    return Triangle(a.position, b.position, c.position, a.normal, b.normal, c.normal, a.scalar, b.scalar, c.scalar);
}
