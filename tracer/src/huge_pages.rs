//! Large build arrays on 2 MiB pages where the kernel offers them.
//!
//! A BVH build writes about 120 bytes a triangle into fresh memory
//! (references and their scratch copy, the triangles in leaf order, the wide
//! tree), an isosurface's welding about 40 a corner, and the first write to
//! each 4 KiB page of fresh memory faults. On this
//! project's 2-core VM a fault cost about 4 µs, so a cold build of the
//! dragon spent about a third of its time faulting (docs/benchmarks.md).
//! Linux backs a range it was advised `MADV_HUGEPAGE` for with 2 MiB pages
//! (when transparent huge pages are set to `madvise` or `always`): one fault
//! for 512 pages. Elsewhere, and where the advice is refused, nothing changes.

/// An empty vector with room for `capacity` elements, its memory advised for
/// huge pages before anything writes it (only when it spans one at least).
pub(crate) fn vec_on_huge_pages<T>(capacity: usize) -> Vec<T> {
    let vector: Vec<T> = Vec::with_capacity(capacity);
    #[cfg(target_os = "linux")]
    advise_huge_pages(
        vector.as_ptr() as usize,
        vector.capacity() * std::mem::size_of::<T>(),
    );
    vector
}

/// The items of a parallel iterator collected, in order, into a vector on huge
/// pages ([`vec_on_huge_pages`]).
pub(crate) fn collect_on_huge_pages<T: Send>(
    items: impl rayon::iter::IndexedParallelIterator<Item = T>,
) -> Vec<T> {
    let mut vector = vec_on_huge_pages(items.len());
    rayon::iter::ParallelExtend::par_extend(&mut vector, items);
    vector
}

#[cfg(target_os = "linux")]
fn advise_huge_pages(start: usize, bytes: usize) {
    const PAGE: usize = 4096;
    const HUGE_PAGE: usize = 2 << 20;
    if bytes < HUGE_PAGE {
        return;
    }
    // madvise takes whole pages.
    let first = start.next_multiple_of(PAGE);
    let end = (start + bytes) / PAGE * PAGE;
    // SAFETY: [first, end) lies inside the vector's own allocation, which no
    // one else references. MADV_HUGEPAGE only changes how the kernel backs
    // the range, never what it holds; if the kernel refuses, nothing changes,
    // so the result is ignored.
    unsafe {
        libc::madvise(first as *mut libc::c_void, end - first, libc::MADV_HUGEPAGE);
    }
}
