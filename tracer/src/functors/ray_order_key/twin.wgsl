// The WGSL twin of `rayOrderKey` (mod.rs beside this file): the Morton code
// of the origin's cell in the scene's box above the direction's octant; the
// cell scale a power of two made from the bits of the box's longest side, so
// that both backends quantise exactly alike; 4294967295 for a dead ray.
// The cell bits per axis are mod.rs's CELL_BITS, substituted.

// `spread_bits`: the low 10 bits of `x` at bits 0, 3, 6, …, 27.
fn $FUNCTION_spread(v: u32) -> u32 {
    var x = v & 0x3ffu;
    x = (x | (x << 16u)) & 0x030000ffu;
    x = (x | (x << 8u)) & 0x0300f00fu;
    x = (x | (x << 4u)) & 0x030c30c3u;
    return (x | (x << 2u)) & 0x09249249u;
}

// `CellGrid::new`'s scale.
fn $FUNCTION_scale(extent: f32) -> f32 {
    let bits = bitcast<u32>(extent);
    if (bitcast<i32>(bits) <= 0) {
        return 0.0;
    }
    let exponent = max(bits >> 23u, $CELL_BITS - 1u);
    return bitcast<f32>((253u + $CELL_BITS - exponent) << 23u);
}

// `CellGrid::morton_code`.
fn $FUNCTION_morton(point: vec3<f32>, lower: vec3<f32>, scale: f32) -> u32 {
    if (!tracer_is_finite(point.x) || !tracer_is_finite(point.y) || !tracer_is_finite(point.z)) {
        return 0u;
    }
    let last = f32((1u << $CELL_BITS) - 1u);
    let cell = vec3<u32>(clamp((point - lower) * scale, vec3<f32>(0.0), vec3<f32>(last)));
    return $FUNCTION_spread(cell.x) | ($FUNCTION_spread(cell.y) << 1u) | ($FUNCTION_spread(cell.z) << 2u);
}

fn $FUNCTION(index: u32, ray: Ray) -> u32 {
    if (!tracer_is_positive(ray.tmax)) {
        return 0xffffffffu;
    }
    let lower = uniform_scene_boundsMin();
    let upper = uniform_scene_boundsMax();
    let extent = upper - lower;
    let scale = $FUNCTION_scale(max(max(extent.x, extent.y), extent.z));
    let signs = vec3<u32>(bitcast<vec3<u32>>(ray.dir) >> vec3<u32>(31u));
    let octant = signs.x | (signs.y << 1u) | (signs.z << 2u);
    return ($FUNCTION_morton(ray.origin, lower, scale) << 3u) | octant;
}
