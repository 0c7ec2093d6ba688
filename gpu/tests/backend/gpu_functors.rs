//! Every generic functor on both backends: the same inputs (random, led by
//! every pair of each type's edge values) through small pipelines, for every
//! element type the functor's signature admits, on the CPU backend and on the
//! GPU backend (its WGSL twin), at sizes on both sides of the workgroup (64)
//! and of the CPU chunk (4096). Each case states how closely the backends
//! must agree and why.

use crate::data::Data;
use dpp_gpu::agreement::{
    both_fail, cell_names, cells_text, compare_cells, Differences, Report, SplitMix64, Tolerance,
};
use dpp_gpu::{run_plan_gpu, GpuContext, GpuRunContext};
use dpp_runtime::column::Scalar as Cell;
use dpp_runtime::cpu::column_pool::ColumnPool;
use dpp_runtime::cpu::exec::{run_plan, RunContext};
use dpp_runtime::cpu::kernels::DEFAULT_CHUNK;
use dpp_runtime::interpret::OutputValue;
use dpp_runtime::interpret::{RunError, RunResult};
use dpp_runtime::*;
use glam::{Vec2, Vec3, Vec4};
use std::f32::consts::PI;
use std::fmt::Write;
use std::path::Path;
use std::sync::Arc;

/// Sizes `n`: empty, one element, one short of and just past a workgroup,
/// and past the CPU chunk.
const SIZES: [usize; 5] = [0, 1, 63, 65, 5000];
/// `k` of `gather<f>(…, group: k)` and `scatter<f>(…, fanout: k)`.
const K: usize = 3;

/// An element type of the table: the primitives and the record `Pair`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Ty {
    Bool,
    U32,
    I32,
    F32,
    V2,
    V3,
    V4,
    Pair,
}

const BOOL: &[Ty] = &[Ty::Bool];
const U32: &[Ty] = &[Ty::U32];
const INTEGER: &[Ty] = &[Ty::U32, Ty::I32];
const SCALAR: &[Ty] = &[Ty::U32, Ty::I32, Ty::F32];
const SCALAR_OR_BOOL: &[Ty] = &[Ty::Bool, Ty::U32, Ty::I32, Ty::F32];
const FLOATS: &[Ty] = &[Ty::F32, Ty::V2, Ty::V3, Ty::V4];
const VECTORS: &[Ty] = &[Ty::V2, Ty::V3, Ty::V4];
const SIGNED: &[Ty] = &[Ty::I32, Ty::F32, Ty::V2, Ty::V3, Ty::V4];
const F32: &[Ty] = &[Ty::F32];
const INTEGER_OR_VECTOR: &[Ty] = &[Ty::U32, Ty::I32, Ty::V2, Ty::V3, Ty::V4];
const NUMERIC: &[Ty] = &[Ty::U32, Ty::I32, Ty::F32, Ty::V2, Ty::V3, Ty::V4];
const ANY: &[Ty] = &[
    Ty::Bool,
    Ty::U32,
    Ty::I32,
    Ty::F32,
    Ty::V2,
    Ty::V3,
    Ty::V4,
    Ty::Pair,
];

impl Ty {
    fn data_functor(self) -> &'static str {
        match self {
            Ty::Bool => "boolData",
            Ty::U32 => "u32Data",
            Ty::I32 => "i32Data",
            Ty::F32 => "f32Data",
            Ty::V2 => "vec2Data",
            Ty::V3 => "vec3Data",
            Ty::V4 => "vec4Data",
            Ty::Pair => "pairData",
        }
    }

    fn elem_type(self, pair: RecordId) -> ElemType {
        match self {
            Ty::Bool => ElemType::Bool,
            Ty::U32 => ElemType::U32,
            Ty::I32 => ElemType::I32,
            Ty::F32 => ElemType::F32,
            Ty::V2 => ElemType::Vec2,
            Ty::V3 => ElemType::Vec3,
            Ty::V4 => ElemType::Vec4,
            Ty::Pair => ElemType::Record(pair),
        }
    }
}

/// How an input column's values are drawn (see [`column`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Values {
    /// Every pair of the type's edge values first, then random values with edges mixed in.
    Any,
    /// [`Values::Any`] without integer zeros (divisors).
    NonZero,
    /// [`Values::Any`] with floats where WGSL bounds the error of `/` (as
    /// divisors) and of `log`: `|x|` in `[2^-126, 2^126]`, or `±0`, `±inf`,
    /// NaN (others become 3).
    Bounded,
    /// Floats in `[-π, π]`: where WGSL bounds the error of `sin` and `cos`;
    /// exponents whose powers of [`Values::Positive`] stay normal.
    Small,
    /// Positive normal floats of magnitude 2^-40 .. 2^40, where WGSL's `pow` is defined.
    Positive,
    /// [`Values::NonZero`] with a zero as the last element.
    ZeroAtEnd,
    /// Floats that are multiples of 1/4 of magnitude at most 256 (and `-0`):
    /// every sum of up to 5000 of them is exact, in any order.
    Sums,
    /// Floats `±1`, `±2`, `±1/2`, rarely `±0`: products in any order are exact.
    Products,
    /// `u32` indices below `m`.
    Index,
    /// Bools, true one time in ten.
    Flags,
}

/// An input's length: `n`, `n * k` (a group gather's source) or `m` (a scatter's target).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Len {
    N,
    Nk,
    M,
}

/// An input column of a case: `name = iota(len) → map<{type}Data>(column: i)`.
#[derive(Clone, Copy, Debug)]
struct Input {
    name: &'static str,
    /// `None`: the case's element type.
    ty: Option<Ty>,
    values: Values,
    len: Len,
}

const fn input(name: &'static str, values: Values) -> Input {
    Input {
        name,
        ty: None,
        values,
        len: Len::N,
    }
}

const fn typed(name: &'static str, ty: Ty, values: Values) -> Input {
    Input {
        name,
        ty: Some(ty),
        values,
        len: Len::N,
    }
}

const A: Input = input("a", Values::Any);
const B: Input = input("b", Values::Any);
const C: Input = input("c", Values::Any);
const D: Input = input("d", Values::Any);
const COND: Input = typed("cond", Ty::Bool, Values::Any);
const GROUPED: Input = Input {
    len: Len::Nk,
    ..input("x", Values::Any)
};

/// How the two backends' results must agree: within a [`Tolerance`], or
/// both failing with messages that contain a text.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Expect {
    Agree(Tolerance),
    Fails(&'static str),
}

const BITS: Expect = Expect::Agree(Tolerance::Bits);
const EXACT: Expect = Expect::Agree(Tolerance::Exact);
const ZERO_SIGN: Expect = Expect::Agree(Tolerance::ZeroSign);

const fn ulp(n: u32) -> Expect {
    Expect::Agree(Tolerance::Ulp(n))
}

/// A row of the table: `ops` (the pipeline's outputs, over the inputs) run
/// for each of `types` and each of [`SIZES`].
struct Case {
    functor: &'static str,
    types: &'static [Ty],
    inputs: &'static [Input],
    ops: &'static str,
    expect: Expect,
    /// Why that expectation.
    why: &'static str,
}

const fn case(
    functor: &'static str,
    types: &'static [Ty],
    inputs: &'static [Input],
    ops: &'static str,
    expect: Expect,
    why: &'static str,
) -> Case {
    Case {
        functor,
        types,
        inputs,
        ops,
        expect,
        why,
    }
}

use Expect::Fails;

const ROUNDED: &str = "WGSL's + - * are correctly rounded, like the CPU's; integers wrap on both";
const MOVE: &str = "a move: every bit is kept";
const NAN_LOSES: &str =
    "NaN loses on both; the sign of a (-0, +0) result is unspecified (the functor's doc)";
const GLAM: &str = "floats: NaN loses per component (f32::min), `a` on a tie, on both";
const CONVERTS: &str =
    "the twin converts on the bits like Rust's `as`: round to nearest even, saturate, NaN to 0";

/// `map` over one to three elements. Ops without `out` are the output `r`.
#[rustfmt::skip]
const ELEMENTWISE: &[Case] = &[
    case("add", NUMERIC, &[A, B], "map<add>(a, b)", EXACT, ROUNDED),
    case("sub", NUMERIC, &[A, B], "map<sub>(a, b)", EXACT, ROUNDED),
    case("mul", NUMERIC, &[A, B], "map<mul>(a, b)", EXACT, ROUNDED),
    case("min", INTEGER_OR_VECTOR, &[A, B], "map<min>(a, b)", EXACT, GLAM),
    case("min", &[Ty::F32], &[A, B], "map<min>(a, b)", ZERO_SIGN, NAN_LOSES),
    case("max", INTEGER_OR_VECTOR, &[A, B], "map<max>(a, b)", EXACT, GLAM),
    case("max", &[Ty::F32], &[A, B], "map<max>(a, b)", ZERO_SIGN, NAN_LOSES),
    case("or", BOOL, &[A, B], "map<or>(a, b)", EXACT, "logic"),
    case("and", BOOL, &[A, B], "map<and>(a, b)", EXACT, "logic"),
    case("div", INTEGER, &[A, input("b", Values::NonZero)], "map<div>(a, b)", EXACT,
        "integer division truncates on both; i32::MIN / -1 wraps"),
    case("div", INTEGER, &[A, input("b", Values::ZeroAtEnd)], "map<div>(a, b)",
        Fails("division by zero"), "an integer division by zero is a run-time error"),
    case("div", FLOATS, &[A, input("b", Values::Bounded)], "map<div>(a, b)", ulp(3),
        "WGSL's / is within 2.5 ULP for |b| in [2^-126, 2^126], the CPU's correctly rounded"),
    case("eq", SCALAR_OR_BOOL, &[A, B], "map<eq>(a, b)", EXACT, "exact; NaN is unequal"),
    case("ne", SCALAR_OR_BOOL, &[A, B], "map<ne>(a, b)", EXACT, "exact; NaN is unequal"),
    case("lt", SCALAR, &[A, B], "map<lt>(a, b)", EXACT, "exact; NaN is unordered"),
    case("le", SCALAR, &[A, B], "map<le>(a, b)", EXACT, "exact; NaN is unordered"),
    case("gt", SCALAR, &[A, B], "map<gt>(a, b)", EXACT, "exact; NaN is unordered"),
    case("ge", SCALAR, &[A, B], "map<ge>(a, b)", EXACT, "exact; NaN is unordered"),
    case("not", BOOL, &[A], "map<not>(a)", EXACT, "logic"),
    case("isZero", SCALAR, &[A], "map<isZero>(a)", EXACT, "on the bits: -0 is zero, NaN is not"),
    case("nonZero", SCALAR, &[A], "map<nonZero>(a)", EXACT, "on the bits: -0 is zero, NaN is not"),
    case("toU32", SCALAR_OR_BOOL, &[A], "map<toU32>(a)", BITS, CONVERTS),
    case("toI32", SCALAR_OR_BOOL, &[A], "map<toI32>(a)", BITS, CONVERTS),
    case("toF32", SCALAR_OR_BOOL, &[A], "map<toF32>(a)", BITS, CONVERTS),
    case("select", ANY, &[COND, A, B], "map<select>(cond, a, b)", BITS, MOVE),
    case("identity", ANY, &[A], "map<identity>(a)", BITS, MOVE),
    case("hash", U32, &[A], "map<hash>(a)", EXACT, "integer arithmetic, wrapping on both"),
    case("random", U32, &[A], "map<random>(a)", EXACT, "24 bits times 2^-24, exact on both"),
];

const EXACT_ON_LAVAPIPE: &str =
    "+ - * / and sqrt are correctly rounded on lavapipe, which fuses no \
    multiply-add here; a GPU that fuses (WGSL allows it) may differ (docs/language.md §7)";

/// The maths of element-wise expressions (`runtime/src/generic/math.rs`).
#[rustfmt::skip]
const MATH: &[Case] = &[
    case("neg", SIGNED, &[A], "map<neg>(a)", BITS, "the sign bit flipped; i32 wraps on both"),
    case("abs", FLOATS, &[A], "map<abs>(a)", BITS, "the sign bit cleared"),
    case("floor", FLOATS, &[A], "map<floor>(a)", EXACT, "exact in WGSL"),
    case("ceil", FLOATS, &[A], "map<ceil>(a)", EXACT, "exact in WGSL"),
    case("fract", FLOATS, &[A], "map<fract>(a)", EXACT, "x - floor(x): both exact"),
    case("sqrt", FLOATS, &[A], "map<sqrt>(a)", EXACT, EXACT_ON_LAVAPIPE),
    case("rsqrt", FLOATS, &[A], "map<rsqrt>(a)", ulp(2),
        "WGSL's inverseSqrt is within 2 ULP (0 measured on lavapipe)"),
    case("exp", FLOATS, &[A], "map<exp>(a)",
        Expect::Agree(Tolerance::Relative { rel: 181.0 / 8_388_608.0, abs: f32::MIN_POSITIVE }),
        "WGSL's exp is within 3 + 2|x| ULP (|x| < 89 where it is finite and normal); \
         lavapipe flushes results below the normal range to 0"),
    case("log", FLOATS, &[input("a", Values::Bounded)], "map<log>(a)",
        Expect::Agree(Tolerance::Relative { rel: 3.0 / 8_388_608.0, abs: 1.0 / 2_097_152.0 }),
        "WGSL's log: 2^-21 absolute in [0.5, 2], 3 ULP elsewhere, for normal x"),
    case("sin", FLOATS, &[input("a", Values::Small)], "map<sin>(a)",
        Expect::Agree(Tolerance::Relative { rel: 0.0, abs: 1.0 / 2048.0 }),
        "WGSL's sin is within 2^-11 absolute in [-π, π] (1 ULP measured on lavapipe)"),
    case("cos", FLOATS, &[input("a", Values::Small)], "map<cos>(a)",
        Expect::Agree(Tolerance::Relative { rel: 0.0, abs: 1.0 / 2048.0 }),
        "WGSL's cos is within 2^-11 absolute in [-π, π] (1 ULP measured on lavapipe)"),
    case("pow", FLOATS, &[input("a", Values::Positive), input("b", Values::Small)], "map<pow>(a, b)",
        Expect::Agree(Tolerance::Relative { rel: 4e-5, abs: f32::MIN_POSITIVE }),
        "WGSL's pow is exp2(b log2 a), defined for a > 0: within 3 + 2|b log2 a| ULP of exp2 \
         and log2's error times b (6.1e-6 measured on lavapipe, which flushes results below the \
         normal range to 0)"),
    case("clamp", FLOATS, &[A, B, C], "map<clamp>(a, b, c)", ZERO_SIGN, NAN_LOSES),
    case("mix", FLOATS, &[A, B, C], "map<mix>(a, b, c)", EXACT, EXACT_ON_LAVAPIPE),
    case("step", FLOATS, &[A, B], "map<step>(a, b)", EXACT, "a comparison; NaN gives 0 on both"),
    case("smoothstep", FLOATS, &[A, B, C], "map<smoothstep>(a, b, c)", EXACT, EXACT_ON_LAVAPIPE),
    case("dot", VECTORS, &[A, B], "map<dot>(a, b)", EXACT, EXACT_ON_LAVAPIPE),
    case("cross", &[Ty::V3], &[A, B], "map<cross>(a, b)", EXACT, EXACT_ON_LAVAPIPE),
    case("length", VECTORS, &[A], "map<length>(a)", EXACT, EXACT_ON_LAVAPIPE),
    case("distance", VECTORS, &[A, B], "map<distance>(a, b)", EXACT, EXACT_ON_LAVAPIPE),
    case("normalize", VECTORS, &[A], "map<normalize>(a)", EXACT, EXACT_ON_LAVAPIPE),
    case("reflect", VECTORS, &[A, B], "map<reflect>(a, b)", EXACT, EXACT_ON_LAVAPIPE),
    case("vec2", F32, &[A, B], "map<vec2>(a, b)", BITS, MOVE),
    case("vec3", F32, &[A, B, C], "map<vec3>(a, b, c)", BITS, MOVE),
    case("vec4", F32, &[A, B, C, D], "map<vec4>(a, b, c, d)", BITS, MOVE),
    case("splat2", F32, &[A], "map<splat2>(a)", BITS, MOVE),
    case("splat3", F32, &[A], "map<splat3>(a)", BITS, MOVE),
    case("splat4", F32, &[A], "map<splat4>(a)", BITS, MOVE),
    case("component", &[Ty::V2], &[A],
        "out x = map<component>(a, index: 0)
         out y = map<component>(a, index: 1)", BITS, MOVE),
    case("component", &[Ty::V3], &[A],
        "out x = map<component>(a, index: 0)
         out y = map<component>(a, index: 1)
         out z = map<component>(a, index: 2)", BITS, MOVE),
    case("component", &[Ty::V4], &[A],
        "out x = map<component>(a, index: 0)
         out w = map<component>(a, index: 3)", BITS, MOVE),
    case("component", &[Ty::V3], &[A], "map<component>(a, index: 3)",
        Fails("out of range for vec3"), "an index beyond the vector is a run-time error"),
    case("component", VECTORS, &[A], "map<component>(a, index: -1)",
        Fails("out of range"), "a negative index is a run-time error"),
    case("rem", INTEGER, &[A, input("b", Values::NonZero)], "map<rem>(a, b)", EXACT,
        "integer remainders are exact; i32::MIN % -1 is 0 on both"),
    case("rem", INTEGER, &[A, input("b", Values::ZeroAtEnd)], "map<rem>(a, b)",
        Fails("division by zero"), "an integer remainder by zero is a run-time error"),
    case("rem", F32, &[A, input("b", Values::Bounded)], "map<rem>(a, b)", EXACT,
        "a - b * trunc(a / b) on both; a GPU whose / is not correctly rounded may differ by b"),
];

/// `hash` and `random` with the named argument `seed`, taken modulo 2^32:
/// negative, i32::MIN, above 2^31 (`hBig` and `hBigWrapped` are the same
/// seed modulo 2^32). Wider seeds: see `integer_arguments_beyond_32_bits_…`.
#[rustfmt::skip]
const NAMED: &[Case] = &[
    case("hash", U32, &[A],
        "out h0 = map<hash>(a, seed: 0)
         out h1 = map<hash>(a, seed: 1)
         out hNegative = map<hash>(a, seed: -7)
         out hMin = map<hash>(a, seed: -2147483648)
         out hBig = map<hash>(a, seed: 3000000000)
         out hBigWrapped = map<hash>(a, seed: -1294967296)",
        EXACT, "integer arithmetic, wrapping on both"),
    case("random", U32, &[A],
        "out r1 = map<random>(a, seed: 1)
         out rNegative = map<random>(a, seed: -1)
         out rBig = map<random>(a, seed: 4294967295)",
        EXACT, "24 bits times 2^-24, exact on both"),
];

/// What every monoid case computes (`{op}` is the case's functor): a
/// reduction, scans (plain, exclusive, segmented) and a combining scatter.
const MONOID_OPS: &str = "out total = reduce<{op}>(a)
    out inclusive = scan<{op}>(a)
    out exclusive = exclusiveScan<{op}>(a)
    out segmented = scan<{op}>(a, segments: flags)
    out segmentedExclusive = exclusiveScan<{op}>(a, segments: flags)
    out combined = scatter<{op}>(idx, a, into: dst)";

const fn monoid_inputs(values: Values) -> [Input; 4] {
    [
        input("a", values),
        typed("flags", Ty::Bool, Values::Flags),
        typed("idx", Ty::U32, Values::Index),
        Input {
            len: Len::M,
            ..input("dst", values)
        },
    ]
}

const SUMS: &[Input] = &monoid_inputs(Values::Sums);
const PRODUCTS: &[Input] = &monoid_inputs(Values::Products);
const ANY_MONOID: &[Input] = &monoid_inputs(Values::Any);

/// The monoids in the primitives that combine in an order of their own on
/// the GPU (trees of partials, atomics).
#[rustfmt::skip]
const MONOIDS: &[Case] = &[
    case("add", NUMERIC, SUMS, MONOID_OPS, EXACT,
        "float inputs whose sums are exact in any order; integers wrap"),
    case("mul", NUMERIC, PRODUCTS, MONOID_OPS, EXACT,
        "float inputs whose products are exact in any order; integers wrap"),
    case("min", INTEGER, ANY_MONOID, MONOID_OPS, EXACT, "exact"),
    case("min", FLOATS, ANY_MONOID, MONOID_OPS, ZERO_SIGN,
        "NaN loses (per component), so any order gives the same value; -0 and +0 tie"),
    case("max", INTEGER, ANY_MONOID, MONOID_OPS, EXACT, "exact"),
    case("max", FLOATS, ANY_MONOID, MONOID_OPS, ZERO_SIGN,
        "NaN loses (per component), so any order gives the same value; -0 and +0 tie"),
    case("or", BOOL, ANY_MONOID, MONOID_OPS, EXACT, "logic"),
    case("and", BOOL, ANY_MONOID, MONOID_OPS, EXACT, "logic"),
];

/// `gather<f>(x, group: k)` and `scatter<f>(a, fanout: k)`.
#[rustfmt::skip]
const GROUPED_CASES: &[Case] = &[
    case("sum", NUMERIC, &[GROUPED], "gather<sum>(x, group: k)", EXACT,
        "both add in the same order, left to right from zero"),
    case("average", SCALAR_OR_BOOL, &[GROUPED], "gather<average>(x, group: k)", ulp(3),
        "the same in-order sum, then WGSL's / (2.5 ULP) by k"),
    case("repeat", ANY, &[A], "scatter<repeat>(a, fanout: k)", BITS, MOVE),
    case("lane", ANY, &[A], "scatter<lane>(a, fanout: k)", EXACT, "lane numbers"),
];

// ---------------------------------------------------------------------------
// Inputs

const U32_EDGES: &[u32] = &[
    0,
    1,
    2,
    7,
    1000,
    0x7fff_ffff,
    0x8000_0000,
    0xffff_fffe,
    u32::MAX,
    0x00ff_ffff,
    0x0100_0000,
    0x0100_0001, // rounds to even (down) as f32
    0x0100_0003, // rounds to even (up) as f32
    0x7fff_ffc0, // a tie as f32: rounds to 2^31
    0xffff_ff80, // a tie as f32: rounds to 2^32
    0xffff_ff7f, // just below the tie
    0x8000_0001,
];

const I32_EDGES: &[i32] = &[
    0,
    1,
    -1,
    2,
    -2,
    -7,
    i32::MIN,
    i32::MIN + 1,
    i32::MAX,
    16_777_217,
    -16_777_217,
    16_777_219,
    -2_147_483_584, // a tie as f32
    0x7fff_ffc0,
];

fn f32_edges() -> Vec<f32> {
    let mut edges = vec![
        0.0,
        -0.0,
        1.0,
        -1.0,
        0.5,
        -1.5,
        2.5,
        -0.999_999_94,
        3.0,
        f32::NAN,
        f32::from_bits(0xffc0_0123), // a negative NaN with a payload
        f32::from_bits(0x7f80_0001), // a signalling NaN
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::MAX,
        -f32::MAX,
        f32::MIN_POSITIVE,
        -f32::MIN_POSITIVE,
        16_777_216.0,
        2_147_483_520.0, // the largest f32 below 2^31
        2_147_483_648.0,
        -2_147_483_648.0,
        -2_147_483_904.0, // the first f32 below -2^31
        4_294_967_040.0,  // the largest f32 below 2^32
        4_294_967_296.0,
        3.0e9,
        -3.0e9,
        1.0e20,
        -1.0e-20,
    ];
    if !flushes_subnormals() {
        edges.extend([1.0e-40, -1.0e-45]);
    }
    edges
}

/// Whether the GPU flushes subnormal floats to zero, which WGSL allows
/// (llvmpipe does not): then the inputs hold none, and a subnormal result
/// may be a zero of the same sign on the GPU.
static FLUSHES_SUBNORMALS: std::sync::OnceLock<bool> = std::sync::OnceLock::new();

fn flushes_subnormals() -> bool {
    FLUSHES_SUBNORMALS.get().copied().unwrap_or(false)
}

fn probe_subnormals(setup: &Setup, gpu: &GpuContext) {
    FLUSHES_SUBNORMALS.get_or_init(|| {
        let source = "pipeline probe {
            a = iota(2) → map<f32Data>(column: 0)
            b = iota(2) → map<f32Data>(column: 1)
            out r = map<mul>(a, b)
        }";
        let plan = compile_text(
            Path::new("probe.dpp"),
            source,
            &setup.library,
            &CompileOptions::default(),
        )
        .unwrap_or_else(|e| panic!("{}", e.render(false)));
        // A subnormal input, and a subnormal result.
        let data = Data::new(vec![
            Column::F32(vec![1.0e-40, f32::MIN_POSITIVE]),
            Column::F32(vec![1.0, 0.5]),
        ]);
        let outputs = run_gpu(setup, gpu, &plan, &data).unwrap().outputs;
        let OutputValue::Array(products) = &outputs[0].1 else {
            panic!("the probe's output is an array")
        };
        let flushes = products.view().as_f32().contains(&0.0);
        if flushes {
            eprintln!("the GPU flushes subnormals to zero: testing without them");
        }
        flushes
    });
}

/// Element `i` of the `role`-th input column among the edges: the first
/// `E²` elements of roles 0 and 1 hold every pair of edges, other roles a
/// spread of them; `None` past that unless by chance.
fn edge_index(i: usize, role: usize, edges: usize, rng: &mut SplitMix64) -> Option<usize> {
    if i < edges * edges {
        return Some(match role {
            0 => i % edges,
            1 => i / edges,
            r => (i * 7 + r) % edges,
        });
    }
    rng.chance(4).then(|| rng.below(edges as u64) as usize)
}

fn random_u32(rng: &mut SplitMix64) -> u32 {
    if rng.chance(2) {
        rng.next_u64() as u32
    } else {
        rng.below(1000) as u32
    }
}

fn random_f32(rng: &mut SplitMix64) -> f32 {
    match rng.below(10) {
        0..=6 => {
            // A random normal float of magnitude 2^-40 .. 2^40.
            let exponent = rng.below(81) as u32 + 127 - 40;
            let sign = (rng.next_u64() as u32) & 0x8000_0000;
            f32::from_bits(sign | exponent << 23 | (rng.next_u64() as u32 & 0x7f_ffff))
        }
        7 | 8 => rng.below(201) as f32 - 100.0,
        _ => (rng.below(64) as f32 - 32.0) / 8.0,
    }
}

fn bools(n: usize, role: usize, values: Values, rng: &mut SplitMix64) -> Vec<bool> {
    (0..n)
        .map(|i| match values {
            Values::Flags => rng.chance(10),
            _ if i < 4 => (if role == 0 { i & 1 } else { i >> 1 & 1 }) == 1,
            _ => rng.chance(2),
        })
        .collect()
}

fn u32s(n: usize, role: usize, values: Values, m: usize, rng: &mut SplitMix64) -> Vec<u32> {
    let mut column: Vec<u32> = (0..n)
        .map(|i| match values {
            Values::Index => rng.below(m as u64) as u32,
            _ => match edge_index(i, role, U32_EDGES.len(), rng) {
                Some(e) => U32_EDGES[e],
                None => random_u32(rng),
            },
        })
        .collect();
    nonzero(&mut column, values, 1);
    column
}

fn i32s(n: usize, role: usize, values: Values, rng: &mut SplitMix64) -> Vec<i32> {
    let mut column: Vec<i32> = (0..n)
        .map(|i| match edge_index(i, role, I32_EDGES.len(), rng) {
            Some(e) => I32_EDGES[e],
            None if rng.chance(2) => rng.next_u64() as i32,
            None => rng.below(2001) as i32 - 1000,
        })
        .collect();
    nonzero(&mut column, values, 1);
    column
}

/// Integer divisors: no zero, or one at the end only.
fn nonzero<T: Copy + Default + PartialEq>(column: &mut [T], values: Values, one: T) {
    if matches!(values, Values::NonZero | Values::ZeroAtEnd) {
        for x in column.iter_mut().filter(|x| **x == T::default()) {
            *x = one;
        }
    }
    if values == Values::ZeroAtEnd {
        if let Some(last) = column.last_mut() {
            *last = T::default();
        }
    }
}

/// Component `component` of a float column (scalars have one).
fn f32s(n: usize, role: usize, component: usize, values: Values, rng: &mut SplitMix64) -> Vec<f32> {
    let edges = f32_edges();
    (0..n)
        .map(|i| match values {
            Values::Sums if rng.chance(16) => -0.0,
            Values::Sums => (rng.below(2049) as f32 - 1024.0) / 4.0,
            Values::Products if rng.chance(4096) => rng.pick(&[0.0, -0.0]),
            Values::Products if rng.chance(8) => rng.pick(&[2.0, -2.0, 0.5, -0.5]),
            Values::Products => rng.pick(&[1.0, -1.0]),
            Values::Small if i < 4 => [0.0, -0.0, PI, -PI][i],
            Values::Small => (rng.below(1 << 24) as f32 / (1 << 23) as f32 - 1.0) * PI,
            Values::Positive => match random_f32(rng).abs() {
                0.0 => 1.0,
                x => x,
            },
            _ => {
                let x = match edge_index(i + component, role, edges.len(), rng) {
                    Some(e) => edges[e],
                    None => random_f32(rng),
                };
                let bounded = x == 0.0 || x.is_nan() || x.is_infinite() || {
                    let magnitude = x.abs();
                    (2f32.powi(-126)..=2f32.powi(126)).contains(&magnitude)
                };
                match values {
                    Values::Bounded if !bounded => 3.0,
                    _ => x,
                }
            }
        })
        .collect()
}

/// A column of `ty` for input `input`, the `role`-th of its case.
fn column(
    ty: Ty,
    pair: RecordId,
    len: usize,
    m: usize,
    role: usize,
    values: Values,
    rng: &mut SplitMix64,
) -> Column {
    let vectors = |components: usize, rng: &mut SplitMix64| -> Vec<Vec<f32>> {
        (0..components)
            .map(|c| f32s(len, role, c, values, rng))
            .collect()
    };
    match ty {
        Ty::Bool => Column::Bool(bools(len, role, values, rng)),
        Ty::U32 => Column::U32(u32s(len, role, values, m, rng)),
        Ty::I32 => Column::I32(i32s(len, role, values, rng)),
        Ty::F32 => Column::F32(f32s(len, role, 0, values, rng)),
        Ty::V2 => {
            let c = vectors(2, rng);
            Column::Vec2((0..len).map(|i| Vec2::new(c[0][i], c[1][i])).collect())
        }
        Ty::V3 => {
            let c = vectors(3, rng);
            Column::Vec3(
                (0..len)
                    .map(|i| Vec3::new(c[0][i], c[1][i], c[2][i]))
                    .collect(),
            )
        }
        Ty::V4 => {
            let c = vectors(4, rng);
            Column::Vec4(
                (0..len)
                    .map(|i| Vec4::new(c[0][i], c[1][i], c[2][i], c[3][i]))
                    .collect(),
            )
        }
        Ty::Pair => Column::Record {
            ty: pair,
            fields: vec![
                Arc::new(column(Ty::U32, pair, len, m, role, values, rng)),
                Arc::new(column(Ty::V3, pair, len, m, role, values, rng)),
                Arc::new(column(Ty::Bool, pair, len, m, role, values, rng)),
            ],
        },
    }
}

// ---------------------------------------------------------------------------
// Running and comparing

/// The generic functors, the record `Pair` and a `…Data` functor per [`Ty`].
struct Setup {
    library: FunctorLibrary,
    pair: RecordId,
}

fn setup() -> Setup {
    let mut library = crate::common::library();
    let pair = library.records.register(RecordType {
        name: "Pair".into(),
        fields: vec![
            ("count".into(), ElemType::U32),
            ("position".into(), ElemType::Vec3),
            ("hit".into(), ElemType::Bool),
        ],
        doc: "a test record".into(),
    });
    for ty in ANY {
        crate::data::register_data_functor(&mut library, ty.data_functor(), ty.elem_type(pair));
    }
    Setup { library, pair }
}

/// The pipeline of `case` for element type `ty`.
fn pipeline(case: &Case, ty: Ty) -> String {
    let mut text = String::from("param n = 0\nparam m = 1\nparam k = 1\npipeline t {\n");
    for (c, input) in case.inputs.iter().enumerate() {
        let len = match input.len {
            Len::N => "n",
            Len::Nk => "n * k",
            Len::M => "m",
        };
        let functor = input.ty.unwrap_or(ty).data_functor();
        let _ = writeln!(
            text,
            "    {} = iota({len}) → map<{functor}>(column: {c})",
            input.name
        );
    }
    let ops = case.ops.replace("{op}", case.functor);
    let ops = match ops.starts_with("out ") {
        true => ops,
        false => format!("out r = {ops}"),
    };
    for line in ops.lines() {
        let _ = writeln!(text, "    {}", line.trim());
    }
    text.push_str("}\n");
    text
}

fn host_cells(value: HostValue) -> Vec<Cell> {
    match value {
        HostValue::Bool(b) => vec![Cell::Int(b.into())],
        HostValue::Int(x) => vec![Cell::Int(x)],
        HostValue::Float(x) => vec![Cell::Float(x as f32)],
        HostValue::Vec2(v) => v.iter().map(|x| Cell::Float(*x)).collect(),
        HostValue::Vec3(v) => v.iter().map(|x| Cell::Float(*x)).collect(),
        HostValue::Vec4(v) => v.iter().map(|x| Cell::Float(*x)).collect(),
    }
}

/// One run of a case: its inputs and what each backend made of them.
struct Run<'a> {
    case: &'a Case,
    records: &'a RecordRegistry,
    ty: Ty,
    n: usize,
    data: Data,
}

impl Run<'_> {
    /// The inputs that element `i` of a map's (or group's, fan-out's) output reads.
    fn inputs_at(&self, i: usize) -> String {
        let mut text = String::new();
        for (input, column) in self.case.inputs.iter().zip(&self.data.columns) {
            let range = match (input.len, self.case.ops.contains("fanout")) {
                (Len::N, true) => i / K..i / K + 1,
                (Len::N, false) => i..i + 1,
                (Len::Nk, _) => i * K..i * K + K,
                (Len::M, _) => continue,
            };
            let values: Vec<String> = range
                .filter(|&j| j < column.len())
                .map(|j| {
                    let mut c = Vec::new();
                    column.scalars_of(j, &mut c);
                    cells_text(&c)
                })
                .collect();
            let _ = write!(text, " {} = {};", input.name, values.join(", "));
        }
        text
    }

    fn describe(&self) -> String {
        format!(
            "`{}` on {:?}, n = {} ({:?}: {})",
            self.case.functor, self.ty, self.n, self.case.expect, self.case.why
        )
    }
}

/// Compares one output of both backends; the first disagreement, described.
fn compare(
    run: &Run<'_>,
    name: &str,
    cpu: &OutputValue,
    gpu: &OutputValue,
    differences: &mut Differences,
) -> Option<String> {
    let Expect::Agree(tolerance) = run.case.expect else {
        unreachable!("only cases that agree compare outputs")
    };
    let (cpu_cells, gpu_cells): (Vec<Vec<Cell>>, Vec<Vec<Cell>>) = match (cpu, gpu) {
        (OutputValue::Host(a), OutputValue::Host(b)) => {
            (vec![host_cells(*a)], vec![host_cells(*b)])
        }
        (OutputValue::Array(a), OutputValue::Array(b)) => {
            if a.elem_type() != b.elem_type() || a.len() != b.len() {
                return Some(format!(
                    "{}: `{name}` is {:?} × {} on the CPU, {:?} × {} on the GPU",
                    run.describe(),
                    a.elem_type(),
                    a.len(),
                    b.elem_type(),
                    b.len()
                ));
            }
            let all = |column: &Column| {
                (0..column.len())
                    .map(|i| {
                        let mut c = Vec::new();
                        column.scalars_of(i, &mut c);
                        c
                    })
                    .collect()
            };
            (all(a), all(b))
        }
        _ => return Some(format!("{}: `{name}` differs in kind", run.describe())),
    };
    let names = match cpu {
        OutputValue::Array(column) => cell_names(column.elem_type(), run.records),
        OutputValue::Host(_) => Vec::new(),
    };
    let flushes = flushes_subnormals();
    let i = (0..cpu_cells.len()).find(|&i| {
        let (cpu, gpu) = (&cpu_cells[i], &gpu_cells[i]);
        let functor = run.case.functor;
        !compare_cells(cpu, gpu, &names, tolerance, flushes, differences, functor).is_empty()
    })?;
    let inputs = match cpu {
        OutputValue::Host(_) => String::from(" (a reduction: all inputs)"),
        OutputValue::Array(_) => run.inputs_at(i),
    };
    Some(format!(
        "{}: `{name}`[{i}] is {} on the CPU, {} on the GPU; inputs:{inputs}",
        run.describe(),
        cells_text(&cpu_cells[i]),
        cells_text(&gpu_cells[i]),
    ))
}

/// The plan of `case` for type `ty` and size `n`, and its inputs.
fn prepare(setup: &Setup, case: &Case, ty: Ty, n: usize) -> (Plan, Data) {
    let source = pipeline(case, ty);
    let m = n / 4 + 1;
    let overrides = [("n", n), ("m", m), ("k", K)]
        .map(|(name, value)| (name.to_string(), value.to_string()))
        .to_vec();
    let options = CompileOptions {
        fuse: true,
        overrides,
    };
    let plan = compile_text(
        Path::new("gpu_functors.dpp"),
        &source,
        &setup.library,
        &options,
    )
    .unwrap_or_else(|e| panic!("{}\n{source}", e.render(false)));
    let columns = case
        .inputs
        .iter()
        .enumerate()
        .map(|(role, input)| {
            let len = match input.len {
                Len::N => n,
                Len::Nk => n * K,
                Len::M => m,
            };
            let ty = input.ty.unwrap_or(ty);
            let mut rng =
                SplitMix64::from_text(&format!("{} {ty:?} {} {n}", case.functor, input.name));
            column(ty, setup.pair, len, m, role, input.values, &mut rng)
        })
        .collect();
    (plan, Data::new(columns))
}

fn run_cpu(setup: &Setup, plan: &Plan, data: &Data) -> Result<RunResult, RunError> {
    let uniforms = Uniforms::default();
    let context = RunContext {
        library: &setup.library,
        uniforms: &uniforms,
        resources: data,
        chunk: DEFAULT_CHUNK,
        column_pool: &ColumnPool::new(),
        elementwise: dpp_runtime::cpu::compiled::Elementwise::default(),
    };
    run_plan(plan, &context)
}

fn run_gpu(
    setup: &Setup,
    gpu: &GpuContext,
    plan: &Plan,
    data: &Data,
) -> Result<RunResult, RunError> {
    let uniforms = Uniforms::default();
    let context = GpuRunContext {
        gpu,
        library: &setup.library,
        uniforms: &uniforms,
        resources: data,
        profile: false,
    };
    run_plan_gpu(plan, &context)
}

/// Runs `case` on both backends for every type and size; returns the
/// disagreements (the first per output and run).
fn check(
    setup: &Setup,
    gpu: &GpuContext,
    case: &Case,
    differences: &mut Differences,
) -> Vec<String> {
    let mut failures = Vec::new();
    for &ty in case.types {
        for n in SIZES {
            let (plan, data) = prepare(setup, case, ty, n);
            let records = &setup.library.records;
            let run = Run {
                case,
                records,
                ty,
                n,
                data,
            };
            let cpu = run_cpu(setup, &plan, &run.data);
            let gpu = run_gpu(setup, gpu, &plan, &run.data);
            match (case.expect, cpu, gpu) {
                // Nothing to divide.
                (Fails(_), Ok(_), Ok(_)) if n == 0 => {}
                (Fails(text), cpu, gpu) => {
                    let (cpu, gpu) = (cpu.map_err(|e| e.message), gpu.map_err(|e| e.message));
                    failures.extend(both_fail(&run.describe(), text, cpu, gpu).err());
                }
                (_, Ok(cpu), Ok(gpu)) => {
                    for ((name, cpu), (gpu_name, gpu)) in cpu.outputs.iter().zip(&gpu.outputs) {
                        assert_eq!(name, gpu_name);
                        failures.extend(compare(&run, name, cpu, gpu, differences));
                    }
                }
                (_, cpu, gpu) => failures.push(format!(
                    "{}: CPU {:?}, GPU {:?}",
                    run.describe(),
                    cpu.err(),
                    gpu.err()
                )),
            }
        }
    }
    failures
}

/// Runs every case of `table`; fails with every disagreement found.
fn check_table(table: &[Case]) {
    let Some(gpu) = crate::gpu() else { return };
    let setup = setup();
    probe_subnormals(&setup, gpu);
    let mut report = Report::default();
    for case in table {
        let failures = check(&setup, gpu, case, &mut report.differences);
        report.case(failures);
    }
    report.assert_agreement();
}

#[test]
fn elementwise_functors_agree() {
    check_table(ELEMENTWISE);
}

#[test]
fn math_functors_agree() {
    check_table(MATH);
}

#[test]
fn monoids_agree_in_reductions_scans_and_combining_scatters() {
    check_table(MONOIDS);
}

#[test]
fn group_and_fanout_functors_agree() {
    check_table(GROUPED_CASES);
}

#[test]
fn seeds_are_taken_modulo_2_to_the_32_on_both_backends() {
    check_table(NAMED);
    // The seed matters, and only modulo 2^32 (on the CPU; the GPU agrees).
    let setup = setup();
    let (plan, data) = prepare(&setup, &NAMED[0], Ty::U32, 65);
    let outputs = run_cpu(&setup, &plan, &data).unwrap().outputs;
    let output = |name: &str| match outputs.iter().find(|(n, _)| n == name) {
        Some((_, OutputValue::Array(column))) => column.view().as_u32().to_vec(),
        other => panic!("{name}: {other:?}"),
    };
    assert_eq!(output("hBig"), output("hBigWrapped"));
    for (a, b) in [("h0", "h1"), ("h0", "hNegative"), ("h0", "hMin")] {
        assert_ne!(output(a), output(b), "{a} and {b}");
    }
}

/// The GPU passes integer arguments in 32 bits: a wider one (which the CPU
/// takes whole) is an error naming the argument, never a wrapped value.
#[test]
fn integer_arguments_beyond_32_bits_are_an_error_on_the_gpu() {
    let Some(gpu) = crate::gpu() else { return };
    let setup = setup();
    let case = case(
        "hash",
        U32,
        &[A],
        "out h = map<hash>(a, seed: 8589934599)",
        EXACT,
        "",
    );
    let (plan, data) = prepare(&setup, &case, Ty::U32, 65);
    assert!(run_cpu(&setup, &plan, &data).is_ok());
    let error = run_gpu(&setup, gpu, &plan, &data).unwrap_err().to_string();
    assert!(
        error.contains("`map<hash>` argument `seed`: 8589934599 does not fit in the 32 bits"),
        "{error}"
    );
}

/// The table leaves out no generic functor, no element type one admits, and
/// no monoid in reductions and scans.
#[test]
fn every_generic_functor_and_type_has_a_case() {
    let setup = setup();
    let tables = [ELEMENTWISE, MATH, NAMED, MONOIDS, GROUPED_CASES];
    for functor in crate::common::library().iter() {
        let signature = functor.signature();
        let variables: Vec<TypeConstraint> = signature
            .inputs
            .iter()
            .filter_map(|p| match p.ty {
                TypePattern::Var(_, constraint) => Some(constraint),
                TypePattern::Exact(_) => None,
            })
            .collect();
        let admits = |ty: Ty| {
            let elem = ty.elem_type(setup.pair);
            match variables.is_empty() {
                true => signature.inputs[0].ty == TypePattern::Exact(elem),
                false => variables.iter().all(|c| c.admits(elem)),
            }
        };
        for ty in ANY.iter().copied().filter(|ty| admits(*ty)) {
            let covered = tables
                .iter()
                .flat_map(|table| table.iter())
                .any(|case| case.functor == signature.name && case.types.contains(&ty));
            assert!(covered, "`{}` on {ty:?} has no case", signature.name);
        }
        if matches!(signature.kind, FunctorKind::Monoid(_)) {
            assert!(
                MONOIDS.iter().any(|case| case.functor == signature.name),
                "monoid `{}` has no reduce/scan case",
                signature.name
            );
        }
    }
}
