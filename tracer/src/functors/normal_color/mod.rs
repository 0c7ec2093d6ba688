//! `normalColor(ray: Ray, hit: Hit) -> (color: vec3)`: the hit triangle's geometric
//! normal, turned to face the viewer, as RGB `n * 0.5 + 0.5`; a dark background on
//! a miss. A picture of the geometry without any lighting.

use crate::functors::tracer_functor;
use crate::functors::wgsl::{
    mesh_module, request_resources, vec3_literal, vector_module, TwinParts,
};
use crate::functors::{HitColumns, RayColumns, MISS_PRIM};
use crate::prefetch::{prefetch, prefetch_hit_ahead};
use crate::scene::TraceResources;
use crate::vector::unit_or_zero;
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, RecordId, Signature,
};
use glam::Vec3;
use std::sync::Arc;

/// The colour of rays that hit nothing.
pub const BACKGROUND: Vec3 = Vec3::new(0.1, 0.1, 0.12);

pub fn functor(ray: RecordId, hit: RecordId) -> Arc<dyn Functor> {
    let signature = Signature::map("normalColor")
        .input("ray", ElemType::Record(ray))
        .input("hit", ElemType::Record(hit))
        .output("color", ElemType::Vec3)
        .doc("viewer-facing geometric normal of the hit as RGB (n*0.5+0.5); dark background on a miss");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

/// `twin.wgsl`, reading the scene's triangles, built once per scene.
fn twin_parts(request: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    let scene = &request_resources::<TraceResources>(request, "normalColor")?.scene;
    Ok(TwinParts {
        constants: vec![
            ("MISS_PRIM", format!("{MISS_PRIM}u")),
            ("BACKGROUND", vec3_literal(BACKGROUND)),
        ],
        modules: vec![vector_module(), mesh_module(scene.gpu_buffers())],
        failures: vec!["normalColor: a hit names a triangle the scene does not have".into()],
        ..TwinParts::default()
    })
}

fn run_cpu(
    ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let mesh = &ctx.resources::<TraceResources>()?.scene.mesh;
    let rays = RayColumns::new(&inputs[0]);
    let hits = HitColumns::new(&inputs[1]);
    let colors = outputs[0].as_vec3_mut();
    colors.reserve(rays.len());
    let (triangles, positions) = (mesh.triangles.as_slice(), mesh.positions.as_slice());
    let live_prim = |index: usize| {
        let prim = *hits.prim.get(index)?;
        (prim != MISS_PRIM).then_some(prim as usize)
    };
    for (index, (&direction, &prim)) in rays.dir.iter().zip(hits.prim).enumerate() {
        prefetch_hit_ahead(index, live_prim, triangles, |_, corners| {
            for vertex in corners {
                prefetch(positions, vertex);
            }
        });
        if prim == MISS_PRIM {
            colors.push(BACKGROUND);
            continue;
        }
        if prim as usize >= mesh.triangles.len() {
            return Err(FunctorError::bad_input(format!(
                "normalColor: hit names triangle {prim}, but the scene has {} triangles",
                mesh.triangles.len()
            )));
        }
        let normal = unit_or_zero(mesh.face_normal(prim as usize));
        let facing = if normal.dot(direction) > 0.0 {
            -normal
        } else {
            normal
        };
        colors.push(facing * 0.5 + 0.5);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::BACKGROUND;
    use crate::functors::test_support::{probe_rays, ray, Fixture};
    use dpp_runtime::Column;
    use glam::Vec3;
    use std::sync::Arc;

    #[test]
    fn normals_face_the_viewer_and_misses_are_background() {
        let fixture = Fixture::new();
        let rays = probe_rays(&fixture);
        let hits = fixture.run("intersect", &[], 0, &[rays.view()]).unwrap();
        let out = fixture
            .run("normalColor", &[], 0, &[rays.view(), hits[0].view()])
            .unwrap();
        let facing_up = Vec3::new(0.5, 0.5, 1.0);
        assert_eq!(
            out[0].view().as_vec3(),
            &[facing_up, facing_up, BACKGROUND, BACKGROUND]
        );

        // Seen from below, the same triangles face -z.
        let from_below =
            fixture.rays(&[ray(Vec3::new(0.25, 0.5, -0.5), Vec3::Z, f32::INFINITY, 0)]);
        let hits = fixture
            .run("intersect", &[], 0, &[from_below.view()])
            .unwrap();
        let out = fixture
            .run("normalColor", &[], 0, &[from_below.view(), hits[0].view()])
            .unwrap();
        assert_eq!(out[0].view().as_vec3(), &[Vec3::new(0.5, 0.5, 0.0)]);
    }

    #[test]
    fn unknown_triangle_is_an_error() {
        let fixture = Fixture::new();
        let rays = probe_rays(&fixture);
        let hits = fixture.run("intersect", &[], 0, &[rays.view()]).unwrap();
        let Column::Record { ty, fields } = &hits[0] else {
            unreachable!()
        };
        let mut fields = fields.clone();
        fields[1] = Arc::new(Column::U32(vec![0, 1, 99, 0]));
        let bad = Column::Record { ty: *ty, fields };
        let error = fixture
            .run("normalColor", &[], 0, &[rays.view(), bad.view()])
            .unwrap_err();
        assert!(error.message.contains("triangle 99"), "{error}");
    }
}
