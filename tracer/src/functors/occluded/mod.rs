//! `occluded(ray: Ray) -> (blocked: bool)`: whether anything lies at
//! `0 < t < ray.tmax` (any hit; traversal stops at the first one). Dead rays
//! (`tmax <= 0`) are never blocked.

use crate::functors::RayColumns;
use crate::scene::TraceResources;
use dpp_runtime::{
    ArrayParam, CallContext, Column, ColumnView, ElemType, Functor, FunctorError, FunctorKind,
    RecordId, Signature, TypePattern,
};

pub struct Occluded {
    signature: Signature,
}

impl Occluded {
    pub fn new(ray: RecordId) -> Occluded {
        Occluded {
            signature: Signature {
                name: "occluded",
                kind: FunctorKind::Map,
                inputs: vec![ArrayParam {
                    name: "ray",
                    ty: TypePattern::Exact(ElemType::Record(ray)),
                }],
                outputs: vec![ArrayParam {
                    name: "blocked",
                    ty: TypePattern::Exact(ElemType::Bool),
                }],
                named: vec![],
                doc: "whether any triangle lies on the ray with 0 < t < tmax",
            },
        }
    }
}

impl Functor for Occluded {
    fn signature(&self) -> &Signature {
        &self.signature
    }

    fn run_cpu(
        &self,
        ctx: &CallContext<'_>,
        inputs: &[ColumnView<'_>],
        outputs: &mut [Column],
    ) -> Result<(), FunctorError> {
        let bvh = &ctx.resources::<TraceResources>()?.scene.bvh;
        let rays = RayColumns::new(&inputs[0]);
        let blocked = outputs[0].as_bool_mut();
        blocked.reserve(rays.len());
        for index in 0..rays.len() {
            let ray = rays.get(index);
            blocked.push(ray.tmax > 0.0 && bvh.occluded(&ray, ray.tmax));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use crate::functors::test_support::{probe_rays, Fixture};

    #[test]
    fn blocked_only_before_tmax() {
        let fixture = Fixture::new();
        let rays = probe_rays(&fixture);
        let out = fixture.run("occluded", &[], 0, &[rays.view()]).unwrap();
        assert_eq!(out[0].view().as_bool(), &[true, true, false, false]);
    }
}
