//! Measures the sort-last compositing schedules on real ranks.
//!
//! ```text
//! mpirun -n N target/release/examples/composite_bench \
//!     [--sizes 512x512,1920x1080,3840x2160] \
//!     [--schedules direct,binary-swap,radix-k:2,radix-k:4,radix-k:8] \
//!     [--repeats R] [--check-max-pixels P] [--seed S] [--cores C]
//! ```
//!
//! `--cores`: the machine's cores, for the `oversubscribed` field (a rank
//! bound to one core by mpirun sees only that one).
//!
//! Every rank makes the fragments the tracer hands over — depth `f32`, alpha
//! `f32`, colour `vec3` (20 bytes per pixel) — with random depths from a
//! generator seeded per rank, and composites them with a nearest-depth blend
//! (the nearer fragment wins, ties go to the front one). **The blend here is
//! written in Rust**; real runs use a blend compiled from `.dpp`, whose cost
//! per pixel differs, so the blend time here is a floor, not a forecast.
//!
//! Per (ranks, size, schedule): one warm-up composite (checked against a
//! direct left fold on rank 0 when the image has at most `--check-max-pixels`
//! pixels: a schedule that computes a wrong image prints no numbers and the
//! run fails), then `R` measured ones. Each measured composite starts after
//! a barrier; a repeat lasts as long as its slowest rank, and per-round,
//! blend and gather times are the maximum over the ranks too. Rank 0 prints
//! one JSON line with the medians over the repeats, the bytes each rank sent
//! (maximum and mean over the ranks, gathered with `all_gather_bytes`) and
//! the model's figures from `dpp_dist::cost` for the fit (`cost_fit`).

use dpp_dist::{composite, cost, CompositeSchedule, Ranks};
use dpp_runtime::interpret::RunError;
use dpp_runtime::{Column, RecordRegistry};
use glam::Vec3;
use std::sync::Arc;
use std::time::Instant;

const BYTES_PER_PIXEL: usize = 4 + 4 + 12;

struct Args {
    sizes: Vec<(usize, usize)>,
    schedules: Vec<CompositeSchedule>,
    repeats: usize,
    check_max_pixels: usize,
    seed: u64,
    /// The machine's cores (mpirun binds a rank to one core when ranks ≤
    /// cores, so a rank cannot count them itself).
    cores: Option<usize>,
}

fn usage(message: &str) -> ! {
    eprintln!("composite_bench: {message}");
    eprintln!(
        "usage: composite_bench [--sizes WxH,...] [--schedules direct,binary-swap,radix-k:K,...] \
         [--repeats R] [--check-max-pixels P] [--seed S] [--cores C]"
    );
    std::process::exit(2)
}

fn parse_args() -> Args {
    let mut args = Args {
        sizes: vec![(512, 512), (1920, 1080), (3840, 2160)],
        schedules: [
            "direct",
            "binary-swap",
            "radix-k:2",
            "radix-k:4",
            "radix-k:8",
        ]
        .iter()
        .map(|s| s.parse().unwrap())
        .collect(),
        repeats: 5,
        check_max_pixels: 2_100_000,
        seed: 2009,
        cores: None,
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let value = it
            .next()
            .unwrap_or_else(|| usage(&format!("{flag} needs a value")));
        let number = |v: &str| -> u64 {
            v.parse()
                .unwrap_or_else(|_| usage(&format!("{flag}: `{v}` is not a number")))
        };
        match flag.as_str() {
            "--sizes" => {
                args.sizes = value
                    .split(',')
                    .map(|s| {
                        let (w, h) = s
                            .split_once('x')
                            .unwrap_or_else(|| usage(&format!("size `{s}` is not WxH")));
                        (number(w) as usize, number(h) as usize)
                    })
                    .collect()
            }
            "--schedules" => {
                args.schedules = value
                    .split(',')
                    .map(|s| s.parse().unwrap_or_else(|e| usage(&format!("{e}"))))
                    .collect()
            }
            "--repeats" => args.repeats = number(&value).max(1) as usize,
            "--check-max-pixels" => args.check_max_pixels = number(&value) as usize,
            "--seed" => args.seed = number(&value),
            "--cores" => args.cores = Some(number(&value) as usize),
            _ => usage(&format!("unknown flag {flag}")),
        }
    }
    args
}

/// SplitMix64: a small generator every rank runs alike.
fn next(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

fn unit(state: &mut u64) -> f32 {
    (next(state) >> 40) as f32 / (1u64 << 24) as f32
}

/// Rank `rank`'s fragments: depth, alpha, colour (a function of seed and
/// rank, so rank 0 can make every rank's for the check).
fn fragments(seed: u64, rank: usize, n: usize) -> Vec<Arc<Column>> {
    let mut state = seed ^ (rank as u64 + 1).wrapping_mul(0xd134_2543_de82_ef95);
    let mut depth = Vec::with_capacity(n);
    let mut alpha = Vec::with_capacity(n);
    let mut colour = Vec::with_capacity(n);
    for _ in 0..n {
        depth.push(unit(&mut state));
        alpha.push(unit(&mut state));
        colour.push(Vec3::new(
            unit(&mut state),
            unit(&mut state),
            unit(&mut state),
        ));
    }
    vec![
        Arc::new(Column::F32(depth)),
        Arc::new(Column::F32(alpha)),
        Arc::new(Column::Vec3(colour)),
    ]
}

fn f32s(column: &Column) -> &[f32] {
    match column {
        Column::F32(v) => v,
        _ => panic!("depth and alpha are f32 columns"),
    }
}

fn vec3s(column: &Column) -> &[Vec3] {
    match column {
        Column::Vec3(v) => v,
        _ => panic!("colour is a vec3 column"),
    }
}

/// Nearest depth wins (ties to the front): associative, not commutative in
/// ties, as compositing blends are.
fn blend(front: &[Arc<Column>], back: &[Arc<Column>]) -> Result<Vec<Arc<Column>>, RunError> {
    let (fd, bd) = (f32s(&front[0]), f32s(&back[0]));
    let (fa, ba) = (f32s(&front[1]), f32s(&back[1]));
    let (fc, bc) = (vec3s(&front[2]), vec3s(&back[2]));
    let n = fd.len();
    let mut depth = Vec::with_capacity(n);
    let mut alpha = Vec::with_capacity(n);
    let mut colour = Vec::with_capacity(n);
    for i in 0..n {
        let nearer = fd[i] <= bd[i];
        depth.push(if nearer { fd[i] } else { bd[i] });
        alpha.push(if nearer { fa[i] } else { ba[i] });
        colour.push(if nearer { fc[i] } else { bc[i] });
    }
    Ok(vec![
        Arc::new(Column::F32(depth)),
        Arc::new(Column::F32(alpha)),
        Arc::new(Column::Vec3(colour)),
    ])
}

fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    let m = values.len() / 2;
    if values.len() % 2 == 1 {
        values[m]
    } else {
        (values[m - 1] + values[m]) / 2.0
    }
}

fn to_bytes(values: &[f64]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

fn from_bytes(bytes: &[u8]) -> Vec<f64> {
    bytes
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
        .collect()
}

fn ms(seconds: f64) -> f64 {
    (seconds * 1e6).round() / 1e3
}

fn json_list(values: &[f64]) -> String {
    let items: Vec<String> = values.iter().map(|v| format!("{v}")).collect();
    format!("[{}]", items.join(","))
}

fn main() {
    let args = parse_args();
    let ranks = Ranks::init().unwrap_or_else(|e| usage(&e.to_string()));
    let (p, me) = (ranks.size(), ranks.rank());
    let cores = args
        .cores
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |c| c.get()));
    let records = RecordRegistry::default();
    let order: Vec<usize> = (0..p).collect();

    for &(width, height) in &args.sizes {
        let n = width * height;
        let mine = fragments(args.seed, me, n);
        for schedule in &args.schedules {
            // Per repeat, every rank's figures: total, gather, blend,
            // exchange bytes, gather bytes, then one time per round.
            let mut per_repeat: Vec<Vec<Vec<f64>>> = Vec::new();
            let mut checked = false;
            for repeat in 0..=args.repeats {
                ranks.barrier();
                let started = Instant::now();
                let result =
                    composite(&ranks, schedule, mine.clone(), &order, &records, &mut blend);
                let total = started.elapsed().as_secs_f64();
                let out = ranks.agree(result).unwrap_or_else(|e| {
                    eprintln!("rank {me}: {schedule} on {width}x{height}: {}", e.message);
                    std::process::exit(1)
                });
                if repeat == 0 {
                    // The warm-up: checked, not measured.
                    let verdict = if me == 0 && n <= args.check_max_pixels {
                        checked = true;
                        let expected = (1..p).fold(mine.clone(), |acc, r| {
                            blend(&acc, &fragments(args.seed, r, n)).unwrap()
                        });
                        if out.image.as_ref() == Some(&expected) {
                            Ok(())
                        } else {
                            Err(RunError::internal(format!(
                                "{schedule} on {p} ranks, {width}x{height}: the image is not the left fold"
                            )))
                        }
                    } else {
                        Ok(())
                    };
                    if let Err(e) = ranks.agree(verdict) {
                        eprintln!("rank {me}: WRONG RESULT: {}", e.message);
                        std::process::exit(1)
                    }
                    continue;
                }
                let stats = &out.stats;
                let mut figures = vec![
                    total,
                    stats.gather.time.as_secs_f64(),
                    stats.blend_time.as_secs_f64(),
                    stats.rounds.iter().map(|r| r.bytes_sent).sum::<u64>() as f64,
                    stats.gather.bytes_sent as f64,
                ];
                figures.extend(stats.rounds.iter().map(|r| r.time.as_secs_f64()));
                let all = ranks.all_gather_bytes(&to_bytes(&figures));
                per_repeat.push(all.iter().map(|b| from_bytes(b)).collect());
            }
            if me != 0 {
                continue;
            }
            // Over the ranks: the slowest for times; bytes are the same in
            // every repeat, so the first repeat's.
            let slowest = |column: usize| -> f64 {
                let mut values: Vec<f64> = per_repeat
                    .iter()
                    .map(|ranks| ranks.iter().map(|f| f[column]).fold(0.0, f64::max))
                    .collect();
                median(&mut values)
            };
            let rounds = per_repeat[0][0].len() - 5;
            let round_ms: Vec<f64> = (0..rounds).map(|i| ms(slowest(5 + i))).collect();
            let first = &per_repeat[0];
            let sent: Vec<f64> = first.iter().map(|f| f[3] + f[4]).collect();
            let exchanged: Vec<f64> = first.iter().map(|f| f[3]).collect();
            let max = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
            let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
            let mut totals: Vec<f64> = per_repeat
                .iter()
                .map(|ranks| ranks.iter().map(|f| f[0]).fold(0.0, f64::max))
                .collect();
            let min_total = totals.iter().copied().fold(f64::INFINITY, f64::min);
            let model = cost(schedule, p, n, BYTES_PER_PIXEL);
            println!(
                "{{\"ranks\":{p},\"cores\":{cores},\"oversubscribed\":{},\"size\":\"{width}x{height}\",\
                 \"pixels\":{n},\"bytes_per_pixel\":{BYTES_PER_PIXEL},\"schedule\":\"{schedule}\",\
                 \"repeats\":{},\"checked\":{checked},\"blend\":\"rust-nearest-depth\",\
                 \"median_ms\":{},\"min_ms\":{},\"round_ms\":{},\"blend_ms\":{},\"gather_ms\":{},\
                 \"bytes_sent_max\":{},\"bytes_sent_mean\":{},\
                 \"exchange_bytes_max\":{},\"exchange_bytes_mean\":{},\
                 \"model\":{{\"rounds\":{},\"messages_per_rank\":{},\"bytes_per_rank\":{},\
                 \"gather_messages\":{},\"gather_bytes\":{}}}}}",
                p > cores,
                args.repeats,
                ms(median(&mut totals)),
                ms(min_total),
                json_list(&round_ms),
                ms(slowest(2)),
                ms(slowest(1)),
                max(&sent),
                mean(&sent),
                max(&exchanged),
                mean(&exchanged),
                model.rounds,
                model.messages_per_rank,
                model.bytes_per_rank,
                model.gather_messages,
                model.gather_bytes,
            );
        }
    }
}
