//! `cubeTriangle(cell: u32, lane: u32) -> (tri: Triangle) [level: float]`:
//! triangle number `lane` of a cell of the run's volume, as marching cubes
//! makes it (the cell's case is recomputed from its 8 corners).
//!
//! Each corner lies on a cell edge, linearly interpolated between the edge's
//! two samples to where the field equals `level`, in world space
//! ([`crate::volume::Volume::position`]); its normal is the field gradient (central
//! differences) interpolated the same way and normalised, pointing towards
//! increasing values; its scalar is the field interpolated the same way. The
//! corners wind counter-clockwise seen from the side of higher values. See
//! [`crate::functors::isosurface`] for the conventions.

use crate::functors::isosurface::VolumeResources;
use crate::functors::isosurface::{
    case_index, cell_origin, corner_values, edge_vertex, level, run_volume, TriangleRecord,
    TriangleWriter,
};
use crate::functors::tracer_functor;
use crate::functors::wgsl::{
    marching_cubes_module, request_resources, vector_module, volume_module, TwinParts,
};
use crate::marching_cubes_tables::tables;
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, HostType, RecordId, Signature,
};
use std::sync::Arc;

pub fn functor(triangle: RecordId) -> Arc<dyn Functor> {
    let signature = Signature::map("cubeTriangle")
        .input("cell", ElemType::U32)
        .input("lane", ElemType::U32)
        .output("tri", ElemType::Record(triangle))
        .named("level", HostType::Float, None, "the isovalue (the same as cubeCase's)")
        .doc("triangle `lane` of a volume cell's marching-cubes surface at level: corners on the cell edges, gradient normals, interpolated scalars");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

/// `twin.wgsl`, reading the volume (built once per volume) and the tables.
fn twin_parts(request: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    let volume = request_resources::<VolumeResources>(request, "cubeTriangle")?
        .gpu_buffers()
        .map_err(|e| FunctorError::bad_input(format!("cubeTriangle: {e}")))?;
    Ok(TwinParts {
        modules: vec![
            vector_module(),
            volume_module(&volume),
            marching_cubes_module(),
        ],
        failures: vec![
            "cubeTriangle: level must be a finite number".into(),
            "cubeTriangle: a cell index is past the volume's last cell".into(),
            "cubeTriangle: a lane is past the cell's triangles at this level".into(),
        ],
        ..TwinParts::default()
    })
}

fn run_cpu(
    ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let volume = run_volume(ctx, "cubeTriangle")?;
    let level = level(ctx, "cubeTriangle")?;
    let tables = tables();
    let (cells, lanes) = (inputs[0].as_u32(), inputs[1].as_u32());
    let mut out = TriangleWriter::new(&mut outputs[0], cells.len())?;
    for (&cell, &lane) in cells.iter().zip(lanes) {
        let origin = cell_origin(volume, cell, "cubeTriangle")?;
        let values = corner_values(volume, origin);
        let case = case_index(&values, level);
        let triangles = tables.case_triangles(case);
        let Some(edges) = triangles.get(lane as usize) else {
            return Err(FunctorError::bad_input(format!(
                "cubeTriangle: cell {cell} has {} triangles at level {level}, no triangle {lane}",
                triangles.len()
            )));
        };
        let vertices = edges.map(|edge| edge_vertex(volume, origin, &values, edge, level));
        out.push(TriangleRecord {
            corners: vertices.map(|v| v.0),
            normals: vertices.map(|v| v.1),
            scalars: vertices.map(|v| v.2),
        });
    }
    Ok(())
}
