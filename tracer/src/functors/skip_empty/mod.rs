//! `skipEmpty(march: March, empty: bool) -> (next: March) [size: int]
//! [step: float]`: a live march whose block is `empty` (transparent) moved to
//! its first sample `step` apart past the block's far side; anything else
//! copied (see [`crate::functors::volume_render`]).

use crate::functors::cell_block::block_size;
use crate::functors::named_f32;
use crate::functors::volume_render::{skip_block, MarchColumns, MarchWriter};
use crate::functors::wgsl::buffers::VolumeGpuBuffers;
use crate::functors::wgsl::{request_resources, twin, vector_module, volume_module, TwinParts};
use crate::scene::TraceResources;
use dpp_runtime::wgsl::{WgslRequest, WgslTwin};
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, HostType, RecordId, Signature,
};

pub struct SkipEmpty {
    signature: Signature,
}

impl SkipEmpty {
    pub fn new(march: RecordId) -> SkipEmpty {
        SkipEmpty {
            signature: Signature::map("skipEmpty")
                .input("march", ElemType::Record(march))
                .input("empty", ElemType::Bool)
                .output("next", ElemType::Record(march))
                .named(
                    "size",
                    HostType::Int,
                    None,
                    "cells per side of a block (>= 1)",
                )
                .named(
                    "step",
                    HostType::Float,
                    None,
                    "the distance between samples (world units, > 0)",
                )
                .doc("a march in an empty block moved past it, on its lattice of samples"),
        }
    }
}

impl Functor for SkipEmpty {
    fn signature(&self) -> &Signature {
        &self.signature
    }

    /// `twin.wgsl`, reading the volume's grid.
    fn wgsl(&self, request: &WgslRequest<'_>) -> Result<WgslTwin, FunctorError> {
        let volume =
            request_resources::<TraceResources>(request, "skipEmpty")?.volume("skipEmpty")?;
        let volume = VolumeGpuBuffers::of_volume(volume)
            .map_err(|e| FunctorError::bad_input(format!("skipEmpty: {}", e.message)))?;
        let parts = TwinParts {
            modules: vec![vector_module(), volume_module(&volume)],
            failures: vec![
                "skipEmpty: size must be at least 1".into(),
                "skipEmpty: step must be a finite number above 0".into(),
            ],
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
        let volume = ctx.resources::<TraceResources>()?.volume("skipEmpty")?;
        let size = block_size(ctx, 0, "skipEmpty")?;
        let step = named_f32(ctx, 1, "skipEmpty", "step")?;
        if step <= 0.0 {
            return Err(FunctorError::bad_input(format!(
                "skipEmpty: step must be above 0, got {step}"
            )));
        }
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
}
