//! `globalId(prim: u32) -> (id: u32)`: the id of triangle `prim` in the whole
//! data set.
//!
//! In a distributed run each rank traces only its part of the data, and a
//! hit's `prim` is the triangle's index in the rank's own mesh (what
//! `surface` looks the triangle up by). The scene may carry a table of each
//! triangle's id in the whole data set ([`crate::TraceScene::with_global_ids`]):
//! then `id` is `prim`'s entry in it, the triangle's index in a
//! single-process run of the whole data. Without a table (a whole data set)
//! `id` is `prim` itself. A miss, `prim = 4294967295` ([`MISS_PRIM`]), stays
//! 4294967295. With a table, a `prim` past the scene's triangles is an error.

use crate::functors::tracer_functor;
use crate::functors::wgsl::{request_resources, TwinParts};
use crate::functors::MISS_PRIM;
use crate::scene::TraceResources;
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{CallContext, Column, ColumnView, ElemType, Functor, FunctorError, Signature};
use std::sync::Arc;

pub fn functor() -> Arc<dyn Functor> {
    let signature = Signature::map("globalId")
        .input("prim", ElemType::U32)
        .output("id", ElemType::U32)
        .doc("the id of triangle prim in the whole data set: its entry in the scene's global id table, prim itself without one (a miss, 4294967295, stays a miss)");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

/// `twin.wgsl`, reading the scene's id table (built once per scene).
fn twin_parts(request: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    let scene = &request_resources::<TraceResources>(request, "globalId")?.scene;
    Ok(TwinParts {
        constants: vec![("MISS_PRIM", format!("{MISS_PRIM}u"))],
        buffers: vec![scene.global_id_gpu_buffer().clone()],
        failures: vec!["globalId: a hit names a triangle the scene does not have".into()],
        ..TwinParts::default()
    })
}

fn run_cpu(
    ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let scene = &ctx.resources::<TraceResources>()?.scene;
    let prims = inputs[0].as_u32();
    let out = outputs[0].as_u32_mut();
    out.reserve(prims.len());
    for &prim in prims {
        let Some(id) = scene.global_id(prim) else {
            return Err(FunctorError::bad_input(format!(
                "globalId: hit names triangle {prim}, but the scene has {} triangles",
                scene.mesh.triangles.len()
            )));
        };
        out.push(id);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use crate::functors::test_support::Fixture;
    use crate::functors::MISS_PRIM;
    use crate::TraceScene;
    use dpp_runtime::Column;
    use std::sync::Arc;

    #[test]
    fn ids_come_from_the_table_or_are_prim() {
        let fixture = Fixture::new();
        let triangles = fixture.resources.scene.mesh.triangles.len() as u32;
        let prims = Column::U32(vec![0, triangles - 1, MISS_PRIM, 1]);
        let out = fixture.run("globalId", &[], 0, &[prims.view()]).unwrap();
        assert_eq!(out[0].view().as_u32(), &[0, triangles - 1, MISS_PRIM, 1]);

        let scene = (*fixture.resources.scene).clone();
        let ids: Vec<u32> = (0..triangles).map(|t| 1000 + 7 * t).collect();
        let scene = scene.with_global_ids(Arc::new(ids)).unwrap();
        let fixture = Fixture::with_scene(scene);
        let out = fixture.run("globalId", &[], 0, &[prims.view()]).unwrap();
        assert_eq!(
            out[0].view().as_u32(),
            &[1000, 1000 + 7 * (triangles - 1), MISS_PRIM, 1007]
        );
        let past = Column::U32(vec![triangles]);
        let error = fixture.run("globalId", &[], 0, &[past.view()]).unwrap_err();
        assert!(error.to_string().contains("globalId"), "{error}");
    }

    #[test]
    fn tables_must_fit_the_scene() {
        let scene: TraceScene = (*Fixture::new().resources.scene).clone();
        let triangles = scene.mesh.triangles.len();
        assert!(scene
            .clone()
            .with_global_ids(Arc::new(vec![0; triangles + 1]))
            .is_err());
        let mut ids = vec![0; triangles];
        ids[0] = MISS_PRIM;
        assert!(scene.with_global_ids(Arc::new(ids)).is_err());
    }
}
