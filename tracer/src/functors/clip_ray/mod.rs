//! `clipRay(ray: Ray, t: f32) -> (ray: Ray)`: the ray ending at `t` where
//! that is nearer than its `tmax` (`tmax = t < tmax ? t : tmax`, so a NaN
//! `t` changes nothing); every other field kept.
//!
//! `pipelines/volume_surface.dpp` stops each ray's march through the volume
//! at the surface it hit (`clipRay(rays, hits.t)`: a miss's `t` is +inf).

use crate::functors::wgsl::no_parts;
use crate::functors::{tracer_functor, with_field_replaced, RAY_TMAX_FIELD};
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, RecordId, Signature,
};
use std::sync::Arc;

pub fn functor(ray: RecordId) -> Arc<dyn Functor> {
    let signature = Signature::map("clipRay")
        .input("ray", ElemType::Record(ray))
        .input("t", ElemType::F32)
        .output("ray", ElemType::Record(ray))
        .doc("the ray ending at t where t is nearer than its tmax, every other field kept");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), no_parts)
}

fn run_cpu(
    _: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let ends = inputs[1].as_f32();
    outputs[0] = with_field_replaced(&inputs[0], RAY_TMAX_FIELD, |tmax| {
        let clipped = tmax.as_f32().iter().zip(ends);
        Column::F32(
            clipped
                .map(|(&tmax, &t)| if t < tmax { t } else { tmax })
                .collect(),
        )
    });
    Ok(())
}

#[cfg(test)]
mod tests {
    use crate::functors::test_support::{ray, Fixture};
    use dpp_runtime::Column;
    use glam::Vec3;

    #[test]
    fn only_a_nearer_end_shortens_the_ray() {
        let fixture = Fixture::new();
        let rays = fixture.rays(&[
            ray(Vec3::ONE, Vec3::Z, 2.0, 7),
            ray(Vec3::ONE, Vec3::Z, 2.0, 8),
            ray(Vec3::ONE, Vec3::Z, f32::INFINITY, 9),
        ]);
        let ends = Column::F32(vec![1.5, f32::NAN, f32::INFINITY]);
        let out = fixture
            .run("clipRay", &[], 0, &[rays.view(), ends.view()])
            .unwrap();
        let tmax = out[0].field(crate::functors::RAY_TMAX_FIELD).unwrap();
        assert_eq!(tmax.view().as_f32(), &[1.5, 2.0, f32::INFINITY]);
        for field in [0, 1, 3, 4, 5] {
            assert_eq!(out[0].field(field), rays.field(field), "field {field}");
        }
    }
}
