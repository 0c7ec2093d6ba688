// Module `tracer_marching_cubes`: the generated marching-cubes tables of
// tracer/src/functors/isosurface/tables.rs. Constants from Rust are
// prepended: TRACER_MC_MAX_CELL_TRIANGLES (u32).
//
// Buffers (tracer/src/functors/wgsl/buffers.rs):
// - tracer_mc_case_triangle_counts: array<u32>, 256: triangles per case;
// - tracer_mc_case_triangles: array<u32>, TRACER_MC_MAX_CELL_TRIANGLES per
//   case: the edges of each triangle, `e0 | e1 << 8 | e2 << 16`;
// - tracer_mc_edge_corners: array<u32>, 12: the corners of each edge, `lo | hi << 8`.

fn tracer_mc_triangle_count(cube_case: u32) -> u32 {
    return tracer_mc_case_triangle_counts[cube_case & 0xffu];
}

fn tracer_mc_triangle_edges(cube_case: u32, triangle: u32) -> vec3<u32> {
    let word = tracer_mc_case_triangles[(cube_case & 0xffu) * TRACER_MC_MAX_CELL_TRIANGLES + triangle];
    return vec3<u32>(word & 0xffu, (word >> 8u) & 0xffu, (word >> 16u) & 0xffu);
}

// The corners `(lo, hi)` that edge `edge` joins, `lo < hi`.
fn tracer_mc_edge_endpoints(edge: u32) -> vec2<u32> {
    let word = tracer_mc_edge_corners[edge];
    return vec2<u32>(word & 0xffu, (word >> 8u) & 0xffu);
}
