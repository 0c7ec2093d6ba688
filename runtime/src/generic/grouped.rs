//! The generic `group` functors (`k` consecutive elements to one, for
//! `gather<f>(src, group: k)`) and `expand` functors (one element to `k`, for
//! `scatter<f>(src, fanout: k)`).

use super::elementwise::{conversion_wgsl, conversions_module, ScalarConversions};
use super::{functor, unexpected_type, Body, ANY, F32, NUMERIC, SCALAR_OR_BOOL, U32};
use crate::column::gather_by_position;
use crate::column::{Column, ColumnView};
use crate::elem::{typed_slice, with_element_type, KernelError};
use crate::functor::{CallContext, Functor, FunctorError};
use crate::monoid::reduce_groups;
use crate::monoid::MonoidOp;
use crate::signature::Signature;
use crate::types::ElemType;
use crate::wgsl::WgslRequest;
use std::sync::Arc;

pub(super) fn functors() -> Vec<Arc<dyn Functor>> {
    vec![
        functor(
            Signature::group("sum")
                .input("x", NUMERIC)
                .output("out", NUMERIC)
                .doc("the sum of each group of k elements, in order; u32 and i32 wrap around"),
            |ctx, inputs| Ok(reduce_groups(MonoidOp::Add, &inputs[0], ctx.group)?),
            sum_twin,
        ),
        functor(
            Signature::group("average")
                .input("x", SCALAR_OR_BOOL)
                .output("out", F32)
                .doc("the mean of each group of k elements as f32 (for bool: the fraction that are true)"),
            average,
            average_twin,
        ),
        functor(
            Signature::expand("repeat")
                .input("x", ANY)
                .output("out", ANY)
                .doc("x[i] in each of the k lanes: out[i*k + j] = x[i]"),
            |ctx, inputs| {
                let lanes = ctx.group;
                let len = inputs[0].len() * lanes;
                Ok(gather_by_position(&inputs[0], len, &|position| {
                    position / lanes
                }))
            },
            |_| Ok(Body::returns("src")),
        ),
        functor(
            Signature::expand("lane")
                .input("x", ANY)
                .output("out", U32)
                .doc("the lane number: out[i*k + j] = j"),
            lane,
            // `k` is a u32 on the GPU, so every lane number fits.
            |_| Ok(Body::returns("lane")),
        ),
    ]
}

/// Each group's elements converted to `f32` (as `toF32` does) and summed in
/// order, divided by `k`.
fn average(ctx: &CallContext<'_>, inputs: &[ColumnView<'_>]) -> Result<Column, FunctorError> {
    let group = ctx.group;
    if group == 0 {
        return Err(KernelError::EmptyGroup.into());
    }
    with_element_type!(inputs[0].elem_type(), scalar_or_bool, T => {
        let groups = typed_slice::<T>(&inputs[0])?.chunks_exact(group);
        let sum = |values: &[T]| values.iter().fold(0.0, |sum, value| sum + value.to_f32());
        Ok(Column::F32(groups.map(|values| sum(values) / group as f32).collect()))
    }, other => Err(unexpected_type(other)))
}

/// `F_src(first + j)` summed for `j = 0..k` from zero, the CPU's order; an
/// empty group fails as on the CPU.
fn sum_twin(request: &WgslRequest<'_>) -> Result<Body, FunctorError> {
    let ty = request.inputs[0];
    if !ty.is_numeric() {
        return Err(unexpected_type(ty));
    }
    let element = format!("{}_src(first + j)", request.function);
    Ok(fold_group(request, &element, "total"))
}

/// Each element converted by `toF32`'s code, summed in order from `0.0` and
/// divided by `k` (WGSL's division is accurate to 2.5 ULP, the CPU's exact).
fn average_twin(request: &WgslRequest<'_>) -> Result<Body, FunctorError> {
    let ty = request.inputs[0];
    let element = format!("{}_src(first + j)", request.function);
    let element =
        conversion_wgsl(ty, ElemType::F32, &element).ok_or_else(|| unexpected_type(ty))?;
    // `k as f32` rounds like `group as f32` does on the CPU.
    let count = conversion_wgsl(ElemType::U32, ElemType::F32, "k").unwrap_or_default();
    let mean = format!("total / {count}");
    Ok(fold_group(request, &element, &mean).with_module(conversions_module()))
}

/// `total = total + element` for `j = 0..k`, left to right from zero like
/// [`reduce_groups`], then `result`; fails for `k = 0` as it does.
fn fold_group(request: &WgslRequest<'_>, element: &str, result: &str) -> Body {
    let output = super::output_type(request);
    Body::statements(format!(
        "var total = {output}();\n\
         for (var j = 0u; j < k; j = j + 1u) {{\n\
         \x20   total = total + {element};\n\
         }}\n\
         return {result};"
    ))
    .failing_when(request, "k == 0u", KernelError::EmptyGroup.to_string())
}

fn lane(ctx: &CallContext<'_>, inputs: &[ColumnView<'_>]) -> Result<Column, FunctorError> {
    let lanes = u32::try_from(ctx.group).map_err(|_| {
        FunctorError::bad_input(format!(
            "a fan-out of {} lanes does not fit lane numbers in u32",
            ctx.group
        ))
    })?;
    Ok(Column::U32(
        (0..inputs[0].len()).flat_map(|_| 0..lanes).collect(),
    ))
}
