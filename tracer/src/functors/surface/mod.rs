//! `surface(ray: Ray, hit: Hit) -> (surf: Surface)`: what shading needs of a hit.
//!
//! - `position`: the barycentric interpolation `(1-u-v) v0 + u v1 + v v2` of the
//!   hit triangle's corners (more precise than `origin + t dir`);
//! - `normal`: the barycentric interpolation of the vertex normals (from the file,
//!   or the smooth area-weighted ones the scene computed at load), normalised and
//!   turned to the side of the triangle the ray comes from (the side the
//!   geometric normal facing the ray points to); the face normal where the
//!   interpolation vanishes. Where it would face away from the viewer (or nearly
//!   so: `normal·view < MIN_VIEW_COSINE`, near silhouettes, where the
//!   interpolated normal leans past the triangle), it is bent towards `view`
//!   just far enough that `normal·view = MIN_VIEW_COSINE`;
//! - `view`: the unit vector from the point towards the ray origin (`-dir`);
//! - `scalar`: the barycentric interpolation of the per-vertex scalars;
//! - `material`: the triangle's material id;
//! - `geometric`: the triangle's unit normal on the ray's side (the view vector
//!   for a degenerate triangle): secondary rays start off the surface along it,
//!   and their directions are kept on its side.
//!
//! A miss gives `hit = false` and zeros except `sample`, `weight` and `depth`;
//! a dead ray (`tmax <= 0`) gives a miss with zero weight, so it shades to black.

use crate::functors::tracer_functor;
use crate::functors::wgsl::{
    f32_literal, mesh_module, request_resources, vector_module, TwinParts,
};
use crate::functors::{runs_of, HitColumns, RayColumns, SurfaceRecord, SurfaceWriter, MISS_PRIM};
use crate::prefetch::{prefetch, prefetch_hit_ahead};
use crate::scene::TraceResources;
use crate::vector::unit_or_zero;
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, RecordId, Signature,
};
use glam::Vec3;
use std::sync::Arc;

/// The least `normal·view` of a shading normal: the interpolated normal is bent
/// towards the viewer up to this, so no shading point faces away from the ray.
pub const MIN_VIEW_COSINE: f32 = 0.01;

pub fn functor(ray: RecordId, hit: RecordId, surface: RecordId) -> Arc<dyn Functor> {
    let signature = Signature::map("surface")
        .input("ray", ElemType::Record(ray))
        .input("hit", ElemType::Record(hit))
        .output("surf", ElemType::Record(surface))
        .doc("the shading point of a hit: position, interpolated normal facing the ray, view vector, interpolated scalar, material, geometric normal facing the ray (miss: hit = false)");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

/// `twin.wgsl`, reading the scene's triangles and vertices, built once per scene.
fn twin_parts(request: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    let scene = &request_resources::<TraceResources>(request, "surface")?.scene;
    // As `facing_the_viewer` computes it.
    let min_view_sine = (1.0 - MIN_VIEW_COSINE * MIN_VIEW_COSINE).sqrt();
    Ok(TwinParts {
        constants: vec![
            ("MISS_PRIM", format!("{MISS_PRIM}u")),
            ("MIN_VIEW_COSINE", f32_literal(MIN_VIEW_COSINE)),
            ("MIN_VIEW_SINE", f32_literal(min_view_sine)),
        ],
        modules: vec![vector_module(), mesh_module(scene.gpu_buffers())],
        failures: vec!["surface: a hit names a triangle the scene does not have".into()],
        ..TwinParts::default()
    })
}

fn run_cpu(
    ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let scene = &ctx.resources::<TraceResources>()?.scene;
    let mesh = &scene.mesh;
    let rays = RayColumns::new(&inputs[0]);
    let hits = HitColumns::new(&inputs[1]);
    let len = rays.len();
    // The same length for every column lets the loop drop its bounds checks.
    let (dirs, tmaxs, samples) = (&rays.dir[..len], &rays.tmax[..len], &rays.sample[..len]);
    let (weights, depths) = (&rays.weight[..len], &rays.depth[..len]);
    let (prims, us, vs) = (&hits.prim[..len], &hits.u[..len], &hits.v[..len]);
    let triangles = mesh.triangles.as_slice();
    let positions = mesh.positions.as_slice();
    let normals = mesh.normals.as_deref();
    let scalars = mesh.scalars.as_deref();
    let triangle_materials = scene.materials.triangle_materials.as_slice();
    // The triangle a live ray hit (none for a miss, a dead ray, or past the end).
    let live_prim = |index: usize| {
        let prim = *prims.get(index)?;
        (prim != MISS_PRIM && tmaxs[index] > 0.0).then_some(prim as usize)
    };
    // Every triangle a live ray hits must exist: checked up front, so that the
    // loop below cannot fail.
    let names_no_triangle =
        |index: usize| live_prim(index).is_some_and(|prim| prim >= triangles.len());
    if let Some(index) = (0..len).find(|&index| names_no_triangle(index)) {
        return Err(FunctorError::bad_input(format!(
            "surface: hit names triangle {}, but the scene has {} triangles",
            prims[index],
            triangles.len()
        )));
    }
    let prefetch_ahead = |index: usize| {
        prefetch_hit_ahead(index, live_prim, triangles, |prim, corners| {
            prefetch(triangle_materials, prim);
            for vertex in corners {
                prefetch(positions, vertex);
                normals.inspect(|normals| prefetch(normals, vertex));
                scalars.inspect(|scalars| prefetch(scalars, vertex));
            }
        })
    };
    // The surface a live ray hit.
    let hit_surface = |index: usize| {
        prefetch_ahead(index);
        let (sample, depth) = (samples[index], depths[index]);
        let prim = prims[index];
        let [a, b, c] = triangles[prim as usize].map(|vertex| vertex as usize);
        let (u, v) = (us[index], vs[index]);
        let w = 1.0 - u - v;
        let [p0, p1, p2] = [positions[a], positions[b], positions[c]];
        let position = w * p0 + u * p1 + v * p2;
        let dir = dirs[index];
        let view = -dir.normalize_or_zero();
        // The geometric normal on the ray's side (or the view vector for a
        // degenerate triangle, which a ray can hardly hit); as
        // `TriangleMesh::face_normal` computes it.
        let face = unit_or_zero((p1 - p0).cross(p2 - p0));
        let facing = if face == Vec3::ZERO {
            view
        } else if face.dot(dir) > 0.0 {
            -face
        } else {
            face
        };
        let interpolated = normals
            .map(|n| (w * n[a] + u * n[b] + v * n[c]).normalize_or_zero())
            .unwrap_or(Vec3::ZERO);
        let normal = if interpolated == Vec3::ZERO {
            facing
        } else if interpolated.dot(facing) < 0.0 {
            -interpolated
        } else {
            interpolated
        };
        let normal = facing_the_viewer(normal, view, facing);
        let scalar = scalars.map_or(position.y, |s| w * s[a] + u * s[b] + v * s[c]);
        SurfaceRecord {
            position,
            normal,
            view,
            scalar,
            // As `TraceScene::triangle_material`.
            material: triangle_materials.get(prim as usize).copied().unwrap_or(0),
            hit: true,
            sample,
            weight: weights[index],
            depth,
            geometric: facing,
        }
    };
    let mut out = SurfaceWriter::new(&mut outputs[0])?;
    for (live, run) in runs_of(len, |index| live_prim(index).is_some()) {
        if live {
            out.extend_with(run.len(), |offset| hit_surface(run.start + offset));
        } else {
            // Misses, a run at a time ([`SurfaceRecord::miss`]): a dead ray's
            // weight is zero, a live ray's is its own.
            let weights = run.clone().map(|index| {
                if tmaxs[index] > 0.0 {
                    weights[index]
                } else {
                    Vec3::ZERO
                }
            });
            out.extend_misses(&samples[run.clone()], weights, &depths[run]);
        }
    }
    Ok(())
}

/// `normal` unchanged where `normal·view >= MIN_VIEW_COSINE`; otherwise the unit
/// vector nearest to it with `normal·view = MIN_VIEW_COSINE` (it keeps its
/// component across the view direction and gets just enough along it). When the
/// normal is (anti)parallel to `view` there is no nearest one, and the geometric
/// normal, which faces the ray, is used.
#[inline]
pub(crate) fn facing_the_viewer(normal: Vec3, view: Vec3, geometric: Vec3) -> Vec3 {
    let cosine = normal.dot(view);
    if cosine >= MIN_VIEW_COSINE || view == Vec3::ZERO {
        return normal;
    }
    let across = (normal - cosine * view).normalize_or_zero();
    if across == Vec3::ZERO {
        return geometric;
    }
    let sine = (1.0 - MIN_VIEW_COSINE * MIN_VIEW_COSINE).sqrt();
    (sine * across + MIN_VIEW_COSINE * view).normalize()
}

#[cfg(test)]
mod tests {
    use super::{facing_the_viewer, MIN_VIEW_COSINE};
    use crate::functors::test_support::{probe_rays, ray, read_surfaces, Fixture};
    use crate::functors::{RayRecord, SurfaceRecord, MISS_PRIM};
    use crate::mesh::TriangleMesh;
    use crate::scene::TraceScene;
    use crate::shading::{Material, MeshMaterials};
    use glam::Vec3;

    /// One triangle with distinct vertex normals and scalars, and a second one
    /// using material 1.
    fn fixture() -> Fixture {
        let mesh = TriangleMesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(5.0, 5.0, 0.0)],
            triangles: vec![[0, 1, 2], [1, 3, 2]],
            normals: Some(vec![
                Vec3::Z,
                Vec3::new(1.0, 0.0, 1.0).normalize(),
                Vec3::new(0.0, 1.0, 1.0).normalize(),
                Vec3::Z,
            ]),
            scalars: Some(vec![0.0, 10.0, 20.0, 30.0]),
        };
        let materials = MeshMaterials {
            materials: vec![Material::named("default"), Material::named("other")],
            triangle_materials: vec![0, 1],
        };
        Fixture::with_scene(TraceScene::with_materials(mesh, materials).unwrap())
    }

    #[test]
    fn interpolates_position_normal_and_scalar() {
        let fixture = fixture();
        let (u, v) = (0.25, 0.5);
        let expected_normal = (0.25 * Vec3::Z
            + 0.25 * Vec3::new(1.0, 0.0, 1.0).normalize()
            + 0.5 * Vec3::new(0.0, 1.0, 1.0).normalize())
        .normalize();
        let mut from_above = ray(Vec3::new(0.25, 0.5, 2.0), Vec3::new(0.0, 0.0, -2.0), 9.0, 7);
        from_above.weight = Vec3::new(0.5, 0.25, 1.0);
        from_above.depth = 2;
        let from_below = ray(Vec3::new(0.25, 0.5, -1.0), Vec3::Z, 9.0, 8);
        let rays = fixture.rays(&[from_above, from_below]);
        let hit = fixture.hits(&[(1.0, 0, u, v), (1.0, 0, u, v)]);
        let out = fixture
            .run("surface", &[], 0, &[rays.view(), hit.view()])
            .unwrap();
        assert_eq!(out[0].elem_type(), fixture.record("Surface"));
        let surfaces = read_surfaces(&out[0]);
        let above = surfaces[0];
        assert!((above.position - Vec3::new(0.25, 0.5, 0.0)).length() < 1e-6);
        assert!((above.normal - expected_normal).length() < 1e-6);
        assert_eq!(above.geometric, Vec3::Z);
        assert_eq!(above.view, Vec3::Z);
        assert!((above.scalar - 12.5).abs() < 1e-5);
        assert!(above.hit);
        assert_eq!(
            (above.material, above.sample, above.weight, above.depth),
            (0, 7, Vec3::new(0.5, 0.25, 1.0), 2)
        );
        // From below, the normal is turned towards the ray.
        let below = surfaces[1];
        assert!((below.normal + expected_normal).length() < 1e-6);
        assert_eq!(below.geometric, Vec3::NEG_Z);
        assert_eq!(below.view, Vec3::NEG_Z);
        assert!((below.scalar - 12.5).abs() < 1e-5);
        assert_eq!((below.sample, below.weight), (8, Vec3::ONE));
    }

    #[test]
    fn a_normal_facing_away_from_the_viewer_is_bent_towards_it() {
        // Vertex normals leaning 60 degrees towards +x over a triangle in z = 0,
        // seen at a grazing angle from -x: the interpolated normal faces away
        // from the viewer (n·v < 0), where Blinn-Phong is meaningless.
        let lean = Vec3::new(3f32.sqrt() / 2.0, 0.0, 0.5);
        let mesh = TriangleMesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            triangles: vec![[0, 1, 2]],
            normals: Some(vec![lean; 3]),
            scalars: None,
        };
        let fixture = Fixture::with_scene(TraceScene::new(mesh).unwrap());
        let target = Vec3::new(0.25, 0.25, 0.0);
        let dir = Vec3::new(1.0, 0.0, -0.2).normalize();
        let rays = fixture.rays(&[ray(target - 2.0 * dir, dir, 9.0, 0)]);
        let hit = fixture.run("intersect", &[], 0, &[rays.view()]).unwrap();
        let out = fixture
            .run("surface", &[], 0, &[rays.view(), hit[0].view()])
            .unwrap();
        let surface = read_surfaces(&out[0])[0];
        assert!(surface.hit);
        assert!(lean.dot(surface.view) < 0.0);
        assert_eq!(surface.geometric, Vec3::Z);
        let cosine = surface.normal.dot(surface.view);
        assert!((cosine - MIN_VIEW_COSINE).abs() < 1e-5, "{cosine}");
        assert!((surface.normal.length() - 1.0).abs() < 1e-5);
        // Bent within the plane of the normal and the view vector, and still on
        // the triangle's front.
        assert!(surface.normal.y.abs() < 1e-6 && surface.normal.z > 0.0);
        // A normal the viewer sees is left alone.
        let n = Vec3::new(0.6, 0.0, 0.8);
        assert_eq!(facing_the_viewer(n, Vec3::Z, Vec3::Z), n);
        assert_eq!(facing_the_viewer(Vec3::NEG_Z, Vec3::Z, Vec3::Z), Vec3::Z);
    }

    #[test]
    fn material_misses_and_dead_rays() {
        let fixture = fixture();
        let mut reflected = ray(Vec3::new(3.0, 3.0, 1.0), Vec3::NEG_Z, 9.0, 1);
        reflected.weight = Vec3::splat(0.5);
        reflected.depth = 1;
        let dead = RayRecord::dead(3, 2);
        // A hit, then a run of a miss and a dead ray, then a hit again.
        let rays = fixture.rays(&[
            ray(Vec3::new(3.0, 3.0, 1.0), Vec3::NEG_Z, 9.0, 0),
            reflected,
            dead,
            ray(Vec3::new(3.0, 3.0, 1.0), Vec3::NEG_Z, 9.0, 4),
        ]);
        let hit = fixture.hits(&[
            (1.0, 1, 0.2, 0.2),
            (f32::INFINITY, MISS_PRIM, 0.0, 0.0),
            (f32::INFINITY, MISS_PRIM, 0.0, 0.0),
            (1.0, 1, 0.2, 0.2),
        ]);
        let out = fixture
            .run("surface", &[], 0, &[rays.view(), hit.view()])
            .unwrap();
        let surfaces = read_surfaces(&out[0]);
        assert_eq!(surfaces[0].material, 1);
        assert!(surfaces[0].normal.z > 0.0 && surfaces[0].hit);
        assert_eq!(surfaces[1], SurfaceRecord::miss(1, Vec3::splat(0.5), 1));
        assert!(!surfaces[1].hit);
        assert_eq!(surfaces[2], SurfaceRecord::miss(3, Vec3::ZERO, 2));
        assert_eq!(
            surfaces[3],
            SurfaceRecord {
                sample: 4,
                ..surfaces[0]
            }
        );
    }

    #[test]
    fn traced_hits_of_the_default_fixture() {
        // Smooth normals of flat squares are +z; scalars default to y.
        let fixture = Fixture::new();
        let rays = probe_rays(&fixture);
        let hit = fixture.run("intersect", &[], 0, &[rays.view()]).unwrap();
        let out = fixture
            .run("surface", &[], 0, &[rays.view(), hit[0].view()])
            .unwrap();
        let surfaces = read_surfaces(&out[0]);
        assert_eq!(
            surfaces.iter().map(|s| s.hit).collect::<Vec<_>>(),
            [true, true, false, false]
        );
        assert!((surfaces[0].position - Vec3::new(0.25, 0.5, 0.0)).length() < 1e-6);
        assert!((surfaces[0].scalar - 0.5).abs() < 1e-6);
        assert_eq!(surfaces[0].normal, Vec3::Z);
        assert_eq!(surfaces[0].geometric, Vec3::Z);
        assert!((surfaces[1].position - Vec3::new(3.0, 0.0, -1.0)).length() < 1e-6);
    }

    #[test]
    fn unknown_triangle_is_an_error() {
        let fixture = fixture();
        let rays = fixture.rays(&[ray(Vec3::Z, Vec3::NEG_Z, 9.0, 0)]);
        let hit = fixture.hits(&[(1.0, 5, 0.0, 0.0)]);
        let error = fixture
            .run("surface", &[], 0, &[rays.view(), hit.view()])
            .unwrap_err();
        assert!(error.message.contains("triangle 5"), "{error}");
    }
}
