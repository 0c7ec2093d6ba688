//! The CPU's `sortByKey` order (docs/benchmarks.md, sort) against rayon's
//! sorts, side by side on the same random keys: 2M, 8M and 32M u32 keys,
//! each sorted with its position (a stable result), best of 3.
//!
//! `cargo run --release -p dpp-runtime --example sort_keys [THREADS]`

use dpp_runtime::column::ColumnView;
use dpp_runtime::cpu::sort::SortedOrder;
use dpp_runtime::random::SplitMix64;
use dpp_runtime::ElemType;
use rayon::prelude::*;
use std::time::Instant;

/// Best wall time of `runs` calls of `sort`, in ms.
fn best_ms(runs: usize, mut sort: impl FnMut()) -> f64 {
    (0..runs)
        .map(|_| {
            let start = Instant::now();
            sort();
            start.elapsed().as_secs_f64() * 1e3
        })
        .fold(f64::INFINITY, f64::min)
}

fn main() {
    let threads: usize = std::env::args()
        .nth(1)
        .map_or(0, |t| t.parse().expect("a thread count"));
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build_global()
        .expect("the thread pool");
    println!("{} threads", rayon::current_num_threads());
    println!("| keys | dpp (rdst on key·position words) | par_sort_unstable (same words) | par_sort_by_key (key, position) |");
    println!("| ---: | ---: | ---: | ---: |");
    for n in [2usize << 20, 8 << 20, 32 << 20] {
        let mut random = SplitMix64::new(n as u64);
        let keys: Vec<u32> = (0..n).map(|_| random.next_u64() as u32).collect();
        let words = || -> Vec<u64> {
            (keys.par_iter().enumerate())
                .map(|(position, &key)| (u64::from(key) << 32) | position as u64)
                .collect()
        };
        let dpp = best_ms(3, || {
            let order = SortedOrder::new(ElemType::U32, &[ColumnView::U32(&keys)]).unwrap();
            assert_eq!(order.len(), n);
        });
        let unstable = best_ms(3, || words().par_sort_unstable());
        let stable = best_ms(3, || {
            let mut pairs: Vec<(u32, u32)> = (keys.par_iter().enumerate())
                .map(|(position, &key)| (key, position as u32))
                .collect();
            pairs.par_sort_by_key(|pair| pair.0);
        });
        println!(
            "| {}M | {dpp:.1} ms | {unstable:.1} ms ({:.2}×) | {stable:.1} ms ({:.2}×) |",
            n >> 20,
            unstable / dpp,
            stable / dpp
        );
    }
}
