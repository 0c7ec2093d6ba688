//! Meshes and ray targets for the tests of watertightness (CPU and GPU).

use crate::mesh::{Bounds, TriangleMesh};
use glam::Vec3;

/// A closed cube of `6 n²` unit squares on integer coordinates `0..=n` (shared
/// vertices, outward winding), so that points on its edges are exact in f32.
pub fn subdivided_cube(n: u32) -> TriangleMesh {
    let mut index_of = std::collections::HashMap::new();
    let mut positions = Vec::new();
    let mut vertex = |p: [u32; 3]| {
        *index_of.entry(p).or_insert_with(|| {
            positions.push(Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32));
            positions.len() as u32 - 1
        })
    };
    let mut triangles = Vec::new();
    for axis in 0..3 {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        for side in [0, n] {
            for i in 0..n {
                for j in 0..n {
                    let mut corner = |di: u32, dj: u32| {
                        let mut p = [0; 3];
                        p[axis] = side;
                        p[u] = i + di;
                        p[v] = j + dj;
                        vertex(p)
                    };
                    let [a, b, c, d] = [corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1)];
                    if side == n {
                        triangles.extend([[a, b, c], [a, c, d]]);
                    } else {
                        triangles.extend([[a, c, b], [a, d, c]]);
                    }
                }
            }
        }
    }
    TriangleMesh {
        positions,
        triangles,
        normals: None,
        scalars: None,
    }
}

/// Targets on a mesh's vertices and edges: the vertices, and points a quarter,
/// a third and half way along every edge.
pub fn vertex_and_edge_targets(mesh: &TriangleMesh) -> Vec<Vec3> {
    let mut targets = mesh.positions.clone();
    let mut edges = std::collections::HashSet::new();
    for &[a, b, c] in &mesh.triangles {
        for (p, q) in [(a, b), (b, c), (c, a)] {
            edges.insert((p.min(q), p.max(q)));
        }
    }
    let mut edges: Vec<_> = edges.into_iter().collect();
    edges.sort_unstable();
    for (p, q) in edges {
        let (p, q) = (mesh.positions[p as usize], mesh.positions[q as usize]);
        for s in [0.25, 1.0 / 3.0, 0.5] {
            targets.push(p + s * (q - p));
        }
    }
    targets
}

/// The outward direction of an axis-aligned box at a point of its surface:
/// the face normal, and at edges and corners the sum of the faces' normals.
pub fn box_outward(target: Vec3, bounds: &Bounds) -> Vec3 {
    let side = |x: f32, low: f32, high: f32| {
        if x == low {
            -1.0
        } else if x == high {
            1.0
        } else {
            0.0
        }
    };
    Vec3::new(
        side(target.x, bounds.min.x, bounds.max.x),
        side(target.y, bounds.min.y, bounds.max.y),
        side(target.z, bounds.min.z, bounds.max.z),
    )
    .normalize()
}
