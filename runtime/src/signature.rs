//! Signatures: what the plan compiler and the backends know of a functor's
//! shape (kind, array inputs and outputs, named arguments), apart from the
//! `Functor` trait that runs it, so that the WGSL contract (`wgsl.rs`) can
//! read signatures without depending on functors.

use crate::host::HostValue;
use crate::monoid::MonoidOp;
use crate::types::{ElemType, HostType, RecordRegistry};

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

/// A concrete element type is the pattern that admits only it.
impl From<ElemType> for TypePattern {
    fn from(ty: ElemType) -> TypePattern {
        TypePattern::Exact(ty)
    }
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
    /// `i32`, `f32`, `vec2`, `vec3`, `vec4`: the numeric types with a negation.
    Signed,
    /// `f32`, `vec2`, `vec3`, `vec4`.
    Float,
    /// `vec2`, `vec3`, `vec4`.
    Vector,
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
            TypeConstraint::Signed => ty.is_numeric() && ty != ElemType::U32,
            TypeConstraint::Float => ty.is_numeric() && !ty.is_integer(),
            TypeConstraint::Vector => {
                matches!(ty, ElemType::Vec2 | ElemType::Vec3 | ElemType::Vec4)
            }
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
            TypeConstraint::Signed => "i32|f32|vec2|vec3|vec4",
            TypeConstraint::Float => "f32|vec2|vec3|vec4",
            TypeConstraint::Vector => "vec2|vec3|vec4",
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

/// Building a signature one parameter at a time.
///
/// Every functor spells out its signature, and as a struct literal each took
/// some 25 lines of `ArrayParam { name, ty }` and `NamedParam { … }` around
/// a few names and types; the builder says the same in one line a parameter:
///
/// ```
/// # use dpp_runtime::{ElemType, HostType, HostValue, Signature};
/// let signature = Signature::map("scale")
///     .input("x", ElemType::F32)
///     .output("y", ElemType::F32)
///     .named("factor", HostType::Float, Some(HostValue::Float(2.0)), "what x is multiplied by")
///     .doc("x times factor");
/// assert_eq!(signature.inputs[0].name, "x");
/// ```
impl Signature {
    /// A signature of `kind` named `name` with no parameters and no doc line yet.
    pub fn of_kind(kind: FunctorKind, name: &'static str) -> Signature {
        Signature {
            name,
            kind,
            inputs: Vec::new(),
            outputs: Vec::new(),
            named: Vec::new(),
            doc: "",
        }
    }

    /// A [`FunctorKind::Map`] signature: `map<name>`.
    pub fn map(name: &'static str) -> Signature {
        Signature::of_kind(FunctorKind::Map, name)
    }

    /// A [`FunctorKind::Group`] signature: `gather<name>(src, group: k)`.
    pub fn group(name: &'static str) -> Signature {
        Signature::of_kind(FunctorKind::Group, name)
    }

    /// A [`FunctorKind::Expand`] signature: `scatter<name>(src, fanout: k)`.
    pub fn expand(name: &'static str) -> Signature {
        Signature::of_kind(FunctorKind::Expand, name)
    }

    /// A [`FunctorKind::Monoid`] signature for `op`.
    pub fn monoid(op: MonoidOp, name: &'static str) -> Signature {
        Signature::of_kind(FunctorKind::Monoid(op), name)
    }

    /// Appends an array input (an [`ElemType`] is an exact pattern).
    pub fn input(mut self, name: &'static str, ty: impl Into<TypePattern>) -> Signature {
        self.inputs.push(ArrayParam {
            name,
            ty: ty.into(),
        });
        self
    }

    /// Appends an array output (an [`ElemType`] is an exact pattern).
    pub fn output(mut self, name: &'static str, ty: impl Into<TypePattern>) -> Signature {
        self.outputs.push(ArrayParam {
            name,
            ty: ty.into(),
        });
        self
    }

    /// Appends a named argument; `default: None` makes it required.
    pub fn named(
        self,
        name: &'static str,
        ty: HostType,
        default: Option<HostValue>,
        doc: &'static str,
    ) -> Signature {
        self.named_param(NamedParam {
            name,
            ty,
            default,
            doc,
        })
    }

    /// Appends a named argument that several functors share, spelt once as a
    /// constant beside the code that reads it.
    pub fn named_param(mut self, param: NamedParam) -> Signature {
        self.named.push(param);
        self
    }

    /// Sets the one line `dpp functors` shows.
    pub fn doc(mut self, doc: &'static str) -> Signature {
        self.doc = doc;
        self
    }

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
