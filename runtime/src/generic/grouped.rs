//! The generic `group` functors (`k` consecutive elements to one, for
//! `gather<f>(src, group: k)`) and `expand` functors (one element to `k`, for
//! `scatter<f>(src, fanout: k)`).

use super::elementwise::ScalarConversions;
use super::{functor, signature, unexpected_type, ANY, F32, NUMERIC, SCALAR_OR_BOOL, U32};
use crate::column::{Column, ColumnView};
use crate::cpu::kernels::{
    gather_by_position, reduce_groups, typed_slice, with_element_type, KernelError,
};
use crate::functor::{CallContext, Functor, FunctorError, FunctorKind, MonoidOp};
use std::sync::Arc;

pub(super) fn functors() -> Vec<Arc<dyn Functor>> {
    vec![
        functor(
            signature(
                FunctorKind::Group,
                "sum",
                &[("x", NUMERIC)],
                NUMERIC,
                "the sum of each group of k elements, in order; u32 and i32 wrap around",
            ),
            |ctx, inputs| Ok(reduce_groups(MonoidOp::Add, &inputs[0], ctx.group)?),
        ),
        functor(
            signature(
                FunctorKind::Group,
                "average",
                &[("x", SCALAR_OR_BOOL)],
                F32,
                "the mean of each group of k elements as f32 (for bool: the fraction that are true)",
            ),
            average,
        ),
        functor(
            signature(
                FunctorKind::Expand,
                "repeat",
                &[("x", ANY)],
                ANY,
                "x[i] in each of the k lanes: out[i*k + j] = x[i]",
            ),
            |ctx, inputs| {
                let lanes = ctx.group;
                let len = inputs[0].len() * lanes;
                Ok(gather_by_position(&inputs[0], len, &|position| {
                    position / lanes
                }))
            },
        ),
        functor(
            signature(
                FunctorKind::Expand,
                "lane",
                &[("x", ANY)],
                U32,
                "the lane number: out[i*k + j] = j",
            ),
            lane,
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

fn lane(ctx: &CallContext<'_>, inputs: &[ColumnView<'_>]) -> Result<Column, FunctorError> {
    let lanes = u32::try_from(ctx.group).map_err(|_| {
        FunctorError(format!(
            "a fan-out of {} lanes does not fit lane numbers in u32",
            ctx.group
        ))
    })?;
    Ok(Column::U32(
        (0..inputs[0].len()).flat_map(|_| 0..lanes).collect(),
    ))
}
