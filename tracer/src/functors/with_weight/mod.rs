//! `withWeight(ray: Ray, weight: vec3) -> (ray: Ray)`: the ray with its
//! colour weight replaced and every other field kept (a dead ray stays dead).
//!
//! A pipeline that writes its reflections' weight itself
//! (`pipelines/workload3_expressions.dpp`: `surf.weight * m.reflectivity`)
//! sets it on `reflectRay`'s ray with this.

use crate::functors::wgsl::no_parts;
use crate::functors::{tracer_functor, with_field_replaced, RAY_WEIGHT_FIELD};
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, RecordId, Signature,
};
use std::sync::Arc;

pub fn functor(ray: RecordId) -> Arc<dyn Functor> {
    let signature = Signature::map("withWeight")
        .input("ray", ElemType::Record(ray))
        .input("weight", ElemType::Vec3)
        .output("ray", ElemType::Record(ray))
        .doc("the ray with its colour weight replaced, every other field kept");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), no_parts)
}

fn run_cpu(
    _: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    outputs[0] = with_field_replaced(&inputs[0], RAY_WEIGHT_FIELD, |_| inputs[1].to_column());
    Ok(())
}

#[cfg(test)]
mod tests {
    use crate::functors::test_support::{ray, Fixture};
    use crate::functors::RayRecord;
    use dpp_runtime::Column;
    use glam::Vec3;

    #[test]
    fn only_the_weight_changes() {
        let fixture = Fixture::new();
        let rays = [ray(Vec3::ONE, Vec3::Z, 2.0, 7), RayRecord::dead(3, 2)];
        let weights = Column::Vec3(vec![Vec3::new(0.5, 0.25, 0.0), Vec3::ONE]);
        let rays = fixture.rays(&rays);
        let out = fixture
            .run("withWeight", &[], 0, &[rays.view(), weights.view()])
            .unwrap();
        for field in 0..6 {
            let expected = if field == crate::functors::RAY_WEIGHT_FIELD {
                weights.clone()
            } else {
                (*rays.field(field).unwrap()).clone()
            };
            assert_eq!(*out[0].field(field).unwrap(), expected, "field {field}");
        }
    }
}
