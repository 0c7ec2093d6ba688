//! `cellBlock(cell: u32) -> (block: u32) [size: int]`: the empty-space
//! skipping block (`size`³ cells, x fastest; see
//! [`crate::functors::volume_render`]) that a cell of the run's volume is in.

use crate::functors::isosurface::cell_origin;
use crate::functors::volume_render::{block_index, point_block};
use crate::functors::wgsl::buffers::VolumeGpuBuffers;
use crate::functors::wgsl::{request_resources, twin, volume_module, TwinParts};
use crate::scene::TraceResources;
use dpp_runtime::wgsl::{WgslRequest, WgslTwin};
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, HostType, Signature,
};

pub struct CellBlock {
    signature: Signature,
}

impl CellBlock {
    pub fn new() -> CellBlock {
        CellBlock {
            signature: Signature::map("cellBlock")
                .input("cell", ElemType::U32)
                .output("block", ElemType::U32)
                .named(
                    "size",
                    HostType::Int,
                    None,
                    "cells per side of a block (>= 1)",
                )
                .doc("the empty-space skipping block of a volume cell"),
        }
    }
}

impl Default for CellBlock {
    fn default() -> Self {
        CellBlock::new()
    }
}

/// The `size` named parameter at `index`: at least 1.
pub(crate) fn block_size(
    ctx: &CallContext<'_>,
    index: usize,
    functor: &str,
) -> Result<u32, FunctorError> {
    ctx.named(index)
        .as_u32()
        .filter(|&size| size >= 1)
        .ok_or_else(|| {
            FunctorError::bad_input(format!(
                "{functor}: size must be at least 1, got {}",
                ctx.named(index)
            ))
        })
}

impl Functor for CellBlock {
    fn signature(&self) -> &Signature {
        &self.signature
    }

    /// `twin.wgsl`, reading the volume's grid.
    fn wgsl(&self, request: &WgslRequest<'_>) -> Result<WgslTwin, FunctorError> {
        let volume =
            request_resources::<TraceResources>(request, "cellBlock")?.volume("cellBlock")?;
        let volume = VolumeGpuBuffers::of_volume(volume)
            .map_err(|e| FunctorError::bad_input(format!("cellBlock: {}", e.message)))?;
        let parts = TwinParts {
            modules: vec![volume_module(&volume)],
            failures: vec![
                "cellBlock: size must be at least 1".into(),
                "cellBlock: a cell index is past the volume's last cell".into(),
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
}
