// Module `tracer_mesh`: the scene's triangles in input file order, for the
// twins that shade a hit (`normalColor`, `surface`). Needs `tracer_vector`.
//
// Buffers (tracer/src/functors/wgsl/buffers.rs):
// - tracer_mesh_triangles: array<vec4<u32>>, per triangle: its three vertex
//   indices and its material id;
// - tracer_mesh_vertices: array<vec4<f32>>, 2 per vertex: (position.xyz,
//   scalar) and (normal.xyz, 0).

fn tracer_mesh_triangle_count() -> u32 {
    return arrayLength(&tracer_mesh_triangles);
}

fn tracer_mesh_triangle(prim: u32) -> vec4<u32> {
    return tracer_mesh_triangles[prim];
}

fn tracer_mesh_position(vertex: u32) -> vec3<f32> {
    return tracer_mesh_vertices[2u * vertex].xyz;
}

fn tracer_mesh_scalar(vertex: u32) -> f32 {
    return tracer_mesh_vertices[2u * vertex].w;
}

fn tracer_mesh_normal(vertex: u32) -> vec3<f32> {
    return tracer_mesh_vertices[2u * vertex + 1u].xyz;
}

// `TriangleMesh::face_normal`: `(v1 - v0) × (v2 - v0)`, not normalised.
fn tracer_mesh_face_normal(prim: u32) -> vec3<f32> {
    let corners = tracer_mesh_triangle(prim);
    let v0 = tracer_mesh_position(corners.x);
    let v1 = tracer_mesh_position(corners.y);
    let v2 = tracer_mesh_position(corners.z);
    return tracer_cross(v1 - v0, v2 - v0);
}
