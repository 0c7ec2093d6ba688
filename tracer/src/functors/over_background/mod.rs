//! `overBackground(color: vec3, alpha: f32) -> (rgb: vec3)`: a colour
//! accumulated front to back with opacity `alpha`, over the shading's
//! background: `color + (1 - alpha) * background` (linear RGB).

use crate::functors::tracer_functor;
use crate::functors::wgsl::{request_resources, TwinParts};
use crate::scene::TraceResources;
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{CallContext, Column, ColumnView, ElemType, Functor, FunctorError, Signature};
use std::sync::Arc;

pub fn functor() -> Arc<dyn Functor> {
    let signature = Signature::map("overBackground")
        .input("color", ElemType::Vec3)
        .input("alpha", ElemType::F32)
        .output("rgb", ElemType::Vec3)
        .doc("a premultiplied colour over the background: color + (1 - alpha) * background");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

/// `twin.wgsl`, reading the background from the shading constants.
fn twin_parts(request: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    let shading =
        request_resources::<TraceResources>(request, "overBackground")?.shading_gpu_buffers();
    Ok(TwinParts {
        buffers: vec![shading.constants],
        ..TwinParts::default()
    })
}

fn run_cpu(
    ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let background = ctx.resources::<TraceResources>()?.shading.background();
    let (colors, alphas) = (inputs[0].as_vec3(), inputs[1].as_f32());
    let out = outputs[0].as_vec3_mut();
    out.extend(
        (colors.iter().zip(alphas)).map(|(&color, &alpha)| color + background * (1.0 - alpha)),
    );
    Ok(())
}
