//! `marchBlock(march: March) -> (block: u32) [size: int]`: the empty-space
//! skipping block (as `cellBlock` numbers them) that a march's next sample
//! `g(t)` lies in, clamped into the grid of blocks (see
//! [`crate::functors::volume_render`]); 0 for a march that is not live.

use crate::functors::cell_block::block_size;
use crate::functors::volume_render::{block_index, point_block, MarchColumns};
use crate::functors::wgsl::buffers::VolumeGpuBuffers;
use crate::functors::wgsl::{request_resources, twin, volume_module, TwinParts};
use crate::scene::TraceResources;
use dpp_runtime::wgsl::{WgslRequest, WgslTwin};
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, HostType, RecordId, Signature,
};

pub struct MarchBlock {
    signature: Signature,
}

impl MarchBlock {
    pub fn new(march: RecordId) -> MarchBlock {
        MarchBlock {
            signature: Signature::map("marchBlock")
                .input("march", ElemType::Record(march))
                .output("block", ElemType::U32)
                .named(
                    "size",
                    HostType::Int,
                    None,
                    "cells per side of a block (>= 1)",
                )
                .doc(
                    "the empty-space skipping block of a march's next sample (0 when it has none)",
                ),
        }
    }
}

impl Functor for MarchBlock {
    fn signature(&self) -> &Signature {
        &self.signature
    }

    /// `twin.wgsl`, reading the volume's grid.
    fn wgsl(&self, request: &WgslRequest<'_>) -> Result<WgslTwin, FunctorError> {
        let volume =
            request_resources::<TraceResources>(request, "marchBlock")?.volume("marchBlock")?;
        let volume = VolumeGpuBuffers::of_volume(volume)
            .map_err(|e| FunctorError::bad_input(format!("marchBlock: {}", e.message)))?;
        let parts = TwinParts {
            modules: vec![volume_module(&volume)],
            failures: vec!["marchBlock: size must be at least 1".into()],
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
}
