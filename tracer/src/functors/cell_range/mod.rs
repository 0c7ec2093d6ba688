//! `cellRange(cell: u32) -> (range: vec2)`: `(min, -max)` of the values at a
//! cell's 8 corners in the run's volume, so that one `scatter<min>` by block
//! reduces both ends (empty-space skipping, see
//! [`crate::functors::volume_render`]). Cells are numbered as for marching
//! cubes ([`crate::functors::isosurface`]).

use crate::functors::isosurface::{cell_origin, corner_values};
use crate::functors::tracer_functor;
use crate::functors::wgsl::{request_resources, vector_module, volume_module, TwinParts};
use crate::scene::TraceResources;
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{CallContext, Column, ColumnView, ElemType, Functor, FunctorError, Signature};
use glam::Vec2;
use std::sync::Arc;

pub fn functor() -> Arc<dyn Functor> {
    let signature = Signature::map("cellRange")
        .input("cell", ElemType::U32)
        .output("range", ElemType::Vec2)
        .doc("(min, -max) of a volume cell's 8 corner values: one min-reduction gives both ends");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

/// `twin.wgsl`, reading the volume.
fn twin_parts(request: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    let volume = request_resources::<TraceResources>(request, "cellRange")?
        .volume_gpu_buffers("cellRange")?;
    Ok(TwinParts {
        modules: vec![vector_module(), volume_module(&volume)],
        failures: vec!["cellRange: a cell index is past the volume's last cell".into()],
        ..TwinParts::default()
    })
}

fn run_cpu(
    ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let volume = ctx.resources::<TraceResources>()?.volume("cellRange")?;
    let out = outputs[0].as_vec2_mut();
    for &cell in inputs[0].as_u32() {
        let values = corner_values(volume, cell_origin(volume, cell, "cellRange")?);
        let (lo, hi) = values
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
                (lo.min(v), hi.max(v))
            });
        out.push(Vec2::new(lo, -hi));
    }
    Ok(())
}
