//! `surface(ray: Ray, hit: Hit) -> (surf: Surface)`: what shading needs of a hit.
//!
//! - `position`: the barycentric interpolation `(1-u-v) v0 + u v1 + v v2` of the
//!   hit triangle's corners (more precise than `origin + t dir`);
//! - `normal`: the barycentric interpolation of the vertex normals (from the file,
//!   or the smooth area-weighted ones the scene computed at load), normalised and
//!   turned to the side of the triangle the ray comes from (the side the
//!   geometric normal facing the ray points to); the face normal where the
//!   interpolation vanishes;
//! - `view`: the unit vector from the point towards the ray origin (`-dir`);
//! - `scalar`: the barycentric interpolation of the per-vertex scalars;
//! - `material`: the triangle's material id.
//!
//! A miss gives `hit = false` and zeros except `sample`, `weight` and `depth`;
//! a dead ray (`tmax <= 0`) gives a miss with zero weight, so it shades to black.

use crate::functors::{HitColumns, RayColumns, SurfaceRecord, SurfaceWriter, MISS_PRIM};
use crate::scene::TraceResources;
use dpp_runtime::{
    ArrayParam, CallContext, Column, ColumnView, ElemType, Functor, FunctorError, FunctorKind,
    RecordId, Signature, TypePattern,
};
use glam::Vec3;

pub struct SurfaceFunctor {
    signature: Signature,
}

impl SurfaceFunctor {
    pub fn new(ray: RecordId, hit: RecordId, surface: RecordId) -> SurfaceFunctor {
        SurfaceFunctor {
            signature: Signature {
                name: "surface",
                kind: FunctorKind::Map,
                inputs: vec![
                    ArrayParam {
                        name: "ray",
                        ty: TypePattern::Exact(ElemType::Record(ray)),
                    },
                    ArrayParam {
                        name: "hit",
                        ty: TypePattern::Exact(ElemType::Record(hit)),
                    },
                ],
                outputs: vec![ArrayParam {
                    name: "surf",
                    ty: TypePattern::Exact(ElemType::Record(surface)),
                }],
                named: vec![],
                doc: "the shading point of a hit: position, interpolated normal facing the ray, view vector, interpolated scalar, material (miss: hit = false)",
            },
        }
    }
}

impl Functor for SurfaceFunctor {
    fn signature(&self) -> &Signature {
        &self.signature
    }

    fn run_cpu(
        &self,
        ctx: &CallContext<'_>,
        inputs: &[ColumnView<'_>],
        outputs: &mut [Column],
    ) -> Result<(), FunctorError> {
        let scene = &ctx.resources::<TraceResources>()?.scene;
        let mesh = &scene.mesh;
        let rays = RayColumns::new(&inputs[0]);
        let hits = HitColumns::new(&inputs[1]);
        let normals = mesh.normals.as_deref();
        let scalars = mesh.scalars.as_deref();
        let mut out = SurfaceWriter::new(&mut outputs[0], rays.len())?;
        for index in 0..rays.len() {
            let (sample, depth) = (rays.sample[index], rays.depth[index]);
            let alive = rays.tmax[index] > 0.0;
            if !alive {
                out.push(SurfaceRecord::miss(sample, Vec3::ZERO, depth));
                continue;
            }
            let prim = hits.prim[index];
            if prim == MISS_PRIM {
                out.push(SurfaceRecord::miss(sample, rays.weight[index], depth));
                continue;
            }
            let Some(&[a, b, c]) = mesh.triangles.get(prim as usize) else {
                return Err(FunctorError(format!(
                    "surface: hit names triangle {prim}, but the scene has {} triangles",
                    mesh.triangles.len()
                )));
            };
            let [a, b, c] = [a as usize, b as usize, c as usize];
            let (u, v) = (hits.u[index], hits.v[index]);
            let w = 1.0 - u - v;
            let position = w * mesh.positions[a] + u * mesh.positions[b] + v * mesh.positions[c];
            let dir = rays.dir[index];
            let view = -dir.normalize_or_zero();
            // The geometric normal on the ray's side (or the view vector for a
            // degenerate triangle, which a ray can hardly hit).
            let face = mesh.face_normal(prim as usize).normalize_or_zero();
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
            let scalar = scalars.map_or(position.y, |s| w * s[a] + u * s[b] + v * s[c]);
            out.push(SurfaceRecord {
                position,
                normal,
                view,
                scalar,
                material: scene.triangle_material(prim),
                hit: true,
                sample,
                weight: rays.weight[index],
                depth,
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use crate::functors::test_support::{probe_rays, ray, read_surfaces, Fixture};
    use crate::functors::{RayRecord, SurfaceRecord, MISS_PRIM};
    use crate::mesh::TriangleMesh;
    use crate::scene::TraceScene;
    use crate::shading::{Material, MeshMaterials};
    use dpp_runtime::{Column, ElemType};
    use glam::Vec3;
    use std::sync::Arc;

    fn hits(fixture: &Fixture, hits: &[(f32, u32, f32, f32)]) -> Column {
        let ElemType::Record(ty) = fixture.record("Hit") else {
            unreachable!("Hit is a record")
        };
        Column::Record {
            ty,
            fields: vec![
                Arc::new(Column::F32(hits.iter().map(|h| h.0).collect())),
                Arc::new(Column::U32(hits.iter().map(|h| h.1).collect())),
                Arc::new(Column::F32(hits.iter().map(|h| h.2).collect())),
                Arc::new(Column::F32(hits.iter().map(|h| h.3).collect())),
            ],
        }
    }

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
        let hit = hits(&fixture, &[(1.0, 0, u, v), (1.0, 0, u, v)]);
        let out = fixture
            .run("surface", &[], 0, &[rays.view(), hit.view()])
            .unwrap();
        assert_eq!(out[0].elem_type(), fixture.record("Surface"));
        let surfaces = read_surfaces(&out[0]);
        let above = surfaces[0];
        assert!((above.position - Vec3::new(0.25, 0.5, 0.0)).length() < 1e-6);
        assert!((above.normal - expected_normal).length() < 1e-6);
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
        assert_eq!(below.view, Vec3::NEG_Z);
        assert!((below.scalar - 12.5).abs() < 1e-5);
        assert_eq!((below.sample, below.weight), (8, Vec3::ONE));
    }

    #[test]
    fn material_misses_and_dead_rays() {
        let fixture = fixture();
        let mut reflected = ray(Vec3::new(3.0, 3.0, 1.0), Vec3::NEG_Z, 9.0, 1);
        reflected.weight = Vec3::splat(0.5);
        reflected.depth = 1;
        let dead = RayRecord::dead(3, 2);
        let rays = fixture.rays(&[
            ray(Vec3::new(3.0, 3.0, 1.0), Vec3::NEG_Z, 9.0, 0),
            reflected,
            dead,
        ]);
        let hit = hits(
            &fixture,
            &[
                (1.0, 1, 0.2, 0.2),
                (f32::INFINITY, MISS_PRIM, 0.0, 0.0),
                (f32::INFINITY, MISS_PRIM, 0.0, 0.0),
            ],
        );
        let out = fixture
            .run("surface", &[], 0, &[rays.view(), hit.view()])
            .unwrap();
        let surfaces = read_surfaces(&out[0]);
        assert_eq!(surfaces[0].material, 1);
        assert!(surfaces[0].normal.z > 0.0 && surfaces[0].hit);
        assert_eq!(surfaces[1], SurfaceRecord::miss(1, Vec3::splat(0.5), 1));
        assert!(!surfaces[1].hit);
        assert_eq!(surfaces[2], SurfaceRecord::miss(3, Vec3::ZERO, 2));
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
        assert!((surfaces[1].position - Vec3::new(3.0, 0.0, -1.0)).length() < 1e-6);
    }

    #[test]
    fn unknown_triangle_is_an_error() {
        let fixture = fixture();
        let rays = fixture.rays(&[ray(Vec3::Z, Vec3::NEG_Z, 9.0, 0)]);
        let hit = hits(&fixture, &[(1.0, 5, 0.0, 0.0)]);
        let error = fixture
            .run("surface", &[], 0, &[rays.view(), hit.view()])
            .unwrap_err();
        assert!(error.0.contains("triangle 5"), "{error}");
    }
}
