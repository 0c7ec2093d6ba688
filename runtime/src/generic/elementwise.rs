//! The generic `map` functors: one element of each input to one output element.

use super::{
    functor, signature, unexpected_type, ANY, BOOL, F32, NUMERIC, SCALAR, SCALAR_OR_BOOL, U32,
};
use crate::column::{Column, ColumnView};
use crate::cpu::kernels::{check_length, typed_slice, with_element_type, PrimitiveElement};
use crate::functor::{
    CallContext, Functor, FunctorError, FunctorKind, NamedParam, Signature, TypePattern,
};
use crate::host::HostValue;
use crate::types::{ElemType, HostType};
use glam::{Vec2, Vec3, Vec4};
use std::sync::Arc;

pub(super) fn functors() -> Vec<Arc<dyn Functor>> {
    let binary = |ty| [("a", ty), ("b", ty)];
    let mut functors = vec![
        functor(
            map(
                "sub",
                &binary(NUMERIC),
                NUMERIC,
                "a - b, componentwise; u32 and i32 wrap around",
            ),
            |_, inputs| subtract(inputs),
        ),
        functor(
            map(
                "div",
                &binary(NUMERIC),
                NUMERIC,
                "a / b, componentwise; integers truncate toward zero, an integer division by zero is an error",
            ),
            divide,
        ),
        functor(
            map("not", &[("x", BOOL)], BOOL, "!x"),
            |_, inputs| Ok(map_with(typed_slice::<bool>(&inputs[0])?, |x| !x)),
        ),
        functor(
            map(
                "select",
                &[("cond", BOOL), ("a", ANY), ("b", ANY)],
                ANY,
                "a where cond, else b (any element type, records too)",
            ),
            |_, inputs| select(typed_slice::<bool>(&inputs[0])?, &inputs[1], &inputs[2]),
        ),
        functor(
            map(
                "identity",
                &[("x", ANY)],
                ANY,
                "x unchanged (a copy), for any element type",
            ),
            |_, inputs| Ok(inputs[0].to_column()),
        ),
        functor(
            map(
                "isZero",
                &[("x", SCALAR)],
                BOOL,
                "x == 0 (true for -0.0, false for NaN)",
            ),
            |_, inputs| compare_with_zero(inputs, true),
        ),
        functor(
            map(
                "nonZero",
                &[("x", SCALAR)],
                BOOL,
                "x != 0 (false for -0.0, true for NaN)",
            ),
            |_, inputs| compare_with_zero(inputs, false),
        ),
        functor(
            Signature {
                named: vec![seed_param()],
                ..map(
                    "hash",
                    &[("x", U32)],
                    U32,
                    "a stateless pseudo-random u32 per element: the PCG hash of x mixed with the hashed seed",
                )
            },
            |ctx, inputs| {
                let seed = seed(ctx)?;
                let values = typed_slice::<u32>(&inputs[0])?;
                Ok(map_with(values, |x| seeded_hash(x, seed)))
            },
        ),
        functor(
            Signature {
                named: vec![seed_param()],
                ..map(
                    "random",
                    &[("x", U32)],
                    F32,
                    "a stateless pseudo-random f32 in [0, 1) per element: the top 24 bits of hash(x)",
                )
            },
            |ctx, inputs| {
                let seed = seed(ctx)?;
                let values = typed_slice::<u32>(&inputs[0])?;
                Ok(map_with(values, |x| unit_float(seeded_hash(x, seed))))
            },
        ),
    ];
    let comparisons = [
        ("eq", Comparison::Equal, SCALAR_OR_BOOL, "a == b"),
        ("ne", Comparison::NotEqual, SCALAR_OR_BOOL, "a != b"),
        (
            "lt",
            Comparison::Less,
            SCALAR,
            "a < b (false where either is NaN)",
        ),
        (
            "le",
            Comparison::LessOrEqual,
            SCALAR,
            "a <= b (false where either is NaN)",
        ),
        (
            "gt",
            Comparison::Greater,
            SCALAR,
            "a > b (false where either is NaN)",
        ),
        (
            "ge",
            Comparison::GreaterOrEqual,
            SCALAR,
            "a >= b (false where either is NaN)",
        ),
    ];
    functors.extend(comparisons.into_iter().map(|(name, comparison, ty, doc)| {
        functor(map(name, &binary(ty), BOOL, doc), move |_, inputs| {
            compare(comparison, inputs)
        })
    }));
    let conversions = [
        (
            "toU32",
            ElemType::U32,
            "to u32: bool is 0 or 1, negative i32 saturate to 0, f32 truncate toward zero and saturate (NaN is 0)",
        ),
        (
            "toI32",
            ElemType::I32,
            "to i32: bool is 0 or 1, u32 above i32::MAX saturate, f32 truncate toward zero and saturate (NaN is 0)",
        ),
        (
            "toF32",
            ElemType::F32,
            "to f32: bool is 0 or 1, integers round to the nearest f32",
        ),
    ];
    functors.extend(conversions.into_iter().map(|(name, target, doc)| {
        let output = TypePattern::Exact(target);
        functor(
            map(name, &[("x", SCALAR_OR_BOOL)], output, doc),
            move |_, inputs| convert(target, inputs),
        )
    }));
    functors
}

fn map(
    name: &'static str,
    inputs: &[(&'static str, TypePattern)],
    output: TypePattern,
    doc: &'static str,
) -> Signature {
    signature(FunctorKind::Map, name, inputs, output, doc)
}

fn map_with<T: Copy, U: PrimitiveElement>(values: &[T], f: impl Fn(T) -> U) -> Column {
    U::into_column(values.iter().map(|&x| f(x)).collect())
}

fn zip_with<T: Copy, U: PrimitiveElement>(a: &[T], b: &[T], f: impl Fn(T, T) -> U) -> Column {
    U::into_column(a.iter().zip(b).map(|(&x, &y)| f(x, y)).collect())
}

/// The inputs `a` and `b` of a binary functor, of the same type and length.
fn operands<'a, T: PrimitiveElement>(
    inputs: &[ColumnView<'a>],
) -> Result<(&'a [T], &'a [T]), FunctorError> {
    let (a, b) = (typed_slice::<T>(&inputs[0])?, typed_slice::<T>(&inputs[1])?);
    check_length("the second operand", a.len(), b.len())?;
    Ok((a, b))
}

/// `sub` and `div` per numeric type; integers wrap around like `add` and `mul` do.
trait Arithmetic: Copy {
    fn subtract(self, other: Self) -> Self;
    /// `None` for an integer division by zero (`i32::MIN / -1` wraps to `i32::MIN`).
    fn divide(self, other: Self) -> Option<Self>;
}

macro_rules! impl_integer_arithmetic {
    ($($t:ty),*) => {$(
        impl Arithmetic for $t {
            fn subtract(self, other: Self) -> Self {
                self.wrapping_sub(other)
            }

            fn divide(self, other: Self) -> Option<Self> {
                (other != 0).then(|| self.wrapping_div(other))
            }
        }
    )*};
}

impl_integer_arithmetic!(u32, i32);

macro_rules! impl_float_arithmetic {
    ($($t:ty),*) => {$(
        impl Arithmetic for $t {
            fn subtract(self, other: Self) -> Self {
                self - other
            }

            fn divide(self, other: Self) -> Option<Self> {
                Some(self / other)
            }
        }
    )*};
}

impl_float_arithmetic!(f32, Vec2, Vec3, Vec4);

fn subtract(inputs: &[ColumnView<'_>]) -> Result<Column, FunctorError> {
    with_element_type!(inputs[0].elem_type(), numeric, T => {
        let (a, b) = operands::<T>(inputs)?;
        Ok(zip_with(a, b, T::subtract))
    }, other => Err(unexpected_type(other)))
}

fn divide(ctx: &CallContext<'_>, inputs: &[ColumnView<'_>]) -> Result<Column, FunctorError> {
    with_element_type!(inputs[0].elem_type(), numeric, T => {
        let (a, b) = operands::<T>(inputs)?;
        let quotients = a.iter().zip(b).enumerate().map(|(position, (&x, &y))| {
            x.divide(y).ok_or_else(|| {
                FunctorError(format!(
                    "integer division by zero at element {}",
                    ctx.first_index + position
                ))
            })
        });
        Ok(T::into_column(quotients.collect::<Result<_, _>>()?))
    }, other => Err(unexpected_type(other)))
}

#[derive(Clone, Copy)]
enum Comparison {
    Equal,
    NotEqual,
    Less,
    LessOrEqual,
    Greater,
    GreaterOrEqual,
}

fn compare(comparison: Comparison, inputs: &[ColumnView<'_>]) -> Result<Column, FunctorError> {
    with_element_type!(inputs[0].elem_type(), scalar_or_bool, T => {
        let (a, b) = operands::<T>(inputs)?;
        let holds: fn(&T, &T) -> bool = match comparison {
            Comparison::Equal => PartialEq::eq,
            Comparison::NotEqual => PartialEq::ne,
            Comparison::Less => PartialOrd::lt,
            Comparison::LessOrEqual => PartialOrd::le,
            Comparison::Greater => PartialOrd::gt,
            Comparison::GreaterOrEqual => PartialOrd::ge,
        };
        Ok(zip_with(a, b, |x, y| holds(&x, &y)))
    }, other => Err(unexpected_type(other)))
}

fn compare_with_zero(inputs: &[ColumnView<'_>], equal: bool) -> Result<Column, FunctorError> {
    with_element_type!(inputs[0].elem_type(), scalar, T => {
        let values = typed_slice::<T>(&inputs[0])?;
        // `Default` is zero for every primitive type.
        Ok(map_with(values, |x| (x == T::default()) == equal))
    }, other => Err(unexpected_type(other)))
}

/// The conversions between `bool`, `u32`, `i32` and `f32`. Out-of-range values
/// saturate rather than wrap, so a negative count or an overlarge float never
/// becomes a huge index.
pub(super) trait ScalarConversions: Copy {
    fn to_u32(self) -> u32;
    fn to_i32(self) -> i32;
    fn to_f32(self) -> f32;
}

impl ScalarConversions for bool {
    fn to_u32(self) -> u32 {
        self.into()
    }

    fn to_i32(self) -> i32 {
        self.into()
    }

    fn to_f32(self) -> f32 {
        u8::from(self).into()
    }
}

impl ScalarConversions for u32 {
    fn to_u32(self) -> u32 {
        self
    }

    fn to_i32(self) -> i32 {
        i32::try_from(self).unwrap_or(i32::MAX)
    }

    fn to_f32(self) -> f32 {
        self as f32
    }
}

impl ScalarConversions for i32 {
    fn to_u32(self) -> u32 {
        u32::try_from(self).unwrap_or(0)
    }

    fn to_i32(self) -> i32 {
        self
    }

    fn to_f32(self) -> f32 {
        self as f32
    }
}

// Rust's float-to-integer `as` truncates toward zero, saturates and maps NaN to 0.
impl ScalarConversions for f32 {
    fn to_u32(self) -> u32 {
        self as u32
    }

    fn to_i32(self) -> i32 {
        self as i32
    }

    fn to_f32(self) -> f32 {
        self
    }
}

fn convert(target: ElemType, inputs: &[ColumnView<'_>]) -> Result<Column, FunctorError> {
    with_element_type!(inputs[0].elem_type(), scalar_or_bool, T => {
        let values = typed_slice::<T>(&inputs[0])?;
        match target {
            ElemType::U32 => Ok(map_with(values, T::to_u32)),
            ElemType::I32 => Ok(map_with(values, T::to_i32)),
            ElemType::F32 => Ok(map_with(values, T::to_f32)),
            other => Err(unexpected_type(other)),
        }
    }, other => Err(unexpected_type(other)))
}

/// `a[i]` where `condition[i]`, else `b[i]`; records field by field.
fn select(
    condition: &[bool],
    a: &ColumnView<'_>,
    b: &ColumnView<'_>,
) -> Result<Column, FunctorError> {
    check_length("the first alternative", condition.len(), a.len())?;
    check_length("the second alternative", condition.len(), b.len())?;
    if a.elem_type() != b.elem_type() {
        return Err(unexpected_type(b.elem_type()));
    }
    if let (ColumnView::Record { ty, fields }, ColumnView::Record { fields: others, .. }) = (a, b) {
        let fields = fields
            .iter()
            .zip(others)
            .map(|(field, other)| select(condition, field, other).map(Arc::new))
            .collect::<Result<_, _>>()?;
        return Ok(Column::Record { ty: *ty, fields });
    }
    with_element_type!(a.elem_type(), primitive, T => {
        let (a, b) = (typed_slice::<T>(a)?, typed_slice::<T>(b)?);
        let chosen = condition.iter().zip(a.iter().zip(b));
        Ok(T::into_column(chosen.map(|(&take_a, (&x, &y))| if take_a { x } else { y }).collect()))
    }, other => Err(unexpected_type(other)))
}

fn seed_param() -> NamedParam {
    NamedParam {
        name: "seed",
        ty: HostType::Int,
        default: Some(HostValue::Int(0)),
        doc: "chooses an independent hash; taken modulo 2^32",
    }
}

fn seed(ctx: &CallContext<'_>) -> Result<u32, FunctorError> {
    match ctx.named.first() {
        // Modulo 2^32, so negative seeds are usable too.
        Some(HostValue::Int(seed)) => Ok(*seed as u32),
        other => Err(FunctorError(format!(
            "internal error: the seed should be an integer, got {other:?}"
        ))),
    }
}

/// The PCG hash of Jarzynski and Olano ("Hash Functions for GPU Rendering",
/// JCGT 2020): one step of a PCG generator and its RXS-M-XS output
/// permutation. Good statistical quality for its cost, and a few WGSL lines.
fn pcg_hash(input: u32) -> u32 {
    let state = input.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
    let word = ((state >> ((state >> 28) + 4)) ^ state).wrapping_mul(277_803_737);
    (word >> 22) ^ word
}

/// `hash(x, seed: s)`. The seed is hashed first so that nearby seeds give
/// unrelated streams.
fn seeded_hash(value: u32, seed: u32) -> u32 {
    pcg_hash(value ^ pcg_hash(seed))
}

/// The top 24 bits of `bits` as a float in `[0, 1)`: exactly representable,
/// so the largest result stays below 1.
fn unit_float(bits: u32) -> f32 {
    (bits >> 8) as f32 / (1 << 24) as f32
}
