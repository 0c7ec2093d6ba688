//! Mesh files written: Wavefront OBJ (positions, normals) and binary
//! little-endian PLY (positions, normals, a `scalar` per vertex), beside their
//! readers ([`crate::obj`], [`crate::ply`]).

use crate::mesh::TriangleMesh;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

/// Writes `mesh` as Wavefront OBJ: `v` lines, `vn` lines when it has normals,
/// and one `f` per triangle (`f a//a b//b c//c` with normals). OBJ has no
/// per-vertex scalar: scalars are not written (use [`write_ply`]).
pub fn write_obj(mesh: &TriangleMesh, path: &Path) -> std::io::Result<()> {
    let mut out = BufWriter::new(File::create(path)?);
    writeln!(
        out,
        "# isosurface written by dpp: {} vertices, {} triangles",
        mesh.positions.len(),
        mesh.triangles.len()
    )?;
    for p in &mesh.positions {
        writeln!(out, "v {} {} {}", p.x, p.y, p.z)?;
    }
    if let Some(normals) = &mesh.normals {
        for n in normals {
            writeln!(out, "vn {} {} {}", n.x, n.y, n.z)?;
        }
    }
    let with_normals = mesh.normals.is_some();
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|v| v + 1);
        if with_normals {
            writeln!(out, "f {a}//{a} {b}//{b} {c}//{c}")?;
        } else {
            writeln!(out, "f {a} {b} {c}")?;
        }
    }
    out.flush()
}

/// Writes `mesh` as binary little-endian PLY: vertex properties `x y z`, then
/// `nx ny nz` when the mesh has normals and `scalar` when it has scalars (all
/// `float`), and faces as `list uchar uint vertex_indices`.
pub fn write_ply(mesh: &TriangleMesh, path: &Path) -> std::io::Result<()> {
    let mut out = BufWriter::new(File::create(path)?);
    let mut header =
        String::from("ply\nformat binary_little_endian 1.0\ncomment isosurface written by dpp\n");
    header.push_str(&format!("element vertex {}\n", mesh.positions.len()));
    for name in ["x", "y", "z"] {
        header.push_str(&format!("property float {name}\n"));
    }
    if mesh.normals.is_some() {
        for name in ["nx", "ny", "nz"] {
            header.push_str(&format!("property float {name}\n"));
        }
    }
    if mesh.scalars.is_some() {
        header.push_str("property float scalar\n");
    }
    header.push_str(&format!(
        "element face {}\nproperty list uchar uint vertex_indices\nend_header\n",
        mesh.triangles.len()
    ));
    out.write_all(header.as_bytes())?;
    for (v, p) in mesh.positions.iter().enumerate() {
        let mut values = p.to_array().to_vec();
        if let Some(normals) = &mesh.normals {
            values.extend(normals[v].to_array());
        }
        if let Some(scalars) = &mesh.scalars {
            values.push(scalars[v]);
        }
        for value in values {
            out.write_all(&value.to_le_bytes())?;
        }
    }
    for t in &mesh.triangles {
        out.write_all(&[3u8])?;
        for v in t {
            out.write_all(&v.to_le_bytes())?;
        }
    }
    out.flush()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::functors::isosurface::mesh::tests::column;
    use crate::functors::isosurface::triangles_to_mesh;

    #[test]
    fn obj_round_trips_through_the_loader() {
        let mesh = triangles_to_mesh(&column(), true).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("iso.obj");
        write_obj(&mesh, &path).unwrap();
        let back = crate::obj::load_obj(&path).unwrap();
        assert_eq!(back.positions, mesh.positions);
        assert_eq!(back.triangles, mesh.triangles);
        assert_eq!(back.normals, mesh.normals);
    }

    #[test]
    fn ply_is_binary_little_endian_with_normals_and_scalars() {
        let mesh = triangles_to_mesh(&column(), true).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("iso.ply");
        write_ply(&mesh, &path).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let end = b"end_header\n";
        let body = bytes.windows(end.len()).position(|w| w == end).unwrap() + end.len();
        let header = std::str::from_utf8(&bytes[..body]).unwrap();
        assert!(header.starts_with("ply\nformat binary_little_endian 1.0\n"));
        assert!(header.contains("element vertex 4\n"));
        assert!(header.contains("property float nz\nproperty float scalar\n"));
        assert!(header.contains("element face 2\nproperty list uchar uint vertex_indices\n"));
        let data = &bytes[body..];
        assert_eq!(data.len(), 4 * 7 * 4 + 2 * 13);
        let float = |at: usize| f32::from_le_bytes(data[at..at + 4].try_into().unwrap());
        // Vertex 3: (1, 1, 0), normal +z, scalar 4.
        let v3: Vec<f32> = (0..7).map(|i| float(3 * 28 + 4 * i)).collect();
        assert_eq!(v3, [1.0, 1.0, 0.0, 0.0, 0.0, 1.0, 4.0]);
        let faces = &data[4 * 28..];
        assert_eq!(faces[13], 3);
        let index = |at: usize| u32::from_le_bytes(faces[at..at + 4].try_into().unwrap());
        assert_eq!([index(14), index(18), index(22)], [1, 3, 2]);
    }
}
