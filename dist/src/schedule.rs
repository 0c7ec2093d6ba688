//! Compositing schedules as data. A schedule is compiled into a [`Plan`]
//! before any byte moves, so that every rank derives the same exchange from
//! the same three numbers (ranks, pixels, order) without talking, the
//! executor stays a dumb loop over the plan, and the plan can be checked in
//! memory (no MPI) and costed for the benchmark.
//!
//! The plan is built over *positions* (front-to-back places in the blend
//! order), not ranks: groups that are contiguous in positions are exactly
//! the groups a non-commutative blend may combine, and only the last step
//! maps positions to ranks through the order.

use std::fmt;
use std::ops::Range;
use std::str::FromStr;

/// The radix when `radix-k` names none: 8, the group size Ascent's VTK-h
/// uses for surfaces and the best single k in Peterka et al.'s (2009)
/// measurements; it keeps the rounds few (log8 p) while each round's k − 1
/// messages stay cheap to overlap.
pub const DEFAULT_RADIX: usize = 8;

/// How ranks exchange parts of their images until each owns one finished
/// region (rank 0 then gathers the regions).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum CompositeSchedule {
    /// One round: every rank owns 1/p of the pixels and receives everyone's
    /// piece of it.
    DirectSend,
    /// IceT's binary swap: log2 p rounds halving the region; for p not a
    /// power of two a fold round first.
    BinarySwap,
    /// Radix-k: rounds with group sizes k_i ≤ K whose product is p (a prime
    /// factor above K is a round of its own).
    RadixK(usize),
}

impl fmt::Display for CompositeSchedule {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CompositeSchedule::DirectSend => f.write_str("direct"),
            CompositeSchedule::BinarySwap => f.write_str("binary-swap"),
            CompositeSchedule::RadixK(k) => write!(f, "radix-k:{k}"),
        }
    }
}

/// A schedule's name that does not parse.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown compositing schedule `{0}` (expected direct, binary-swap, radix-k or radix-k:K with K ≥ 2)")]
pub struct ParseScheduleError(pub String);

impl FromStr for CompositeSchedule {
    type Err = ParseScheduleError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "direct" => Ok(CompositeSchedule::DirectSend),
            "binary-swap" => Ok(CompositeSchedule::BinarySwap),
            "radix-k" => Ok(CompositeSchedule::RadixK(DEFAULT_RADIX)),
            _ => match s.strip_prefix("radix-k:").map(str::parse::<usize>) {
                Some(Ok(k)) if k >= 2 => Ok(CompositeSchedule::RadixK(k)),
                _ => Err(ParseScheduleError(s.to_string())),
            },
        }
    }
}

/// Where a piece that a rank blends comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Source {
    /// What the rank held before the round, cut to the range it keeps.
    Own,
    /// What it received from this rank in the round.
    From(usize),
}

/// One message: the peer (receiver of a send, sender of a receive) and the
/// pixels it carries.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Transfer {
    pub peer: usize,
    pub pixels: Range<usize>,
}

/// One rank's part in one round.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Step {
    /// The pixels the rank holds after the round (empty: it holds nothing
    /// any more, or never held a non-empty part).
    pub keep: Range<usize>,
    /// Parts of what it held, to other ranks (never empty ranges).
    pub sends: Vec<Transfer>,
    /// Pieces of `keep` from other ranks (each covers all of `keep`).
    pub receives: Vec<Transfer>,
    /// The pieces to blend into `keep`, front to back (a left fold). Empty
    /// when `keep` is empty; just `[Own]` when the rank receives nothing.
    pub blend: Vec<Source>,
}

/// The whole exchange for `ranks` ranks and `pixels` pixels, identical on
/// every rank.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Plan {
    pub ranks: usize,
    pub pixels: usize,
    /// `rounds[i][r]`: rank r's part in round i.
    pub rounds: Vec<Vec<Step>>,
    /// After the rounds, the finished region of each rank; the non-empty
    /// ones partition `0..pixels`. Rank 0 gathers them.
    pub owned: Vec<Range<usize>>,
}

/// Part `d` of `k` of `range` (the parts are contiguous, in order, and
/// differ in length by at most one).
fn split(range: &Range<usize>, k: usize, d: usize) -> Range<usize> {
    let len = range.len();
    range.start + d * len / k..range.start + (d + 1) * len / k
}

/// Factors `p` into group sizes ≤ `max_k` (a prime above `max_k` is a group
/// of its own), largest first: first-fit decreasing over the prime factors,
/// so the rounds are few and deterministic.
pub fn radix_factors(p: usize, max_k: usize) -> Vec<usize> {
    let mut primes = Vec::new();
    let mut rest = p;
    let mut f = 2;
    while f * f <= rest {
        while rest % f == 0 {
            primes.push(f);
            rest /= f;
        }
        f += 1;
    }
    if rest > 1 {
        primes.push(rest);
    }
    primes.sort_unstable_by(|a, b| b.cmp(a));
    let mut bins: Vec<usize> = Vec::new();
    for prime in primes {
        match bins.iter_mut().find(|b| **b * prime <= max_k) {
            Some(bin) => *bin *= prime,
            None => bins.push(prime),
        }
    }
    bins.sort_unstable_by(|a, b| b.cmp(a));
    bins
}

/// Whether the schedule folds first, and its group size per round.
fn shape(schedule: &CompositeSchedule, p: usize) -> (usize, Vec<usize>) {
    if p <= 1 {
        return (1, Vec::new());
    }
    match *schedule {
        CompositeSchedule::DirectSend => (p, vec![p]),
        CompositeSchedule::BinarySwap => {
            let folded = 1usize << (usize::BITS - 1 - p.leading_zeros());
            (folded, vec![2; folded.trailing_zeros() as usize])
        }
        CompositeSchedule::RadixK(k) => (p, radix_factors(p, k.max(2))),
    }
}

/// The plan of `schedule` for `p` ranks, `n` pixels and the blend order
/// `order` (positions front to back → ranks; a permutation of `0..p`).
///
/// # Panics
/// If `order` is not a permutation of `0..p` (the executor checks it first).
pub fn plan(schedule: &CompositeSchedule, p: usize, n: usize, order: &[usize]) -> Plan {
    assert_eq!(order.len(), p, "the order names every rank once");
    let mut seen = vec![false; p];
    for &r in order {
        assert!(r < p && !seen[r], "the order is a permutation of 0..p");
        seen[r] = true;
    }
    let idle = |_| Step {
        keep: 0..0,
        sends: Vec::new(),
        receives: Vec::new(),
        blend: Vec::new(),
    };
    let mut held: Vec<Range<usize>> = vec![0..n; p];
    let mut rounds = Vec::new();
    let (folded, factors) = shape(schedule, p);

    // Virtual participant v stands for a contiguous run of positions: the
    // fold pairs positions (2v, 2v + 1) for the first `extra` of them, and
    // the lower rank of a pair receives, so that rank 0 always takes part
    // and gathers its own region.
    let extra = p - folded;
    let virtual_rank: Vec<usize> = (0..folded)
        .map(|v| {
            if v < extra {
                order[2 * v].min(order[2 * v + 1])
            } else {
                order[v + extra]
            }
        })
        .collect();
    if extra > 0 {
        let mut steps: Vec<Step> = (0..p).map(idle).collect();
        for v in 0..extra {
            let (front, back) = (order[2 * v], order[2 * v + 1]);
            let (keeper, leaver) = (front.min(back), front.max(back));
            steps[keeper].keep = 0..n;
            if n > 0 {
                let whole = |peer| vec![Transfer { peer, pixels: 0..n }];
                steps[leaver].sends = whole(keeper);
                steps[keeper].receives = whole(leaver);
                steps[keeper].blend = if keeper == front {
                    vec![Source::Own, Source::From(back)]
                } else {
                    vec![Source::From(front), Source::Own]
                };
            }
            held[leaver] = 0..0;
        }
        for &r in &virtual_rank[extra..] {
            steps[r].keep = 0..n;
            steps[r].blend = if n > 0 { vec![Source::Own] } else { Vec::new() };
        }
        rounds.push(steps);
    }

    let mut stride = 1;
    for &k in &factors {
        let mut steps: Vec<Step> = (0..p).map(idle).collect();
        for v in 0..folded {
            let r = virtual_rank[v];
            let digit = (v / stride) % k;
            let base = v - digit * stride;
            let members: Vec<usize> = (0..k).map(|t| virtual_rank[base + t * stride]).collect();
            let region = held[r].clone();
            let keep = split(&region, k, digit);
            let step = &mut steps[r];
            for (t, &peer) in members.iter().enumerate() {
                if t == digit {
                    continue;
                }
                let theirs = split(&region, k, t);
                if !theirs.is_empty() {
                    step.sends.push(Transfer {
                        peer,
                        pixels: theirs,
                    });
                }
                if !keep.is_empty() {
                    step.receives.push(Transfer {
                        peer,
                        pixels: keep.clone(),
                    });
                }
            }
            if !keep.is_empty() {
                step.blend = members
                    .iter()
                    .enumerate()
                    .map(|(t, &peer)| {
                        if t == digit {
                            Source::Own
                        } else {
                            Source::From(peer)
                        }
                    })
                    .collect();
            }
            step.keep = keep;
        }
        for (r, step) in steps.iter().enumerate() {
            held[r] = step.keep.clone();
        }
        rounds.push(steps);
        stride *= k;
    }
    for range in &mut held {
        if range.start >= range.end {
            *range = 0..0;
        }
    }
    Plan {
        ranks: p,
        pixels: n,
        rounds,
        owned: held,
    }
}

/// What a schedule costs along its critical path: per round, the busiest
/// rank's figures, summed over the rounds (ranks wait for their partners, so
/// a round lasts as long as its busiest rank). The final gather is separate:
/// it is the same for every schedule but the fold's idle ranks.
#[derive(Clone, Debug, PartialEq)]
pub struct Cost {
    /// Exchange rounds (the fold counts as one), not counting the gather.
    pub rounds: usize,
    /// Messages sent by the busiest rank, summed over the rounds.
    pub messages_per_rank: usize,
    /// Bytes sent by the busiest rank, summed over the rounds.
    pub bytes_per_rank: f64,
    /// Messages rank 0 receives in the gather.
    pub gather_messages: usize,
    /// Bytes rank 0 receives in the gather.
    pub gather_bytes: f64,
}

/// The cost model of `schedule` for `p` ranks and `n` pixels of
/// `bytes_per_pixel` bytes (all fragment columns together), with pixels
/// divided exactly (it is the plan's figure when every split is exact; the
/// benchmark fits latency and bandwidth terms to it).
pub fn cost(schedule: &CompositeSchedule, p: usize, n: usize, bytes_per_pixel: usize) -> Cost {
    let (folded, factors) = shape(schedule, p);
    let image = n as f64 * bytes_per_pixel as f64;
    let mut rounds = factors.len();
    let mut messages = 0;
    let mut bytes = 0.0;
    if folded < p {
        rounds += 1;
        messages += 1;
        bytes += image;
    }
    let mut region = image;
    for &k in &factors {
        messages += k - 1;
        bytes += region * (k - 1) as f64 / k as f64;
        region /= k as f64;
    }
    Cost {
        rounds,
        messages_per_rank: messages,
        bytes_per_rank: bytes,
        gather_messages: folded - 1,
        gather_bytes: image * (folded - 1) as f64 / folded as f64,
    }
}

impl Plan {
    /// The same figures as [`cost`], measured on this plan (exact for any
    /// split; empty messages are not sent, so a tiny image costs less).
    pub fn cost(&self, bytes_per_pixel: usize) -> Cost {
        let b = bytes_per_pixel as f64;
        let mut messages = 0;
        let mut bytes = 0.0;
        for round in &self.rounds {
            messages += round.iter().map(|s| s.sends.len()).max().unwrap_or(0);
            bytes += round
                .iter()
                .map(|s| s.sends.iter().map(|t| t.pixels.len()).sum::<usize>())
                .max()
                .unwrap_or(0) as f64
                * b;
        }
        let others = self.owned.iter().skip(1).filter(|r| !r.is_empty());
        Cost {
            rounds: self.rounds.len(),
            messages_per_rank: messages,
            bytes_per_rank: bytes,
            gather_messages: others.clone().count(),
            gather_bytes: others.map(|r| r.len()).sum::<usize>() as f64 * b,
        }
    }
}

/// Non-negative least squares for a handful of terms: the coefficients
/// `c ≥ 0` minimising `Σ_i (rows[i] · c − times[i])²`. It exists for the
/// compositing benchmark, which fits latency, bandwidth and blend terms
/// (α per message, β per byte, γ per blended pixel) of [`cost`] to measured
/// times, where a negative α or β would be meaningless. Exact for few terms:
/// the optimum is the unconstrained least squares over its non-zero terms,
/// so it tries every subset of the terms (2^k solves; `k` ≤ 10) and keeps
/// the best one whose coefficients are all non-negative. Columns are scaled
/// to unit norm first (messages count in ones, bytes in billions). `None`
/// when there are no rows or rows of different lengths.
pub fn fit_nonnegative(rows: &[Vec<f64>], times: &[f64]) -> Option<Vec<f64>> {
    let k = rows.first()?.len();
    if rows.len() != times.len() || rows.iter().any(|r| r.len() != k) || k > 10 {
        return None;
    }
    let norms: Vec<f64> = (0..k)
        .map(|j| rows.iter().map(|r| r[j] * r[j]).sum::<f64>().sqrt())
        .collect();
    let residual = |c: &[f64]| -> f64 {
        rows.iter()
            .zip(times)
            .map(|(r, t)| (r.iter().zip(c).map(|(x, c)| x * c).sum::<f64>() - t).powi(2))
            .sum()
    };
    let mut best = (residual(&vec![0.0; k]), vec![0.0; k]);
    for mask in 1u32..(1 << k) {
        let terms: Vec<usize> = (0..k)
            .filter(|j| mask & (1 << j) != 0 && norms[*j] > 0.0)
            .collect();
        if terms.len() != mask.count_ones() as usize {
            continue;
        }
        // Normal equations over the scaled columns, Gaussian elimination
        // with partial pivoting.
        let m = terms.len();
        let x = |r: &Vec<f64>, a: usize| r[terms[a]] / norms[terms[a]];
        let mut a = vec![vec![0.0; m + 1]; m];
        for (r, t) in rows.iter().zip(times) {
            for (i, line) in a.iter_mut().enumerate() {
                for (j, cell) in line.iter_mut().take(m).enumerate() {
                    *cell += x(r, i) * x(r, j);
                }
                line[m] += x(r, i) * t;
            }
        }
        let mut solvable = true;
        for col in 0..m {
            let pivot = (col..m)
                .max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))
                .unwrap();
            if a[pivot][col].abs() < 1e-12 {
                solvable = false;
                break;
            }
            a.swap(col, pivot);
            let pivot_line = a[col].clone();
            for (row, line) in a.iter_mut().enumerate() {
                if row != col {
                    let f = line[col] / pivot_line[col];
                    for (cell, p) in line.iter_mut().zip(&pivot_line).skip(col) {
                        *cell -= f * p;
                    }
                }
            }
        }
        if !solvable {
            continue;
        }
        let mut c = vec![0.0; k];
        for (i, &j) in terms.iter().enumerate() {
            c[j] = a[i][m] / a[i][i] / norms[j];
        }
        if c.iter().all(|v| *v >= 0.0) {
            let r = residual(&c);
            if r < best.0 {
                best = (r, c);
            }
        }
    }
    Some(best.1)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// SplitMix64, for random orders.
    fn next(state: &mut u64) -> u64 {
        *state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = *state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    fn shuffled(p: usize, seed: u64) -> Vec<usize> {
        let mut state = seed;
        let mut order: Vec<usize> = (0..p).collect();
        for i in (1..p).rev() {
            order.swap(i, (next(&mut state) % (i as u64 + 1)) as usize);
        }
        order
    }

    /// Runs the plan in memory: each rank's pixel `i` starts as its rank id
    /// in brackets; the blend concatenates (associative, not commutative).
    /// Returns rank 0's gathered image and checks every step's bookkeeping.
    /// Messages in flight to each rank: (sender, pixels, values).
    type Inbox = Vec<Vec<(usize, Range<usize>, Vec<String>)>>;

    fn simulate(plan: &Plan) -> Vec<String> {
        let (p, n) = (plan.ranks, plan.pixels);
        let mut held: Vec<(Range<usize>, Vec<String>)> =
            (0..p).map(|r| (0..n, vec![format!("[{r}]"); n])).collect();
        for round in &plan.rounds {
            let mut inbox: Inbox = vec![Vec::new(); p];
            for (r, step) in round.iter().enumerate() {
                let (range, data) = &held[r];
                for t in &step.sends {
                    assert!(!t.pixels.is_empty());
                    assert!(range.start <= t.pixels.start && t.pixels.end <= range.end);
                    let part =
                        data[t.pixels.start - range.start..t.pixels.end - range.start].to_vec();
                    inbox[t.peer].push((r, t.pixels.clone(), part));
                }
            }
            let mut next_held = Vec::new();
            for (r, step) in round.iter().enumerate() {
                let mut got = std::mem::take(&mut inbox[r]);
                assert_eq!(
                    got.len(),
                    step.receives.len(),
                    "rank {r}: messages match receives"
                );
                for t in &step.receives {
                    let i = got
                        .iter()
                        .position(|(from, ..)| *from == t.peer)
                        .expect("a matching send");
                    assert_eq!(got[i].1, t.pixels);
                }
                let (range, data) = &held[r];
                let keep = step.keep.clone();
                if keep.is_empty() {
                    assert!(step.blend.is_empty() && step.receives.is_empty());
                    next_held.push((0..0, Vec::new()));
                    continue;
                }
                assert!(range.start <= keep.start && keep.end <= range.end);
                let own = data[keep.start - range.start..keep.end - range.start].to_vec();
                let mut acc: Option<Vec<String>> = None;
                for source in &step.blend {
                    let piece = match source {
                        Source::Own => own.clone(),
                        Source::From(peer) => {
                            let i = got.iter().position(|(from, ..)| from == peer).unwrap();
                            got.remove(i).2
                        }
                    };
                    acc = Some(match acc {
                        None => piece,
                        Some(front) => front.into_iter().zip(piece).map(|(a, b)| a + &b).collect(),
                    });
                }
                assert!(got.is_empty(), "rank {r}: every received piece is blended");
                next_held.push((keep, acc.unwrap()));
            }
            held = next_held;
        }
        // The gather.
        let mut image = vec![String::new(); n];
        let mut covered = vec![false; n];
        for (r, region) in plan.owned.iter().enumerate() {
            assert_eq!(&held[r].0, region, "rank {r} owns what it holds");
            for (i, value) in region.clone().zip(&held[r].1) {
                assert!(!covered[i], "pixel {i} owned twice");
                covered[i] = true;
                image[i] = value.clone();
            }
        }
        assert!(covered.iter().all(|c| *c), "every pixel owned");
        image
    }

    fn schedules() -> Vec<CompositeSchedule> {
        vec![
            CompositeSchedule::DirectSend,
            CompositeSchedule::BinarySwap,
            CompositeSchedule::RadixK(2),
            CompositeSchedule::RadixK(3),
            CompositeSchedule::RadixK(4),
            CompositeSchedule::RadixK(8),
        ]
    }

    #[test]
    fn every_schedule_gives_the_left_fold_over_the_order() {
        let sizes: Vec<usize> = (1..=9).chain([12, 16, 17, 24]).collect();
        for schedule in schedules() {
            for &p in &sizes {
                for n in [0, 1, p.saturating_sub(1), p, p + 1, 3 * p + 2, 64, 101] {
                    for seed in 0..4 {
                        let order = if seed == 0 {
                            (0..p).collect()
                        } else {
                            shuffled(p, seed)
                        };
                        let expected: String = order.iter().map(|r| format!("[{r}]")).collect();
                        let image = simulate(&plan(&schedule, p, n, &order));
                        for (i, value) in image.iter().enumerate() {
                            assert_eq!(
                                value, &expected,
                                "{schedule} p={p} n={n} order={order:?} pixel {i}"
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn schedule_names_round_trip() {
        for schedule in schedules() {
            assert_eq!(
                schedule.to_string().parse::<CompositeSchedule>(),
                Ok(schedule)
            );
        }
        assert_eq!(
            "radix-k".parse(),
            Ok(CompositeSchedule::RadixK(DEFAULT_RADIX))
        );
        assert_eq!("direct".parse(), Ok(CompositeSchedule::DirectSend));
        assert_eq!("binary-swap".parse(), Ok(CompositeSchedule::BinarySwap));
        for bad in [
            "",
            "radix",
            "radix-k:",
            "radix-k:1",
            "radix-k:x",
            "Direct",
            "binary_swap",
        ] {
            assert!(bad.parse::<CompositeSchedule>().is_err(), "{bad}");
        }
    }

    #[test]
    fn factors_stay_within_the_radix_and_multiply_to_p() {
        assert_eq!(radix_factors(16, 8), vec![8, 2]);
        assert_eq!(radix_factors(12, 8), vec![6, 2]);
        assert_eq!(radix_factors(64, 8), vec![8, 8]);
        assert_eq!(radix_factors(13, 8), vec![13]);
        assert_eq!(radix_factors(8, 2), vec![2, 2, 2]);
        assert_eq!(radix_factors(1, 8), Vec::<usize>::new());
        for p in 1..200 {
            for k in 2..10 {
                let factors = radix_factors(p, k);
                assert_eq!(factors.iter().product::<usize>(), p);
                for f in factors {
                    assert!(f <= k || (2..f).all(|d| f % d != 0), "p={p} k={k}: {f}");
                }
            }
        }
    }

    #[test]
    fn radix_k_spans_direct_send_and_binary_swap() {
        let order: Vec<usize> = (0..8).collect();
        let direct = plan(&CompositeSchedule::DirectSend, 8, 64, &order);
        assert_eq!(plan(&CompositeSchedule::RadixK(8), 8, 64, &order), direct);
        let swap = plan(&CompositeSchedule::BinarySwap, 8, 64, &order);
        assert_eq!(plan(&CompositeSchedule::RadixK(2), 8, 64, &order), swap);
        assert_eq!(swap.rounds.len(), 3);
        assert_eq!(direct.rounds.len(), 1);
    }

    #[test]
    fn the_cost_model_matches_the_plans() {
        for schedule in schedules() {
            for p in (1..=9).chain([12, 16, 24, 32]) {
                // Every split exact: n a multiple of every partial product.
                let n = 64 * 9 * 5 * 7;
                let order = shuffled(p, 7);
                let measured = plan(&schedule, p, n, &order).cost(16);
                assert_eq!(cost(&schedule, p, n, 16), measured, "{schedule} p={p}");
            }
        }
        // Closed forms for p = 8, n pixels of b bytes.
        let (n, b) = (1 << 20, 16);
        let image = (n * b) as f64;
        let direct = cost(&CompositeSchedule::DirectSend, 8, n, b);
        assert_eq!((direct.rounds, direct.messages_per_rank), (1, 7));
        assert_eq!(direct.bytes_per_rank, image * 7.0 / 8.0);
        let swap = cost(&CompositeSchedule::BinarySwap, 8, n, b);
        assert_eq!((swap.rounds, swap.messages_per_rank), (3, 3));
        assert_eq!(swap.bytes_per_rank, image * 7.0 / 8.0);
        assert_eq!(swap.gather_bytes, image * 7.0 / 8.0);
        // A fold: 6 ranks fold to 4; two ranks send their whole image first.
        let fold = cost(&CompositeSchedule::BinarySwap, 6, n, b);
        assert_eq!(
            (fold.rounds, fold.messages_per_rank, fold.gather_messages),
            (3, 3, 3)
        );
        assert_eq!(fold.bytes_per_rank, image + image * 3.0 / 4.0);
        let one = cost(&CompositeSchedule::RadixK(8), 1, n, b);
        assert_eq!(
            (one.rounds, one.messages_per_rank, one.gather_messages),
            (0, 0, 0)
        );
    }

    #[test]
    fn plans_are_deterministic_and_tiny_images_send_no_empty_messages() {
        let order = shuffled(9, 3);
        let a = plan(&CompositeSchedule::RadixK(3), 9, 5, &order);
        assert_eq!(a, plan(&CompositeSchedule::RadixK(3), 9, 5, &order));
        for round in &a.rounds {
            for step in round {
                assert!(step.sends.iter().all(|t| !t.pixels.is_empty()));
            }
        }
        assert_eq!(a.owned.iter().filter(|r| !r.is_empty()).count(), 5);
    }

    #[test]
    fn the_fit_recovers_known_terms_and_never_goes_negative() {
        // t = 2e-5 per message + 1e-9 per byte + 3e-9 per pixel, exactly.
        let schedules = [
            CompositeSchedule::DirectSend,
            CompositeSchedule::BinarySwap,
            CompositeSchedule::RadixK(4),
        ];
        let mut rows = Vec::new();
        let mut times = Vec::new();
        for schedule in &schedules {
            for p in 2..9 {
                for n in [1000, 250_000, 2_000_000] {
                    let c = cost(schedule, p, n, 20);
                    let messages = (c.messages_per_rank + c.gather_messages) as f64;
                    let bytes = c.bytes_per_rank + c.gather_bytes;
                    let pixels = c.bytes_per_rank / 20.0;
                    rows.push(vec![messages, bytes, pixels]);
                    times.push(2e-5 * messages + 1e-9 * bytes + 3e-9 * pixels);
                }
            }
        }
        let fit = fit_nonnegative(&rows, &times).unwrap();
        for (got, want) in fit.iter().zip([2e-5, 1e-9, 3e-9]) {
            assert!((got - want).abs() <= 1e-6 * want, "{fit:?}");
        }
        // Times that fall with the first term: its coefficient is 0, not < 0.
        let rows = vec![vec![1.0, 1.0], vec![2.0, 3.0], vec![3.0, 7.0]];
        // Exactly −1·x0 + 2·x1: unconstrained, the first term would be negative.
        let fit = fit_nonnegative(&rows, &[1.0, 4.0, 11.0]).unwrap();
        assert_eq!(fit[0], 0.0);
        assert!(fit[1] > 0.0);
        assert_eq!(fit_nonnegative(&[], &[]), None);
    }
}
