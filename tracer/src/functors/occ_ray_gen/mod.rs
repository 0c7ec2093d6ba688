//! `occRayGen(surf: Surface) -> (ray: Ray) [range: float = 0.05]`, an expand
//! functor used as `scatter<occRayGen>(surf, fanout: aoSamples, range: aoRange)`:
//! the paper's ambient-occlusion rays.
//!
//! Lane `j` of surface `i` is a cosine-weighted direction in the hemisphere
//! about the shading normal, from `range * scene.diagonal` long (`range` is a
//! fraction of the scene diagonal), starting `SURFACE_EPSILON * scene.diagonal`
//! off the surface along the geometric normal (on the ray's side). Where the
//! shading normal leans away from the geometric one, a direction that would go
//! into the surface is mirrored in the triangle's plane, so that no occlusion ray
//! starts into its own surface. The two random numbers come from a stateless PCG
//! hash of `(sample, depth, lane)`, so images are deterministic and independent
//! of chunking and thread count. Non-hit surfaces (and `range <= 0`) give dead
//! rays, which `occluded` reports as not blocked.

use crate::functors::tracer_functor;
use crate::functors::wgsl::{
    diagonal_failure, random_module, sampling_module, surface_module, vector_module, TwinParts,
};
use crate::functors::{
    named_f32, scene_diagonal, RayRecord, RayWriter, SurfaceColumns, SURFACE_EPSILON,
};
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, HostType, HostValue,
    RecordId, Signature,
};
use glam::Vec3;
use std::f32::consts::TAU;
use std::sync::Arc;

pub fn functor(surface: RecordId, ray: RecordId) -> Arc<dyn Functor> {
    let signature = Signature::expand("occRayGen")
        .input("surf", ElemType::Record(surface))
        .output("ray", ElemType::Record(ray))
        .named(
            "range",
            HostType::Float,
            Some(HostValue::Float(0.05)),
            "length of the occlusion rays as a fraction of the scene diagonal",
        )
        .doc("lane j: a cosine-weighted hemisphere ray about the normal, hashed from (sample, depth, j); dead for a miss");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

/// `twin.wgsl`: the same hashed random numbers and hemisphere mapping.
fn twin_parts(_: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    Ok(TwinParts {
        modules: vec![
            vector_module(),
            random_module(),
            sampling_module(),
            surface_module(),
        ],
        failures: vec![
            "occRayGen: range must be a finite number".into(),
            diagonal_failure("occRayGen"),
        ],
        ..TwinParts::default()
    })
}

fn run_cpu(
    ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let range = named_f32(ctx, 0, "occRayGen", "range")?;
    let diagonal = scene_diagonal(ctx, "occRayGen")?;
    let lanes = u32::try_from(ctx.group).map_err(|_| {
        FunctorError::bad_input(format!("occRayGen: fanout {} is too large", ctx.group))
    })?;
    let epsilon = SURFACE_EPSILON * diagonal;
    let length = range * diagonal;
    let reaches = length > 0.0;
    let surfaces = SurfaceColumns::new(&inputs[0]);
    let mut out = RayWriter::new(&mut outputs[0], surfaces.len() * ctx.group)?;
    for index in 0..surfaces.len() {
        let surface = surfaces.get(index);
        for lane in 0..lanes {
            if !surface.hit || !reaches {
                out.push(RayRecord::dead(surface.sample, surface.depth));
                continue;
            }
            let (u1, u2) = random_pair(surface.sample, surface.depth, lane);
            out.push(RayRecord {
                origin: surface.offset_origin(epsilon),
                dir: surface.above_surface(cosine_hemisphere(surface.normal, u1, u2)),
                tmax: length,
                sample: surface.sample,
                weight: surface.weight,
                depth: surface.depth,
            });
        }
    }
    Ok(())
}

/// The PCG hash (Jarzynski and Olano, "Hash Functions for GPU Rendering", 2020).
#[inline]
pub(crate) fn pcg_hash(value: u32) -> u32 {
    let state = value.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
    let word = ((state >> ((state >> 28) + 4)) ^ state).wrapping_mul(277_803_737);
    (word >> 22) ^ word
}

/// Two numbers in [0, 1) (24 bits each) from `(sample, depth, lane)`.
#[inline]
pub(crate) fn random_pair(sample: u32, depth: u32, lane: u32) -> (f32, f32) {
    let first = pcg_hash(sample ^ pcg_hash(depth ^ pcg_hash(lane)));
    let second = pcg_hash(first);
    let unit = |bits: u32| (bits >> 8) as f32 * (1.0 / (1u32 << 24) as f32);
    (unit(first), unit(second))
}

/// A unit direction about unit `normal` with density `cos θ / π`, strictly above
/// the tangent plane for `u1 < 1` (Malley's method on the frame of Duff et al.,
/// "Building an Orthonormal Basis, Revisited", 2017).
#[inline]
pub(crate) fn cosine_hemisphere(normal: Vec3, u1: f32, u2: f32) -> Vec3 {
    let radius = u1.sqrt();
    let (sin, cos) = (TAU * u2).sin_cos();
    let height = (1.0 - u1).max(0.0).sqrt();
    let sign = 1.0f32.copysign(normal.z);
    let a = -1.0 / (sign + normal.z);
    let b = normal.x * normal.y * a;
    let tangent = Vec3::new(
        1.0 + sign * normal.x * normal.x * a,
        sign * b,
        -sign * normal.x,
    );
    let bitangent = Vec3::new(b, sign + normal.y * normal.y * a, -normal.y);
    (tangent * (radius * cos) + bitangent * (radius * sin) + normal * height).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::functors::test_support::{read_rays, surface_hit, Fixture};
    use crate::functors::SurfaceRecord;

    fn surface(normal: Vec3, sample: u32, depth: u32) -> SurfaceRecord {
        SurfaceRecord {
            depth,
            ..surface_hit(Vec3::new(0.5, 0.5, 0.0), normal, sample)
        }
    }

    #[test]
    fn directions_lie_in_the_hemisphere_and_are_cosine_weighted() {
        let fixture = Fixture::new();
        let diagonal = fixture.resources.scene.bounds.diagonal();
        let normals = [
            Vec3::Z,
            Vec3::NEG_Z,
            Vec3::X,
            Vec3::new(1.0, -2.0, 0.5).normalize(),
        ];
        for normal in normals {
            let surfaces = fixture.surfaces(&[surface(normal, 11, 0)]);
            let lanes = 4096;
            let out = fixture
                .run_grouped(
                    "occRayGen",
                    &[HostValue::Float(0.1)],
                    lanes,
                    0,
                    &[surfaces.view()],
                )
                .unwrap();
            let rays = read_rays(&out[0]);
            assert_eq!(rays.len(), lanes);
            let mut cosines = 0.0;
            for ray in &rays {
                let cosine = ray.dir.dot(normal);
                assert!(cosine > 0.0, "{normal}: {}", ray.dir);
                assert!((ray.dir.length() - 1.0).abs() < 1e-5);
                assert!((ray.tmax - 0.1 * diagonal).abs() < 1e-5);
                assert_eq!(
                    ray.origin,
                    Vec3::new(0.5, 0.5, 0.0) + normal * SURFACE_EPSILON * diagonal
                );
                assert_eq!((ray.sample, ray.depth, ray.weight), (11, 0, Vec3::ONE));
                cosines += cosine;
            }
            // E[cos θ] = 2/3 under the density cos θ / π.
            let mean = cosines / lanes as f32;
            assert!((mean - 2.0 / 3.0).abs() < 0.02, "{normal}: {mean}");
        }
    }

    #[test]
    fn rays_stay_on_the_triangles_side_when_the_normal_leans_into_it() {
        // A shading normal leaning below its triangle's plane: offset along it,
        // the rays started under the small square, and the hemisphere about it
        // reaches into the surface, so the square (or the floor under it) blocked
        // most of them. They start off the triangle's front, and directions into
        // the surface are mirrored out of it.
        let fixture = Fixture::new();
        let diagonal = fixture.resources.scene.bounds.diagonal();
        let normal = Vec3::new(1.0, 0.0, -0.3).normalize();
        let mut leaning = surface(normal, 3, 0);
        leaning.geometric = Vec3::Z;
        let surfaces = fixture.surfaces(&[leaning]);
        let out = fixture
            .run_grouped(
                "occRayGen",
                &[HostValue::Float(0.1)],
                256,
                0,
                &[surfaces.view()],
            )
            .unwrap();
        let rays = read_rays(&out[0]);
        let origin = Vec3::new(0.5, 0.5, SURFACE_EPSILON * diagonal);
        let into_the_surface = (0..256)
            .filter(|&lane| {
                let (u1, u2) = random_pair(3, 0, lane);
                cosine_hemisphere(normal, u1, u2).z < 0.0
            })
            .count();
        assert!(
            into_the_surface > 50,
            "{into_the_surface}: the test should reach into the surface"
        );
        for ray in &rays {
            assert_eq!(ray.origin, origin);
            assert!(ray.dir.z >= 0.0, "{}", ray.dir);
            assert!((ray.dir.length() - 1.0).abs() < 1e-5);
        }
        let blocked = fixture.run("occluded", &[], 0, &[out[0].view()]).unwrap();
        assert!(blocked[0].view().as_bool().iter().all(|&b| !b));
    }

    #[test]
    fn deterministic_chunk_independent_and_varying() {
        let fixture = Fixture::new();
        let records = [
            surface(Vec3::Z, 0, 0),
            surface(Vec3::Z, 1, 0),
            surface(Vec3::Z, 0, 1),
        ];
        let all = fixture.surfaces(&records);
        let run = |surfaces: &[SurfaceRecord], first: usize| {
            let column = fixture.surfaces(surfaces);
            read_rays(
                &fixture
                    .run_grouped("occRayGen", &[], 4, first, &[column.view()])
                    .unwrap()[0],
            )
        };
        let whole = run(&records, 0);
        assert_eq!(
            whole,
            read_rays(
                &fixture
                    .run_grouped("occRayGen", &[], 4, 0, &[all.view()])
                    .unwrap()[0]
            )
        );
        // The same rays when the surfaces come in other chunks.
        let mut split = run(&records[..1], 0);
        split.extend(run(&records[1..], 1));
        assert_eq!(whole, split);
        // Lanes differ, and so do samples and depths.
        let directions: Vec<Vec3> = whole.iter().map(|r| r.dir).collect();
        for i in 0..directions.len() {
            for j in 0..i {
                assert_ne!(directions[i], directions[j], "rays {i} and {j}");
            }
        }
    }

    #[test]
    fn misses_and_zero_range_give_dead_rays() {
        let fixture = Fixture::new();
        let surfaces = fixture.surfaces(&[SurfaceRecord::miss(4, Vec3::ONE, 2)]);
        let out = fixture
            .run_grouped("occRayGen", &[], 3, 0, &[surfaces.view()])
            .unwrap();
        assert_eq!(read_rays(&out[0]), vec![RayRecord::dead(4, 2); 3]);
        let surfaces = fixture.surfaces(&[surface(Vec3::Z, 0, 0)]);
        let out = fixture
            .run_grouped(
                "occRayGen",
                &[HostValue::Float(0.0)],
                2,
                0,
                &[surfaces.view()],
            )
            .unwrap();
        assert!(read_rays(&out[0]).iter().all(|r| r.tmax == 0.0));
        let error = fixture
            .run_grouped(
                "occRayGen",
                &[HostValue::Float(f64::NAN)],
                2,
                0,
                &[surfaces.view()],
            )
            .unwrap_err();
        assert!(error.message.contains("range"), "{error}");
    }

    #[test]
    fn the_hash_is_the_reference_pcg() {
        // Values of the reference implementation.
        assert_eq!(pcg_hash(0), 129_708_002);
        let (a, b) = random_pair(1, 2, 3);
        assert!((0.0..1.0).contains(&a) && (0.0..1.0).contains(&b));
    }
}
