//! VTK polydata and unstructured grids as triangle meshes: `.vtp`, `.vtu`,
//! legacy `.vtk` (POLYDATA, UNSTRUCTURED_GRID), and the pieces of `.pvtp`
//! and `.pvtu`.
//!
//! Triangles are numbered in file order, cell by cell:
//! - polydata: polygons fan-triangulated (`(v0,v1,v2), (v0,v2,v3), …`), then
//!   triangle strips (triangle `j` of a strip is `(p[j], p[j+1], p[j+2])`,
//!   every odd one with its first two corners swapped to keep the strip's
//!   winding, as VTK does); vertices and lines make no triangles;
//! - unstructured grids: triangles, quads, pixels, polygons and strips as
//!   they are; tetrahedra, hexahedra, voxels, wedges and pyramids by their
//!   *external* faces (those of no other 3-D cell of the piece: a face is
//!   matched by its set of point ids), each in VTK's face order and fanned;
//!   vertices and lines make none; any other (quadratic, polyhedron…) cell
//!   type is an error.
//!
//! A field on points becomes the mesh's per-vertex scalars. A field on
//! cells colours flat: after the mesh's crease normals are computed (so the
//! shading stays smooth across cells), each cell gets its own copy of its
//! corners, carrying the cell's value. Each piece of a parallel file is a
//! mesh of its own (its external faces are its own), as a rank that reads
//! only that piece sees it.

use super::{inline_pieces, parse, Association, Field, FieldChoice, VtkError, VtkKind};
use crate::equal_keys::{for_each_run_of_equal_keys, Keyed};
use crate::mesh::TriangleMesh;
use glam::Vec3;
use rayon::prelude::*;
use std::collections::HashMap;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use vtkio::model::{CellType, DataSet, IOBuffer, VertexNumbers};

/// The meshes of `path`: one for a serial file (its pieces joined), one per
/// piece file, in order, for a `.pvtp` or `.pvtu`. `field` chooses the
/// scalars; on a parallel file the array the first piece's choice names is
/// taken from every piece.
pub fn read_mesh_pieces(path: &Path, field: &FieldChoice) -> Result<Vec<TriangleMesh>, VtkError> {
    if VtkKind::of(path) != Some(VtkKind::Mesh { parallel: true }) {
        return Ok(vec![read_mesh(path, field)?.0]);
    }
    let mut choice = field.clone();
    let mut meshes = Vec::new();
    for file in super::piece_files(path)? {
        let (mesh, concrete) = read_mesh(&file, &choice)?;
        choice = concrete.unwrap_or(choice);
        meshes.push(mesh);
    }
    Ok(meshes)
}

/// The mesh of one serial file (`.vtp`, `.vtu`, legacy `.vtk`), and the
/// field's choice made concrete (`None` when it has no arrays).
pub fn read_mesh(
    path: &Path,
    field: &FieldChoice,
) -> Result<(TriangleMesh, Option<FieldChoice>), VtkError> {
    let mut builder = Builder::default();
    match parse(path)? {
        DataSet::PolyData { pieces, .. } => {
            for piece in inline_pieces(path, pieces)? {
                let points = builder.points(path, &piece.points)?;
                let lists = [&piece.verts, &piece.lines, &piece.polys, &piece.strips]
                    .map(|list| list.as_ref().map(|l| cell_list(path, l, points)).transpose());
                let [verts, lines, polys, strips] = lists;
                let (verts, lines, polys, strips) = (verts?, lines?, polys?, strips?);
                let count = |l: &Option<CellList>| l.as_ref().map_or(0, CellList::len);
                let cells = count(&verts) + count(&lines) + count(&polys) + count(&strips);
                let mut cell = count(&verts) + count(&lines);
                for (list, strip) in [(polys, false), (strips, true)] {
                    for corners in list.iter().flat_map(CellList::iter) {
                        builder.face(corners, strip, cell);
                        cell += 1;
                    }
                }
                builder.field(path, field, &piece.data, points, cells)?;
            }
        }
        DataSet::UnstructuredGrid { pieces, .. } => {
            for piece in inline_pieces(path, pieces)? {
                let points = builder.points(path, &piece.points)?;
                let list = cell_list(path, &piece.cells.cell_verts, points)?;
                if list.len() != piece.cells.types.len() {
                    return Err(VtkError::new(
                        path,
                        format!(
                            "{} cells but {} cell types",
                            list.len(),
                            piece.cells.types.len()
                        ),
                    ));
                }
                builder.unstructured(path, &list, &piece.cells.types)?;
                builder.field(path, field, &piece.data, points, list.len())?;
            }
        }
        DataSet::ImageData { .. } => {
            return Err(VtkError::new(
                path,
                "image data is a volume, not a mesh (render its isosurface with --iso LEVEL)",
            ))
        }
        _ => {
            return Err(VtkError::new(
                path,
                "dpp reads VTK polydata and unstructured grids as meshes, image data as volumes; not structured or rectilinear grids",
            ))
        }
    }
    Ok(builder.finish())
}

/// A mesh assembled piece by piece.
#[derive(Default)]
struct Builder {
    positions: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
    /// Each triangle's cell, numbered over all pieces.
    cells: Vec<u32>,
    /// The first point and cell of the current piece, and the cells of the
    /// pieces before the next.
    first_point: u32,
    first_cell: u32,
    next_cell: u32,
    /// Per point or per cell, pieces joined; `None` once a piece had none.
    scalars: Option<(Association, Vec<f32>)>,
    choice: Option<FieldChoice>,
    pieces: usize,
}

impl Builder {
    /// Adds a piece's points; returns their number.
    fn points(&mut self, path: &Path, points: &IOBuffer) -> Result<usize, VtkError> {
        let coordinates: Vec<f64> = points
            .cast_into()
            .ok_or_else(|| VtkError::new(path, "the points are a bit array"))?;
        if !coordinates.len().is_multiple_of(3) {
            return Err(VtkError::new(
                path,
                format!(
                    "{} point coordinates is not a multiple of 3",
                    coordinates.len()
                ),
            ));
        }
        self.first_point = self.positions.len() as u32;
        self.first_cell = self.next_cell;
        let count = coordinates.len() / 3;
        if self.positions.len() + count > u32::MAX as usize {
            return Err(VtkError::new(path, "more than 2³² points"));
        }
        (self.positions).extend(
            (coordinates.chunks_exact(3)).map(|p| Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32)),
        );
        Ok(count)
    }

    /// A polygon (fanned) or strip of the current piece's point ids.
    fn face(&mut self, corners: &[u32], strip: bool, cell: usize) {
        let at = |i: usize| corners[i] + self.first_point;
        let cell = self.first_cell + cell as u32;
        for i in 1..corners.len().saturating_sub(1) {
            let triangle = match strip {
                false => [at(0), at(i), at(i + 1)],
                true if i % 2 == 1 => [at(i - 1), at(i), at(i + 1)],
                true => [at(i), at(i - 1), at(i + 1)],
            };
            self.triangles.push(triangle);
            self.cells.push(cell);
        }
    }

    fn unstructured(
        &mut self,
        path: &Path,
        list: &CellList,
        types: &[CellType],
    ) -> Result<(), VtkError> {
        let mut shapes = Vec::with_capacity(types.len());
        for (cell, (corners, &kind)) in list.iter().zip(types).enumerate() {
            let shape = Shape::of(kind).ok_or_else(|| {
                VtkError::new(
                    path,
                    format!(
                        "cell {cell} is a {kind:?} (VTK type {}), which dpp does not read: linear cells only (vertex, line, triangle, strip, polygon, pixel, quad, tetra, voxel, hexahedron, wedge, pyramid)",
                        kind as u8
                    ),
                )
            })?;
            if let Some(needed) = shape.points() {
                if corners.len() != needed {
                    return Err(VtkError::new(
                        path,
                        format!(
                            "cell {cell} is a {kind:?} of {} points; it needs {needed}",
                            corners.len()
                        ),
                    ));
                }
            }
            shapes.push(shape);
        }
        // Each 3-D cell's faces by their sorted point ids, in cell order.
        let key = |corners: &[u32], face: &[usize]| {
            let mut key = [u32::MAX; 4];
            for (k, &f) in key.iter_mut().zip(face) {
                *k = corners[f];
            }
            key.sort_unstable();
            key
        };
        let keys: Vec<[u32; 4]> = (list.iter().zip(&shapes))
            .flat_map(|(corners, shape)| shape.faces().iter().map(move |face| key(corners, face)))
            .collect();
        if u32::try_from(keys.len()).is_err() {
            return Err(VtkError::new(path, "more than 2³² faces of 3-D cells"));
        }
        let mut external = faces_of_one_cell(&keys).into_iter();
        let mut face = Vec::with_capacity(4);
        for (cell, (corners, shape)) in list.iter().zip(&shapes).enumerate() {
            match shape {
                Shape::Surface { strip } => self.face(corners, *strip, cell),
                Shape::Pixel => self.face(
                    &[corners[0], corners[1], corners[3], corners[2]],
                    false,
                    cell,
                ),
                Shape::Solid(_) => {
                    for local in shape.faces() {
                        if external.next() == Some(true) {
                            face.clear();
                            face.extend(local.iter().map(|&f| corners[f]));
                            self.face(&face, false, cell);
                        }
                    }
                }
                Shape::None => {}
            }
        }
        Ok(())
    }

    /// The current piece's field.
    fn field(
        &mut self,
        path: &Path,
        choice: &FieldChoice,
        attributes: &vtkio::model::Attributes,
        points: usize,
        cells: usize,
    ) -> Result<(), VtkError> {
        let first_piece = self.pieces == 0;
        self.pieces += 1;
        self.next_cell = self.first_cell.saturating_add(cells as u32);
        let choice = self.choice.clone().unwrap_or_else(|| choice.clone());
        let picked = choice.pick(path, attributes, points, cells)?;
        let Some((
            Field {
                association,
                values,
            },
            concrete,
        )) = picked
        else {
            self.scalars = None;
            return Ok(());
        };
        match &mut self.scalars {
            None if first_piece => self.scalars = Some((association, values)),
            Some((own, all)) if *own == association => all.extend(values),
            _ => self.scalars = None,
        }
        self.choice = Some(concrete);
        Ok(())
    }

    fn finish(self) -> (TriangleMesh, Option<FieldChoice>) {
        let mut mesh = TriangleMesh {
            positions: self.positions,
            triangles: self.triangles,
            normals: None,
            scalars: None,
        };
        match self.scalars {
            Some((Association::Point, values)) => mesh.scalars = Some(values),
            Some((Association::Cell, values)) => mesh = flat_by_cell(mesh, &self.cells, &values),
            None => {}
        }
        (mesh, self.choice)
    }
}

/// Gives each cell its own copies of its corners, with the cell's value as
/// their scalar, after computing crease normals on the shared corners.
fn flat_by_cell(mut mesh: TriangleMesh, cells: &[u32], values: &[f32]) -> TriangleMesh {
    // A broken mesh keeps no normals; the scene's checks then say what is wrong.
    if mesh.validate().is_ok() {
        mesh.add_crease_normals(crate::scene::CREASE_ANGLE_DEGREES.to_radians());
    }
    let mut copies: HashMap<(u32, u32), u32> = HashMap::new();
    let mut flat = TriangleMesh {
        normals: mesh.normals.as_ref().map(|_| Vec::new()),
        ..TriangleMesh::default()
    };
    let mut scalars = Vec::new();
    for (triangle, &cell) in mesh.triangles.iter().zip(cells) {
        let corners = triangle.map(|vertex| {
            *copies.entry((cell, vertex)).or_insert_with(|| {
                let index = flat.positions.len() as u32;
                flat.positions.push(mesh.positions[vertex as usize]);
                if let (Some(new), Some(old)) = (&mut flat.normals, &mesh.normals) {
                    new.push(old[vertex as usize]);
                }
                let value = values.get(cell as usize).copied().unwrap_or(f32::NAN);
                scalars.push(value);
                index
            })
        });
        flat.triangles.push(corners);
    }
    flat.scalars = Some(scalars);
    flat
}

/// What a cell type contributes to the surface.
#[derive(Clone, Copy)]
enum Shape {
    /// Vertices and lines: nothing.
    None,
    /// Triangle, quad, polygon (fanned) or a strip: itself.
    Surface { strip: bool },
    /// A pixel: a quad whose points are in x-then-y order.
    Pixel,
    /// A 3-D cell: its faces (VTK's face lists, outward).
    Solid(&'static [&'static [usize]]),
}

const TETRA: &[&[usize]] = &[&[0, 1, 3], &[1, 2, 3], &[2, 0, 3], &[0, 2, 1]];
const HEXAHEDRON: &[&[usize]] = &[
    &[0, 4, 7, 3],
    &[1, 2, 6, 5],
    &[0, 1, 5, 4],
    &[3, 7, 6, 2],
    &[0, 3, 2, 1],
    &[4, 5, 6, 7],
];
const VOXEL: &[&[usize]] = &[
    &[0, 4, 6, 2],
    &[1, 3, 7, 5],
    &[0, 1, 5, 4],
    &[2, 6, 7, 3],
    &[0, 2, 3, 1],
    &[4, 5, 7, 6],
];
const WEDGE: &[&[usize]] = &[
    &[0, 1, 2],
    &[3, 5, 4],
    &[0, 3, 4, 1],
    &[1, 4, 5, 2],
    &[2, 5, 3, 0],
];
const PYRAMID: &[&[usize]] = &[
    &[0, 3, 2, 1],
    &[0, 1, 4],
    &[1, 2, 4],
    &[2, 3, 4],
    &[3, 0, 4],
];

impl Shape {
    fn of(kind: CellType) -> Option<Shape> {
        Some(match kind {
            CellType::Vertex | CellType::PolyVertex | CellType::Line | CellType::PolyLine => {
                Shape::None
            }
            CellType::Triangle | CellType::Quad | CellType::Polygon => {
                Shape::Surface { strip: false }
            }
            CellType::TriangleStrip => Shape::Surface { strip: true },
            CellType::Pixel => Shape::Pixel,
            CellType::Tetra => Shape::Solid(TETRA),
            CellType::Voxel => Shape::Solid(VOXEL),
            CellType::Hexahedron => Shape::Solid(HEXAHEDRON),
            CellType::Wedge => Shape::Solid(WEDGE),
            CellType::Pyramid => Shape::Solid(PYRAMID),
            _ => return None,
        })
    }

    /// The number of points the type has, where it is fixed.
    fn points(self) -> Option<usize> {
        match self {
            Shape::Pixel => Some(4),
            Shape::Solid(faces) => faces.iter().flat_map(|f| f.iter()).max().map(|m| m + 1),
            Shape::None | Shape::Surface { .. } => None,
        }
    }

    fn faces(self) -> &'static [&'static [usize]] {
        match self {
            Shape::Solid(faces) => faces,
            _ => &[],
        }
    }
}

/// For each face (its sorted point ids), whether no other face has the same
/// ids. By a sort of the faces' ids rather than a hash map of them: on a
/// million hexahedra the map's lookups were most of reading the file
/// (docs/benchmarks.md, "External faces by a sort").
fn faces_of_one_cell(keys: &[[u32; 4]]) -> Vec<bool> {
    let faces = keys
        .par_iter()
        .enumerate()
        .map(|(index, key)| Keyed {
            key: key
                .iter()
                .fold(0u128, |packed, &id| packed << 32 | u128::from(id)),
            index: index as u32,
        })
        .collect();
    let alone: Vec<AtomicBool> = keys.par_iter().map(|_| AtomicBool::new(false)).collect();
    for_each_run_of_equal_keys(faces, |run| {
        if let [face] = run {
            alone[face.index as usize].store(true, Ordering::Relaxed);
        }
    });
    alone.into_par_iter().map(AtomicBool::into_inner).collect()
}

/// Cells as point-id lists: cell `c` is `ids[starts[c]..starts[c + 1]]`,
/// every id checked against the piece's point count.
struct CellList {
    starts: Vec<usize>,
    ids: Vec<u32>,
}

impl CellList {
    fn len(&self) -> usize {
        self.starts.len() - 1
    }

    fn iter(&self) -> impl Iterator<Item = &[u32]> {
        self.starts.windows(2).map(|w| &self.ids[w[0]..w[1]])
    }
}

/// Legacy lists (`n i1 … in`, cell after cell) and XML ones (connectivity
/// with end offsets, or start offsets with a leading 0 as legacy 5.1 files
/// have) alike, checked: no vtkio conversion, which panics on bad input.
fn cell_list(path: &Path, numbers: &VertexNumbers, points: usize) -> Result<CellList, VtkError> {
    let bad = |what: String| VtkError::new(path, what);
    let check = |id: u64| {
        if id < points as u64 {
            Ok(id as u32)
        } else {
            Err(bad(format!(
                "a cell uses point {id}, but the piece has {points} points"
            )))
        }
    };
    let mut starts = vec![0];
    let mut ids = Vec::new();
    match numbers {
        VertexNumbers::Legacy {
            num_cells,
            vertices,
        } => {
            let mut rest = &vertices[..];
            while let Some((&n, tail)) = rest.split_first() {
                let n = n as usize;
                if n > tail.len() {
                    return Err(bad(format!(
                        "a cell of {n} points runs past the end of the cell list"
                    )));
                }
                for &id in &tail[..n] {
                    ids.push(check(id as u64)?);
                }
                starts.push(ids.len());
                rest = &tail[n..];
            }
            if starts.len() - 1 != *num_cells as usize {
                return Err(bad(format!(
                    "the cell list holds {} cells, but its header says {num_cells}",
                    starts.len() - 1
                )));
            }
        }
        VertexNumbers::XML {
            connectivity,
            offsets,
        } => {
            let ends = match offsets.first() {
                Some(0) => &offsets[1..],
                _ => &offsets[..],
            };
            let mut start = 0usize;
            for &end in ends {
                let end = usize::try_from(end).unwrap_or(usize::MAX);
                if end < start || end > connectivity.len() {
                    return Err(bad(format!(
                        "cell offset {end} is out of order or past the {} point ids",
                        connectivity.len()
                    )));
                }
                for &id in &connectivity[start..end] {
                    ids.push(check(id)?);
                }
                starts.push(ids.len());
                start = end;
            }
        }
    }
    Ok(CellList { starts, ids })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vtk::{fixture, read_mutated_fixtures};

    #[test]
    fn faces_of_one_cell_are_those_whose_ids_no_other_face_has() {
        let mut random = dpp_runtime::random::SplitMix64::new(3);
        // Few distinct ids, so that many faces repeat (twice, or more).
        let keys: Vec<[u32; 4]> = (0..20_000)
            .map(|_| {
                let mut key: [u32; 4] = std::array::from_fn(|_| random.below(12) as u32);
                if random.chance(2) {
                    key[3] = u32::MAX;
                }
                key.sort_unstable();
                key
            })
            .collect();
        let mut uses: HashMap<[u32; 4], u32> = HashMap::new();
        for key in &keys {
            *uses.entry(*key).or_default() += 1;
        }
        let expected: Vec<bool> = keys.iter().map(|key| uses[key] == 1).collect();
        assert!(expected.contains(&true) && expected.contains(&false));
        assert_eq!(faces_of_one_cell(&keys), expected);
        assert_eq!(faces_of_one_cell(&[]), Vec::<bool>::new());
    }

    fn read(name: &str, field: &str) -> Result<TriangleMesh, VtkError> {
        let choice = match field {
            "" => FieldChoice::default(),
            field => field.parse().unwrap(),
        };
        read_mesh(&fixture(name), &choice).map(|(mesh, _)| mesh)
    }

    /// `expected.json`'s numbers, from VTK's own surface filter.
    fn expected() -> (usize, Vec<usize>, Vec<f32>) {
        let text = std::fs::read_to_string(fixture("expected.json")).unwrap();
        let number = |key: &str| {
            let at = text.find(&format!("\"{key}\"")).unwrap();
            let rest = &text[at + key.len() + 3..];
            let end = rest.find([']', ',', '}']).unwrap();
            rest[..=end].to_string()
        };
        let list = |key: &str| -> Vec<f32> {
            let at = text.find(&format!("\"{key}\"")).unwrap();
            let rest = &text[text[at..].find('[').unwrap() + at + 1..];
            let body = &rest[..rest.find(']').unwrap()];
            body.split(',').map(|v| v.trim().parse().unwrap()).collect()
        };
        let total = number("surface_triangles")
            .trim_end_matches([',', '}'])
            .trim()
            .parse()
            .unwrap();
        let pieces = list("piece_surface_triangles")
            .iter()
            .map(|&v| v as usize)
            .collect();
        (total, pieces, list("pressure"))
    }

    #[test]
    fn polydata_in_every_format_is_the_obj() {
        let obj = crate::obj::load_obj(&fixture("shape.obj")).unwrap();
        for name in [
            "shape.vtp",
            "shape_legacy.vtk",
            "shape_legacy_binary.vtk",
            "shape_legacy42.vtk",
        ] {
            let mesh = read(name, "").unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(mesh.positions, obj.positions, "{name}");
            assert_eq!(mesh.triangles, obj.triangles, "{name}");
            let scalars = mesh.scalars.as_ref().unwrap();
            for (p, v) in obj.positions.iter().zip(scalars) {
                assert!((v - (p.y + p.z)).abs() < 1e-6, "{name}: {v} at {p}");
            }
        }
    }

    #[test]
    fn unstructured_grids_give_their_external_faces_coloured_flat() {
        let (total, pieces, pressure) = expected();
        for name in ["cells.vtu", "cells_legacy.vtk", "cells_legacy42.vtk"] {
            let mesh = read(name, "").unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(mesh.triangles.len(), total, "{name}");
            let scalars = mesh.scalars.as_ref().unwrap();
            for triangle in &mesh.triangles {
                let values = triangle.map(|v| scalars[v as usize]);
                assert!(
                    values[0] == values[1] && values[1] == values[2],
                    "{name}: {values:?}"
                );
                assert!(pressure.contains(&values[0]), "{name}: {values:?}");
            }
            // Every cell shows: each has an external face here.
            let shown: std::collections::BTreeSet<u32> =
                scalars.iter().map(|v| v.to_bits()).collect();
            assert_eq!(shown.len(), pressure.len(), "{name}");
            let by_point = read(name, "temperature").unwrap();
            assert_eq!(by_point.triangles.len(), total);
            let t = by_point.scalars.unwrap();
            for (p, v) in by_point.positions.iter().zip(&t) {
                assert!((v - (2.0 * p.x + p.z)).abs() < 1e-5);
            }
        }
        let meshes = read_mesh_pieces(&fixture("cells.pvtu"), &FieldChoice::default()).unwrap();
        let counts: Vec<usize> = meshes.iter().map(|m| m.triangles.len()).collect();
        assert_eq!(counts, pieces);
        // What the ranks of a distributed run deal the pieces out by.
        for (n, &count) in pieces.iter().enumerate() {
            let piece = fixture(&format!("cells/cells_{n}.vtu"));
            assert_eq!(
                crate::partition::count_triangles(&piece).unwrap(),
                count as u64
            );
        }
    }

    fn write(dir: &tempfile::TempDir, name: &str, text: &str) -> std::path::PathBuf {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        path
    }

    #[test]
    fn bad_grids_say_what_is_wrong() {
        let dir = tempfile::tempdir().unwrap();
        let grid = |cells: &str, types: &str, data: &str| {
            format!(
                "# vtk DataFile Version 4.2\nt\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 4 float\n0 0 0 1 0 0 0 1 0 0 0 1\nCELLS 1 {}\n{cells}\nCELL_TYPES 1\n{types}\n{data}",
                cells.split_whitespace().count()
            )
        };
        let error = |name: &str, text: String, field: &str| {
            let path = write(&dir, name, &text);
            let choice = match field {
                "" => FieldChoice::default(),
                f => f.parse().unwrap(),
            };
            read_mesh(&path, &choice).unwrap_err().to_string()
        };
        let message = error("quadratic.vtk", grid("4 0 1 2 3", "24", ""), "");
        assert!(
            message.contains("quadratic.vtk") && message.contains("QuadraticTetra"),
            "{message}"
        );
        let message = error("range.vtk", grid("4 0 1 2 9", "10", ""), "");
        assert!(
            message.contains("point 9") && message.contains("4 points"),
            "{message}"
        );
        let message = error("short.vtk", grid("3 0 1 2", "10", ""), "");
        assert!(message.contains("needs 4"), "{message}");
        let message = error("field.vtk", grid("4 0 1 2 3", "10", ""), "p");
        assert!(message.contains("no array named `p`"), "{message}");
        let fields = "POINT_DATA 4\nFIELD f 1\np 1 3 float\n1 2 3\n";
        let message = error("length.vtk", grid("4 0 1 2 3", "10", fields), "p");
        assert!(message.contains("length.vtk"), "{message}");
    }

    #[test]
    fn an_empty_compressed_array_is_an_error_not_a_panic() {
        let error = read("shape_zlib.vtp", "").unwrap_err().to_string();
        assert!(
            error.contains("shape_zlib.vtp") && error.contains("vtkio"),
            "{error}"
        );
    }

    #[test]
    fn mutated_files_never_panic() {
        let names = [
            "shape.vtp",
            "shape_legacy_binary.vtk",
            "shape_legacy42.vtk",
            "cells.vtu",
            "cells_legacy.vtk",
        ];
        read_mutated_fixtures(&names, 5, 80, |path| {
            let _ = read_mesh(path, &FieldChoice::default());
        });
    }
}
