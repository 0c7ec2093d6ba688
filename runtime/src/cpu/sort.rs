//! `sort` and `sortByKey` on the CPU (docs/language.md §3, sort).
//!
//! Each key becomes one `u64`: its bits mapped so that unsigned order is
//! the keys' order ([`order_bits`]) above its position. Every such word is
//! distinct, so sorting them (unstable or not, in any number of threads)
//! gives one result, the stable order; the sorted keys come back from the
//! high halves, and the positions in the low halves are the permutation that
//! moves the values.

use super::shared_scatter::SharedTarget;
use crate::column::{gather_by_position, Column, ColumnView};
use crate::elem::{check_length, KernelError};
use crate::types::ElemType;
use rayon::prelude::*;

/// Elements per task when the sorted keys and values are written out.
const COPY_BLOCK: usize = 1 << 16;

/// `key`'s bits, mapped so that comparing them as unsigned integers orders
/// the keys: `u32` as it is, `i32` with its sign bit flipped, `f32` with its
/// sign bit flipped when positive and every bit flipped when negative, which
/// is the total order -NaN < -inf < … < -0 < +0 < … < +inf < +NaN.
pub fn order_bits(ty: ElemType, bits: u32) -> u32 {
    match ty {
        ElemType::I32 => bits ^ 0x8000_0000,
        ElemType::F32 if bits & 0x8000_0000 != 0 => !bits,
        ElemType::F32 => bits ^ 0x8000_0000,
        _ => bits,
    }
}

/// The inverse of [`order_bits`].
fn key_bits(ty: ElemType, ordered: u32) -> u32 {
    match ty {
        ElemType::I32 => ordered ^ 0x8000_0000,
        ElemType::F32 if ordered & 0x8000_0000 == 0 => !ordered,
        ElemType::F32 => ordered ^ 0x8000_0000,
        _ => ordered,
    }
}

/// The raw bits of a key array of `u32`, `i32` or `f32`.
fn raw_bits<'a>(keys: &ColumnView<'a>) -> Result<&'a [u32], KernelError> {
    Ok(match keys {
        ColumnView::U32(values) => values,
        ColumnView::I32(values) => bytemuck::cast_slice(values),
        ColumnView::F32(values) => bytemuck::cast_slice(values),
        other => {
            return Err(KernelError::TypeMismatch {
                expected: ElemType::U32,
                found: other.elem_type(),
            })
        }
    })
}

/// The keys of one sort, in their stable ascending order.
pub struct SortedOrder {
    key_type: ElemType,
    /// Ordered key bits above original positions, ascending.
    words: Vec<u64>,
}

impl SortedOrder {
    /// Sorts the keys given as consecutive parts (a stage's chunks, in order).
    pub fn new(key_type: ElemType, parts: &[ColumnView<'_>]) -> Result<SortedOrder, KernelError> {
        let len = parts.iter().map(ColumnView::len).sum();
        let mut words = vec![0u64; len];
        let mut part_words = Vec::with_capacity(parts.len());
        let (mut rest, mut first) = (words.as_mut_slice(), 0usize);
        for part in parts {
            let (these, after) = rest.split_at_mut(part.len());
            part_words.push((first, part, these));
            first += part.len();
            rest = after;
        }
        part_words
            .into_par_iter()
            .try_for_each(|(first, part, out)| {
                if part.elem_type() != key_type {
                    return Err(KernelError::TypeMismatch {
                        expected: key_type,
                        found: part.elem_type(),
                    });
                }
                for (position, (word, &bits)) in out.iter_mut().zip(raw_bits(part)?).enumerate() {
                    let ordered = order_bits(key_type, bits);
                    *word = (u64::from(ordered) << 32) | (first + position) as u64;
                }
                Ok(())
            })?;
        sort_distinct_words(&mut words);
        Ok(SortedOrder { key_type, words })
    }

    pub fn len(&self) -> usize {
        self.words.len()
    }

    pub fn is_empty(&self) -> bool {
        self.words.is_empty()
    }

    /// The sorted keys, written into `target` (an array of the keys' type
    /// and length, whose contents are overwritten).
    pub fn keys_into(&self, mut target: Column) -> Result<Column, KernelError> {
        check_length("the sorted keys", self.len(), target.len())?;
        let ty = self.key_type;
        let out: &mut [u32] = match &mut target {
            Column::U32(values) => values,
            Column::I32(values) => bytemuck::cast_slice_mut(values),
            Column::F32(values) => bytemuck::cast_slice_mut(values),
            other => {
                return Err(KernelError::TypeMismatch {
                    expected: ty,
                    found: other.elem_type(),
                })
            }
        };
        out.par_chunks_mut(COPY_BLOCK)
            .zip(self.words.par_chunks(COPY_BLOCK))
            .for_each(|(out, words)| {
                for (key, word) in out.iter_mut().zip(words) {
                    *key = key_bits(ty, (word >> 32) as u32);
                }
            });
        Ok(target)
    }

    /// `values` (as long as the keys, any element type) in the keys' sorted
    /// order, written into `target` (an array of their type and length).
    pub fn values_into(
        &self,
        values: &ColumnView<'_>,
        target: Column,
    ) -> Result<Column, KernelError> {
        check_length("the values sorted by key", self.len(), values.len())?;
        check_length("the sorted values' array", self.len(), target.len())?;
        let target = SharedTarget::new(target);
        self.words
            .par_chunks(COPY_BLOCK)
            .enumerate()
            .try_for_each(|(block, words)| {
                let moved = gather_by_position(values, words.len(), &|position| {
                    words[position] as u32 as usize
                });
                target.write_range(block * COPY_BLOCK, &moved.view())
            })?;
        Ok(target.into_column())
    }
}

/// Sorts words that are all distinct, so that any sort gives the one
/// ascending sequence: rdst's parallel radix sort (docs/benchmarks.md, sort).
fn sort_distinct_words(words: &mut [u64]) {
    use rdst::RadixSort;
    words.radix_sort_unstable();
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn float_order_is_total_and_inverts() {
        let ascending = [
            f32::from_bits(0xFFFF_FFFF), // -NaN, largest payload
            f32::from_bits(0xFFC0_0000), // -NaN
            f32::NEG_INFINITY,
            -1.0,
            -f32::MIN_POSITIVE,
            -0.0,
            0.0,
            f32::from_bits(1),
            1.0,
            f32::INFINITY,
            f32::NAN,
            f32::from_bits(0x7FFF_FFFF),
        ];
        let ordered: Vec<u32> = ascending
            .iter()
            .map(|k| order_bits(ElemType::F32, k.to_bits()))
            .collect();
        assert!(ordered.windows(2).all(|w| w[0] < w[1]), "{ordered:x?}");
        for key in ascending {
            let ordered = order_bits(ElemType::F32, key.to_bits());
            assert_eq!(key_bits(ElemType::F32, ordered), key.to_bits());
        }
        let ints = [i32::MIN, -1, 0, 1, i32::MAX];
        let ordered: Vec<u32> = ints
            .iter()
            .map(|&k| order_bits(ElemType::I32, k as u32))
            .collect();
        assert!(ordered.windows(2).all(|w| w[0] < w[1]));
    }

    #[test]
    fn sorts_stably_across_parts() {
        let keys = [3u32, 1, 3, 0, 1, 3, 2];
        let (first, second) = keys.split_at(3);
        let parts = [ColumnView::U32(first), ColumnView::U32(second)];
        let order = SortedOrder::new(ElemType::U32, &parts).unwrap();
        let sorted = order.keys_into(Column::U32(vec![0; keys.len()])).unwrap();
        assert_eq!(sorted.view().as_u32(), &[0, 1, 1, 2, 3, 3, 3]);
        let positions: Vec<u32> = (0..keys.len() as u32).collect();
        let moved = order
            .values_into(
                &ColumnView::U32(&positions),
                Column::U32(vec![0; keys.len()]),
            )
            .unwrap();
        assert_eq!(moved.view().as_u32(), &[3, 1, 4, 6, 0, 2, 5]);
    }
}
