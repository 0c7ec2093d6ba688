//! `alive(ray: Ray) -> (alive: bool)`: `tmax > 0` (false for NaN), the mask a
//! pipeline compacts its rays with.

use crate::functors::tracer_functor;
use crate::functors::wgsl::{vector_module, TwinParts};
use crate::functors::RayColumns;
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, RecordId, Signature,
};
use std::sync::Arc;

pub fn functor(ray: RecordId) -> Arc<dyn Functor> {
    let signature = Signature::map("alive")
        .input("ray", ElemType::Record(ray))
        .output("alive", ElemType::Bool)
        .doc("whether the ray is alive: tmax > 0");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

/// `twin.wgsl`: `tmax > 0` on the bits.
fn twin_parts(_: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    Ok(TwinParts {
        modules: vec![vector_module()],
        ..TwinParts::default()
    })
}

fn run_cpu(
    _ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let rays = RayColumns::new(&inputs[0]);
    outputs[0]
        .as_bool_mut()
        .extend(rays.tmax.iter().map(|&tmax| tmax > 0.0));
    Ok(())
}

#[cfg(test)]
mod tests {
    use crate::functors::test_support::{ray, Fixture};
    use crate::functors::RayRecord;
    use glam::Vec3;

    #[test]
    fn positive_tmax_is_alive() {
        let fixture = Fixture::new();
        let rays = fixture.rays(&[
            ray(Vec3::ZERO, Vec3::Z, f32::INFINITY, 0),
            ray(Vec3::ZERO, Vec3::Z, 1e-6, 1),
            RayRecord::dead(2, 0),
            ray(Vec3::ZERO, Vec3::Z, -1.0, 3),
            ray(Vec3::ZERO, Vec3::Z, f32::NAN, 4),
        ]);
        let out = fixture.run("alive", &[], 0, &[rays.view()]).unwrap();
        assert_eq!(out[0].view().as_bool(), &[true, true, false, false, false]);
    }
}
