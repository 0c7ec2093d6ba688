//! `marchBlock(march: March) -> (block: u32) [size: int]`: the empty-space
//! skipping block (as `cellBlock` numbers them) that a march's next sample
//! `g(t)` lies in, clamped into the grid of blocks (see
//! [`crate::functors::volume_render`]); 0 for a march that is not live.

use crate::functors::tracer_functor;
use crate::functors::volume_render::{
    block_index, block_size, point_block, MarchColumns, BLOCK_SIZE,
};
use crate::functors::wgsl::{request_resources, volume_module, TwinParts};
use crate::scene::TraceResources;
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, RecordId, Signature,
};
use std::sync::Arc;

pub fn functor(march: RecordId) -> Arc<dyn Functor> {
    let signature = Signature::map("marchBlock")
        .input("march", ElemType::Record(march))
        .output("block", ElemType::U32)
        .named_param(BLOCK_SIZE)
        .doc("the empty-space skipping block of a march's next sample (0 when it has none)");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

/// `twin.wgsl`, reading the volume's grid.
fn twin_parts(request: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    let volume = request_resources::<TraceResources>(request, "marchBlock")?
        .volume_gpu_buffers("marchBlock")?;
    Ok(TwinParts {
        modules: vec![volume_module(&volume)],
        failures: vec!["marchBlock: size must be at least 1".into()],
        ..TwinParts::default()
    })
}

fn run_cpu(
    ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let volume = ctx.resources::<TraceResources>()?.volume("marchBlock")?;
    let size = block_size(ctx, 0, "marchBlock")?;
    let marches = MarchColumns::new(&inputs[0]);
    let out = outputs[0].as_u32_mut();
    out.extend((0..marches.len()).map(|i| {
        let m = marches.get(i);
        if m.live() {
            block_index(
                volume,
                point_block(volume, m.origin + m.dir * m.t, size),
                size,
            )
        } else {
            0
        }
    }));
    Ok(())
}
