//! `withWeight(ray: Ray, weight: vec3) -> (ray: Ray)`: the ray with its
//! colour weight replaced and every other field kept (a dead ray stays dead).
//!
//! A pipeline that writes its reflections' weight itself
//! (`pipelines/workload3_expressions.dpp`: `surf.weight * m.reflectivity`)
//! sets it on `reflectRay`'s ray with this.

use crate::functors::wgsl::{twin, TwinParts};
use dpp_runtime::wgsl::{WgslRequest, WgslTwin};
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, RecordId, Signature,
};

/// `weight`'s place among `Ray`'s fields (`functors::register_records`).
const WEIGHT_FIELD: usize = 4;

pub struct WithWeight {
    signature: Signature,
}

impl WithWeight {
    pub fn new(ray: RecordId) -> WithWeight {
        WithWeight {
            signature: Signature::map("withWeight")
                .input("ray", ElemType::Record(ray))
                .input("weight", ElemType::Vec3)
                .output("ray", ElemType::Record(ray))
                .doc("the ray with its colour weight replaced, every other field kept"),
        }
    }
}

impl Functor for WithWeight {
    fn signature(&self) -> &Signature {
        &self.signature
    }

    fn wgsl(&self, request: &WgslRequest<'_>) -> Result<WgslTwin, FunctorError> {
        twin(
            &self.signature,
            request,
            include_str!("twin.wgsl"),
            TwinParts::default(),
        )
    }

    fn run_cpu(
        &self,
        _: &CallContext<'_>,
        inputs: &[ColumnView<'_>],
        outputs: &mut [Column],
    ) -> Result<(), FunctorError> {
        let mut rays = inputs[0].to_column();
        *rays.field_mut(WEIGHT_FIELD) = inputs[1].to_column();
        outputs[0] = rays;
        Ok(())
    }
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
            let expected = if field == super::WEIGHT_FIELD {
                weights.clone()
            } else {
                (*rays.field(field).unwrap()).clone()
            };
            assert_eq!(*out[0].field(field).unwrap(), expected, "field {field}");
        }
    }
}
