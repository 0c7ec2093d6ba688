//! `caseTriangles(case: u32) -> (count: u32)`: how many triangles marching
//! cubes makes in a cell of this case (0 to 5), from the generated tables
//! ([`crate::marching_cubes_tables`]).

use crate::functors::tracer_functor;
use crate::functors::wgsl::{marching_cubes_module, TwinParts};
use crate::marching_cubes_tables::tables;
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{CallContext, Column, ColumnView, ElemType, Functor, FunctorError, Signature};
use std::sync::Arc;

pub fn functor() -> Arc<dyn Functor> {
    let signature = Signature::map("caseTriangles")
        .input("case", ElemType::U32)
        .output("count", ElemType::U32)
        .doc("the number of marching-cubes triangles (0..5) of a cell case");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

/// `twin.wgsl`, reading the generated tables.
fn twin_parts(_: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    Ok(TwinParts {
        modules: vec![marching_cubes_module()],
        failures: vec!["caseTriangles: a case is not a marching-cubes case (0..255)".into()],
        ..TwinParts::default()
    })
}

fn run_cpu(
    _ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let counts = &tables().counts;
    let cases = inputs[0].as_u32();
    let out = outputs[0].as_u32_mut();
    out.reserve(cases.len());
    for &case in cases {
        let count = counts.get(case as usize).ok_or_else(|| {
            FunctorError::bad_input(format!(
                "caseTriangles: case {case} is not a marching-cubes case (0..255)"
            ))
        })?;
        out.push(*count as u32);
    }
    Ok(())
}
