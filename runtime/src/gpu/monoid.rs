//! The monoids of reductions, scans and combining scatters in WGSL: identities
//! and combining functions per element type, and the atomic update a
//! combining scatter performs per word (a compare-and-swap loop, which needs
//! no forward progress between workgroups).

use crate::cpu::kernels::{monoid_name, monoid_supports};
use crate::functor::MonoidOp;
use crate::types::ElemType;
use std::fmt::Write;

fn type_name(ty: ElemType) -> &'static str {
    match ty {
        ElemType::Bool => "bool",
        ElemType::U32 => "u32",
        ElemType::I32 => "i32",
        ElemType::F32 => "f32",
        ElemType::Vec2 => "vec2<f32>",
        ElemType::Vec3 => "vec3<f32>",
        ElemType::Vec4 => "vec4<f32>",
        ElemType::Record(_) => unreachable!("monoids are defined on primitives"),
    }
}

fn short(ty: ElemType) -> &'static str {
    match ty {
        ElemType::Bool => "bool",
        ElemType::U32 => "u32",
        ElemType::I32 => "i32",
        ElemType::F32 => "f32",
        ElemType::Vec2 => "vec2",
        ElemType::Vec3 => "vec3",
        ElemType::Vec4 => "vec4",
        ElemType::Record(_) => unreachable!("monoids are defined on primitives"),
    }
}

/// The scalar a component of `ty` is.
pub fn component(ty: ElemType) -> ElemType {
    match ty {
        ElemType::Vec2 | ElemType::Vec3 | ElemType::Vec4 => ElemType::F32,
        scalar => scalar,
    }
}

/// The identity of `op` on `ty` as a WGSL expression (the CPU's identities).
pub fn identity(op: MonoidOp, ty: ElemType) -> Result<String, String> {
    if !monoid_supports(op, ty) {
        return Err(format!(
            "`{}` is not defined on {ty:?} elements",
            monoid_name(op)
        ));
    }
    let scalar = match (op, component(ty)) {
        (MonoidOp::Or, _) => "false",
        (MonoidOp::And, _) => "true",
        (MonoidOp::Add, ElemType::U32) => "0u",
        (MonoidOp::Add, ElemType::I32) => "0i",
        (MonoidOp::Add, _) => "0.0",
        (MonoidOp::Mul, ElemType::U32) => "1u",
        (MonoidOp::Mul, ElemType::I32) => "1i",
        (MonoidOp::Mul, _) => "1.0",
        (MonoidOp::Min, ElemType::U32) => "4294967295u",
        (MonoidOp::Min, ElemType::I32) => "2147483647i",
        (MonoidOp::Min, _) => "bitcast<f32>(0x7f800000u)",
        (MonoidOp::Max, ElemType::U32) => "0u",
        (MonoidOp::Max, ElemType::I32) => "bitcast<i32>(0x80000000u)",
        (MonoidOp::Max, _) => "bitcast<f32>(0xff800000u)",
    };
    Ok(match ty {
        ElemType::Vec2 | ElemType::Vec3 | ElemType::Vec4 => format!("{}({scalar})", type_name(ty)),
        _ => scalar.to_string(),
    })
}

/// Defines (once in `out`) and names `fn monoid_{op}_{ty}(a, b)`, with the
/// same statements as the monoid functors' twins.
pub fn combine_function(op: MonoidOp, ty: ElemType, out: &mut String) -> Result<String, String> {
    identity(op, ty)?;
    let name = format!("monoid_{}_{}", monoid_name(op), short(ty));
    if !out.contains(&format!("fn {name}(")) {
        let statements = crate::generic::monoid_statements(op, ty)
            .ok_or_else(|| format!("`{}` is not defined on {ty:?} elements", monoid_name(op)))?;
        let t = type_name(ty);
        let _ = writeln!(out, "fn {name}(a: {t}, b: {t}) -> {t} {{ {statements} }}");
    }
    Ok(name)
}

/// Defines `fn {field}_update(i, j, value)` that combines `value` (a scalar
/// component) into word `j` of element `i` of atomic field `field`.
pub fn atomic_update(
    op: MonoidOp,
    ty: ElemType,
    field: &str,
    out: &mut String,
) -> Result<String, String> {
    let scalar = component(ty);
    let combine = combine_function(op, scalar, out)?;
    let name = format!("{field}_update");
    let (to_value, to_word) = match scalar {
        ElemType::Bool => ("(old != 0u)", "select(0u, 1u, new_value)"),
        ElemType::U32 => ("old", "new_value"),
        ElemType::I32 => ("bitcast<i32>(old)", "bitcast<u32>(new_value)"),
        _ => ("bitcast<f32>(old)", "bitcast<u32>(new_value)"),
    };
    let _ = writeln!(
        out,
        "fn {name}(i: u32, j: u32, value: {t}) {{\n\
         \x20   var old = {field}_atomic_load(i, j);\n\
         \x20   loop {{\n\
         \x20       let new_value = {combine}({to_value}, value);\n\
         \x20       let seen = {field}_cas(i, j, old, {to_word});\n\
         \x20       if (seen.y != 0u) {{ break; }}\n\
         \x20       old = seen.x;\n\
         \x20   }}\n\
         }}",
        t = type_name(scalar)
    );
    Ok(name)
}
