//! The CPU kernels against plain sequential references, on sizes around the
//! (small) test chunk size so that the multi-chunk paths run.

use dpp_runtime::cpu::kernels::{
    gather, reduce, run_chunked, scan, scatter, scatter_combine, scatter_combine_parts,
    ScatterPart, DEFAULT_CHUNK,
};
use dpp_runtime::elem::{Element, KernelError, PrimitiveElement};
use dpp_runtime::monoid::{combine_columns, identity, monoid_supports, reduce_groups};
use dpp_runtime::{Column, ElemType, HostValue, MonoidOp, RecordId};
use glam::{Vec2, Vec3, Vec4};
use proptest::prelude::*;
use proptest::test_runner::TestCaseError;
use std::fmt::Debug;
use std::sync::Arc;

const TEST_CHUNK: usize = 64;

/// Empty, single, prime, around one and two chunks, and a prime above the default chunk.
const SIZES: [usize; 9] = [0, 1, 7, 63, 64, 65, 128, 211, 4099];

/// A monoid as the reference implements it, independently of the kernels.
struct Reference<T> {
    op: MonoidOp,
    identity: T,
    combine: fn(T, T) -> T,
}

impl<T: Copy> Reference<T> {
    fn reduce(&self, values: &[T]) -> T {
        values
            .iter()
            .fold(self.identity, |total, &value| (self.combine)(total, value))
    }

    fn scan(&self, values: &[T], inclusive: bool, segment_starts: Option<&[bool]>) -> Vec<T> {
        let mut running = self.identity;
        let mut scanned = Vec::new();
        for (position, &value) in values.iter().enumerate() {
            if segment_starts.is_some_and(|flags| flags[position]) {
                scanned.push(if inclusive { value } else { self.identity });
                running = value;
            } else {
                let before = running;
                running = (self.combine)(running, value);
                scanned.push(if inclusive { running } else { before });
            }
        }
        scanned
    }
}

/// Values of a size from [`SIZES`] and segment flags of the same length.
fn values_and_flags<T: Debug>(
    element: impl Strategy<Value = T> + Clone,
) -> impl Strategy<Value = (Vec<T>, Vec<bool>)> {
    prop::sample::select(SIZES.to_vec()).prop_flat_map(move |len| {
        (
            prop::collection::vec(element.clone(), len),
            prop::collection::vec(prop::bool::weighted(0.05), len),
        )
    })
}

/// Reduce and every flavour of scan, chunked, against the reference.
fn check_monoid<T: PrimitiveElement>(
    reference: &Reference<T>,
    values: &[T],
    flags: &[bool],
) -> Result<(), TestCaseError> {
    let column = T::into_column(values.to_vec());
    let view = column.view();
    let op = reference.op;
    prop_assert_eq!(
        reduce(op, &view, TEST_CHUNK)?,
        reference.reduce(values).into_element().to_host()
    );
    for inclusive in [true, false] {
        for segment_starts in [None, Some(flags)] {
            let expected = T::into_column(reference.scan(values, inclusive, segment_starts));
            let scanned = scan(op, &view, inclusive, segment_starts, TEST_CHUNK)?;
            prop_assert_eq!(&scanned, &expected, "{:?} inclusive: {}", op, inclusive);
        }
    }
    Ok(())
}

/// Floats that are small integers, so sums are exact in any order.
fn small_integral_float() -> impl Strategy<Value = f32> + Clone {
    (-1000i32..1000).prop_map(|value| value as f32)
}

/// Products of signs are exact in any order.
fn sign() -> impl Strategy<Value = f32> + Clone {
    prop_oneof![Just(-1.0f32), Just(1.0f32)]
}

fn add<T: std::ops::Add<Output = T>>(a: T, b: T) -> T {
    a + b
}

fn mul<T: std::ops::Mul<Output = T>>(a: T, b: T) -> T {
    a * b
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(16))]

    #[test]
    fn u32_monoids((values, flags) in values_and_flags(any::<u32>())) {
        for reference in [
            Reference { op: MonoidOp::Add, identity: 0, combine: u32::wrapping_add },
            Reference { op: MonoidOp::Mul, identity: 1, combine: u32::wrapping_mul },
            Reference { op: MonoidOp::Min, identity: u32::MAX, combine: Ord::min },
            Reference { op: MonoidOp::Max, identity: 0, combine: Ord::max },
        ] {
            check_monoid(&reference, &values, &flags)?;
        }
    }

    #[test]
    fn i32_monoids((values, flags) in values_and_flags(any::<i32>())) {
        for reference in [
            Reference { op: MonoidOp::Add, identity: 0, combine: i32::wrapping_add },
            Reference { op: MonoidOp::Mul, identity: 1, combine: i32::wrapping_mul },
            Reference { op: MonoidOp::Min, identity: i32::MAX, combine: Ord::min },
            Reference { op: MonoidOp::Max, identity: i32::MIN, combine: Ord::max },
        ] {
            check_monoid(&reference, &values, &flags)?;
        }
    }

    #[test]
    fn f32_sums((values, flags) in values_and_flags(small_integral_float())) {
        let reference = Reference { op: MonoidOp::Add, identity: 0.0, combine: add };
        check_monoid(&reference, &values, &flags)?;
    }

    #[test]
    fn f32_products((values, flags) in values_and_flags(sign())) {
        let reference = Reference { op: MonoidOp::Mul, identity: 1.0, combine: mul };
        check_monoid(&reference, &values, &flags)?;
    }

    #[test]
    fn f32_min_max((values, flags) in values_and_flags(-1e30f32..1e30)) {
        for reference in [
            Reference { op: MonoidOp::Min, identity: f32::INFINITY, combine: f32::min },
            Reference { op: MonoidOp::Max, identity: f32::NEG_INFINITY, combine: f32::max },
        ] {
            check_monoid(&reference, &values, &flags)?;
        }
    }

    #[test]
    fn vector_monoids(
        (values, flags) in values_and_flags(prop::array::uniform4(small_integral_float())),
    ) {
        let vec2s: Vec<Vec2> = values.iter().map(|v| Vec2::new(v[0], v[1])).collect();
        let vec3s: Vec<Vec3> = values.iter().map(|v| Vec3::new(v[0], v[1], v[2])).collect();
        let vec4s: Vec<Vec4> = values.iter().map(|&v| Vec4::from_array(v)).collect();
        for (op, identity, combine) in [
            (MonoidOp::Add, Vec2::ZERO, add as fn(Vec2, Vec2) -> Vec2),
            (MonoidOp::Min, Vec2::INFINITY, Vec2::min),
            (MonoidOp::Max, Vec2::NEG_INFINITY, Vec2::max),
        ] {
            check_monoid(&Reference { op, identity, combine }, &vec2s, &flags)?;
        }
        for (op, identity, combine) in [
            (MonoidOp::Add, Vec3::ZERO, add as fn(Vec3, Vec3) -> Vec3),
            (MonoidOp::Min, Vec3::INFINITY, Vec3::min),
            (MonoidOp::Max, Vec3::NEG_INFINITY, Vec3::max),
        ] {
            check_monoid(&Reference { op, identity, combine }, &vec3s, &flags)?;
        }
        for (op, identity, combine) in [
            (MonoidOp::Add, Vec4::ZERO, add as fn(Vec4, Vec4) -> Vec4),
            (MonoidOp::Min, Vec4::INFINITY, Vec4::min),
            (MonoidOp::Max, Vec4::NEG_INFINITY, Vec4::max),
        ] {
            check_monoid(&Reference { op, identity, combine }, &vec4s, &flags)?;
        }
    }

    #[test]
    fn vector_products((values, flags) in values_and_flags(prop::array::uniform3(sign()))) {
        let vec3s: Vec<Vec3> = values.iter().map(|&v| Vec3::from_array(v)).collect();
        let reference = Reference { op: MonoidOp::Mul, identity: Vec3::ONE, combine: mul };
        check_monoid(&reference, &vec3s, &flags)?;
    }

    #[test]
    fn bool_monoids((values, flags) in values_and_flags(any::<bool>())) {
        for reference in [
            Reference { op: MonoidOp::Or, identity: false, combine: |a, b| a || b },
            Reference { op: MonoidOp::And, identity: true, combine: |a, b| a && b },
        ] {
            check_monoid(&reference, &values, &flags)?;
        }
    }

    #[test]
    fn gather_matches_indexing(
        (src, indices) in prop::collection::vec(any::<i32>(), 1..50).prop_flat_map(|src| {
            let len = src.len() as u32;
            (Just(src), prop::collection::vec(0..len, 0..100))
        }),
    ) {
        let expected: Vec<i32> = indices.iter().map(|&index| src[index as usize]).collect();
        prop_assert_eq!(gather(&indices, &Column::I32(src).view())?, Column::I32(expected));
    }

    #[test]
    fn scatters_match_sequential_writes(
        (dst, indices, src, mask) in (1usize..40, 0usize..100).prop_flat_map(|(dst_len, len)| (
            prop::collection::vec(-1000i32..1000, dst_len),
            prop::collection::vec(0..dst_len as u32, len),
            prop::collection::vec(-1000i32..1000, len),
            prop::option::of(prop::collection::vec(any::<bool>(), len)),
        )),
    ) {
        let written = |position: usize| mask.as_ref().is_none_or(|mask| mask[position]);
        let mut overwritten = dst.clone();
        let mut summed = dst.clone();
        let mut smallest = dst.clone();
        for (position, (&index, &value)) in indices.iter().zip(&src).enumerate() {
            if written(position) {
                let index = index as usize;
                overwritten[index] = value;
                summed[index] += value;
                smallest[index] = smallest[index].min(value);
            }
        }
        let src_column = Column::I32(src);
        let mask = mask.as_deref();
        let mut result = Column::I32(dst.clone());
        scatter(&indices, &src_column.view(), mask, &mut result)?;
        prop_assert_eq!(result, Column::I32(overwritten));
        for (op, expected) in [(MonoidOp::Add, summed), (MonoidOp::Min, smallest)] {
            let mut result = Column::I32(dst.clone());
            scatter_combine(op, &indices, &src_column.view(), mask, &mut result)?;
            prop_assert_eq!(result, Column::I32(expected));
        }
    }
}

#[test]
fn segmented_scans_restart_at_flags() {
    let values = Column::U32(vec![1, 2, 3, 4, 5]);
    let flags = [false, false, true, false, true];
    for chunk in [1, 2, 3, DEFAULT_CHUNK] {
        let scan = |inclusive| {
            scan(
                MonoidOp::Add,
                &values.view(),
                inclusive,
                Some(&flags),
                chunk,
            )
        };
        assert_eq!(scan(true), Ok(Column::U32(vec![1, 3, 3, 7, 5])));
        assert_eq!(scan(false), Ok(Column::U32(vec![0, 1, 0, 3, 0])));
    }
}

/// Float sums depend on the chunk size but never on the number of threads.
#[test]
fn float_results_do_not_depend_on_the_thread_count() {
    let values: Vec<f32> = (0..4099u32)
        .map(|i| ((i.wrapping_mul(2_654_435_761) >> 8) as f32).sin() * 1e6)
        .collect();
    let column = Column::F32(values);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let total = reduce(MonoidOp::Add, &column.view(), TEST_CHUNK).unwrap();
            let scanned = scan(MonoidOp::Add, &column.view(), true, None, TEST_CHUNK).unwrap();
            let bits: Vec<u32> = scanned
                .view()
                .as_f32()
                .iter()
                .map(|x| x.to_bits())
                .collect();
            (total.as_f64().unwrap().to_bits(), bits)
        })
    };
    let single = run(1);
    assert_eq!(run(2), single);
    assert_eq!(run(3), single);
}

#[test]
fn reductions_become_host_values() {
    let reduce_default = |op, column: Column| reduce(op, &column.view(), DEFAULT_CHUNK);
    assert_eq!(
        reduce_default(MonoidOp::Add, Column::U32(vec![u32::MAX, 1])),
        Ok(HostValue::Int(0))
    );
    assert_eq!(
        reduce_default(MonoidOp::Min, Column::I32(vec![-5, 3])),
        Ok(HostValue::Int(-5))
    );
    assert_eq!(
        reduce_default(MonoidOp::Max, Column::F32(vec![0.5, 2.5])),
        Ok(HostValue::Float(2.5))
    );
    assert_eq!(
        reduce_default(MonoidOp::Or, Column::Bool(vec![false, true])),
        Ok(HostValue::Bool(true))
    );
    assert_eq!(
        reduce_default(MonoidOp::Add, Column::Vec3(vec![Vec3::X, Vec3::Y])),
        Ok(HostValue::Vec3([1.0, 1.0, 0.0]))
    );
    // An empty array reduces to the identity.
    assert_eq!(
        reduce_default(MonoidOp::Min, Column::U32(Vec::new())),
        Ok(HostValue::Int(u32::MAX.into()))
    );
}

#[test]
fn identities_and_supported_types() {
    assert_eq!(identity(MonoidOp::Add, ElemType::U32), Ok(Element::U32(0)));
    assert_eq!(
        identity(MonoidOp::Mul, ElemType::Vec2),
        Ok(Element::Vec2(Vec2::ONE))
    );
    assert_eq!(
        identity(MonoidOp::Min, ElemType::F32),
        Ok(Element::F32(f32::INFINITY))
    );
    assert_eq!(
        identity(MonoidOp::Max, ElemType::I32),
        Ok(Element::I32(i32::MIN))
    );
    assert_eq!(
        identity(MonoidOp::And, ElemType::Bool),
        Ok(Element::Bool(true))
    );
    for ty in ElemType::PRIMITIVES {
        for op in [MonoidOp::Add, MonoidOp::Mul, MonoidOp::Min, MonoidOp::Max] {
            assert_eq!(monoid_supports(op, ty), ty.is_numeric(), "{op:?} on {ty:?}");
        }
        for op in [MonoidOp::Or, MonoidOp::And] {
            assert_eq!(
                monoid_supports(op, ty),
                ty == ElemType::Bool,
                "{op:?} on {ty:?}"
            );
        }
    }
    assert!(!monoid_supports(
        MonoidOp::Add,
        ElemType::Record(RecordId(0))
    ));
}

#[test]
fn unsupported_operations_are_errors() {
    let flags = Column::Bool(vec![true, false]);
    assert_eq!(
        reduce(MonoidOp::Add, &flags.view(), TEST_CHUNK),
        Err(KernelError::UnsupportedOperation {
            op: MonoidOp::Add,
            ty: ElemType::Bool
        })
    );
    let error = scan(
        MonoidOp::Or,
        &Column::U32(vec![]).view(),
        true,
        None,
        TEST_CHUNK,
    );
    assert_eq!(
        error.unwrap_err().to_string(),
        "`or` is not defined on U32 elements"
    );
    assert!(combine_columns(MonoidOp::Max, &flags.view(), &flags.view()).is_err());
}

#[test]
fn combine_columns_is_elementwise() {
    let a = Column::Vec2(vec![Vec2::new(1.0, 5.0), Vec2::ZERO]);
    let b = Column::Vec2(vec![Vec2::new(2.0, 3.0), Vec2::ONE]);
    assert_eq!(
        combine_columns(MonoidOp::Max, &a.view(), &b.view()),
        Ok(Column::Vec2(vec![Vec2::new(2.0, 5.0), Vec2::ONE]))
    );
    assert_eq!(
        combine_columns(MonoidOp::Max, &a.view(), &a.slice(0..1)),
        Err(KernelError::LengthMismatch {
            what: "the second operand",
            expected: 2,
            found: 1
        })
    );
}

#[test]
fn reduce_groups_folds_whole_groups() {
    let values = Column::U32((1..=7).collect());
    assert_eq!(
        reduce_groups(MonoidOp::Add, &values.view(), 3),
        Ok(Column::U32(vec![6, 15]))
    );
    assert_eq!(
        reduce_groups(MonoidOp::Add, &values.view(), 0),
        Err(KernelError::EmptyGroup)
    );
}

#[test]
fn run_chunked_returns_results_in_range_order() {
    assert_eq!(run_chunked(0, 64, |range| range), Vec::new());
    assert_eq!(
        run_chunked(130, 64, |range| range),
        vec![0..64, 64..128, 128..130]
    );
}

/// A record column with a `u32` and a `vec3` field; kernels never consult the record type.
fn records(counts: &[u32], positions: &[Vec3]) -> Column {
    Column::Record {
        ty: RecordId(0),
        fields: vec![
            Arc::new(Column::U32(counts.to_vec())),
            Arc::new(Column::Vec3(positions.to_vec())),
        ],
    }
}

#[test]
fn gather_and_scatter_records() {
    let src = records(&[1, 2, 3], &[Vec3::X, Vec3::Y, Vec3::Z]);
    assert_eq!(
        gather(&[2, 2, 0], &src.view()),
        Ok(records(&[3, 3, 1], &[Vec3::Z, Vec3::Z, Vec3::X]))
    );
    let mut dst = records(&[0; 4], &[Vec3::ZERO; 4]);
    scatter(
        &[3, 0, 3],
        &src.view(),
        Some(&[true, true, false]),
        &mut dst,
    )
    .unwrap();
    assert_eq!(
        dst,
        records(&[2, 0, 0, 1], &[Vec3::Y, Vec3::ZERO, Vec3::ZERO, Vec3::X])
    );
}

/// A stage's combining scatter: its chunks' parts in turn, on any number of
/// threads, give the sequential kernel's bits, float sums into a slot from
/// several parts included (their order changes the sum), over a target large
/// enough to be cut into several ranges.
#[test]
fn combining_scatter_of_parts_is_sequential_on_any_thread_count() {
    let dst_len = 300_007;
    let initial: Vec<f32> = (0..dst_len).map(|slot| (slot % 7) as f32 * 0.1).collect();
    // Part `p` writes a run of slots from its own start, with a stride that
    // crosses the others' runs, and values of very different magnitudes.
    struct OwnedPart {
        indices: Vec<u32>,
        values: Column,
        mask: Option<Vec<bool>>,
    }
    let owned: Vec<OwnedPart> = (0..23u32)
        .map(|p| {
            let len = 9_000 + 1_000 * p as usize;
            let sign = if p % 2 == 0 { 1.0 } else { -1.0 };
            OwnedPart {
                indices: (0..len as u32)
                    .map(|i| (p * 13_001 + i * (1 + p % 5)) % dst_len as u32)
                    .collect(),
                values: Column::F32(
                    (0..len)
                        .map(|i| sign * if i % 3 == 0 { 1.0e7 } else { 0.3 + p as f32 })
                        .collect(),
                ),
                mask: (p % 4 == 1).then(|| (0..len).map(|i| i % 5 != 0).collect()),
            }
        })
        .collect();
    let scatter_parts: Vec<ScatterPart<'_>> = owned
        .iter()
        .map(|part| ScatterPart {
            indices: &part.indices,
            src: part.values.view(),
            mask: part.mask.as_deref(),
        })
        .collect();
    let mut expected = Column::F32(initial.clone());
    for part in &scatter_parts {
        scatter_combine(
            MonoidOp::Add,
            part.indices,
            &part.src,
            part.mask,
            &mut expected,
        )
        .unwrap();
    }
    for threads in [1, 2, 3, 8] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let mut result = Column::F32(initial.clone());
        pool.install(|| scatter_combine_parts(MonoidOp::Add, &scatter_parts, &mut result))
            .unwrap();
        assert_eq!(result, expected, "{threads} threads");
    }
    // A bad index in the last part: nothing is written.
    let bad = [0, dst_len as u32];
    let bad_values = Column::F32(vec![1.0, 2.0]);
    let mut with_bad = scatter_parts.clone();
    with_bad.push(ScatterPart {
        indices: &bad,
        src: bad_values.view(),
        mask: None,
    });
    let mut result = Column::F32(initial.clone());
    assert!(scatter_combine_parts(MonoidOp::Add, &with_bad, &mut result).is_err());
    assert_eq!(result, Column::F32(initial));
}

#[test]
fn out_of_range_indices_are_errors() {
    let src = Column::F32(vec![1.0, 2.0, 3.0]);
    let out_of_range = KernelError::IndexOutOfRange {
        position: 1,
        index: 5,
        len: 3,
    };
    assert_eq!(gather(&[0, 5, 1], &src.view()), Err(out_of_range.clone()));
    assert_eq!(
        out_of_range.to_string(),
        "index 5 (at position 1) is out of range for an array of length 3"
    );
    assert!(gather(&[0], &Column::F32(Vec::new()).view()).is_err());

    let mut dst = Column::F32(vec![0.0; 3]);
    assert_eq!(
        scatter(&[0, 5, 1], &src.view(), None, &mut dst),
        Err(out_of_range.clone())
    );
    assert_eq!(
        scatter_combine(MonoidOp::Add, &[0, 5, 1], &src.view(), None, &mut dst),
        Err(out_of_range)
    );
    // A failed scatter writes nothing.
    assert_eq!(dst, Column::F32(vec![0.0; 3]));
    // Masked-out elements may carry any index (a compaction's dropped elements).
    scatter(
        &[0, 5, 1],
        &src.view(),
        Some(&[true, false, true]),
        &mut dst,
    )
    .unwrap();
    assert_eq!(dst, Column::F32(vec![1.0, 3.0, 0.0]));
}

#[test]
fn scatter_argument_mismatches_are_errors() {
    let src = Column::U32(vec![1, 2]);
    let mut dst = Column::U32(vec![0; 4]);
    assert_eq!(
        scatter(&[0], &src.view(), None, &mut dst),
        Err(KernelError::LengthMismatch {
            what: "the scattered array",
            expected: 1,
            found: 2
        })
    );
    assert!(scatter(&[0, 1], &src.view(), Some(&[true]), &mut dst).is_err());
    let mut floats = Column::F32(vec![0.0; 4]);
    assert_eq!(
        scatter(&[0, 1], &src.view(), None, &mut floats),
        Err(KernelError::TypeMismatch {
            expected: ElemType::F32,
            found: ElemType::U32
        })
    );
}
