//! The monoids of reductions, scans and combining scatters in WGSL: the
//! runtime's identities (`dpp_runtime::monoid`) and combining functions (the
//! monoid functors' twins) spelled for a shader, and the atomic update a
//! combining scatter performs per word (a compare-and-swap loop, which needs
//! no forward progress between workgroups).

use dpp_runtime::monoid::MonoidOp;
use dpp_runtime::types::ElemType;
use dpp_runtime::wgsl::{element_wgsl, primitive_type_wgsl};
use std::fmt::Write;

/// The WGSL type of a primitive element type (monoids are defined on no other).
fn type_name(ty: ElemType) -> Result<&'static str, String> {
    primitive_type_wgsl(ty).ok_or_else(|| format!("monoids are not defined on {ty:?} elements"))
}

/// The scalar a component of `ty` is.
fn component(ty: ElemType) -> ElemType {
    match ty {
        ElemType::Vec2 | ElemType::Vec3 | ElemType::Vec4 => ElemType::F32,
        scalar => scalar,
    }
}

/// The identity of `op` on `ty` as a WGSL expression (the runtime's identity).
pub fn identity(op: MonoidOp, ty: ElemType) -> Result<String, String> {
    dpp_runtime::monoid::identity(op, ty)
        .map(element_wgsl)
        .map_err(|e| e.to_string())
}

/// Defines (once in `out`) and names `fn monoid_{op}_{ty}(a, b)`, with the
/// same statements as the monoid functors' twins.
pub fn combine_function(op: MonoidOp, ty: ElemType, out: &mut String) -> Result<String, String> {
    identity(op, ty)?;
    let t = type_name(ty)?;
    let short: String = t.chars().take_while(|c| *c != '<').collect();
    let name = format!("monoid_{}_{short}", op.name());
    if !out.contains(&format!("fn {name}(")) {
        let statements = dpp_runtime::generic::monoid_statements(op, ty)
            .ok_or_else(|| format!("`{}` is not defined on {ty:?} elements", op.name()))?;
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
        t = type_name(scalar)?
    );
    Ok(name)
}
