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
use crate::ply_body::{Body, BodyEncoding, VertexSlot, RECORDS_PER_CHUNK};
use flate2::read::MultiGzDecoder;
use glam::Vec3;
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{DefaultElement, ElementDef, Header, PropertyType, ScalarType};
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

/// Reads PLY data from any reader; see [`load_ply`]. The whole file is read
/// into memory first, and its body decoded in parallel ([`crate::ply_body`]).
pub fn read_ply(mut reader: impl BufRead) -> Result<TriangleMesh, ReadError> {
    let mut bytes = Vec::new();
    reader
        .read_to_end(&mut bytes)
        .map_err(|e| ReadError::Parse(e.to_string()))?;
    read_ply_bytes(&bytes, RECORDS_PER_CHUNK)
}

/// [`read_ply`] of a file's bytes, the body in chunks of `records_per_chunk`.
fn read_ply_bytes(bytes: &[u8], records_per_chunk: usize) -> Result<TriangleMesh, ReadError> {
    let mut reader = Reader::new(std::io::Cursor::new(bytes));
    let header = Parser::<DefaultElement>::new()
        .read_header(&mut reader)
        .map_err(|e| ReadError::Parse(e.to_string()))?;
    let layout = Layout::of(&header)?;
    let body_start = reader.get_ref().position() as usize;
    let mut body = Body::new(
        &bytes[body_start..],
        BodyEncoding::of(header.encoding),
        reader.line(),
        records_per_chunk,
    );
    let (mut vertices, mut triangles) = (None, None);
    for (name, element) in &header.elements {
        if vertices.is_some() && triangles.is_some() {
            break; // nothing after them is needed
        }
        match name.as_str() {
            "vertex" => vertices = Some(body.vertices(element, &layout.vertex_slots)?),
            "face" => triangles = Some(body.faces(element, layout.indices)?),
            _ => body.skip(element)?,
        }
    }
    let vertices = vertices.unwrap_or_default();
    let mut mesh = TriangleMesh {
        positions: vertices.positions,
        triangles: triangles.unwrap_or(Ok(Vec::new()))?,
        ..TriangleMesh::default()
    };
    if layout.normals && vertices.normals.iter().all(|n| *n != Vec3::ZERO) {
        mesh.normals = Some(vertices.normals);
    }
    if layout.scalar {
        mesh.scalars = Some(vertices.scalars);
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

/// What [`read_ply`] takes from the vertex and face elements.
struct Layout {
    /// Where each vertex property goes, in the header's order.
    vertex_slots: Vec<VertexSlot>,
    /// The face element's list of vertex indices.
    indices: &'static str,
    normals: bool,
    scalar: bool,
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
        let scalar = scalar_property(vertex);
        let vertex_slots = (vertex.properties.keys())
            .map(|name| match name.as_str() {
                "x" => VertexSlot::Position(0),
                "y" => VertexSlot::Position(1),
                "z" => VertexSlot::Position(2),
                "nx" if normals => VertexSlot::Normal(0),
                "ny" if normals => VertexSlot::Normal(1),
                "nz" if normals => VertexSlot::Normal(2),
                name if Some(name) == scalar => VertexSlot::Scalar,
                _ => VertexSlot::Skipped,
            })
            .collect();

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
        Ok(Layout {
            vertex_slots,
            indices,
            normals,
            scalar: scalar.is_some(),
        })
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

    /// A PLY file of random layout and content: ASCII or binary of either
    /// byte order; coordinates of several types; optional normals, colour and
    /// scalar; polygons of 3 to 6 corners with several index types; elements
    /// to skip before and after (with lists).
    fn random_ply(seed: u64) -> Vec<u8> {
        let mut random = dpp_runtime::random::SplitMix64::new(seed);
        let mut pick = |n: u64| (random.next_u64() % n) as usize;
        let format = ["ascii", "binary_little_endian", "binary_big_endian"][pick(3)];
        let big_endian = format == "binary_big_endian";
        let coordinate = ["float", "double", "int", "short", "uchar"][pick(5)];
        let normals = pick(2) == 0;
        let scalar = ["", "float intensity", "double value", "float confidence"][pick(4)];
        let count_type = ["uchar", "ushort", "int"][pick(3)];
        let index_type = ["int", "uint", "short"][pick(3)];
        let (vertices, faces) = (5 + pick(60), 1 + pick(90));
        let mut header = format!("ply\nformat {format} 1.0\ncomment random\n");
        header += "element material 2\nproperty float shininess\nproperty list uchar int ids\n";
        header += &format!("element vertex {vertices}\n");
        for axis in ["x", "y", "z"] {
            header += &format!("property {coordinate} {axis}\n");
        }
        if normals {
            header += "property float nx\nproperty float ny\nproperty float nz\n";
        }
        header += "property uchar red\n";
        if !scalar.is_empty() {
            header += &format!("property {scalar}\n");
        }
        header += &format!(
            "element face {faces}\nproperty uchar flags\nproperty list {count_type} {index_type} vertex_indices\n"
        );
        header +=
            "element edge 1\nproperty int vertex1\nproperty list uchar uchar tags\nend_header\n";
        let mut bytes = header.into_bytes();
        // One record of values, each (type, value) in ASCII or binary.
        let mut record = |bytes: &mut Vec<u8>, values: &[(&str, f64)]| {
            if format == "ascii" {
                let words: Vec<String> = values
                    .iter()
                    .map(|&(kind, value)| match kind {
                        "float" => (value as f32).to_string(),
                        "double" => value.to_string(),
                        _ => (value as i64).to_string(),
                    })
                    .collect();
                bytes.extend(words.join(" ").as_bytes());
                bytes.extend(if pick(4) == 0 { &b" \r\n"[..] } else { b"\n" });
                return;
            }
            for &(kind, value) in values {
                let mut encoded = match kind {
                    "float" => (value as f32).to_le_bytes().to_vec(),
                    "double" => value.to_le_bytes().to_vec(),
                    "int" => (value as i32).to_le_bytes().to_vec(),
                    "uint" => (value as u32).to_le_bytes().to_vec(),
                    "short" => (value as i16).to_le_bytes().to_vec(),
                    "ushort" => (value as u16).to_le_bytes().to_vec(),
                    _ => vec![value as u8],
                };
                if big_endian {
                    encoded.reverse();
                }
                bytes.extend(encoded);
            }
        };
        for id in 0..2 {
            record(
                &mut bytes,
                &[
                    ("float", 0.5),
                    ("uchar", 2.0),
                    ("int", id.into()),
                    ("int", 7.0),
                ],
            );
        }
        let mut random = dpp_runtime::random::SplitMix64::new(seed ^ 0xdecaf);
        let mut unit = || (random.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
        for _ in 0..vertices {
            let mut values: Vec<(&str, f64)> = (0..3)
                .map(|_| match coordinate {
                    "float" | "double" => (coordinate, 20.0 * unit() - 10.0),
                    "uchar" => (coordinate, (255.0 * unit()).floor()),
                    _ => (coordinate, (2000.0 * unit() - 1000.0).floor()),
                })
                .collect();
            if normals {
                values.extend((0..3).map(|_| ("float", 0.25 + unit())));
            }
            values.push(("uchar", 255.0));
            if let Some((kind, _)) = scalar.split_once(' ') {
                values.push((kind, 100.0 * unit()));
            }
            record(&mut bytes, &values);
        }
        for _ in 0..faces {
            let corners = 3 + (4.0 * unit()) as usize;
            let mut values = vec![("uchar", 1.0), (count_type, corners as f64)];
            values.extend((0..corners).map(|_| (index_type, (vertices as f64 * unit()).floor())));
            record(&mut bytes, &values);
        }
        record(&mut bytes, &[("int", 3.0), ("uchar", 1.0), ("uchar", 9.0)]);
        bytes
    }

    /// The mesh as ply-rs-bw reads the whole file into its generic elements:
    /// a serial reader, written independently of ours.
    fn read_serially(bytes: &[u8]) -> TriangleMesh {
        use ply_rs_bw::ply::Property;
        let ply = Parser::<DefaultElement>::new()
            .read_ply(&mut Cursor::new(bytes))
            .unwrap();
        let number = |property: &Property| match *property {
            Property::Char(v) => f64::from(v),
            Property::UChar(v) => f64::from(v),
            Property::Short(v) => f64::from(v),
            Property::UShort(v) => f64::from(v),
            Property::Int(v) => f64::from(v),
            Property::UInt(v) => f64::from(v),
            Property::Float(v) => f64::from(v),
            Property::Double(v) => v,
            _ => panic!("a list where a number was expected"),
        };
        let list = |property: &Property| -> Vec<u32> {
            match property {
                Property::ListUChar(v) => v.iter().map(|&i| i.into()).collect(),
                Property::ListShort(v) => v.iter().map(|&i| i as u32).collect(),
                Property::ListUShort(v) => v.iter().map(|&i| i.into()).collect(),
                Property::ListInt(v) => v.iter().map(|&i| i as u32).collect(),
                Property::ListUInt(v) => v.clone(),
                _ => panic!("not a list of indices"),
            }
        };
        let vertices = &ply.payload["vertex"];
        let vec3 = |v: &DefaultElement, [x, y, z]: [&str; 3]| {
            Vec3::new(
                number(&v[x]) as f32,
                number(&v[y]) as f32,
                number(&v[z]) as f32,
            )
        };
        let mut mesh = TriangleMesh {
            positions: vertices.iter().map(|v| vec3(v, ["x", "y", "z"])).collect(),
            ..TriangleMesh::default()
        };
        if vertices.first().is_some_and(|v| v.contains_key("nx")) {
            mesh.normals = Some(
                (vertices.iter())
                    .map(|v| vec3(v, ["nx", "ny", "nz"]))
                    .collect(),
            );
        }
        mesh.scalars = scalar_property(&ply.header.elements["vertex"])
            .map(|name| vertices.iter().map(|v| number(&v[name]) as f32).collect());
        for face in &ply.payload["face"] {
            let corners = list(&face["vertex_indices"]);
            for pair in corners[1..].windows(2) {
                mesh.triangles.push([corners[0], pair[0], pair[1]]);
            }
        }
        mesh
    }

    #[test]
    fn the_parallel_reader_reads_what_the_serial_one_does_in_chunks_of_any_size() {
        for seed in 0..48 {
            let bytes = random_ply(seed);
            let serial = read_serially(&bytes);
            for records in [1, 2, 7, RECORDS_PER_CHUNK] {
                let parallel = read_ply_bytes(&bytes, records).unwrap_or_else(|e| {
                    panic!(
                        "seed {seed}, chunks of {records}: {e}\n{}",
                        String::from_utf8_lossy(&bytes)
                    )
                });
                assert_eq!(parallel, serial, "seed {seed}, chunks of {records}");
            }
        }
    }

    #[test]
    fn cut_or_damaged_files_are_errors_not_panics() {
        for seed in 0..6 {
            let bytes = random_ply(seed);
            let whole = read_ply_bytes(&bytes, 3).unwrap();
            for cut in 0..bytes.len() {
                // Cut inside the trailing `edge` element, the mesh is whole;
                // cut inside the last face's ASCII line, its last index may
                // have lost digits and still be one.
                if let Ok(mesh) = read_ply_bytes(&bytes[..cut], 3) {
                    assert_eq!(mesh.positions, whole.positions, "seed {seed} cut at {cut}");
                    let all_but_last = whole.triangles.len() - 1;
                    assert_eq!(mesh.triangles.len(), whole.triangles.len());
                    assert_eq!(
                        mesh.triangles[..all_but_last],
                        whole.triangles[..all_but_last]
                    );
                }
            }
            let mut random = dpp_runtime::random::SplitMix64::new(seed);
            for _ in 0..200 {
                let mut damaged = bytes.clone();
                let at = random.next_u64() as usize % damaged.len();
                damaged[at] = random.next_u64() as u8;
                for records in [1, RECORDS_PER_CHUNK] {
                    // Either result is fine; a panic is not.
                    let _ = read_ply_bytes(&damaged, records);
                }
            }
        }
    }

    #[test]
    fn a_binary_element_without_properties_costs_nothing_however_many_it_claims() {
        let quad = binary_quad(false);
        let claimed = String::from_utf8_lossy(&quad).replacen(
            "element vertex",
            "element nothing 99999999999999\nelement vertex",
            1,
        );
        let header_end = claimed.find("end_header\n").unwrap() + "end_header\n".len();
        let old_header_end = quad.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
        let mut bytes = claimed.as_bytes()[..header_end].to_vec();
        bytes.extend(&quad[old_header_end..]);
        assert_eq!(read(&bytes).unwrap(), read(&quad).unwrap());
    }

    #[test]
    fn missing_files_name_the_path() {
        let error = load_ply(Path::new("/nonexistent/mesh.ply")).unwrap_err();
        assert!(error
            .to_string()
            .contains("cannot open /nonexistent/mesh.ply"));
    }
}
