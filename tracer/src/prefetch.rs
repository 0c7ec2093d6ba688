//! Software prefetch for the gathers that follow a hit: a shading functor
//! reads a triangle's corners by the triangle id the traversal returned, a
//! chain of dependent loads (id → corner indices → corner data) whose cache
//! misses a loop over rays otherwise takes one after the other.

/// How many hits ahead [`prefetch_hit_ahead`] fetches a hit triangle's corners
/// (and twice that far, its corner indices).
const TRIANGLE_AHEAD: usize = 8;

/// For a loop over hits at `index`: fetches the corner indices of the triangle
/// hit `2 * TRIANGLE_AHEAD` hits on, and hands `fetch` the triangle hit
/// `TRIANGLE_AHEAD` on with its corners, whose indices are in cache by then,
/// so that the loop does not wait on each hit's chain of misses.
/// `live_prim(i)` is the triangle hit `i` names, if it is to be shaded (none
/// past the end); a triangle the mesh lacks is skipped.
#[inline(always)]
pub fn prefetch_hit_ahead(
    index: usize,
    live_prim: impl Fn(usize) -> Option<usize>,
    triangles: &[[u32; 3]],
    fetch: impl FnOnce(usize, [usize; 3]),
) {
    if let Some(prim) = live_prim(index + 2 * TRIANGLE_AHEAD) {
        prefetch(triangles, prim);
    }
    if let Some(prim) = live_prim(index + TRIANGLE_AHEAD) {
        if let Some(corners) = triangles.get(prim) {
            fetch(prim, corners.map(|vertex| vertex as usize));
        }
    }
}

/// Asks the CPU to bring `values[index]` into its caches; nothing if `index`
/// is out of range or the target has no prefetch instruction.
#[inline(always)]
pub fn prefetch<T>(values: &[T], index: usize) {
    #[cfg(target_arch = "x86_64")]
    if let Some(value) = values.get(index) {
        // SAFETY: `_mm_prefetch` is a hint that never faults; SSE is part of
        // the x86-64 baseline.
        unsafe {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            _mm_prefetch::<_MM_HINT_T0>((value as *const T).cast::<i8>());
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (values, index);
}
