//! Indexed triangle meshes as the tracer receives them from a file or a generator.

use crate::vector::unit_or_zero;
use glam::{Vec3, Vec3A};
use rayon::prelude::*;
use std::collections::HashMap;
use thiserror::Error;

/// A triangle mesh. Triangle `i` is the `i`-th triangle of the input after fan
/// triangulation (`(v0,v1,v2), (v0,v2,v3), …` per face, faces in file order); hit
/// records name triangles by this index.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriangleMesh {
    pub positions: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
    /// Per-vertex shading normals, when the input has them.
    pub normals: Option<Vec<Vec3>>,
    /// Per-vertex scalar field values (for colour maps), when the input has them.
    pub scalars: Option<Vec<f32>>,
}

/// An axis-aligned box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    pub min: Vec3,
    pub max: Vec3,
}

impl Bounds {
    pub fn center(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }

    /// Length of the box's diagonal (computed without squaring overflow for
    /// boxes wider than about 1e19).
    pub fn diagonal(&self) -> f32 {
        let extent = self.max - self.min;
        let length = extent.length();
        if length.is_finite() || !extent.is_finite() {
            return length;
        }
        let largest = extent.abs().max_element();
        largest * (extent / largest).length()
    }
}

#[derive(Clone, Debug, Error, PartialEq)]
pub enum MeshError {
    #[error("the mesh has no triangles")]
    NoTriangles,
    #[error("vertex {index} has a non-finite coordinate {position:?}")]
    NonFiniteVertex { index: usize, position: Vec3 },
    #[error(
        "triangle {triangle} uses vertex {vertex}, but the mesh has only {vertex_count} vertices"
    )]
    VertexIndexOutOfRange {
        triangle: usize,
        vertex: u32,
        vertex_count: usize,
    },
    #[error("the mesh has {triangles} triangles; at most {max} are supported (triangle ids are u32 and u32::MAX means a miss)")]
    TooManyTriangles { triangles: usize, max: usize },
    #[error("the mesh has {vertices} vertices but {values} per-vertex {what}")]
    AttributeLengthMismatch {
        what: &'static str,
        vertices: usize,
        values: usize,
    },
    #[error("vertex normal {index} is not finite: {normal:?}")]
    NonFiniteNormal { index: usize, normal: Vec3 },
    #[error(
        "the mesh's largest coordinate magnitude is {largest:e}; dpp computes in f32 and \
         supports meshes whose largest coordinate lies between {MIN_LARGEST_COORDINATE:e} and \
         {MAX_COORDINATE:e} (squared distances must stay normal numbers): rescale the mesh"
    )]
    OutOfScale { largest: f32 },
}

/// The largest coordinate magnitude a mesh may have, and the least its
/// largest may be (unless all are zero): between them the squares of
/// world-space distances (lights, camera, bounds) stay normal f32 numbers.
/// Tracing itself holds further (the BVH rescales by a power of two).
pub const MAX_COORDINATE: f32 = 1e18;
pub const MIN_LARGEST_COORDINATE: f32 = 1e-18;

/// Elements per parallel chunk of the mesh's checks and bounds.
const PARALLEL_CHUNK: usize = 1 << 14;

/// The index of the first element of `items` that is `bad`, searched in
/// parallel chunks (the first one, whatever the thread count).
fn first_where<T: Sync>(items: &[T], bad: impl Fn(&T) -> bool + Sync) -> Option<usize> {
    items
        .par_chunks(PARALLEL_CHUNK)
        .enumerate()
        .find_map_first(|(number, chunk)| {
            let within = chunk.iter().position(&bad)?;
            Some(number * PARALLEL_CHUNK + within)
        })
}

/// Triangle ids are `u32` and `u32::MAX` marks a miss, so the count must stay below it.
pub const MAX_TRIANGLES: usize = u32::MAX as usize - 1;

impl TriangleMesh {
    /// Checks everything later stages rely on: at least one triangle, finite
    /// vertices, indices in range, attribute arrays matching the vertex count.
    pub fn validate(&self) -> Result<(), MeshError> {
        self.validated_bounds().map(drop)
    }

    /// [`TriangleMesh::validate`], returning the [`TriangleMesh::bounds`] it
    /// checked the mesh's scale with, so that a caller need not compute them again.
    pub fn validated_bounds(&self) -> Result<Bounds, MeshError> {
        if self.triangles.is_empty() {
            return Err(MeshError::NoTriangles);
        }
        if self.triangles.len() > MAX_TRIANGLES {
            return Err(MeshError::TooManyTriangles {
                triangles: self.triangles.len(),
                max: MAX_TRIANGLES,
            });
        }
        // In parallel, as the BVH build that follows is: these passes were
        // a tenth of the dragon's build time on one thread. The first bad
        // element is reported, whatever the thread count.
        if let Some(index) = first_where(&self.positions, |p| !p.is_finite()) {
            let position = self.positions[index];
            return Err(MeshError::NonFiniteVertex { index, position });
        }
        let vertex_count = self.positions.len();
        let out_of_range = |indices: &[u32; 3]| indices.iter().any(|&v| v as usize >= vertex_count);
        if let Some(triangle) = first_where(&self.triangles, out_of_range) {
            let indices = self.triangles[triangle];
            let vertex = *indices
                .iter()
                .find(|&&v| v as usize >= vertex_count)
                .unwrap_or(&indices[0]);
            return Err(MeshError::VertexIndexOutOfRange {
                triangle,
                vertex,
                vertex_count,
            });
        }
        // Every index is in range, so the triangles have bounds.
        let bounds = self.bounds().ok_or(MeshError::NoTriangles)?;
        let largest = bounds.min.abs().max(bounds.max.abs()).max_element();
        if largest > MAX_COORDINATE || (largest > 0.0 && largest < MIN_LARGEST_COORDINATE) {
            return Err(MeshError::OutOfScale { largest });
        }
        if let Some(normals) = &self.normals {
            if normals.len() != vertex_count {
                return Err(MeshError::AttributeLengthMismatch {
                    what: "normals",
                    vertices: vertex_count,
                    values: normals.len(),
                });
            }
            if let Some(index) = first_where(normals, |n| !n.is_finite()) {
                let normal = normals[index];
                return Err(MeshError::NonFiniteNormal { index, normal });
            }
        }
        if let Some(scalars) = &self.scalars {
            if scalars.len() != vertex_count {
                return Err(MeshError::AttributeLengthMismatch {
                    what: "scalars",
                    vertices: vertex_count,
                    values: scalars.len(),
                });
            }
        }
        Ok(bounds)
    }

    /// The box around the vertices that triangles use (unused vertices do not
    /// count: they cannot be hit). `None` for a mesh without triangles.
    /// In parallel chunks: minima and maxima are exact in any order, so the
    /// box does not depend on the thread count.
    pub fn bounds(&self) -> Option<Bounds> {
        let chunk_bounds = |chunk: &[[u32; 3]]| {
            chunk
                .iter()
                .flatten()
                .filter_map(|&v| self.positions.get(v as usize))
                .map(|&p| Vec3A::from(p))
                .fold(None, |joined: Option<(Vec3A, Vec3A)>, p| match joined {
                    Some((min, max)) => Some((min.min(p), max.max(p))),
                    None => Some((p, p)),
                })
        };
        let joined = self
            .triangles
            .par_chunks(PARALLEL_CHUNK)
            .map(chunk_bounds)
            .reduce(
                || None,
                |a, b| match (a, b) {
                    (Some(a), Some(b)) => Some((a.0.min(b.0), a.1.max(b.1))),
                    (a, b) => a.or(b),
                },
            );
        joined.map(|(min, max)| Bounds {
            min: min.into(),
            max: max.into(),
        })
    }

    /// The three corner positions of triangle `index` (indices must be valid).
    #[inline]
    pub fn triangle_vertices(&self, index: usize) -> [Vec3; 3] {
        let [a, b, c] = self.triangles[index];
        [
            self.positions[a as usize],
            self.positions[b as usize],
            self.positions[c as usize],
        ]
    }

    /// The unnormalised geometric normal `(v1 - v0) × (v2 - v0)` of triangle `index`.
    #[inline]
    pub fn face_normal(&self, index: usize) -> Vec3 {
        let [v0, v1, v2] = self.triangle_vertices(index);
        (v1 - v0).cross(v2 - v0)
    }

    /// Gives a mesh without normals smooth vertex normals that keep its sharp
    /// edges: each triangle corner averages (area-weighted) the faces around its
    /// vertex whose normals are within `crease` radians of its own face, and a
    /// vertex whose corners disagree is split into one vertex per normal (same
    /// position and scalar). Triangles keep their order and their positions.
    /// Around a vertex with more than [`MAX_DIRECTIONS_AROUND_A_VERTEX`]
    /// different face directions, corners keep their face's normal.
    pub fn add_crease_normals(&mut self, crease: f32) {
        self.add_crease_normals_in_runs(crease, VERTICES_PER_NORMAL_RUN);
    }

    /// [`TriangleMesh::add_crease_normals`] with the vertices smoothed in
    /// parallel runs of `run_length` (the result does not depend on it).
    fn add_crease_normals_in_runs(&mut self, crease: f32, run_length: usize) {
        let faces: Vec<Vec3> = (0..self.triangles.len())
            .into_par_iter()
            .map(|t| self.face_normal(t))
            .collect();
        let units: Vec<Vec3> = faces.par_iter().map(|&n| unit_or_zero(n)).collect();
        let cos_crease = crease.cos();
        let vertex_count = self.positions.len();
        // The corners around each vertex, as (triangle, corner) pairs in CSR
        // form (a counting sort, which keeps each vertex's corners in triangle
        // order); and where each corner landed, to find its new vertex again.
        let mut starts = vec![0usize; vertex_count + 1];
        for triangle in &self.triangles {
            for &vertex in triangle {
                starts[vertex as usize + 1] += 1;
            }
        }
        for i in 0..vertex_count {
            starts[i + 1] += starts[i];
        }
        let mut fill = starts.clone();
        let mut corners = vec![(0u32, 0u8); starts[vertex_count]];
        let mut slot_of_corner = vec![0u32; 3 * self.triangles.len()];
        for (t, triangle) in self.triangles.iter().enumerate() {
            for (c, &vertex) in triangle.iter().enumerate() {
                corners[fill[vertex as usize]] = (t as u32, c as u8);
                slot_of_corner[3 * t + c] = fill[vertex as usize] as u32;
                fill[vertex as usize] += 1;
            }
        }
        drop(fill);
        // Vertices in fixed-size runs, each smoothed on its own: a vertex's
        // new vertices depend only on its own corners, so the runs' results,
        // concatenated in order, are what one pass over all vertices gives.
        let runs: Vec<std::ops::Range<usize>> = (0..vertex_count)
            .step_by(run_length)
            .map(|first| first..(first + run_length).min(vertex_count))
            .collect();
        // Each corner's new vertex, in CSR order, split at the runs' corners.
        let mut new_vertex_of_slot = vec![0u32; corners.len()];
        let mut slots_of_run = Vec::with_capacity(runs.len());
        let mut rest = &mut new_vertex_of_slot[..];
        for run in &runs {
            let (own, after) = rest.split_at_mut(starts[run.end] - starts[run.start]);
            slots_of_run.push(own);
            rest = after;
        }
        let smoothed: Vec<SmoothedRun> = runs
            .par_iter()
            .zip(slots_of_run.par_iter_mut())
            .map(|(run, slots)| {
                let mut directions = DirectionsAroundVertex::default();
                let mut smoothed = SmoothedRun::default();
                let first_slot = starts[run.start];
                for vertex in run.clone() {
                    let around = &corners[starts[vertex]..starts[vertex + 1]];
                    directions.smooth(
                        around
                            .iter()
                            .map(|&(t, _)| (units[t as usize], faces[t as usize])),
                        cos_crease,
                    );
                    // One new vertex per distinct normal, in the order of the corners.
                    let first_new = smoothed.normals.len() as u32;
                    for &normal in &directions.distinct_normals {
                        smoothed.old_vertex.push(vertex as u32);
                        smoothed.normals.push(normal);
                    }
                    let own_slots = &mut slots[starts[vertex] - first_slot..][..around.len()];
                    for (slot, &group) in own_slots.iter_mut().zip(&directions.corner_group) {
                        *slot = first_new + directions.distinct_of_group[group as usize];
                    }
                }
                smoothed
            })
            .collect();
        // Run-local vertex numbers become global ones.
        let mut first_of_run = Vec::with_capacity(smoothed.len());
        let mut new_vertices = 0u32;
        for run in &smoothed {
            first_of_run.push(new_vertices);
            new_vertices += run.normals.len() as u32;
        }
        slots_of_run
            .par_iter_mut()
            .zip(&first_of_run)
            .for_each(|(slots, &first)| slots.iter_mut().for_each(|slot| *slot += first));
        let old_vertex: Vec<u32> = smoothed
            .iter()
            .flat_map(|run| run.old_vertex.iter().copied())
            .collect();
        let normals: Vec<Vec3> = smoothed.into_iter().flat_map(|run| run.normals).collect();
        let (old_positions, old_scalars) =
            (std::mem::take(&mut self.positions), self.scalars.take());
        self.positions = old_vertex
            .par_iter()
            .map(|&v| old_positions[v as usize])
            .collect();
        self.scalars =
            old_scalars.map(|old| old_vertex.par_iter().map(|&v| old[v as usize]).collect());
        self.triangles
            .par_iter_mut()
            .enumerate()
            .for_each(|(t, triangle)| {
                for (c, vertex) in triangle.iter_mut().enumerate() {
                    *vertex = new_vertex_of_slot[slot_of_corner[3 * t + c] as usize];
                }
            });
        self.normals = Some(normals);
    }
}

/// Vertices smoothed by one task of [`TriangleMesh::add_crease_normals`]: enough
/// that a task outweighs its scheduling, few enough for two threads to share
/// a 100K-vertex mesh evenly.
const VERTICES_PER_NORMAL_RUN: usize = 4096;

/// The new vertices of one run of old ones, in order: the old vertex each
/// copies its position and scalar from, and its normal.
#[derive(Default)]
struct SmoothedRun {
    old_vertex: Vec<u32>,
    normals: Vec<Vec3>,
}

/// Around a vertex with more distinct face directions than this, each corner
/// keeps its own face's normal: the crease test compares every pair of
/// directions around a vertex, and a vertex shared by many thousands of
/// differently oriented triangles (a finely divided cone's apex, a broken file
/// that names one vertex in every face) would take quadratic time.
pub const MAX_DIRECTIONS_AROUND_A_VERTEX: usize = 1024;

/// The normals of the corners around one vertex, in buffers reused from vertex
/// to vertex. Corners whose faces point exactly the same way form one group, so
/// a fan of coplanar triangles (a disk's cap, however finely divided) costs
/// time linear in its size.
#[derive(Default)]
struct DirectionsAroundVertex {
    /// Groups are numbered in the order of their first corner.
    directions: FirstAppearance,
    corner_group: Vec<u32>,
    /// Per group: its unit face direction, the sum of its faces' area-weighted
    /// normals, and its corners' normal.
    group_direction: Vec<Vec3>,
    group_faces: Vec<Vec3>,
    group_normal: Vec<Vec3>,
    /// The different normals, in the order of their first corner, and which of
    /// them each group takes.
    normals: FirstAppearance,
    distinct_normals: Vec<Vec3>,
    distinct_of_group: Vec<u32>,
}

impl DirectionsAroundVertex {
    /// Each corner, given as its face's unit normal and area-weighted normal, gets
    /// the normalised sum of the area-weighted normals of the faces around the
    /// vertex within the crease angle of its own (summed in the order of the
    /// corners, group by group), or its own unit normal where that sum vanishes.
    fn smooth(&mut self, corners: impl Iterator<Item = (Vec3, Vec3)>, cos_crease: f32) {
        self.directions.clear();
        self.corner_group.clear();
        self.group_direction.clear();
        self.group_faces.clear();
        for (unit, face) in corners {
            let group = self.directions.number(exact_key(unit));
            if group as usize == self.group_direction.len() {
                self.group_direction.push(unit);
                self.group_faces.push(Vec3::ZERO);
            }
            self.group_faces[group as usize] += face;
            self.corner_group.push(group);
        }
        let flat = self.group_direction.len() > MAX_DIRECTIONS_AROUND_A_VERTEX;
        self.group_normal.clear();
        for &own in &self.group_direction {
            let sum: Vec3 = if flat {
                Vec3::ZERO
            } else {
                self.group_direction
                    .iter()
                    .zip(&self.group_faces)
                    .filter(|(unit, _)| unit.dot(own) >= cos_crease)
                    .map(|(_, &faces)| faces)
                    .sum()
            };
            self.group_normal.push(if sum == Vec3::ZERO {
                own
            } else {
                unit_or_zero(sum)
            });
        }
        // Groups with equal normals share one vertex.
        self.normals.clear();
        self.distinct_normals.clear();
        self.distinct_of_group.clear();
        for &normal in &self.group_normal {
            let distinct = self.normals.number(exact_key(normal));
            if distinct as usize == self.distinct_normals.len() {
                self.distinct_normals.push(normal);
            }
            self.distinct_of_group.push(distinct);
        }
    }
}

/// Numbers keys in the order they first appear: an equal key seen before gets
/// its number, a new one the next. A linear search while there are few (most
/// vertices have about six corners), a hash map beyond.
#[derive(Default)]
struct FirstAppearance {
    keys: Vec<[u32; 3]>,
    numbers: HashMap<[u32; 3], u32>,
}

impl FirstAppearance {
    const LINEAR_SEARCH_UP_TO: usize = 16;

    fn clear(&mut self) {
        self.keys.clear();
        if !self.numbers.is_empty() {
            // Not `clear`: that costs the map's whole capacity at every vertex.
            self.numbers = HashMap::new();
        }
    }

    fn number(&mut self, key: [u32; 3]) -> u32 {
        let next = self.keys.len() as u32;
        if self.keys.len() <= Self::LINEAR_SEARCH_UP_TO {
            if let Some(found) = self.keys.iter().position(|&seen| seen == key) {
                return found as u32;
            }
            self.keys.push(key);
            if self.keys.len() > Self::LINEAR_SEARCH_UP_TO {
                self.numbers = (self.keys.iter().copied()).zip(0..).collect();
            }
            return next;
        }
        let keys = &mut self.keys;
        *self.numbers.entry(key).or_insert_with(|| {
            keys.push(key);
            next
        })
    }
}

/// A vector's bits with `-0.0` read as `0.0`, so that equal vectors have equal keys.
fn exact_key(vector: Vec3) -> [u32; 3] {
    (vector + Vec3::ZERO).to_array().map(f32::to_bits)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one_triangle() -> TriangleMesh {
        TriangleMesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::splat(100.0)],
            triangles: vec![[0, 1, 2]],
            normals: None,
            scalars: None,
        }
    }

    #[test]
    fn valid_mesh_passes_and_bounds_ignore_unused_vertices() {
        let mesh = one_triangle();
        assert_eq!(mesh.validate(), Ok(()));
        let bounds = mesh.bounds().unwrap();
        assert_eq!(bounds.min, Vec3::ZERO);
        assert_eq!(bounds.max, Vec3::new(1.0, 1.0, 0.0));
        assert_eq!(bounds.center(), Vec3::new(0.5, 0.5, 0.0));
        assert!((bounds.diagonal() - 2f32.sqrt()).abs() < 1e-6);
        let huge = Bounds {
            min: Vec3::ZERO,
            max: Vec3::new(3e30, 0.0, 4e30),
        };
        assert!((huge.diagonal() / 5e30 - 1.0).abs() < 1e-6);
        assert_eq!(mesh.face_normal(0), Vec3::Z);
    }

    /// A unit cube of 8 shared vertices (12 triangles, outward winding).
    fn cube() -> TriangleMesh {
        let corner =
            |i: u32| Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32);
        let mut triangles = Vec::new();
        for [a, b, c, d] in [
            [0, 2, 3, 1],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 4, 6, 2],
            [1, 3, 7, 5],
        ] {
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
        }
        TriangleMesh {
            positions: (0..8).map(corner).collect(),
            triangles,
            normals: None,
            scalars: Some((0..8).map(|i| i as f32).collect()),
        }
    }

    #[test]
    fn crease_normals_keep_a_cubes_edges_sharp() {
        let mut mesh = cube();
        let before = mesh.clone();
        mesh.add_crease_normals(60f32.to_radians());
        // Each corner of the cube becomes three vertices, one per face.
        assert_eq!(mesh.positions.len(), 24);
        let normals = mesh.normals.as_ref().unwrap();
        for (t, triangle) in mesh.triangles.iter().enumerate() {
            let face = mesh.face_normal(t).normalize();
            for &v in triangle {
                assert!(
                    (normals[v as usize] - face).length() < 1e-6,
                    "a flat face has its own normal"
                );
            }
            // Same triangles in the same order, at the same positions, with the same scalars.
            for (&old, &new) in before.triangles[t].iter().zip(triangle) {
                let (old, new) = (old as usize, new as usize);
                assert_eq!(mesh.positions[new], before.positions[old]);
                assert_eq!(
                    mesh.scalars.as_ref().unwrap()[new],
                    before.scalars.as_ref().unwrap()[old]
                );
            }
        }
    }

    #[test]
    fn crease_normals_leave_gentle_bends_smooth() {
        // Two triangles folded by 20 degrees along their shared edge: one normal per
        // vertex, weighted by area (the first triangle is 4 times the second).
        let bend = 20f32.to_radians();
        let mut mesh = TriangleMesh {
            positions: vec![
                Vec3::ZERO,
                Vec3::Y,
                4.0 * Vec3::X,
                Vec3::new(-bend.cos(), 0.0, bend.sin()),
            ],
            triangles: vec![[0, 2, 1], [0, 1, 3]],
            normals: None,
            scalars: None,
        };
        let faces = [
            mesh.face_normal(0).normalize(),
            mesh.face_normal(1).normalize(),
        ];
        mesh.add_crease_normals(60f32.to_radians());
        assert_eq!(mesh.positions.len(), 4);
        let normals = mesh.normals.clone().unwrap();
        assert!((normals[0] - normals[1]).length() < 1e-6);
        let expected = (4.0 * faces[0] + faces[1]).normalize();
        assert!(
            (normals[0] - expected).length() < 1e-6,
            "{} vs {expected}",
            normals[0]
        );
    }

    /// A cone of `segments` triangles around its apex (vertex 0), over a unit
    /// circle at height -1, and, when `cap`, a planar cap fanned around its
    /// centre (the last vertex).
    fn cone(segments: u32, cap: bool) -> TriangleMesh {
        let rim = |i: u32| {
            let angle = std::f32::consts::TAU * i as f32 / segments as f32;
            Vec3::new(angle.cos(), -1.0, angle.sin())
        };
        let mut positions = vec![Vec3::ZERO];
        positions.extend((0..segments).map(rim));
        let next = |i: u32| 1 + (i + 1) % segments;
        let mut triangles: Vec<[u32; 3]> = (0..segments).map(|i| [0, next(i), 1 + i]).collect();
        if cap {
            positions.push(Vec3::new(0.0, -1.0, 0.0));
            triangles.extend((0..segments).map(|i| [segments + 1, 1 + i, next(i)]));
        }
        TriangleMesh {
            positions,
            triangles,
            normals: None,
            scalars: None,
        }
    }

    #[test]
    fn crease_normals_do_not_depend_on_how_the_vertices_are_split_into_runs() {
        // A capped cone (its rim vertices split in two) beside a cube (its
        // corners split in three), with a scalar per vertex to carry along.
        let mut mesh = cone(500, true);
        let first_corner = mesh.positions.len() as u32;
        let cube = cube();
        mesh.positions
            .extend(cube.positions.iter().map(|&p| p + 3.0 * Vec3::X));
        (mesh.triangles).extend(cube.triangles.iter().map(|t| t.map(|v| v + first_corner)));
        mesh.scalars = Some((0..mesh.positions.len()).map(|v| v as f32).collect());
        let crease = 30f32.to_radians();
        let mut whole = mesh.clone();
        whole.add_crease_normals_in_runs(crease, mesh.positions.len());
        assert!(whole.positions.len() > mesh.positions.len());
        for run_length in [1, 3, 64, VERTICES_PER_NORMAL_RUN] {
            let mut split = mesh.clone();
            split.add_crease_normals_in_runs(crease, run_length);
            assert_eq!(split, whole, "runs of {run_length} vertices");
        }
    }

    #[test]
    fn crease_normals_of_a_finely_fanned_cap_are_its_plane() {
        // 200,000 coplanar triangles around the cap's centre: one direction, so
        // linear time (comparing every pair of corners would take minutes).
        let segments = 200_000;
        let mut mesh = cone(segments, true);
        mesh.add_crease_normals(60f32.to_radians());
        let normals = mesh.normals.as_ref().unwrap();
        let at_centre: Vec<u32> = mesh.triangles[segments as usize..]
            .iter()
            .map(|triangle| triangle[0])
            .collect();
        assert!(at_centre.iter().all(|&v| v == at_centre[0]), "one vertex");
        assert_eq!(
            mesh.positions[at_centre[0] as usize],
            Vec3::new(0.0, -1.0, 0.0)
        );
        assert!((normals[at_centre[0] as usize] - Vec3::NEG_Y).length() < 1e-6);
        // Where the thin sides meet, at the apex, there are too many directions:
        // each corner keeps its face's normal.
        for (t, triangle) in mesh.triangles[..segments as usize].iter().enumerate() {
            let face = mesh.face_normal(t).normalize();
            assert_eq!(normals[triangle[0] as usize], face);
        }
    }

    #[test]
    fn corners_keep_their_faces_around_a_vertex_of_too_many_directions() {
        let limit = MAX_DIRECTIONS_AROUND_A_VERTEX as u32;
        for (segments, flat) in [(limit, false), (limit + 1, true)] {
            let mut mesh = cone(segments, false);
            mesh.add_crease_normals(60f32.to_radians());
            let normals = mesh.normals.as_ref().unwrap();
            let apex: Vec<usize> = mesh.triangles.iter().map(|t| t[0] as usize).collect();
            if flat {
                for (t, &vertex) in apex.iter().enumerate() {
                    let face = mesh.face_normal(t).normalize();
                    assert!((normals[vertex] - face).length() < 1e-6);
                }
            } else {
                // Every face within 60 degrees is averaged in: each corner's
                // normal leans from its face towards the axis.
                for (t, &vertex) in apex.iter().enumerate() {
                    let face = mesh.face_normal(t).normalize();
                    assert!(normals[vertex].y > face.y + 0.1, "{segments}");
                }
            }
        }
    }

    #[test]
    fn keys_are_numbered_by_first_appearance_before_and_after_the_map() {
        let mut numbering = FirstAppearance::default();
        for round in 0..2 {
            numbering.clear();
            // 40 different keys, each given twice, the repeats three keys late.
            let keys: Vec<[u32; 3]> = (0..40).map(|i| [i, round, 7]).collect();
            for (i, &key) in keys.iter().enumerate() {
                assert_eq!(numbering.number(key), i as u32);
                if i >= 3 {
                    assert_eq!(numbering.number(keys[i - 3]), i as u32 - 3);
                }
            }
        }
    }

    #[test]
    fn empty_mesh_is_rejected() {
        let mesh = TriangleMesh::default();
        assert_eq!(mesh.validate(), Err(MeshError::NoTriangles));
        assert_eq!(mesh.bounds(), None);
    }

    #[test]
    fn non_finite_vertex_is_rejected() {
        let mut mesh = one_triangle();
        mesh.positions[1].y = f32::NAN;
        assert!(matches!(
            mesh.validate(),
            Err(MeshError::NonFiniteVertex { index: 1, .. })
        ));
        mesh.positions[1].y = f32::INFINITY;
        assert!(matches!(
            mesh.validate(),
            Err(MeshError::NonFiniteVertex { index: 1, .. })
        ));
    }

    #[test]
    fn meshes_too_large_or_too_small_for_f32_are_rejected() {
        for (scale, accepted) in [(1e17, true), (1e19, false), (1e-17, true), (1e-19, false)] {
            let mut mesh = one_triangle();
            mesh.positions.truncate(3);
            mesh.positions.iter_mut().for_each(|p| *p *= scale);
            let result = mesh.validate();
            assert_eq!(result.is_ok(), accepted, "{scale}: {result:?}");
            if !accepted {
                assert!(matches!(result, Err(MeshError::OutOfScale { .. })));
                assert!(result.unwrap_err().to_string().contains("rescale the mesh"));
            }
        }
    }

    #[test]
    fn out_of_range_index_is_rejected() {
        let mut mesh = one_triangle();
        mesh.triangles.push([0, 2, 4]);
        let error = mesh.validate().unwrap_err();
        assert_eq!(
            error,
            MeshError::VertexIndexOutOfRange {
                triangle: 1,
                vertex: 4,
                vertex_count: 4
            }
        );
        assert!(error.to_string().contains("triangle 1 uses vertex 4"));
    }

    /// A strip of `triangles` triangles over `triangles + 2` vertices, with
    /// coordinates that differ everywhere, so each chunk has its own box.
    fn strip(triangles: u32) -> TriangleMesh {
        TriangleMesh {
            positions: (0..triangles + 2)
                .map(|i| Vec3::new(i as f32, (i % 7) as f32 - 3.0, -((i % 13) as f32)))
                .collect(),
            triangles: (0..triangles).map(|t| [t, t + 1, t + 2]).collect(),
            normals: None,
            scalars: None,
        }
    }

    #[test]
    fn checks_and_bounds_across_parallel_chunks_are_the_serial_ones() {
        // Three chunks and a partial fourth, on 1, 2 and 8 threads.
        let triangles = 3 * PARALLEL_CHUNK as u32 + 17;
        let mesh = strip(triangles);
        let serial = mesh
            .triangles
            .iter()
            .flatten()
            .map(|&v| mesh.positions[v as usize])
            .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p), hi.max(p))
            });
        for threads in [1, 2, 8] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let bounds = mesh.validated_bounds().unwrap();
                assert_eq!((bounds.min, bounds.max), serial, "{threads} threads");
                // Two bad vertices and two bad triangles in different chunks:
                // the first of each is the one named.
                let mut bad = mesh.clone();
                let (first, later) = (PARALLEL_CHUNK + 5, 2 * PARALLEL_CHUNK + 1);
                bad.positions[later].x = f32::NAN;
                bad.positions[first].z = f32::INFINITY;
                assert!(matches!(
                    bad.validate(),
                    Err(MeshError::NonFiniteVertex { index, .. }) if index == first
                ));
                let mut bad = mesh.clone();
                let vertex_count = bad.positions.len();
                bad.triangles[later][0] = vertex_count as u32;
                bad.triangles[first][2] = vertex_count as u32 + 9;
                assert_eq!(
                    bad.validate(),
                    Err(MeshError::VertexIndexOutOfRange {
                        triangle: first,
                        vertex: vertex_count as u32 + 9,
                        vertex_count,
                    })
                );
            });
        }
    }

    #[test]
    fn attribute_lengths_must_match_vertices() {
        let mut mesh = one_triangle();
        mesh.scalars = Some(vec![0.0; 3]);
        assert!(matches!(
            mesh.validate(),
            Err(MeshError::AttributeLengthMismatch {
                what: "scalars",
                ..
            })
        ));
        mesh.scalars = None;
        mesh.normals = Some(vec![Vec3::Z; 4]);
        assert_eq!(mesh.validate(), Ok(()));
        mesh.normals.as_mut().unwrap()[2] = Vec3::NAN;
        assert!(matches!(
            mesh.validate(),
            Err(MeshError::NonFiniteNormal { index: 2, .. })
        ));
    }
}
