//! Indexed triangle meshes as the tracer receives them from a file or a generator.

use glam::Vec3;
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

    /// Length of the box's diagonal.
    pub fn diagonal(&self) -> f32 {
        (self.max - self.min).length()
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
}

/// Triangle ids are `u32` and `u32::MAX` marks a miss, so the count must stay below it.
pub const MAX_TRIANGLES: usize = u32::MAX as usize - 1;

impl TriangleMesh {
    /// Checks everything later stages rely on: at least one triangle, finite
    /// vertices, indices in range, attribute arrays matching the vertex count.
    pub fn validate(&self) -> Result<(), MeshError> {
        if self.triangles.is_empty() {
            return Err(MeshError::NoTriangles);
        }
        if self.triangles.len() > MAX_TRIANGLES {
            return Err(MeshError::TooManyTriangles {
                triangles: self.triangles.len(),
                max: MAX_TRIANGLES,
            });
        }
        if let Some((index, &position)) = self
            .positions
            .iter()
            .enumerate()
            .find(|(_, p)| !p.is_finite())
        {
            return Err(MeshError::NonFiniteVertex { index, position });
        }
        let vertex_count = self.positions.len();
        for (triangle, indices) in self.triangles.iter().enumerate() {
            if let Some(&vertex) = indices.iter().find(|&&v| v as usize >= vertex_count) {
                return Err(MeshError::VertexIndexOutOfRange {
                    triangle,
                    vertex,
                    vertex_count,
                });
            }
        }
        if let Some(normals) = &self.normals {
            if normals.len() != vertex_count {
                return Err(MeshError::AttributeLengthMismatch {
                    what: "normals",
                    vertices: vertex_count,
                    values: normals.len(),
                });
            }
            if let Some((index, &normal)) = normals.iter().enumerate().find(|(_, n)| !n.is_finite())
            {
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
        Ok(())
    }

    /// The box around the vertices that triangles use (unused vertices do not
    /// count: they cannot be hit). `None` for a mesh without triangles.
    pub fn bounds(&self) -> Option<Bounds> {
        let mut vertices = self
            .triangles
            .iter()
            .flatten()
            .filter_map(|&v| self.positions.get(v as usize));
        let first = *vertices.next()?;
        let (min, max) = vertices.fold((first, first), |(min, max), &p| (min.min(p), max.max(p)));
        Some(Bounds { min, max })
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

    /// Smooth, area-weighted vertex normals: each vertex gets the normalised sum
    /// of the face normals `(v1 - v0) × (v2 - v0)` (whose length is twice the
    /// area) of the triangles that use it. A vertex that no triangle (or only
    /// degenerate ones) uses, or whose faces cancel out, gets zero; the shading
    /// then falls back to the face normal. Indices must be valid.
    pub fn smooth_normals(&self) -> Vec<Vec3> {
        let mut normals = vec![Vec3::ZERO; self.positions.len()];
        for (index, triangle) in self.triangles.iter().enumerate() {
            let normal = self.face_normal(index);
            for &vertex in triangle {
                normals[vertex as usize] += normal;
            }
        }
        for normal in &mut normals {
            *normal = normal.normalize_or_zero();
        }
        normals
    }
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
        assert_eq!(mesh.face_normal(0), Vec3::Z);
    }

    #[test]
    fn smooth_normals_are_area_weighted() {
        // A big triangle in z = 0 and a small one in x = 0 sharing the edge 0-1.
        let mesh = TriangleMesh {
            positions: vec![
                Vec3::ZERO,
                Vec3::Y,
                Vec3::new(4.0, 0.0, 0.0),
                Vec3::new(0.0, 0.0, 1.0),
                Vec3::splat(9.0),
            ],
            triangles: vec![[0, 2, 1], [0, 1, 3]],
            normals: None,
            scalars: None,
        };
        let normals = mesh.smooth_normals();
        // Faces: +z with area 2 (weight 4), +x with area 0.5 (weight 1).
        let shared = Vec3::new(1.0, 0.0, 4.0).normalize();
        assert!((normals[0] - shared).length() < 1e-6);
        assert!((normals[1] - shared).length() < 1e-6);
        assert_eq!(normals[2], Vec3::Z);
        assert_eq!(normals[3], Vec3::X);
        assert_eq!(normals[4], Vec3::ZERO);
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
