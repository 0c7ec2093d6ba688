//! `reflectRay(surf: Surface) -> (ray: Ray) [maxDepth: int = 3]`: the mirror
//! reflection ray of a hit whose material reflects.
//!
//! Where the material's reflectivity is above 0 and `surf.depth + 1 < maxDepth`,
//! the ray starts `SURFACE_EPSILON * scene.diagonal` off the surface along the
//! geometric normal `g` (on the ray's side), in the direction `d - 2 (d·n) n`
//! (`d = -view`, `n` the shading normal), or `d - 2 (d·g) g` where that would
//! go into the surface (the shading normal leaning away from `g`), with `tmax = inf`,
//! `depth = surf.depth + 1` and `weight = surf.weight * reflectivity`: an
//! untinted mirror, so that with the shader's `1 - reflectivity` the pixel is the
//! blend `(1 - r) local + r reflected`. Everywhere else the ray is dead (`tmax =
//! 0`, zero weight), so with `maxDepth` the pipeline traces at most `maxDepth`
//! segments per camera ray (the camera ray included).

use crate::functors::tracer_functor;
use crate::functors::wgsl::{
    diagonal_failure, request_resources, surface_module, vector_module, TwinParts,
};
use crate::functors::{scene_diagonal, RayRecord, RayWriter, SurfaceColumns, SURFACE_EPSILON};
use crate::scene::TraceResources;
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, HostType, HostValue,
    RecordId, Signature,
};
use glam::Vec3;
use std::sync::Arc;

pub fn functor(surface: RecordId, ray: RecordId) -> Arc<dyn Functor> {
    let signature = Signature::map("reflectRay")
        .input("surf", ElemType::Record(surface))
        .output("ray", ElemType::Record(ray))
        .named(
            "maxDepth",
            HostType::Int,
            Some(HostValue::Int(3)),
            "ray segments per camera ray: a reflection of depth >= maxDepth is dead",
        )
        .doc("mirror reflection of a reflective hit (weight * reflectivity, depth + 1); dead otherwise or at maxDepth");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

/// `twin.wgsl`, reading the materials, built once per shading set-up.
fn twin_parts(request: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    let shading = request_resources::<TraceResources>(request, "reflectRay")?.shading_gpu_buffers();
    Ok(TwinParts {
        modules: vec![vector_module(), surface_module()],
        buffers: vec![shading.materials],
        failures: vec![
            diagonal_failure("reflectRay"),
            "reflectRay: a surface has a material the scene does not have".into(),
        ],
        ..TwinParts::default()
    })
}

fn run_cpu(
    ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let max_depth = ctx.named(0).as_int().unwrap_or(0);
    let materials = ctx.resources::<TraceResources>()?.shading.materials();
    let epsilon = SURFACE_EPSILON * scene_diagonal(ctx, "reflectRay")?;
    let surfaces = SurfaceColumns::new(&inputs[0]);
    // Every material a reflected hit names must exist: checked up front, so
    // that the loop below cannot fail.
    let reflects =
        |i: usize| surfaces.hit[i] && i64::from(surfaces.depth[i].saturating_add(1)) < max_depth;
    if let Some(index) = (0..surfaces.len())
        .find(|&i| reflects(i) && surfaces.material[i] as usize >= materials.len())
    {
        return Err(FunctorError::bad_input(format!(
            "reflectRay: surface has material {}, but the scene has {} materials",
            surfaces.material[index],
            materials.len()
        )));
    }
    let mut out = RayWriter::new(&mut outputs[0], surfaces.len())?;
    out.extend_with(surfaces.len(), |index| {
        if !reflects(index) {
            // Two more of the surface's fields read, not all ten.
            return RayRecord::dead(
                surfaces.sample[index],
                surfaces.depth[index].saturating_add(1),
            );
        }
        let surface = surfaces.get(index);
        let depth = surface.depth.saturating_add(1);
        let reflectivity = materials[surface.material as usize].reflectivity;
        if reflectivity <= 0.0 {
            return RayRecord::dead(surface.sample, depth);
        }
        let incoming = -surface.view;
        let mirror = |normal: Vec3| incoming - 2.0 * incoming.dot(normal) * normal;
        let mut dir = mirror(surface.normal);
        if dir.dot(surface.geometric) <= 0.0 {
            dir = mirror(surface.geometric);
        }
        RayRecord {
            origin: surface.offset_origin(epsilon),
            dir: dir.normalize_or_zero(),
            tmax: f32::INFINITY,
            sample: surface.sample,
            weight: surface.weight * reflectivity,
            depth,
        }
    });
    Ok(())
}

#[cfg(test)]
mod tests {
    use crate::functors::test_support::{read_rays, surface_hit, Fixture};
    use crate::functors::{RayRecord, SurfaceRecord, SURFACE_EPSILON};
    use crate::shading::MaterialSpec;
    use dpp_runtime::HostValue;
    use glam::Vec3;

    fn mirror_fixture() -> Fixture {
        let mut fixture = Fixture::new();
        fixture.set_shading(|shading| {
            let spec = MaterialSpec {
                reflectivity: Some(0.5),
                ..Default::default()
            };
            shading.set_material("default", &spec).unwrap();
        });
        fixture
    }

    fn surface(view: Vec3, depth: u32) -> SurfaceRecord {
        SurfaceRecord {
            view,
            weight: Vec3::new(1.0, 0.5, 0.25),
            depth,
            ..surface_hit(Vec3::new(0.5, 0.5, 0.0), Vec3::Z, 9)
        }
    }

    #[test]
    fn mirror_direction_weight_and_depth() {
        let fixture = mirror_fixture();
        let diagonal = fixture.resources.scene.bounds.diagonal();
        let view = Vec3::new(-1.0, 0.0, 1.0).normalize();
        let surfaces = fixture.surfaces(&[surface(view, 0), surface(Vec3::Z, 1)]);
        let out = fixture
            .run("reflectRay", &[], 0, &[surfaces.view()])
            .unwrap();
        let rays = read_rays(&out[0]);
        // Coming in along (1, 0, -1), leaving along (1, 0, 1).
        assert!((rays[0].dir - Vec3::new(1.0, 0.0, 1.0).normalize()).length() < 1e-6);
        assert_eq!(
            rays[0].origin,
            Vec3::new(0.5, 0.5, SURFACE_EPSILON * diagonal)
        );
        assert_eq!(rays[0].tmax, f32::INFINITY);
        assert_eq!(rays[0].weight, Vec3::new(0.5, 0.25, 0.125));
        assert_eq!((rays[0].sample, rays[0].depth), (9, 1));
        assert!((rays[1].dir - Vec3::Z).length() < 1e-6);
        assert_eq!(rays[1].depth, 2);
    }

    #[test]
    fn a_reflection_never_goes_into_the_surface() {
        // The shading normal leans so far from the triangle's that the mirror
        // direction about it points below the triangle's plane: the ray is mirrored
        // about the geometric normal instead, and starts off the triangle's front.
        let fixture = mirror_fixture();
        let diagonal = fixture.resources.scene.bounds.diagonal();
        let view = Vec3::new(0.28, 0.0, 0.96);
        let mut leaning = surface(view, 0);
        leaning.normal = Vec3::new(3f32.sqrt() / 2.0, 0.0, 0.5);
        let about_normal = -view + 2.0 * view.dot(leaning.normal) * leaning.normal;
        assert!(
            about_normal.z < 0.0,
            "the test should reflect into the surface"
        );
        let surfaces = fixture.surfaces(&[leaning]);
        let out = fixture
            .run("reflectRay", &[], 0, &[surfaces.view()])
            .unwrap();
        let ray = read_rays(&out[0])[0];
        assert!(
            (ray.dir - Vec3::new(-0.28, 0.0, 0.96)).length() < 1e-6,
            "{}",
            ray.dir
        );
        assert_eq!(ray.origin, Vec3::new(0.5, 0.5, SURFACE_EPSILON * diagonal));
    }

    #[test]
    fn dead_at_max_depth_for_misses_and_dull_materials() {
        let fixture = mirror_fixture();
        let surfaces = fixture.surfaces(&[
            surface(Vec3::Z, 1),
            surface(Vec3::Z, 2),
            SurfaceRecord::miss(4, Vec3::ONE, 0),
        ]);
        let out = fixture
            .run("reflectRay", &[HostValue::Int(3)], 0, &[surfaces.view()])
            .unwrap();
        let rays = read_rays(&out[0]);
        assert!(rays[0].tmax > 0.0 && rays[0].depth == 2);
        assert_eq!(rays[1], RayRecord::dead(9, 3));
        assert_eq!(rays[2], RayRecord::dead(4, 1));
        // maxDepth 1: no reflections at all.
        let out = fixture
            .run("reflectRay", &[HostValue::Int(1)], 0, &[surfaces.view()])
            .unwrap();
        assert!(read_rays(&out[0]).iter().all(|r| r.tmax == 0.0));
        // The default material does not reflect.
        let dull = Fixture::new();
        let out = dull.run("reflectRay", &[], 0, &[surfaces.view()]).unwrap();
        assert_eq!(read_rays(&out[0])[0], RayRecord::dead(9, 2));
        // And `alive` tells them apart.
        let out = fixture
            .run("reflectRay", &[], 0, &[surfaces.view()])
            .unwrap();
        let alive = fixture.run("alive", &[], 0, &[out[0].view()]).unwrap();
        assert_eq!(alive[0].view().as_bool(), &[true, false, false]);
    }

    /// A hit naming a material the scene lacks is an error where it would be
    /// reflected, and nothing where it is not (a ray at the bounce limit).
    #[test]
    fn a_missing_material_is_an_error_only_where_it_reflects() {
        let fixture = mirror_fixture();
        let mut unknown = surface(Vec3::Z, 0);
        unknown.material = 99;
        let surfaces = fixture.surfaces(&[surface(Vec3::Z, 0), unknown]);
        let error = fixture
            .run("reflectRay", &[HostValue::Int(3)], 0, &[surfaces.view()])
            .unwrap_err();
        assert!(error.message.contains("material 99"), "{}", error.message);
        let out = fixture
            .run("reflectRay", &[HostValue::Int(1)], 0, &[surfaces.view()])
            .unwrap();
        assert!(read_rays(&out[0]).iter().all(|r| r.tmax == 0.0));
    }
}
