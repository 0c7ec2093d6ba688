//! A plain scatter done inside its stage's chunks, in parallel, with the
//! sequential kernel's result: the last writer of a slot wins. The same
//! shared target takes the values a stage materialises, each chunk writing
//! its own range.
//!
//! Every target slot is owned by the first chunk that claims it. A chunk
//! writes the slots it owns straight into the target, so no two threads write
//! one slot. A chunk's writes to slots another chunk owns are kept aside and
//! applied after the stage, in chunk order, where the writer comes after the
//! owner (otherwise the owner's value is the later one and stands). When the
//! indices are a permutation (a tracer's pixel indices) nothing is kept aside:
//! the stage keeps no copy of the values it scatters.
//!
//! Claims are one bit per slot, set a machine word at a time: a chunk of
//! coherent indices (a Morton-ordered tile of pixels) claims up to 64 slots
//! with one atomic. Scatters of one stage with the same indices and mask into
//! targets of the same length share their claims.

use super::kernels::scatter;
use crate::column::{Column, ColumnView};
use crate::elem::{
    check_length, check_same_type, typed_slice, with_element_type, KernelError, PrimitiveElement,
};
use crate::types::ElemType;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// Which slots of the targets of a group of scatters are claimed.
pub struct ScatterClaims {
    target_len: usize,
    /// One bit per slot.
    claimed: Vec<AtomicU64>,
}

/// Bitmap words a chunk may span, per element, to be claimed word by word.
const DENSE_WORDS_PER_ELEMENT: usize = 4;

/// What one chunk claimed.
pub struct Claimed {
    /// Positions (in the chunk, in order) whose slots it owns; `None` when it
    /// owns the slots of every position its mask keeps.
    own: Option<Vec<u32>>,
    /// Positions whose slots another chunk owns.
    aside: Vec<u32>,
    /// The slots it won, as bitmap words and bits.
    won: Vec<(usize, u64)>,
}

impl Claimed {
    /// Whether the chunk has writes to apply after the stage.
    pub fn kept_aside(&self) -> bool {
        !self.aside.is_empty()
    }
}

impl ScatterClaims {
    pub fn new(target_len: usize) -> ScatterClaims {
        ScatterClaims {
            target_len,
            claimed: (0..target_len.div_ceil(64))
                .map(|_| AtomicU64::new(0))
                .collect(),
        }
    }

    /// Claims the slots a chunk writes, checking the indices as the
    /// sequential kernel does.
    pub fn claim(&self, indices: &[u32], mask: Option<&[bool]>) -> Result<Claimed, KernelError> {
        if let Some(mask) = mask {
            check_length("the scatter mask", indices.len(), mask.len())?;
        }
        let used = |position: usize| mask.is_none_or(|mask| mask[position]);
        let target_len = self.target_len;
        // The range first, in a loop without exits (which vectorises), and
        // the position of a bad index only if there is one.
        let (lowest, highest) = match mask {
            None => indices.iter().fold((u32::MAX, 0), |(low, high), &index| {
                (low.min(index), high.max(index))
            }),
            Some(mask) => {
                indices
                    .iter()
                    .zip(mask)
                    .fold((u32::MAX, 0), |(low, high), (&index, &used)| {
                        let (for_low, for_high) = if used { (index, index) } else { (u32::MAX, 0) };
                        (low.min(for_low), high.max(for_high))
                    })
            }
        };
        if lowest <= highest && highest as usize >= target_len {
            let position = (0..indices.len())
                .find(|&position| used(position) && indices[position] as usize >= target_len)
                .expect("the highest index is out of range");
            return Err(KernelError::IndexOutOfRange {
                position,
                index: indices[position],
                len: target_len,
            });
        }
        let mut claimed = Claimed {
            own: None,
            aside: Vec::new(),
            won: Vec::new(),
        };
        if lowest > highest {
            return Ok(claimed);
        }
        let bit = |index: u32| 1u64 << (index % 64);
        let word = |index: u32| index as usize / 64;
        let first_word = word(lowest);
        let words = word(highest) + 1 - first_word;
        if words > DENSE_WORDS_PER_ELEMENT * indices.len() {
            // Scattered indices: a word per element.
            let mut own = Vec::with_capacity(indices.len());
            let mut won = std::collections::HashSet::new();
            for (position, &index) in indices.iter().enumerate() {
                if !used(position) {
                    continue;
                }
                let before = self.claimed[word(index)].fetch_or(bit(index), Ordering::Relaxed);
                if before & bit(index) == 0 {
                    won.insert(index);
                    claimed.won.push((word(index), bit(index)));
                }
                if won.contains(&index) {
                    own.push(position as u32);
                } else {
                    claimed.aside.push(position as u32);
                }
            }
            claimed.own = Some(own);
            return Ok(claimed);
        }
        // The chunk's bits, a word per 64 slots from `first_word` on, and the
        // words it has bits in (a tile of pixels spans many words of rows it
        // does not touch).
        let mut wanted = vec![0u64; words];
        let mut touched = Vec::new();
        for (position, &index) in indices.iter().enumerate() {
            if used(position) {
                let offset = word(index) - first_word;
                if wanted[offset] == 0 {
                    touched.push(offset);
                }
                wanted[offset] |= bit(index);
            }
        }
        let mut all_won = true;
        // From here on `won` holds the bits the chunk won.
        let mut won = wanted;
        for &offset in &touched {
            let bits = won[offset];
            let before = self.claimed[first_word + offset].fetch_or(bits, Ordering::Relaxed);
            all_won &= before & bits == 0;
            won[offset] = bits & !before;
        }
        claimed.won = touched
            .iter()
            .filter(|&&offset| won[offset] != 0)
            .map(|&offset| (first_word + offset, won[offset]))
            .collect();
        if !all_won {
            let mut own = Vec::with_capacity(indices.len());
            for (position, &index) in indices.iter().enumerate() {
                if !used(position) {
                    continue;
                }
                if won[word(index) - first_word] & bit(index) != 0 {
                    own.push(position as u32);
                } else {
                    claimed.aside.push(position as u32);
                }
            }
            claimed.own = Some(own);
        }
        Ok(claimed)
    }
}

impl ScatterClaims {
    /// Sets every slot of `column` that no chunk claimed to zero (the default
    /// of its type), in parallel: a scatter's `len:` target starts as zeros,
    /// and the slots its chunks claimed were all written, so only the others
    /// need clearing. A scatter of a tracer's pixels claims every slot and
    /// clears nothing.
    pub fn zero_unclaimed(&self, column: &mut Column) {
        fn zero<T: Copy + Default + Send>(values: &mut [T], claimed: &[AtomicU64]) {
            // Whole bitmap words per part, so that parts own their slots.
            const WORDS_PER_PART: usize = 1 << 10;
            values
                .par_chunks_mut(64 * WORDS_PER_PART)
                .zip(claimed.par_chunks(WORDS_PER_PART))
                .for_each(|(part, words)| {
                    for (slots, word) in part.chunks_mut(64).zip(words) {
                        let mut unclaimed = !word.load(Ordering::Relaxed);
                        if unclaimed == u64::MAX {
                            slots.fill(T::default());
                            continue;
                        }
                        while unclaimed != 0 {
                            let bit = unclaimed.trailing_zeros() as usize;
                            if let Some(slot) = slots.get_mut(bit) {
                                *slot = T::default();
                            }
                            unclaimed &= unclaimed - 1;
                        }
                    }
                });
        }
        debug_assert_eq!(column.len(), self.target_len);
        crate::for_each_primitive!(Column, column, v => zero(v, &self.claimed), Column::Record { fields, .. } => {
            for field in fields {
                self.zero_unclaimed(Arc::make_mut(field));
            }
        })
    }
}

/// The chunk that owns each slot, for applying the writes kept aside: built
/// after the stage, and only when some chunk kept writes aside.
pub struct Owners {
    /// 1 + the first position of the owning chunk (0: no chunk wrote the slot).
    owner: Vec<u32>,
}

impl Owners {
    /// From every chunk's claims, with the chunk's first position.
    pub fn new<'c>(
        target_len: usize,
        chunks: impl Iterator<Item = (usize, &'c Claimed)>,
    ) -> Owners {
        let mut owner = vec![0u32; target_len];
        for (chunk_start, claimed) in chunks {
            for &(word, bits) in &claimed.won {
                let mut bits = bits;
                while bits != 0 {
                    owner[word * 64 + bits.trailing_zeros() as usize] = chunk_start as u32 + 1;
                    bits &= bits - 1;
                }
            }
        }
        Owners { owner }
    }

    /// Writes the values the chunk starting at `chunk_start` kept aside, where
    /// it comes after the slot's owner (so that its value is the later one).
    pub fn apply_aside(
        &self,
        chunk_start: usize,
        claimed: &Claimed,
        indices: &[u32],
        values: &ColumnView<'_>,
        dst: &mut Column,
    ) -> Result<(), KernelError> {
        let mut mask = vec![false; indices.len()];
        for &position in &claimed.aside {
            let slot = indices[position as usize] as usize;
            mask[position as usize] = chunk_start as u32 + 1 > self.owner[slot];
        }
        scatter(indices, values, Some(&mask), dst)
    }
}

/// An array written by many chunks at once, each only at slots no other chunk
/// writes: the target of a plain scatter (the slots a chunk owns), or a value
/// its stage materialises (the chunk's own range).
pub struct SharedTarget {
    target: Column,
    len: usize,
    /// Base pointer of each primitive leaf of the target (its fields, in order,
    /// for a record), with the leaf's type.
    leaves: Vec<(ElemType, *mut u8)>,
}

// The leaves are written only at slots the writing chunk owns (see
// `ScatterClaims`) or in its own range, so no two threads write one element.
unsafe impl Sync for SharedTarget {}
unsafe impl Send for SharedTarget {}

impl SharedTarget {
    pub fn new(mut target: Column) -> SharedTarget {
        let mut leaves = Vec::new();
        collect_leaves(&mut target, &mut leaves);
        let len = target.len();
        SharedTarget {
            target,
            len,
            leaves,
        }
    }

    pub fn elem_type(&self) -> ElemType {
        self.target.elem_type()
    }

    /// Writes `src[p]` at `indices[p]` for the positions `p` the chunk owns
    /// (`claimed` comes from these indices and mask, which it checked).
    pub fn write(
        &self,
        claimed: &Claimed,
        indices: &[u32],
        mask: Option<&[bool]>,
        src: &ColumnView<'_>,
    ) -> Result<(), KernelError> {
        check_length("the scattered array", indices.len(), src.len())?;
        check_same_type(self.elem_type(), src.elem_type())?;
        let mut leaves = self.leaves.iter();
        match &claimed.own {
            Some(own) => write_leaves(&mut leaves, own.iter().map(|&p| p as usize), indices, src),
            None => {
                let used = |p: &usize| mask.is_none_or(|mask| mask[*p]);
                write_leaves(&mut leaves, (0..indices.len()).filter(used), indices, src)
            }
        }
    }

    /// Copies `src` to the slots `start .. start + src.len()`, which no other
    /// chunk writes (a chunk's own range of its stage).
    pub fn write_range(&self, start: usize, src: &ColumnView<'_>) -> Result<(), KernelError> {
        check_same_type(self.elem_type(), src.elem_type())?;
        let end = start + src.len();
        if end > self.len {
            return Err(KernelError::LengthMismatch {
                what: "the array a chunk writes its range of",
                expected: end,
                found: self.len,
            });
        }
        copy_leaves(&mut self.leaves.iter(), start, src)
    }

    pub fn into_column(self) -> Column {
        self.target
    }
}

fn collect_leaves(column: &mut Column, leaves: &mut Vec<(ElemType, *mut u8)>) {
    if let Column::Record { fields, .. } = column {
        for field in fields {
            collect_leaves(Arc::make_mut(field), leaves);
        }
        return;
    }
    let ty = column.elem_type();
    let pointer = with_element_type!(ty, primitive, T => {
        T::vec_of(column).expect("the column's own type").as_mut_ptr().cast::<u8>()
    }, _ => unreachable!("records are split into fields"));
    leaves.push((ty, pointer));
}

fn write_leaves<'l>(
    leaves: &mut impl Iterator<Item = &'l (ElemType, *mut u8)>,
    own: impl Iterator<Item = usize> + Clone,
    indices: &[u32],
    src: &ColumnView<'_>,
) -> Result<(), KernelError> {
    if let ColumnView::Record { fields, .. } = src {
        return fields
            .iter()
            .try_for_each(|field| write_leaves(leaves, own.clone(), indices, field));
    }
    let &(ty, pointer) = leaves.next().expect("one leaf per field");
    with_element_type!(ty, primitive, T => {
        let src = typed_slice::<T>(src)?;
        let pointer = pointer.cast::<T>();
        for position in own {
            // SAFETY: `indices[position]` was checked against the target's
            // length, and this chunk owns that slot (no other thread writes it).
            unsafe { pointer.add(indices[position] as usize).write(src[position]) };
        }
        Ok(())
    }, _ => unreachable!("records are split into fields"))
}

fn copy_leaves<'l>(
    leaves: &mut impl Iterator<Item = &'l (ElemType, *mut u8)>,
    start: usize,
    src: &ColumnView<'_>,
) -> Result<(), KernelError> {
    if let ColumnView::Record { fields, .. } = src {
        return fields
            .iter()
            .try_for_each(|field| copy_leaves(leaves, start, field));
    }
    let &(ty, pointer) = leaves.next().expect("one leaf per field");
    with_element_type!(ty, primitive, T => {
        let src = typed_slice::<T>(src)?;
        // SAFETY: `start + src.len()` was checked against the target's length,
        // and no other thread writes this range.
        unsafe {
            std::ptr::copy_nonoverlapping(src.as_ptr(), pointer.cast::<T>().add(start), src.len())
        };
        Ok(())
    }, _ => unreachable!("records are split into fields"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Chunks of `indices` claimed and written in parallel, then the writes
    /// kept aside applied: the sequential kernel's result, bit for bit.
    fn check(indices: &[u32], mask: Option<&[bool]>, target_len: usize, chunk: usize) {
        let values = Column::U32((0..indices.len() as u32).map(|v| v + 1000).collect());
        let mut expected = Column::U32(vec![7; target_len]);
        scatter(indices, &values.view(), mask, &mut expected).unwrap();

        let claims = ScatterClaims::new(target_len);
        let target = SharedTarget::new(Column::U32(vec![7; target_len]));
        let starts: Vec<usize> = (0..indices.len()).step_by(chunk).collect();
        let chunk_of = |start: usize| start..(start + chunk).min(indices.len());
        let claimed: Vec<Claimed> = starts
            .par_iter()
            .map(|&start| {
                let range = chunk_of(start);
                let mask = mask.map(|m| &m[range.clone()]);
                let claimed = claims.claim(&indices[range.clone()], mask).unwrap();
                let values = values.slice(range.clone());
                target
                    .write(&claimed, &indices[range], mask, &values)
                    .unwrap();
                claimed
            })
            .collect();
        let owners = Owners::new(target_len, starts.iter().copied().zip(&claimed));
        let mut dst = target.into_column();
        for (&start, claimed) in starts.iter().zip(&claimed) {
            let range = chunk_of(start);
            let values = values.slice(range.clone());
            owners
                .apply_aside(start, claimed, &indices[range], &values, &mut dst)
                .unwrap();
        }
        assert_eq!(dst, expected, "indices {indices:?}");
    }

    /// A small deterministic generator (the tests need no crate for it).
    fn numbers(seed: u64, count: usize, below: u32) -> Vec<u32> {
        let mut state = seed;
        (0..count)
            .map(|_| {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((state >> 33) % u64::from(below)) as u32
            })
            .collect()
    }

    #[test]
    fn a_permutation_is_written_in_place() {
        let mut permutation: Vec<u32> = (0..1000).rev().collect();
        permutation.rotate_left(37);
        check(&permutation, None, 1000, 64);
    }

    #[test]
    fn collisions_across_chunks_keep_the_last_writer() {
        for (seed, slots) in [(1, 3), (2, 50), (3, 700)] {
            check(&numbers(seed, 2000, slots), None, slots as usize, 16);
        }
    }

    #[test]
    fn scattered_indices_into_a_large_target_claim_slot_by_slot() {
        // Far more words than elements: the sparse path, collisions included.
        let mut indices = numbers(4, 600, 1 << 20);
        indices.extend(numbers(4, 300, 1 << 20));
        check(&indices, None, 1 << 20, 32);
    }

    #[test]
    fn masked_positions_neither_write_nor_claim() {
        let indices = numbers(5, 1500, 40);
        let mask: Vec<bool> = numbers(6, 1500, 3).iter().map(|&n| n != 0).collect();
        check(&indices, Some(&mask), 40, 16);
    }

    #[test]
    fn only_the_slots_no_chunk_claimed_are_cleared() {
        // More slots than one part of the clearing (64 Ki), and not a whole
        // number of words; claimed in dense and in sparse chunks.
        let target_len = (1 << 17) + 37;
        let claims = ScatterClaims::new(target_len);
        let dense: Vec<u32> = (1000..5000).chain(70_000..70_100).collect();
        let sparse = numbers(7, 300, target_len as u32);
        for indices in [&dense, &sparse] {
            claims.claim(indices, None).unwrap();
        }
        let last = target_len as u32 - 1;
        claims.claim(&[last], None).unwrap();
        let mut column = Column::U32(vec![9; target_len]);
        claims.zero_unclaimed(&mut column);
        let claimed: std::collections::HashSet<u32> =
            dense.iter().chain(&sparse).copied().chain([last]).collect();
        let Column::U32(values) = column else {
            unreachable!()
        };
        for (slot, &value) in values.iter().enumerate() {
            let expected = if claimed.contains(&(slot as u32)) {
                9
            } else {
                0
            };
            assert_eq!(value, expected, "slot {slot}");
        }
    }

    #[test]
    fn chunks_writing_their_ranges_in_parallel_make_the_whole_record_array() {
        use crate::types::{RecordRegistry, RecordType};
        let mut records = RecordRegistry::default();
        let ty = records.register(RecordType {
            name: "Pair".into(),
            fields: vec![("id".into(), ElemType::U32), ("on".into(), ElemType::Bool)],
            doc: String::new(),
        });
        let len = 1000;
        let whole = Column::Record {
            ty,
            fields: vec![
                Arc::new(Column::U32((0..len as u32).map(|v| v * 3).collect())),
                Arc::new(Column::Bool((0..len).map(|v| v % 7 == 0).collect())),
            ],
        };
        let target = SharedTarget::new(Column::zeroed(ElemType::Record(ty), len, &records));
        (0..len).into_par_iter().step_by(64).for_each(|start| {
            let range = start..(start + 64).min(len);
            target.write_range(start, &whole.slice(range)).unwrap();
        });
        assert_eq!(target.into_column(), whole);
    }

    #[test]
    fn a_range_past_the_end_or_of_another_type_is_an_error() {
        let target = SharedTarget::new(Column::U32(vec![0; 4]));
        let error = target
            .write_range(2, &Column::U32(vec![1, 2, 3]).view())
            .unwrap_err();
        assert_eq!(
            error.to_string(),
            "the array a chunk writes its range of has length 4, expected 5"
        );
        assert!(target
            .write_range(0, &Column::F32(vec![1.0]).view())
            .is_err());
        assert_eq!(target.into_column(), Column::U32(vec![0; 4]));
    }

    #[test]
    fn an_index_out_of_range_is_reported_as_the_sequential_kernel_does() {
        let claims = ScatterClaims::new(4);
        let error = claims.claim(&[1, 9, 2], None).err().unwrap();
        assert_eq!(
            error.to_string(),
            "index 9 (at position 1) is out of range for an array of length 4"
        );
        // A masked-off index is not checked.
        assert!(claims.claim(&[1, 9], Some(&[true, false])).is_ok());
    }
}
