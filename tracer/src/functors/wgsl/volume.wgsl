// Module `tracer_volume`: the run's volume as marching cubes reads it
// (`Volume` in tracer/src/volume/mod.rs and the cell helpers of
// tracer/src/functors/isosurface/mod.rs).
//
// Buffers (tracer/src/functors/wgsl/buffers.rs):
// - tracer_volume_grid: array<vec4<u32>>, 4 entries: (dims.xyz, cell count),
//   (bits of origin.xyz, 0), (bits of spacing.xyz, 0), (first.xyz, 0) (the
//   global index of sample (0, 0, 0): zero for a whole volume);
// - tracer_volume_values: array<f32>, sample (i, j, k) at i + dims.x * (j + dims.y * k).

fn tracer_volume_dims() -> vec3<u32> {
    return tracer_volume_grid[0].xyz;
}

fn tracer_volume_cell_count() -> u32 {
    return tracer_volume_grid[0].w;
}

fn tracer_volume_value(sample: vec3<u32>) -> f32 {
    let dims = tracer_volume_dims();
    return tracer_volume_values[sample.x + dims.x * (sample.y + dims.y * sample.z)];
}

// `Volume::position`: `origin + spacing * (first + (i, j, k))`, the global
// index converted to f32 once.
fn tracer_volume_position(sample: vec3<u32>) -> vec3<f32> {
    let origin = bitcast<vec3<f32>>(tracer_volume_grid[1].xyz);
    let spacing = bitcast<vec3<f32>>(tracer_volume_grid[2].xyz);
    let first = tracer_volume_grid[3].xyz;
    return origin + spacing * vec3<f32>(first + sample);
}

// `Volume::gradient`: central differences inside, one-sided on the border,
// 0 along an axis with a single sample; in world units.
fn tracer_volume_gradient(sample: vec3<u32>) -> vec3<f32> {
    let dims = tracer_volume_dims();
    let spacing = bitcast<vec3<f32>>(tracer_volume_grid[2].xyz);
    var gradient = vec3<f32>(0.0);
    for (var axis = 0u; axis < 3u; axis = axis + 1u) {
        if (dims[axis] < 2u) {
            continue;
        }
        let at = sample[axis];
        var low = sample;
        var high = sample;
        low[axis] = select(at - 1u, 0u, at == 0u);
        high[axis] = min(at + 1u, dims[axis] - 1u);
        let steps = f32(high[axis] - low[axis]);
        gradient[axis] = (tracer_volume_value(high) - tracer_volume_value(low)) / (steps * spacing[axis]);
    }
    return gradient;
}

// `cell_origin`: the lowest sample of cell `cell` (x fastest); the caller
// checks `cell < tracer_volume_cell_count()`.
fn tracer_volume_cell_origin(cell: u32) -> vec3<u32> {
    let cells = max(tracer_volume_dims(), vec3<u32>(1u)) - vec3<u32>(1u);
    let x = cell % cells.x;
    let rest = cell / cells.x;
    return vec3<u32>(x, rest % cells.y, rest / cells.y);
}

// `corner_sample`: corner `n` is at offset (n & 1, n >> 1 & 1, n >> 2 & 1).
fn tracer_volume_corner_sample(origin: vec3<u32>, corner: u32) -> vec3<u32> {
    return origin + vec3<u32>(corner & 1u, (corner >> 1u) & 1u, (corner >> 2u) & 1u);
}

fn tracer_volume_corner_values(origin: vec3<u32>) -> array<f32, 8> {
    var values: array<f32, 8>;
    for (var corner = 0u; corner < 8u; corner = corner + 1u) {
        values[corner] = tracer_volume_value(tracer_volume_corner_sample(origin, corner));
    }
    return values;
}

// `case_index`: bit n set when corner n is below the level.
fn tracer_volume_case_index(corner_values: array<f32, 8>, level: f32) -> u32 {
    var values = corner_values;
    var cube_case = 0u;
    for (var corner = 0u; corner < 8u; corner = corner + 1u) {
        if (values[corner] < level) {
            cube_case = cube_case | (1u << corner);
        }
    }
    return cube_case;
}
