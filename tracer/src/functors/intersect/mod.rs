//! `intersect(ray: Ray) -> (hit: Hit)`: the closest hit of each ray with
//! `0 < t < ray.tmax`, triangles named in input file order. Of triangles hit at
//! exactly the same distance (a ray through a shared edge, or overlapping copies
//! of a surface), the first in the BVH's leaf order: the same one on every
//! backend and traversal, whatever order they visit nodes in. Dead rays (`tmax
//! <= 0`) miss without a traversal.

use crate::functors::tracer_functor;
use crate::functors::wgsl::{bvh_traversal_parts, request_resources, TwinParts};
use crate::functors::MISS_PRIM;
use crate::functors::{write_hits, RayColumns};
use crate::scene::TraceResources;
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, RecordId, Signature,
};
use std::sync::Arc;

pub fn functor(ray: RecordId, hit: RecordId) -> Arc<dyn Functor> {
    let signature = Signature::map("intersect")
        .input("ray", ElemType::Record(ray))
        .output("hit", ElemType::Record(hit))
        .doc("closest hit of the ray with the scene (miss: t = inf, prim = 4294967295)");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

/// `twin.wgsl`: the CPU's traversal on the scene's BVH.
fn twin_parts(request: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    let scene = &request_resources::<TraceResources>(request, "intersect")?.scene;
    Ok(TwinParts {
        constants: vec![("MISS_PRIM", format!("{MISS_PRIM}u"))],
        ..bvh_traversal_parts(scene.gpu_buffers(), "intersect")
    })
}

fn run_cpu(
    ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let bvh = &ctx.resources::<TraceResources>()?.scene.bvh;
    let rays = RayColumns::new(&inputs[0]);
    let len = rays.len();
    // Dead rays (tmax <= 0) miss without a traversal.
    // SAFETY: `intersect_closest_into` writes all `len` places.
    unsafe {
        write_hits(&mut outputs[0], len, |hits| {
            bvh.intersect_closest_into(len, |index| rays.get(index), hits)
        })
    }
}

#[cfg(test)]
mod tests {
    use crate::functors::test_support::{probe_rays, Fixture};
    use crate::functors::MISS_PRIM;
    use dpp_runtime::Column;
    use glam::Vec3;

    #[test]
    fn closest_hits_in_file_order_and_misses() {
        let fixture = Fixture::new();
        let rays = probe_rays(&fixture);
        let out = fixture.run("intersect", &[], 0, &[rays.view()]).unwrap();
        let hits = out[0].view();
        assert_eq!(out[0].elem_type(), fixture.record("Hit"));
        assert_eq!(
            hits.field(0).as_f32(),
            &[2.0, 3.0, f32::INFINITY, f32::INFINITY]
        );
        // (0.25, 0.5) lies in the second triangle of the small square; (3, 0) in the
        // big square's first (4-5-6) triangle.
        assert_eq!(hits.field(1).as_u32(), &[1, 2, MISS_PRIM, MISS_PRIM]);
        assert_eq!(&hits.field(2).as_f32()[2..], &[0.0, 0.0]);
        assert_eq!(&hits.field(3).as_f32()[2..], &[0.0, 0.0]);
        // Barycentrics reproduce the hit point: triangle 1 is (v0, v2, v3).
        let (u, v) = (hits.field(2).as_f32()[0], hits.field(3).as_f32()[0]);
        let point = (1.0 - u - v) * Vec3::new(-1.0, -1.0, 0.0)
            + u * Vec3::new(1.0, 1.0, 0.0)
            + v * Vec3::new(-1.0, 1.0, 0.0);
        assert!((point - Vec3::new(0.25, 0.5, 0.0)).length() < 1e-6);
    }

    #[test]
    fn dead_rays_miss() {
        let fixture = Fixture::new();
        let mut rays = crate::functors::test_support::read_rays(&probe_rays(&fixture));
        for ray in &mut rays {
            ray.tmax = 0.0;
        }
        rays[1].tmax = -1.0;
        rays[2].tmax = f32::NAN;
        let rays = fixture.rays(&rays);
        let out = fixture.run("intersect", &[], 0, &[rays.view()]).unwrap();
        assert_eq!(out[0].view().field(1).as_u32(), &[MISS_PRIM; 4]);
        let out = fixture.run("occluded", &[], 0, &[rays.view()]).unwrap();
        assert_eq!(out[0].view().as_bool(), &[false; 4]);
    }

    #[test]
    fn missing_scene_is_an_error() {
        let fixture = Fixture::new();
        let rays = probe_rays(&fixture);
        let functor = fixture.library.get("intersect").unwrap();
        let ctx = dpp_runtime::CallContext {
            named: &[],
            uniforms: &fixture.uniforms,
            resources: &(),
            first_index: 0,
            group: 1,
            records: &fixture.library.records,
        };
        let mut outputs = vec![Column::with_capacity(
            fixture.record("Hit"),
            0,
            &fixture.library.records,
        )];
        let error = functor
            .run_cpu(&ctx, &[rays.view()], &mut outputs)
            .unwrap_err();
        assert!(error.message.contains("no scene loaded"), "{error}");
    }
}
