//! Wavefront OBJ loading (through `tobj`).
//!
//! tobj triangulates a face `v0 v1 … vn` as the fan `(v0,v1,v2), (v0,v2,v3), …`
//! (its `export_faces`: quads become `(a,b,c),(a,c,d)`, polygons a fan) and emits
//! one model per `o`/`g`/`usemtl` run, in file order. Concatenating the models in
//! order therefore numbers triangles exactly as the language spec demands.

use crate::mesh::{MeshError, TriangleMesh};
use glam::Vec3;
use std::fs::File;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use thiserror::Error;

#[derive(Debug, Error)]
pub enum ObjError {
    #[error("cannot open {path}: {source}")]
    Open {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: malformed OBJ ({source})")]
    Parse {
        path: PathBuf,
        source: tobj::LoadError,
    },
    #[error("{path}: {source}")]
    InvalidMesh { path: PathBuf, source: MeshError },
}

/// Loads every model of an OBJ file into one mesh, in file order. Materials are
/// not read (`mtllib` is ignored). Vertex normals are kept only when every
/// vertex has one.
pub fn load_obj(path: &Path) -> Result<TriangleMesh, ObjError> {
    let file = File::open(path).map_err(|source| ObjError::Open {
        path: path.to_path_buf(),
        source,
    })?;
    read_obj(&mut BufReader::new(file)).map_err(|error| match error {
        ReadError::Parse(source) => ObjError::Parse {
            path: path.to_path_buf(),
            source,
        },
        ReadError::InvalidMesh(source) => ObjError::InvalidMesh {
            path: path.to_path_buf(),
            source,
        },
    })
}

/// Failures of [`read_obj`], which has no path to report.
#[derive(Debug, Error)]
pub enum ReadError {
    #[error("malformed OBJ ({0})")]
    Parse(tobj::LoadError),
    #[error(transparent)]
    InvalidMesh(MeshError),
}

/// Reads OBJ text from any reader; see [`load_obj`].
pub fn read_obj(reader: &mut impl BufRead) -> Result<TriangleMesh, ReadError> {
    let options = tobj::LoadOptions {
        single_index: true,
        triangulate: true,
        ignore_points: true,
        ignore_lines: true,
    };
    // Materials are not part of the scene yet; an unreadable mtllib must not fail the load.
    let (models, _materials) =
        tobj::load_obj_buf(reader, &options, |_| Err(tobj::LoadError::OpenFileFailed))
            .map_err(ReadError::Parse)?;

    let mut mesh = TriangleMesh::default();
    let mut normals = Vec::new();
    let mut every_vertex_has_a_normal = true;
    for model in &models {
        let part = &model.mesh;
        let first_vertex = u32::try_from(mesh.positions.len())
            .map_err(|_| ReadError::Parse(tobj::LoadError::GenericFailure))?;
        mesh.positions.extend(
            part.positions
                .chunks_exact(3)
                .map(|p| Vec3::new(p[0], p[1], p[2])),
        );
        mesh.triangles.extend(
            part.indices
                .chunks_exact(3)
                .map(|t| [t[0], t[1], t[2]].map(|v| v + first_vertex)),
        );
        // tobj pushes a normal only for vertices that reference one.
        if part.normals.len() == part.positions.len() {
            normals.extend(
                part.normals
                    .chunks_exact(3)
                    .map(|n| Vec3::new(n[0], n[1], n[2])),
            );
        } else {
            every_vertex_has_a_normal = false;
        }
    }
    if every_vertex_has_a_normal && !normals.is_empty() {
        mesh.normals = Some(normals);
    }
    mesh.validate().map_err(ReadError::InvalidMesh)?;
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Cursor;

    fn read(text: &str) -> Result<TriangleMesh, ReadError> {
        read_obj(&mut Cursor::new(text))
    }

    fn write_temp(name: &str, text: &str) -> tempfile::TempDir {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join(name), text).unwrap();
        dir
    }

    #[test]
    fn polygons_are_fan_triangulated_in_file_order() {
        let text = "\
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 2 0 0
v 2 1 0
f 5 6 3
f 1 2 3 4
f 1 2 5 6 3
";
        let dir = write_temp("fan.obj", text);
        let mesh = load_obj(&dir.path().join("fan.obj")).unwrap();
        let corners: Vec<[Vec3; 3]> = (0..mesh.triangles.len())
            .map(|i| mesh.triangle_vertices(i))
            .collect();
        let p = |i: usize| {
            [
                Vec3::ZERO,
                Vec3::X,
                Vec3::new(1.0, 1.0, 0.0),
                Vec3::Y,
                Vec3::new(2.0, 0.0, 0.0),
                Vec3::new(2.0, 1.0, 0.0),
            ][i - 1]
        };
        let expected = vec![
            [p(5), p(6), p(3)],
            [p(1), p(2), p(3)],
            [p(1), p(3), p(4)],
            [p(1), p(2), p(5)],
            [p(1), p(5), p(6)],
            [p(1), p(6), p(3)],
        ];
        assert_eq!(corners, expected);
        assert_eq!(mesh.normals, None);
    }

    #[test]
    fn groups_and_objects_are_merged_in_file_order() {
        let text = "\
o first
v 0 0 0
v 1 0 0
v 0 1 0
f 1 2 3
g second
v 0 0 5
v 1 0 5
v 0 1 5
f 4 5 6
usemtl other
f -3 -1 -2
o third
f 1 3 2
";
        let mesh = read(text).unwrap();
        assert_eq!(mesh.triangles.len(), 4);
        let z: Vec<f32> = (0..4).map(|i| mesh.triangle_vertices(i)[0].z).collect();
        assert_eq!(z, vec![0.0, 5.0, 5.0, 0.0]);
        assert_eq!(mesh.triangle_vertices(2)[1], Vec3::new(0.0, 1.0, 5.0));
        assert_eq!(mesh.triangle_vertices(3)[1], Vec3::new(0.0, 1.0, 0.0));
    }

    #[test]
    fn vertex_normals_are_kept_when_complete() {
        let text = "\
v 0 0 0
v 1 0 0
v 0 1 0
vn 0 0 1
f 1//1 2//1 3//1
";
        let mesh = read(text).unwrap();
        assert_eq!(mesh.normals, Some(vec![Vec3::Z; 3]));

        let partial = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2 3\n";
        assert_eq!(read(partial).unwrap().normals, None);
    }

    #[test]
    fn nan_vertex_is_an_error() {
        let error = read("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n").unwrap_err();
        assert!(matches!(
            error,
            ReadError::InvalidMesh(MeshError::NonFiniteVertex { index: 1, .. })
        ));
    }

    #[test]
    fn bad_index_is_an_error() {
        for text in [
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -4\n",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n",
        ] {
            assert!(
                matches!(read(text), Err(ReadError::Parse(_))),
                "accepted {text:?}"
            );
        }
    }

    #[test]
    fn malformed_vertex_is_an_error() {
        assert!(matches!(
            read("v 0 zero 0\n"),
            Err(ReadError::Parse(tobj::LoadError::PositionParseError))
        ));
    }

    #[test]
    fn file_without_faces_is_an_error() {
        let dir = write_temp("empty.obj", "v 0 0 0\n# nothing else\n");
        let error = load_obj(&dir.path().join("empty.obj")).unwrap_err();
        assert!(matches!(
            error,
            ObjError::InvalidMesh {
                source: MeshError::NoTriangles,
                ..
            }
        ));
        assert!(error.to_string().contains("empty.obj"));
    }

    #[test]
    fn missing_file_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("does-not-exist.obj");
        let error = load_obj(&path).unwrap_err();
        assert!(matches!(error, ObjError::Open { .. }));
        assert!(error.to_string().contains("does-not-exist.obj"));
    }

    #[test]
    fn missing_material_library_is_ignored() {
        let mesh =
            read("mtllib nowhere.mtl\nusemtl x\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        assert_eq!(mesh.triangles.len(), 1);
    }
}
