//! `cellBlock(cell: u32) -> (block: u32) [size: int]`: the empty-space
//! skipping block (`size`³ cells, x fastest; see
//! [`crate::functors::volume_render`]) that a cell of the run's volume is in.

use crate::functors::isosurface::cell_origin;
use crate::functors::tracer_functor;
use crate::functors::volume_render::{block_index, block_size, point_block, BLOCK_SIZE};
use crate::functors::wgsl::{request_resources, volume_module, TwinParts};
use crate::scene::TraceResources;
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{CallContext, Column, ColumnView, ElemType, Functor, FunctorError, Signature};
use std::sync::Arc;

pub fn functor() -> Arc<dyn Functor> {
    let signature = Signature::map("cellBlock")
        .input("cell", ElemType::U32)
        .output("block", ElemType::U32)
        .named_param(BLOCK_SIZE)
        .doc("the empty-space skipping block of a volume cell");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

/// `twin.wgsl`, reading the volume's grid.
fn twin_parts(request: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    let volume = request_resources::<TraceResources>(request, "cellBlock")?
        .volume_gpu_buffers("cellBlock")?;
    Ok(TwinParts {
        modules: vec![volume_module(&volume)],
        failures: vec![
            "cellBlock: size must be at least 1".into(),
            "cellBlock: a cell index is past the volume's last cell".into(),
        ],
        ..TwinParts::default()
    })
}

fn run_cpu(
    ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let volume = ctx.resources::<TraceResources>()?.volume("cellBlock")?;
    let size = block_size(ctx, 0, "cellBlock")?;
    let out = outputs[0].as_u32_mut();
    for &cell in inputs[0].as_u32() {
        let origin = cell_origin(volume, cell, "cellBlock")?;
        let block = point_block(volume, origin.as_vec3(), size);
        out.push(block_index(volume, block, size));
    }
    Ok(())
}
