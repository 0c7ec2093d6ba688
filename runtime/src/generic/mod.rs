//! The generic functors the language requires beside the ray-tracing ones
//! (spec §2): arithmetic monoids, comparisons, conversions, `select`, `hash`
//! and `random`, group reductions and fan-out, so that pipelines other than
//! ray tracing (a histogram, a stream compaction, a prefix sum) can be written.

mod elementwise;
mod grouped;

use crate::column::{Column, ColumnView};
use crate::cpu::kernels::combine_columns;
use crate::functor::{
    ArrayParam, CallContext, Functor, FunctorError, FunctorKind, FunctorLibrary, MonoidOp,
    Signature, TypeConstraint, TypePattern,
};
use crate::types::ElemType;
use std::sync::Arc;

/// Registers every generic functor. Panics if one of their names is taken.
pub fn register_generic_functors(library: &mut FunctorLibrary) {
    for functor in monoid_functors()
        .into_iter()
        .chain(elementwise::functors())
        .chain(grouped::functors())
    {
        library.register(functor);
    }
}

const ANY: TypePattern = TypePattern::Var(0, TypeConstraint::Any);
const NUMERIC: TypePattern = TypePattern::Var(0, TypeConstraint::Numeric);
const SCALAR: TypePattern = TypePattern::Var(0, TypeConstraint::Scalar);
const SCALAR_OR_BOOL: TypePattern = TypePattern::Var(0, TypeConstraint::ScalarOrBool);
const BOOL: TypePattern = TypePattern::Exact(ElemType::Bool);
const U32: TypePattern = TypePattern::Exact(ElemType::U32);
const F32: TypePattern = TypePattern::Exact(ElemType::F32);

/// The CPU implementation of a generic functor: a chunk's inputs to its one output.
type Kernel =
    Box<dyn Fn(&CallContext<'_>, &[ColumnView<'_>]) -> Result<Column, FunctorError> + Send + Sync>;

/// Every generic functor has one output, which its kernel builds whole.
struct GenericFunctor {
    signature: Signature,
    kernel: Kernel,
}

impl Functor for GenericFunctor {
    fn signature(&self) -> &Signature {
        &self.signature
    }

    fn run_cpu(
        &self,
        ctx: &CallContext<'_>,
        inputs: &[ColumnView<'_>],
        outputs: &mut [Column],
    ) -> Result<(), FunctorError> {
        outputs[0] = (self.kernel)(ctx, inputs)?;
        Ok(())
    }
}

/// A signature with array inputs, one output named `out` and no named parameters.
fn signature(
    kind: FunctorKind,
    name: &'static str,
    inputs: &[(&'static str, TypePattern)],
    output: TypePattern,
    doc: &'static str,
) -> Signature {
    Signature {
        name,
        kind,
        inputs: inputs
            .iter()
            .map(|&(name, ty)| ArrayParam { name, ty })
            .collect(),
        outputs: vec![ArrayParam {
            name: "out",
            ty: output,
        }],
        named: Vec::new(),
        doc,
    }
}

fn functor(
    signature: Signature,
    kernel: impl Fn(&CallContext<'_>, &[ColumnView<'_>]) -> Result<Column, FunctorError>
        + Send
        + Sync
        + 'static,
) -> Arc<dyn Functor> {
    Arc::new(GenericFunctor {
        signature,
        kernel: Box::new(kernel),
    })
}

/// The error for input types the signature excludes: the type checker let a
/// call through that it should have rejected.
fn unexpected_type(ty: ElemType) -> FunctorError {
    FunctorError(format!(
        "internal error: a generic functor received {ty:?} elements, which its signature excludes"
    ))
}

fn monoid_functors() -> Vec<Arc<dyn Functor>> {
    let monoids = [
        (
            MonoidOp::Add,
            "add",
            NUMERIC,
            "a + b, componentwise; u32 and i32 wrap around",
        ),
        (
            MonoidOp::Mul,
            "mul",
            NUMERIC,
            "a * b, componentwise; u32 and i32 wrap around",
        ),
        (
            MonoidOp::Min,
            "min",
            NUMERIC,
            "the smaller of a and b, componentwise",
        ),
        (
            MonoidOp::Max,
            "max",
            NUMERIC,
            "the larger of a and b, componentwise",
        ),
        (MonoidOp::Or, "or", BOOL, "a || b"),
        (MonoidOp::And, "and", BOOL, "a && b"),
    ];
    monoids
        .into_iter()
        .map(|(op, name, ty, doc)| {
            let kind = FunctorKind::Monoid(op);
            functor(
                signature(kind, name, &[("a", ty), ("b", ty)], ty, doc),
                move |_, inputs| Ok(combine_columns(op, &inputs[0], &inputs[1])?),
            )
        })
        .collect()
}
