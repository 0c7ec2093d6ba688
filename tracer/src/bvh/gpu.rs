//! The BVH as the GPU reads it: the same bytes the CPU traverses, as 32-bit
//! words, and the traversal constants the WGSL twin must share with the CPU
//! (`functors/wgsl/bvh.wgsl` mirrors [`Bvh::traverse_axes`] step by step).

use super::{Bvh, BvhChild, BvhNode, BvhTriangle, MAX_STACK_DEPTH, ROBUST_FAR_SCALE};
use std::mem::{offset_of, size_of};

// The WGSL traversal reads a node as four `vec4<f32>` (per child: min and
// index bits, max and count bits) and a triangle as nine `f32`: fail the build
// rather than the GPU if the CPU layout changes.
const _: () = {
    assert!(size_of::<BvhNode>() == 64);
    assert!(size_of::<BvhChild>() == 32);
    assert!(offset_of!(BvhChild, min) == 0);
    assert!(offset_of!(BvhChild, index) == 12);
    assert!(offset_of!(BvhChild, max) == 16);
    assert!(offset_of!(BvhChild, count) == 28);
    assert!(size_of::<BvhTriangle>() == 36);
    assert!(offset_of!(BvhTriangle, v1) == 12);
    assert!(offset_of!(BvhTriangle, v2) == 24);
};

impl Bvh {
    /// The nodes' bytes as words: node `n` is words `16 n .. 16 n + 16`.
    pub fn gpu_node_words(&self) -> Vec<u32> {
        bytemuck::cast_slice(self.nodes()).to_vec()
    }

    /// The leaf-order triangles' bytes as words: triangle `i` is words `9 i .. 9 i + 9`.
    pub fn gpu_triangle_words(&self) -> Vec<u32> {
        bytemuck::cast_slice(self.triangles()).to_vec()
    }

    /// The factor box exit distances are scaled by before the entry test; the
    /// GPU must use the same one to cull the same boxes.
    pub fn gpu_robust_far_scale() -> f32 {
        ROBUST_FAR_SCALE
    }

    /// The traversal stack's capacity (the GPU's is the same, and overflow
    /// is a reported failure there).
    pub fn gpu_max_stack_depth() -> usize {
        MAX_STACK_DEPTH
    }
}
