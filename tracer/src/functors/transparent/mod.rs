//! `transparent(range: vec2) -> (empty: bool)`: whether the transfer function
//! (the shading's colour map and opacity over its scalar range) is
//! transparent over the values `range.x ..= -range.y` (a block's
//! `(min, -max)` from `cellRange`; see [`crate::functors::volume_render`]):
//! every opacity entry a value in it reads is 0. A block with no cells (`min
//! > max`) is transparent.

use crate::functors::tracer_functor;
use crate::functors::wgsl::{request_resources, vector_module, TwinParts};
use crate::scene::TraceResources;
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{CallContext, Column, ColumnView, ElemType, Functor, FunctorError, Signature};
use std::sync::Arc;

pub fn functor() -> Arc<dyn Functor> {
    let signature = Signature::map("transparent")
        .input("range", ElemType::Vec2)
        .output("empty", ElemType::Bool)
        .doc("whether the transfer function's opacity is 0 over the values range.x ..= -range.y");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

/// `twin.wgsl`, reading the colour map (opacity in `w`) and scalar range.
fn twin_parts(request: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    let shading =
        request_resources::<TraceResources>(request, "transparent")?.shading_gpu_buffers();
    Ok(TwinParts {
        modules: vec![vector_module()],
        buffers: vec![shading.constants, shading.colormap],
        ..TwinParts::default()
    })
}

fn run_cpu(
    ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let shading = &ctx.resources::<TraceResources>()?.shading;
    let [low, high] = shading.scalar_range();
    // As `ShadingGpuBuffers` computes it for the twins.
    let inverse_range = 1.0 / (high - low);
    let map = shading.colormap();
    let out = outputs[0].as_bool_mut();
    out.extend(inputs[0].as_vec2().iter().map(|range| {
        let (lo, hi) = (range.x, -range.y);
        // A block without cells keeps its fill, min above max; NaN is empty too.
        lo.partial_cmp(&hi).is_none_or(|order| order.is_gt())
            || map.transparent_between((lo - low) * inverse_range, (hi - low) * inverse_range)
    }));
    Ok(())
}
