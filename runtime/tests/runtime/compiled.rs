//! The CPU backend's compiled element-wise runs (`cpu::compiled`): a fused
//! stage whose element-wise ops run as one machine-code loop gives the same
//! bits as the same stage run one op at a time over columns, for every
//! functor that compiles, on values chosen to break them (NaN, ±0, ±∞,
//! subnormals, integer extremes); and an element that fails fails the same
//! way.
//!
//! `check(source)` compiles `source` fused, runs it both ways on 2 threads
//! with small chunks of 98 elements (so that chunk edges, a short last
//! chunk, and the kernels' blocks of four and the elements after the last
//! block are all crossed), asserts that at least one run of ops was compiled, and compares every
//! output bit for bit.

use crate::common::{library, pipelines_path, trim_indent};
use dpp_runtime::compile::{compile_text, CompileOptions};
use dpp_runtime::cpu::column_pool::ColumnPool;
use dpp_runtime::cpu::compiled::Elementwise;
use dpp_runtime::cpu::exec::{run_plan, RunContext};
use dpp_runtime::functor::ClosureFunctor;
use dpp_runtime::interpret::{OutputValue, RunResult};
use dpp_runtime::signature::Signature;
use dpp_runtime::*;
use std::sync::Arc;

/// Floats that break arithmetic: NaN of both signs, signed zeros and
/// infinities, subnormals, the extremes, integers' edges as floats, and
/// ordinary values.
const EDGES: [f32; 24] = [
    f32::NAN,
    -f32::NAN,
    0.0,
    -0.0,
    f32::INFINITY,
    f32::NEG_INFINITY,
    1.0e-40,
    -1.0e-40,
    f32::MIN_POSITIVE,
    f32::MAX,
    f32::MIN,
    1.0,
    -1.0,
    0.5,
    -2.5,
    3.0,
    4_294_967_296.0,
    2_147_483_648.0,
    -2_147_483_904.0,
    16_777_217.0,
    0.1,
    7.25,
    -1.0e-3,
    100.0,
];

/// `edgeA(i)` and `edgeB(i)`: [`EDGES`] in two orders, so that every pair
/// of them meets within 24² elements (`i % 24` and `i / 24 % 24`).
fn edge_library() -> FunctorLibrary {
    let mut library = library();
    for (name, step) in [("edgeA", 1usize), ("edgeB", 24)] {
        let signature = Signature::map(name)
            .input("i", ElemType::U32)
            .output("out", ElemType::F32)
            .doc("test values");
        let functor = ClosureFunctor::new(signature, move |_, inputs, outputs| {
            let ColumnView::U32(indices) = &inputs[0] else {
                unreachable!("a u32 input")
            };
            let pick = |i: u32| {
                let i = i as usize;
                EDGES[(i / step) % EDGES.len()]
            };
            outputs[0] = Column::F32(indices.iter().map(|&i| pick(i)).collect());
            Ok(())
        });
        library.register(Arc::new(functor));
    }
    library
}

fn run(source: &str, elementwise: Elementwise) -> Result<RunResult, String> {
    let library = edge_library();
    let path = pipelines_path("compiled_test.dpp");
    let plan = compile_text(
        &path,
        &trim_indent(source),
        &library,
        &CompileOptions::default(),
    )
    .unwrap_or_else(|e| panic!("{}", e.render(false)));
    let uniforms = Uniforms::default();
    let context = RunContext {
        library: &library,
        uniforms: &uniforms,
        resources: &(),
        chunk: 98,
        column_pool: &ColumnPool::new(),
        elementwise,
    };
    let threads = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .expect("a thread pool");
    threads
        .install(|| run_plan(&plan, &context))
        .map_err(|e| e.message)
}

/// Every output's elements as bits (bools as 0 and 1), every NaN as one:
/// IEEE 754 leaves a NaN result's sign and payload open, and x86 takes them
/// from whichever operand an instruction names first, which two compilers
/// order differently (`a * b` or `b * a`); both are NaN where one is.
fn bits(result: &RunResult) -> Vec<(String, Vec<u32>)> {
    fn float(x: f32) -> u32 {
        if x.is_nan() {
            f32::NAN.to_bits()
        } else {
            x.to_bits()
        }
    }
    fn leaves(column: &Column, out: &mut Vec<u32>) {
        match column {
            Column::Bool(v) => out.extend(v.iter().map(|&b| u32::from(b))),
            Column::U32(v) => out.extend(v),
            Column::I32(v) => out.extend(v.iter().map(|&x| x as u32)),
            Column::F32(v) => out.extend(v.iter().map(|&x| float(x))),
            Column::Vec2(v) => out.extend(v.iter().flat_map(|x| x.to_array().map(float))),
            Column::Vec3(v) => out.extend(v.iter().flat_map(|x| x.to_array().map(float))),
            Column::Vec4(v) => out.extend(v.iter().flat_map(|x| x.to_array().map(float))),
            Column::Record { fields, .. } => fields.iter().for_each(|f| leaves(f, out)),
        }
    }
    result
        .outputs
        .iter()
        .map(|(name, value)| {
            let mut out = Vec::new();
            match value {
                OutputValue::Array(column) => leaves(column, &mut out),
                OutputValue::Host(value) => out.push(format!("{value}").len() as u32),
            }
            (name.clone(), out)
        })
        .collect()
}

fn check(source: &str) {
    let compiled = run(source, Elementwise::Compiled).expect("the compiled run");
    let columns = run(source, Elementwise::Columns).expect("the column run");
    assert!(
        compiled
            .profile
            .iter()
            .any(|stage| !stage.compiled.is_empty()),
        "no run of ops was compiled"
    );
    assert!(columns
        .profile
        .iter()
        .all(|stage| stage.compiled.is_empty()));
    for ((name, compiled), (_, columns)) in bits(&compiled).iter().zip(&bits(&columns)) {
        let differing = compiled.iter().zip(columns).position(|(a, b)| a != b);
        assert_eq!(
            differing,
            None,
            "`{name}` differs at word {differing:?}: compiled {:#x}, columns {:#x}",
            compiled[differing.unwrap_or(0)],
            columns[differing.unwrap_or(0)]
        );
        assert_eq!(compiled.len(), columns.len(), "`{name}`");
    }
}

/// `body` after `a` and `b` (f32 edges, 24² elements) are made.
fn over_edges(body: &str) -> String {
    format!(
        "pipeline t {{\n    i = iota(600)\n    a = map<edgeA>(i)\n    b = map<edgeB>(i)\n{body}\n}}"
    )
}

#[test]
fn float_arithmetic_and_functions() {
    check(&over_edges(
        "
    out sum = a + b
    out difference = a - b
    out product = a * b
    out quotient = a / b
    out remainder = a % b
    out smaller = min(a, b)
    out larger = max(a, b)
    out negated = -a
    out magnitude = abs(a)
    out floors = floor(a)
    out ceilings = ceil(b)
    out fractions = fract(a)
    out roots = sqrt(a)
    out inverse = rsqrt(b)
    out exps = exp(a)
    out logs = log(b)
    out sines = sin(a)
    out cosines = cos(b)
    out powers = pow(a, b)
    out clamped = clamp(a, b, 2.0)
    out mixed = mix(a, b, 0.25)
    out steps = step(a, b)
    out smooth = smoothstep(b, a, 0.5)
    out same = map<identity>(a * 2.0)",
    ));
}

#[test]
fn vectors_and_geometry() {
    check(&over_edges(
        "
    u = vec3(a, b, 1.0)
    v = vec3(b, 2.0, a)
    w = vec2(a, b)
    q = vec4(a, b, a, 0.5)
    out sums = u + v
    out scaled = u * a
    out quotient = v / b
    out smaller = min(u, v)
    out dots = dot(u, v)
    out crosses = cross(u, v)
    out lengths = length(u)
    out distances = distance(u, v)
    out normals = normalize(v)
    out reflected = reflect(u, normalize(v))
    out flat = w * w - w
    out dots2 = dot(w, w)
    out lengths4 = length(q + q)
    out clamped4 = clamp(q, q * 0.5, q * 2.0)
    out components = u.x + v.z * q.w",
    ));
}

#[test]
fn comparisons_logic_selections_and_conversions() {
    check(&over_edges(
        "
    out below = a < b
    out atMost = a <= b
    out above = a > b
    out atLeast = a >= b
    out equal = a == b
    out different = a != b
    out either = a < b || a > 1.0
    out both = !(a < b) && b > 0.0
    out chosen = select(a < b, vec3(a, b, a), vec3(b, a, b))
    out zero = map<isZero>(a)
    out nonzero = map<nonZero>(b * 0.0)
    out unsigned = toU32(a)
    out signed = toI32(b)
    out back = toF32(toU32(a)) + toF32(toI32(b))
    out flags = toF32(a < b) + toF32(toU32(a < b))",
    ));
}

#[test]
fn integer_arithmetic_wraps_and_saturates() {
    check(&over_edges(
        "
    u = toU32(a) + map<hash>(i)
    // Odd, so never zero.
    v = toU32(b) / 2 * 2 + 1
    s = toI32(a) - toI32(b)
    two = toI32(select(a < b, 2.0, 2.0))
    t = toI32(b * 3.0) * two + two / two
    sign = toI32(select(a < 0.0, -1.0, 1.0))
    out sums = u + v * 7
    out differences = s - t
    out quotients = u / v
    out remainders = u % v
    out signedQuotients = s / t
    out signedRemainders = s % t
    // i32::MIN / -1 wraps, and i32::MIN % -1 is 0.
    out byOne = toI32(a) / sign + toI32(a) % sign
    out smallest = min(u, v) + max(u, v)
    out signedSmallest = min(s, t) - max(s, t)
    out negated = -s
    out compared = u < v && s >= t",
    ));
}

#[test]
fn gathers_and_iota_inside_a_compiled_run() {
    check(&over_edges(
        "
    n = len(a)
    j = iota(n) * 7 % n
    out shuffled = gather(j, a) + gather(j, b) * 2.0
    out positions = iota(n) + j
    // One index into arrays of two lengths, inside the shorter.
    short = gather(iota(300), b)
    k = j % 300
    out mixed = gather(k, a) * gather(k, short)",
    ));
}

/// The pair idiom (every point with each item: `k / n`, `k % n`), which
/// the kernels run point block by item: with one item, fewer items than a
/// block and more, so that chunks begin and end inside a point's pairs; and
/// a `pow` that only a `select` reads, computed only where it is taken.
#[test]
fn the_pair_idiom_every_point_with_each_item() {
    for items in [1, 3, 7] {
        check(&over_edges(&format!(
            "
    points = gather(iota(37), a)
    // Values made before the compiled run: read at the pairs' places.
    e = scatter<repeat>(b, fanout: {items})
    k = iota(len(a) * {items})
    p = gather(k / {items}, a)
    q = gather(k % {items}, points)
    out terms = select(p < q, pow(q, p), 0.0) + toF32(k)
    out others = select(p < q, 1.0, exp(p))
    out parts = vec3(p, q, 1.0) * gather(k / {items}, b) + toF32(k % {items})
    out sums = gather<sum>(p * q, group: {items})
    out mixed = e * p + select(e < q, sqrt(p), q)"
        )));
    }
}

/// Selects whose conditions hold over runs of elements, so that whole
/// blocks of four take one side and the kernels skip the steps only the
/// other side reads: nested, on either side, with a `pow` and a value also
/// read after the select, and through the pair idiom's items; and a
/// gather inside a discarded side still fails where its index does.
#[test]
fn a_block_skips_the_side_of_a_select_that_none_of_its_lanes_takes() {
    check(&over_edges(
        "
    run = iota(len(a)) / 8 % 3 == 0
    other = iota(len(a)) / 4 % 2 == 1
    u = vec3(a, b, 1.0)
    heavy = normalize(u) * sqrt(abs(a)) + vec3(pow(abs(b), a))
    out taken = select(run, heavy, vec3(0.0))
    out nested = select(run, select(other, a * b + exp(a), b / a), 0.0)
    out otherSide = select(other, 1.0, sqrt(a) * log(b))
    shared = a * 3.0 + b
    out sharedToo = select(run, shared, 0.0) + shared",
    ));
    for items in [1, 3] {
        check(&over_edges(&format!(
            "
    k = iota(len(a) * {items})
    p = gather(k / {items}, a)
    q = gather(k % {items}, b)
    lit = k / {items} / 8 % 2 == 0
    out terms = select(lit && q > 0.0, pow(abs(p), q) * p + q, 0.0)
    out sums = gather<sum>(select(lit, p * q + sqrt(abs(p)), 0.0), group: {items})"
        )));
    }
    let failing = over_edges(
        "
    never = iota(len(a)) > 1000
    out g = select(never, gather(toU32(a) + 5, b) * 2.0, 0.0)",
    );
    let compiled = run(&failing, Elementwise::Compiled).map(|_| ());
    let columns = run(&failing, Elementwise::Columns).map(|_| ());
    assert!(columns.is_err(), "the discarded gather should fail");
    assert_eq!(compiled, columns);
}

/// A failing element stops the compiled loop; the ops then run one by one
/// and report it exactly as the column run does.
#[test]
fn a_failing_element_fails_as_it_does_column_at_a_time() {
    for failing in [
        "out q = toU32(a) / toU32(b)",
        "out r = toI32(a) % toI32(b * 0.0)",
        "out g = gather(toU32(a) + 5, b) * 2.0",
        // Inside the longer array, past the shorter.
        "short = gather(iota(300), b)\n    out g = gather(i, a) * gather(i, short)",
        // From an empty array.
        "none = gather(iota(0), b)\n    out g = gather(i, a) * gather(i, none)",
        // The pair idiom past its points, and with no items.
        "short = gather(iota(300), b)\n    k = iota(600 * 2)\n    out g = gather(k / 2, short) * gather(k % 2, a)",
        "k = iota(600 * 2)\n    out g = gather(k / 0, a) * gather(k % 0, b)",
    ] {
        let source = over_edges(&format!("    {failing}"));
        let compiled = run(&source, Elementwise::Compiled).map(|_| ());
        let columns = run(&source, Elementwise::Columns).map(|_| ());
        assert!(columns.is_err(), "`{failing}` should fail");
        assert_eq!(compiled, columns, "`{failing}`");
    }
}
