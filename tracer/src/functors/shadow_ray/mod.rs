//! `shadowRay(surf: Surface) -> (ray: Ray)`, an expand functor used as
//! `scatter<shadowRay>(surf, fanout: scene.lights)`: lane `j` is the ray from the
//! surface point towards light `j`.
//!
//! The ray starts `SURFACE_EPSILON * scene.diagonal` off the surface along the
//! geometric normal (on the ray's side, so never on or behind the triangle's
//! plane, which the shading normal does not ensure), has a unit direction and
//! `tmax` = the distance to the light minus that epsilon, so the light itself
//! never blocks it. It keeps the surface's `sample`, `weight` and `depth`. A
//! non-hit surface, or a light on the far side of the surface (`n·l <= 0`, which
//! the shader does not light anyway), gives a dead ray (`tmax = 0`), which
//! `occluded` reports as not blocked.

use crate::functors::tracer_functor;
use crate::functors::wgsl::{
    diagonal_failure, request_resources, surface_module, vector_module, TwinParts,
};
use crate::functors::{
    runs_of, scene_diagonal, RayRecord, RayWriter, SurfaceColumns, SurfaceRecord, SURFACE_EPSILON,
};
use crate::scene::TraceResources;
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, RecordId, Signature,
};
use glam::Vec3;
use std::sync::Arc;

pub fn functor(surface: RecordId, ray: RecordId) -> Arc<dyn Functor> {
    let signature = Signature::expand("shadowRay")
        .input("surf", ElemType::Record(surface))
        .output("ray", ElemType::Record(ray))
        .doc("lane j: the ray from the surface point to light j (fanout: scene.lights); dead for a miss or a light behind the surface");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

/// `twin.wgsl`, reading the lights, built once per shading set-up.
fn twin_parts(request: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    let shading = request_resources::<TraceResources>(request, "shadowRay")?.shading_gpu_buffers();
    Ok(TwinParts {
        modules: vec![vector_module(), surface_module()],
        buffers: vec![shading.lights],
        failures: vec![
            "shadowRay: the fanout is not the scene's number of lights; use fanout: scene.lights"
                .into(),
            diagonal_failure("shadowRay"),
        ],
        ..TwinParts::default()
    })
}

fn run_cpu(
    ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let lights = ctx.resources::<TraceResources>()?.shading.lights();
    let lanes = ctx.group;
    if lanes != lights.len() {
        return Err(FunctorError::bad_input(format!(
            "shadowRay: fanout {lanes}, but the scene has {} lights; use fanout: scene.lights",
            lights.len()
        )));
    }
    let epsilon = SURFACE_EPSILON * scene_diagonal(ctx, "shadowRay")?;
    let surfaces = SurfaceColumns::new(&inputs[0]);
    let mut out = RayWriter::new(&mut outputs[0], surfaces.len() * lanes)?;
    for (hit, run) in runs_of(surfaces.len(), |index| surfaces.hit[index]) {
        if !hit {
            // A run of misses reads two more of the surfaces' fields, not all ten.
            let depths = surfaces.depth[run.clone()].iter().copied();
            out.extend_dead(&surfaces.sample[run], depths, lanes);
            continue;
        }
        // A run of hits in one pass, the lanes of a surface in turn; the
        // surface and the rays' origin are read once per surface.
        let mut next = (run.start, 0);
        let (mut surface, mut origin) = (SurfaceRecord::miss(0, Vec3::ZERO, 0), Vec3::ZERO);
        out.extend_with(run.len() * lanes, |_| {
            let (index, lane) = next;
            next = if lane + 1 == lanes {
                (index + 1, 0)
            } else {
                (index, lane + 1)
            };
            if lane == 0 {
                surface = surfaces.get(index);
                origin = surface.offset_origin(epsilon);
            }
            let to_light = lights[lane].position - origin;
            let distance = to_light.length();
            let tmax = distance - epsilon;
            if !(surface.normal.dot(to_light) > 0.0 && tmax > 0.0) {
                return RayRecord::dead(surface.sample, surface.depth);
            }
            RayRecord {
                origin,
                dir: to_light / distance,
                tmax,
                sample: surface.sample,
                weight: surface.weight,
                depth: surface.depth,
            }
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use crate::functors::test_support::{read_rays, surface_hit, Fixture};
    use crate::functors::{RayRecord, SurfaceRecord, SURFACE_EPSILON};
    use crate::shading::PointLight;
    use glam::Vec3;

    /// The default fixture lit by three lights: above, beside and below the
    /// z = 0 plane (behind a surface facing +z).
    fn three_lights() -> Fixture {
        let mut fixture = Fixture::new();
        let lights = vec![
            PointLight::new(Vec3::new(0.0, 0.0, 4.0), 1.0),
            PointLight::new(Vec3::new(6.0, 0.0, 1.0), 1.0),
            PointLight::new(Vec3::new(0.0, 0.0, -3.0), 1.0),
        ];
        fixture.set_shading(|shading| shading.set_lights(lights).unwrap());
        fixture
    }

    #[test]
    fn one_ray_per_light_towards_it() {
        let fixture = three_lights();
        let diagonal = fixture.resources.scene.bounds.diagonal();
        let epsilon = SURFACE_EPSILON * diagonal;
        let surfaces = fixture.surfaces(&[
            surface_hit(Vec3::ZERO, Vec3::Z, 5),
            SurfaceRecord::miss(6, Vec3::ONE, 1),
        ]);
        let out = fixture
            .run_grouped("shadowRay", &[], 3, 0, &[surfaces.view()])
            .unwrap();
        let rays = read_rays(&out[0]);
        assert_eq!(rays.len(), 6);
        let origin = Vec3::new(0.0, 0.0, epsilon);
        assert_eq!(rays[0].origin, origin);
        assert_eq!(rays[0].dir, Vec3::Z);
        assert!((rays[0].tmax - (4.0 - 2.0 * epsilon)).abs() < 1e-6);
        assert_eq!(
            (rays[0].sample, rays[0].weight, rays[0].depth),
            (5, Vec3::ONE, 0)
        );
        let to_second = Vec3::new(6.0, 0.0, 1.0) - origin;
        assert!((rays[1].dir - to_second.normalize()).length() < 1e-6);
        assert!((rays[1].tmax - (to_second.length() - epsilon)).abs() < 1e-5);
        assert_eq!(rays[2], RayRecord::dead(5, 0));
        for lane in 0..3 {
            assert_eq!(rays[3 + lane], RayRecord::dead(6, 1));
        }
        // Traced from the big square under the small one: the small square blocks
        // the light straight above; the ray to (6, 0, 1) passes z = 0 at x = 3,
        // beside the small square.
        let from_big = fixture.surfaces(&[surface_hit(Vec3::new(0.0, 0.0, -1.0), Vec3::Z, 0)]);
        let out = fixture
            .run_grouped("shadowRay", &[], 3, 0, &[from_big.view()])
            .unwrap();
        let blocked = fixture.run("occluded", &[], 0, &[out[0].view()]).unwrap();
        assert_eq!(blocked[0].view().as_bool(), &[true, false, false]);
    }

    #[test]
    fn a_normal_leaning_into_the_surface_does_not_start_the_ray_inside_it() {
        // A shading normal that leans below its triangle's plane (records from
        // interpolated normals can lean down to it, near silhouettes and creases):
        // offset along it, the ray started under the small square, which then
        // blocked the light it faces. It starts off the triangle's front instead.
        let mut fixture = Fixture::new();
        let light = PointLight::new(Vec3::new(5.0, 0.5, 1.0), 1.0);
        fixture.set_shading(|shading| shading.set_lights(vec![light]).unwrap());
        let epsilon = SURFACE_EPSILON * fixture.resources.scene.bounds.diagonal();
        let mut surface = surface_hit(Vec3::new(0.5, 0.5, 0.0), Vec3::new(1.0, 0.0, -0.2), 0);
        surface.normal = surface.normal.normalize();
        surface.geometric = Vec3::Z;
        let surfaces = fixture.surfaces(&[surface]);
        let out = fixture
            .run_grouped("shadowRay", &[], 1, 0, &[surfaces.view()])
            .unwrap();
        let rays = read_rays(&out[0]);
        assert!(rays[0].tmax > 0.0);
        assert_eq!(rays[0].origin, Vec3::new(0.5, 0.5, epsilon));
        let blocked = fixture.run("occluded", &[], 0, &[out[0].view()]).unwrap();
        assert_eq!(blocked[0].view().as_bool(), &[false]);
    }

    /// Runs of hits and of misses, several lights: each surface's rays are
    /// those it makes alone, at its place.
    #[test]
    fn rays_of_runs_of_hits_and_misses_land_at_their_surfaces_places() {
        let fixture = three_lights();
        let records: Vec<SurfaceRecord> = (0..11)
            .map(|index| match index % 5 {
                1 | 2 => SurfaceRecord::miss(index, Vec3::ONE, 1),
                _ => surface_hit(Vec3::new(0.1 * index as f32, 0.5, 0.0), Vec3::Z, index),
            })
            .collect();
        let run = |surfaces: &[SurfaceRecord]| {
            let column = fixture.surfaces(surfaces);
            let out = fixture.run_grouped("shadowRay", &[], 3, 0, &[column.view()]);
            read_rays(&out.unwrap()[0])
        };
        let alone: Vec<RayRecord> = records
            .iter()
            .flat_map(|record| run(std::slice::from_ref(record)))
            .collect();
        assert_eq!(run(&records), alone);
    }

    #[test]
    fn fanout_must_match_the_lights() {
        let fixture = Fixture::new();
        let surfaces = fixture.surfaces(&[surface_hit(Vec3::ZERO, Vec3::Z, 0)]);
        let error = fixture
            .run_grouped("shadowRay", &[], 3, 0, &[surfaces.view()])
            .unwrap_err();
        assert!(error.message.contains("2 lights"), "{error}");
    }
}
