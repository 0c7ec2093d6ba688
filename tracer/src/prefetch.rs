//! Software prefetch for the gathers that follow a hit: a shading functor
//! reads a triangle's corners by the triangle id the traversal returned, a
//! chain of dependent loads (id → corner indices → corner data) whose cache
//! misses a loop over rays otherwise takes one after the other.

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
