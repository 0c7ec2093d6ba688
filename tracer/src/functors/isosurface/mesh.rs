//! From the isosurface pipeline's `Triangle` output to a [`TriangleMesh`]
//! (written to files by [`crate::mesh_write`]).

use super::weld::{quantise, weld_corners};
use crate::mesh::TriangleMesh;
use dpp_runtime::{Column, ColumnView, ElemType};
use glam::Vec3;
use rayon::prelude::*;
use thiserror::Error;

/// The column given to [`triangles_to_mesh`] is not an array of `Triangle` records.
#[derive(Clone, Debug, Error, PartialEq)]
#[error(
    "expected an array of Triangle records (a, b, c, na, nb, nc: vec3; sa, sb, sc: f32), got {0}"
)]
pub struct NotTriangles(pub String);

/// The field columns of an array of `Triangle` records.
pub struct TriangleColumns<'a> {
    pub corners: [&'a [Vec3]; 3],
    pub normals: [&'a [Vec3]; 3],
    pub scalars: [&'a [f32]; 3],
}

impl<'a> TriangleColumns<'a> {
    /// The fields of `view`, checked by shape (9 fields: 6 `vec3`, then 3 `f32`).
    pub fn new(view: &ColumnView<'a>) -> Result<TriangleColumns<'a>, NotTriangles> {
        let ColumnView::Record { fields, .. } = view else {
            return Err(NotTriangles(format!("{:?} elements", view.elem_type())));
        };
        let types: Vec<ElemType> = fields.iter().map(ColumnView::elem_type).collect();
        let mut expected = vec![ElemType::Vec3; 6];
        expected.extend([ElemType::F32; 3]);
        if types != expected {
            return Err(NotTriangles(format!("a record with fields {types:?}")));
        }
        Ok(TriangleColumns {
            corners: [0, 1, 2].map(|i| fields[i].as_vec3()),
            normals: [3, 4, 5].map(|i| fields[i].as_vec3()),
            scalars: [6, 7, 8].map(|i| fields[i].as_f32()),
        })
    }

    pub fn len(&self) -> usize {
        self.corners[0].len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The triangles of the isosurface pipeline's `triangles` output as a mesh with
/// per-vertex normals and scalars, triangles in output order.
///
/// Without `weld` every triangle gets its own three vertices. With `weld`,
/// vertices at the same position (quantised to 2⁻²⁰ of the bounding box's
/// diagonal) become one, keeping the normal and scalar of the first triangle
/// that uses it (shared vertices are computed bit-identically by every cell, so
/// they agree), and triangles that collapse (two corners welded into one) are
/// dropped, so triangle `i` of the mesh is then not always triangle `i` of the
/// output.
pub fn triangles_to_mesh(triangles: &Column, weld: bool) -> Result<TriangleMesh, NotTriangles> {
    if weld {
        let corners = corner_bounds(triangles, None)?;
        return Ok(welded_mesh(triangles, None, corners)?.0);
    }
    let view = triangles.view();
    let columns = TriangleColumns::new(&view)?;
    let n = columns.len();
    let mut mesh = TriangleMesh {
        positions: Vec::with_capacity(3 * n),
        triangles: Vec::with_capacity(n),
        normals: Some(Vec::with_capacity(3 * n)),
        scalars: Some(Vec::with_capacity(3 * n)),
    };
    let normals = mesh.normals.as_mut().unwrap();
    let scalars = mesh.scalars.as_mut().unwrap();
    for t in 0..n {
        let first = mesh.positions.len() as u32;
        for i in 0..3 {
            mesh.positions.push(columns.corners[i][t]);
            normals.push(columns.normals[i][t]);
            scalars.push(columns.scalars[i][t]);
        }
        mesh.triangles.push([first, first + 1, first + 2]);
    }
    Ok(mesh)
}

/// The box around the finite corners of the triangles `subset` (all without
/// one): what the welding quantum is taken from. `(+inf, -inf)` for none.
pub fn corner_bounds(
    triangles: &Column,
    subset: Option<&[u32]>,
) -> Result<(Vec3, Vec3), NotTriangles> {
    let view = triangles.view();
    let columns = TriangleColumns::new(&view)?;
    let n = subset.map_or(columns.len(), <[u32]>::len);
    let empty = (Vec3::INFINITY, Vec3::NEG_INFINITY);
    let join = |(low, high): (Vec3, Vec3), (other_low, other_high): (Vec3, Vec3)| {
        (low.min(other_low), high.max(other_high))
    };
    let (min, max) = (0..n)
        .into_par_iter()
        .map(|position| {
            let t = subset.map_or(position, |subset| subset[position] as usize);
            columns
                .corners
                .iter()
                // `-0` as `+0`: which of two equal zeros `min` keeps would
                // otherwise depend on the order of the joins.
                .map(|corner| corner[t] + Vec3::ZERO)
                .filter(|p| p.is_finite())
                .fold(empty, |bounds, p| join(bounds, (p, p)))
        })
        .reduce(|| empty, join);
    Ok((min, max))
}

/// The welded mesh of the triangles `subset` (all without one), in their
/// order, with the welding quantum taken from `corners`, the box around the
/// corners of *every* triangle of the surface: a part of a distributed
/// surface, welded with the whole surface's box, drops exactly the triangles
/// the whole would (those that collapse). Also the positions in `subset` of
/// the triangles kept.
pub fn welded_mesh(
    triangles: &Column,
    subset: Option<&[u32]>,
    (min, max): (Vec3, Vec3),
) -> Result<(TriangleMesh, Vec<u32>), NotTriangles> {
    let view = triangles.view();
    let columns = TriangleColumns::new(&view)?;
    let n = subset.map_or(columns.len(), <[u32]>::len);
    let diagonal = if min.cmple(max).all() {
        (max - min).length() as f64
    } else {
        0.0
    };
    let quantum = (diagonal / f64::from(1u32 << 20)).max(f64::MIN_POSITIVE);
    // Corner `3 position + i` is corner `i` of the `position`th triangle.
    let corner = |corner: usize| {
        let position = corner / 3;
        let t = subset.map_or(position, |subset| subset[position] as usize);
        (corner % 3, t)
    };
    let welding = weld_corners(3 * n, quantise(min, quantum), |c| {
        let (i, t) = corner(c);
        quantise(columns.corners[i][t], quantum)
    });
    let positions = welding.per_vertex(|c| {
        let (i, t) = corner(c);
        columns.corners[i][t]
    });
    let normals = welding.per_vertex(|c| {
        let (i, t) = corner(c);
        columns.normals[i][t]
    });
    let scalars = welding.per_vertex(|c| {
        let (i, t) = corner(c);
        columns.scalars[i][t]
    });
    // A triangle two of whose corners became one vertex is dropped.
    let vertices = |position: usize| -> [u32; 3] {
        std::array::from_fn(|i| welding.corner_vertex[3 * position + i])
    };
    let kept: Vec<u32> = (0..n as u32)
        .into_par_iter()
        .filter(|&position| {
            let [a, b, c] = vertices(position as usize);
            a != b && b != c && c != a
        })
        .collect();
    let triangles = kept
        .par_iter()
        .map(|&position| vertices(position as usize))
        .collect();
    let mesh = TriangleMesh {
        positions,
        triangles,
        normals: Some(normals),
        scalars: Some(scalars),
    };
    Ok((mesh, kept))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::functors::isosurface::{TriangleRecord, TriangleWriter};
    use crate::register_isosurface_functors;
    use dpp_runtime::FunctorLibrary;

    /// Two triangles sharing the edge (1,0,0)-(0,1,0).
    pub(crate) fn column() -> Column {
        let mut library = FunctorLibrary::default();
        let ty = register_isosurface_functors(&mut library);
        let mut column = Column::with_capacity(ElemType::Record(ty), 2, &library.records);
        let mut writer = TriangleWriter::new(&mut column, 2).unwrap();
        writer.push(TriangleRecord {
            corners: [Vec3::ZERO, Vec3::X, Vec3::Y],
            normals: [Vec3::Z; 3],
            scalars: [1.0, 2.0, 3.0],
        });
        writer.push(TriangleRecord {
            corners: [Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
            normals: [Vec3::Z; 3],
            scalars: [2.0, 4.0, 3.0],
        });
        column
    }

    #[test]
    fn welding_shares_vertices() {
        let column = column();
        let loose = triangles_to_mesh(&column, false).unwrap();
        assert_eq!(loose.positions.len(), 6);
        assert_eq!(loose.triangles, [[0, 1, 2], [3, 4, 5]]);
        let welded = triangles_to_mesh(&column, true).unwrap();
        assert_eq!(welded.positions.len(), 4);
        assert_eq!(welded.triangles, [[0, 1, 2], [1, 3, 2]]);
        assert_eq!(welded.scalars.as_deref(), Some(&[1.0, 2.0, 3.0, 4.0][..]));
        assert_eq!(welded.normals.as_ref().unwrap().len(), 4);
        welded.validate().unwrap();
        assert!(triangles_to_mesh(&Column::U32(vec![1]), true).is_err());
    }
}
