//! Every generic functor's CPU implementation on small hand-checked inputs.

use dpp_runtime::column::Scalar;
use dpp_runtime::generic::register_generic_functors;
use dpp_runtime::{
    CallContext, Column, ElemType, FunctorError, FunctorKind, FunctorLibrary, HostValue, RecordId,
    RecordType, TypePattern, Uniforms,
};
use glam::{Vec2, Vec3, Vec4};
use std::path::Path;
use std::sync::Arc;

/// The generic functors and the record type `Pair { count: u32, position: vec3 }`.
fn library() -> (FunctorLibrary, RecordId) {
    let mut library = FunctorLibrary::default();
    let pair = library.records.register(RecordType {
        name: "Pair".into(),
        fields: vec![
            ("count".into(), ElemType::U32),
            ("position".into(), ElemType::Vec3),
        ],
        doc: "a test record".into(),
    });
    register_generic_functors(&mut library);
    (library, pair)
}

fn pairs(ty: RecordId, counts: &[u32], positions: &[Vec3]) -> Column {
    Column::Record {
        ty,
        fields: vec![
            Arc::new(Column::U32(counts.to_vec())),
            Arc::new(Column::Vec3(positions.to_vec())),
        ],
    }
}

/// One call of a functor on one chunk.
struct Call {
    functor: &'static str,
    inputs: Vec<Column>,
    /// Named arguments; the signature's defaults when empty.
    named: Vec<HostValue>,
    /// `k` of a group or fan-out.
    group: usize,
    /// Index of the chunk's first element.
    first_index: usize,
}

fn call(functor: &'static str, inputs: Vec<Column>) -> Call {
    Call {
        functor,
        inputs,
        named: Vec::new(),
        group: 1,
        first_index: 0,
    }
}

fn grouped(functor: &'static str, group: usize, inputs: Vec<Column>) -> Call {
    Call {
        group,
        ..call(functor, inputs)
    }
}

fn run(
    library: &FunctorLibrary,
    call: &Call,
    output_type: ElemType,
) -> Result<Column, FunctorError> {
    let functor = library
        .get(call.functor)
        .unwrap_or_else(|| panic!("no functor `{}`", call.functor));
    // A required argument (`component`'s index) must be in `call.named`.
    let defaults: Vec<HostValue> = functor
        .signature()
        .named
        .iter()
        .filter_map(|param| param.default)
        .collect();
    let uniforms = Uniforms::default();
    let ctx = CallContext {
        named: if call.named.is_empty() {
            &defaults
        } else {
            &call.named
        },
        uniforms: &uniforms,
        resources: &(),
        first_index: call.first_index,
        group: call.group,
        records: &library.records,
    };
    let inputs: Vec<_> = call.inputs.iter().map(Column::view).collect();
    let mut outputs = vec![Column::with_capacity(output_type, 0, &library.records)];
    functor.run_cpu(&ctx, &inputs, &mut outputs)?;
    let [output] = <[Column; 1]>::try_from(outputs).expect("one output");
    Ok(output)
}

/// Runs every call and compares its output (or its error message) with the expectation.
fn check(cases: Vec<(Call, Result<Column, &str>)>) {
    let (library, _) = library();
    for (call, expected) in cases {
        let output_type = expected
            .as_ref()
            .map_or(ElemType::U32, |column| column.elem_type());
        let result = run(&library, &call, output_type).map_err(|error| error.message);
        assert_eq!(
            result,
            expected.map_err(str::to_string),
            "{}({:?})",
            call.functor,
            call.inputs
        );
    }
}

fn u32s(values: &[u32]) -> Column {
    Column::U32(values.to_vec())
}

fn i32s(values: &[i32]) -> Column {
    Column::I32(values.to_vec())
}

fn f32s(values: &[f32]) -> Column {
    Column::F32(values.to_vec())
}

fn bools(values: &[bool]) -> Column {
    Column::Bool(values.to_vec())
}

#[test]
fn monoids() {
    check(vec![
        (
            call("add", vec![u32s(&[1, u32::MAX]), u32s(&[2, 2])]),
            Ok(u32s(&[3, 1])),
        ),
        (
            call(
                "add",
                vec![
                    Column::Vec3(vec![Vec3::new(1.0, 2.0, 3.0)]),
                    Column::Vec3(vec![Vec3::ONE]),
                ],
            ),
            Ok(Column::Vec3(vec![Vec3::new(2.0, 3.0, 4.0)])),
        ),
        (
            call("mul", vec![i32s(&[-3, i32::MAX]), i32s(&[4, 2])]),
            Ok(i32s(&[-12, -2])),
        ),
        (
            call("min", vec![f32s(&[1.0, -2.0]), f32s(&[0.5, 3.0])]),
            Ok(f32s(&[0.5, -2.0])),
        ),
        (
            call(
                "max",
                vec![
                    Column::Vec2(vec![Vec2::new(1.0, 5.0)]),
                    Column::Vec2(vec![Vec2::new(2.0, 3.0)]),
                ],
            ),
            Ok(Column::Vec2(vec![Vec2::new(2.0, 5.0)])),
        ),
        (
            call(
                "or",
                vec![bools(&[true, false, false]), bools(&[false, false, true])],
            ),
            Ok(bools(&[true, false, true])),
        ),
        (
            call(
                "and",
                vec![bools(&[true, true, false]), bools(&[true, false, true])],
            ),
            Ok(bools(&[true, false, false])),
        ),
        (
            call("add", vec![u32s(&[1, 2]), u32s(&[1])]),
            Err("the second operand has length 1, expected 2"),
        ),
    ]);
}

#[test]
fn arithmetic() {
    check(vec![
        (
            call("sub", vec![u32s(&[5, 0]), u32s(&[3, 1])]),
            Ok(u32s(&[2, u32::MAX])),
        ),
        (
            call("sub", vec![f32s(&[1.5]), f32s(&[0.5])]),
            Ok(f32s(&[1.0])),
        ),
        (
            call(
                "sub",
                vec![Column::Vec4(vec![Vec4::ONE]), Column::Vec4(vec![Vec4::X])],
            ),
            Ok(Column::Vec4(vec![Vec4::new(0.0, 1.0, 1.0, 1.0)])),
        ),
        (
            call("div", vec![i32s(&[7, -7, i32::MIN]), i32s(&[2, 2, -1])]),
            Ok(i32s(&[3, -3, i32::MIN])),
        ),
        (
            call("div", vec![f32s(&[1.0]), f32s(&[0.0])]),
            Ok(f32s(&[f32::INFINITY])),
        ),
        (
            Call {
                first_index: 100,
                ..call("div", vec![u32s(&[4, 4]), u32s(&[2, 0])])
            },
            Err("integer division by zero at element 101"),
        ),
    ]);
}

#[test]
fn comparisons() {
    check(vec![
        (
            call("eq", vec![u32s(&[1, 2]), u32s(&[1, 3])]),
            Ok(bools(&[true, false])),
        ),
        (
            call("eq", vec![bools(&[true, false]), bools(&[true, true])]),
            Ok(bools(&[true, false])),
        ),
        (
            call("ne", vec![f32s(&[f32::NAN, 1.0]), f32s(&[f32::NAN, 1.0])]),
            Ok(bools(&[true, false])),
        ),
        (
            call("lt", vec![i32s(&[-1, 2]), i32s(&[0, 2])]),
            Ok(bools(&[true, false])),
        ),
        (
            call("le", vec![i32s(&[-1, 2, 3]), i32s(&[0, 2, 2])]),
            Ok(bools(&[true, true, false])),
        ),
        (
            call("gt", vec![f32s(&[f32::NAN, 2.0]), f32s(&[0.0, 1.0])]),
            Ok(bools(&[false, true])),
        ),
        (
            call("ge", vec![u32s(&[1, 2, 3]), u32s(&[2, 2, 2])]),
            Ok(bools(&[false, true, true])),
        ),
        (
            call("isZero", vec![f32s(&[0.0, -0.0, 1.0, f32::NAN])]),
            Ok(bools(&[true, true, false, false])),
        ),
        (
            call("nonZero", vec![i32s(&[0, -1])]),
            Ok(bools(&[false, true])),
        ),
        (
            call("not", vec![bools(&[true, false])]),
            Ok(bools(&[false, true])),
        ),
    ]);
}

#[test]
fn conversions() {
    check(vec![
        (
            call("toU32", vec![bools(&[true, false])]),
            Ok(u32s(&[1, 0])),
        ),
        (call("toU32", vec![i32s(&[-5, 7])]), Ok(u32s(&[0, 7]))),
        (
            call("toU32", vec![f32s(&[-1.5, 2.9, f32::NAN, 1e10])]),
            Ok(u32s(&[0, 2, 0, u32::MAX])),
        ),
        (
            call("toI32", vec![u32s(&[3, u32::MAX])]),
            Ok(i32s(&[3, i32::MAX])),
        ),
        (
            call("toI32", vec![f32s(&[-2.7, -1e10])]),
            Ok(i32s(&[-2, i32::MIN])),
        ),
        (call("toI32", vec![bools(&[true])]), Ok(i32s(&[1]))),
        (
            call("toF32", vec![u32s(&[16_777_217])]),
            Ok(f32s(&[16_777_216.0])),
        ),
        (call("toF32", vec![i32s(&[-3])]), Ok(f32s(&[-3.0]))),
        (
            call("toF32", vec![bools(&[true, false])]),
            Ok(f32s(&[1.0, 0.0])),
        ),
    ]);
}

#[test]
fn select_and_identity_take_any_type() {
    let (_, pair) = library();
    check(vec![
        (
            call(
                "select",
                vec![bools(&[true, false]), u32s(&[1, 2]), u32s(&[10, 20])],
            ),
            Ok(u32s(&[1, 20])),
        ),
        (
            call(
                "select",
                vec![
                    bools(&[false, true]),
                    pairs(pair, &[1, 2], &[Vec3::X, Vec3::Y]),
                    pairs(pair, &[3, 4], &[Vec3::Z, Vec3::ONE]),
                ],
            ),
            Ok(pairs(pair, &[3, 2], &[Vec3::Z, Vec3::Y])),
        ),
        (
            call("identity", vec![Column::Vec3(vec![Vec3::X])]),
            Ok(Column::Vec3(vec![Vec3::X])),
        ),
        (
            call("identity", vec![pairs(pair, &[7], &[Vec3::Z])]),
            Ok(pairs(pair, &[7], &[Vec3::Z])),
        ),
    ]);
}

/// The values are pinned: pipelines' random streams (and the GPU backend) depend on them.
#[test]
fn hash_and_random() {
    let inputs = || vec![u32s(&[0, 1, 2, 123_456_789])];
    let seeded = |functor, seed| Call {
        named: vec![HostValue::Int(seed)],
        ..call(functor, inputs())
    };
    check(vec![
        (
            call("hash", inputs()),
            Ok(u32s(&[
                817_759_070,
                1_583_546_800,
                3_259_027_186,
                731_433_701,
            ])),
        ),
        (
            seeded("hash", 1),
            Ok(u32s(&[
                3_911_864_714,
                2_979_142_878,
                3_752_912_895,
                4_288_249_776,
            ])),
        ),
        // Seeds are taken modulo 2^32.
        (
            seeded("hash", 1 + (1 << 32)),
            Ok(u32s(&[
                3_911_864_714,
                2_979_142_878,
                3_752_912_895,
                4_288_249_776,
            ])),
        ),
        (
            call("random", vec![u32s(&[0, 1])]),
            Ok(f32s(&[
                (817_759_070 >> 8) as f32 / 16_777_216.0,
                (1_583_546_800 >> 8) as f32 / 16_777_216.0,
            ])),
        ),
    ]);
}

#[test]
fn random_is_in_the_unit_interval() {
    let (library, _) = library();
    let ten_thousand = call("random", vec![Column::U32((0..10_000).collect())]);
    let output = run(&library, &ten_thousand, ElemType::F32).unwrap();
    assert!(output
        .view()
        .as_f32()
        .iter()
        .all(|x| (0.0..1.0).contains(x)));
}

#[test]
fn groups() {
    check(vec![
        (
            grouped("sum", 2, vec![u32s(&[1, 2, 3, 4, 5])]),
            Ok(u32s(&[3, 7])),
        ),
        (
            grouped("sum", 2, vec![Column::Vec2(vec![Vec2::X, Vec2::Y])]),
            Ok(Column::Vec2(vec![Vec2::ONE])),
        ),
        (
            grouped("average", 2, vec![f32s(&[1.0, 2.0, 3.0, 5.0])]),
            Ok(f32s(&[1.5, 4.0])),
        ),
        (
            grouped("average", 4, vec![bools(&[true, false, true, true])]),
            Ok(f32s(&[0.75])),
        ),
        (
            grouped("average", 0, vec![f32s(&[1.0])]),
            Err("a group needs at least one element"),
        ),
    ]);
}

#[test]
fn fan_outs() {
    let (_, pair) = library();
    check(vec![
        (
            grouped("repeat", 3, vec![u32s(&[7, 8])]),
            Ok(u32s(&[7, 7, 7, 8, 8, 8])),
        ),
        (
            grouped("repeat", 2, vec![pairs(pair, &[1, 2], &[Vec3::X, Vec3::Y])]),
            Ok(pairs(
                pair,
                &[1, 1, 2, 2],
                &[Vec3::X, Vec3::X, Vec3::Y, Vec3::Y],
            )),
        ),
        (grouped("repeat", 0, vec![u32s(&[7, 8])]), Ok(u32s(&[]))),
        (
            grouped("lane", 3, vec![f32s(&[0.5, 0.25])]),
            Ok(u32s(&[0, 1, 2, 0, 1, 2])),
        ),
    ]);
}

/// Float results compared on their bits (so `-0.0` is not `0.0`), but any
/// NaN matches any NaN where the expectation is NaN.
fn check_floats(cases: Vec<(Call, Column)>) {
    let (library, _) = library();
    for (call, expected) in cases {
        let output = run(&library, &call, expected.elem_type())
            .unwrap_or_else(|error| panic!("{}: {}", call.functor, error.message));
        let (mut got, mut want) = (Vec::new(), Vec::new());
        assert_eq!(output.len(), expected.len(), "{}", call.functor);
        for i in 0..output.len() {
            output.scalars_of(i, &mut got);
            expected.scalars_of(i, &mut want);
        }
        let same = got.iter().zip(&want).all(|(g, w)| match (g, w) {
            (Scalar::Float(g), Scalar::Float(w)) => {
                g.to_bits() == w.to_bits() || (g.is_nan() && w.is_nan())
            }
            (g, w) => g == w,
        });
        assert!(
            same,
            "{}({:?}) = {output:?}, expected {expected:?}",
            call.functor, call.inputs
        );
    }
}

fn vec2s(values: &[[f32; 2]]) -> Column {
    Column::Vec2(values.iter().map(|&v| Vec2::from_array(v)).collect())
}

fn vec3s(values: &[[f32; 3]]) -> Column {
    Column::Vec3(values.iter().map(|&v| Vec3::from_array(v)).collect())
}

fn vec4s(values: &[[f32; 4]]) -> Column {
    Column::Vec4(values.iter().map(|&v| Vec4::from_array(v)).collect())
}

const INF: f32 = f32::INFINITY;
const NAN: f32 = f32::NAN;

#[test]
fn neg_and_abs_work_on_the_sign_bit() {
    check(vec![(
        call("neg", vec![i32s(&[1, -5, i32::MIN, 0])]),
        Ok(i32s(&[-1, 5, i32::MIN, 0])),
    )]);
    check_floats(vec![
        (
            call("neg", vec![f32s(&[0.0, -0.0, 1.5, INF])]),
            f32s(&[-0.0, 0.0, -1.5, -INF]),
        ),
        (
            call("neg", vec![vec3s(&[[1.0, -2.0, 0.0]])]),
            vec3s(&[[-1.0, 2.0, -0.0]]),
        ),
        (
            call("abs", vec![vec2s(&[[-0.0, -2.5], [-INF, 3.0]])]),
            vec2s(&[[0.0, 2.5], [INF, 3.0]]),
        ),
    ]);
    // NaN keeps its payload; only the sign changes.
    let (library, _) = library();
    let nan = f32::from_bits(0x7fc0_0123);
    for (functor, input, expected) in [("neg", nan, 0xffc0_0123), ("abs", -nan, 0x7fc0_0123)] {
        let output = run(
            &library,
            &call(functor, vec![f32s(&[input])]),
            ElemType::F32,
        )
        .unwrap();
        assert_eq!(output.view().as_f32()[0].to_bits(), expected, "{functor}");
    }
}

#[test]
fn rounding_functions() {
    check_floats(vec![
        (
            call("floor", vec![f32s(&[-1.5, 1.5, -0.0, INF, NAN])]),
            f32s(&[-2.0, 1.0, -0.0, INF, NAN]),
        ),
        (
            call("ceil", vec![f32s(&[-1.5, 1.5, -0.5])]),
            f32s(&[-1.0, 2.0, -0.0]),
        ),
        // x - floor(x): in [0, 1], and 1 where a tiny negative x rounds up.
        (
            call("fract", vec![f32s(&[1.25, -1.25, -0.0, -1e-8, INF])]),
            f32s(&[0.25, 0.75, 0.0, 1.0, NAN]),
        ),
        (
            call("fract", vec![vec4s(&[[2.5, -0.5, 3.0, -3.75]])]),
            vec4s(&[[0.5, 0.5, 0.0, 0.25]]),
        ),
    ]);
}

#[test]
fn powers_logarithms_and_trigonometry() {
    check_floats(vec![
        (
            call("sqrt", vec![f32s(&[4.0, 2.0, -0.0, -1.0, INF])]),
            f32s(&[2.0, std::f32::consts::SQRT_2, -0.0, NAN, INF]),
        ),
        (
            call("rsqrt", vec![f32s(&[4.0, 0.0, -0.0, INF, -4.0])]),
            f32s(&[0.5, INF, -INF, 0.0, NAN]),
        ),
        (
            call("exp", vec![f32s(&[0.0, -INF, INF, NAN, 100.0, -200.0])]),
            f32s(&[1.0, 0.0, INF, NAN, INF, 0.0]),
        ),
        (
            call("log", vec![f32s(&[1.0, 0.0, -0.0, -1.0, INF])]),
            f32s(&[0.0, -INF, -INF, NAN, INF]),
        ),
        (
            call(
                "sin",
                vec![f32s(&[0.0, -0.0, std::f32::consts::FRAC_PI_2, INF])],
            ),
            f32s(&[0.0, -0.0, 1.0, NAN]),
        ),
        (
            call("cos", vec![vec2s(&[[0.0, std::f32::consts::PI]])]),
            vec2s(&[[1.0, -1.0]]),
        ),
        (
            call(
                "pow",
                vec![
                    f32s(&[2.0, 4.0, NAN, 0.0, -8.0]),
                    f32s(&[10.0, 0.5, 0.0, -1.0, 1.0 / 3.0]),
                ],
            ),
            f32s(&[1024.0, 2.0, 1.0, INF, NAN]),
        ),
    ]);
}

#[test]
fn clamp_mix_step_and_smoothstep() {
    check_floats(vec![
        // NaN loses in min and max: a NaN x is clamped to lo, a NaN bound is no bound.
        (
            call(
                "clamp",
                vec![
                    f32s(&[5.0, -1.0, NAN, 0.5]),
                    f32s(&[0.0, 0.0, 0.0, NAN]),
                    f32s(&[1.0, 1.0, 1.0, 1.0]),
                ],
            ),
            f32s(&[1.0, 0.0, 0.0, 0.5]),
        ),
        (
            call(
                "clamp",
                vec![
                    vec2s(&[[-2.0, 2.0]]),
                    vec2s(&[[-1.0, -1.0]]),
                    vec2s(&[[1.0, 1.0]]),
                ],
            ),
            vec2s(&[[-1.0, 1.0]]),
        ),
        // WGSL's formula: exact at t = 0 and t = 1, and NaN for inf * 0.
        (
            call(
                "mix",
                vec![
                    f32s(&[1.0, 0.1, 0.1, INF]),
                    f32s(&[3.0, 0.7, 0.7, 0.0]),
                    f32s(&[0.5, 0.0, 1.0, 1.0]),
                ],
            ),
            f32s(&[2.0, 0.1, 0.7, NAN]),
        ),
        (
            call(
                "step",
                vec![f32s(&[1.0, 1.0, NAN, -0.0]), f32s(&[1.0, 0.5, 1.0, 0.0])],
            ),
            f32s(&[1.0, 0.0, 0.0, 1.0]),
        ),
        // lo == hi makes t NaN, which the clamp turns into 0; lo > hi reverses.
        (
            call(
                "smoothstep",
                vec![
                    f32s(&[0.0, 0.0, 0.0, 0.0, 1.0, 1.0]),
                    f32s(&[1.0, 1.0, 1.0, 2.0, 1.0, 0.0]),
                    f32s(&[0.5, -1.0, 2.0, 0.5, 1.0, 0.25]),
                ],
            ),
            f32s(&[0.5, 0.0, 1.0, 0.15625, 0.0, 0.84375]),
        ),
    ]);
}

#[test]
fn vector_geometry() {
    let max = f32::MAX;
    check_floats(vec![
        (
            call(
                "dot",
                vec![vec3s(&[[1.0, 2.0, 3.0]]), vec3s(&[[4.0, 5.0, 6.0]])],
            ),
            f32s(&[32.0]),
        ),
        // Left to right: MAX - MAX + MAX / 2, where a pairwise sum overflows.
        (
            call(
                "dot",
                vec![vec4s(&[[-0.0, 1.0, -1.0, 0.5]]), vec4s(&[[max; 4]])],
            ),
            f32s(&[max / 2.0]),
        ),
        (
            call("dot", vec![vec2s(&[[INF, 1.0]]), vec2s(&[[0.0, 1.0]])]),
            f32s(&[NAN]),
        ),
        (
            call(
                "cross",
                vec![
                    vec3s(&[[1.0, 0.0, 0.0], [1.0, 2.0, 3.0]]),
                    vec3s(&[[0.0, 1.0, 0.0], [4.0, 5.0, 6.0]]),
                ],
            ),
            vec3s(&[[0.0, 0.0, 1.0], [-3.0, 6.0, -3.0]]),
        ),
        (
            call(
                "length",
                vec![vec2s(&[[3.0, 4.0], [0.0, -0.0], [1e20, 0.0]])],
            ),
            f32s(&[5.0, 0.0, INF]),
        ),
        (
            call("length", vec![vec4s(&[[1.0, -1.0, 1.0, -1.0]])]),
            f32s(&[2.0]),
        ),
        (
            call("distance", vec![vec2s(&[[4.0, 6.0]]), vec2s(&[[1.0, 2.0]])]),
            f32s(&[5.0]),
        ),
        // The zero vector, and one whose squared length underflows, give +0s.
        (
            call(
                "normalize",
                vec![vec3s(&[
                    [3.0, 0.0, 4.0],
                    [0.0, -0.0, 0.0],
                    [1e-30, 0.0, -1e-30],
                    [NAN, 0.0, 0.0],
                ])],
            ),
            vec3s(&[[0.6, 0.0, 0.8], [0.0; 3], [0.0; 3], [NAN; 3]]),
        ),
        (
            call("normalize", vec![vec4s(&[[0.0, 0.0, -2.0, 0.0]])]),
            vec4s(&[[0.0, 0.0, -1.0, 0.0]]),
        ),
        (
            call(
                "reflect",
                vec![vec3s(&[[1.0, -1.0, 0.0]]), vec3s(&[[0.0, 1.0, 0.0]])],
            ),
            vec3s(&[[1.0, 1.0, 0.0]]),
        ),
        (
            call("reflect", vec![vec2s(&[[2.0, 3.0]]), vec2s(&[[-1.0, 0.0]])]),
            vec2s(&[[-2.0, 3.0]]),
        ),
    ]);
}

#[test]
fn vectors_from_components_and_back() {
    check_floats(vec![
        (
            call("vec2", vec![f32s(&[1.0, 2.0]), f32s(&[3.0, -0.0])]),
            vec2s(&[[1.0, 3.0], [2.0, -0.0]]),
        ),
        (
            call("vec3", vec![f32s(&[1.0]), f32s(&[2.0]), f32s(&[NAN])]),
            vec3s(&[[1.0, 2.0, NAN]]),
        ),
        (
            call(
                "vec4",
                vec![f32s(&[1.0]), f32s(&[2.0]), f32s(&[3.0]), f32s(&[4.0])],
            ),
            vec4s(&[[1.0, 2.0, 3.0, 4.0]]),
        ),
        (call("splat2", vec![f32s(&[-0.0])]), vec2s(&[[-0.0; 2]])),
        (call("splat3", vec![f32s(&[1.5])]), vec3s(&[[1.5; 3]])),
        (call("splat4", vec![f32s(&[INF])]), vec4s(&[[INF; 4]])),
    ]);
    let component = |index: i64, v: Column| Call {
        named: vec![HostValue::Int(index)],
        ..call("component", vec![v])
    };
    let v3 = || vec3s(&[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
    check(vec![
        (component(0, v3()), Ok(f32s(&[1.0, 4.0]))),
        (component(2, v3()), Ok(f32s(&[3.0, 6.0]))),
        (
            component(3, vec4s(&[[1.0, 2.0, 3.0, 4.0]])),
            Ok(f32s(&[4.0])),
        ),
        (
            component(3, v3()),
            Err("component index 3 is out of range for vec3, whose components are 0 to 2"),
        ),
        (
            component(-1, vec2s(&[[1.0, 2.0]])),
            Err("component index -1 is out of range for vec2, whose components are 0 to 1"),
        ),
        (
            call("vec2", vec![f32s(&[1.0, 2.0]), f32s(&[3.0])]),
            Err("a component has length 1, expected 2"),
        ),
    ]);
}

#[test]
fn remainders_truncate_like_wgsl() {
    check(vec![
        (
            call(
                "rem",
                vec![i32s(&[7, -7, 7, -7, i32::MIN]), i32s(&[3, 3, -3, -3, -1])],
            ),
            Ok(i32s(&[1, -1, 1, -1, 0])),
        ),
        (
            call("rem", vec![u32s(&[7, u32::MAX]), u32s(&[3, 2])]),
            Ok(u32s(&[1, 1])),
        ),
        (
            Call {
                first_index: 100,
                ..call("rem", vec![i32s(&[4, 4]), i32s(&[3, 0])])
            },
            Err("integer division by zero at element 101"),
        ),
    ]);
    // a - b * trunc(a / b): unlike C's fmod, -0 % 1 is +0 and x % inf is NaN.
    check_floats(vec![(
        call(
            "rem",
            vec![
                f32s(&[5.5, -5.5, 5.5, -0.0, 1.0, 1.0, INF]),
                f32s(&[2.0, 2.0, -2.0, 1.0, INF, 0.0, 1.0]),
            ],
        ),
        f32s(&[1.5, -1.5, 1.5, 0.0, NAN, NAN, NAN]),
    )]);
}

/// The functors in a pipeline, as the compiler's expressions will use them.
#[test]
fn math_functors_in_a_pipeline() {
    let library = crate::common::library();
    let source = "pipeline p {
        x = iota(3) → map<toF32>()
        y = map<splat3>(x) → map<component>(index: 1)
        v = map<vec3>(x, y, map<neg>(x))
        out n = map<normalize>(v) → map<length>()
        out z = map<component>(v, index: 2)
        lo = fill(3, 0.0)
        hi = fill(3, 2.0)
        out s = map<smoothstep>(lo, hi, x)
    }";
    let plan = crate::common::compile(Path::new("math.dpp"), source, &library, true)
        .unwrap_or_else(|e| panic!("{}", e.render(false)));
    // |(k, k, -k)| / sqrt(3 k^2) rounds to 1 - 2^-24; the zero vector stays 0.
    assert_eq!(
        crate::common::run_text(&plan, &library),
        "n = [0.0, 0.99999994, 0.99999994]\nz = [-0.0, -1.0, -2.0]\ns = [0.0, 0.5, 1.0]\n"
    );
    // u32 has no negation: a compile-time error, as for every excluded type.
    let unsigned = "pipeline p {\n    out r = iota(3) → map<neg>()\n}";
    let failure = crate::common::compile(Path::new("neg.dpp"), unsigned, &library, true)
        .expect_err("neg of u32");
    let text = crate::common::diagnostics_text(&failure);
    assert!(text.contains("i32|f32|vec2|vec3|vec4"), "{text}");
    let bad = source.replace("index: 2", "index: 4");
    let plan = crate::common::compile(Path::new("math.dpp"), &bad, &library, false).unwrap();
    assert_eq!(
        crate::common::run_text(&plan, &library),
        "run-time error: stage 9 [map<component>]: component index 4 is out of range for vec3, whose components are 0 to 2\n"
    );
}

#[test]
fn signatures_are_registered_once_with_docs() {
    let (library, _) = library();
    let names: Vec<&str> = library.names().collect();
    let mut expected = vec![
        "add",
        "and",
        "average",
        "div",
        "eq",
        "ge",
        "gt",
        "hash",
        "identity",
        "isZero",
        "lane",
        "le",
        "lt",
        "max",
        "min",
        "mul",
        "ne",
        "nonZero",
        "not",
        "or",
        "random",
        "repeat",
        "select",
        "sub",
        "sum",
        "toF32",
        "toI32",
        "toU32",
        "neg",
        "abs",
        "floor",
        "ceil",
        "fract",
        "sqrt",
        "rsqrt",
        "exp",
        "log",
        "sin",
        "cos",
        "pow",
        "clamp",
        "mix",
        "step",
        "smoothstep",
        "dot",
        "cross",
        "length",
        "distance",
        "normalize",
        "reflect",
        "vec2",
        "vec3",
        "vec4",
        "splat2",
        "splat3",
        "splat4",
        "component",
        "rem",
    ];
    expected.sort_unstable();
    assert_eq!(names, expected);
    for functor in library.iter() {
        let signature = functor.signature();
        assert!(!signature.doc.is_empty(), "{} has no doc", signature.name);
        assert_eq!(signature.outputs.len(), 1, "{}", signature.name);
        if let FunctorKind::Monoid(_) = signature.kind {
            let types = [&signature.inputs[0].ty, &signature.inputs[1].ty];
            assert_eq!(types, [&signature.outputs[0].ty; 2], "{}", signature.name);
        }
    }
    let hash = library.get("hash").unwrap().signature();
    assert_eq!(
        hash.display(&library.records),
        "map          hash(x: u32) -> (out: u32) [seed: int = 0]"
    );
    let display = |name| {
        library
            .get(name)
            .unwrap()
            .signature()
            .display(&library.records)
    };
    assert_eq!(
        display("smoothstep"),
        "map          smoothstep(lo: T0:f32|vec2|vec3|vec4, hi: T0:f32|vec2|vec3|vec4, x: T0:f32|vec2|vec3|vec4) -> (out: T0:f32|vec2|vec3|vec4)"
    );
    assert_eq!(
        display("component"),
        "map          component(v: T0:vec2|vec3|vec4) -> (out: f32) [index: int]"
    );
    assert_eq!(
        display("neg"),
        "map          neg(x: T0:i32|f32|vec2|vec3|vec4) -> (out: T0:i32|f32|vec2|vec3|vec4)"
    );
    assert_eq!(
        library.get("select").unwrap().signature().inputs[1].ty,
        TypePattern::Var(0, dpp_runtime::TypeConstraint::Any)
    );
}
