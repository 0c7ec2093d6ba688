//! Wavefront OBJ loading (through `tobj`).
//!
//! tobj triangulates a face `v0 v1 … vn` as the fan `(v0,v1,v2), (v0,v2,v3), …`
//! (its `export_faces`: quads become `(a,b,c),(a,c,d)`, polygons a fan) and emits
//! one model per `o`/`g`/`usemtl` run, in file order. Concatenating the models in
//! order therefore numbers triangles exactly as the language reference demands
//! (docs/language.md §8).
//!
//! Materials ([`load_obj_with_materials`]): each `mtllib` is read relative to the
//! OBJ's folder. A missing MTL file is not an error (every triangle then gets the
//! default material, silently); an unreadable or malformed one is. Material id 0
//! is the default material, for triangles before any `usemtl` or after a
//! `usemtl` of a name no MTL defines; the MTL materials follow as ids 1, 2, … in
//! the order the MTL files define them.

use crate::mesh::{MeshError, TriangleMesh};
use crate::shading::{Material, MeshMaterials, ShadingError};
use glam::Vec3;
use std::cell::RefCell;
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
    #[error("cannot read material library {path}: {reason}")]
    MaterialLibrary { path: PathBuf, reason: String },
    #[error("{path}: {source}")]
    BadMaterial { path: PathBuf, source: ShadingError },
}

/// Loads every model of an OBJ file into one mesh, in file order. Materials are
/// not read (`mtllib` is ignored). Vertex normals are kept only when every
/// vertex has one.
pub fn load_obj(path: &Path) -> Result<TriangleMesh, ObjError> {
    let file = open(path)?;
    read_obj(&mut BufReader::new(file)).map_err(|error| read_error(path, error))
}

/// [`load_obj`] with the materials of the OBJ's MTL files and each triangle's
/// material id (see the module documentation).
pub fn load_obj_with_materials(path: &Path) -> Result<(TriangleMesh, MeshMaterials), ObjError> {
    let file = open(path)?;
    let folder = path.parent().unwrap_or(Path::new("")).to_path_buf();
    // tobj's loader callback cannot return our errors: keep the first one here.
    let failure: RefCell<Option<ObjError>> = RefCell::new(None);
    let loader = |name: &Path| -> tobj::MTLLoadResult {
        let mtl_path = folder.join(name);
        let file = match File::open(&mtl_path) {
            Ok(file) => file,
            Err(error) if error.kind() == std::io::ErrorKind::NotFound => {
                return Ok(Default::default());
            }
            Err(error) => {
                failure
                    .borrow_mut()
                    .get_or_insert(ObjError::MaterialLibrary {
                        path: mtl_path,
                        reason: error.to_string(),
                    });
                return Err(tobj::LoadError::OpenFileFailed);
            }
        };
        tobj::load_mtl_buf(&mut BufReader::new(file)).inspect_err(|error| {
            failure
                .borrow_mut()
                .get_or_insert(ObjError::MaterialLibrary {
                    path: mtl_path.clone(),
                    reason: format!("malformed MTL ({error})"),
                });
        })
    };
    let result = read_models(&mut BufReader::new(file), loader);
    if let Some(error) = failure.into_inner() {
        return Err(error);
    }
    let (mesh, model_materials, mtl_materials) = result.map_err(|error| read_error(path, error))?;
    let mut materials = MeshMaterials::default();
    for mtl in &mtl_materials {
        let material = Material::from_mtl(mtl).map_err(|source| ObjError::BadMaterial {
            path: path.to_path_buf(),
            source,
        })?;
        materials.materials.push(material);
    }
    if model_materials.iter().any(|&(_, id)| id.is_some()) {
        materials.triangle_materials = model_materials
            .iter()
            .flat_map(|&(triangles, id)| {
                // tobj only hands out ids of loaded materials; +1 skips the default.
                let id = id.map_or(0, |id| id as u32 + 1);
                std::iter::repeat_n(id, triangles)
            })
            .collect();
    }
    Ok((mesh, materials))
}

fn open(path: &Path) -> Result<File, ObjError> {
    File::open(path).map_err(|source| ObjError::Open {
        path: path.to_path_buf(),
        source,
    })
}

fn read_error(path: &Path, error: ReadError) -> ObjError {
    match error {
        ReadError::Parse(source) => ObjError::Parse {
            path: path.to_path_buf(),
            source,
        },
        ReadError::InvalidMesh(source) => ObjError::InvalidMesh {
            path: path.to_path_buf(),
            source,
        },
    }
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
    // An unreadable mtllib must not fail the load: materials are not read here.
    read_models(reader, |_| Err(tobj::LoadError::OpenFileFailed)).map(|(mesh, _, _)| mesh)
}

/// Each model's triangle count and material id, in file order.
type ModelMaterials = Vec<(usize, Option<usize>)>;

fn read_models(
    reader: &mut impl BufRead,
    material_loader: impl Fn(&Path) -> tobj::MTLLoadResult,
) -> Result<(TriangleMesh, ModelMaterials, Vec<tobj::Material>), ReadError> {
    let options = tobj::LoadOptions {
        single_index: true,
        triangulate: true,
        ignore_points: true,
        ignore_lines: true,
    };
    let (models, materials) =
        tobj::load_obj_buf(reader, &options, material_loader).map_err(ReadError::Parse)?;
    // The loader's own failures are reported by the caller.
    let materials = materials.unwrap_or_default();

    let mut mesh = TriangleMesh::default();
    let mut normals = Vec::new();
    let mut every_vertex_has_a_normal = true;
    let mut model_materials = Vec::with_capacity(models.len());
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
        model_materials.push((part.indices.len() / 3, part.material_id));
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
    Ok((mesh, model_materials, materials))
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

    const TWO_MATERIALS: &str = "\
mtllib scene.mtl
v 0 0 0
v 1 0 0
v 0 1 0
v 0 0 1
f 1 2 3
usemtl red
f 1 2 4
f 1 3 4
usemtl mirror
f 2 3 4
usemtl nowhere
f 1 2 3
usemtl red
f 4 3 2
";

    #[test]
    fn materials_follow_usemtl_in_file_order() {
        let mtl = "\
# two materials
newmtl mirror
Kd 0.1 0.1 0.1
Ks 0.9 0.9 0.9
Ns 500
illum 3

newmtl red
Kd 1 0 0
Pm 0.25
";
        let dir = write_temp("scene.obj", TWO_MATERIALS);
        std::fs::write(dir.path().join("scene.mtl"), mtl).unwrap();
        let (mesh, materials) = load_obj_with_materials(&dir.path().join("scene.obj")).unwrap();
        assert_eq!(mesh.triangles.len(), 6);
        let names: Vec<&str> = materials
            .materials
            .iter()
            .map(|m| m.name.as_str())
            .collect();
        assert_eq!(names, ["default", "mirror", "red"]);
        assert_eq!(materials.triangle_materials, [0, 2, 2, 1, 0, 2]);
        let mirror = &materials.materials[1];
        assert_eq!(mirror.kd, Vec3::splat(0.1));
        assert_eq!(mirror.ns, 500.0);
        assert!((mirror.reflectivity - 0.9).abs() < 1e-6);
        let red = &materials.materials[2];
        assert_eq!(
            (red.kd, red.ks, red.reflectivity),
            (Vec3::X, Vec3::splat(0.3), 0.25)
        );
        // The same file without its MTL: all default, no error.
        std::fs::remove_file(dir.path().join("scene.mtl")).unwrap();
        let (mesh, materials) = load_obj_with_materials(&dir.path().join("scene.obj")).unwrap();
        assert_eq!(mesh.triangles.len(), 6);
        assert_eq!(materials, MeshMaterials::default());
    }

    #[test]
    fn malformed_material_library_is_an_error() {
        let dir = write_temp("scene.obj", TWO_MATERIALS);
        let path = dir.path().join("scene.obj");
        std::fs::write(dir.path().join("scene.mtl"), "newmtl red\nKd 1 zero 0\n").unwrap();
        let error = load_obj_with_materials(&path).unwrap_err();
        assert!(matches!(error, ObjError::MaterialLibrary { .. }), "{error}");
        assert!(error.to_string().contains("scene.mtl"), "{error}");
        std::fs::write(dir.path().join("scene.mtl"), "newmtl red\nrefl much\n").unwrap();
        let error = load_obj_with_materials(&path).unwrap_err().to_string();
        assert!(
            error.contains("`red`") && error.contains("refl much"),
            "{error}"
        );
        // load_obj ignores materials altogether.
        assert_eq!(load_obj(&path).unwrap().triangles.len(), 6);
    }

    #[test]
    fn missing_material_library_is_ignored() {
        let mesh =
            read("mtllib nowhere.mtl\nusemtl x\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        assert_eq!(mesh.triangles.len(), 1);
    }
}
