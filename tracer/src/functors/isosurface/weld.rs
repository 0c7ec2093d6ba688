//! Which corners of a triangle soup are one vertex: corners whose quantised
//! positions are equal. A vertex is numbered by the first corner that has it
//! (corner `3 t + i` is corner `i` of triangle `t`), so the vertices come in
//! the order a walk of the corners first meets them.
//!
//! By a sort (`crate::equal_keys`), as data-parallel libraries find
//! duplicate vertices: each corner's key (the three quantised coordinates,
//! packed into 63 bits) is sorted with its corner, every run of equal keys is one vertex, and its
//! smallest corner says where that vertex goes. On every core, the same
//! numbering on any number of threads (a run's smallest corner does not depend
//! on the order the sort leaves within it). A first walk of the corners with a
//! hash map, as this was written before, took 1.06 s of the ch2 brain's
//! 1.6M-triangle isosurface, two thirds of its extraction
//! (docs/benchmarks.md). Keys that do not pack (an infinite corner, or one
//! 2²¹ quanta or more from the origin given) are welded by that walk, which
//! gives the same numbering.

use crate::equal_keys::{for_each_run_of_equal_keys, Keyed};
use crate::huge_pages::collect_on_huge_pages;
use glam::Vec3;
use rayon::prelude::*;
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};

/// The welding of `corner_count` corners: each corner's vertex, and each
/// vertex's first corner.
#[derive(Debug, PartialEq)]
pub(super) struct Welding {
    pub corner_vertex: Vec<u32>,
    pub vertex_corner: Vec<u32>,
}

impl Welding {
    /// `value(corner)` of each vertex's first corner, in vertex order.
    pub fn per_vertex<T: Send>(&self, value: impl Fn(usize) -> T + Sync) -> Vec<T> {
        self.vertex_corner
            .par_iter()
            .map(|&corner| value(corner as usize))
            .collect()
    }
}

/// Bits per axis of a packed key (three of them fill 63 bits).
const AXIS_BITS: u32 = 21;

/// A position as its key: each coordinate over `quantum`, rounded half away
/// from zero, saturated (NaN gives 0). Exactly `(x / quantum).round() as
/// i64`, without `round`, which is a library call on x86-64's baseline.
pub(super) fn quantise(position: Vec3, quantum: f64) -> [i64; 3] {
    position.to_array().map(|x| {
        let scaled = f64::from(x) / quantum;
        let truncated = scaled as i64;
        // Exact: below 2⁵³ the two are within 1, above it `scaled` is whole.
        let fraction = scaled - truncated as f64;
        if fraction >= 0.5 {
            truncated.saturating_add(1)
        } else if fraction <= -0.5 {
            truncated.saturating_sub(1)
        } else {
            truncated
        }
    })
}

/// Welds the corners `0 .. corner_count`, where `key(corner)` is the
/// corner's quantised position; keys are packed as offsets from `origin`
/// (the quantised low corner of their box).
pub(super) fn weld_corners(
    corner_count: usize,
    origin: [i64; 3],
    key: impl Fn(usize) -> [i64; 3] + Sync,
) -> Welding {
    match packed_keys(corner_count, origin, &key) {
        Some(entries) => weld_by_sorting(entries),
        None => weld_by_walking(corner_count, key),
    }
}

/// Every corner's key as offsets from `origin`, packed, if every offset is
/// below 2²¹ and the corners can be numbered in a `u32`.
fn packed_keys(
    corner_count: usize,
    origin: [i64; 3],
    key: &(impl Fn(usize) -> [i64; 3] + Sync),
) -> Option<Vec<Keyed<u64>>> {
    u32::try_from(corner_count).ok()?;
    let unpacked = AtomicBool::new(false);
    let entries = collect_on_huge_pages((0..corner_count).into_par_iter().map(|corner| {
        let k = key(corner);
        let offsets: [i64; 3] = std::array::from_fn(|axis| k[axis].saturating_sub(origin[axis]));
        if offsets
            .iter()
            .any(|offset| !(0..1 << AXIS_BITS).contains(offset))
        {
            unpacked.store(true, Ordering::Relaxed);
        }
        let packed = offsets.iter().fold(0u64, |packed, &offset| {
            packed << AXIS_BITS | (offset as u64 & ((1 << AXIS_BITS) - 1))
        });
        Keyed {
            key: packed,
            index: corner as u32,
        }
    }));
    (!unpacked.into_inner()).then_some(entries)
}

fn weld_by_sorting(entries: Vec<Keyed<u64>>) -> Welding {
    let corner_count = entries.len();
    // Each corner's representative: the smallest corner of its run.
    let zeros =
        || collect_on_huge_pages((0..corner_count).into_par_iter().map(|_| AtomicU32::new(0)));
    let representative = zeros();
    for_each_run_of_equal_keys(entries, |run| {
        let first = run.iter().map(|entry| entry.index).min().unwrap_or(0);
        for entry in run {
            representative[entry.index as usize].store(first, Ordering::Relaxed);
        }
    });
    let first_of = |corner: usize| representative[corner].load(Ordering::Relaxed);
    // The representatives in corner order are the vertices in order.
    let vertex_corner: Vec<u32> = (0..corner_count as u32)
        .into_par_iter()
        .filter(|&corner| first_of(corner as usize) == corner)
        .collect();
    let vertex_at = zeros();
    vertex_corner
        .par_iter()
        .enumerate()
        .for_each(|(vertex, &corner)| {
            vertex_at[corner as usize].store(vertex as u32, Ordering::Relaxed)
        });
    let corner_vertex = collect_on_huge_pages(
        (0..corner_count)
            .into_par_iter()
            .map(|corner| vertex_at[first_of(corner) as usize].load(Ordering::Relaxed)),
    );
    Welding {
        corner_vertex,
        vertex_corner,
    }
}

/// One walk of the corners in order with a map from key to vertex.
fn weld_by_walking(corner_count: usize, key: impl Fn(usize) -> [i64; 3]) -> Welding {
    let mut vertex_of_key: HashMap<[i64; 3], u32> = HashMap::with_capacity(corner_count / 2);
    let mut vertex_corner = Vec::with_capacity(corner_count / 2);
    let corner_vertex = (0..corner_count)
        .map(|corner| {
            *vertex_of_key.entry(key(corner)).or_insert_with(|| {
                vertex_corner.push(corner as u32);
                vertex_corner.len() as u32 - 1
            })
        })
        .collect();
    Welding {
        corner_vertex,
        vertex_corner,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dpp_runtime::random::SplitMix64;

    /// Both ways give the same welding of `keys`, and it is a welding: equal
    /// keys share a vertex, different keys do not, and each vertex's corner is
    /// the first with its key.
    fn check(keys: &[[i64; 3]], origin: [i64; 3]) {
        let sorted = weld_corners(keys.len(), origin, |corner| keys[corner]);
        let walked = weld_by_walking(keys.len(), |corner| keys[corner]);
        assert_eq!(sorted, walked);
        let mut first_with: HashMap<[i64; 3], usize> = HashMap::new();
        for (corner, &vertex) in sorted.corner_vertex.iter().enumerate() {
            let first = *first_with.entry(keys[corner]).or_insert(corner);
            assert_eq!(sorted.vertex_corner[vertex as usize] as usize, first);
        }
        assert_eq!(sorted.vertex_corner.len(), first_with.len());
    }

    #[test]
    fn sorting_welds_as_the_walk_does() {
        check(&[], [0; 3]);
        check(&[[5, -3, 2]], [5, -3, 2]);
        let mut random = SplitMix64::new(7);
        for (count, spread) in [(3, 2), (999, 4), (30_001, 40), (30_000, 1 << 20)] {
            let keys: Vec<[i64; 3]> = (0..count)
                .map(|_| std::array::from_fn(|_| random.below(spread) as i64 - 7))
                .collect();
            assert!(packed_keys(keys.len(), [-7; 3], &|corner| keys[corner]).is_some());
            check(&keys, [-7; 3]);
        }
    }

    #[test]
    fn keys_that_do_not_pack_are_walked() {
        let far = [[0, 0, 0], [1 << AXIS_BITS, 0, 0], [0, 0, 0]];
        assert!(packed_keys(far.len(), [0; 3], &|corner| far[corner]).is_none());
        check(&far, [0; 3]);
        let below = [[0, 0, 0], [0, -1, 0]];
        assert!(packed_keys(below.len(), [0; 3], &|corner| below[corner]).is_none());
        check(&below, [0; 3]);
        // Infinite corners saturate.
        let infinite = [
            [i64::MAX, 0, 0],
            [i64::MIN, 0, 0],
            [i64::MAX, 0, 0],
            [0, 0, 0],
        ];
        check(&infinite, [0; 3]);
        check(&infinite, [i64::MIN; 3]);
        let edge = [[0, 0, 0], [(1 << AXIS_BITS) - 1, 0, 0]];
        assert!(packed_keys(edge.len(), [0; 3], &|corner| edge[corner]).is_some());
        check(&edge, [0; 3]);
    }

    #[test]
    fn quantise_rounds_as_round_does() {
        let reference = |x: f32, quantum: f64| (f64::from(x) / quantum).round() as i64;
        let mut random = SplitMix64::new(11);
        let mut values = vec![
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.5,
            -1.5,
            2.5,
            -2.5,
            0.499_999_97,
            f32::MAX,
            f32::MIN,
            f32::MIN_POSITIVE,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ];
        values.extend((0..100_000).map(|_| f32::from_bits(random.next_u32())));
        for quantum in [1.0, 0.25, 1e-3, 3.7e-7, f64::MIN_POSITIVE, 1e30] {
            for &x in &values {
                let expected = [reference(x, quantum); 3];
                assert_eq!(
                    quantise(Vec3::splat(x), quantum),
                    expected,
                    "{x:e} / {quantum:e}"
                );
            }
        }
    }
}
