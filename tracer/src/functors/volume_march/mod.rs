//! `volumeMarch(march: March) -> (march: March) [step: float] [unit: float]
//! [samples: int = 8] [cutoff: float = 0.99] [shade: bool = false]`: the next
//! `samples` samples of a live march, `step` apart: trilinear values
//! classified by the transfer function (the shading's colour map and opacity
//! over its scalar range), opacity corrected from slabs `unit` thick to
//! `step`, optionally shaded by the gradient, composited front to back; the
//! march ends early once its opacity reaches `cutoff`. The definition is
//! [`crate::functors::volume_render`]'s. A march that is not live is copied.

use crate::functors::named_f32;
use crate::functors::tracer_functor;
use crate::functors::volume_render::{march, step, MarchColumns, MarchParams, MarchWriter, STEP};
use crate::functors::wgsl::{request_resources, vector_module, volume_module, TwinParts};
use crate::scene::TraceResources;
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, HostType, HostValue,
    RecordId, Signature,
};
use std::sync::Arc;

pub fn functor(march: RecordId) -> Arc<dyn Functor> {
    let signature = Signature::map("volumeMarch")
        .input("march", ElemType::Record(march))
        .output("next", ElemType::Record(march))
        .named_param(STEP)
        .named(
            "unit",
            HostType::Float,
            None,
            "the thickness the transfer function's opacities are for (world units, > 0)",
        )
        .named(
            "samples",
            HostType::Int,
            Some(HostValue::Int(8)),
            "samples per call (>= 1)",
        )
        .named(
            "cutoff",
            HostType::Float,
            Some(HostValue::Float(0.99)),
            "early ray termination: the opacity at which a march ends",
        )
        .named(
            "shade",
            HostType::Bool,
            Some(HostValue::Bool(false)),
            "shade samples by the field's gradient and a head light",
        )
        .doc("the next samples of a live march, composited front to back");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

/// `twin.wgsl`, reading the volume, the colour map (opacity in `w`) and
/// the scalar range.
fn twin_parts(request: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    let resources = request_resources::<TraceResources>(request, "volumeMarch")?;
    let volume = resources.volume_gpu_buffers("volumeMarch")?;
    let shading = resources.shading_gpu_buffers();
    Ok(TwinParts {
        modules: vec![vector_module(), volume_module(&volume)],
        buffers: vec![shading.constants, shading.colormap],
        failures: vec![
            "volumeMarch: step and unit must be finite numbers above 0".into(),
            "volumeMarch: samples must be at least 1".into(),
            "volumeMarch: cutoff must be a finite number".into(),
        ],
        ..TwinParts::default()
    })
}

fn run_cpu(
    ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let resources = ctx.resources::<TraceResources>()?;
    let volume = resources.volume("volumeMarch")?;
    let unit = named_f32(ctx, 1, "volumeMarch", "unit")?;
    if unit <= 0.0 {
        return Err(FunctorError::bad_input(format!(
            "volumeMarch: unit must be above 0, got {unit}"
        )));
    }
    let samples = ctx.named(2).as_u32().filter(|&n| n >= 1).ok_or_else(|| {
        FunctorError::bad_input(format!(
            "volumeMarch: samples must be at least 1, got {}",
            ctx.named(2)
        ))
    })?;
    let [low, high] = resources.shading.scalar_range();
    let params = MarchParams {
        step: step(ctx, 0, "volumeMarch")?,
        unit,
        samples,
        cutoff: named_f32(ctx, 3, "volumeMarch", "cutoff")?,
        shade: ctx.named(4).as_bool().unwrap_or(false),
        low,
        // As `ShadingGpuBuffers` computes it for the twins.
        inverse_range: 1.0 / (high - low),
    };
    let map = resources.shading.colormap();
    let marches = MarchColumns::new(&inputs[0]);
    let mut out = MarchWriter::new(&mut outputs[0])?;
    for i in 0..marches.len() {
        out.push(march(volume, map, &params, marches.get(i)));
    }
    Ok(())
}
