//! PLY (Stanford polygon file) loading, through `ply-rs-bw`: ASCII and binary
//! (little and big endian), optionally gzip-compressed (`.ply.gz`; detected from
//! the data, not the name).
//!
//! What is read:
//! - the `vertex` element's `x`, `y`, `z` (any numeric type), its normals when it
//!   has all of `nx`, `ny`, `nz`, and at most one per-vertex scalar for colour
//!   maps (see [`scalar_property`]): the first of [`SCALAR_NAMES`] it has, else its
//!   first other `float`/`double` property that is not a colour or a texture
//!   coordinate;
//! - the `face` element's `vertex_indices` (or `vertex_index`) list. A face
//!   `v0 v1 … vn` becomes the fan `(v0,v1,v2), (v0,v2,v3), …`, faces in file order,
//!   as for OBJ, so triangle ids name the same triangles in both formats.
//!
//! Every other element and property is skipped. A vertex normal of length zero
//! (some exporters write them for unused vertices) drops all the file's normals:
//! they are then computed at load like for a mesh without any.
//!
//! Broken files are errors, never panics: a truncated payload, an unparsable
//! header or number, a face with fewer than three or negative indices, and (from
//! [`TriangleMesh::validate`]) indices out of range and non-finite vertices.

use crate::mesh::{MeshError, TriangleMesh};
use flate2::read::MultiGzDecoder;
use glam::Vec3;
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{
    BeginList, ElementDef, Header, PropertyAccess, PropertyAccessResult, PropertyDef, PropertyType,
    ScalarType,
};
use std::fs::File;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Vertex properties taken as the per-vertex scalar, in order of preference.
pub const SCALAR_NAMES: &[&str] = &[
    "scalar",
    "value",
    "intensity",
    "confidence",
    "quality",
    "density",
    "temperature",
    "pressure",
];

/// Vertex properties that are never the scalar (positions, normals, colours,
/// texture coordinates).
const NOT_SCALARS: &[&str] = &[
    "x",
    "y",
    "z",
    "nx",
    "ny",
    "nz",
    "red",
    "green",
    "blue",
    "alpha",
    "r",
    "g",
    "b",
    "a",
    "diffuse_red",
    "diffuse_green",
    "diffuse_blue",
    "u",
    "v",
    "s",
    "t",
    "texture_u",
    "texture_v",
];

/// The name the chosen scalar property is read under (renamed in the header).
const SCALAR_KEY: &str = "\u{1}dpp-scalar";
/// The name the face's index list is read under.
const INDICES_KEY: &str = "vertex_indices";

#[derive(Debug, Error)]
pub enum PlyError {
    #[error("cannot open {path}: {source}")]
    Open {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {source}")]
    Read { path: PathBuf, source: ReadError },
}

/// Failures of [`read_ply`], which has no path to report.
#[derive(Debug, Error)]
pub enum ReadError {
    #[error("malformed PLY ({0})")]
    Parse(String),
    #[error("{0}")]
    Unsupported(String),
    #[error("face {face} has {count} vertex indices; a face needs at least 3")]
    ShortFace { face: usize, count: usize },
    #[error("face {face} has a negative vertex index")]
    NegativeIndex { face: usize },
    #[error(transparent)]
    InvalidMesh(MeshError),
}

/// Loads a PLY file (`.ply`, or gzip-compressed) as one mesh; see the module documentation.
pub fn load_ply(path: &Path) -> Result<TriangleMesh, PlyError> {
    let reader = open_maybe_gzipped(path).map_err(|source| PlyError::Open {
        path: path.to_path_buf(),
        source,
    })?;
    read_ply(reader).map_err(|source| PlyError::Read {
        path: path.to_path_buf(),
        source,
    })
}

/// Opens `path` for buffered reading, decompressing it when it starts with
/// gzip's magic bytes (so `mesh.ply.gz` and `mesh.obj.gz` read like the plain files).
pub fn open_maybe_gzipped(path: &Path) -> std::io::Result<Box<dyn BufRead>> {
    let mut file = BufReader::with_capacity(1 << 16, File::open(path)?);
    let gzipped = file.fill_buf()?.starts_with(&[0x1f, 0x8b]);
    Ok(if gzipped {
        Box::new(BufReader::with_capacity(1 << 16, MultiGzDecoder::new(file)))
    } else {
        Box::new(file)
    })
}

/// Reads PLY data from any reader; see [`load_ply`].
pub fn read_ply(reader: impl BufRead) -> Result<TriangleMesh, ReadError> {
    let mut reader = Reader::new(reader);
    let header = Parser::<Skip>::new()
        .read_header(&mut reader)
        .map_err(|e| ReadError::Parse(e.to_string()))?;
    let layout = Layout::of(&header)?;

    let mut vertices = None;
    let mut faces = None;
    for (name, element) in &header.elements {
        if vertices.is_some() && faces.is_some() {
            break; // nothing after them is needed
        }
        let parse = |e: ply_rs_bw::parser::ParseError| ReadError::Parse(e.to_string());
        if *name == layout.vertex.name {
            vertices = Some(
                Parser::<Vertex>::new()
                    .read_payload_for_element(&mut reader, &layout.vertex, &header)
                    .map_err(parse)?,
            );
        } else if *name == layout.face.name {
            faces = Some(
                Parser::<Face>::new()
                    .read_payload_for_element(&mut reader, &layout.face, &header)
                    .map_err(parse)?,
            );
        } else {
            Parser::<Skip>::new()
                .read_payload_for_element(&mut reader, element, &header)
                .map_err(parse)?;
        }
    }
    let (vertices, faces) = (vertices.unwrap_or_default(), faces.unwrap_or_default());

    let mut mesh = TriangleMesh {
        positions: vertices.iter().map(|v| v.position).collect(),
        ..TriangleMesh::default()
    };
    if layout.normals {
        let normals: Vec<Vec3> = vertices.iter().map(|v| v.normal).collect();
        if normals.iter().all(|n| *n != Vec3::ZERO) {
            mesh.normals = Some(normals);
        }
    }
    if layout.scalar.is_some() {
        mesh.scalars = Some(vertices.iter().map(|v| v.scalar).collect());
    }
    drop(vertices);
    mesh.triangles.reserve(faces.len());
    for (index, face) in faces.iter().enumerate() {
        if face.negative {
            return Err(ReadError::NegativeIndex { face: index });
        }
        let corners = &face.indices;
        if corners.len() < 3 {
            return Err(ReadError::ShortFace {
                face: index,
                count: corners.len(),
            });
        }
        for pair in corners[1..].windows(2) {
            mesh.triangles.push([corners[0], pair[0], pair[1]]);
        }
    }
    mesh.validate().map_err(ReadError::InvalidMesh)?;
    Ok(mesh)
}

/// The name of the vertex property [`read_ply`] takes as the per-vertex scalar, if any.
pub fn scalar_property(vertex: &ElementDef) -> Option<&str> {
    let numeric = |name: &str| {
        matches!(
            vertex.properties.get(name).map(|p| &p.data_type),
            Some(PropertyType::Scalar(_))
        )
    };
    if let Some(name) = SCALAR_NAMES.iter().find(|name| numeric(name)) {
        return Some(name);
    }
    vertex
        .properties
        .values()
        .find(|p| {
            matches!(
                p.data_type,
                PropertyType::Scalar(ScalarType::Float | ScalarType::Double)
            ) && !NOT_SCALARS.contains(&p.name.as_str())
        })
        .map(|p| p.name.as_str())
}

/// The vertex and face elements as they are read: properties renamed to the
/// keys [`Vertex`] and [`Face`] know.
struct Layout {
    vertex: ElementDef,
    face: ElementDef,
    normals: bool,
    scalar: Option<String>,
}

impl Layout {
    fn of(header: &Header) -> Result<Layout, ReadError> {
        let vertex = header.elements.get("vertex").ok_or_else(|| {
            ReadError::Unsupported("the file has no `vertex` element".to_string())
        })?;
        let face = header.elements.get("face").ok_or_else(|| {
            ReadError::Unsupported(
                "the file has no `face` element (point clouds and triangle strips are not supported)"
                    .to_string(),
            )
        })?;
        if u32::try_from(vertex.count).is_err() {
            return Err(ReadError::Unsupported(format!(
                "the file declares {} vertices; at most {} are supported",
                vertex.count,
                u32::MAX
            )));
        }
        let scalar_type = |element: &ElementDef, name: &str| {
            matches!(
                element.properties.get(name).map(|p| &p.data_type),
                Some(PropertyType::Scalar(_))
            )
        };
        for axis in ["x", "y", "z"] {
            if !scalar_type(vertex, axis) {
                return Err(ReadError::Unsupported(format!(
                    "the `vertex` element has no numeric `{axis}` property"
                )));
            }
        }
        let normals = ["nx", "ny", "nz"]
            .iter()
            .all(|name| scalar_type(vertex, name));
        let scalar = scalar_property(vertex).map(str::to_string);
        let vertex = renamed(vertex, |name| {
            if Some(name) == scalar.as_deref() {
                SCALAR_KEY
            } else {
                name
            }
        });

        let list = |name: &str| {
            matches!(
                face.properties.get(name).map(|p| &p.data_type),
                Some(PropertyType::List(..))
            )
        };
        let indices = ["vertex_indices", "vertex_index"]
            .into_iter()
            .find(|name| list(name))
            .ok_or_else(|| {
                ReadError::Unsupported(
                    "the `face` element has no `vertex_indices` (or `vertex_index`) list"
                        .to_string(),
                )
            })?;
        let face = renamed(face, |name| {
            if name == indices {
                INDICES_KEY
            } else if name == INDICES_KEY {
                "\u{1}unused"
            } else {
                name
            }
        });
        Ok(Layout {
            vertex,
            face,
            normals,
            scalar,
        })
    }
}

/// `element` with its properties renamed (same order, same types).
fn renamed<'a>(element: &'a ElementDef, rename: impl Fn(&'a str) -> &'a str) -> ElementDef {
    let mut copy = ElementDef::new(element.name.clone());
    copy.count = element.count;
    for property in element.properties.values() {
        let name = rename(&property.name).to_string();
        copy.properties.insert(
            name.clone(),
            PropertyDef::new(name, property.data_type.clone()),
        );
    }
    copy
}

#[derive(Default)]
struct Vertex {
    position: Vec3,
    normal: Vec3,
    scalar: f32,
}

impl Vertex {
    #[inline]
    fn set(&mut self, name: &str, value: f32) -> PropertyAccessResult {
        match name {
            "x" => self.position.x = value,
            "y" => self.position.y = value,
            "z" => self.position.z = value,
            "nx" => self.normal.x = value,
            "ny" => self.normal.y = value,
            "nz" => self.normal.z = value,
            SCALAR_KEY => self.scalar = value,
            _ => return PropertyAccessResult::Ignored,
        }
        PropertyAccessResult::Set
    }
}

impl PropertyAccess for Vertex {
    fn new() -> Self {
        Vertex::default()
    }
    fn set_char(&mut self, name: &str, value: i8) -> PropertyAccessResult {
        self.set(name, value.into())
    }
    fn set_uchar(&mut self, name: &str, value: u8) -> PropertyAccessResult {
        self.set(name, value.into())
    }
    fn set_short(&mut self, name: &str, value: i16) -> PropertyAccessResult {
        self.set(name, value.into())
    }
    fn set_ushort(&mut self, name: &str, value: u16) -> PropertyAccessResult {
        self.set(name, value.into())
    }
    fn set_int(&mut self, name: &str, value: i32) -> PropertyAccessResult {
        self.set(name, value as f32)
    }
    fn set_uint(&mut self, name: &str, value: u32) -> PropertyAccessResult {
        self.set(name, value as f32)
    }
    fn set_float(&mut self, name: &str, value: f32) -> PropertyAccessResult {
        self.set(name, value)
    }
    fn set_double(&mut self, name: &str, value: f64) -> PropertyAccessResult {
        self.set(name, value as f32)
    }
}

/// A face's vertex indices; `negative` when one of them was below zero.
#[derive(Default)]
struct Face {
    indices: Vec<u32>,
    negative: bool,
}

impl Face {
    fn set_signed(
        &mut self,
        name: &str,
        values: impl Iterator<Item = i64>,
    ) -> PropertyAccessResult {
        if name != INDICES_KEY {
            return PropertyAccessResult::Ignored;
        }
        self.indices = values
            .map(|v| {
                u32::try_from(v).unwrap_or_else(|_| {
                    self.negative = true;
                    0
                })
            })
            .collect();
        PropertyAccessResult::Set
    }
}

impl PropertyAccess for Face {
    fn new() -> Self {
        Face::default()
    }
    fn begin_list_uint(&mut self, name: &str, _len: usize) -> BeginList<'_, u32> {
        if name == INDICES_KEY {
            BeginList::Fill(&mut self.indices)
        } else {
            BeginList::UseSetter
        }
    }
    fn set_list_char(&mut self, name: &str, value: Vec<i8>) -> PropertyAccessResult {
        self.set_signed(name, value.into_iter().map(i64::from))
    }
    fn set_list_uchar(&mut self, name: &str, value: Vec<u8>) -> PropertyAccessResult {
        self.set_signed(name, value.into_iter().map(i64::from))
    }
    fn set_list_short(&mut self, name: &str, value: Vec<i16>) -> PropertyAccessResult {
        self.set_signed(name, value.into_iter().map(i64::from))
    }
    fn set_list_ushort(&mut self, name: &str, value: Vec<u16>) -> PropertyAccessResult {
        self.set_signed(name, value.into_iter().map(i64::from))
    }
    fn set_list_int(&mut self, name: &str, value: Vec<i32>) -> PropertyAccessResult {
        self.set_signed(name, value.into_iter().map(i64::from))
    }
    fn set_list_float(&mut self, name: &str, _value: Vec<f32>) -> PropertyAccessResult {
        Face::not_indices(name)
    }
    fn set_list_double(&mut self, name: &str, _value: Vec<f64>) -> PropertyAccessResult {
        Face::not_indices(name)
    }
}

impl Face {
    /// Vertex indices must be integers.
    fn not_indices(name: &str) -> PropertyAccessResult {
        if name == INDICES_KEY {
            PropertyAccessResult::UnsupportedType
        } else {
            PropertyAccessResult::Ignored
        }
    }
}

/// An element that is read and thrown away.
struct Skip;

impl PropertyAccess for Skip {
    fn new() -> Self {
        Skip
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::{Cursor, Write};

    fn read(bytes: &[u8]) -> Result<TriangleMesh, ReadError> {
        read_ply(Cursor::new(bytes))
    }

    const SQUARE_AND_TRIANGLE: &str = "ply
format ascii 1.0
comment a unit square (a quad) and a triangle beside it
element vertex 5
property float x
property float y
property float z
property uchar red
property float value
element face 2
property list uchar int vertex_indices
end_header
0 0 0 255 0.5
1 0 0 255 1.5
1 1 0 255 2.5
0 1 0 255 3.5
2 0 0 255 4.5
4 0 1 2 3
3 1 4 2
";

    #[test]
    fn ascii_faces_are_fan_triangulated_with_the_scalar_property() {
        let mesh = read(SQUARE_AND_TRIANGLE.as_bytes()).unwrap();
        assert_eq!(mesh.positions.len(), 5);
        assert_eq!(mesh.positions[2], Vec3::new(1.0, 1.0, 0.0));
        assert_eq!(mesh.triangles, vec![[0, 1, 2], [0, 2, 3], [1, 4, 2]]);
        assert_eq!(mesh.scalars, Some(vec![0.5, 1.5, 2.5, 3.5, 4.5]));
        assert_eq!(mesh.normals, None);
    }

    #[test]
    fn the_same_faces_number_triangles_as_the_obj_loader_does() {
        let obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nf 1 2 3 4\nf 2 5 3\n";
        let from_obj = crate::obj::read_obj(&mut Cursor::new(obj)).unwrap();
        let from_ply = read(SQUARE_AND_TRIANGLE.as_bytes()).unwrap();
        assert_eq!(from_obj.triangles, from_ply.triangles);
        assert_eq!(from_obj.positions, from_ply.positions);
    }

    /// A binary PLY of one quad: double positions, float normals, an `intensity`
    /// and a `confidence` (intensity wins), `uint` indices.
    fn binary_quad(big_endian: bool) -> Vec<u8> {
        let format = if big_endian {
            "binary_big_endian"
        } else {
            "binary_little_endian"
        };
        let mut bytes = format!(
            "ply\nformat {format} 1.0\nelement vertex 4\nproperty double x\nproperty double y\n\
             property double z\nproperty float nx\nproperty float ny\nproperty float nz\n\
             property float confidence\nproperty float intensity\n\
             element face 1\nproperty list uchar uint vertex_indices\nend_header\n"
        )
        .into_bytes();
        let f64_bytes = |v: f64| {
            if big_endian {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            }
        };
        let f32_bytes = |v: f32| {
            if big_endian {
                v.to_be_bytes()
            } else {
                v.to_le_bytes()
            }
        };
        for (i, [x, y]) in [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]
            .into_iter()
            .enumerate()
        {
            for value in [x, y, 0.5] {
                bytes.extend(f64_bytes(value));
            }
            for value in [0.0, 0.0, 1.0, 0.25, i as f32 * 10.0] {
                bytes.extend(f32_bytes(value));
            }
        }
        bytes.push(4);
        for index in [3u32, 0, 1, 2] {
            bytes.extend(if big_endian {
                index.to_be_bytes()
            } else {
                index.to_le_bytes()
            });
        }
        bytes
    }

    #[test]
    fn binary_little_and_big_endian_read_the_same_mesh() {
        for big_endian in [false, true] {
            let mesh = read(&binary_quad(big_endian)).unwrap();
            assert_eq!(mesh.positions[1], Vec3::new(1.0, 0.0, 0.5));
            assert_eq!(mesh.triangles, vec![[3, 0, 1], [3, 1, 2]]);
            assert_eq!(mesh.normals, Some(vec![Vec3::Z; 4]));
            assert_eq!(mesh.scalars, Some(vec![0.0, 10.0, 20.0, 30.0]));
        }
    }

    #[test]
    fn gzip_is_detected_from_the_data() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("quad.ply.gz");
        let mut encoder = flate2::write::GzEncoder::new(
            File::create(&path).unwrap(),
            flate2::Compression::fast(),
        );
        encoder.write_all(&binary_quad(false)).unwrap();
        encoder.finish().unwrap();
        let mesh = load_ply(&path).unwrap();
        assert_eq!(mesh.triangles.len(), 2);
        // A plain file under a .gz name reads as well.
        std::fs::write(&path, SQUARE_AND_TRIANGLE).unwrap();
        assert_eq!(load_ply(&path).unwrap().triangles.len(), 3);
    }

    #[test]
    fn vertex_index_lists_other_elements_and_no_scalar() {
        let text = "ply
format ascii 1.0
element material 1
property float shininess
element vertex 3
property int x
property int y
property int z
property float u
property float v
element face 1
property uchar flags
property list ushort short vertex_index
element edge 1
property int vertex1
property int vertex2
end_header
0.5
0 0 0 0 0
1 0 0 1 0
0 1 0 0 1
7 3 2 1 0
0 1
";
        let mesh = read(text.as_bytes()).unwrap();
        assert_eq!(mesh.triangles, vec![[2, 1, 0]]);
        assert_eq!(mesh.positions[1], Vec3::X);
        assert_eq!(mesh.scalars, None, "texture coordinates are not a scalar");
    }

    #[test]
    fn zero_normals_are_dropped() {
        let text = SQUARE_AND_TRIANGLE
            .replace(
                "property uchar red\n",
                "property float nx\nproperty float ny\nproperty float nz\n",
            )
            .replace(" 255 ", " 0 0 0 ");
        let mesh = read(text.as_bytes()).unwrap();
        assert_eq!(mesh.normals, None);
        assert!(mesh.scalars.is_some());
    }

    #[test]
    fn a_file_writes_by_dpp_iso_reads_back() {
        let mesh = TriangleMesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            triangles: vec![[0, 1, 2]],
            normals: Some(vec![Vec3::Z; 3]),
            scalars: Some(vec![1.0, 2.0, 3.0]),
        };
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("iso.ply");
        crate::mesh_write::write_ply(&mesh, &path).unwrap();
        assert_eq!(load_ply(&path).unwrap(), mesh);
    }

    fn error(bytes: &[u8]) -> String {
        read(bytes).unwrap_err().to_string()
    }

    #[test]
    fn truncated_files_are_errors() {
        let quad = binary_quad(false);
        for cut in [quad.len() - 1, quad.len() - 20, quad.len() - 100] {
            let message = error(&quad[..cut]);
            assert!(message.contains("malformed PLY"), "{message}");
            assert!(message.contains("end of file"), "{message}");
        }
        let text = SQUARE_AND_TRIANGLE.trim_end_matches("3 1 4 2\n");
        let message = error(text.as_bytes());
        assert!(message.contains("end of file"), "{message}");
        // A header cut short.
        let message = error(&SQUARE_AND_TRIANGLE.as_bytes()[..60]);
        assert!(message.contains("malformed PLY"), "{message}");
    }

    #[test]
    fn bad_indices_and_non_finite_vertices_are_errors() {
        let out_of_range = SQUARE_AND_TRIANGLE.replace("3 1 4 2", "3 1 5 2");
        let message = error(out_of_range.as_bytes());
        assert!(message.contains("uses vertex 5"), "{message}");
        let negative = SQUARE_AND_TRIANGLE.replace("3 1 4 2", "3 1 -4 2");
        assert!(error(negative.as_bytes()).contains("face 1 has a negative vertex index"));
        let short = SQUARE_AND_TRIANGLE.replace("3 1 4 2", "2 1 4");
        assert!(error(short.as_bytes()).contains("face 1 has 2 vertex indices"));
        let nan = SQUARE_AND_TRIANGLE.replace("1 1 0 255", "1 nan 0 255");
        // ASCII "nan" does not even parse; a binary NaN does and fails validation.
        assert!(error(nan.as_bytes()).contains("malformed PLY"));
        let mut quad = binary_quad(false);
        let first_y = quad.len() - (4 * 44 + 1 + 16) + 8;
        quad[first_y..first_y + 8].copy_from_slice(&f64::NAN.to_le_bytes());
        let message = error(&quad);
        assert!(
            message.contains("vertex 0 has a non-finite coordinate"),
            "{message}"
        );
        let junk = SQUARE_AND_TRIANGLE.replace("1 1 0 255", "1 one 0 255");
        assert!(error(junk.as_bytes()).contains("malformed PLY"));
        let float_indices = SQUARE_AND_TRIANGLE.replace("uchar int vertex", "uchar float vertex");
        assert!(error(float_indices.as_bytes()).contains("vertex_indices"));
    }

    #[test]
    fn missing_elements_and_properties_are_errors() {
        let no_faces = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n\
                        property float y\nproperty float z\nend_header\n0 0 0\n";
        assert!(error(no_faces.as_bytes()).contains("no `face` element"));
        let no_z = SQUARE_AND_TRIANGLE.replace("property float z\n", "");
        assert!(error(no_z.as_bytes()).contains("no numeric `z` property"));
        let no_indices = SQUARE_AND_TRIANGLE.replace("vertex_indices", "corners");
        assert!(error(no_indices.as_bytes()).contains("no `vertex_indices`"));
        let no_triangles = SQUARE_AND_TRIANGLE
            .replace("element face 2", "element face 0")
            .replace("4 0 1 2 3\n3 1 4 2\n", "");
        assert!(error(no_triangles.as_bytes()).contains("no triangles"));
        assert!(error(b"solid stl\n").contains("malformed PLY"));
        assert!(error(b"").contains("malformed PLY"));
    }

    #[test]
    fn missing_files_name_the_path() {
        let error = load_ply(Path::new("/nonexistent/mesh.ply")).unwrap_err();
        assert!(error
            .to_string()
            .contains("cannot open /nonexistent/mesh.ply"));
    }
}
