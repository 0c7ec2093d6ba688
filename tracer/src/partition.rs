//! Splitting a mesh data set among the ranks of a distributed run, as pure
//! functions (the caller shares what ranks must agree on).
//!
//! - Several mesh files (pieces): [`count_triangles`] cheaply per piece, then
//!   [`assign_pieces`] gives each rank a contiguous run of pieces balanced by
//!   triangles. A piece's triangles keep their single-process ids: the id of
//!   its first triangle is the sum of the triangle counts of the pieces before
//!   it in file order ([`piece_offsets`]).
//! - One mesh file: every rank reads it and keeps its region,
//!   [`split_spatially`]: a k-d split of the triangles' centroids balanced by
//!   triangle count, returning the part's mesh and its triangles' ids in the
//!   whole mesh.

use crate::mesh::TriangleMesh;
use crate::ply::open_maybe_gzipped;
use crate::shading::MeshMaterials;
use glam::Vec3;
use std::io::{self, BufRead};
use std::path::{Path, PathBuf};
use thiserror::Error;

#[derive(Debug, Error)]
pub enum CountError {
    #[error("{}: {source}", path.display())]
    Io { path: PathBuf, source: io::Error },
    #[error("{}: {what}", path.display())]
    Format { path: PathBuf, what: String },
}

/// The number of triangles a mesh file holds, cheaply (without building the
/// mesh), by extension (case-insensitive, gzip detected from the data):
///
/// - PLY (`.ply`, `.ply.gz`): the header's `element face N`, read alone. This
///   counts faces: exact for triangle meshes (what `dpp iso` writes), but a
///   polygon face fan-triangulates into more than one triangle, so for a PLY
///   of polygons it is a lower bound — the caller should compare it with the
///   loaded mesh's `triangles.len()` and refuse to number by it if they differ.
/// - OBJ (`.obj`, `.obj.gz`): a scan of the `f` lines, each face of `n ≥ 3`
///   vertices counting `n - 2` triangles (its fan); lines joined with a
///   trailing `\` are not followed.
/// - VTK meshes (`.vtp`, `.vtu`, legacy `.vtk`): the mesh itself, read
///   whole (a fan's and an external surface's triangles are not in any
///   header), with its default field.
pub fn count_triangles(path: &Path) -> Result<u64, CountError> {
    let io_error = |source| CountError::Io {
        path: path.to_path_buf(),
        source,
    };
    let format = |what: String| CountError::Format {
        path: path.to_path_buf(),
        what,
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let name = name.strip_suffix(".gz").unwrap_or(&name);
    if crate::vtk::VtkKind::of(path).is_some() {
        let (mesh, _) =
            crate::vtk::mesh::read_mesh(path, &Default::default()).map_err(|e| format(e.what))?;
        return Ok(mesh.triangles.len() as u64);
    }
    let reader = open_maybe_gzipped(path).map_err(io_error)?;
    if name.ends_with(".ply") {
        count_ply_faces(reader).map_err(|e| match e {
            Ok(what) => format(what),
            Err(source) => io_error(source),
        })
    } else if name.ends_with(".obj") {
        count_obj_triangles(reader).map_err(io_error)
    } else {
        Err(format(
            "unknown mesh file type (expected .ply, .ply.gz, .obj or .obj.gz)".into(),
        ))
    }
}

/// `element face N` of a PLY header; `Err(Ok(what))` for a malformed header.
fn count_ply_faces(mut reader: impl BufRead) -> Result<u64, Result<String, io::Error>> {
    let mut line = Vec::new();
    let mut first = true;
    loop {
        line.clear();
        if reader.read_until(b'\n', &mut line).map_err(Err)? == 0 {
            return Err(Ok("the PLY header ends before end_header".into()));
        }
        let text = String::from_utf8_lossy(&line);
        let words: Vec<&str> = text.split_whitespace().collect();
        if first {
            if words.first() != Some(&"ply") {
                return Err(Ok("not a PLY file (it does not start with 'ply')".into()));
            }
            first = false;
            continue;
        }
        match words.as_slice() {
            ["element", "face", n] => {
                return n
                    .parse()
                    .map_err(|_| Ok(format!("'element face {n}' is not a count")));
            }
            ["end_header"] => return Ok(0),
            _ => {}
        }
    }
}

/// `Σ (n - 2)` over the `f` lines of an OBJ.
fn count_obj_triangles(mut reader: impl BufRead) -> io::Result<u64> {
    let mut line = Vec::new();
    let mut triangles = 0u64;
    loop {
        line.clear();
        if reader.read_until(b'\n', &mut line)? == 0 {
            return Ok(triangles);
        }
        let text = line.trim_ascii_start();
        if text.len() > 1 && text[0] == b'f' && text[1].is_ascii_whitespace() {
            let vertices = text[1..]
                .split(|b| b.is_ascii_whitespace())
                .filter(|w| !w.is_empty())
                .take_while(|w| w[0] != b'#')
                .count() as u64;
            triangles += vertices.saturating_sub(2);
        }
    }
}

/// Pieces (in file order, with `counts[p]` triangles each) to `ranks` ranks:
/// rank `r` gets the pieces `result[r]`, a contiguous run, runs in rank order
/// covering every piece once, so that the largest rank's triangle count is
/// as small as it can be (ties: the split that gives earlier ranks as many
/// pieces as possible, making it deterministic). With more ranks than pieces
/// some ranks get none.
pub fn assign_pieces(counts: &[u64], ranks: usize) -> Vec<Vec<usize>> {
    let ranks = ranks.max(1);
    // The least feasible maximum, by binary search over the answer.
    let fits = |limit: u64| -> bool {
        let (mut used, mut load) = (1usize, 0u64);
        for &c in counts {
            if c > limit {
                return false;
            }
            if load + c > limit {
                used += 1;
                load = 0;
            }
            load += c;
        }
        used <= ranks
    };
    let (mut lo, mut hi) = (
        counts.iter().copied().max().unwrap_or(0),
        counts.iter().sum::<u64>(),
    );
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if fits(mid) {
            hi = mid;
        } else {
            lo = mid + 1;
        }
    }
    let limit = lo;
    // Greedy under the limit, leaving at least one piece for each later rank
    // where there are enough pieces to go round.
    let mut result = vec![Vec::new(); ranks];
    let mut piece = 0;
    for (r, pieces) in result.iter_mut().enumerate() {
        let later_ranks = ranks - r - 1;
        let mut load = 0u64;
        while piece < counts.len() {
            let left_after = counts.len() - piece - 1;
            if !pieces.is_empty() && (load + counts[piece] > limit || left_after < later_ranks) {
                break;
            }
            load += counts[piece];
            pieces.push(piece);
            piece += 1;
        }
    }
    debug_assert_eq!(piece, counts.len());
    result
}

/// The id of each piece's first triangle in the single-process order of all
/// pieces concatenated (file order): the sum of the counts before it.
pub fn piece_offsets(counts: &[u64]) -> Vec<u64> {
    counts
        .iter()
        .scan(0u64, |sum, &c| {
            let offset = *sum;
            *sum += c;
            Some(offset)
        })
        .collect()
}

/// Part `part` of `parts` of `mesh`, split by space: the triangles whose
/// centroids fall in the part's cell of a k-d split of all centroids,
/// balanced by triangle count (a box of `n` parts is cut across its widest
/// axis into `n / 2` and `n - n / 2` parts' worth of triangles, at the
/// triangle of that rank in the order of centroid coordinate, ties by
/// triangle index), so every triangle is in exactly one part and the parts'
/// counts differ by at most about one triangle per level of the split.
/// Deterministic: it depends only on the mesh and `parts`.
///
/// Returns the part's mesh (its triangles in the whole mesh's order, keeping
/// only the vertices they use, with their normals and scalars) and the id of
/// each of its triangles in the whole mesh (for
/// [`crate::TraceScene::with_global_ids`]). Materials: [`split_materials`].
pub fn split_spatially(mesh: &TriangleMesh, parts: usize, part: usize) -> (TriangleMesh, Vec<u32>) {
    let ids = spatial_part(mesh, parts, part);
    (sub_mesh(mesh, &ids), ids)
}

/// The ids of the triangles of part `part` of `parts` of [`split_spatially`],
/// ascending.
pub fn spatial_part(mesh: &TriangleMesh, parts: usize, part: usize) -> Vec<u32> {
    let centroids: Vec<Vec3> = (0..mesh.triangles.len())
        .map(|t| {
            let [a, b, c] = mesh.triangle_vertices(t);
            (a + b + c) / 3.0
        })
        .collect();
    let mut ids: Vec<u32> = (0..mesh.triangles.len() as u32).collect();
    let (mut parts, mut part) = (parts.max(1), part);
    if part >= parts {
        return Vec::new();
    }
    // Descend the k-d tree to the part's leaf.
    while parts > 1 {
        let (min, max) = ids.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), &t| (lo.min(centroids[t as usize]), hi.max(centroids[t as usize])),
        );
        let extent = (max - min).max(Vec3::ZERO);
        let axis = if extent.x >= extent.y && extent.x >= extent.z {
            0
        } else if extent.y >= extent.z {
            1
        } else {
            2
        };
        let left = parts / 2;
        let cut = (ids.len() * left * 2 + parts) / (2 * parts);
        let key = |t: &u32| (centroids[*t as usize][axis], *t);
        if cut < ids.len() {
            ids.select_nth_unstable_by(cut, |a, b| {
                let (ka, kb) = (key(a), key(b));
                ka.0.total_cmp(&kb.0).then(ka.1.cmp(&kb.1))
            });
        }
        if part < left {
            ids.truncate(cut);
            parts = left;
        } else {
            ids.drain(..cut);
            part -= left;
            parts -= left;
        }
    }
    ids.sort_unstable();
    ids
}

/// The triangles `ids` of `mesh` (in that order) with only the vertices they
/// use, renumbered in order of first use, with their normals and scalars.
pub fn sub_mesh(mesh: &TriangleMesh, ids: &[u32]) -> TriangleMesh {
    let mut new_index = vec![u32::MAX; mesh.positions.len()];
    let mut used = Vec::new();
    let triangles = ids
        .iter()
        .map(|&t| {
            mesh.triangles[t as usize].map(|v| {
                if new_index[v as usize] == u32::MAX {
                    new_index[v as usize] = used.len() as u32;
                    used.push(v as usize);
                }
                new_index[v as usize]
            })
        })
        .collect();
    TriangleMesh {
        positions: used.iter().map(|&v| mesh.positions[v]).collect(),
        triangles,
        normals: mesh
            .normals
            .as_ref()
            .map(|n| used.iter().map(|&v| n[v]).collect()),
        scalars: mesh
            .scalars
            .as_ref()
            .map(|s| used.iter().map(|&v| s[v]).collect()),
    }
}

/// The materials of the triangles `ids` of a mesh: the same table, and each
/// kept triangle's material id.
pub fn split_materials(materials: &MeshMaterials, ids: &[u32]) -> MeshMaterials {
    MeshMaterials {
        materials: materials.materials.clone(),
        triangle_materials: if materials.triangle_materials.is_empty() {
            Vec::new()
        } else {
            ids.iter()
                .map(|&t| materials.triangle_materials[t as usize])
                .collect()
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::fs;

    #[test]
    fn counts_ply_faces_and_obj_fans() {
        let dir = tempfile::tempdir().unwrap();
        let ply = dir.path().join("m.ply");
        fs::write(
            &ply,
            "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n",
        )
        .unwrap();
        assert_eq!(count_triangles(&ply).unwrap(), 2);
        assert_eq!(crate::ply::load_ply(&ply).unwrap().triangles.len(), 2);
        let obj = dir.path().join("m.OBJ");
        let text = "# a quad, a triangle and a pentagon\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 2 0\nf 1 2 3 4\n  f 1/1 2/2 3/3 # comment\nfa 1 2 3\nf 1 2 3 4 5\nvt 0 0\n";
        fs::write(&obj, text).unwrap();
        assert_eq!(count_triangles(&obj).unwrap(), 2 + 1 + 3);
        let gz = dir.path().join("m.obj.gz");
        let mut encoder = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        std::io::Write::write_all(&mut encoder, text.as_bytes()).unwrap();
        fs::write(&gz, encoder.finish().unwrap()).unwrap();
        assert_eq!(count_triangles(&gz).unwrap(), 6);
        assert!(count_triangles(&dir.path().join("m.stl")).is_err());
        let bad = dir.path().join("bad.ply");
        fs::write(&bad, "ply\nelement face many\nend_header\n").unwrap();
        assert!(count_triangles(&bad).is_err());
    }

    /// The least possible largest load, by trying every contiguous split.
    fn best(counts: &[u64], ranks: usize) -> u64 {
        fn go(counts: &[u64], ranks: usize) -> u64 {
            if ranks == 1 || counts.is_empty() {
                return counts.iter().sum();
            }
            (0..=counts.len())
                .map(|k| {
                    counts[..k]
                        .iter()
                        .sum::<u64>()
                        .max(go(&counts[k..], ranks - 1))
                })
                .min()
                .unwrap()
        }
        go(counts, ranks)
    }

    #[test]
    fn pieces_go_to_ranks_contiguously_minimising_the_largest_load() {
        let mut random = dpp_runtime::random::SplitMix64::new(7);
        for trial in 0..300 {
            let n = (trial % 9) as usize;
            let counts: Vec<u64> = (0..n).map(|_| random.next_u64() % 100).collect();
            for ranks in 1..=6 {
                let assigned = assign_pieces(&counts, ranks);
                assert_eq!(assigned.len(), ranks);
                let flat: Vec<usize> = assigned.iter().flatten().copied().collect();
                assert_eq!(flat, (0..n).collect::<Vec<_>>(), "{counts:?} {ranks}");
                let largest = assigned
                    .iter()
                    .map(|p| p.iter().map(|&i| counts[i]).sum::<u64>())
                    .max()
                    .unwrap();
                assert_eq!(
                    largest,
                    best(&counts, ranks),
                    "{counts:?} {ranks}: {assigned:?}"
                );
                if n >= ranks {
                    assert!(assigned.iter().all(|p| !p.is_empty()), "{assigned:?}");
                }
                assert_eq!(assigned, assign_pieces(&counts, ranks));
            }
        }
        assert_eq!(piece_offsets(&[3, 0, 5, 2]), [0, 3, 3, 8]);
        assert_eq!(
            assign_pieces(&[5, 1, 1, 1, 1, 1], 2),
            [vec![0], vec![1, 2, 3, 4, 5]]
        );
    }

    #[test]
    fn spatial_parts_partition_the_triangles_in_balance() {
        let mut mesh = crate::builtin_scene::builtin_scene(16).unwrap();
        let n = mesh.triangles.len();
        mesh.scalars = Some((0..mesh.positions.len()).map(|v| v as f32).collect());
        for parts in 1..=7 {
            let mut owner = vec![usize::MAX; n];
            for part in 0..parts {
                let (sub, ids) = split_spatially(&mesh, parts, part);
                assert_eq!(sub.triangles.len(), ids.len());
                let ideal = n as f64 / parts as f64;
                assert!(
                    (ids.len() as f64 - ideal).abs() <= 2.0,
                    "{parts}: {} vs {ideal}",
                    ids.len()
                );
                assert!(ids.windows(2).all(|w| w[0] < w[1]));
                sub.validate().unwrap();
                for (t, &id) in ids.iter().enumerate() {
                    assert_eq!(owner[id as usize], usize::MAX);
                    owner[id as usize] = part;
                    assert_eq!(
                        sub.triangle_vertices(t),
                        mesh.triangle_vertices(id as usize)
                    );
                    for k in 0..3 {
                        let (v, w) = (
                            sub.triangles[t][k] as usize,
                            mesh.triangles[id as usize][k] as usize,
                        );
                        assert_eq!(
                            sub.normals.as_ref().unwrap()[v],
                            mesh.normals.as_ref().unwrap()[w]
                        );
                        assert_eq!(
                            sub.scalars.as_ref().unwrap()[v],
                            mesh.scalars.as_ref().unwrap()[w]
                        );
                    }
                }
                let used: std::collections::HashSet<u32> =
                    sub.triangles.iter().flatten().copied().collect();
                assert_eq!(used.len(), sub.positions.len(), "only used vertices");
                assert_eq!((sub, ids), split_spatially(&mesh, parts, part));
            }
            assert!(owner.iter().all(|&o| o != usize::MAX));
        }
        let materials = MeshMaterials {
            materials: MeshMaterials::default().materials,
            triangle_materials: (0..n as u32).map(|t| t % 3).collect(),
        };
        let ids = spatial_part(&mesh, 3, 1);
        let kept = split_materials(&materials, &ids);
        assert_eq!(kept.triangle_materials.len(), ids.len());
        assert_eq!(kept.triangle_materials[0], ids[0] % 3);
    }
}
