//! The test harness for functor twins: what a test that runs the same
//! functors on the CPU backend and on this one (through their WGSL twins)
//! needs to compare them. Both the generic functors' tests (this crate's
//! `tests/backend/gpu_functors.rs`) and the tracer's
//! (`dpp-tracer`'s `functors/wgsl/agreement.rs`) use it, so that they draw
//! inputs from one generator ([`SplitMix64`]), state how closely the backends
//! must agree in one vocabulary ([`Tolerance`], [`Within`]), compare values
//! with one routine ([`compare_cells`]) and report in one format
//! ([`Report`]).

use dpp_runtime::column::{ulp_distance, Scalar as Cell};
use dpp_runtime::{ElemType, RecordRegistry};
use std::collections::BTreeMap;
use std::fmt::Write;

pub use dpp_runtime::random::SplitMix64;

/// How closely a float of the GPU must match the CPU's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Tolerance {
    /// Every bit, NaN payloads and the signs of zeros included.
    Bits,
    /// Every bit, but any NaN matches any NaN (WGSL fixes no NaN payload).
    Exact,
    /// [`Tolerance::Exact`], but `+0` matches `-0`.
    ZeroSign,
    /// Within this many units in the last place (NaN matches NaN).
    Ulp(u32),
    /// NaN matches any NaN, infinities only themselves, and finite values
    /// agree when `|gpu - cpu| <= max(abs, rel * max(|cpu|, |gpu|))`.
    Relative { rel: f32, abs: f32 },
}

impl Tolerance {
    /// Whether the GPU's `gpu` is close enough to the CPU's `cpu`. On a GPU
    /// that flushes subnormals to zero (which WGSL allows), a result whose
    /// exact value is subnormal may be a zero of its sign there, also where
    /// the CPU rounds it up to the least normal float (seen on an NVIDIA H100).
    pub fn floats_agree(self, cpu: f32, gpu: f32, gpu_flushes_subnormals: bool) -> bool {
        if cpu.to_bits() == gpu.to_bits() {
            return true;
        }
        let tiny = cpu.is_subnormal() || cpu.abs() == f32::MIN_POSITIVE;
        if gpu_flushes_subnormals && tiny && gpu == 0.0 {
            return cpu.is_sign_negative() == gpu.is_sign_negative();
        }
        if self == Tolerance::Bits {
            return false;
        }
        if cpu.is_nan() || gpu.is_nan() {
            return cpu.is_nan() && gpu.is_nan();
        }
        match self {
            Tolerance::ZeroSign => cpu == 0.0 && gpu == 0.0,
            Tolerance::Ulp(n) => ulp_distance(cpu, gpu) <= u64::from(n),
            Tolerance::Relative { rel, abs } => {
                cpu.is_finite()
                    && gpu.is_finite()
                    && (cpu - gpu).abs() <= abs.max(rel * cpu.abs().max(gpu.abs()))
            }
            Tolerance::Bits | Tolerance::Exact => false,
        }
    }

    /// Integers exactly, floats by [`Tolerance::floats_agree`].
    pub fn cells_agree(self, cpu: Cell, gpu: Cell, gpu_flushes_subnormals: bool) -> bool {
        match (cpu, gpu) {
            (Cell::Float(a), Cell::Float(b)) => self.floats_agree(a, b, gpu_flushes_subnormals),
            (a, b) => a == b,
        }
    }
}

/// A tolerance and why it is enough.
#[derive(Clone, Copy, Debug)]
pub struct Within {
    pub tolerance: Tolerance,
    pub why: &'static str,
}

/// `x` for integers, `x (bits)` for floats.
pub fn cell_text(cell: Cell) -> String {
    match cell {
        Cell::Int(x) => x.to_string(),
        Cell::Float(x) => format!("{x:?} ({:#010x})", x.to_bits()),
    }
}

/// One cell as [`cell_text`], several as a tuple.
pub fn cells_text(cells: &[Cell]) -> String {
    let text: Vec<String> = cells.iter().map(|cell| cell_text(*cell)).collect();
    match text.len() {
        1 => text[0].clone(),
        _ => format!("({})", text.join(", ")),
    }
}

/// The names of the cells of an element of type `ty` (as `Column::scalars_of`
/// lists them): `value` for a scalar, `.x`…`.w` for vector components,
/// field paths for records (`hit.t`).
pub fn cell_names(ty: ElemType, records: &RecordRegistry) -> Vec<String> {
    let mut names = Vec::new();
    push_cell_names(ty, records, "", &mut names);
    names
}

fn push_cell_names(ty: ElemType, records: &RecordRegistry, prefix: &str, out: &mut Vec<String>) {
    let components = |n: usize, out: &mut Vec<String>| {
        out.extend(
            ["x", "y", "z", "w"][..n]
                .iter()
                .map(|c| format!("{prefix}.{c}")),
        )
    };
    match ty {
        ElemType::Vec2 => components(2, out),
        ElemType::Vec3 => components(3, out),
        ElemType::Vec4 => components(4, out),
        ElemType::Record(id) => {
            for (name, field) in &records.get(id).fields {
                let name = match prefix {
                    "" => name.clone(),
                    _ => format!("{prefix}.{name}"),
                };
                push_cell_names(*field, records, &name, out);
            }
        }
        _ => out.push(match prefix {
            "" => "value".into(),
            _ => prefix.into(),
        }),
    }
}

/// The comparison of one element: each cell that disagrees, described as
/// `{name} is {cpu} on the CPU, {gpu} on the GPU` (`names` from
/// [`cell_names`]); every float pair is also recorded in `differences` under
/// `functor` and the cell's name.
pub fn compare_cells(
    cpu: &[Cell],
    gpu: &[Cell],
    names: &[String],
    tolerance: Tolerance,
    gpu_flushes_subnormals: bool,
    differences: &mut Differences,
    functor: &str,
) -> Vec<String> {
    if cpu.len() != gpu.len() {
        return vec![format!(
            "{} cells on the CPU, {} on the GPU",
            cpu.len(),
            gpu.len()
        )];
    }
    let mut differing = Vec::new();
    for (f, (&x, &y)) in cpu.iter().zip(gpu).enumerate() {
        let name = names.get(f).map_or("value", String::as_str);
        if let (Cell::Float(x), Cell::Float(y)) = (x, y) {
            differences.record(functor, name, x, y);
        }
        if !tolerance.cells_agree(x, y, gpu_flushes_subnormals) {
            differing.push(format!(
                "{name} is {} on the CPU, {} on the GPU",
                cell_text(x),
                cell_text(y)
            ));
        }
    }
    differing
}

/// What a case that both backends must refuse found: `Ok` where both failed
/// with `text` in their messages.
pub fn both_fail<T, U>(
    label: &str,
    text: &str,
    cpu: Result<T, String>,
    gpu: Result<U, String>,
) -> Result<(), String> {
    match (cpu, gpu) {
        (Err(cpu), Err(gpu)) if cpu.contains(text) && gpu.contains(text) => Ok(()),
        (cpu, gpu) => Err(format!(
            "{label}: both backends should fail with `{text}`; CPU: {:?}, GPU: {:?}",
            cpu.err(),
            gpu.err()
        )),
    }
}

/// The largest differences seen between the backends' floats, per functor
/// and cell.
#[derive(Default)]
pub struct Differences {
    cells: BTreeMap<(String, String), CellDifferences>,
}

#[derive(Default)]
struct CellDifferences {
    compared: usize,
    differing: usize,
    max_ulps: u64,
    max_abs: f32,
    max_rel: f32,
}

impl Differences {
    pub fn record(&mut self, functor: &str, cell: &str, cpu: f32, gpu: f32) {
        let stats = self
            .cells
            .entry((functor.to_string(), cell.to_string()))
            .or_default();
        stats.compared += 1;
        if cpu.to_bits() == gpu.to_bits() || !cpu.is_finite() || !gpu.is_finite() {
            return;
        }
        stats.differing += 1;
        let abs = (cpu - gpu).abs();
        stats.max_ulps = stats.max_ulps.max(ulp_distance(cpu, gpu));
        stats.max_abs = stats.max_abs.max(abs);
        stats.max_rel = stats.max_rel.max(abs / cpu.abs().max(gpu.abs()));
    }

    /// One line per cell whose floats differed anywhere.
    pub fn table(&self) -> String {
        let mut text = String::from(
            "largest CPU/GPU differences of float cells (cells not listed agree in every bit):\n",
        );
        for ((functor, cell), s) in &self.cells {
            if s.differing > 0 {
                let _ = writeln!(
                    text,
                    "  {functor:14} {cell:14} {:6} of {:7} differ; max {:4} ULP, abs {:.2e}, rel {:.2e}",
                    s.differing, s.compared, s.max_ulps, s.max_abs, s.max_rel
                );
            }
        }
        text
    }
}

/// The outcome of a table of cases: every disagreement, and the largest
/// float differences of those that agreed.
#[derive(Default)]
pub struct Report {
    cases: usize,
    failures: Vec<String>,
    pub differences: Differences,
}

impl Report {
    /// Counts one case and keeps its disagreements.
    pub fn case(&mut self, failures: impl IntoIterator<Item = String>) {
        self.cases += 1;
        self.failures.extend(failures);
    }

    /// Prints the differences table (see `--nocapture`) and fails with every
    /// disagreement, if any.
    pub fn assert_agreement(&self) {
        eprintln!("{} cases\n{}", self.cases, self.differences.table());
        assert!(
            self.failures.is_empty(),
            "{} disagreement(s) between the backends in {} cases:\n{}",
            self.failures.len(),
            self.cases,
            self.failures.join("\n")
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tolerances_order_from_bits_to_relative() {
        let nan = f32::from_bits(0x7fc0_0001);
        assert!(!Tolerance::Bits.floats_agree(f32::NAN, nan, false));
        assert!(Tolerance::Exact.floats_agree(f32::NAN, nan, false));
        assert!(!Tolerance::Exact.floats_agree(0.0, -0.0, false));
        assert!(Tolerance::ZeroSign.floats_agree(0.0, -0.0, false));
        assert!(Tolerance::Ulp(1).floats_agree(1.0, f32::from_bits(0x3f80_0001), false));
        let relative = Tolerance::Relative {
            rel: 1e-5,
            abs: 1e-6,
        };
        assert!(relative.floats_agree(1.0, 1.000_005, false));
        assert!(!relative.floats_agree(f32::INFINITY, f32::MAX, false));
        assert!(Tolerance::Bits.floats_agree(-1.0e-40, -0.0, true));
        assert!(!Tolerance::Bits.floats_agree(-1.0e-40, 0.0, true));
    }
}
