//! The generic functors the language requires beside the ray-tracing ones
//! (docs/language.md §9): arithmetic monoids, comparisons, conversions, `select`, `hash`
//! and `random`, group reductions and fan-out, so that pipelines other than
//! ray tracing (a histogram, a stream compaction, a prefix sum) can be written;
//! and the maths of element-wise expressions (`math.rs`).

mod elementwise;
mod grouped;
mod math;

use crate::column::{Column, ColumnView};
use crate::functor::{CallContext, ClosureFunctor, Functor, FunctorError, FunctorLibrary};
use crate::monoid::combine_columns;
use crate::monoid::MonoidOp;
use crate::signature::{Signature, TypeConstraint, TypePattern};
use crate::types::ElemType;
use crate::wgsl::{elem_type_wgsl, twin_parameters, WgslModule, WgslRequest, WgslTwin};
use std::fmt::Display;
use std::sync::Arc;

/// Registers every generic functor. Panics if one of their names is taken.
pub fn register_generic_functors(library: &mut FunctorLibrary) {
    for functor in monoid_functors()
        .into_iter()
        .chain(elementwise::functors())
        .chain(grouped::functors())
        .chain(math::functors())
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

/// `fn {function}({parameters}) -> Out { body }`, the header from the
/// signature (so it always matches the calling convention), the body from
/// `generate`, which writes it for the request's element types.
fn generated_twin(
    signature: &Signature,
    request: &WgslRequest<'_>,
    generate: &impl Fn(&WgslRequest<'_>) -> Result<Body, FunctorError>,
) -> Result<WgslTwin, FunctorError> {
    let (inputs, outputs) = (&signature.inputs, &signature.outputs);
    if request.inputs.len() != inputs.len() || request.outputs.len() != outputs.len() {
        return Err(FunctorError::bad_input(format!(
            "internal error: a WGSL twin of `{}` was asked for {} inputs and {} outputs",
            signature.name,
            request.inputs.len(),
            request.outputs.len()
        )));
    }
    let body = generate(request)?;
    let parameters: Vec<String> = twin_parameters(signature, request.inputs, request.records)
        .into_iter()
        .map(|(name, ty)| format!("{name}: {ty}"))
        .collect();
    let source = format!(
        "fn {}({}) -> {} {{\n{}}}\n",
        request.function,
        parameters.join(", "),
        output_type(request),
        body.statements
    );
    Ok(WgslTwin {
        source,
        modules: body.modules,
        buffers: Vec::new(),
        failures: body.failures,
    })
}

/// What a generator writes: the statements of a twin's function and what they need.
#[derive(Default)]
struct Body {
    statements: String,
    modules: Vec<WgslModule>,
    /// The messages of `{function}_fail(code)`, by code.
    failures: Vec<String>,
}

impl Body {
    fn returns(value: impl Display) -> Body {
        Body::statements(format!("return {value};"))
    }

    /// `lines` (one statement a line) indented as the function's body.
    fn statements(lines: impl AsRef<str>) -> Body {
        let mut statements = String::new();
        for line in lines.as_ref().lines() {
            statements.push_str("    ");
            statements.push_str(line);
            statements.push('\n');
        }
        Body {
            statements,
            ..Body::default()
        }
    }

    fn with_module(mut self, module: WgslModule) -> Body {
        self.modules.push(module);
        self
    }

    /// Fails with `message` where `condition` holds, before anything else: the
    /// backend records the failure and the value returned (zero) is never used.
    fn failing_when(
        mut self,
        request: &WgslRequest<'_>,
        condition: &str,
        message: impl Into<String>,
    ) -> Body {
        let code = self.failures.len();
        self.failures.push(message.into());
        self.statements = format!(
            "    if ({condition}) {{\n        {}_fail({code}u);\n        return {}();\n    }}\n{}",
            request.function,
            output_type(request),
            self.statements
        );
        self
    }
}

/// The WGSL spelling of an element type in `request`'s record registry.
fn wgsl_type(request: &WgslRequest<'_>, ty: ElemType) -> String {
    elem_type_wgsl(ty, request.records)
}

fn output_type(request: &WgslRequest<'_>) -> String {
    wgsl_type(request, request.outputs[0])
}

/// The unsigned integer type of the same shape as a float type: its bits.
fn float_bits_type(ty: ElemType) -> Option<&'static str> {
    match ty {
        ElemType::F32 => Some("u32"),
        ElemType::Vec2 => Some("vec2<u32>"),
        ElemType::Vec3 => Some("vec3<u32>"),
        ElemType::Vec4 => Some("vec4<u32>"),
        _ => None,
    }
}

/// Whether `value` (a float type, componentwise for vectors) is NaN, tested
/// on its bits: WGSL implementations may assume that no float is NaN, so a
/// float comparison could be optimised out.
fn is_nan(value: &str, ty: ElemType) -> Option<String> {
    let bits = float_bits_type(ty)?;
    Some(format!(
        "((bitcast<{bits}>({value}) & {}) > {})",
        bits_constant(ty, "0x7fffffffu")?,
        bits_constant(ty, "0x7f800000u")?
    ))
}

/// The u32 literal `word` in the bits type of the float type `ty`: splat
/// for vectors, as it is for a scalar.
fn bits_constant(ty: ElemType, word: &str) -> Option<String> {
    Some(match (ty, float_bits_type(ty)?) {
        (ElemType::F32, _) => word.to_string(),
        (_, bits) => format!("{bits}({word})"),
    })
}

/// `min(a, b)` (`better` is `<`) or `max(a, b)` (`>`) of the float type
/// `ty` as a WGSL expression that agrees with Rust's `f32::min`/`max` per
/// component: NaN loses, `a` on a tie. `a` and `b` are names (each is read
/// several times).
fn nan_ignoring_wgsl(better: &str, a: &str, b: &str, ty: ElemType) -> Option<String> {
    let (a_nan, b_nan) = (is_nan(a, ty)?, is_nan(b, ty)?);
    Some(format!(
        "select(select(select({a}, {b}, {b} {better} {a}), {a}, {b_nan}), {b}, {a_nan})"
    ))
}

/// A generic functor: its one output built whole by `kernel`, its twin's body
/// generated per instantiation by `twin`.
fn functor(
    signature: Signature,
    kernel: impl Fn(&CallContext<'_>, &[ColumnView<'_>]) -> Result<Column, FunctorError>
        + Send
        + Sync
        + 'static,
    twin: impl Fn(&WgslRequest<'_>) -> Result<Body, FunctorError> + Send + Sync + 'static,
) -> Arc<dyn Functor> {
    let functor = ClosureFunctor::new(signature, move |ctx, inputs, outputs| {
        outputs[0] = kernel(ctx, inputs)?;
        Ok(())
    })
    .with_twin(move |signature, request| generated_twin(signature, request, &twin));
    Arc::new(functor)
}

/// The error for input types the signature excludes: the type checker let a
/// call through that it should have rejected.
fn unexpected_type(ty: ElemType) -> FunctorError {
    FunctorError::bad_input(format!(
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
            functor(
                Signature::monoid(op, name)
                    .input("a", ty)
                    .input("b", ty)
                    .output("out", ty)
                    .doc(doc),
                move |_, inputs| Ok(combine_columns(op, &inputs[0], &inputs[1])?),
                move |request| monoid_twin(op, request),
            )
        })
        .collect()
}

/// `a op b` as the CPU's [`MonoidElement`](crate::monoid::MonoidElement)
/// computes it: integers wrap (as WGSL's do); float `min`/`max`, per
/// component for vectors, return the other operand where one is NaN and `a`
/// on a tie (Rust's `f32::min`; the sign of a zero result is unspecified on
/// both sides). Ignoring NaN keeps them associative, so a reduction in any
/// order agrees.
fn monoid_twin(op: MonoidOp, request: &WgslRequest<'_>) -> Result<Body, FunctorError> {
    monoid_statements(op, request.inputs[0])
        .map(Body::statements)
        .ok_or_else(|| unexpected_type(request.inputs[0]))
}

/// The statements of `fn (a: T, b: T) -> T { … }` computing `a op b`: the
/// monoid twins' and the GPU backend's reductions, scans and combining
/// scatters, one definition for both.
pub fn monoid_statements(op: MonoidOp, ty: ElemType) -> Option<String> {
    let (name, better) = match op {
        MonoidOp::Min => ("min", "<"),
        MonoidOp::Max => ("max", ">"),
        MonoidOp::Add if ty.is_numeric() => return Some("return a + b;".into()),
        MonoidOp::Mul if ty.is_numeric() => return Some("return a * b;".into()),
        MonoidOp::Or if ty == ElemType::Bool => return Some("return a || b;".into()),
        MonoidOp::And if ty == ElemType::Bool => return Some("return a && b;".into()),
        _ => return None,
    };
    match ty {
        ElemType::U32 | ElemType::I32 => Some(format!("return {name}(a, b);")),
        _ => Some(format!(
            "return {};",
            nan_ignoring_wgsl(better, "a", "b", ty)?
        )),
    }
}
