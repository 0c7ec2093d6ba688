//! The marching-cubes tables, generated at first use from the cube's topology
//! (nothing here is hand-typed but the cube's 8 corners and 12 edges).
//!
//! # Conventions
//!
//! - Corner `n` of a cell is at offset `(n & 1, n >> 1 & 1, n >> 2 & 1)` from the
//!   cell's lowest sample (x is bit 0, y bit 1, z bit 2).
//! - A corner is *inside* when its value is **below** the level; bit `n` of a
//!   cell's case is set when corner `n` is inside. Case 0 (all outside) and case
//!   255 (all inside) have no surface.
//! - Edge `e` joins corners [`EDGES`]`[e] = [lo, hi]`, `lo < hi`, so `lo` is the
//!   endpoint with the smaller coordinate: two cells that share an edge
//!   interpolate its vertex from the same samples in the same order and get the
//!   same floating-point position.
//!
//! # How the tables are made
//!
//! For each of the 256 cases:
//!
//! 1. the *crossing* edges are those whose corners differ (one inside, one out);
//! 2. on each of the 6 faces the crossing edges pair up into segments of the
//!    surface's trace on that face: a face has 0, 2 or 4 crossings; with 2 they
//!    form one segment; with 4 the face is *ambiguous* (diagonal corners equal)
//!    and the fixed rule is to **separate the inside corners**: each inside
//!    corner's two face edges form a segment. The rule depends only on the signs
//!    of that face's four corners, so the two cells sharing a face choose the
//!    same segments and the surface is watertight;
//! 3. each segment is directed so that, seen from outside the cube, the outside
//!    corners of the face are on its left (the inside ones on its right);
//! 4. every crossing edge then has exactly one segment leaving and one arriving
//!    (it lies on two faces); following them gives closed polygons, whose
//!    winding makes their normal (right-hand rule) point **towards the outside**,
//!    the side of values above the level, i.e. up the field's gradient;
//! 5. each polygon (3 to 7 vertices) is fan-triangulated from the first vertex
//!    whose diagonals do not lie in a cube face. A diagonal between two vertices
//!    on one face would lie in that face, where the neighbouring cell may draw
//!    the same segment, and the mesh would no longer be a 2-manifold.
//!
//! At most [`MAX_CELL_TRIANGLES`] = 5 triangles per cell come out, as in classic
//! marching cubes, and every case without an ambiguous face has the classic
//! triangle count (see the tests).

use std::sync::OnceLock;

/// The most triangles one cell produces.
pub const MAX_CELL_TRIANGLES: usize = 5;

/// The 12 edges of the cube as corner pairs `[lo, hi]`: the 4 edges along x
/// first, then the 4 along y, then the 4 along z.
pub const EDGES: [[u8; 2]; 12] = [
    [0, 1],
    [2, 3],
    [4, 5],
    [6, 7],
    [0, 2],
    [1, 3],
    [4, 6],
    [5, 7],
    [0, 4],
    [1, 5],
    [2, 6],
    [3, 7],
];

/// The position of corner `n` in the unit cube.
pub fn corner_offset(corner: u8) -> [u32; 3] {
    [
        (corner & 1) as u32,
        (corner >> 1 & 1) as u32,
        (corner >> 2 & 1) as u32,
    ]
}

/// The generated tables: for each case, its triangles as triples of edge indices.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct McTables {
    /// Triangles of each case (`0..=5`).
    pub counts: [u8; 256],
    /// The first `counts[case]` entries are the case's triangles, each three
    /// edges whose vertices, in this order, wind counter-clockwise seen from
    /// the outside (values above the level). Unused entries are `[0; 3]`.
    pub triangles: [[[u8; 3]; MAX_CELL_TRIANGLES]; 256],
}

impl McTables {
    /// The triangles of `case` (only its low 8 bits are used).
    pub fn case_triangles(&self, case: u32) -> &[[u8; 3]] {
        let case = (case & 0xff) as usize;
        &self.triangles[case][..self.counts[case] as usize]
    }
}

/// The tables, generated on first use.
pub fn tables() -> &'static McTables {
    static TABLES: OnceLock<McTables> = OnceLock::new();
    TABLES.get_or_init(generate)
}

/// One face of the cube: its outward normal and its 4 edges.
#[derive(Clone, Copy, Debug)]
struct Face {
    normal: [f32; 3],
    edges: [u8; 4],
}

fn faces() -> [Face; 6] {
    std::array::from_fn(|f| {
        let (axis, side) = (f / 2, (f % 2) as u8);
        let on_face = |corner: u8| (corner >> axis & 1) == side;
        let mut edges = [0u8; 4];
        let mut count = 0;
        for (e, &[a, b]) in EDGES.iter().enumerate() {
            if on_face(a) && on_face(b) {
                edges[count] = e as u8;
                count += 1;
            }
        }
        assert_eq!(count, 4, "a cube face has 4 edges");
        let mut normal = [0.0; 3];
        normal[axis] = if side == 1 { 1.0 } else { -1.0 };
        Face { normal, edges }
    })
}

fn corner_point(corner: u8) -> [f32; 3] {
    corner_offset(corner).map(|c| c as f32)
}

fn edge_midpoint(edge: u8) -> [f32; 3] {
    let [a, b] = EDGES[edge as usize].map(corner_point);
    std::array::from_fn(|i| 0.5 * (a[i] + b[i]))
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    std::array::from_fn(|i| a[i] - b[i])
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn inside(case: u8, corner: u8) -> bool {
    case >> corner & 1 == 1
}

/// Whether edge `e` has one corner inside and one outside in `case`.
pub fn is_crossing(case: u8, edge: u8) -> bool {
    let [a, b] = EDGES[edge as usize];
    inside(case, a) != inside(case, b)
}

/// Whether two edges lie on a common face of the cube.
pub fn share_a_face(a: u8, b: u8) -> bool {
    faces()
        .iter()
        .any(|f| f.edges.contains(&a) && f.edges.contains(&b))
}

/// The surface's segments on the faces of the cube for `case`, directed so that
/// the outside corners are on the left seen from outside the cube: `(from, to)`.
pub fn face_segments(case: u8) -> Vec<(u8, u8)> {
    let mut segments = Vec::new();
    for face in faces() {
        let crossing: Vec<u8> = face
            .edges
            .iter()
            .copied()
            .filter(|&e| is_crossing(case, e))
            .collect();
        let pairs: Vec<(u8, u8)> = match crossing.len() {
            0 => vec![],
            2 => vec![(crossing[0], crossing[1])],
            4 => {
                // Ambiguous: each inside corner's two edges on this face form a
                // segment that cuts that corner off.
                let corners: Vec<u8> = {
                    let mut c: Vec<u8> =
                        face.edges.iter().flat_map(|&e| EDGES[e as usize]).collect();
                    c.sort_unstable();
                    c.dedup();
                    c
                };
                corners
                    .iter()
                    .filter(|&&c| inside(case, c))
                    .map(|&c| {
                        let mut at_corner = face
                            .edges
                            .iter()
                            .copied()
                            .filter(|&e| EDGES[e as usize].contains(&c));
                        (at_corner.next().unwrap(), at_corner.next().unwrap())
                    })
                    .collect()
            }
            n => unreachable!("a face has an even number of crossings, got {n}"),
        };
        for (e1, e2) in pairs {
            let m1 = edge_midpoint(e1);
            let direction = sub(edge_midpoint(e2), m1);
            let [a, b] = EDGES[e1 as usize];
            let outside_corner = if inside(case, a) { b } else { a };
            let left = cross(face.normal, direction);
            if dot(left, sub(corner_point(outside_corner), m1)) > 0.0 {
                segments.push((e1, e2));
            } else {
                segments.push((e2, e1));
            }
        }
    }
    segments
}

/// The closed polygons of `case`, each a cycle of edges, winding
/// counter-clockwise seen from the outside.
pub fn polygons(case: u8) -> Vec<Vec<u8>> {
    let segments = face_segments(case);
    let mut next = [u8::MAX; 12];
    for &(from, to) in &segments {
        assert_eq!(
            next[from as usize],
            u8::MAX,
            "case {case}: edge {from} starts two segments"
        );
        next[from as usize] = to;
    }
    let mut visited = [false; 12];
    let mut polygons = Vec::new();
    for start in 0..12u8 {
        if !is_crossing(case, start) || visited[start as usize] {
            continue;
        }
        let mut polygon = Vec::new();
        let mut edge = start;
        while !visited[edge as usize] {
            visited[edge as usize] = true;
            polygon.push(edge);
            edge = next[edge as usize];
            assert!(edge != u8::MAX, "case {case}: an open polygon");
        }
        assert_eq!(edge, start, "case {case}: a polygon does not close");
        polygons.push(polygon);
    }
    polygons
}

/// Fan-triangulates a polygon from the first vertex none of whose diagonals
/// joins two edges of one face.
fn triangulate(case: u8, polygon: &[u8]) -> Vec<[u8; 3]> {
    let n = polygon.len();
    assert!(n >= 3, "case {case}: a polygon of {n} vertices");
    let apex = (0..n)
        .find(|&apex| {
            (2..n - 1).all(|step| !share_a_face(polygon[apex], polygon[(apex + step) % n]))
        })
        .unwrap_or_else(|| panic!("case {case}: no fan of {polygon:?} avoids the faces"));
    (1..n - 1)
        .map(|i| {
            [
                polygon[apex],
                polygon[(apex + i) % n],
                polygon[(apex + i + 1) % n],
            ]
        })
        .collect()
}

fn generate() -> McTables {
    let mut tables = McTables {
        counts: [0; 256],
        triangles: [[[0; 3]; MAX_CELL_TRIANGLES]; 256],
    };
    for case in 0..=255u8 {
        let triangles: Vec<[u8; 3]> = polygons(case)
            .iter()
            .flat_map(|polygon| triangulate(case, polygon))
            .collect();
        assert!(
            triangles.len() <= MAX_CELL_TRIANGLES,
            "case {case}: {} triangles",
            triangles.len()
        );
        tables.counts[case as usize] = triangles.len() as u8;
        tables.triangles[case as usize][..triangles.len()].copy_from_slice(&triangles);
    }
    tables
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::{BTreeMap, BTreeSet};

    fn case_of(corners: &[u8]) -> u8 {
        corners.iter().fold(0, |case, &c| case | 1 << c)
    }

    fn crossing_edges(case: u8) -> BTreeSet<u8> {
        (0..12).filter(|&e| is_crossing(case, e)).collect()
    }

    fn used_edges(case: u8) -> BTreeSet<u8> {
        tables()
            .case_triangles(case as u32)
            .iter()
            .flatten()
            .copied()
            .collect()
    }

    fn ambiguous(case: u8) -> bool {
        faces()
            .iter()
            .any(|face| face.edges.iter().filter(|&&e| is_crossing(case, e)).count() == 4)
    }

    /// The 24 rotations of the cube as permutations of its corners.
    fn rotations() -> Vec<[u8; 8]> {
        let apply = |corner: u8, f: fn([u32; 3]) -> [u32; 3]| {
            let [x, y, z] = f(corner_offset(corner));
            (x | y << 1 | z << 2) as u8
        };
        let about_z: [u8; 8] = std::array::from_fn(|c| apply(c as u8, |[x, y, z]| [1 - y, x, z]));
        let about_x: [u8; 8] = std::array::from_fn(|c| apply(c as u8, |[x, y, z]| [x, 1 - z, y]));
        let identity: [u8; 8] = std::array::from_fn(|c| c as u8);
        let mut group = vec![identity];
        let mut frontier = vec![identity];
        while let Some(p) = frontier.pop() {
            for g in [about_z, about_x] {
                let q: [u8; 8] = std::array::from_fn(|c| g[p[c] as usize]);
                if !group.contains(&q) {
                    group.push(q);
                    frontier.push(q);
                }
            }
        }
        group
    }

    fn permute(case: u8, p: &[u8; 8]) -> u8 {
        (0..8u8)
            .filter(|&c| inside(case, c))
            .fold(0, |out, c| out | 1 << p[c as usize])
    }

    /// The smallest case equivalent to `case` under rotations and complement
    /// (Lorensen and Cline's 15 classes).
    fn class(case: u8, rotations: &[[u8; 8]]) -> u8 {
        rotations
            .iter()
            .flat_map(|p| [permute(case, p), !permute(case, p)])
            .min()
            .unwrap()
    }

    #[test]
    fn edges_are_the_twelve_unit_edges_low_corner_first() {
        let mut seen = BTreeSet::new();
        for [a, b] in EDGES {
            assert!(a < b);
            assert_eq!((a ^ b).count_ones(), 1, "{a}-{b} is not a cube edge");
            seen.insert((a, b));
        }
        assert_eq!(seen.len(), 12);
        assert_eq!(rotations().len(), 24);
    }

    #[test]
    fn empty_and_full_cells_have_no_triangles() {
        assert_eq!(tables().counts[0], 0);
        assert_eq!(tables().counts[255], 0);
        assert!(tables().case_triangles(0).is_empty());
    }

    #[test]
    fn every_crossing_edge_is_used_and_no_other() {
        for case in 0..=255u8 {
            assert_eq!(used_edges(case), crossing_edges(case), "case {case}");
            for triangle in tables().case_triangles(case as u32) {
                let distinct: BTreeSet<u8> = triangle.iter().copied().collect();
                assert_eq!(distinct.len(), 3, "case {case}: {triangle:?}");
            }
        }
    }

    #[test]
    fn complementary_cases_have_the_same_edges() {
        for case in 0..=255u8 {
            assert_eq!(used_edges(case), used_edges(!case), "case {case}");
            // Unambiguous complements are the same surface turned inside out.
            if !ambiguous(case) {
                assert_eq!(
                    tables().counts[case as usize],
                    tables().counts[!case as usize],
                    "case {case}"
                );
            }
        }
    }

    #[test]
    fn at_most_five_triangles_and_counts_are_crossings_minus_twice_the_polygons() {
        let max = (0..256).map(|c| tables().counts[c]).max().unwrap();
        assert_eq!(max as usize, MAX_CELL_TRIANGLES);
        for case in 0..=255u8 {
            let expected = crossing_edges(case).len() - 2 * polygons(case).len();
            assert_eq!(tables().counts[case as usize] as usize, expected);
        }
    }

    #[test]
    fn unambiguous_cases_have_the_classic_counts() {
        // A representative of each of Lorensen and Cline's 15 cases (corners
        // inside) and its classic triangle count.
        let classic: [(&[u8], u8); 15] = [
            (&[], 0),
            (&[0], 1),
            (&[0, 1], 2),
            (&[0, 3], 2),
            (&[0, 7], 2),
            (&[0, 1, 2], 3),
            (&[0, 1, 7], 3),
            (&[1, 2, 4], 3),
            (&[0, 1, 2, 3], 2),
            (&[0, 1, 2, 4], 4),
            (&[0, 3, 4, 7], 4),
            (&[0, 1, 3, 7], 4),
            (&[0, 1, 2, 7], 4),
            (&[0, 3, 5, 6], 4),
            (&[0, 2, 3, 7], 4),
        ];
        let rotations = rotations();
        let expected: BTreeMap<u8, u8> = classic
            .iter()
            .map(|(corners, count)| (class(case_of(corners), &rotations), *count))
            .collect();
        assert_eq!(expected.len(), 15, "the representatives are distinct");
        let classes: BTreeSet<u8> = (0..=255u8).map(|c| class(c, &rotations)).collect();
        assert_eq!(classes, expected.keys().copied().collect());
        let mut checked = 0;
        for case in 0..=255u8 {
            let count = tables().counts[case as usize];
            if !ambiguous(case) {
                assert_eq!(count, expected[&class(case, &rotations)], "case {case}");
                checked += 1;
            }
            // Few enough inside corners: separating them is what classic MC
            // does too, so even the ambiguous cases agree.
            if case.count_ones() <= 4 {
                assert_eq!(count, expected[&class(case, &rotations)], "case {case}");
            }
        }
        assert!(checked > 100, "{checked}");
        // A few by hand.
        for (corners, count) in [
            (&[0u8][..], 1),
            (&[0, 1], 2),
            (&[0, 1, 2, 3], 2),
            (&[0, 1, 2, 4], 4),
            (&[0, 3, 5, 6], 4),
        ] {
            assert_eq!(tables().counts[case_of(corners) as usize], count);
        }
    }

    #[test]
    fn triangles_face_the_outside() {
        // Cutting off one inside corner: the normal points away from it.
        for corner in 0..8u8 {
            let case = case_of(&[corner]);
            let [t] = tables().case_triangles(case as u32) else {
                panic!("case {case} has one triangle")
            };
            let [a, b, c] = t.map(edge_midpoint);
            let normal = cross(sub(b, a), sub(c, a));
            assert!(dot(normal, sub(a, corner_point(corner))) > 0.0, "{corner}");
            // The complement: one outside corner, the normal points to it.
            let [t] = tables().case_triangles(!case as u32) else {
                panic!("case {} has one triangle", !case)
            };
            let [a, b, c] = t.map(edge_midpoint);
            let normal = cross(sub(b, a), sub(c, a));
            assert!(dot(normal, sub(corner_point(corner), a)) > 0.0, "{corner}");
        }
    }

    #[test]
    fn each_face_segment_is_one_triangle_edge_and_diagonals_are_interior() {
        for case in 0..=255u8 {
            let mut directed: BTreeMap<(u8, u8), usize> = BTreeMap::new();
            for &[a, b, c] in tables().case_triangles(case as u32) {
                for edge in [(a, b), (b, c), (c, a)] {
                    *directed.entry(edge).or_default() += 1;
                }
            }
            for segment in face_segments(case) {
                assert_eq!(directed.get(&segment), Some(&1), "case {case}");
                assert_eq!(directed.get(&(segment.1, segment.0)), None);
            }
            for (&(a, b), &n) in &directed {
                assert_eq!(n, 1, "case {case}: ({a}, {b}) twice");
                if !face_segments(case).contains(&(a, b)) {
                    // A diagonal: used once each way, inside the cube.
                    assert_eq!(directed.get(&(b, a)), Some(&1), "case {case}");
                    assert!(!share_a_face(a, b), "case {case}: ({a}, {b})");
                }
            }
        }
    }

    #[test]
    fn ambiguous_faces_are_resolved_by_the_face_alone() {
        // The two cells that share a face see the same four corner signs there
        // and must draw the same segments (reversed, as the face's outward
        // normals are opposite). Check through cells stacked along each axis.
        for axis in 0..3usize {
            let faces = faces();
            // Face 2·axis is the low side, 2·axis + 1 the high side.
            let (top_of_below, bottom_of_above) = (faces[2 * axis + 1], faces[2 * axis]);
            for below in 0..=255u8 {
                for above in 0..=255u8 {
                    // `below`'s high face is `above`'s low face: corners with bit
                    // `axis` set in `below` are those without it in `above`.
                    let shared = (0..8u8)
                        .filter(|&c| c >> axis & 1 == 1)
                        .all(|c| inside(below, c) == inside(above, c & !(1 << axis)));
                    if !shared {
                        continue;
                    }
                    let on = |face: Face, case: u8| -> BTreeSet<(u8, u8)> {
                        face_segments(case)
                            .into_iter()
                            .filter(|(a, b)| face.edges.contains(a) && face.edges.contains(b))
                            .collect()
                    };
                    // Edge e on the high face of `below` is edge e' on the low face of
                    // `above`, whose corners are those minus the axis bit.
                    let shift = |e: u8| {
                        let [a, b] = EDGES[e as usize].map(|c| c & !(1 << axis));
                        EDGES.iter().position(|&x| x == [a, b]).unwrap() as u8
                    };
                    let from_below: BTreeSet<(u8, u8)> = on(top_of_below, below)
                        .into_iter()
                        .map(|(a, b)| (shift(b), shift(a)))
                        .collect();
                    assert_eq!(
                        from_below,
                        on(bottom_of_above, above),
                        "axis {axis}: {below} | {above}"
                    );
                }
            }
        }
    }
}
