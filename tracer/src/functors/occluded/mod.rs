//! `occluded(ray: Ray) -> (blocked: bool)`: whether anything lies at
//! `0 < t < ray.tmax` (any hit; traversal stops at the first one). Dead rays
//! (`tmax <= 0`) are never blocked.

use crate::functors::tracer_functor;
use crate::functors::wgsl::{bvh_traversal_parts, request_resources, TwinParts};
use crate::functors::RayColumns;
use crate::scene::TraceResources;
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, RecordId, Signature,
};
use std::sync::Arc;

pub fn functor(ray: RecordId) -> Arc<dyn Functor> {
    let signature = Signature::map("occluded")
        .input("ray", ElemType::Record(ray))
        .output("blocked", ElemType::Bool)
        .doc("whether any triangle lies on the ray with 0 < t < tmax");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

/// `twin.wgsl`: the CPU's any-hit traversal on the scene's BVH.
fn twin_parts(request: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    let scene = &request_resources::<TraceResources>(request, "occluded")?.scene;
    Ok(bvh_traversal_parts(scene.gpu_buffers(), "occluded"))
}

fn run_cpu(
    ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let bvh = &ctx.resources::<TraceResources>()?.scene.bvh;
    let rays = RayColumns::new(&inputs[0]);
    let blocked = outputs[0].as_bool_mut();
    blocked.reserve(rays.len());
    // Dead rays (tmax <= 0) are never blocked.
    bvh.occluded_batch_skipping_dead(
        rays.len(),
        |index| rays.tmax[index],
        |index| rays.get(index),
        |window| blocked.extend_from_slice(window),
    );
    Ok(())
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
