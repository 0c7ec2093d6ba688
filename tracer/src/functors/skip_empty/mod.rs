//! `skipEmpty(march: March, empty: bool) -> (next: March) [size: int]
//! [step: float]`: a live march whose block is `empty` (transparent) moved to
//! its first sample `step` apart past the block's far side; anything else
//! copied (see [`crate::functors::volume_render`]).

use crate::functors::tracer_functor;
use crate::functors::volume_render::{
    block_size, skip_block, step, MarchColumns, MarchWriter, BLOCK_SIZE, STEP,
};
use crate::functors::wgsl::{request_resources, vector_module, volume_module, TwinParts};
use crate::scene::TraceResources;
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, RecordId, Signature,
};
use std::sync::Arc;

pub fn functor(march: RecordId) -> Arc<dyn Functor> {
    let signature = Signature::map("skipEmpty")
        .input("march", ElemType::Record(march))
        .input("empty", ElemType::Bool)
        .output("next", ElemType::Record(march))
        .named_param(BLOCK_SIZE)
        .named_param(STEP)
        .doc("a march in an empty block moved past it, on its lattice of samples");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

/// `twin.wgsl`, reading the volume's grid.
fn twin_parts(request: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    let volume = request_resources::<TraceResources>(request, "skipEmpty")?
        .volume_gpu_buffers("skipEmpty")?;
    Ok(TwinParts {
        modules: vec![vector_module(), volume_module(&volume)],
        failures: vec![
            "skipEmpty: size must be at least 1".into(),
            "skipEmpty: step must be a finite number above 0".into(),
        ],
        ..TwinParts::default()
    })
}

fn run_cpu(
    ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let volume = ctx.resources::<TraceResources>()?.volume("skipEmpty")?;
    let size = block_size(ctx, 0, "skipEmpty")?;
    let step = step(ctx, 1, "skipEmpty")?;
    let marches = MarchColumns::new(&inputs[0]);
    let empty = inputs[1].as_bool();
    let mut out = MarchWriter::new(&mut outputs[0])?;
    for (i, &empty) in empty.iter().enumerate().take(marches.len()) {
        let m = marches.get(i);
        out.push(if empty && m.live() {
            skip_block(volume, m, size, step)
        } else {
            m
        });
    }
    Ok(())
}
