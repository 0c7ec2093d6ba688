//! `cubeCase(cell: u32) -> (case: u32) [level: float]`: the marching-cubes case
//! of a cell of the run's volume (see [`crate::functors::isosurface`]): bit `n`
//! is set when corner `n` (at offset `(n & 1, n >> 1 & 1, n >> 2 & 1)`) is below
//! `level`. Used as `iota(volume.cells) → map<cubeCase>(level: level)`.

use crate::functors::isosurface::VolumeResources;
use crate::functors::isosurface::{case_index, cell_origin, corner_values, level, run_volume};
use crate::functors::tracer_functor;
use crate::functors::wgsl::{request_resources, vector_module, volume_module, TwinParts};
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, HostType, Signature,
};
use std::sync::Arc;

pub fn functor() -> Arc<dyn Functor> {
    let signature = Signature::map("cubeCase")
        .input("cell", ElemType::U32)
        .output("case", ElemType::U32)
        .named("level", HostType::Float, None, "the isovalue; corners below it are inside")
        .doc("the marching-cubes case (0..255) of a volume cell: bit n set when corner n is below level");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

/// `twin.wgsl`, reading the volume, built once per volume.
fn twin_parts(request: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    let volume = request_resources::<VolumeResources>(request, "cubeCase")?
        .gpu_buffers()
        .map_err(|e| FunctorError::bad_input(format!("cubeCase: {e}")))?;
    Ok(TwinParts {
        modules: vec![vector_module(), volume_module(&volume)],
        failures: vec![
            "cubeCase: level must be a finite number".into(),
            "cubeCase: a cell index is past the volume's last cell".into(),
        ],
        ..TwinParts::default()
    })
}

fn run_cpu(
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
