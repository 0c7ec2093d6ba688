//! Array elements of the primitive types as Rust values: one [`Element`], the
//! [`PrimitiveElement`] trait that ties each [`ElemType`] to its Rust type, and
//! [`with_element_type!`], the one place where a run-time element type becomes
//! a type parameter. Backend-neutral: the CPU backend's kernels, the generic
//! functors and the GPU backend's read-back all use it.

use crate::column::{Column, ColumnView};
use crate::error::ErrorKind;
use crate::host::HostValue;
use crate::types::{ElemType, MonoidOp};
use glam::{Vec2, Vec3, Vec4};
use std::fmt;

/// What goes wrong inside an element-wise kernel: bad user data (an index out
/// of range) or a plan-compiler bug (mismatched types or lengths).
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
    #[error("`{}` is not defined on {ty:?} elements", .op.name())]
    UnsupportedOperation { op: MonoidOp, ty: ElemType },
    #[error("a group needs at least one element")]
    EmptyGroup,
}

impl KernelError {
    /// Bad user data (an index out of range, a group that does not fit) is
    /// the user's; a type mismatch or an operation that type checking
    /// admitted is a bug of ours.
    pub fn kind(&self) -> ErrorKind {
        match self {
            KernelError::IndexOutOfRange { .. }
            | KernelError::LengthMismatch { .. }
            | KernelError::EmptyGroup => ErrorKind::BadInput,
            KernelError::TypeMismatch { .. } | KernelError::UnsupportedOperation { .. } => {
                ErrorKind::Internal
            }
        }
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
        $crate::elem::with_element_type!(
            $ty, [Bool, U32, I32, F32, Vec2, Vec3, Vec4], $T => $body, $other => $otherwise
        )
    };
    ($ty:expr, numeric, $T:ident => $body:expr, $other:pat => $otherwise:expr) => {
        $crate::elem::with_element_type!(
            $ty, [U32, I32, F32, Vec2, Vec3, Vec4], $T => $body, $other => $otherwise
        )
    };
    ($ty:expr, scalar, $T:ident => $body:expr, $other:pat => $otherwise:expr) => {
        $crate::elem::with_element_type!(
            $ty, [U32, I32, F32], $T => $body, $other => $otherwise
        )
    };
    ($ty:expr, float, $T:ident => $body:expr, $other:pat => $otherwise:expr) => {
        $crate::elem::with_element_type!(
            $ty, [F32, Vec2, Vec3, Vec4], $T => $body, $other => $otherwise
        )
    };
    ($ty:expr, vector, $T:ident => $body:expr, $other:pat => $otherwise:expr) => {
        $crate::elem::with_element_type!(
            $ty, [Vec2, Vec3, Vec4], $T => $body, $other => $otherwise
        )
    };
    ($ty:expr, scalar_or_bool, $T:ident => $body:expr, $other:pat => $otherwise:expr) => {
        $crate::elem::with_element_type!(
            $ty, [Bool, U32, I32, F32], $T => $body, $other => $otherwise
        )
    };
    ($ty:expr, [$($variant:ident),+], $T:ident => $body:expr, $other:pat => $otherwise:expr) => {
        match $ty {
            $($crate::types::ElemType::$variant => {
                type $T = $crate::elem::element_rust_type!($variant);
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

pub(crate) fn typed_vec<T: PrimitiveElement>(
    column: &mut Column,
) -> Result<&mut Vec<T>, KernelError> {
    let found = column.elem_type();
    T::vec_of(column).ok_or(KernelError::TypeMismatch {
        expected: T::ELEM_TYPE,
        found,
    })
}

pub(crate) fn typed_element<T: PrimitiveElement>(element: Element) -> Result<T, KernelError> {
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
