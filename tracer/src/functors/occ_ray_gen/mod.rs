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
    above_plane, named_f32, offset_origin, runs_of, scene_diagonal, RayRecord, RayWriter,
    SurfaceColumns, SURFACE_EPSILON,
};
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, HostType, HostValue,
    RecordId, Signature,
};
use glam::Vec3;
use multiversion::multiversion;
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
    // Lanes are hashed as u32.
    u32::try_from(ctx.group).map_err(|_| {
        FunctorError::bad_input(format!("occRayGen: fanout {} is too large", ctx.group))
    })?;
    let epsilon = SURFACE_EPSILON * diagonal;
    let length = range * diagonal;
    let reaches = length > 0.0;
    let surfaces = SurfaceColumns::new(&inputs[0]);
    let lanes = ctx.group;
    let mut out = RayWriter::new(&mut outputs[0], surfaces.len() * lanes)?;
    // A run of misses gives dead rays, which read three of the surfaces' ten
    // fields; a hit's rays are made in batches, which are appended before the
    // next dead rays so that every ray lands at its place.
    let mut batch = LiveRays::default();
    for (live, run) in runs_of(surfaces.len(), |index| reaches && surfaces.hit[index]) {
        if !live {
            batch.make(&surfaces, epsilon, length, &mut out);
            let depths = surfaces.depth[run.clone()].iter().copied();
            out.extend_dead(&surfaces.sample[run], depths, lanes);
            continue;
        }
        for index in run {
            for lane in 0..lanes {
                batch.surface[batch.len] = index;
                batch.lane[batch.len] = lane as u32;
                batch.len += 1;
                if batch.len == LIVE_BATCH {
                    batch.make(&surfaces, epsilon, length, &mut out);
                }
            }
        }
    }
    batch.make(&surfaces, epsilon, length, &mut out);
    Ok(())
}

/// Live rays made eight at a time: a ray is a long chain of dependent
/// operations (four hashes, two square roots, a division), and the loops over
/// a batch become vector instructions that make several side by side (the
/// functor took 0.90–0.94 of the time it took one ray at a time with libm's
/// `sincosf`, docs/benchmarks.md). Each ray is [`random_pair`], [`Hemisphere`] and
/// [`above_plane`] of its own surface and lane.
const LIVE_BATCH: usize = 8;

#[derive(Default)]
struct LiveRays {
    len: usize,
    surface: [usize; LIVE_BATCH],
    lane: [u32; LIVE_BATCH],
}

impl LiveRays {
    /// Appends the batch's rays to `out` and empties it.
    fn make(
        &mut self,
        surfaces: &SurfaceColumns<'_>,
        epsilon: f32,
        length: f32,
        out: &mut RayWriter<'_>,
    ) {
        if self.len == 0 {
            return;
        }
        make_live_rays(self, surfaces, epsilon, length, out);
        self.len = 0;
    }
}

/// [`LiveRays::make`], compiled for AVX2 too where the CPU has it: eight rays
/// are then one vector register (the same IEEE operations, so the same rays).
#[multiversion(targets("x86_64+avx2"))]
fn make_live_rays(
    batch: &LiveRays,
    surfaces: &SurfaceColumns<'_>,
    epsilon: f32,
    length: f32,
    out: &mut RayWriter<'_>,
) {
    type Lanes = [f32; LIVE_BATCH];
    // The inputs, gathered into one array per scalar (unused slots repeat
    // the first ray, so the loops below always run over the whole batch).
    let mut sample = [0; LIVE_BATCH];
    let mut depth = [0; LIVE_BATCH];
    let mut position = [[0.0; LIVE_BATCH]; 3];
    let mut normal = [[0.0; LIVE_BATCH]; 3];
    let mut geometric = [[0.0; LIVE_BATCH]; 3];
    let mut weight = [[0.0; LIVE_BATCH]; 3];
    for slot in 0..LIVE_BATCH {
        let index = batch.surface[if slot < batch.len { slot } else { 0 }];
        sample[slot] = surfaces.sample[index];
        depth[slot] = surfaces.depth[index];
        for (axes, column) in [
            (&mut position, surfaces.position),
            (&mut normal, surfaces.normal),
            (&mut geometric, surfaces.geometric),
            (&mut weight, surfaces.weight),
        ] {
            for axis in 0..3 {
                axes[axis][slot] = column[index][axis];
            }
        }
    }
    let at =
        |axes: &[Lanes; 3], slot: usize| Vec3::new(axes[0][slot], axes[1][slot], axes[2][slot]);
    let mut origin = [[0.0; LIVE_BATCH]; 3];
    let mut dir = [[0.0; LIVE_BATCH]; 3];
    for slot in 0..LIVE_BATCH {
        let (u1, u2) = random_pair(sample[slot], depth[slot], batch.lane[slot]);
        let made = above_plane(
            Hemisphere::about(at(&normal, slot)).cosine_direction(u1, u2),
            at(&geometric, slot),
        );
        let start = offset_origin(at(&position, slot), at(&geometric, slot), epsilon);
        for axis in 0..3 {
            dir[axis][slot] = made[axis];
            origin[axis][slot] = start[axis];
        }
    }
    out.extend_with(batch.len, |slot| RayRecord {
        origin: at(&origin, slot),
        dir: at(&dir, slot),
        tmax: length,
        sample: sample[slot],
        weight: at(&weight, slot),
        depth: depth[slot],
    });
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

/// The orthonormal frame about a unit normal (Duff et al., "Building an
/// Orthonormal Basis, Revisited", 2017), built for each ray of a batch, side
/// by side in vector lanes.
pub(crate) struct Hemisphere {
    tangent: Vec3,
    bitangent: Vec3,
    normal: Vec3,
}

impl Hemisphere {
    #[inline]
    pub(crate) fn about(normal: Vec3) -> Hemisphere {
        let sign = 1.0f32.copysign(normal.z);
        let a = -1.0 / (sign + normal.z);
        let b = normal.x * normal.y * a;
        Hemisphere {
            tangent: Vec3::new(
                1.0 + sign * normal.x * normal.x * a,
                sign * b,
                -sign * normal.x,
            ),
            bitangent: Vec3::new(b, sign + normal.y * normal.y * a, -normal.y),
            normal,
        }
    }

    /// A unit direction with density `cos θ / π`, strictly above the tangent
    /// plane for `u1 < 1` (Malley's method).
    #[inline]
    pub(crate) fn cosine_direction(&self, u1: f32, u2: f32) -> Vec3 {
        let radius = u1.sqrt();
        let (sin, cos) = sin_cos_of_turn(u2);
        let height = (1.0 - u1).max(0.0).sqrt();
        (self.tangent * (radius * cos) + self.bitangent * (radius * sin) + self.normal * height)
            .normalize()
    }
}

/// `(sin 2πt, cos 2πt)` for `t` in [0, 1], inline and without a call (libm's
/// `sincosf` was a quarter of this functor's time): the nearest quarter turn,
/// then Taylor polynomials of the angle left, in [-π/4, π/4], where their
/// error is below 2e-9; in f32 the results are within 3e-7 of the true values.
#[inline]
fn sin_cos_of_turn(turn: f32) -> (f32, f32) {
    let quarters = turn * 4.0;
    // `turn` >= 0, so the truncation rounds to the nearest quarter.
    let quarter = (quarters + 0.5) as i32;
    let angle = (quarters - quarter as f32) * std::f32::consts::FRAC_PI_2;
    let square = angle * angle;
    let sin = angle
        * (1.0
            + square
                * (-1.0 / 6.0
                    + square * (1.0 / 120.0 + square * (-1.0 / 5040.0 + square / 362_880.0))));
    let cos =
        1.0 + square * (-0.5 + square * (1.0 / 24.0 + square * (-1.0 / 720.0 + square / 40_320.0)));
    // A quarter turn on: (cos, -sin); a half turn: both negated. Chosen, not
    // branched on, so that batches of rays vectorise.
    let (sin, cos) = if quarter & 1 != 0 {
        (cos, -sin)
    } else {
        (sin, cos)
    };
    if quarter & 2 != 0 {
        (-sin, -cos)
    } else {
        (sin, cos)
    }
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

    /// The rays of `surfaces`, the first of which is element `first` of the
    /// whole array, with `fanout` lanes each.
    fn rays(
        fixture: &Fixture,
        surfaces: &[SurfaceRecord],
        fanout: usize,
        first: usize,
    ) -> Vec<RayRecord> {
        let column = fixture.surfaces(surfaces);
        let out = fixture.run_grouped("occRayGen", &[], fanout, first, &[column.view()]);
        read_rays(&out.unwrap()[0])
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
                Hemisphere::about(normal).cosine_direction(u1, u2).z < 0.0
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
        let run = |surfaces: &[SurfaceRecord], first: usize| rays(&fixture, surfaces, 4, first);
        let whole = run(&records, 0);
        assert_eq!(whole, run(&records, 0));
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

    /// Hits and misses interleaved, with a fanout that splits surfaces across
    /// batches: each surface's rays are those it makes alone, at its place.
    #[test]
    fn rays_of_hits_and_misses_land_at_their_surfaces_places() {
        let fixture = Fixture::new();
        let records: Vec<SurfaceRecord> = (0..23)
            .map(|index| match index % 7 {
                // Runs of one and of three misses.
                1 | 3..=5 => SurfaceRecord::miss(index, Vec3::ONE, 1),
                _ => surface(Vec3::new(0.3, -0.2, 1.0).normalize(), index, 1),
            })
            .collect();
        let run = |surfaces: &[SurfaceRecord], first: usize| rays(&fixture, surfaces, 3, first);
        let whole = run(&records, 0);
        let alone: Vec<RayRecord> = (0..records.len())
            .flat_map(|index| run(&records[index..=index], index))
            .collect();
        assert_eq!(whole, alone);
        assert_eq!(whole.iter().filter(|ray| ray.tmax > 0.0).count(), 3 * 10);
    }

    #[test]
    fn misses_and_zero_range_give_dead_rays() {
        let fixture = Fixture::new();
        // No surfaces, and no hit among them: nothing live to make.
        let none = fixture.surfaces(&[]);
        let out = fixture
            .run_grouped("occRayGen", &[], 4, 0, &[none.view()])
            .unwrap();
        assert!(read_rays(&out[0]).is_empty());
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
    fn sine_and_cosine_of_a_turn_are_within_3e7() {
        for step in 0..=(1 << 16) {
            let turn = step as f32 / (1 << 16) as f32;
            let (sin, cos) = sin_cos_of_turn(turn);
            let angle = std::f64::consts::TAU * f64::from(turn);
            assert!((f64::from(sin) - angle.sin()).abs() < 3e-7, "{turn}: {sin}");
            assert!((f64::from(cos) - angle.cos()).abs() < 3e-7, "{turn}: {cos}");
        }
    }

    #[test]
    fn the_hash_is_the_reference_pcg() {
        // Values of the reference implementation.
        assert_eq!(pcg_hash(0), 129_708_002);
        let (a, b) = random_pair(1, 2, 3);
        assert!((0.0..1.0).contains(&a) && (0.0..1.0).contains(&b));
    }
}
