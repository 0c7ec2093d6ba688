// Module `tracer_bvh`: the CPU's BVH traversal (`Bvh::traverse_axes` in
// tracer/src/bvh.rs) and its watertight triangle test, step by step, so that
// the GPU visits nodes and triangles in the CPU's order and keeps the same
// closest hit (of hits at exactly the same distance, the lowest leaf-order
// triangle, whatever the order of visits). Needs
// `tracer_vector`. Constants from Rust are prepended:
// TRACER_BVH_MAX_STACK_DEPTH (u32), TRACER_BVH_ROBUST_FAR_SCALE (f32), and the
// scene's TRACER_BVH_SCALE and TRACER_BVH_INVERSE_SCALE (f32).
//
// Buffers (tracer/src/functors/wgsl/buffers.rs):
// - tracer_bvh_nodes: array<vec4<f32>>, 4 per node: per child (left, then
//   right) `(min.xyz, bits of index)` and `(max.xyz, bits of count)`; a child
//   with count 0 is inner node `index`, else the leaf of triangles
//   `index .. index + count` (leaf order). The root is node 0.
// - tracer_bvh_triangles: array<f32>, 9 per leaf-order triangle: v0, v1, v2.
// - tracer_bvh_triangle_ids: array<u32>, the file-order id of each.

struct TracerBvhHit {
    found: bool,
    // The traversal needed more than TRACER_BVH_MAX_STACK_DEPTH entries and
    // stopped; the caller reports it with its `_fail`.
    stack_overflow: bool,
    t: f32,
    u: f32,
    v: f32,
    // The triangle in input file order.
    prim: u32,
}

// `PreparedRay` with the axis permutation of the dominant direction axis.
struct TracerBvhRay {
    origin: vec3<f32>,
    inverse_direction: vec3<f32>,
    // The sign bits of the direction: the ray enters a box through its max plane.
    enters_at_max: vec3<bool>,
    shear: vec3<f32>,
    kx: u32,
    ky: u32,
    kz: u32,
}

struct TracerBvhTriangleHit {
    found: bool,
    t: f32,
    u: f32,
    v: f32,
}

fn tracer_bvh_prepare(origin: vec3<f32>, direction: vec3<f32>) -> TracerBvhRay {
    let magnitude = abs(direction);
    // The CPU's `traverse` dispatch: x dominant (1, 2, 0), else y (2, 0, 1),
    // else z (0, 1, 2).
    var kx = 0u;
    var ky = 1u;
    var kz = 2u;
    if (magnitude.x >= magnitude.y && magnitude.x >= magnitude.z) {
        kx = 1u;
        ky = 2u;
        kz = 0u;
    } else if (magnitude.y >= magnitude.z) {
        kx = 2u;
        ky = 0u;
        kz = 1u;
    }
    let sign_bits = bitcast<vec3<u32>>(direction) & vec3<u32>(0x80000000u);
    let shear = vec3<f32>(direction[kx] / direction[kz], direction[ky] / direction[kz], 1.0 / direction[kz]);
    return TracerBvhRay(origin, vec3<f32>(1.0) / direction, sign_bits != vec3<u32>(0u), shear, kx, ky, kz);
}

// `is_entered_before`: a box entered at `t_entry` (+inf: missed) can hold a
// hit closer than `closest`.
fn tracer_bvh_is_entered_before(t_entry: f32, closest: f32) -> bool {
    return t_entry < tracer_infinity() && t_entry <= closest * TRACER_BVH_ROBUST_FAR_SCALE;
}

// `entry_distance`: where the ray enters the box, +inf if it misses it
// before `tmax`. A NaN slab distance fails both comparisons and leaves the
// slab unconstrained, as on the CPU.
fn tracer_bvh_entry_distance(ray: TracerBvhRay, box_min: vec3<f32>, box_max: vec3<f32>, tmax: f32) -> f32 {
    var t_enter = 0.0;
    var t_exit = tmax;
    for (var axis = 0u; axis < 3u; axis = axis + 1u) {
        let near = select(box_min[axis], box_max[axis], ray.enters_at_max[axis]);
        let far = select(box_max[axis], box_min[axis], ray.enters_at_max[axis]);
        let t_near = (near - ray.origin[axis]) * ray.inverse_direction[axis];
        let t_far = (far - ray.origin[axis]) * ray.inverse_direction[axis];
        if (t_near > t_enter) {
            t_enter = t_near;
        }
        if (t_far < t_exit) {
            t_exit = t_far;
        }
    }
    if (t_enter <= t_exit * TRACER_BVH_ROBUST_FAR_SCALE) {
        return t_enter;
    }
    return tracer_infinity();
}

// `px * qy - py * qx` with the exact sign (exactly 0 when the products are
// equal): Kahan's difference of products, exact products through `fma`,
// within 1.5 ulps. The CPU gets the same signs from its f32 difference (the
// difference of rounded products has the exact sign or is 0) and its f64
// re-evaluation of zeros. WGSL has no f64, and a GPU compiler may contract
// the plain `a * b - c * d` into an `fma` (NVIDIA's does), whose result is
// neither sign-exact nor the negation of the same edge's in the neighbouring
// triangle: rays through shared edges and vertices then leak (seen on an
// H100: 64 of 8648 rays aimed at a closed cube's vertices and edges).
fn tracer_bvh_edge_exact(px: f32, py: f32, qx: f32, qy: f32) -> f32 {
    let rounded = py * qx;
    let rounding_error = fma(-py, qx, rounded);
    return fma(px, qy, -rounded) + rounding_error;
}

// Watertight ray-triangle test (Woop, Benthin, Wald 2013, two-sided) of
// leaf-order triangle `index`: `intersect_triangle` on the CPU. Hits at
// `0 < t < tmax`, or `0 < t <= tmax` with `up_to_tmax`.
fn tracer_bvh_intersect_triangle(ray: TracerBvhRay, index: u32, tmax: f32, up_to_tmax: bool) -> TracerBvhTriangleHit {
    let miss = TracerBvhTriangleHit(false, 0.0, 0.0, 0.0);
    let base = index * 9u;
    let v0 = vec3<f32>(tracer_bvh_triangles[base], tracer_bvh_triangles[base + 1u], tracer_bvh_triangles[base + 2u]);
    let v1 = vec3<f32>(tracer_bvh_triangles[base + 3u], tracer_bvh_triangles[base + 4u], tracer_bvh_triangles[base + 5u]);
    let v2 = vec3<f32>(tracer_bvh_triangles[base + 6u], tracer_bvh_triangles[base + 7u], tracer_bvh_triangles[base + 8u]);
    // The vertices relative to the origin, permuted and sheared into ray space.
    let p0 = v0 - ray.origin;
    let p1 = v1 - ray.origin;
    let p2 = v2 - ray.origin;
    // (A vertex's sheared coordinates are the same in every triangle that
    // shares it, contracted or not: the same operations on the same values.)
    let ax = p0[ray.kx] - ray.shear.x * p0[ray.kz];
    let ay = p0[ray.ky] - ray.shear.y * p0[ray.kz];
    let az = ray.shear.z * p0[ray.kz];
    let bx = p1[ray.kx] - ray.shear.x * p1[ray.kz];
    let by = p1[ray.ky] - ray.shear.y * p1[ray.kz];
    let bz = ray.shear.z * p1[ray.kz];
    let cx = p2[ray.kx] - ray.shear.x * p2[ray.kz];
    let cy = p2[ray.ky] - ray.shear.y * p2[ray.kz];
    let cz = ray.shear.z * p2[ray.kz];

    let u = tracer_bvh_edge_exact(cx, cy, bx, by);
    let v = tracer_bvh_edge_exact(ax, ay, cx, cy);
    let w = tracer_bvh_edge_exact(bx, by, ax, ay);
    if ((u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0)) {
        return miss;
    }
    let determinant = u + v + w;
    if (determinant == 0.0) {
        return miss;
    }
    let t = (u * az + v * bz + w * cz) / determinant;
    if (t > 0.0 && (t < tmax || (up_to_tmax && t == tmax))) {
        return TracerBvhTriangleHit(true, t, v / determinant, w / determinant);
    }
    return miss;
}

// The closest hit with `0 < t < tmax` or, with `any_hit`, the first one found.
fn tracer_bvh_traverse(origin: vec3<f32>, direction: vec3<f32>, tmax: f32, any_hit: bool) -> TracerBvhHit {
    // The stored vertices are multiplied by a power of two (`Bvh::scale`): so
    // are the origin and tmax, and hit distances are divided back, exactly.
    let ray = tracer_bvh_prepare(origin * TRACER_BVH_SCALE, direction);
    var closest = tmax * TRACER_BVH_SCALE;
    var found = false;
    var best_triangle = 0u;
    var best_t = 0.0;
    var best_u = 0.0;
    var best_v = 0.0;
    // Inner nodes still to visit, with the distance at which the ray enters them.
    var stack_nodes: array<u32, TRACER_BVH_MAX_STACK_DEPTH>;
    var stack_entries: array<f32, TRACER_BVH_MAX_STACK_DEPTH>;
    var stack_len = 0u;
    var node = 0u;
    loop {
        let base = node * 4u;
        let left_low = tracer_bvh_nodes[base];
        let left_high = tracer_bvh_nodes[base + 1u];
        let right_low = tracer_bvh_nodes[base + 2u];
        let right_high = tracer_bvh_nodes[base + 3u];
        let t_left = tracer_bvh_entry_distance(ray, left_low.xyz, left_high.xyz, closest);
        let t_right = tracer_bvh_entry_distance(ray, right_low.xyz, right_high.xyz, closest);
        // Near child first; the left one on a tie.
        var child_index = array<u32, 2>(bitcast<u32>(left_low.w), bitcast<u32>(right_low.w));
        var child_count = array<u32, 2>(bitcast<u32>(left_high.w), bitcast<u32>(right_high.w));
        var child_entry = array<f32, 2>(t_left, t_right);
        if (t_right < t_left) {
            child_index = array<u32, 2>(child_index[1], child_index[0]);
            child_count = array<u32, 2>(child_count[1], child_count[0]);
            child_entry = array<f32, 2>(t_right, t_left);
        }
        var inner_nodes = array<u32, 2>(0u, 0u);
        var inner_entries = array<f32, 2>(0.0, 0.0);
        var inner_len = 0u;
        for (var side = 0u; side < 2u; side = side + 1u) {
            let t_entry = child_entry[side];
            // Also culls the far child when the near leaf produced a closer hit.
            if (!tracer_bvh_is_entered_before(t_entry, closest)) {
                continue;
            }
            if (child_count[side] == 0u) {
                inner_nodes[inner_len] = child_index[side];
                inner_entries[inner_len] = t_entry;
                inner_len = inner_len + 1u;
                continue;
            }
            let first = child_index[side];
            for (var triangle = first; triangle < first + child_count[side]; triangle = triangle + 1u) {
                // A tie with the best hit goes to the lower leaf-order index.
                let hit = tracer_bvh_intersect_triangle(ray, triangle, closest, found && triangle < best_triangle);
                if (hit.found) {
                    found = true;
                    best_triangle = triangle;
                    best_t = hit.t;
                    best_u = hit.u;
                    best_v = hit.v;
                    if (any_hit) {
                        return TracerBvhHit(true, false, best_t * TRACER_BVH_INVERSE_SCALE, best_u, best_v, tracer_bvh_triangle_ids[best_triangle]);
                    }
                    closest = hit.t;
                }
            }
        }
        if (inner_len == 2u) {
            if (stack_len >= TRACER_BVH_MAX_STACK_DEPTH) {
                return TracerBvhHit(false, true, 0.0, 0.0, 0.0, 0u);
            }
            stack_nodes[stack_len] = inner_nodes[1];
            stack_entries[stack_len] = inner_entries[1];
            stack_len = stack_len + 1u;
            node = inner_nodes[0];
        } else if (inner_len == 1u) {
            node = inner_nodes[0];
        } else {
            // Pop until a node that can still hold a closer hit.
            var resumed = false;
            loop {
                if (stack_len == 0u) {
                    break;
                }
                stack_len = stack_len - 1u;
                if (tracer_bvh_is_entered_before(stack_entries[stack_len], closest)) {
                    node = stack_nodes[stack_len];
                    resumed = true;
                    break;
                }
            }
            if (!resumed) {
                break;
            }
        }
    }
    if (!found) {
        return TracerBvhHit(false, false, 0.0, 0.0, 0.0, 0u);
    }
    return TracerBvhHit(true, false, best_t * TRACER_BVH_INVERSE_SCALE, best_u, best_v, tracer_bvh_triangle_ids[best_triangle]);
}
