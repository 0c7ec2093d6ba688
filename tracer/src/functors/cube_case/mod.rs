//! `cubeCase(cell: u32) -> (case: u32) [level: float]`: the marching-cubes case
//! of a cell of the run's volume (see [`crate::functors::isosurface`]): bit `n`
//! is set when corner `n` (at offset `(n & 1, n >> 1 & 1, n >> 2 & 1)`) is below
//! `level`. Used as `iota(volume.cells) → map<cubeCase>(level: level)`.

use crate::functors::isosurface::VolumeResources;
use crate::functors::isosurface::{case_index, cell_origin, corner_values, level, run_volume};
use crate::functors::wgsl::{request_resources, twin, vector_module, volume_module, TwinParts};
use dpp_runtime::wgsl::{WgslRequest, WgslTwin};
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, HostType, Signature,
};

pub struct CubeCase {
    signature: Signature,
}

impl CubeCase {
    pub fn new() -> CubeCase {
        CubeCase {
            signature: Signature::map("cubeCase")
                .input("cell", ElemType::U32)
                .output("case", ElemType::U32)
                .named("level", HostType::Float, None, "the isovalue; corners below it are inside")
                .doc("the marching-cubes case (0..255) of a volume cell: bit n set when corner n is below level"),
        }
    }
}

impl Default for CubeCase {
    fn default() -> Self {
        CubeCase::new()
    }
}

impl Functor for CubeCase {
    fn signature(&self) -> &Signature {
        &self.signature
    }

    /// `twin.wgsl`, reading the volume, built once per volume.
    fn wgsl(&self, request: &WgslRequest<'_>) -> Result<WgslTwin, FunctorError> {
        let volume = request_resources::<VolumeResources>(request, "cubeCase")?
            .gpu_buffers()
            .map_err(|e| FunctorError::bad_input(format!("cubeCase: {e}")))?;
        let parts = TwinParts {
            modules: vec![vector_module(), volume_module(&volume)],
            failures: vec![
                "cubeCase: level must be a finite number".into(),
                "cubeCase: a cell index is past the volume's last cell".into(),
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
        let volume = run_volume(ctx, "cubeCase")?;
        let level = level(ctx, "cubeCase")?;
        let cells = inputs[0].as_u32();
        let out = outputs[0].as_u32_mut();
        out.reserve(cells.len());
        for &cell in cells {
            let origin = cell_origin(volume, cell, "cubeCase")?;
            out.push(case_index(&corner_values(volume, origin), level));
        }
        Ok(())
    }
}
