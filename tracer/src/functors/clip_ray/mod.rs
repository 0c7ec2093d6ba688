//! `clipRay(ray: Ray, t: f32) -> (ray: Ray)`: the ray ending at `t` where
//! that is nearer than its `tmax` (`tmax = t < tmax ? t : tmax`, so a NaN
//! `t` changes nothing); every other field kept.
//!
//! `pipelines/volume_surface.dpp` stops each ray's march through the volume
//! at the surface it hit (`clipRay(rays, hits.t)`: a miss's `t` is +inf).

use crate::functors::wgsl::{twin, TwinParts};
use dpp_runtime::wgsl::{WgslRequest, WgslTwin};
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, RecordId, Signature,
};

/// `tmax`'s place among `Ray`'s fields (`functors::register_records`).
const TMAX_FIELD: usize = 2;

pub struct ClipRay {
    signature: Signature,
}

impl ClipRay {
    pub fn new(ray: RecordId) -> ClipRay {
        ClipRay {
            signature: Signature::map("clipRay")
                .input("ray", ElemType::Record(ray))
                .input("t", ElemType::F32)
                .output("ray", ElemType::Record(ray))
                .doc("the ray ending at t where t is nearer than its tmax, every other field kept"),
        }
    }
}

impl Functor for ClipRay {
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
        let ends = inputs[1].as_f32();
        let tmax = rays.field_mut(TMAX_FIELD).as_f32_mut();
        for (tmax, &t) in tmax.iter_mut().zip(ends) {
            if t < *tmax {
                *tmax = t;
            }
        }
        outputs[0] = rays;
        Ok(())
    }
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
        let tmax = out[0].field(super::TMAX_FIELD).unwrap();
        assert_eq!(tmax.view().as_f32(), &[1.5, 2.0, f32::INFINITY]);
        for field in [0, 1, 3, 4, 5] {
            assert_eq!(out[0].field(field), rays.field(field), "field {field}");
        }
    }
}
