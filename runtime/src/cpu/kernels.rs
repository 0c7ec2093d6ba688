//! The CPU backend's kernels for the primitives other than `map`: `gather`,
//! `scatter` (plain and combining), `reduce` and `scan`, over the monoids of
//! [`crate::monoid`].
//!
//! Every kernel runs sequentially over the slice it is given. The parallel
//! drivers ([`reduce`], [`scan`], built on [`run_chunked`]) split their input
//! into chunks of a fixed size and combine the chunk results in chunk order, so
//! a result never depends on the number of threads or on scheduling. Integer,
//! `bool`, `min` and `max` results do not depend on the chunk size either;
//! float sums and products do (floating-point `+` and `*` are not associative),
//! which is why the backend uses one fixed chunk size, [`DEFAULT_CHUNK`].
//!
//! Bad user data (an index out of range) is reported as a [`KernelError`], never
//! a panic. A type mismatch between arguments is a plan-compiler bug; it is an
//! error too, but a kernel may have written part of its output by then.

use crate::column::{gather_by_position, Column, ColumnView};
use crate::elem::{
    check_length, check_same_type, typed_element, typed_slice, typed_vec, with_element_type,
    Element, KernelError, PrimitiveElement,
};
use crate::host::HostValue;
use crate::monoid::{combine_elements, identity, unsupported, Monoid, MonoidOp};
use crate::types::{ElemType, RecordRegistry};
use rayon::prelude::*;
use std::ops::Range;
use std::sync::Arc;

/// The number of elements per chunk of the CPU backend. Fixed (rather than
/// derived from the thread count) so that float reductions and scans give the
/// same bits on every machine.
pub const DEFAULT_CHUNK: usize = 4096;

/// Checks the indices that will be used (those where `mask` is true, all
/// without a mask) before anything is read or written, so a bad index leaves
/// the output untouched.
fn check_indices(indices: &[u32], mask: Option<&[bool]>, len: usize) -> Result<(), KernelError> {
    let used = |position: usize| mask.is_none_or(|mask| mask[position]);
    match indices
        .iter()
        .enumerate()
        .find(|&(position, &index)| used(position) && index as usize >= len)
    {
        Some((position, &index)) => Err(KernelError::IndexOutOfRange {
            position,
            index,
            len,
        }),
        None => Ok(()),
    }
}

/// `out[i] = src[indices[i]]`, for every element type, records included.
pub fn gather(indices: &[u32], src: &ColumnView<'_>) -> Result<Column, KernelError> {
    check_indices(indices, None, src.len())?;
    Ok(gather_by_position(src, indices.len(), &|position| {
        indices[position] as usize
    }))
}

/// The argument checks shared by both scatters.
pub(crate) fn check_scatter(
    indices: &[u32],
    src: &ColumnView<'_>,
    mask: Option<&[bool]>,
    dst_type: ElemType,
    dst_len: usize,
) -> Result<(), KernelError> {
    check_length("the scattered array", indices.len(), src.len())?;
    if let Some(mask) = mask {
        check_length("the scatter mask", indices.len(), mask.len())?;
    }
    check_same_type(dst_type, src.elem_type())?;
    check_indices(indices, mask, dst_len)
}

/// `dst[indices[i]] = src[i]` for increasing `i` where `mask[i]`; the
/// indices are already checked.
fn scatter_typed<T: Copy>(indices: &[u32], src: &[T], mask: Option<&[bool]>, dst: &mut [T]) {
    for (position, (&index, &value)) in indices.iter().zip(src).enumerate() {
        if mask.is_none_or(|mask| mask[position]) {
            dst[index as usize] = value;
        }
    }
}

/// `dst[indices[i]] = src[i]` where `mask[i]` (everywhere without a mask), for
/// every element type, records included. Indices where the mask is false are
/// not checked, so a compaction may compute out-of-range indices for the
/// elements it drops. With duplicate indices the last writer wins: the
/// largest `i` among those writing the same slot.
pub fn scatter(
    indices: &[u32],
    src: &ColumnView<'_>,
    mask: Option<&[bool]>,
    dst: &mut Column,
) -> Result<(), KernelError> {
    check_scatter(indices, src, mask, dst.elem_type(), dst.len())?;
    scatter_checked(indices, src, mask, dst)
}

fn scatter_checked(
    indices: &[u32],
    src: &ColumnView<'_>,
    mask: Option<&[bool]>,
    dst: &mut Column,
) -> Result<(), KernelError> {
    if let Column::Record { fields, .. } = dst {
        return fields
            .iter_mut()
            .enumerate()
            .try_for_each(|(index, field)| {
                scatter_checked(indices, src.field(index), mask, Arc::make_mut(field))
            });
    }
    with_element_type!(dst.elem_type(), primitive, T => {
        let src = typed_slice::<T>(src)?;
        scatter_typed(indices, src, mask, typed_vec::<T>(dst)?);
        Ok(())
    }, record => Err(KernelError::TypeMismatch { expected: record, found: src.elem_type() }))
}

/// `dst[indices[i]] = dst[indices[i]] op src[i]` where `mask[i]` (everywhere
/// without a mask), applied in increasing `i`, so even float sums into the same
/// slot are deterministic. Index checks as in [`scatter`].
pub fn scatter_combine(
    op: MonoidOp,
    indices: &[u32],
    src: &ColumnView<'_>,
    mask: Option<&[bool]>,
    dst: &mut Column,
) -> Result<(), KernelError> {
    let part = ScatterPart {
        indices,
        src: src.clone(),
        mask,
    };
    scatter_combine_parts(op, std::slice::from_ref(&part), dst)
}

/// One part of a combining scatter: a stage's chunk of indices, values and mask.
#[derive(Clone)]
pub struct ScatterPart<'a> {
    pub indices: &'a [u32],
    pub src: ColumnView<'a>,
    pub mask: Option<&'a [bool]>,
}

/// Below this many slots a combining scatter runs on one thread.
const SLOTS_PER_SCATTER_TASK: usize = 1 << 16;

/// [`scatter_combine`] of `parts` one after another, as one pass over their
/// concatenation. It runs in parallel over ranges of `dst`: each task combines
/// the values whose slots are in its range, part after part, so each slot
/// sees its values in the same order as in one pass, and the bits do not
/// depend on the number of tasks. A task skips the parts whose indices all
/// lie outside its range: a stage's chunks of rays in Morton order each
/// write a few rows of the image. (One pass on one thread left the other
/// idle for 26 ms of a 920 ms WORKLOAD3 frame, adding 8.3M colours.) Every
/// part's indices are checked before anything is written.
pub fn scatter_combine_parts(
    op: MonoidOp,
    parts: &[ScatterPart<'_>],
    dst: &mut Column,
) -> Result<(), KernelError> {
    let (dst_type, dst_len) = (dst.elem_type(), dst.len());
    // Each part's least and greatest index used (none where all are masked off).
    let bounds = parts
        .par_iter()
        .map(|part| {
            check_scatter(part.indices, &part.src, part.mask, dst_type, dst_len)?;
            Ok(used_index_bounds(part.indices, part.mask))
        })
        .collect::<Result<Vec<_>, KernelError>>()?;
    with_element_type!(dst_type, primitive, T => {
        let monoid = Monoid::<T>::new(op)?;
        let sources = parts
            .iter()
            .map(|part| typed_slice::<T>(&part.src))
            .collect::<Result<Vec<_>, _>>()?;
        let dst = typed_vec::<T>(dst)?;
        // Several ranges per thread, as the parts crowd unevenly.
        let tasks = (4 * rayon::current_num_threads())
            .min(dst_len / SLOTS_PER_SCATTER_TASK)
            .max(1);
        let slots_per_task = dst_len.div_ceil(tasks).max(1);
        dst.par_chunks_mut(slots_per_task)
            .with_max_len(1)
            .enumerate()
            .for_each(|(task, slots)| {
                let first = task * slots_per_task;
                let last = first + slots.len() - 1;
                for ((part, src), bounds) in parts.iter().zip(&sources).zip(&bounds) {
                    if !bounds.is_some_and(|(least, most)| least <= last && most >= first) {
                        continue;
                    }
                    for (position, &index) in part.indices.iter().enumerate() {
                        // Wrapping: a slot below `first` falls far outside.
                        let slot = (index as usize).wrapping_sub(first);
                        if slot < slots.len() && part.mask.is_none_or(|mask| mask[position]) {
                            slots[slot] = monoid.combine(slots[slot], src[position]);
                        }
                    }
                }
            });
        Ok(())
    }, record => Err(unsupported(op, record)))
}

/// The least and greatest of the indices that `mask` keeps (all without one).
fn used_index_bounds(indices: &[u32], mask: Option<&[bool]>) -> Option<(usize, usize)> {
    indices
        .iter()
        .enumerate()
        .filter(|&(position, _)| mask.is_none_or(|mask| mask[position]))
        .fold(None, |bounds, (_, &index)| {
            let index = index as usize;
            Some(
                bounds.map_or((index, index), |(least, most): (usize, usize)| {
                    (least.min(index), most.max(index))
                }),
            )
        })
}

/// Runs `work` over `0..len` cut into consecutive ranges of `chunk` elements
/// (the last one shorter), in parallel, and returns the results in range
/// order. No range for `len == 0`.
pub fn run_chunked<T: Send>(
    len: usize,
    chunk: usize,
    work: impl Fn(Range<usize>) -> T + Sync,
) -> Vec<T> {
    assert!(chunk > 0, "run_chunked needs a positive chunk size");
    (0..len.div_ceil(chunk))
        .into_par_iter()
        // One chunk per task: rayon's adaptive splitting otherwise stops at a
        // few pieces per thread, and a thread done with its half finds nothing
        // to steal while another works through the other half (15 ms idle of
        // a 99 ms WORKLOAD2 frame, whose rows cost unevenly).
        .with_max_len(1)
        .map(|index| {
            let start = index * chunk;
            work(start..len.min(start + chunk))
        })
        .collect()
}

/// Pass 1 of a reduction: the identity combined with every element of `values`
/// (one chunk), left to right.
pub fn reduce_partial(op: MonoidOp, values: &ColumnView<'_>) -> Result<Element, KernelError> {
    with_element_type!(values.elem_type(), primitive, T => {
        let monoid = Monoid::<T>::new(op)?;
        Ok(monoid.fold(monoid.identity, typed_slice::<T>(values)?).into_element())
    }, record => Err(unsupported(op, record)))
}

/// Pass 2 of a reduction: the identity of `op` on `ty` combined with the chunks'
/// partials in chunk order (the identity alone for an empty array).
pub fn combine_partials(
    op: MonoidOp,
    ty: ElemType,
    partials: &[Element],
) -> Result<Element, KernelError> {
    partials
        .iter()
        .try_fold(identity(op, ty)?, |accumulated, &partial| {
            combine_elements(op, accumulated, partial)
        })
}

/// [`combine_partials`] as the host scalar `reduce` returns.
pub fn reduce_to_host(
    op: MonoidOp,
    ty: ElemType,
    partials: &[Element],
) -> Result<HostValue, KernelError> {
    Ok(combine_partials(op, ty, partials)?.to_host())
}

/// `reduce<op>(values)` over chunks of `chunk` elements, in parallel.
pub fn reduce(
    op: MonoidOp,
    values: &ColumnView<'_>,
    chunk: usize,
) -> Result<HostValue, KernelError> {
    let partials = run_chunked(values.len(), chunk, |range| {
        reduce_partial(op, &values.slice(range))
    })
    .into_iter()
    .collect::<Result<Vec<_>, _>>()?;
    reduce_to_host(op, values.elem_type(), &partials)
}

/// What a chunk contributes to the scan of the chunks after it: the standard
/// (flag, value) pair of a segmented scan. `value` combines the chunk's
/// elements from its last segment start on (all of them when no segment starts
/// in it); `starts_segment` says whether one did, which cuts off every carry
/// from earlier chunks. Unsegmented scans have `starts_segment == false`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScanTotal {
    pub starts_segment: bool,
    pub value: Element,
}

fn check_segment_flags(len: usize, segment_starts: Option<&[bool]>) -> Result<(), KernelError> {
    match segment_starts {
        Some(flags) => check_length("the segment flags", len, flags.len()),
        None => Ok(()),
    }
}

/// Pass 1 of a scan: the [`ScanTotal`] of one chunk. `segment_starts` holds
/// the chunk's own flags (`true` at `i` starts a segment at element `i`).
pub fn scan_total(
    op: MonoidOp,
    values: &ColumnView<'_>,
    segment_starts: Option<&[bool]>,
) -> Result<ScanTotal, KernelError> {
    check_segment_flags(values.len(), segment_starts)?;
    let last_start = segment_starts.and_then(|flags| flags.iter().rposition(|&flag| flag));
    let value = with_element_type!(values.elem_type(), primitive, T => {
        let monoid = Monoid::<T>::new(op)?;
        let values = typed_slice::<T>(values)?;
        // A segment restarts with its first element, as `scan_chunk` does, so a
        // carry holds exactly the bits the sequential scan would have.
        match last_start {
            Some(start) => monoid.fold(values[start], &values[start + 1..]),
            None => monoid.fold(monoid.identity, values),
        }
        .into_element()
    }, record => return Err(unsupported(op, record)));
    Ok(ScanTotal {
        starts_segment: last_start.is_some(),
        value,
    })
}

/// The segmented-scan pair operator: `later` after `earlier`. Associative, so
/// chunk totals may be combined in any grouping, but not commutative.
pub fn combine_scan_totals(
    op: MonoidOp,
    earlier: ScanTotal,
    later: ScanTotal,
) -> Result<ScanTotal, KernelError> {
    check_same_type(earlier.value.elem_type(), later.value.elem_type())?;
    if later.starts_segment {
        return Ok(later);
    }
    Ok(ScanTotal {
        starts_segment: earlier.starts_segment,
        value: combine_elements(op, earlier.value, later.value)?,
    })
}

/// Pass 2 of a scan: the exclusive scan of the chunk totals, i.e. the carry
/// into each chunk (the identity for the first), computed sequentially in
/// chunk order.
pub fn scan_carries(
    op: MonoidOp,
    ty: ElemType,
    totals: &[ScanTotal],
) -> Result<Vec<Element>, KernelError> {
    let mut running = ScanTotal {
        starts_segment: false,
        value: identity(op, ty)?,
    };
    totals
        .iter()
        .map(|&total| {
            let carry = running.value;
            running = combine_scan_totals(op, running, total)?;
            Ok(carry)
        })
        .collect()
}

/// Pass 3 of a scan: scans one chunk starting from `carry_in`.
///
/// Inclusive: `out[i] = carry_in op values[0] op … op values[i]`; exclusive:
/// the same without `values[i]`. With `segment_starts`, a `true` flag at `i`
/// restarts the scan: an inclusive scan restarts with `values[i]`, an
/// exclusive one with the identity at `i`; the carry only reaches the elements
/// before the chunk's first segment start.
pub fn scan_chunk(
    op: MonoidOp,
    values: &ColumnView<'_>,
    inclusive: bool,
    carry_in: Element,
    segment_starts: Option<&[bool]>,
) -> Result<Column, KernelError> {
    check_segment_flags(values.len(), segment_starts)?;
    with_element_type!(values.elem_type(), primitive, T => {
        let monoid = Monoid::<T>::new(op)?;
        let values = typed_slice::<T>(values)?;
        let mut running = typed_element::<T>(carry_in)?;
        let scanned = values.iter().enumerate().map(|(position, &value)| {
            let restarts = segment_starts.is_some_and(|flags| flags[position]);
            let before = if restarts { monoid.identity } else { running };
            running = if restarts { value } else { monoid.combine(running, value) };
            if inclusive { running } else { before }
        });
        Ok(T::into_column(scanned.collect()))
    }, record => Err(unsupported(op, record)))
}

/// `scan<op>(values)` (or `exclusiveScan` when `!inclusive`), optionally
/// segmented, in the three passes over chunks of `chunk` elements: totals in
/// parallel, carries sequentially, rescans in parallel.
pub fn scan(
    op: MonoidOp,
    values: &ColumnView<'_>,
    inclusive: bool,
    segment_starts: Option<&[bool]>,
    chunk: usize,
) -> Result<Column, KernelError> {
    check_segment_flags(values.len(), segment_starts)?;
    let chunk_flags = |range: &Range<usize>| segment_starts.map(|flags| &flags[range.clone()]);
    let totals = run_chunked(values.len(), chunk, |range| {
        scan_total(op, &values.slice(range.clone()), chunk_flags(&range))
    })
    .into_iter()
    .collect::<Result<Vec<_>, _>>()?;
    let carries = scan_carries(op, values.elem_type(), &totals)?;
    let chunks = run_chunked(values.len(), chunk, |range| {
        let carry_in = carries[range.start / chunk];
        scan_chunk(
            op,
            &values.slice(range.clone()),
            inclusive,
            carry_in,
            chunk_flags(&range),
        )
    })
    .into_iter()
    .collect::<Result<Vec<_>, _>>()?;
    // Scan results are never records, so concatenating them consults no record types.
    Ok(Column::concat(
        values.elem_type(),
        &chunks,
        &RecordRegistry::default(),
    ))
}
