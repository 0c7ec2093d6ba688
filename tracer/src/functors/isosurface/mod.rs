//! Marching cubes as a pipeline (`pipelines/isosurface.dpp`): what the three
//! isosurface functors share.
//!
//! - [`VolumeResources`]: the run's resources for the isosurface functors (they
//!   downcast `ctx.resources::<VolumeResources>()`), and [`volume_uniforms`],
//!   the `volume.*` uniforms of a volume;
//! - the `Triangle` record, `Triangle { a: vec3, b: vec3, c: vec3, na: vec3,
//!   nb: vec3, nc: vec3, sa: f32, sb: f32, sc: f32 }`: corners, unit vertex
//!   normals and vertex scalars of one triangle;
//! - [`crate::marching_cubes_tables`]: the marching-cubes tables, generated
//!   from the cube's topology;
//! - the per-cell geometry the functors `cubeCase`, `caseTriangles` and
//!   `cubeTriangle` compute (see their modules);
//! - [`mesh`]: turning the `Triangle` output into a [`crate::TriangleMesh`]
//!   (welded or not), which [`crate::mesh_write`] writes as OBJ or PLY;
//!   `weld.rs` finds which corners are one vertex, by a sort.
//!
//! # Conventions
//!
//! Cell `c` is the cube whose lowest sample is `(i, j, k)` with
//! `c = i + cx * (j + cy * k)`, `(cx, cy, cz)` = [`Volume::cell_dims`]. A
//! sample is *inside* when its value is below the level (a sample equal to the
//! level is outside). Triangles wind counter-clockwise seen from the outside
//! and the vertex normals are the normalised field gradient, interpolated along
//! the edge: both point towards **increasing** values, i.e. outwards for a
//! sphere whose inside is below the level (a distance field). The gradient is
//! [`Volume::gradient`]'s (central differences, one-sided at the volume's
//! border, in world units); a vertex where it vanishes gets a
//! zero normal (the tracer's `surface` functor then falls back to the face
//! normal). A vertex's scalar is the field interpolated along the edge (so the
//! level itself, up to rounding); a second field could be interpolated the same
//! way.
//!
//! Vertex positions are interpolated from the edge's lower sample to its upper
//! one, from the same samples in every cell that shares the edge, so shared
//! vertices are bit-identical and the surface is watertight.

pub mod mesh;
mod weld;

pub use mesh::{corner_bounds, triangles_to_mesh, welded_mesh, NotTriangles, TriangleColumns};

use crate::functors::record_fields_mut;
use crate::functors::wgsl::buffers::VolumeGpuBuffers;
use crate::marching_cubes_tables::{corner_offset, EDGES};
use crate::volume::Volume;
use dpp_runtime::{CallContext, Column, FunctorError, HostType, HostValue, Uniforms};
use glam::{UVec3, Vec3};
use std::sync::Arc;

/// The run's resources for the isosurface functors.
#[derive(Clone, Debug)]
pub struct VolumeResources {
    pub volume: Arc<Volume>,
}

impl VolumeResources {
    /// The volume as the WGSL twins read it, built once per volume.
    pub fn gpu_buffers(&self) -> Result<VolumeGpuBuffers, FunctorError> {
        VolumeGpuBuffers::of_volume(&self.volume)
    }
}

/// The `volume.*` uniforms: `(record, field, type)`.
pub const VOLUME_UNIFORM_FIELDS: [(&str, &str, HostType); 7] = [
    ("volume", "cells", HostType::Int),
    ("volume", "dimsX", HostType::Int),
    ("volume", "dimsY", HostType::Int),
    ("volume", "dimsZ", HostType::Int),
    ("volume", "min", HostType::Float),
    ("volume", "max", HostType::Float),
    ("volume", "cellSize", HostType::Float),
];

/// The values of [`VOLUME_UNIFORM_FIELDS`] for `volume`: the number of cells,
/// the sample counts along each axis, the smallest and largest finite
/// value (0 and 0 when there is none), and the cell size: the smallest
/// distance between neighbouring samples along an axis.
pub fn volume_uniforms(volume: &Volume) -> Uniforms {
    let mut uniforms = Uniforms::default();
    let int = |v: u64| HostValue::Int(v as i64);
    uniforms.set("volume", "cells", int(volume.cell_count()));
    uniforms.set("volume", "dimsX", int(volume.dims.x.into()));
    uniforms.set("volume", "dimsY", int(volume.dims.y.into()));
    uniforms.set("volume", "dimsZ", int(volume.dims.z.into()));
    let finite = volume.values.iter().filter(|v| v.is_finite());
    let (min, max) = finite.fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
        (lo.min(v), hi.max(v))
    });
    let (min, max) = if min <= max { (min, max) } else { (0.0, 0.0) };
    uniforms.set("volume", "min", HostValue::Float(min.into()));
    uniforms.set("volume", "max", HostValue::Float(max.into()));
    let cell = volume.spacing.abs().min_element();
    uniforms.set("volume", "cellSize", HostValue::Float(cell.into()));
    uniforms
}

/// One `Triangle` record.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriangleRecord {
    pub corners: [Vec3; 3],
    pub normals: [Vec3; 3],
    pub scalars: [f32; 3],
}

/// Appends `Triangle` records to an output column.
pub(crate) struct TriangleWriter<'a> {
    corners: [&'a mut Vec<Vec3>; 3],
    normals: [&'a mut Vec<Vec3>; 3],
    scalars: [&'a mut Vec<f32>; 3],
}

impl<'a> TriangleWriter<'a> {
    pub fn new(
        column: &'a mut Column,
        capacity: usize,
    ) -> Result<TriangleWriter<'a>, FunctorError> {
        let [a, b, c, na, nb, nc, sa, sb, sc] = record_fields_mut::<9>(column)?;
        let mut writer = TriangleWriter {
            corners: [a.as_vec3_mut(), b.as_vec3_mut(), c.as_vec3_mut()],
            normals: [na.as_vec3_mut(), nb.as_vec3_mut(), nc.as_vec3_mut()],
            scalars: [sa.as_f32_mut(), sb.as_f32_mut(), sc.as_f32_mut()],
        };
        for v in writer.corners.iter_mut().chain(writer.normals.iter_mut()) {
            v.reserve(capacity);
        }
        for v in writer.scalars.iter_mut() {
            v.reserve(capacity);
        }
        Ok(writer)
    }

    #[inline]
    pub fn push(&mut self, triangle: TriangleRecord) {
        for i in 0..3 {
            self.corners[i].push(triangle.corners[i]);
            self.normals[i].push(triangle.normals[i]);
            self.scalars[i].push(triangle.scalars[i]);
        }
    }
}

/// The run's volume, checked for consistency.
pub(crate) fn run_volume<'a>(
    ctx: &'a CallContext<'_>,
    functor: &str,
) -> Result<&'a Volume, FunctorError> {
    let volume = &ctx.resources::<VolumeResources>()?.volume;
    let expected = volume.dims.x as u64 * volume.dims.y as u64 * volume.dims.z as u64;
    if volume.values.len() as u64 != expected {
        return Err(FunctorError::bad_input(format!(
            "{functor}: the volume has {} values for {}×{}×{} samples",
            volume.values.len(),
            volume.dims.x,
            volume.dims.y,
            volume.dims.z
        )));
    }
    Ok(volume)
}

/// The `level` named parameter (index 0), a finite number.
pub(crate) fn level(ctx: &CallContext<'_>, functor: &str) -> Result<f32, FunctorError> {
    crate::functors::named_f32(ctx, 0, functor, "level")
}

/// The lowest sample of cell `cell`, or an error past the last cell.
#[inline]
pub(crate) fn cell_origin(
    volume: &Volume,
    cell: u32,
    functor: &str,
) -> Result<UVec3, FunctorError> {
    let dims = volume.cell_dims();
    if cell as u64 >= volume.cell_count() {
        return Err(FunctorError::bad_input(format!(
            "{functor}: cell {cell}, but the volume has {} cells",
            volume.cell_count()
        )));
    }
    let (x, rest) = (cell % dims.x, cell / dims.x);
    Ok(UVec3::new(x, rest % dims.y, rest / dims.y))
}

/// The sample at corner `corner` of the cell whose lowest sample is `origin`.
#[inline]
pub(crate) fn corner_sample(origin: UVec3, corner: u8) -> UVec3 {
    origin + UVec3::from_array(corner_offset(corner))
}

/// The values at the 8 corners of a cell.
#[inline]
pub(crate) fn corner_values(volume: &Volume, origin: UVec3) -> [f32; 8] {
    std::array::from_fn(|corner| {
        let s = corner_sample(origin, corner as u8);
        volume.value(s.x, s.y, s.z)
    })
}

/// The marching-cubes case: bit `n` set when corner `n` is below the level.
#[inline]
pub(crate) fn case_index(values: &[f32; 8], level: f32) -> u32 {
    values
        .iter()
        .enumerate()
        .fold(0, |case, (n, &v)| case | (((v < level) as u32) << n))
}

/// The surface's vertex on edge `edge` of a cell: position, unit normal (up the
/// gradient; zero where the gradient vanishes) and interpolated value.
#[inline]
pub(crate) fn edge_vertex(
    volume: &Volume,
    origin: UVec3,
    values: &[f32; 8],
    edge: u8,
    level: f32,
) -> (Vec3, Vec3, f32) {
    let [lo, hi] = EDGES[edge as usize];
    let (v0, v1) = (values[lo as usize], values[hi as usize]);
    let t = ((level - v0) / (v1 - v0)).clamp(0.0, 1.0);
    let t = if t.is_nan() { 0.5 } else { t };
    let (s0, s1) = (corner_sample(origin, lo), corner_sample(origin, hi));
    let (p0, p1) = (
        volume.position(s0.x, s0.y, s0.z),
        volume.position(s1.x, s1.y, s1.z),
    );
    let (g0, g1) = (
        volume.gradient(s0.x, s0.y, s0.z),
        volume.gradient(s1.x, s1.y, s1.z),
    );
    let position = p0 + (p1 - p0) * t;
    let normal = (g0 + (g1 - g0) * t).normalize_or_zero();
    (position, normal, v0 + (v1 - v0) * t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::register_isosurface_functors;
    use dpp_runtime::FunctorLibrary;

    fn volume(dims: UVec3, f: impl Fn(Vec3) -> f32) -> Volume {
        Volume::from_fn(dims, Vec3::ZERO, Vec3::new(0.5, 1.0, 2.0), |p, _| f(p))
    }

    #[test]
    fn cells_and_corners_follow_the_sample_order() {
        let v = volume(UVec3::new(4, 3, 2), |p| p.x + 10.0 * p.y + 100.0 * p.z);
        assert_eq!(v.cell_count(), 3 * 2);
        assert_eq!(cell_origin(&v, 0, "t").unwrap(), UVec3::ZERO);
        assert_eq!(cell_origin(&v, 4, "t").unwrap(), UVec3::new(1, 1, 0));
        assert!(cell_origin(&v, 6, "t").is_err());
        let values = corner_values(&v, UVec3::new(1, 1, 0));
        for (corner, value) in values.iter().enumerate() {
            let s = corner_sample(UVec3::new(1, 1, 0), corner as u8);
            assert_eq!(*value, v.value(s.x, s.y, s.z));
        }
        // x = 0.5, 1.0; y = 1, 2; z = 0, 2: only corner 0 (0.5 + 10) is below 11.
        assert_eq!(case_index(&values, 11.0), 1);
        assert_eq!(case_index(&values, 1000.0), 255);
    }

    #[test]
    fn gradients_are_in_world_units() {
        let v = volume(UVec3::new(4, 4, 4), |p| 3.0 * p.x - 2.0 * p.y + 0.5 * p.z);
        for s in [UVec3::ZERO, UVec3::new(1, 2, 3), UVec3::new(3, 3, 3)] {
            let g = v.gradient(s.x, s.y, s.z);
            assert!((g - Vec3::new(3.0, -2.0, 0.5)).length() < 1e-5, "{g}");
        }
    }

    #[test]
    fn edge_vertices_interpolate_linearly() {
        let v = volume(UVec3::new(2, 2, 2), |p| p.x);
        let values = corner_values(&v, UVec3::ZERO);
        // Edge 0 runs along x from 0 to 0.5.
        let (p, n, s) = edge_vertex(&v, UVec3::ZERO, &values, 0, 0.125);
        assert_eq!(p, Vec3::new(0.125, 0.0, 0.0));
        assert_eq!(n, Vec3::X);
        assert_eq!(s, 0.125);
    }

    #[test]
    fn uniforms_match_their_declared_types() {
        let mut library = FunctorLibrary::default();
        register_isosurface_functors(&mut library);
        let v = volume(UVec3::new(4, 3, 2), |p| p.x - p.y);
        let uniforms = volume_uniforms(&v);
        for (record, field, ty) in VOLUME_UNIFORM_FIELDS {
            assert_eq!(library.uniforms.records[record][field], ty);
            assert_eq!(uniforms.get(record, field).unwrap().host_type(), ty);
        }
        assert_eq!(uniforms.get("volume", "cells"), Some(HostValue::Int(6)));
        assert_eq!(uniforms.get("volume", "dimsY"), Some(HostValue::Int(3)));
        assert_eq!(uniforms.get("volume", "min"), Some(HostValue::Float(-2.0)));
        assert_eq!(uniforms.get("volume", "max"), Some(HostValue::Float(1.5)));
    }
}
