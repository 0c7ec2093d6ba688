//! Fits the terms of `dpp_dist::cost` to `composite_bench`'s measurements
//! and extrapolates every schedule to many ranks.
//!
//! ```text
//! cargo run --release -p dpp-dist --example cost_fit -- target/composite-bench/results.jsonl [CORES]
//! ```
//!
//! The model along a schedule's critical path (the busiest rank per round,
//! summed over the rounds, plus rank 0's gather):
//!
//! ```text
//! T = α · (messages + gather messages) + β · (bytes + gather bytes) + γ · blended pixels
//! ```
//!
//! where blended pixels = exchange bytes / bytes per pixel (a rank that
//! receives k − 1 pieces of region/k pixels blends k − 1 times over region/k
//! pixels, exactly what it sends). Because blended pixels and exchange bytes
//! are proportional, γ cannot be told from β by total times alone; so γ is
//! fitted to the measured blend time, and α, β to the total minus the blend
//! time, both by non-negative least squares (`fit_nonnegative`), in
//! seconds. Rows with more ranks than cores ran oversubscribed: each rank
//! had a share of a core, so the fit is done twice — on the raw times, and
//! on times scaled by cores / ranks (as if the work of the ranks were spread
//! over cores of their own) — and once on the rows with ranks ≤ cores only.
//! The extrapolation uses the scaled fit; all three are printed.

use dpp_dist::schedule::fit_nonnegative;
use dpp_dist::{cost, CompositeSchedule};
use serde_json::Value;

struct Row {
    ranks: usize,
    cores: usize,
    pixels: usize,
    bytes_per_pixel: usize,
    schedule: CompositeSchedule,
    total: f64,
    blend: f64,
}

impl Row {
    /// (α term, β term, γ term) regressors from the model.
    fn terms(&self) -> [f64; 3] {
        terms(
            &self.schedule,
            self.ranks,
            self.pixels,
            self.bytes_per_pixel,
        )
    }

    fn share(&self, scaled: bool) -> f64 {
        if scaled && self.ranks > self.cores {
            self.cores as f64 / self.ranks as f64
        } else {
            1.0
        }
    }
}

fn terms(schedule: &CompositeSchedule, p: usize, n: usize, bpp: usize) -> [f64; 3] {
    let c = cost(schedule, p, n, bpp);
    [
        (c.messages_per_rank + c.gather_messages) as f64,
        c.bytes_per_rank + c.gather_bytes,
        c.bytes_per_rank / bpp as f64,
    ]
}

struct Fit {
    alpha: f64,
    beta: f64,
    gamma: f64,
    /// Root mean square of (predicted − measured) / measured, over the rows
    /// with more than one rank.
    rel_rms: f64,
}

impl Fit {
    fn predict(&self, t: [f64; 3]) -> f64 {
        self.alpha * t[0] + self.beta * t[1] + self.gamma * t[2]
    }
}

fn fit(rows: &[&Row], scaled: bool) -> Fit {
    let x: Vec<Vec<f64>> = rows.iter().map(|r| r.terms()[..2].to_vec()).collect();
    let y: Vec<f64> = rows
        .iter()
        .map(|r| (r.total - r.blend) * r.share(scaled))
        .collect();
    let ab = fit_nonnegative(&x, &y).expect("rows to fit");
    let xg: Vec<Vec<f64>> = rows.iter().map(|r| vec![r.terms()[2]]).collect();
    let yg: Vec<f64> = rows.iter().map(|r| r.blend * r.share(scaled)).collect();
    let g = fit_nonnegative(&xg, &yg).expect("rows to fit");
    let mut fit = Fit {
        alpha: ab[0],
        beta: ab[1],
        gamma: g[0],
        rel_rms: 0.0,
    };
    let errors: Vec<f64> = rows
        .iter()
        .filter(|r| r.ranks > 1)
        .map(|r| {
            let measured = r.total * r.share(scaled);
            (fit.predict(r.terms()) - measured) / measured
        })
        .collect();
    fit.rel_rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len().max(1) as f64).sqrt();
    fit
}

fn main() {
    // cost_fit [RESULTS.jsonl] [CORES]: the machine's cores override the
    // lines' (a rank bound to one core by mpirun counted one).
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = args
        .first()
        .cloned()
        .unwrap_or_else(|| "target/composite-bench/results.jsonl".into());
    let machine_cores: Option<usize> = args.get(1).map(|c| c.parse().expect("CORES is a number"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| {
        eprintln!("cost_fit: cannot read {path}: {e}");
        std::process::exit(2)
    });
    let rows: Vec<Row> = text
        .lines()
        .filter(|l| l.starts_with('{'))
        .map(|line| {
            let v: Value = serde_json::from_str(line).expect("a JSON line");
            let num = |k: &str| v[k].as_f64().unwrap_or_else(|| panic!("{k} in {line}"));
            Row {
                ranks: num("ranks") as usize,
                cores: machine_cores.unwrap_or(num("cores") as usize),
                pixels: num("pixels") as usize,
                bytes_per_pixel: num("bytes_per_pixel") as usize,
                schedule: v["schedule"].as_str().unwrap().parse().unwrap(),
                total: num("median_ms") / 1e3,
                blend: num("blend_ms") / 1e3,
            }
        })
        .collect();
    println!("{} measurements from {path}\n", rows.len());

    let all: Vec<&Row> = rows.iter().collect();
    let unshared: Vec<&Row> = rows.iter().filter(|r| r.ranks <= r.cores).collect();
    let fits = [
        ("all rows, times scaled by cores/ranks", fit(&all, true)),
        ("all rows, raw times", fit(&all, false)),
        ("ranks ≤ cores only", fit(&unshared, false)),
    ];
    println!("| fit | α (µs per message) | β (ns per byte) | 1/β (GB/s) | γ (ns per blended pixel) | rel. RMS error |");
    println!("|---|---|---|---|---|---|");
    for (name, f) in &fits {
        println!(
            "| {name} | {:.1} | {:.3} | {:.2} | {:.2} | {:.0} % |",
            f.alpha * 1e6,
            f.beta * 1e9,
            if f.beta > 0.0 {
                1e-9 / f.beta
            } else {
                f64::INFINITY
            },
            f.gamma * 1e9,
            f.rel_rms * 100.0
        );
    }

    // Model against measurement for the scaled fit, per schedule and size.
    let primary = &fits[0].1;
    println!("\nscaled fit against the (scaled) measurements, ms:");
    println!("| size | schedule | ranks | measured | model |");
    println!("|---|---|---|---|---|");
    for r in rows.iter().filter(|r| r.ranks > 1 && r.ranks % 4 == 0) {
        println!(
            "| {} | {} | {} | {:.1} | {:.1} |",
            r.pixels,
            r.schedule,
            r.ranks,
            r.total * r.share(true) * 1e3,
            primary.predict(r.terms()) * 1e3
        );
    }

    let (n, bpp) = (3840 * 2160, 20);
    let schedules: Vec<CompositeSchedule> = [
        "direct",
        "binary-swap",
        "radix-k:2",
        "radix-k:4",
        "radix-k:8",
    ]
    .iter()
    .map(|s| s.parse().unwrap())
    .collect();
    let ps = [64, 256, 1024, 4096];
    println!("\nextrapolated to 3840x2160, 20 B/pixel (scaled fit), ms: exchange + gather = total");
    print!("| schedule |");
    for p in ps {
        print!(" {p} ranks |");
    }
    println!();
    println!("|---|{}", "---|".repeat(ps.len()));
    for schedule in &schedules {
        print!("| {schedule} |");
        for p in ps {
            let c = cost(schedule, p, n, bpp);
            let total = primary.predict(terms(schedule, p, n, bpp));
            let gather = primary.alpha * c.gather_messages as f64 + primary.beta * c.gather_bytes;
            print!(
                " {:.0} + {:.0} = {:.0} |",
                (total - gather) * 1e3,
                gather * 1e3,
                total * 1e3
            );
        }
        println!();
    }
    println!("\nmodel figures behind it (messages per rank, MB sent per rank in the exchange):");
    for schedule in &schedules {
        let cells: Vec<String> = ps
            .iter()
            .map(|&p| {
                let c = cost(schedule, p, n, bpp);
                format!(
                    "{p}: {} msgs, {:.1} MB, {} rounds",
                    c.messages_per_rank,
                    c.bytes_per_rank / 1e6,
                    c.rounds
                )
            })
            .collect();
        println!("  {schedule}: {}", cells.join("; "));
    }
}
