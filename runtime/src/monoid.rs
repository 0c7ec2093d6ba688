//! The monoids of `reduce`, `scan`, combining `scatter` and the monoid
//! functors: which operation exists on which element type, its identity and
//! how it combines, defined once for the type checker and every backend (the
//! GPU backend spells the same identities and combining functions in WGSL).

use crate::column::{Column, ColumnView};
use crate::elem::check_length;
use crate::elem::{
    typed_element, typed_slice, with_element_type, Element, KernelError, PrimitiveElement,
};
use crate::types::ElemType;
use glam::{Vec2, Vec3, Vec4};

pub use crate::types::MonoidOp;

/// The monoid operations of an element type. Which ones exist: `add`, `mul`,
/// `min`, `max` on `u32`, `i32`, `f32` and (componentwise) `vec2`–`vec4`;
/// `or`, `and` on `bool`.
///
/// `u32` and `i32` `add` and `mul` wrap around on overflow (as WGSL does).
/// `f32` `min`/`max` ignore a NaN operand (IEEE `minNum`); vectors follow glam,
/// whose SIMD types may return either operand.
pub trait MonoidElement: PrimitiveElement {
    /// The identity of `op`, or `None` where `op` is not defined on this type.
    fn identity(op: MonoidOp) -> Option<Self>;
    /// `a op b`; only called with an `op` whose identity exists.
    fn combine(op: MonoidOp, a: Self, b: Self) -> Self;
}

macro_rules! impl_integer_monoid {
    ($($t:ty),*) => {$(
        impl MonoidElement for $t {
            fn identity(op: MonoidOp) -> Option<Self> {
                match op {
                    MonoidOp::Add => Some(0),
                    MonoidOp::Mul => Some(1),
                    MonoidOp::Min => Some(<$t>::MAX),
                    MonoidOp::Max => Some(<$t>::MIN),
                    MonoidOp::Or | MonoidOp::And => None,
                }
            }

            #[inline(always)]
            fn combine(op: MonoidOp, a: Self, b: Self) -> Self {
                match op {
                    MonoidOp::Add => a.wrapping_add(b),
                    MonoidOp::Mul => a.wrapping_mul(b),
                    MonoidOp::Min => a.min(b),
                    MonoidOp::Max => a.max(b),
                    MonoidOp::Or | MonoidOp::And => {
                        unreachable!("{op:?} has no identity on {}", stringify!($t))
                    }
                }
            }
        }
    )*};
}

impl_integer_monoid!(u32, i32);

/// `f32::min`/`max` per component: NaN is ignored, so the operation stays
/// associative and a GPU reduction in another order agrees.
trait NanIgnoringMinMax: Copy {
    fn nan_ignoring_min(self, other: Self) -> Self;
    fn nan_ignoring_max(self, other: Self) -> Self;
}

impl NanIgnoringMinMax for f32 {
    fn nan_ignoring_min(self, other: f32) -> f32 {
        self.min(other)
    }
    fn nan_ignoring_max(self, other: f32) -> f32 {
        self.max(other)
    }
}

macro_rules! impl_nan_ignoring_vector {
    ($($t:ty),*) => {$(
        impl NanIgnoringMinMax for $t {
            fn nan_ignoring_min(self, other: $t) -> $t {
                let (a, b) = (self.to_array(), other.to_array());
                <$t>::from_array(std::array::from_fn(|i| a[i].min(b[i])))
            }
            fn nan_ignoring_max(self, other: $t) -> $t {
                let (a, b) = (self.to_array(), other.to_array());
                <$t>::from_array(std::array::from_fn(|i| a[i].max(b[i])))
            }
        }
    )*};
}

impl_nan_ignoring_vector!(Vec2, Vec3, Vec4);

macro_rules! impl_float_monoid {
    ($($t:ty: zero $zero:expr, one $one:expr, infinity $infinity:expr;)*) => {$(
        impl MonoidElement for $t {
            fn identity(op: MonoidOp) -> Option<Self> {
                match op {
                    MonoidOp::Add => Some($zero),
                    MonoidOp::Mul => Some($one),
                    MonoidOp::Min => Some($infinity),
                    MonoidOp::Max => Some(-$infinity),
                    MonoidOp::Or | MonoidOp::And => None,
                }
            }

            #[inline(always)]
            fn combine(op: MonoidOp, a: Self, b: Self) -> Self {
                match op {
                    MonoidOp::Add => a + b,
                    MonoidOp::Mul => a * b,
                    MonoidOp::Min => a.nan_ignoring_min(b),
                    MonoidOp::Max => a.nan_ignoring_max(b),
                    MonoidOp::Or | MonoidOp::And => {
                        unreachable!("{op:?} has no identity on {}", stringify!($t))
                    }
                }
            }
        }
    )*};
}

impl_float_monoid! {
    f32: zero 0.0, one 1.0, infinity f32::INFINITY;
    Vec2: zero Vec2::ZERO, one Vec2::ONE, infinity Vec2::INFINITY;
    Vec3: zero Vec3::ZERO, one Vec3::ONE, infinity Vec3::INFINITY;
    Vec4: zero Vec4::ZERO, one Vec4::ONE, infinity Vec4::INFINITY;
}

impl MonoidElement for bool {
    fn identity(op: MonoidOp) -> Option<Self> {
        match op {
            MonoidOp::Or => Some(false),
            MonoidOp::And => Some(true),
            MonoidOp::Add | MonoidOp::Mul | MonoidOp::Min | MonoidOp::Max => None,
        }
    }

    fn combine(op: MonoidOp, a: Self, b: Self) -> Self {
        match op {
            MonoidOp::Or => a || b,
            MonoidOp::And => a && b,
            MonoidOp::Add | MonoidOp::Mul | MonoidOp::Min | MonoidOp::Max => {
                unreachable!("{op:?} has no identity on bool")
            }
        }
    }
}

/// A monoid operation checked to exist on `T`.
#[derive(Clone, Copy)]
pub(crate) struct Monoid<T> {
    op: MonoidOp,
    pub(crate) identity: T,
}

impl<T: MonoidElement> Monoid<T> {
    pub(crate) fn new(op: MonoidOp) -> Result<Monoid<T>, KernelError> {
        let identity = T::identity(op).ok_or(KernelError::UnsupportedOperation {
            op,
            ty: T::ELEM_TYPE,
        })?;
        Ok(Monoid { op, identity })
    }

    pub(crate) fn combine(self, a: T, b: T) -> T {
        T::combine(self.op, a, b)
    }

    /// `start op values[0] op values[1] …`, left to right, with the
    /// operation matched once, outside the loop ([`per_operation`]).
    pub(crate) fn fold(self, start: T, values: &[T]) -> T {
        per_operation(self.op, |op| fold_with(op, start, values))
    }
}

#[inline(always)]
fn fold_with<T: MonoidElement>(op: MonoidOp, start: T, values: &[T]) -> T {
    values.iter().fold(start, |accumulated, &value| {
        T::combine(op, accumulated, value)
    })
}

/// `body(op)`, with `op` a constant in each arm, so that a loop in `body`
/// is compiled once per operation with no `match` per element: with the
/// `match` inside, a loop ran 3-4x slower than a plain map
/// (docs/benchmarks.md, "Shading written as expressions").
#[inline(always)]
fn per_operation<R>(op: MonoidOp, body: impl Fn(MonoidOp) -> R) -> R {
    match op {
        MonoidOp::Add => body(MonoidOp::Add),
        MonoidOp::Mul => body(MonoidOp::Mul),
        MonoidOp::Min => body(MonoidOp::Min),
        MonoidOp::Max => body(MonoidOp::Max),
        MonoidOp::Or => body(MonoidOp::Or),
        MonoidOp::And => body(MonoidOp::And),
    }
}

pub(crate) fn unsupported(op: MonoidOp, ty: ElemType) -> KernelError {
    KernelError::UnsupportedOperation { op, ty }
}

/// Whether `op` is defined on elements of type `ty` (see [`MonoidElement`]).
pub fn monoid_supports(op: MonoidOp, ty: ElemType) -> bool {
    identity(op, ty).is_ok()
}

/// The identity of `op` on `ty`: `0` for `add`, `1` for `mul`, the largest
/// value (`+inf` for floats) for `min`, the smallest for `max`, `false` for
/// `or`, `true` for `and`.
pub fn identity(op: MonoidOp, ty: ElemType) -> Result<Element, KernelError> {
    with_element_type!(ty, primitive, T => Ok(Monoid::<T>::new(op)?.identity.into_element()),
        record => Err(unsupported(op, record)))
}

/// `a op b` for two elements of the same type.
pub fn combine_elements(op: MonoidOp, a: Element, b: Element) -> Result<Element, KernelError> {
    with_element_type!(a.elem_type(), primitive, T => {
        let monoid = Monoid::<T>::new(op)?;
        Ok(monoid.combine(typed_element(a)?, typed_element(b)?).into_element())
    }, record => Err(unsupported(op, record)))
}

/// `out[i] = a[i] op b[i]`: the CPU implementation of the monoid functors in `map`.
pub fn combine_columns(
    op: MonoidOp,
    a: &ColumnView<'_>,
    b: &ColumnView<'_>,
) -> Result<Column, KernelError> {
    check_length("the second operand", a.len(), b.len())?;
    with_element_type!(a.elem_type(), primitive, T => {
        Monoid::<T>::new(op)?;
        let (a, b) = (typed_slice::<T>(a)?, typed_slice::<T>(b)?);
        Ok(T::into_column(per_operation(op, |op| -> Vec<T> {
            a.iter().zip(b).map(|(&x, &y)| T::combine(op, x, y)).collect()
        })))
    }, record => Err(unsupported(op, record)))
}

/// `out[i] = values[i*k] op … op values[i*k + k-1]`, folded left to right from
/// the identity; `len(out) = len(values) / k`, a trailing partial group is ignored.
pub fn reduce_groups(
    op: MonoidOp,
    values: &ColumnView<'_>,
    group: usize,
) -> Result<Column, KernelError> {
    if group == 0 {
        return Err(KernelError::EmptyGroup);
    }
    with_element_type!(values.elem_type(), primitive, T => {
        let identity = Monoid::<T>::new(op)?.identity;
        let values = typed_slice::<T>(values)?;
        Ok(T::into_column(per_operation(op, |op| -> Vec<T> {
            values
                .chunks_exact(group)
                .map(|group| fold_with(op, identity, group))
                .collect()
        })))
    }, record => Err(unsupported(op, record)))
}
