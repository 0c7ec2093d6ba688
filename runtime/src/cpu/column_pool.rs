//! Large arrays that runs let go of, kept for the next arrays of their type.
//!
//! A fresh large allocation comes from the kernel as unmapped pages, and the
//! first write to each 4 KiB page faults and clears it; freeing it unmaps it
//! again. WORKLOAD3 allocates about 3 GB of arrays a frame (the hits, shading
//! points and rays of every bounce), and those faults were about a quarter of
//! its CPU time. Arrays from the pool are already mapped: an array whose every
//! element the stage writes takes one as it is, and a zeroed one is cleared on
//! every thread, which is cheaper than faulting the pages in.
//!
//! Only arrays nothing else holds come back (a shared `Arc` is left to its
//! other owners), so a reused array is never visible through an old handle.

use crate::column::Column;
use crate::types::{ElemType, RecordRegistry};
use rayon::prelude::*;
use std::sync::{Arc, Mutex};

/// Arrays smaller than this are left to the allocator, which keeps them mapped.
const POOL_MIN_BYTES: usize = 1 << 20;

/// The most memory the pool keeps; arrays beyond it are freed.
const POOL_MAX_BYTES: usize = 4 << 30;

/// A kept array serves a request only if its capacity is at most this many
/// times the requested length, so that a small array does not hold a large
/// one's memory.
const MOST_CAPACITY_PER_ELEMENT: usize = 2;

/// What a taken array must hold before the stage writes it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Contents {
    /// All zeros: a scatter's target, whose unwritten slots stay zero.
    Zeroed,
    /// Anything: every element is written before anything reads it.
    Overwritten,
}

/// Kept arrays, by element type; shared by every run that gets the same pool.
#[derive(Debug)]
pub struct ColumnPool {
    free: Mutex<PoolState>,
    /// Arrays smaller than this are not kept.
    least_bytes: usize,
}

#[derive(Debug, Default)]
struct PoolState {
    /// Primitive columns only: a record's fields are kept one by one.
    columns: Vec<Column>,
    bytes: usize,
    /// How many columns have been taken from the pool.
    reused: usize,
}

impl Default for ColumnPool {
    fn default() -> ColumnPool {
        ColumnPool::new()
    }
}

impl ColumnPool {
    pub fn new() -> ColumnPool {
        ColumnPool {
            free: Mutex::default(),
            least_bytes: POOL_MIN_BYTES,
        }
    }

    /// A pool that keeps arrays of every size, so that a test's small
    /// arrays take the same path as a frame's large ones.
    pub fn keeping_every_size() -> ColumnPool {
        ColumnPool {
            free: Mutex::default(),
            least_bytes: 0,
        }
    }

    /// An array of `len` elements of `ty`, with `contents` as asked.
    pub fn take(
        &self,
        ty: ElemType,
        len: usize,
        contents: Contents,
        records: &RecordRegistry,
    ) -> Column {
        match ty {
            ElemType::Record(id) => Column::record_with(id, records, |field| {
                self.take(field, len, contents, records)
            }),
            primitive => match self.kept(primitive, len) {
                Some(mut column) => {
                    resize_to(&mut column, len);
                    if contents == Contents::Zeroed {
                        zero_in_parallel(&mut column);
                    }
                    column
                }
                // Fresh zero pages: zeroed either way, cleared only when touched.
                None => Column::zeroed(primitive, len, records),
            },
        }
    }

    /// Keeps `array` (its fields, for a record) if nothing else holds it.
    pub fn give(&self, array: Arc<Column>) {
        let Ok(column) = Arc::try_unwrap(array) else {
            return;
        };
        match column {
            Column::Record { fields, .. } => fields.into_iter().for_each(|f| self.give(f)),
            primitive => {
                let bytes = capacity_bytes(&primitive);
                if bytes == 0 || bytes < self.least_bytes {
                    return;
                }
                let mut state = self.free.lock().unwrap_or_else(|e| e.into_inner());
                if state.bytes + bytes <= POOL_MAX_BYTES {
                    state.bytes += bytes;
                    state.columns.push(primitive);
                }
            }
        }
    }

    /// The bytes the pool keeps now.
    pub fn kept_bytes(&self) -> usize {
        self.free.lock().unwrap_or_else(|e| e.into_inner()).bytes
    }

    /// How many columns have been taken from the pool so far.
    pub fn reused(&self) -> usize {
        self.free.lock().unwrap_or_else(|e| e.into_inner()).reused
    }

    /// The smallest kept column of `ty` that holds `len` elements without
    /// wasting most of itself.
    fn kept(&self, ty: ElemType, len: usize) -> Option<Column> {
        let mut state = self.free.lock().unwrap_or_else(|e| e.into_inner());
        let (position, _) = state
            .columns
            .iter()
            .enumerate()
            .filter(|(_, column)| column.elem_type() == ty)
            .map(|(position, column)| (position, capacity(column)))
            .filter(|(_, capacity)| {
                (len..=len.saturating_mul(MOST_CAPACITY_PER_ELEMENT)).contains(capacity)
            })
            .min_by_key(|(_, capacity)| *capacity)?;
        let column = state.columns.swap_remove(position);
        state.bytes -= capacity_bytes(&column);
        state.reused += 1;
        Some(column)
    }
}

fn capacity(column: &Column) -> usize {
    crate::for_each_primitive!(Column, column, v => v.capacity(), Column::Record { .. } => 0)
}

fn capacity_bytes(column: &Column) -> usize {
    fn bytes<T>(values: &Vec<T>) -> usize {
        values.capacity() * std::mem::size_of::<T>()
    }
    crate::for_each_primitive!(Column, column, v => bytes(v), Column::Record { .. } => 0)
}

/// `len` elements, within the column's capacity: new ones are zero.
fn resize_to(column: &mut Column, len: usize) {
    crate::for_each_primitive!(Column, column, v => v.resize(len, Default::default()), Column::Record { .. } => unreachable!("the pool keeps primitive columns"))
}

fn zero_in_parallel(column: &mut Column) {
    fn zero<T: Copy + Default + Send>(values: &mut [T]) {
        values
            .par_chunks_mut(1 << 16)
            .for_each(|part| part.fill(T::default()));
    }
    crate::for_each_primitive!(Column, column, v => zero(v), Column::Record { .. } => unreachable!("the pool keeps primitive columns"))
}

#[cfg(test)]
mod tests {
    use super::*;

    const BIG: usize = POOL_MIN_BYTES; // f32 elements: four times the least kept size

    #[test]
    fn a_given_array_is_taken_again_and_zeroed_when_asked() {
        let pool = ColumnPool::new();
        let records = RecordRegistry::default();
        let array = Arc::new(Column::F32(vec![7.0; BIG]));
        let address = array.view().as_f32().as_ptr();
        pool.give(array);
        assert_eq!(pool.kept_bytes(), BIG * 4);

        let stale = pool.take(ElemType::F32, BIG - 5, Contents::Overwritten, &records);
        assert_eq!(stale.view().as_f32().as_ptr(), address, "the same memory");
        assert_eq!(stale.len(), BIG - 5);
        assert_eq!(pool.kept_bytes(), 0);

        pool.give(Arc::new(stale));
        let zeroed = pool.take(ElemType::F32, BIG, Contents::Zeroed, &records);
        assert_eq!(zeroed.view().as_f32().as_ptr(), address);
        assert!(zeroed.view().as_f32().iter().all(|x| *x == 0.0));
    }

    #[test]
    fn shared_small_mistyped_and_much_larger_arrays_are_not_used() {
        let pool = ColumnPool::new();
        let records = RecordRegistry::default();
        let shared = Arc::new(Column::F32(vec![1.0; BIG]));
        pool.give(shared.clone());
        pool.give(Arc::new(Column::F32(vec![1.0; 16])));
        assert_eq!(
            pool.kept_bytes(),
            0,
            "a held array and a small one are not kept"
        );

        pool.give(Arc::new(Column::U32(vec![1; BIG])));
        let floats = pool.take(ElemType::F32, BIG, Contents::Overwritten, &records);
        assert!(
            floats.view().as_f32().iter().all(|x| *x == 0.0),
            "fresh, not the u32s"
        );
        let quarter = pool.take(ElemType::U32, BIG / 4, Contents::Overwritten, &records);
        assert!(
            quarter.view().as_u32().iter().all(|x| *x == 0),
            "too small for the kept one"
        );
        assert_eq!(pool.kept_bytes(), BIG * 4, "the u32 array is still kept");
    }
}
