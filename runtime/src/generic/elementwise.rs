//! The generic `map` functors: one element of each input to one output element.

use super::{
    functor, is_nan, unexpected_type, Body, ANY, BOOL, F32, NUMERIC, SCALAR, SCALAR_OR_BOOL, U32,
};
use crate::column::{Column, ColumnView};
use crate::elem::{check_length, typed_slice, with_element_type, PrimitiveElement};
use crate::functor::{CallContext, Functor, FunctorError};
use crate::host::HostValue;
use crate::signature::{Signature, TypePattern};
use crate::types::{ElemType, HostType};
use crate::wgsl::{WgslModule, WgslRequest};
use glam::{Vec2, Vec3, Vec4};
use std::borrow::Cow;
use std::sync::Arc;

pub(super) fn functors() -> Vec<Arc<dyn Functor>> {
    let mut functors = vec![
        functor(
            binary("sub", NUMERIC)
                .output("out", NUMERIC)
                .doc("a - b, componentwise; u32 and i32 wrap around"),
            |_, inputs| subtract(inputs),
            |request| numeric_twin(request, Body::returns("a - b")),
        ),
        functor(
            binary("div", NUMERIC).output("out", NUMERIC).doc(
                "a / b, componentwise; integers truncate toward zero, an integer division by zero is an error",
            ),
            divide,
            divide_twin,
        ),
        functor(
            unary("not", BOOL, BOOL).doc("!x"),
            |_, inputs| Ok(map_with(typed_slice::<bool>(&inputs[0])?, |x| !x)),
            |_| Ok(Body::returns("!x")),
        ),
        functor(
            Signature::map("select")
                .input("cond", BOOL)
                .input("a", ANY)
                .input("b", ANY)
                .output("out", ANY)
                .doc("a where cond, else b (any element type, records too)"),
            |_, inputs| select(typed_slice::<bool>(&inputs[0])?, &inputs[1], &inputs[2]),
            select_twin,
        ),
        functor(
            unary("identity", ANY, ANY).doc("x unchanged (a copy), for any element type"),
            |_, inputs| Ok(inputs[0].to_column()),
            |_| Ok(Body::returns("x")),
        ),
        functor(
            unary("isZero", SCALAR, BOOL).doc("x == 0 (true for -0.0, false for NaN)"),
            |_, inputs| compare_with_zero(inputs, true),
            |request| compare_with_zero_twin(request, true),
        ),
        functor(
            unary("nonZero", SCALAR, BOOL).doc("x != 0 (false for -0.0, true for NaN)"),
            |_, inputs| compare_with_zero(inputs, false),
            |request| compare_with_zero_twin(request, false),
        ),
        functor(
            seeded(unary("hash", U32, U32)).doc(
                "a stateless pseudo-random u32 per element: the PCG hash of x mixed with the hashed seed",
            ),
            |ctx, inputs| {
                let seed = seed(ctx)?;
                let values = typed_slice::<u32>(&inputs[0])?;
                Ok(map_with(values, |x| seeded_hash(x, seed)))
            },
            |_| Ok(Body::returns(seeded_hash_wgsl("x", "seed")).with_module(pcg_module())),
        ),
        functor(
            seeded(unary("random", U32, F32)).doc(
                "a stateless pseudo-random f32 in [0, 1) per element: the top 24 bits of hash(x)",
            ),
            |ctx, inputs| {
                let seed = seed(ctx)?;
                let values = typed_slice::<u32>(&inputs[0])?;
                Ok(map_with(values, |x| unit_float(seeded_hash(x, seed))))
            },
            |_| {
                let bits = seeded_hash_wgsl("x", "seed");
                Ok(Body::returns(unit_float_wgsl(&bits)).with_module(pcg_module()))
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
        functor(
            binary(name, ty).output("out", BOOL).doc(doc),
            move |_, inputs| compare(comparison, inputs),
            move |request| compare_twin(comparison, request),
        )
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
        functor(
            unary(name, SCALAR_OR_BOOL, target).doc(doc),
            move |_, inputs| convert(target, inputs),
            move |request| convert_twin(target, request),
        )
    }));
    functors
}

/// A `map` signature with inputs `a` and `b` of type `ty` (its output still to add).
pub(super) fn binary(name: &'static str, ty: TypePattern) -> Signature {
    Signature::map(name).input("a", ty).input("b", ty)
}

/// A `map` signature from `x: input` to `out: output`.
pub(super) fn unary(
    name: &'static str,
    input: TypePattern,
    output: impl Into<TypePattern>,
) -> Signature {
    Signature::map(name).input("x", input).output("out", output)
}

pub(super) fn map_with<T: Copy, U: PrimitiveElement>(values: &[T], f: impl Fn(T) -> U) -> Column {
    U::into_column(values.iter().map(|&x| f(x)).collect())
}

pub(super) fn zip_with<T: Copy, U: PrimitiveElement>(
    a: &[T],
    b: &[T],
    f: impl Fn(T, T) -> U,
) -> Column {
    U::into_column(a.iter().zip(b).map(|(&x, &y)| f(x, y)).collect())
}

/// The inputs `a` and `b` of a binary functor, of the same type and length.
pub(super) fn operands<'a, T: PrimitiveElement>(
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

/// `body` for the numeric types, `sub`'s and `div`'s signature; WGSL's
/// integer `+ - *` wrap like the CPU's.
fn numeric_twin(request: &WgslRequest<'_>, body: Body) -> Result<Body, FunctorError> {
    match request.inputs[0] {
        ty if ty.is_numeric() => Ok(body),
        other => Err(unexpected_type(other)),
    }
}

fn divide(ctx: &CallContext<'_>, inputs: &[ColumnView<'_>]) -> Result<Column, FunctorError> {
    with_element_type!(inputs[0].elem_type(), numeric, T => {
        let (a, b) = operands::<T>(inputs)?;
        dividing(ctx, a, b, T::divide)
    }, other => Err(unexpected_type(other)))
}

/// `divide(a, b)` element by element, where `None` is a division by zero
/// (an error naming the element): `div`'s and `rem`'s kernels.
pub(super) fn dividing<T: PrimitiveElement>(
    ctx: &CallContext<'_>,
    a: &[T],
    b: &[T],
    divide: impl Fn(T, T) -> Option<T>,
) -> Result<Column, FunctorError> {
    let results = a.iter().zip(b).enumerate().map(|(position, (&x, &y))| {
        divide(x, y).ok_or_else(|| {
            FunctorError::bad_input(format!(
                "{DIVISION_BY_ZERO} at element {}",
                ctx.first_index + position
            ))
        })
    });
    Ok(T::into_column(results.collect::<Result<_, _>>()?))
}

/// WGSL's `i32::MIN / -1` is `i32::MIN`, as `wrapping_div`; a division by
/// zero fails. The CPU's message also names the element, which a failure code
/// cannot carry. Float division in WGSL is only accurate to 2.5 ULP.
fn divide_twin(request: &WgslRequest<'_>) -> Result<Body, FunctorError> {
    let quotient = Body::returns("a / b");
    match request.inputs[0] {
        ElemType::U32 => Ok(quotient.failing_when(request, "b == 0u", DIVISION_BY_ZERO)),
        ElemType::I32 => Ok(quotient.failing_when(request, "b == 0i", DIVISION_BY_ZERO)),
        _ => numeric_twin(request, quotient),
    }
}

pub(super) const DIVISION_BY_ZERO: &str = "integer division by zero";

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

/// Floats are compared only where neither is NaN (tested on the bits, see
/// [`is_nan`]), so that NaN compares unequal and unordered as on the CPU.
fn compare_twin(comparison: Comparison, request: &WgslRequest<'_>) -> Result<Body, FunctorError> {
    let ty = request.inputs[0];
    let operator = match comparison {
        Comparison::Equal | Comparison::NotEqual => "==",
        Comparison::Less => "<",
        Comparison::LessOrEqual => "<=",
        Comparison::Greater => ">",
        Comparison::GreaterOrEqual => ">=",
    };
    let ordered = !matches!(comparison, Comparison::Equal | Comparison::NotEqual);
    let holds = match ty {
        ElemType::Bool if ordered => return Err(unexpected_type(ty)),
        ElemType::Bool | ElemType::U32 | ElemType::I32 => format!("a {operator} b"),
        ElemType::F32 => {
            let nan = |value| is_nan(value, ty).unwrap_or_default();
            format!("!({} || {}) && a {operator} b", nan("a"), nan("b"))
        }
        other => return Err(unexpected_type(other)),
    };
    Ok(Body::returns(match comparison {
        Comparison::NotEqual => format!("!({holds})"),
        _ => holds,
    }))
}

fn compare_with_zero(inputs: &[ColumnView<'_>], equal: bool) -> Result<Column, FunctorError> {
    with_element_type!(inputs[0].elem_type(), scalar, T => {
        let values = typed_slice::<T>(&inputs[0])?;
        // `Default` is zero for every primitive type.
        Ok(map_with(values, |x| (x == T::default()) == equal))
    }, other => Err(unexpected_type(other)))
}

/// A float is zero when its bits but the sign are, so `-0.0` is zero and NaN is not.
fn compare_with_zero_twin(request: &WgslRequest<'_>, equal: bool) -> Result<Body, FunctorError> {
    let operator = if equal { "==" } else { "!=" };
    Ok(Body::returns(match request.inputs[0] {
        ElemType::U32 => format!("x {operator} 0u"),
        ElemType::I32 => format!("x {operator} 0i"),
        ElemType::F32 => format!("(bitcast<u32>(x) & 0x7fffffffu) {operator} 0u"),
        other => return Err(unexpected_type(other)),
    }))
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

/// [`ScalarConversions`] in WGSL, where WGSL's own conversions differ: its
/// float-to-integer conversions stop at the largest float below the bound
/// (4294967040 for u32) and leave NaN indeterminate, and its integer-to-float
/// conversion may round either way. These are exact, on bits and integers.
const CONVERSIONS_WGSL: &str = "\
// Rust's `as f32`: round to nearest, ties to even.
fn generic_u32_to_f32(x: u32) -> f32 {
    if (x < 0x1000000u) {
        return f32(x); // exact below 2^24
    }
    let top = firstLeadingBit(x);
    let shift = top - 23u;
    let kept = x >> shift;
    let dropped = x & ((1u << shift) - 1u);
    let half = 1u << (shift - 1u);
    let up = dropped > half || (dropped == half && (kept & 1u) == 1u);
    // Rounding 0xffffff up carries into the exponent, as it should.
    return bitcast<f32>(((top + 127u) << 23u) + (kept - 0x800000u) + select(0u, 1u, up));
}

fn generic_i32_to_f32(x: i32) -> f32 {
    let bits = bitcast<u32>(x);
    // The magnitude of i32::MIN, 2^31, fits in u32.
    let magnitude = select(bits, 0u - bits, x < 0i);
    return bitcast<f32>(bitcast<u32>(generic_u32_to_f32(magnitude)) | (bits & 0x80000000u));
}

// Rust's `as u32`: NaN and negatives to 0, 2^32 and above to u32::MAX.
fn generic_f32_to_u32(x: f32) -> u32 {
    let bits = bitcast<u32>(x);
    if (bits > 0x7f800000u) {
        return 0u; // NaN, or the sign bit set
    }
    if (bits >= 0x4f800000u) {
        return 0xffffffffu; // 2^32 and above
    }
    return u32(x);
}

// Rust's `as i32`: NaN to 0, beyond the range to i32::MIN or i32::MAX.
fn generic_f32_to_i32(x: f32) -> i32 {
    let bits = bitcast<u32>(x);
    let magnitude = bits & 0x7fffffffu;
    if (magnitude > 0x7f800000u) {
        return 0i; // NaN
    }
    if (magnitude >= 0x4f000000u) {
        // |x| >= 2^31
        return select(2147483647i, i32(-2147483648), bits != magnitude);
    }
    return i32(x);
}
";

/// The module with [`CONVERSIONS_WGSL`], for every twin that converts.
pub(super) fn conversions_module() -> WgslModule {
    WgslModule {
        name: "generic_conversions",
        source: Cow::Borrowed(CONVERSIONS_WGSL),
        buffers: Vec::new(),
    }
}

/// `value` (of type `from`) converted to `to` as [`ScalarConversions`] does,
/// as a WGSL expression that may call [`conversions_module`].
pub(super) fn conversion_wgsl(from: ElemType, to: ElemType, value: &str) -> Option<String> {
    use ElemType::{Bool, F32, I32, U32};
    Some(match (from, to) {
        (from, to) if from == to => value.to_string(),
        // WGSL converts `true` to 1 and `false` to 0, as Rust does.
        (Bool, U32) => format!("u32({value})"),
        (Bool, I32) => format!("i32({value})"),
        (Bool, F32) => format!("f32({value})"),
        (U32, I32) => format!("i32(min({value}, 0x7fffffffu))"),
        (I32, U32) => format!("u32(max({value}, 0i))"),
        (U32, F32) => format!("generic_u32_to_f32({value})"),
        (I32, F32) => format!("generic_i32_to_f32({value})"),
        (F32, U32) => format!("generic_f32_to_u32({value})"),
        (F32, I32) => format!("generic_f32_to_i32({value})"),
        _ => return None,
    })
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

fn convert_twin(target: ElemType, request: &WgslRequest<'_>) -> Result<Body, FunctorError> {
    let from = request.inputs[0];
    let converted = conversion_wgsl(from, target, "x").ok_or_else(|| unexpected_type(from))?;
    Ok(Body::returns(converted).with_module(conversions_module()))
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

/// An `if`, since WGSL's `select` takes no structs.
fn select_twin(request: &WgslRequest<'_>) -> Result<Body, FunctorError> {
    match *request.inputs {
        [ElemType::Bool, a, b] if a == b => {
            Ok(Body::statements("if (cond) {\n    return a;\n}\nreturn b;"))
        }
        [_, _, b] => Err(unexpected_type(b)),
        _ => Err(unexpected_type(request.inputs[0])),
    }
}

/// `signature` with the `seed` argument of `hash` and `random`.
fn seeded(signature: Signature) -> Signature {
    signature.named(
        "seed",
        HostType::Int,
        Some(HostValue::Int(0)),
        "chooses an independent hash; taken modulo 2^32",
    )
}

fn seed(ctx: &CallContext<'_>) -> Result<u32, FunctorError> {
    match ctx.named.first() {
        // Modulo 2^32, so negative seeds are usable too.
        Some(HostValue::Int(seed)) => Ok(*seed as u32),
        other => Err(FunctorError::bad_input(format!(
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

/// [`pcg_hash`] in WGSL, for the twins of `hash` and `random`.
const PCG_WGSL: &str = "\
fn generic_pcg_hash(input: u32) -> u32 {
    let state = input * 747796405u + 2891336453u;
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}
";

fn pcg_module() -> WgslModule {
    WgslModule {
        name: "generic_pcg",
        source: Cow::Borrowed(PCG_WGSL),
        buffers: Vec::new(),
    }
}

/// [`seeded_hash`] in WGSL; the seed, an `i32` there, is taken modulo 2^32 by `bitcast`.
fn seeded_hash_wgsl(value: &str, seed: &str) -> String {
    format!("generic_pcg_hash({value} ^ generic_pcg_hash(bitcast<u32>({seed})))")
}

/// The top 24 bits of `bits` as a float in `[0, 1)`: exactly representable,
/// so the largest result stays below 1.
fn unit_float(bits: u32) -> f32 {
    (bits >> 8) as f32 / (1 << 24) as f32
}

/// [`unit_float`] in WGSL: a multiplication by 2^-24, exact like the CPU's
/// division, where a WGSL division would be accurate only to 2.5 ULP.
fn unit_float_wgsl(bits: &str) -> String {
    format!("f32(({bits}) >> 8u) * 5.9604644775390625e-8")
}
