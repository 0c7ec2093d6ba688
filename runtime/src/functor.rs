//! Functors: named, typed per-element kernels, and the library that holds them.
//!
//! The runtime knows functors only through [`Functor`]: a [`Signature`] for the
//! plan compiler and a chunk-wise CPU implementation for the CPU backend.

use crate::column::{Column, ColumnView};
use crate::error::ErrorKind;
use crate::host::{HostValue, UniformSchema, Uniforms};
use crate::monoid::MonoidOp;
use crate::types::{ElemType, HostType, RecordRegistry};
use crate::wgsl::{WgslRequest, WgslTwin};
use std::any::Any;
use std::collections::BTreeMap;
use std::fmt;
use std::sync::Arc;

/// What shape of element function a functor is, which decides the primitives it may appear in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FunctorKind {
    /// One element of each input to one element of each output: `map<f>`.
    Map,
    /// `k` consecutive elements of one input to one output element: `gather<f>(src, group: k)`.
    Group,
    /// One input element and a lane `j < k` to one output element: `scatter<f>(src, fanout: k)`.
    /// The CPU implementation receives the source elements and writes `k` outputs for each.
    Expand,
    /// An associative, commutative binary operation with an identity: usable in
    /// `map`, `reduce`, `scan` and combining `scatter`.
    Monoid(MonoidOp),
}

/// A type in a signature: concrete, or a variable bound at each call.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TypePattern {
    Exact(ElemType),
    /// Type variable number `n` (`T0`, `T1`, …), limited by a constraint.
    Var(u8, TypeConstraint),
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TypeConstraint {
    /// Any element type, records included.
    Any,
    /// `u32`, `i32`, `f32`, `vec2`, `vec3`, `vec4`.
    Numeric,
    /// `u32`, `i32`, `f32`.
    Scalar,
    /// `u32`, `i32`.
    Integer,
    /// `bool`, `u32`, `i32`, `f32`.
    ScalarOrBool,
    /// Every primitive element type (no records).
    Primitive,
}

impl TypeConstraint {
    pub fn admits(self, ty: ElemType) -> bool {
        match self {
            TypeConstraint::Any => true,
            TypeConstraint::Numeric => ty.is_numeric(),
            TypeConstraint::Scalar => matches!(ty, ElemType::U32 | ElemType::I32 | ElemType::F32),
            TypeConstraint::Integer => ty.is_integer(),
            TypeConstraint::ScalarOrBool => matches!(
                ty,
                ElemType::Bool | ElemType::U32 | ElemType::I32 | ElemType::F32
            ),
            TypeConstraint::Primitive => !matches!(ty, ElemType::Record(_)),
        }
    }

    pub fn describe(self) -> &'static str {
        match self {
            TypeConstraint::Any => "any",
            TypeConstraint::Numeric => "numeric",
            TypeConstraint::Scalar => "u32|i32|f32",
            TypeConstraint::Integer => "u32|i32",
            TypeConstraint::ScalarOrBool => "bool|u32|i32|f32",
            TypeConstraint::Primitive => "primitive",
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct ArrayParam {
    pub name: &'static str,
    pub ty: TypePattern,
}

/// A uniform argument a functor accepts as `name: value` (a host scalar).
#[derive(Clone, Debug, PartialEq)]
pub struct NamedParam {
    pub name: &'static str,
    pub ty: HostType,
    /// `None` makes the argument required.
    pub default: Option<HostValue>,
    pub doc: &'static str,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Signature {
    pub name: &'static str,
    pub kind: FunctorKind,
    /// Array inputs, in order. An `Expand` functor's lane index is not listed.
    pub inputs: Vec<ArrayParam>,
    pub outputs: Vec<ArrayParam>,
    pub named: Vec<NamedParam>,
    /// One line for `dpp functors`.
    pub doc: &'static str,
}

impl Signature {
    /// `name(a: T0, b: T0) -> T0 [k: float = 1.0]` with record names resolved.
    pub fn display(&self, records: &RecordRegistry) -> String {
        let pattern = |p: &TypePattern| match p {
            TypePattern::Exact(t) => t.name(records),
            TypePattern::Var(n, c) => match c {
                TypeConstraint::Any => format!("T{n}"),
                c => format!("T{n}:{}", c.describe()),
            },
        };
        let inputs: Vec<String> = self
            .inputs
            .iter()
            .map(|p| format!("{}: {}", p.name, pattern(&p.ty)))
            .collect();
        let outputs: Vec<String> = self
            .outputs
            .iter()
            .map(|p| format!("{}: {}", p.name, pattern(&p.ty)))
            .collect();
        let kind = match self.kind {
            FunctorKind::Map => "map".to_string(),
            FunctorKind::Group => "group".to_string(),
            FunctorKind::Expand => "expand".to_string(),
            FunctorKind::Monoid(op) => format!("monoid {op:?}").to_lowercase(),
        };
        let mut text = format!(
            "{:<12} {}({}) -> ({})",
            kind,
            self.name,
            inputs.join(", "),
            outputs.join(", ")
        );
        for n in &self.named {
            match &n.default {
                Some(d) => text.push_str(&format!(" [{}: {} = {}]", n.name, n.ty, d)),
                None => text.push_str(&format!(" [{}: {}]", n.name, n.ty)),
            }
        }
        text
    }
}

/// Everything a functor's CPU implementation may read besides its array inputs.
pub struct CallContext<'a> {
    /// The values of the functor's named parameters, defaults filled in, in signature order.
    pub named: &'a [HostValue],
    pub uniforms: &'a Uniforms,
    /// Scene data (BVH, triangles, materials) the functor library put there; see
    /// [`FunctorLibrary::resources`].
    pub resources: &'a (dyn Any + Send + Sync),
    /// Index, in the functor's input index space, of the first element of this chunk.
    pub first_index: usize,
    /// `k` for `Group` and `Expand` functors; 1 otherwise.
    pub group: usize,
    pub records: &'a RecordRegistry,
}

impl CallContext<'_> {
    /// The named parameter at `index` of the signature (already type-checked).
    pub fn named(&self, index: usize) -> HostValue {
        self.named[index]
    }

    pub fn resources<T: Any>(&self) -> Result<&T, FunctorError> {
        self.resources.downcast_ref::<T>().ok_or_else(|| {
            FunctorError::bad_input(format!(
                "this functor needs {} but the run has none (no scene loaded?)",
                std::any::type_name::<T>()
            ))
        })
    }
}

/// A run-time failure inside a functor (a missing scene, an index out of range),
/// with the kind that decides the exit status.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FunctorError {
    pub kind: ErrorKind,
    pub message: String,
}

impl FunctorError {
    pub fn new(kind: ErrorKind, message: impl Into<String>) -> FunctorError {
        FunctorError {
            kind,
            message: message.into(),
        }
    }

    /// The input the functor was given is wrong: the common case.
    pub fn bad_input(message: impl Into<String>) -> FunctorError {
        FunctorError::new(ErrorKind::BadInput, message)
    }

    pub fn internal(message: impl Into<String>) -> FunctorError {
        FunctorError::new(ErrorKind::Internal, message)
    }
}

impl fmt::Display for FunctorError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for FunctorError {}

pub trait Functor: Send + Sync {
    fn signature(&self) -> &Signature;

    /// Runs the functor over one chunk. `inputs` follow the signature (types already
    /// checked and type variables bound); `outputs` are empty columns of the output
    /// types that the implementation must fill to the chunk's output length:
    /// `n` for `Map` and `Monoid`, `n / k` for `Group`, `n * k` for `Expand`
    /// (output `i*k + j` from input `i`, lane `j`).
    fn run_cpu(
        &self,
        ctx: &CallContext<'_>,
        inputs: &[ColumnView<'_>],
        outputs: &mut [Column],
    ) -> Result<(), FunctorError>;

    /// The functor's WGSL twin for the GPU backend (conventions in [`crate::wgsl`]).
    fn wgsl(&self, request: &WgslRequest<'_>) -> Result<WgslTwin, FunctorError> {
        let _ = request;
        Err(crate::wgsl::no_twin(self.signature().name))
    }
}

/// Every functor, record type and uniform a pipeline may name.
#[derive(Clone, Default)]
pub struct FunctorLibrary {
    functors: BTreeMap<&'static str, Arc<dyn Functor>>,
    pub records: RecordRegistry,
    pub uniforms: UniformSchema,
}

impl FunctorLibrary {
    pub fn register(&mut self, functor: Arc<dyn Functor>) {
        let name = functor.signature().name;
        let previous = self.functors.insert(name, functor);
        assert!(previous.is_none(), "functor `{name}` registered twice");
    }

    pub fn get(&self, name: &str) -> Option<&Arc<dyn Functor>> {
        self.functors.get(name)
    }

    pub fn names(&self) -> impl Iterator<Item = &'static str> + '_ {
        self.functors.keys().copied()
    }

    pub fn iter(&self) -> impl Iterator<Item = &Arc<dyn Functor>> {
        self.functors.values()
    }
}
