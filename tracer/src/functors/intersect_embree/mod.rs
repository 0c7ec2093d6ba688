//! The Embree engine (feature `embree`): an alternative `intersect` functor that
//! asks Embree 3 for the closest hits, as the paper compared against Embree.
//!
//! The pipeline does not change: the same `map<intersect>` stage runs over the
//! same chunks of rays, and only the functor behind the name `intersect` is
//! swapped ([`library_with_embree`]). The hits mean the same as our CPU's: `t`,
//! the triangle in file order (Embree's `primID`, since the index buffer is the
//! mesh's triangles in file order), and the barycentrics `u` of `v1` and `v` of
//! `v2`; dead rays (`tmax <= 0`, or NaN) miss without a query. Embree counts hits
//! with `0 <= t <= tmax` where our traversal takes `0 < t < tmax`: the two differ
//! only for a hit exactly at either end.
//!
//! Two modes: [`EmbreeMode::Single`] calls `rtcIntersect1` once per ray (the
//! paper's single-ray comparison), [`EmbreeMode::Packet16`] hands Embree 16 rays
//! at a time through `rtcIntersect16` (its packet mode; dead rays are masked out).

use crate::functors::{hit_fields, record_fields_mut, RayColumns};
use crate::mesh::{MeshError, TriangleMesh};
use dpp_runtime::{
    CallContext, Column, ColumnView, Functor, FunctorError, FunctorLibrary, Signature,
};
use embree3::{
    BufferUsage, Device, Format, GeometryKind, Hit16, IntersectContext, Ray, Ray16, RayHit,
    RayHit16, Scene, SceneFlags, SoAHit, SoARay, ValidMask, ValidMaskN, INVALID_ID,
};
use std::sync::Arc;
use std::time::{Duration, Instant};
use thiserror::Error;

#[derive(Debug, Error)]
pub enum EmbreeError {
    #[error("Embree: {0}")]
    Embree(String),
    #[error("invalid mesh: {0}")]
    Mesh(#[from] MeshError),
}

/// How the functor queries Embree.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EmbreeMode {
    /// `rtcIntersect1`, one ray at a time.
    Single,
    /// `rtcIntersect16`, packets of 16 rays.
    Packet16,
}

impl EmbreeMode {
    pub fn name(self) -> &'static str {
        match self {
            EmbreeMode::Single => "single",
            EmbreeMode::Packet16 => "packet",
        }
    }
}

/// A committed Embree scene of one triangle mesh (geometry 0), built once per
/// scene and shared by every frame.
pub struct EmbreeScene {
    scene: Scene<'static>,
    /// How long building Embree's BVH (`rtcCommitScene`) and copying the mesh took.
    pub build_time: Duration,
}

impl std::fmt::Debug for EmbreeScene {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EmbreeScene")
            .field("build_time", &self.build_time)
            .finish_non_exhaustive()
    }
}

impl EmbreeScene {
    /// Copies the mesh into Embree's buffers and builds its BVH (default quality).
    pub fn build(mesh: &TriangleMesh) -> Result<EmbreeScene, EmbreeError> {
        mesh.validate()?;
        let failed = |what: &str, error: embree3::Error| {
            EmbreeError::Embree(format!("{what} failed ({error:?})"))
        };
        let start = Instant::now();
        let device = Device::new().map_err(|e| failed("creating a device", e))?;
        let mut geometry = device
            .create_geometry(GeometryKind::TRIANGLE)
            .map_err(|e| failed("creating a triangle geometry", e))?;
        geometry
            .set_new_buffer::<[f32; 3]>(
                BufferUsage::VERTEX,
                0,
                Format::FLOAT3,
                12,
                mesh.positions.len(),
            )
            .map_err(|e| failed("allocating the vertex buffer", e))?
            .iter_mut()
            .zip(&mesh.positions)
            .for_each(|(slot, p)| *slot = p.to_array());
        geometry
            .set_new_buffer::<[u32; 3]>(
                BufferUsage::INDEX,
                0,
                Format::UINT3,
                12,
                mesh.triangles.len(),
            )
            .map_err(|e| failed("allocating the index buffer", e))?
            .copy_from_slice(&mesh.triangles);
        let geometry = geometry.commit();
        let mut scene = device
            .create_scene()
            .map_err(|e| failed("creating a scene", e))?;
        // Robust mode: a watertight triangle test like ours, so that no ray slips
        // between two triangles that share an edge (the default test lets a few
        // through, and then the engines' hit counts differ).
        scene.set_flags(SceneFlags::ROBUST);
        scene.attach_geometry(&geometry);
        scene.commit();
        Ok(EmbreeScene {
            scene,
            build_time: start.elapsed(),
        })
    }
}

/// `intersect` through Embree; see the module documentation.
pub struct EmbreeIntersect {
    signature: Signature,
    scene: Arc<EmbreeScene>,
    mode: EmbreeMode,
}

impl EmbreeIntersect {
    /// `signature` is the CPU `intersect`'s, so pipelines type-check the same.
    pub fn new(signature: Signature, scene: Arc<EmbreeScene>, mode: EmbreeMode) -> EmbreeIntersect {
        EmbreeIntersect {
            signature,
            scene,
            mode,
        }
    }
}

/// Embree's ray for one of ours (`tnear` 0, `tfar` our `tmax`).
#[inline]
fn embree_ray(rays: &RayColumns<'_>, index: usize) -> Ray {
    Ray::segment(
        rays.origin[index].to_array(),
        rays.dir[index].to_array(),
        0.0,
        rays.tmax[index],
    )
}

impl Functor for EmbreeIntersect {
    fn signature(&self) -> &Signature {
        &self.signature
    }

    fn run_cpu(
        &self,
        _ctx: &CallContext<'_>,
        inputs: &[ColumnView<'_>],
        outputs: &mut [Column],
    ) -> Result<(), FunctorError> {
        let rays = RayColumns::new(&inputs[0]);
        let n = rays.len();
        let [t, prim, u, v] = record_fields_mut::<4>(&mut outputs[0])?;
        let (t, prim, u, v) = (
            t.as_f32_mut(),
            prim.as_u32_mut(),
            u.as_f32_mut(),
            v.as_f32_mut(),
        );
        t.reserve(n);
        prim.reserve(n);
        u.reserve(n);
        v.reserve(n);
        let scene = &self.scene.scene;
        let mut context = IntersectContext::coherent();
        let mut push = |hit: Option<crate::bvh::HitRecord>| {
            let (hit_t, hit_prim, hit_u, hit_v) = hit_fields(hit);
            t.push(hit_t);
            prim.push(hit_prim);
            u.push(hit_u);
            v.push(hit_v);
        };
        match self.mode {
            EmbreeMode::Single => {
                for index in 0..n {
                    let hit = if rays.tmax[index] > 0.0 {
                        let mut ray_hit = RayHit::from_ray(embree_ray(&rays, index));
                        scene.intersect(&mut context, &mut ray_hit);
                        (ray_hit.hit.geomID != INVALID_ID).then_some(crate::bvh::HitRecord {
                            t: ray_hit.ray.tfar,
                            prim: ray_hit.hit.primID,
                            u: ray_hit.hit.u,
                            v: ray_hit.hit.v,
                        })
                    } else {
                        None
                    };
                    push(hit);
                }
            }
            EmbreeMode::Packet16 => {
                let mut packet = RayHit16 {
                    ray: Ray16::empty(),
                    hit: Hit16::new(),
                };
                for start in (0..n).step_by(16) {
                    let lanes = (n - start).min(16);
                    let mut valid = ValidMaskN::<16>::new([ValidMask::Invalid; 16]);
                    for lane in 0..16 {
                        packet.hit.geomID[lane] = INVALID_ID;
                        packet.hit.primID[lane] = INVALID_ID;
                        if lane >= lanes {
                            continue;
                        }
                        let index = start + lane;
                        let ray = &mut packet.ray;
                        ray.set_org(lane, rays.origin[index].to_array());
                        ray.set_dir(lane, rays.dir[index].to_array());
                        ray.set_tnear(lane, 0.0);
                        ray.set_tfar(lane, rays.tmax[index]);
                        ray.set_time(lane, 0.0);
                        ray.set_mask(lane, u32::MAX);
                        ray.set_flags(lane, 0);
                        if rays.tmax[index] > 0.0 {
                            valid.lanes_mut()[lane] = ValidMask::Valid;
                        }
                    }
                    scene.intersect16(&mut context, &mut packet, &valid);
                    for lane in 0..lanes {
                        let hit = (packet.hit.geomID[lane] != INVALID_ID).then(|| {
                            crate::bvh::HitRecord {
                                t: packet.ray.tfar(lane),
                                prim: packet.hit.primID[lane],
                                u: packet.hit.u(lane),
                                v: packet.hit.v(lane),
                            }
                        });
                        push(hit);
                    }
                }
            }
        }
        Ok(())
    }
}

/// A copy of `library` in which `intersect` is answered by Embree (every other
/// functor, record and uniform is the same).
pub fn library_with_embree(
    library: &FunctorLibrary,
    scene: Arc<EmbreeScene>,
    mode: EmbreeMode,
) -> Result<FunctorLibrary, FunctorError> {
    let intersect = library.get("intersect").ok_or_else(|| {
        FunctorError("the library has no `intersect` functor to replace".to_string())
    })?;
    let embree: Arc<dyn Functor> = Arc::new(EmbreeIntersect::new(
        intersect.signature().clone(),
        scene,
        mode,
    ));
    let mut swapped = FunctorLibrary::default();
    swapped.records = library.records.clone();
    swapped.uniforms = library.uniforms.clone();
    for functor in library.iter() {
        if functor.signature().name == "intersect" {
            swapped.register(embree.clone());
        } else {
            swapped.register(functor.clone());
        }
    }
    Ok(swapped)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::functors::test_support::{probe_rays, read_rays, Fixture};
    use crate::functors::MISS_PRIM;

    /// Runs `intersect` of `library` on `rays` in the fixture's context.
    fn hits(fixture: &Fixture, library: &FunctorLibrary, rays: &Column) -> Vec<Vec<f32>> {
        let functor = library.get("intersect").unwrap();
        let ctx = CallContext {
            named: &[],
            uniforms: &fixture.uniforms,
            resources: &fixture.resources,
            first_index: 0,
            group: 1,
            records: &library.records,
        };
        let mut outputs = vec![Column::with_capacity(
            fixture.record("Hit"),
            0,
            &library.records,
        )];
        functor.run_cpu(&ctx, &[rays.view()], &mut outputs).unwrap();
        let view = outputs[0].view();
        vec![
            view.field(0).as_f32().to_vec(),
            view.field(1).as_u32().iter().map(|&p| p as f32).collect(),
            view.field(2).as_f32().to_vec(),
            view.field(3).as_f32().to_vec(),
        ]
    }

    #[test]
    fn embree_hits_mean_what_the_cpu_hits_mean() {
        let fixture = Fixture::new();
        let scene = Arc::new(EmbreeScene::build(&fixture.resources.scene.mesh).unwrap());
        // Enough rays for a full packet, a partial one, and dead rays among them.
        let mut rays = read_rays(&probe_rays(&fixture));
        rays = rays.iter().cycle().take(37).copied().collect();
        rays[5].tmax = 0.0;
        rays[9].tmax = -1.0;
        rays[17].tmax = f32::NAN;
        let rays = fixture.rays(&rays);
        let expected = hits(&fixture, &fixture.library, &rays);
        assert!(expected[1].contains(&(MISS_PRIM as f32)));
        for mode in [EmbreeMode::Single, EmbreeMode::Packet16] {
            let library = library_with_embree(&fixture.library, scene.clone(), mode).unwrap();
            let got = hits(&fixture, &library, &rays);
            assert_eq!(got[1], expected[1], "{mode:?}: triangle ids");
            for field in [0, 2, 3] {
                for (a, b) in got[field].iter().zip(&expected[field]) {
                    assert!(a == b || (a - b).abs() < 1e-5, "{mode:?}: {a} vs {b}");
                }
            }
        }
    }

    #[test]
    fn the_swapped_library_keeps_every_other_functor() {
        let fixture = Fixture::new();
        let scene = Arc::new(EmbreeScene::build(&fixture.resources.scene.mesh).unwrap());
        let library = library_with_embree(&fixture.library, scene, EmbreeMode::Single).unwrap();
        let names = |l: &FunctorLibrary| l.names().collect::<Vec<_>>();
        assert_eq!(names(&library), names(&fixture.library));
        assert_eq!(
            library.get("intersect").unwrap().signature(),
            fixture.library.get("intersect").unwrap().signature()
        );
    }
}
