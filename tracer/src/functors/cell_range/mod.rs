//! `cellRange(cell: u32) -> (range: vec2)`: `(min, -max)` of the values at a
//! cell's 8 corners in the run's volume, so that one `scatter<min>` by block
//! reduces both ends (empty-space skipping, see
//! [`crate::functors::volume_render`]). Cells are numbered as for marching
//! cubes ([`crate::functors::isosurface`]).

use crate::functors::isosurface::{cell_origin, corner_values};
use crate::functors::wgsl::buffers::VolumeGpuBuffers;
use crate::functors::wgsl::{request_resources, twin, vector_module, volume_module, TwinParts};
use crate::scene::TraceResources;
use dpp_runtime::wgsl::{WgslRequest, WgslTwin};
use dpp_runtime::{CallContext, Column, ColumnView, ElemType, Functor, FunctorError, Signature};
use glam::Vec2;

pub struct CellRange {
    signature: Signature,
}

impl CellRange {
    pub fn new() -> CellRange {
        CellRange {
            signature: Signature::map("cellRange")
                .input("cell", ElemType::U32)
                .output("range", ElemType::Vec2)
                .doc("(min, -max) of a volume cell's 8 corner values: one min-reduction gives both ends"),
        }
    }
}

impl Default for CellRange {
    fn default() -> Self {
        CellRange::new()
    }
}

impl Functor for CellRange {
    fn signature(&self) -> &Signature {
        &self.signature
    }

    /// `twin.wgsl`, reading the volume.
    fn wgsl(&self, request: &WgslRequest<'_>) -> Result<WgslTwin, FunctorError> {
        let volume =
            request_resources::<TraceResources>(request, "cellRange")?.volume("cellRange")?;
        let volume = VolumeGpuBuffers::of_volume(volume)
            .map_err(|e| FunctorError::bad_input(format!("cellRange: {}", e.message)))?;
        let parts = TwinParts {
            modules: vec![vector_module(), volume_module(&volume)],
            failures: vec!["cellRange: a cell index is past the volume's last cell".into()],
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
}
