//! `volumeEntry(ray: Ray) -> (march: March) [step: float] [jitter: bool =
//! false]`: where a camera ray's march through the run's volume starts and
//! ends (see [`crate::functors::volume_render`] for the definition): the ray
//! clipped to the box of the samples, the first sample moved a hashed
//! fraction of `step` further with `jitter`. A ray that misses the box gets a
//! march that is not live.

use crate::functors::tracer_functor;
use crate::functors::volume_render::{entry, jitter, step, MarchRecord, MarchWriter, STEP};
use crate::functors::wgsl::{
    random_module, request_resources, vector_module, volume_module, TwinParts,
};
use crate::functors::RayColumns;
use crate::scene::TraceResources;
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, HostType, HostValue,
    RecordId, Signature,
};
use std::sync::Arc;

pub fn functor(ray: RecordId, march: RecordId) -> Arc<dyn Functor> {
    let signature = Signature::map("volumeEntry")
        .input("ray", ElemType::Record(ray))
        .output("march", ElemType::Record(march))
        .named_param(STEP)
        .named(
            "jitter",
            HostType::Bool,
            Some(HostValue::Bool(false)),
            "start each ray a hashed fraction of a step further (deterministic)",
        )
        .doc("the ray clipped to the volume's box: the march from its first sample to its last");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

/// `twin.wgsl`, reading the volume's grid.
fn twin_parts(request: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    let volume = request_resources::<TraceResources>(request, "volumeEntry")?
        .volume_gpu_buffers("volumeEntry")?;
    Ok(TwinParts {
        modules: vec![vector_module(), random_module(), volume_module(&volume)],
        failures: vec!["volumeEntry: step must be a finite number above 0".into()],
        ..TwinParts::default()
    })
}

fn run_cpu(
    ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let volume = ctx.resources::<TraceResources>()?.volume("volumeEntry")?;
    let step = step(ctx, 0, "volumeEntry")?;
    let jittered = ctx.named(1).as_bool().unwrap_or(false);
    let rays = RayColumns::new(&inputs[0]);
    let mut out = MarchWriter::new(&mut outputs[0])?;
    for i in 0..rays.len() {
        let (o, d, t, t_end) = entry(volume, rays.origin[i], rays.dir[i], rays.tmax[i]);
        let sample = rays.sample[i];
        let march = if t <= t_end {
            let offset = if jittered { jitter(sample) * step } else { 0.0 };
            MarchRecord {
                origin: o,
                dir: d,
                t: t + offset,
                t_end,
                color: glam::Vec3::ZERO,
                alpha: 0.0,
                sample,
            }
        } else {
            MarchRecord::missed(o, d, sample)
        };
        out.push(march);
    }
    Ok(())
}
