//! `volumeEntry(ray: Ray) -> (march: March) [step: float] [jitter: bool =
//! false]`: where a camera ray's march through the run's volume starts and
//! ends (see [`crate::functors::volume_render`] for the definition): the ray
//! clipped to the box of the samples, the first sample moved a hashed
//! fraction of `step` further with `jitter`. A ray that misses the box gets a
//! march that is not live.

use crate::functors::volume_render::{entry, jitter, MarchRecord, MarchWriter};
use crate::functors::wgsl::buffers::VolumeGpuBuffers;
use crate::functors::wgsl::{
    random_module, request_resources, twin, vector_module, volume_module, TwinParts,
};
use crate::functors::{named_f32, RayColumns};
use crate::scene::TraceResources;
use dpp_runtime::wgsl::{WgslRequest, WgslTwin};
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, HostType, HostValue,
    RecordId, Signature,
};

pub struct VolumeEntry {
    signature: Signature,
}

impl VolumeEntry {
    pub fn new(ray: RecordId, march: RecordId) -> VolumeEntry {
        VolumeEntry {
            signature: Signature::map("volumeEntry")
                .input("ray", ElemType::Record(ray))
                .output("march", ElemType::Record(march))
                .named("step", HostType::Float, None, "the distance between samples (world units, > 0)")
                .named(
                    "jitter",
                    HostType::Bool,
                    Some(HostValue::Bool(false)),
                    "start each ray a hashed fraction of a step further (deterministic)",
                )
                .doc("the ray clipped to the volume's box: the march from its first sample to its last"),
        }
    }
}

/// The `step` named parameter (index 0): finite and positive.
pub(crate) fn step(ctx: &CallContext<'_>, functor: &str) -> Result<f32, FunctorError> {
    let step = named_f32(ctx, 0, functor, "step")?;
    if step > 0.0 {
        Ok(step)
    } else {
        Err(FunctorError::bad_input(format!(
            "{functor}: step must be above 0, got {step}"
        )))
    }
}

impl Functor for VolumeEntry {
    fn signature(&self) -> &Signature {
        &self.signature
    }

    /// `twin.wgsl`, reading the volume's grid.
    fn wgsl(&self, request: &WgslRequest<'_>) -> Result<WgslTwin, FunctorError> {
        let volume =
            request_resources::<TraceResources>(request, "volumeEntry")?.volume("volumeEntry")?;
        let volume = VolumeGpuBuffers::of_volume(volume)
            .map_err(|e| FunctorError::bad_input(format!("volumeEntry: {}", e.message)))?;
        let parts = TwinParts {
            modules: vec![vector_module(), random_module(), volume_module(&volume)],
            failures: vec!["volumeEntry: step must be a finite number above 0".into()],
            ..TwinParts::default()
        };
        twin(&self.signature, request, include_str!("twin.wgsl"), parts)
    }

    fn run_cpu(
        &self,
        ctx: &CallContext<'_>,
        inputs: &[ColumnView<'_>],
        outputs: &mut [Column],
    ) -> Result<(), FunctorError> {
        let volume = ctx.resources::<TraceResources>()?.volume("volumeEntry")?;
        let step = step(ctx, "volumeEntry")?;
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
}
