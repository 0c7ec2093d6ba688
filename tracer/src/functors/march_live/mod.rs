//! `marchLive(march: March) -> (live: bool)`: `t <= tEnd` (false for NaN):
//! whether the march has samples left, the mask a pipeline compacts its
//! marches with.

use crate::functors::tracer_functor;
use crate::functors::volume_render::MarchColumns;
use crate::functors::wgsl::no_parts;
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, RecordId, Signature,
};
use std::sync::Arc;

pub fn functor(march: RecordId) -> Arc<dyn Functor> {
    let signature = Signature::map("marchLive")
        .input("march", ElemType::Record(march))
        .output("live", ElemType::Bool)
        .doc("whether the march has samples left: t <= tEnd");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), no_parts)
}

fn run_cpu(
    _ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let marches = MarchColumns::new(&inputs[0]);
    let out = outputs[0].as_bool_mut();
    out.extend((0..marches.len()).map(|i| marches.get(i).live()));
    Ok(())
}
