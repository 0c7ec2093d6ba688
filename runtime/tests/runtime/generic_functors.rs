//! Every generic functor's CPU implementation on small hand-checked inputs.

use dpp_runtime::generic::register_generic_functors;
use dpp_runtime::{
    CallContext, Column, ElemType, FunctorError, FunctorKind, FunctorLibrary, HostValue, RecordId,
    RecordType, TypePattern, Uniforms,
};
use glam::{Vec2, Vec3, Vec4};
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
    let defaults: Vec<HostValue> = functor
        .signature()
        .named
        .iter()
        .map(|param| param.default.expect("generic named params have defaults"))
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

#[test]
fn signatures_are_registered_once_with_docs() {
    let (library, _) = library();
    let names: Vec<&str> = library.names().collect();
    let mut expected = vec![
        "add", "and", "average", "div", "eq", "ge", "gt", "hash", "identity", "isZero", "lane",
        "le", "lt", "max", "min", "mul", "ne", "nonZero", "not", "or", "random", "repeat",
        "select", "sub", "sum", "toF32", "toI32", "toU32",
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
    assert_eq!(
        library.get("select").unwrap().signature().inputs[1].ty,
        TypePattern::Var(0, dpp_runtime::TypeConstraint::Any)
    );
}
