//! The CPU backend's kernels for the primitives other than `map`: `gather`,
//! `scatter` (plain and combining), `reduce` and `scan`, and the monoid
//! arithmetic they share with the generic monoid functors.
//!
//! Every kernel runs sequentially over the slice it is given. The parallel
//! drivers ([`reduce`], [`scan`], built on [`run_chunked`]) split their input
//! into chunks of a fixed size and combine the chunk results in chunk order, so
//! a result never depends on the number of threads or on scheduling. Integer,
//! `bool`, `min` and `max` results do not depend on the chunk size either;
//! float sums and products do (floating-point `+` and `*` are not associative),
//! which is why the backend uses one fixed chunk size, [`DEFAULT_CHUNK`].
//!
//! Bad user data (an index out of range) is reported as a [`KernelError`], never
//! a panic. A type mismatch between arguments is a plan-compiler bug; it is an
//! error too, but a kernel may have written part of its output by then.

use crate::column::{Column, ColumnView};
use crate::functor::{FunctorError, MonoidOp};
use crate::host::HostValue;
use crate::map_primitive;
use crate::types::{ElemType, RecordRegistry};
use glam::{Vec2, Vec3, Vec4};
use rayon::prelude::*;
use std::fmt;
use std::ops::Range;
use std::sync::Arc;

/// The number of elements per chunk of the CPU backend. Fixed (rather than
/// derived from the thread count) so that float reductions and scans give the
/// same bits on every machine.
pub const DEFAULT_CHUNK: usize = 4096;

#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum KernelError {
    #[error("index {index} (at position {position}) is out of range for an array of length {len}")]
    IndexOutOfRange {
        position: usize,
        index: u32,
        len: usize,
    },
    #[error("{what} has length {found}, expected {expected}")]
    LengthMismatch {
        what: &'static str,
        expected: usize,
        found: usize,
    },
    #[error("{found:?} elements where {expected:?} elements were expected")]
    TypeMismatch { expected: ElemType, found: ElemType },
    #[error("`{}` is not defined on {ty:?} elements", monoid_name(*.op))]
    UnsupportedOperation { op: MonoidOp, ty: ElemType },
    #[error("a group needs at least one element")]
    EmptyGroup,
}

/// The functor that performs `op`, as pipelines spell it.
pub(crate) fn monoid_name(op: MonoidOp) -> &'static str {
    match op {
        MonoidOp::Add => "add",
        MonoidOp::Mul => "mul",
        MonoidOp::Min => "min",
        MonoidOp::Max => "max",
        MonoidOp::Or => "or",
        MonoidOp::And => "and",
    }
}

// Functors call kernels for their per-chunk work and report kernel errors as their own.
impl From<KernelError> for FunctorError {
    fn from(error: KernelError) -> FunctorError {
        FunctorError(error.to_string())
    }
}

/// One element of a primitive type: a reduction's partial result, a scan's
/// carry, a monoid identity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Element {
    Bool(bool),
    U32(u32),
    I32(i32),
    F32(f32),
    Vec2(Vec2),
    Vec3(Vec3),
    Vec4(Vec4),
}

impl Element {
    pub fn elem_type(self) -> ElemType {
        match self {
            Element::Bool(_) => ElemType::Bool,
            Element::U32(_) => ElemType::U32,
            Element::I32(_) => ElemType::I32,
            Element::F32(_) => ElemType::F32,
            Element::Vec2(_) => ElemType::Vec2,
            Element::Vec3(_) => ElemType::Vec3,
            Element::Vec4(_) => ElemType::Vec4,
        }
    }

    /// The host scalar a `reduce` returns: integers widen to `Int`, `f32` to `Float`.
    pub fn to_host(self) -> HostValue {
        match self {
            Element::Bool(value) => HostValue::Bool(value),
            Element::U32(value) => HostValue::Int(value.into()),
            Element::I32(value) => HostValue::Int(value.into()),
            Element::F32(value) => HostValue::Float(value.into()),
            Element::Vec2(value) => HostValue::Vec2(value.to_array()),
            Element::Vec3(value) => HostValue::Vec3(value.to_array()),
            Element::Vec4(value) => HostValue::Vec4(value.to_array()),
        }
    }
}

/// The Rust type of a primitive element type, with typed access to columns,
/// views and [`Element`]s, so kernels can be written once as generic functions.
pub trait PrimitiveElement:
    Copy + PartialEq + Default + fmt::Debug + Send + Sync + 'static
{
    const ELEM_TYPE: ElemType;
    fn slice_of<'a>(view: &ColumnView<'a>) -> Option<&'a [Self]>;
    fn vec_of(column: &mut Column) -> Option<&mut Vec<Self>>;
    fn into_column(values: Vec<Self>) -> Column;
    fn into_element(self) -> Element;
    fn from_element(element: Element) -> Option<Self>;
}

/// The Rust type behind a variant name of [`ElemType`]; used by [`with_element_type`].
macro_rules! element_rust_type {
    (Bool) => {
        bool
    };
    (U32) => {
        u32
    };
    (I32) => {
        i32
    };
    (F32) => {
        f32
    };
    (Vec2) => {
        ::glam::Vec2
    };
    (Vec3) => {
        ::glam::Vec3
    };
    (Vec4) => {
        ::glam::Vec4
    };
}
pub(crate) use element_rust_type;

/// Runs `$body` once per listed element type with the type alias `$T` naming
/// its Rust type: the one place where a run-time [`ElemType`] becomes a type
/// parameter of generic code over [`PrimitiveElement`]. The named lists match
/// [`crate::TypeConstraint`]s; any other type goes to the `$other` arm.
macro_rules! with_element_type {
    ($ty:expr, primitive, $T:ident => $body:expr, $other:pat => $otherwise:expr) => {
        $crate::cpu::kernels::with_element_type!(
            $ty, [Bool, U32, I32, F32, Vec2, Vec3, Vec4], $T => $body, $other => $otherwise
        )
    };
    ($ty:expr, numeric, $T:ident => $body:expr, $other:pat => $otherwise:expr) => {
        $crate::cpu::kernels::with_element_type!(
            $ty, [U32, I32, F32, Vec2, Vec3, Vec4], $T => $body, $other => $otherwise
        )
    };
    ($ty:expr, scalar, $T:ident => $body:expr, $other:pat => $otherwise:expr) => {
        $crate::cpu::kernels::with_element_type!(
            $ty, [U32, I32, F32], $T => $body, $other => $otherwise
        )
    };
    ($ty:expr, scalar_or_bool, $T:ident => $body:expr, $other:pat => $otherwise:expr) => {
        $crate::cpu::kernels::with_element_type!(
            $ty, [Bool, U32, I32, F32], $T => $body, $other => $otherwise
        )
    };
    ($ty:expr, [$($variant:ident),+], $T:ident => $body:expr, $other:pat => $otherwise:expr) => {
        match $ty {
            $($crate::types::ElemType::$variant => {
                type $T = $crate::cpu::kernels::element_rust_type!($variant);
                $body
            })+
            $other => $otherwise,
        }
    };
}
pub(crate) use with_element_type;

macro_rules! impl_primitive_element {
    ($($variant:ident),*) => {$(
        impl PrimitiveElement for element_rust_type!($variant) {
            const ELEM_TYPE: ElemType = ElemType::$variant;

            fn slice_of<'a>(view: &ColumnView<'a>) -> Option<&'a [Self]> {
                match view {
                    ColumnView::$variant(values) => Some(values),
                    _ => None,
                }
            }

            fn vec_of(column: &mut Column) -> Option<&mut Vec<Self>> {
                match column {
                    Column::$variant(values) => Some(values),
                    _ => None,
                }
            }

            fn into_column(values: Vec<Self>) -> Column {
                Column::$variant(values)
            }

            fn into_element(self) -> Element {
                Element::$variant(self)
            }

            fn from_element(element: Element) -> Option<Self> {
                match element {
                    Element::$variant(value) => Some(value),
                    _ => None,
                }
            }
        }
    )*};
}

impl_primitive_element!(Bool, U32, I32, F32, Vec2, Vec3, Vec4);

/// The typed slice of a view, or a type mismatch.
pub fn typed_slice<'a, T: PrimitiveElement>(view: &ColumnView<'a>) -> Result<&'a [T], KernelError> {
    T::slice_of(view).ok_or(KernelError::TypeMismatch {
        expected: T::ELEM_TYPE,
        found: view.elem_type(),
    })
}

fn typed_vec<T: PrimitiveElement>(column: &mut Column) -> Result<&mut Vec<T>, KernelError> {
    let found = column.elem_type();
    T::vec_of(column).ok_or(KernelError::TypeMismatch {
        expected: T::ELEM_TYPE,
        found,
    })
}

fn typed_element<T: PrimitiveElement>(element: Element) -> Result<T, KernelError> {
    T::from_element(element).ok_or(KernelError::TypeMismatch {
        expected: T::ELEM_TYPE,
        found: element.elem_type(),
    })
}

pub(crate) fn check_length(
    what: &'static str,
    expected: usize,
    found: usize,
) -> Result<(), KernelError> {
    if expected == found {
        Ok(())
    } else {
        Err(KernelError::LengthMismatch {
            what,
            expected,
            found,
        })
    }
}

pub(crate) fn check_same_type(expected: ElemType, found: ElemType) -> Result<(), KernelError> {
    if expected == found {
        Ok(())
    } else {
        Err(KernelError::TypeMismatch { expected, found })
    }
}

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
struct Monoid<T> {
    op: MonoidOp,
    identity: T,
}

impl<T: MonoidElement> Monoid<T> {
    fn new(op: MonoidOp) -> Result<Monoid<T>, KernelError> {
        let identity = T::identity(op).ok_or(KernelError::UnsupportedOperation {
            op,
            ty: T::ELEM_TYPE,
        })?;
        Ok(Monoid { op, identity })
    }

    fn combine(self, a: T, b: T) -> T {
        T::combine(self.op, a, b)
    }

    /// `start op values[0] op values[1] …`, left to right.
    fn fold(self, start: T, values: &[T]) -> T {
        values.iter().fold(start, |accumulated, &value| {
            self.combine(accumulated, value)
        })
    }
}

fn unsupported(op: MonoidOp, ty: ElemType) -> KernelError {
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
        let monoid = Monoid::<T>::new(op)?;
        let (a, b) = (typed_slice::<T>(a)?, typed_slice::<T>(b)?);
        Ok(T::into_column(a.iter().zip(b).map(|(&x, &y)| monoid.combine(x, y)).collect()))
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
        let monoid = Monoid::<T>::new(op)?;
        let groups = typed_slice::<T>(values)?.chunks_exact(group);
        Ok(T::into_column(groups.map(|group| monoid.fold(monoid.identity, group)).collect()))
    }, record => Err(unsupported(op, record)))
}

/// Checks the indices that will be used (those where `mask` is true, all
/// without a mask) before anything is read or written, so a bad index leaves
/// the output untouched.
fn check_indices(indices: &[u32], mask: Option<&[bool]>, len: usize) -> Result<(), KernelError> {
    let used = |position: usize| mask.is_none_or(|mask| mask[position]);
    match indices
        .iter()
        .enumerate()
        .find(|&(position, &index)| used(position) && index as usize >= len)
    {
        Some((position, &index)) => Err(KernelError::IndexOutOfRange {
            position,
            index,
            len,
        }),
        None => Ok(()),
    }
}

/// `out[i] = src[indices[i]]`, for every element type, records included.
pub fn gather(indices: &[u32], src: &ColumnView<'_>) -> Result<Column, KernelError> {
    check_indices(indices, None, src.len())?;
    Ok(gather_by_position(src, indices.len(), &|position| {
        indices[position] as usize
    }))
}

/// `out[i] = src[source_of(i)]` for `i < len`. The runtime's own index maps
/// (a fan-out's `i / k`) use it directly; `source_of` must stay below
/// `src.len()`, so user-supplied indices go through [`gather`].
pub(crate) fn gather_by_position(
    src: &ColumnView<'_>,
    len: usize,
    source_of: &impl Fn(usize) -> usize,
) -> Column {
    map_primitive!(ColumnView => Column, src,
    values => (0..len).map(|position| values[source_of(position)]).collect(),
    ColumnView::Record { ty, fields } => Column::Record {
        ty: *ty,
        fields: fields
            .iter()
            .map(|field| Arc::new(gather_by_position(field, len, source_of)))
            .collect(),
    })
}

/// The argument checks shared by both scatters.
pub(crate) fn check_scatter(
    indices: &[u32],
    src: &ColumnView<'_>,
    mask: Option<&[bool]>,
    dst_type: ElemType,
    dst_len: usize,
) -> Result<(), KernelError> {
    check_length("the scattered array", indices.len(), src.len())?;
    if let Some(mask) = mask {
        check_length("the scatter mask", indices.len(), mask.len())?;
    }
    check_same_type(dst_type, src.elem_type())?;
    check_indices(indices, mask, dst_len)
}

/// `dst[indices[i]] = write(dst[indices[i]], src[i])` for increasing `i` where
/// `mask[i]`; the indices are already checked.
fn scatter_typed<T: Copy>(
    indices: &[u32],
    src: &[T],
    mask: Option<&[bool]>,
    dst: &mut [T],
    write: impl Fn(T, T) -> T,
) {
    for (position, (&index, &value)) in indices.iter().zip(src).enumerate() {
        if mask.is_none_or(|mask| mask[position]) {
            let slot = &mut dst[index as usize];
            *slot = write(*slot, value);
        }
    }
}

/// `dst[indices[i]] = src[i]` where `mask[i]` (everywhere without a mask), for
/// every element type, records included. Indices where the mask is false are
/// not checked, so a compaction may compute out-of-range indices for the
/// elements it drops. With duplicate indices the last writer wins: the
/// largest `i` among those writing the same slot.
pub fn scatter(
    indices: &[u32],
    src: &ColumnView<'_>,
    mask: Option<&[bool]>,
    dst: &mut Column,
) -> Result<(), KernelError> {
    check_scatter(indices, src, mask, dst.elem_type(), dst.len())?;
    scatter_checked(indices, src, mask, dst)
}

fn scatter_checked(
    indices: &[u32],
    src: &ColumnView<'_>,
    mask: Option<&[bool]>,
    dst: &mut Column,
) -> Result<(), KernelError> {
    if let Column::Record { fields, .. } = dst {
        return fields
            .iter_mut()
            .enumerate()
            .try_for_each(|(index, field)| {
                scatter_checked(indices, src.field(index), mask, Arc::make_mut(field))
            });
    }
    with_element_type!(dst.elem_type(), primitive, T => {
        let src = typed_slice::<T>(src)?;
        scatter_typed(indices, src, mask, typed_vec::<T>(dst)?, |_, new| new);
        Ok(())
    }, record => Err(KernelError::TypeMismatch { expected: record, found: src.elem_type() }))
}

/// `dst[indices[i]] = dst[indices[i]] op src[i]` where `mask[i]` (everywhere
/// without a mask), applied in increasing `i`, so even float sums into the same
/// slot are deterministic. Index checks as in [`scatter`].
pub fn scatter_combine(
    op: MonoidOp,
    indices: &[u32],
    src: &ColumnView<'_>,
    mask: Option<&[bool]>,
    dst: &mut Column,
) -> Result<(), KernelError> {
    check_scatter(indices, src, mask, dst.elem_type(), dst.len())?;
    with_element_type!(dst.elem_type(), primitive, T => {
        let monoid = Monoid::<T>::new(op)?;
        let (src, dst) = (typed_slice::<T>(src)?, typed_vec::<T>(dst)?);
        scatter_typed(indices, src, mask, dst, |old, new| monoid.combine(old, new));
        Ok(())
    }, record => Err(unsupported(op, record)))
}

/// Runs `work` over `0..len` cut into consecutive ranges of `chunk` elements
/// (the last one shorter), in parallel, and returns the results in range
/// order. No range for `len == 0`.
pub fn run_chunked<T: Send>(
    len: usize,
    chunk: usize,
    work: impl Fn(Range<usize>) -> T + Sync,
) -> Vec<T> {
    assert!(chunk > 0, "run_chunked needs a positive chunk size");
    (0..len.div_ceil(chunk))
        .into_par_iter()
        // One chunk per task: rayon's adaptive splitting otherwise stops at a
        // few pieces per thread, and a thread done with its half finds nothing
        // to steal while another works through the other half (15 ms idle of
        // a 99 ms WORKLOAD2 frame, whose rows cost unevenly).
        .with_max_len(1)
        .map(|index| {
            let start = index * chunk;
            work(start..len.min(start + chunk))
        })
        .collect()
}

/// Pass 1 of a reduction: the identity combined with every element of `values`
/// (one chunk), left to right.
pub fn reduce_partial(op: MonoidOp, values: &ColumnView<'_>) -> Result<Element, KernelError> {
    with_element_type!(values.elem_type(), primitive, T => {
        let monoid = Monoid::<T>::new(op)?;
        Ok(monoid.fold(monoid.identity, typed_slice::<T>(values)?).into_element())
    }, record => Err(unsupported(op, record)))
}

/// Pass 2 of a reduction: the identity of `op` on `ty` combined with the chunks'
/// partials in chunk order (the identity alone for an empty array).
pub fn combine_partials(
    op: MonoidOp,
    ty: ElemType,
    partials: &[Element],
) -> Result<Element, KernelError> {
    partials
        .iter()
        .try_fold(identity(op, ty)?, |accumulated, &partial| {
            combine_elements(op, accumulated, partial)
        })
}

/// [`combine_partials`] as the host scalar `reduce` returns.
pub fn reduce_to_host(
    op: MonoidOp,
    ty: ElemType,
    partials: &[Element],
) -> Result<HostValue, KernelError> {
    Ok(combine_partials(op, ty, partials)?.to_host())
}

/// `reduce<op>(values)` over chunks of `chunk` elements, in parallel.
pub fn reduce(
    op: MonoidOp,
    values: &ColumnView<'_>,
    chunk: usize,
) -> Result<HostValue, KernelError> {
    let partials = run_chunked(values.len(), chunk, |range| {
        reduce_partial(op, &values.slice(range))
    })
    .into_iter()
    .collect::<Result<Vec<_>, _>>()?;
    reduce_to_host(op, values.elem_type(), &partials)
}

/// What a chunk contributes to the scan of the chunks after it: the standard
/// (flag, value) pair of a segmented scan. `value` combines the chunk's
/// elements from its last segment start on (all of them when no segment starts
/// in it); `starts_segment` says whether one did, which cuts off every carry
/// from earlier chunks. Unsegmented scans have `starts_segment == false`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScanTotal {
    pub starts_segment: bool,
    pub value: Element,
}

fn check_segment_flags(len: usize, segment_starts: Option<&[bool]>) -> Result<(), KernelError> {
    match segment_starts {
        Some(flags) => check_length("the segment flags", len, flags.len()),
        None => Ok(()),
    }
}

/// Pass 1 of a scan: the [`ScanTotal`] of one chunk. `segment_starts` holds
/// the chunk's own flags (`true` at `i` starts a segment at element `i`).
pub fn scan_total(
    op: MonoidOp,
    values: &ColumnView<'_>,
    segment_starts: Option<&[bool]>,
) -> Result<ScanTotal, KernelError> {
    check_segment_flags(values.len(), segment_starts)?;
    let last_start = segment_starts.and_then(|flags| flags.iter().rposition(|&flag| flag));
    let value = with_element_type!(values.elem_type(), primitive, T => {
        let monoid = Monoid::<T>::new(op)?;
        let values = typed_slice::<T>(values)?;
        // A segment restarts with its first element, as `scan_chunk` does, so a
        // carry holds exactly the bits the sequential scan would have.
        match last_start {
            Some(start) => monoid.fold(values[start], &values[start + 1..]),
            None => monoid.fold(monoid.identity, values),
        }
        .into_element()
    }, record => return Err(unsupported(op, record)));
    Ok(ScanTotal {
        starts_segment: last_start.is_some(),
        value,
    })
}

/// The segmented-scan pair operator: `later` after `earlier`. Associative, so
/// chunk totals may be combined in any grouping, but not commutative.
pub fn combine_scan_totals(
    op: MonoidOp,
    earlier: ScanTotal,
    later: ScanTotal,
) -> Result<ScanTotal, KernelError> {
    check_same_type(earlier.value.elem_type(), later.value.elem_type())?;
    if later.starts_segment {
        return Ok(later);
    }
    Ok(ScanTotal {
        starts_segment: earlier.starts_segment,
        value: combine_elements(op, earlier.value, later.value)?,
    })
}

/// Pass 2 of a scan: the exclusive scan of the chunk totals, i.e. the carry
/// into each chunk (the identity for the first), computed sequentially in
/// chunk order.
pub fn scan_carries(
    op: MonoidOp,
    ty: ElemType,
    totals: &[ScanTotal],
) -> Result<Vec<Element>, KernelError> {
    let mut running = ScanTotal {
        starts_segment: false,
        value: identity(op, ty)?,
    };
    totals
        .iter()
        .map(|&total| {
            let carry = running.value;
            running = combine_scan_totals(op, running, total)?;
            Ok(carry)
        })
        .collect()
}

/// Pass 3 of a scan: scans one chunk starting from `carry_in`.
///
/// Inclusive: `out[i] = carry_in op values[0] op … op values[i]`; exclusive:
/// the same without `values[i]`. With `segment_starts`, a `true` flag at `i`
/// restarts the scan: an inclusive scan restarts with `values[i]`, an
/// exclusive one with the identity at `i`; the carry only reaches the elements
/// before the chunk's first segment start.
pub fn scan_chunk(
    op: MonoidOp,
    values: &ColumnView<'_>,
    inclusive: bool,
    carry_in: Element,
    segment_starts: Option<&[bool]>,
) -> Result<Column, KernelError> {
    check_segment_flags(values.len(), segment_starts)?;
    with_element_type!(values.elem_type(), primitive, T => {
        let monoid = Monoid::<T>::new(op)?;
        let values = typed_slice::<T>(values)?;
        let mut running = typed_element::<T>(carry_in)?;
        let scanned = values.iter().enumerate().map(|(position, &value)| {
            let restarts = segment_starts.is_some_and(|flags| flags[position]);
            let before = if restarts { monoid.identity } else { running };
            running = if restarts { value } else { monoid.combine(running, value) };
            if inclusive { running } else { before }
        });
        Ok(T::into_column(scanned.collect()))
    }, record => Err(unsupported(op, record)))
}

/// `scan<op>(values)` (or `exclusiveScan` when `!inclusive`), optionally
/// segmented, in the three passes over chunks of `chunk` elements: totals in
/// parallel, carries sequentially, rescans in parallel.
pub fn scan(
    op: MonoidOp,
    values: &ColumnView<'_>,
    inclusive: bool,
    segment_starts: Option<&[bool]>,
    chunk: usize,
) -> Result<Column, KernelError> {
    check_segment_flags(values.len(), segment_starts)?;
    let chunk_flags = |range: &Range<usize>| segment_starts.map(|flags| &flags[range.clone()]);
    let totals = run_chunked(values.len(), chunk, |range| {
        scan_total(op, &values.slice(range.clone()), chunk_flags(&range))
    })
    .into_iter()
    .collect::<Result<Vec<_>, _>>()?;
    let carries = scan_carries(op, values.elem_type(), &totals)?;
    let chunks = run_chunked(values.len(), chunk, |range| {
        let carry_in = carries[range.start / chunk];
        scan_chunk(
            op,
            &values.slice(range.clone()),
            inclusive,
            carry_in,
            chunk_flags(&range),
        )
    })
    .into_iter()
    .collect::<Result<Vec<_>, _>>()?;
    // Scan results are never records, so concatenating them consults no record types.
    Ok(Column::concat(
        values.elem_type(),
        &chunks,
        &RecordRegistry::default(),
    ))
}
