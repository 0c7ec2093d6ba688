//! The Embree engine (feature `embree`): alternative `intersect` and `occluded`
//! functors that ask Embree 3 for the closest hits and for any hit, as the
//! paper compared against Embree.
//!
//! The pipeline does not change: the same `map<intersect>` and `map<occluded>`
//! stages run over the same chunks of rays, and only the functors behind those
//! names are swapped ([`library_with_embree`]). The hits mean the same as our CPU's: `t`,
//! the triangle in file order (Embree's `primID`, since the index buffer is the
//! mesh's triangles in file order), and the barycentrics `u` of `v1` and `v` of
//! `v2`; dead rays (`tmax <= 0`, or NaN) miss without a query. Embree counts hits
//! with `0 <= t <= tmax` where our traversal takes `0 < t < tmax`: the two differ
//! only for a hit exactly at either end.
//!
//! `occluded` is `rtcOccluded1`/`rtcOccluded16` on the segment `0 ..= tmax`,
//! where ours is blocked by a hit with `0 < t < tmax`.
//!
//! Two modes: [`EmbreeMode::Single`] calls `rtcIntersect1` (`rtcOccluded1`) once
//! per ray (the paper's single-ray comparison), [`EmbreeMode::Packet16`] hands
//! Embree 16 rays at a time through `rtcIntersect16` (`rtcOccluded16`), its
//! packet mode; dead rays are masked out.

use crate::functors::{write_hits, RayColumns};
use crate::mesh::{MeshError, TriangleMesh};
use dpp_runtime::{ClosureFunctor, Column, ColumnView, Functor, FunctorError, FunctorLibrary};
use embree3::{
    BufferUsage, BuildQuality, Device, Format, GeometryKind, Hit16, IntersectContext, Ray, Ray16,
    RayHit, RayHit16, Scene, SceneFlags, SoAHit, SoARay, ValidMask, ValidMaskN, INVALID_ID,
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

/// The quality of Embree's BVH build (`rtcSetSceneBuildQuality`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EmbreeQuality {
    /// `RTC_BUILD_QUALITY_MEDIUM`, Embree's default.
    Default,
    /// `RTC_BUILD_QUALITY_HIGH`: a slower build of a faster BVH.
    High,
}

impl EmbreeScene {
    /// Copies the mesh into Embree's buffers and builds its BVH (default
    /// quality). `robust`: Embree's watertight triangle test
    /// (`RTC_SCENE_FLAG_ROBUST`), like ours; otherwise its default, faster
    /// test, which lets a few rays through the edges two triangles share.
    pub fn build(mesh: &TriangleMesh, robust: bool) -> Result<EmbreeScene, EmbreeError> {
        EmbreeScene::build_at(mesh, robust, EmbreeQuality::Default)
    }

    /// [`EmbreeScene::build`] at the given build quality.
    pub fn build_at(
        mesh: &TriangleMesh,
        robust: bool,
        quality: EmbreeQuality,
    ) -> Result<EmbreeScene, EmbreeError> {
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
        if robust {
            scene.set_flags(SceneFlags::ROBUST);
        }
        if quality == EmbreeQuality::High {
            scene.set_build_quality(BuildQuality::HIGH);
        }
        scene.attach_geometry(&geometry);
        scene.commit();
        Ok(EmbreeScene {
            scene,
            build_time: start.elapsed(),
        })
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

/// The packets of 16 rays that `n` rays make: each one's first ray and length.
fn packets(n: usize) -> impl Iterator<Item = (usize, usize)> {
    (0..n)
        .step_by(16)
        .map(move |start| (start, (n - start).min(16)))
}

/// Rays `start .. start + lanes` into the first lanes of `packet`; the mask
/// of the live ones (`tmax > 0`), or `None` where none is live: such a
/// packet is answered without asking Embree (as dpp's traversal answers
/// dead rays without a traversal), which is what a harness of one's own
/// would do with a run of misses' dead rays.
fn load_packet(
    packet: &mut Ray16,
    rays: &RayColumns<'_>,
    start: usize,
    lanes: usize,
) -> Option<ValidMaskN<16>> {
    let mut valid = ValidMaskN::<16>::new([ValidMask::Invalid; 16]);
    let mut any_live = false;
    for lane in 0..lanes {
        let index = start + lane;
        packet.set_org(lane, rays.origin[index].to_array());
        packet.set_dir(lane, rays.dir[index].to_array());
        packet.set_tnear(lane, 0.0);
        packet.set_tfar(lane, rays.tmax[index]);
        packet.set_time(lane, 0.0);
        packet.set_mask(lane, u32::MAX);
        packet.set_flags(lane, 0);
        if rays.tmax[index] > 0.0 {
            valid.lanes_mut()[lane] = ValidMask::Valid;
            any_live = true;
        }
    }
    any_live.then_some(valid)
}

/// `intersect` through Embree; see the module documentation.
fn intersect(
    scene: &EmbreeScene,
    mode: EmbreeMode,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let rays = RayColumns::new(&inputs[0]);
    let n = rays.len();
    let scene = &scene.scene;
    let mut context = IntersectContext::coherent();
    // SAFETY: both modes write every index below `n`.
    unsafe {
        write_hits(&mut outputs[0], n, |mut hits| match mode {
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
                    hits.write(index, hit);
                }
            }
            EmbreeMode::Packet16 => {
                let mut packet = RayHit16 {
                    ray: Ray16::empty(),
                    hit: Hit16::new(),
                };
                for (start, lanes) in packets(n) {
                    packet.hit.geomID = [INVALID_ID; 16];
                    packet.hit.primID = [INVALID_ID; 16];
                    if let Some(valid) = load_packet(&mut packet.ray, &rays, start, lanes) {
                        scene.intersect16(&mut context, &mut packet, &valid);
                    }
                    // A packet's hits at a time, as dpp's traversal writes them.
                    let packet_hits = (0..lanes).map(|lane| {
                        (packet.hit.geomID[lane] != INVALID_ID).then(|| crate::bvh::HitRecord {
                            t: packet.ray.tfar(lane),
                            prim: packet.hit.primID[lane],
                            u: packet.hit.u(lane),
                            v: packet.hit.v(lane),
                        })
                    });
                    hits.write_from(start, packet_hits);
                }
            }
        })
    }
}

/// `occluded` through Embree; see the module documentation.
fn occluded(
    scene: &EmbreeScene,
    mode: EmbreeMode,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let rays = RayColumns::new(&inputs[0]);
    let n = rays.len();
    let blocked = outputs[0].as_bool_mut();
    blocked.reserve(n);
    let scene = &scene.scene;
    // Shadow and occlusion rays leave from many points: not coherent.
    let mut context = IntersectContext::incoherent();
    match mode {
        EmbreeMode::Single => {
            for index in 0..n {
                blocked.push(
                    rays.tmax[index] > 0.0
                        && scene.occluded(&mut context, &mut embree_ray(&rays, index)),
                );
            }
        }
        EmbreeMode::Packet16 => {
            let mut packet = Ray16::empty();
            for (start, lanes) in packets(n) {
                if let Some(valid) = load_packet(&mut packet, &rays, start, lanes) {
                    scene.occluded16(&mut context, &mut packet, &valid);
                }
                // Embree marks a blocked ray by setting its `tfar` to -inf (a
                // dead ray's own `tmax` may be -inf: it is never blocked).
                blocked.extend((0..lanes).map(|lane| {
                    rays.tmax[start + lane] > 0.0 && packet.tfar(lane) == f32::NEG_INFINITY
                }));
            }
        }
    }
    Ok(())
}

/// A copy of `library` in which `intersect` and `occluded` are answered by
/// Embree (every other functor, record and uniform is the same).
pub fn library_with_embree(
    library: &FunctorLibrary,
    scene: Arc<EmbreeScene>,
    mode: EmbreeMode,
) -> Result<FunctorLibrary, FunctorError> {
    let signature = |name: &str| {
        library
            .get(name)
            .map(|functor| functor.signature().clone())
            .ok_or_else(|| {
                FunctorError::bad_input(format!("the library has no `{name}` functor to replace"))
            })
    };
    // `signature` is the CPU functor's, so that pipelines type-check the same.
    let intersect: Arc<dyn Functor> = Arc::new(ClosureFunctor::new(signature("intersect")?, {
        let scene = scene.clone();
        move |_, inputs, outputs| intersect(&scene, mode, inputs, outputs)
    }));
    let occluded: Arc<dyn Functor> = Arc::new(ClosureFunctor::new(
        signature("occluded")?,
        move |_, inputs, outputs| occluded(&scene, mode, inputs, outputs),
    ));
    let mut swapped = FunctorLibrary::default();
    swapped.records = library.records.clone();
    swapped.uniforms = library.uniforms.clone();
    for functor in library.iter() {
        swapped.register(match functor.signature().name {
            "intersect" => intersect.clone(),
            "occluded" => occluded.clone(),
            _ => functor.clone(),
        });
    }
    Ok(swapped)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::functors::test_support::{probe_rays, read_rays, Fixture};
    use crate::functors::MISS_PRIM;
    use dpp_runtime::{CallContext, ElemType};

    /// Runs functor `name` of `library` on `rays` in the fixture's context;
    /// its output, of type `output`.
    fn run_on_rays(
        fixture: &Fixture,
        library: &FunctorLibrary,
        name: &str,
        output: ElemType,
        rays: &Column,
    ) -> Column {
        let functor = library.get(name).unwrap();
        let ctx = CallContext {
            named: &[],
            uniforms: &fixture.uniforms,
            resources: &fixture.resources,
            first_index: 0,
            group: 1,
            records: &library.records,
        };
        let mut outputs = vec![Column::with_capacity(output, 0, &library.records)];
        functor.run_cpu(&ctx, &[rays.view()], &mut outputs).unwrap();
        outputs.remove(0)
    }

    /// `intersect` of `library` on `rays`: each field of the hits.
    fn hits(fixture: &Fixture, library: &FunctorLibrary, rays: &Column) -> Vec<Vec<f32>> {
        let hits = run_on_rays(fixture, library, "intersect", fixture.record("Hit"), rays);
        let view = hits.view();
        vec![
            view.field(0).as_f32().to_vec(),
            view.field(1).as_u32().iter().map(|&p| p as f32).collect(),
            view.field(2).as_f32().to_vec(),
            view.field(3).as_f32().to_vec(),
        ]
    }

    /// Embree's scene of the fixture, with its robust test and with its fast
    /// one: the probe rays meet no shared edge, so both must hit alike.
    fn both_embree_scenes(fixture: &Fixture) -> [(bool, Arc<EmbreeScene>); 2] {
        [true, false].map(|robust| {
            (
                robust,
                Arc::new(EmbreeScene::build(&fixture.resources.scene.mesh, robust).unwrap()),
            )
        })
    }

    #[test]
    fn embree_hits_mean_what_the_cpu_hits_mean() {
        let fixture = Fixture::new();
        // Enough rays for a full packet, a partial one, and dead rays among them.
        let mut rays = read_rays(&probe_rays(&fixture));
        rays = rays.iter().cycle().take(53).copied().collect();
        rays[5].tmax = 0.0;
        rays[9].tmax = -1.0;
        // A whole packet of dead rays, which Embree is not asked about.
        for (i, ray) in rays[16..32].iter_mut().enumerate() {
            ray.tmax = [0.0, f32::NAN, f32::NEG_INFINITY][i % 3];
        }
        let rays = fixture.rays(&rays);
        let expected = hits(&fixture, &fixture.library, &rays);
        assert!(expected[1].contains(&(MISS_PRIM as f32)));
        for (robust, scene) in both_embree_scenes(&fixture) {
            for mode in [EmbreeMode::Single, EmbreeMode::Packet16] {
                let library = library_with_embree(&fixture.library, scene.clone(), mode).unwrap();
                let got = hits(&fixture, &library, &rays);
                assert_eq!(
                    got[1], expected[1],
                    "{mode:?}, robust {robust}: triangle ids"
                );
                for field in [0, 2, 3] {
                    for (a, b) in got[field].iter().zip(&expected[field]) {
                        assert!(
                            a == b || (a - b).abs() < 1e-5,
                            "{mode:?}, robust {robust}: {a} vs {b}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn embree_occlusion_means_what_the_cpu_occlusion_means() {
        let fixture = Fixture::new();
        let mut rays = read_rays(&probe_rays(&fixture));
        rays = rays.iter().cycle().take(53).copied().collect();
        rays[4].tmax = 0.0;
        rays[9].tmax = f32::NEG_INFINITY;
        // A whole packet of dead rays, which Embree is not asked about.
        for (i, ray) in rays[16..32].iter_mut().enumerate() {
            ray.tmax = [0.0, f32::NAN, f32::NEG_INFINITY][i % 3];
        }
        let rays = fixture.rays(&rays);
        let blocked = |library: &FunctorLibrary| {
            let blocked = run_on_rays(&fixture, library, "occluded", ElemType::Bool, &rays);
            blocked.view().as_bool().to_vec()
        };
        let expected = blocked(&fixture.library);
        assert!(expected.contains(&true) && expected.contains(&false));
        assert!(
            !expected[4] && !expected[9] && !expected[20],
            "dead rays are never blocked"
        );
        for (robust, scene) in both_embree_scenes(&fixture) {
            for mode in [EmbreeMode::Single, EmbreeMode::Packet16] {
                let library = library_with_embree(&fixture.library, scene.clone(), mode).unwrap();
                assert_eq!(blocked(&library), expected, "{mode:?}, robust {robust}");
            }
        }
    }

    #[test]
    fn the_swapped_library_keeps_every_other_functor() {
        let fixture = Fixture::new();
        let scene = Arc::new(EmbreeScene::build(&fixture.resources.scene.mesh, true).unwrap());
        let library = library_with_embree(&fixture.library, scene, EmbreeMode::Single).unwrap();
        let names = |l: &FunctorLibrary| l.names().collect::<Vec<_>>();
        assert_eq!(names(&library), names(&fixture.library));
        for name in ["intersect", "occluded"] {
            assert_eq!(
                library.get(name).unwrap().signature(),
                fixture.library.get(name).unwrap().signature()
            );
        }
    }
}
