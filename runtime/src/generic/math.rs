//! The maths of element-wise expressions (`a + b * c`, `sqrt(x)`, `v.x`,
//! `vec3(x, y, z)`), which the compiler desugars into `map`s of these: float
//! functions per component, vector geometry, vector construction and
//! components, `neg` and `rem`. Each computes what WGSL defines, written out
//! in the twin where a builtin would leave a choice to the implementation
//! (NaN in `min`/`max`, `mix`'s formula), so that the backends differ only
//! where WGSL's precision does (docs/language.md §7).

use super::elementwise::{binary, dividing, map_with, operands, unary, zip_with, DIVISION_BY_ZERO};
use super::{
    bits_constant, float_bits_type, functor, nan_ignoring_wgsl, output_type, unexpected_type,
    wgsl_type, Body, F32, SCALAR,
};
use crate::column::{Column, ColumnView};
use crate::elem::{check_length, typed_slice, with_element_type, PrimitiveElement};
use crate::functor::{CallContext, Functor, FunctorError};
use crate::host::HostValue;
use crate::signature::{Signature, TypeConstraint, TypePattern};
use crate::types::{ElemType, HostType};
use crate::wgsl::WgslRequest;
use glam::{Vec2, Vec3, Vec4};
use std::sync::Arc;

const SIGNED: TypePattern = TypePattern::Var(0, TypeConstraint::Signed);
const FLOAT: TypePattern = TypePattern::Var(0, TypeConstraint::Float);
const VECTOR: TypePattern = TypePattern::Var(0, TypeConstraint::Vector);
const VEC3: TypePattern = TypePattern::Exact(ElemType::Vec3);

pub(super) fn functors() -> Vec<Arc<dyn Functor>> {
    let mut functors = vec![
        functor(
            unary("neg", SIGNED, SIGNED)
                .doc("-x: i32 wraps (-i32::MIN is i32::MIN), floats flip the sign bit (NaN and 0 too)"),
            negate,
            negate_twin,
        ),
        functor(
            unary("abs", FLOAT, FLOAT).doc("|x| per component: the sign bit cleared"),
            |_, inputs| per_component(inputs, f32::abs),
            |request| {
                let clear = sign_bit_wgsl(request, "&", "0x7fffffffu")?;
                Ok(Body::returns(clear))
            },
        ),
        functor(
            binary("pow", FLOAT).output("out", FLOAT).doc(
                "a to the power b per component; the GPU's is exp2(b * log2(a)), for a > 0 only",
            ),
            |_, inputs| per_component2(inputs, f32::powf),
            |request| float_twin(request, Body::returns("pow(a, b)")),
        ),
        functor(
            Signature::map("clamp")
                .input("x", FLOAT)
                .input("lo", FLOAT)
                .input("hi", FLOAT)
                .output("out", FLOAT)
                .doc("min(max(x, lo), hi) per component, min and max ignoring NaN"),
            |_, inputs| per_component3(inputs, |x, lo, hi| x.max(lo).min(hi)),
            |request| {
                let ty = float_type(request)?;
                let low = min_max(">", "x", "lo", ty)?;
                let clamped = min_max("<", "low", "hi", ty)?;
                Ok(Body::statements(format!(
                    "let low = {low};\nreturn {clamped};"
                )))
            },
        ),
        functor(
            Signature::map("mix")
                .input("a", FLOAT)
                .input("b", FLOAT)
                .input("t", FLOAT)
                .output("out", FLOAT)
                .doc("a * (1 - t) + b * t per component (WGSL's formula)"),
            |_, inputs| per_component3(inputs, |a, b, t| a * (1.0 - t) + b * t),
            |request| float_twin(request, Body::returns("a * (1.0 - t) + b * t")),
        ),
        functor(
            Signature::map("step")
                .input("edge", FLOAT)
                .input("x", FLOAT)
                .output("out", FLOAT)
                .doc("1 where edge <= x, else 0 (also where either is NaN), per component"),
            |_, inputs| per_component2(inputs, |edge, x| if edge <= x { 1.0 } else { 0.0 }),
            step_twin,
        ),
        functor(
            Signature::map("smoothstep")
                .input("lo", FLOAT)
                .input("hi", FLOAT)
                .input("x", FLOAT)
                .output("out", FLOAT)
                .doc("t * t * (3 - 2t) with t = clamp((x - lo) / (hi - lo), 0, 1), per component"),
            |_, inputs| per_component3(inputs, smoothstep),
            smoothstep_twin,
        ),
        functor(
            binary("dot", VECTOR)
                .output("out", F32)
                .doc("the sum of the products of the components, in order"),
            |_, inputs| {
                with_element_type!(inputs[0].elem_type(), vector, T => {
                    let (a, b) = operands::<T>(inputs)?;
                    Ok(zip_with(a, b, Vector::dot))
                }, other => Err(unexpected_type(other)))
            },
            |request| vector_twin(request, Body::returns(sum_of_products(request, "a", "b")?)),
        ),
        functor(
            binary("cross", VEC3)
                .output("out", VEC3)
                .doc("the cross product (a.y b.z - b.y a.z, a.z b.x - b.z a.x, a.x b.y - b.x a.y)"),
            |_, inputs| {
                let (a, b) = operands::<Vec3>(inputs)?;
                Ok(zip_with(a, b, Vec3::cross))
            },
            |_| {
                Ok(Body::returns(
                    "vec3<f32>(a.y * b.z - b.y * a.z, a.z * b.x - b.z * a.x, a.x * b.y - b.x * a.y)",
                ))
            },
        ),
        functor(
            Signature::map("length")
                .input("v", VECTOR)
                .output("out", F32)
                .doc("sqrt(dot(v, v))"),
            |_, inputs| {
                with_element_type!(inputs[0].elem_type(), vector, T => {
                    Ok(map_with(typed_slice::<T>(&inputs[0])?, Vector::length))
                }, other => Err(unexpected_type(other)))
            },
            |request| {
                let squared = sum_of_products(request, "v", "v")?;
                vector_twin(request, Body::returns(format!("sqrt({squared})")))
            },
        ),
        functor(
            binary("distance", VECTOR)
                .output("out", F32)
                .doc("length(a - b)"),
            |_, inputs| {
                with_element_type!(inputs[0].elem_type(), vector, T => {
                    let (a, b) = operands::<T>(inputs)?;
                    Ok(zip_with(a, b, |a, b| Vector::length(a - b)))
                }, other => Err(unexpected_type(other)))
            },
            |request| {
                let squared = sum_of_products(request, "d", "d")?;
                let body = Body::statements(format!("let d = a - b;\nreturn sqrt({squared});"));
                vector_twin(request, body)
            },
        ),
        functor(
            Signature::map("normalize")
                .input("v", VECTOR)
                .output("out", VECTOR)
                .doc("v / length(v); the zero vector where length(v) is 0 (also where dot(v, v) underflows)"),
            |_, inputs| {
                with_element_type!(inputs[0].elem_type(), vector, T => {
                    Ok(map_with(typed_slice::<T>(&inputs[0])?, normalize))
                }, other => Err(unexpected_type(other)))
            },
            |request| {
                let squared = sum_of_products(request, "v", "v")?;
                let zero = format!("{}()", output_type(request));
                let body = Body::statements(format!(
                    "let l = sqrt({squared});\nif (l == 0.0) {{\n    return {zero};\n}}\nreturn v / l;"
                ));
                vector_twin(request, body)
            },
        ),
        functor(
            Signature::map("reflect")
                .input("i", VECTOR)
                .input("n", VECTOR)
                .output("out", VECTOR)
                .doc("i - 2 dot(n, i) n, the reflection of i off the plane of unit normal n"),
            |_, inputs| {
                with_element_type!(inputs[0].elem_type(), vector, T => {
                    let (i, n) = operands::<T>(inputs)?;
                    Ok(zip_with(i, n, |i, n| i - (2.0 * Vector::dot(n, i)) * n))
                }, other => Err(unexpected_type(other)))
            },
            |request| {
                let dot = sum_of_products(request, "n", "i")?;
                vector_twin(request, Body::returns(format!("i - 2.0 * ({dot}) * n")))
            },
        ),
        functor(
            Signature::map("component")
                .input("v", VECTOR)
                .output("out", F32)
                .named("index", HostType::Int, None, "which component: 0 is x, 1 y, 2 z, 3 w")
                .doc("component `index` of v; an index beyond v's components is an error"),
            component,
            component_twin,
        ),
        functor(
            binary("rem", SCALAR).output("out", SCALAR).doc(
                "a - b * trunc(a / b): the remainder of a division truncated toward zero; an integer remainder by zero is an error",
            ),
            remainder,
            remainder_twin,
        ),
    ];
    let functions = [
        (
            "floor",
            f32::floor as fn(f32) -> f32,
            "floor(x)",
            "the largest integer <= x, per component",
        ),
        (
            "ceil",
            f32::ceil,
            "ceil(x)",
            "the smallest integer >= x, per component",
        ),
        (
            "fract",
            fract,
            "x - floor(x)",
            "x - floor(x), per component",
        ),
        (
            "sqrt",
            f32::sqrt,
            "sqrt(x)",
            "the square root, per component",
        ),
        (
            "rsqrt",
            rsqrt,
            "inverseSqrt(x)",
            "1 / sqrt(x), per component (WGSL's inverseSqrt)",
        ),
        ("exp", f32::exp, "exp(x)", "e to the power x, per component"),
        (
            "log",
            f32::ln,
            "log(x)",
            "the natural logarithm, per component",
        ),
        (
            "sin",
            f32::sin,
            "sin(x)",
            "the sine of x radians, per component",
        ),
        (
            "cos",
            f32::cos,
            "cos(x)",
            "the cosine of x radians, per component",
        ),
    ];
    functors.extend(functions.into_iter().map(|(name, f, wgsl, doc)| {
        functor(
            unary(name, FLOAT, FLOAT).doc(doc),
            move |_, inputs| per_component(inputs, f),
            move |request| float_twin(request, Body::returns(wgsl)),
        )
    }));
    let vectors = [
        (
            ElemType::Vec2,
            "vec2",
            "splat2",
            2,
            "a vec2 from its components",
            "a vec2 with x in every component",
        ),
        (
            ElemType::Vec3,
            "vec3",
            "splat3",
            3,
            "a vec3 from its components",
            "a vec3 with x in every component",
        ),
        (
            ElemType::Vec4,
            "vec4",
            "splat4",
            4,
            "a vec4 from its components",
            "a vec4 with x in every component",
        ),
    ];
    for (ty, name, splat, size, doc, splat_doc) in vectors {
        let components = &["x", "y", "z", "w"][..size];
        let signature = components
            .iter()
            .fold(Signature::map(name), |s, c| s.input(c, F32))
            .output("out", ty)
            .doc(doc);
        let arguments = components.join(", ");
        functors.push(functor(
            signature,
            move |_, inputs| build_vectors(ty, inputs),
            move |request| {
                Ok(Body::returns(format!(
                    "{}({arguments})",
                    output_type(request)
                )))
            },
        ));
        functors.push(functor(
            unary(splat, F32, ty).doc(splat_doc),
            move |_, inputs| {
                let x = typed_slice::<f32>(&inputs[0])?;
                with_element_type!(ty, vector, T => {
                    Ok(map_with(x, |x| T::from_fn(|_| x)))
                }, other => Err(unexpected_type(other)))
            },
            |request| Ok(Body::returns(format!("{}(x)", output_type(request)))),
        ));
    }
    functors
}

/// `f32` and the vectors as their components, so that a function of floats
/// is written once for all four.
trait Components: PrimitiveElement {
    fn component(self, i: usize) -> f32;
    fn from_fn(f: impl FnMut(usize) -> f32) -> Self;
}

impl Components for f32 {
    fn component(self, _: usize) -> f32 {
        self
    }

    fn from_fn(mut f: impl FnMut(usize) -> f32) -> f32 {
        f(0)
    }
}

/// The vectors' geometry, with the products of `dot` added left to right as
/// the twins spell them out: glam's `Vec4::dot` adds them pairwise (SIMD),
/// which rounds and overflows otherwise.
trait Vector: Components + std::ops::Sub<Output = Self> {
    const SIZE: usize;

    fn dot(self, other: Self) -> f32 {
        (1..Self::SIZE).fold(self.component(0) * other.component(0), |sum, i| {
            sum + self.component(i) * other.component(i)
        })
    }

    fn length(self) -> f32 {
        self.dot(self).sqrt()
    }
}

macro_rules! impl_vector {
    ($($t:ty: $size:expr),*) => {$(
        impl Components for $t {
            fn component(self, i: usize) -> f32 {
                self.to_array()[i]
            }

            fn from_fn(f: impl FnMut(usize) -> f32) -> $t {
                <$t>::from_array(std::array::from_fn(f))
            }
        }

        impl Vector for $t {
            const SIZE: usize = $size;
        }
    )*};
}

impl_vector!(Vec2: 2, Vec3: 3, Vec4: 4);

/// `f` of each component of the one input.
fn per_component(inputs: &[ColumnView<'_>], f: fn(f32) -> f32) -> Result<Column, FunctorError> {
    with_element_type!(inputs[0].elem_type(), float, T => {
        let x = typed_slice::<T>(&inputs[0])?;
        Ok(map_with(x, |x| T::from_fn(|i| f(x.component(i)))))
    }, other => Err(unexpected_type(other)))
}

/// `f` of each pair of components of the two inputs.
fn per_component2(
    inputs: &[ColumnView<'_>],
    f: impl Fn(f32, f32) -> f32,
) -> Result<Column, FunctorError> {
    with_element_type!(inputs[0].elem_type(), float, T => {
        let (a, b) = operands::<T>(inputs)?;
        Ok(zip_with(a, b, |a, b| T::from_fn(|i| f(a.component(i), b.component(i)))))
    }, other => Err(unexpected_type(other)))
}

/// `f` of each triple of components of the three inputs.
fn per_component3(
    inputs: &[ColumnView<'_>],
    f: impl Fn(f32, f32, f32) -> f32,
) -> Result<Column, FunctorError> {
    with_element_type!(inputs[0].elem_type(), float, T => {
        let (a, b) = operands::<T>(inputs)?;
        let c = typed_slice::<T>(&inputs[2])?;
        check_length("the third operand", a.len(), c.len())?;
        let values = a.iter().zip(b).zip(c).map(|((&a, &b), &c)| {
            T::from_fn(|i| f(a.component(i), b.component(i), c.component(i)))
        });
        Ok(T::into_column(values.collect()))
    }, other => Err(unexpected_type(other)))
}

/// The number of components of a vector type.
fn vector_size(ty: ElemType) -> Result<usize, FunctorError> {
    match ty {
        ElemType::Vec2 => Ok(2),
        ElemType::Vec3 => Ok(3),
        ElemType::Vec4 => Ok(4),
        other => Err(unexpected_type(other)),
    }
}

/// WGSL's `fract`: `x - floor(x)` (Rust's `f32::fract` truncates instead).
fn fract(x: f32) -> f32 {
    x - x.floor()
}

fn rsqrt(x: f32) -> f32 {
    1.0 / x.sqrt()
}

/// WGSL's formula, with a clamp that, like the twin's, ignores NaN: a NaN
/// `t` (`lo == hi`, or a NaN input) is clamped to 0.
// `f32::clamp` would keep a NaN `t`.
#[allow(clippy::manual_clamp)]
fn smoothstep(lo: f32, hi: f32, x: f32) -> f32 {
    let t = ((x - lo) / (hi - lo)).max(0.0).min(1.0);
    t * t * (3.0 - 2.0 * t)
}

fn normalize<T: Vector + std::ops::Div<f32, Output = T>>(v: T) -> T {
    let length = v.length();
    if length == 0.0 {
        T::default()
    } else {
        v / length
    }
}

/// Only the float types reach a float functor's twin.
fn float_type(request: &WgslRequest<'_>) -> Result<ElemType, FunctorError> {
    match request.inputs[0] {
        ty if float_bits_type(ty).is_some() => Ok(ty),
        other => Err(unexpected_type(other)),
    }
}

fn float_twin(request: &WgslRequest<'_>, body: Body) -> Result<Body, FunctorError> {
    float_type(request).map(|_| body)
}

fn vector_twin(request: &WgslRequest<'_>, body: Body) -> Result<Body, FunctorError> {
    match request.inputs[0] {
        ElemType::Vec2 | ElemType::Vec3 | ElemType::Vec4 => Ok(body),
        other => Err(unexpected_type(other)),
    }
}

/// [`nan_ignoring_wgsl`] for a float type (`>` is max, `<` min).
fn min_max(better: &str, a: &str, b: &str, ty: ElemType) -> Result<String, FunctorError> {
    nan_ignoring_wgsl(better, a, b, ty).ok_or_else(|| unexpected_type(ty))
}

/// `x` (a float type) with its sign bit combined by `operator` with `word`,
/// on the bits, so that NaN and zeros keep their payloads.
fn sign_bit_wgsl(
    request: &WgslRequest<'_>,
    operator: &str,
    word: &str,
) -> Result<String, FunctorError> {
    let ty = float_type(request)?;
    let (bits, mask) = match (float_bits_type(ty), bits_constant(ty, word)) {
        (Some(bits), Some(mask)) => (bits, mask),
        _ => return Err(unexpected_type(ty)),
    };
    Ok(format!(
        "bitcast<{}>(bitcast<{bits}>(x) {operator} {mask})",
        wgsl_type(request, ty)
    ))
}

/// `a.x * b.x + a.y * b.y + …`, left to right as glam's `dot`: WGSL's `dot`
/// leaves the order to the implementation.
fn sum_of_products(request: &WgslRequest<'_>, a: &str, b: &str) -> Result<String, FunctorError> {
    let n = vector_size(request.inputs[0])?;
    let products: Vec<String> = ["x", "y", "z", "w"][..n]
        .iter()
        .map(|c| format!("{a}.{c} * {b}.{c}"))
        .collect();
    Ok(products.join(" + "))
}

fn negate(_: &CallContext<'_>, inputs: &[ColumnView<'_>]) -> Result<Column, FunctorError> {
    match inputs[0].elem_type() {
        ElemType::I32 => Ok(map_with(typed_slice::<i32>(&inputs[0])?, i32::wrapping_neg)),
        ty => with_element_type!(ty, float, T => {
            let x = typed_slice::<T>(&inputs[0])?;
            Ok(map_with(x, |x| T::from_fn(|i| -x.component(i))))
        }, other => Err(unexpected_type(other))),
    }
}

/// WGSL's integer `-` wraps; a float's sign bit is flipped on the bits, as
/// Rust's `-` does (a float negation could canonicalise NaN).
fn negate_twin(request: &WgslRequest<'_>) -> Result<Body, FunctorError> {
    match request.inputs[0] {
        ElemType::I32 => Ok(Body::returns("-x")),
        _ => Ok(Body::returns(sign_bit_wgsl(request, "^", "0x80000000u")?)),
    }
}

/// `select` of zeros and ones on a comparison that NaN makes false, tested
/// on the bits (see [`super::is_nan`]).
fn step_twin(request: &WgslRequest<'_>) -> Result<Body, FunctorError> {
    let ty = float_type(request)?;
    let nan = |value| super::is_nan(value, ty).ok_or_else(|| unexpected_type(ty));
    let t = wgsl_type(request, ty);
    Ok(Body::returns(format!(
        "select({t}(0.0), {t}(1.0), (edge <= x) & !({} | {}))",
        nan("edge")?,
        nan("x")?
    )))
}

fn smoothstep_twin(request: &WgslRequest<'_>) -> Result<Body, FunctorError> {
    let ty = float_type(request)?;
    let t = wgsl_type(request, ty);
    let low = min_max(">", "q", "zero", ty)?;
    let clamped = min_max("<", "low", "one", ty)?;
    Ok(Body::statements(format!(
        "let zero = {t}(0.0);\nlet one = {t}(1.0);\nlet q = (x - lo) / (hi - lo);\n\
         let low = {low};\nlet s = {clamped};\nreturn s * s * (3.0 - 2.0 * s);"
    )))
}

/// The index argument of `component`, checked against the vector's size.
fn component_index(ctx: &CallContext<'_>, ty: ElemType) -> Result<usize, FunctorError> {
    let n = vector_size(ty)?;
    match ctx.named(0) {
        HostValue::Int(i) if (0..n as i64).contains(&i) => Ok(i as usize),
        HostValue::Int(i) => Err(FunctorError::bad_input(format!(
            "component index {i} is out of range for {}, whose components are 0 to {}",
            ty.name(ctx.records),
            n - 1
        ))),
        other => Err(FunctorError::bad_input(format!(
            "internal error: the component index should be an integer, got {other:?}"
        ))),
    }
}

fn component(ctx: &CallContext<'_>, inputs: &[ColumnView<'_>]) -> Result<Column, FunctorError> {
    let ty = inputs[0].elem_type();
    let i = component_index(ctx, ty)?;
    with_element_type!(ty, vector, T => {
        Ok(map_with(typed_slice::<T>(&inputs[0])?, |v| v.component(i)))
    }, other => Err(unexpected_type(other)))
}

/// The index is checked before the vector is read: WGSL would clamp an
/// index out of range, where the CPU fails.
fn component_twin(request: &WgslRequest<'_>) -> Result<Body, FunctorError> {
    let ty = request.inputs[0];
    let n = vector_size(ty)?;
    let message = format!(
        "component index is out of range for {}, whose components are 0 to {}",
        ty.name(request.records),
        n - 1
    );
    Ok(Body::returns("v[arg_index]").failing_when(
        request,
        &format!("arg_index < 0i || arg_index >= {n}i"),
        message,
    ))
}

fn build_vectors(ty: ElemType, inputs: &[ColumnView<'_>]) -> Result<Column, FunctorError> {
    let columns: Vec<&[f32]> = inputs
        .iter()
        .map(typed_slice::<f32>)
        .collect::<Result<_, _>>()?;
    let n = columns[0].len();
    for column in &columns[1..] {
        check_length("a component", n, column.len())?;
    }
    with_element_type!(ty, vector, T => {
        Ok(T::into_column((0..n).map(|e| T::from_fn(|i| columns[i][e])).collect()))
    }, other => Err(unexpected_type(other)))
}

/// `rem` per scalar type: `None` for an integer remainder by zero.
trait Remainder: Copy {
    fn remainder(self, other: Self) -> Option<Self>;
}

// `i32::MIN % -1` is 0 (WGSL's too), which `wrapping_rem` gives without overflowing.
impl Remainder for u32 {
    fn remainder(self, other: u32) -> Option<u32> {
        (other != 0).then(|| self.wrapping_rem(other))
    }
}

impl Remainder for i32 {
    fn remainder(self, other: i32) -> Option<i32> {
        (other != 0).then(|| self.wrapping_rem(other))
    }
}

/// WGSL's definition, not Rust's `%` (an exact `fmod`): they differ where
/// `a / b` rounds.
impl Remainder for f32 {
    fn remainder(self, other: f32) -> Option<f32> {
        Some(self - other * (self / other).trunc())
    }
}

fn remainder(ctx: &CallContext<'_>, inputs: &[ColumnView<'_>]) -> Result<Column, FunctorError> {
    with_element_type!(inputs[0].elem_type(), scalar, T => {
        let (a, b) = operands::<T>(inputs)?;
        dividing(ctx, a, b, T::remainder)
    }, other => Err(unexpected_type(other)))
}

/// WGSL's integer `%` is 0 for `i32::MIN % -1`, as `wrapping_rem`; the
/// float one is spelled out, as the CPU computes it.
fn remainder_twin(request: &WgslRequest<'_>) -> Result<Body, FunctorError> {
    let remainder = Body::returns("a % b");
    match request.inputs[0] {
        ElemType::U32 => Ok(remainder.failing_when(request, "b == 0u", DIVISION_BY_ZERO)),
        ElemType::I32 => Ok(remainder.failing_when(request, "b == 0i", DIVISION_BY_ZERO)),
        ElemType::F32 => Ok(Body::returns("a - b * trunc(a / b)")),
        other => Err(unexpected_type(other)),
    }
}
