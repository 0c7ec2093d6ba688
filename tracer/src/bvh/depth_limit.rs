//! Keeping a binary tree within the traversal stacks' depth.
//!
//! PLOC clusters by locality, so a region of many tiny or degenerate triangles
//! (the poles of a finely tessellated sphere, a fan around one vertex) can grow
//! a chain far deeper than `log2(n)`. The stacks (and the GPU shaders) have a
//! fixed bound, [`super::MAX_STACK_DEPTH`]; rather than discarding the whole
//! tree for a balanced one, [`limit_depth`] rebuilds only the subtrees that
//! would reach past it, each by a [`median_split`] of its own triangles, and
//! keeps PLOC's tree everywhere else.

use super::MAX_STACK_DEPTH;
use crate::mesh::{TriangleMesh, MAX_TRIANGLES};
use glam::Vec3A;
use obvhs::aabb::Aabb;
use obvhs::bvh2::node::Bvh2Node;

/// Triangles per leaf of a median-split tree.
const MEDIAN_SPLIT_LEAF_SIZE: usize = 4;

// A median split of the largest mesh fits the stacks, so [`limit_depth`] can
// always fall back to one from the root (checked at compile time).
const _: () = assert!(median_split_levels(MAX_TRIANGLES) <= MAX_STACK_DEPTH);

/// The box of triangle `id`.
pub(super) fn triangle_box(mesh: &TriangleMesh, id: u32) -> Aabb {
    Aabb::from_points(&mesh.triangle_vertices(id as usize).map(Vec3A::from))
}

/// The tree `(nodes, primitive_indices)` (obvhs layout: root at 0, siblings at
/// `first_index` and `first_index + 1`) with no inner node deeper than
/// `max_depth` (the root's depth is 1), or `None` when it has none already.
/// PLOC's nodes are kept down to where a subtree would reach past the limit and
/// a child of it could not be rebuilt within it anymore; that subtree is
/// rebuilt by a median split of its triangles. At worst that is the root, and
/// a median split of any mesh fits (a compile-time assertion below).
pub(super) fn limit_depth(
    nodes: &[Bvh2Node],
    primitive_indices: &[u32],
    mesh: &TriangleMesh,
    max_depth: usize,
) -> Option<(Vec<Bvh2Node>, Vec<u32>)> {
    let sizes = SubtreeSizes::of(nodes);
    if sizes.inner_height[0] <= max_depth {
        return None;
    }
    let fits_in_a_median_split = |index: usize, depth: usize| {
        let levels = median_split_levels(sizes.triangles[index]);
        levels == 0 || depth + levels - 1 <= max_depth
    };
    let mut limited = vec![Bvh2Node::default()];
    let mut limited_indices = Vec::with_capacity(primitive_indices.len());
    // (source node, limited node, its depth)
    let mut work = vec![(0usize, 0usize, 1usize)];
    while let Some((source, target, depth)) = work.pop() {
        let node = &nodes[source];
        let first = limited_indices.len() as u32;
        let child = node.first_index as usize;
        if node.is_leaf() {
            let range = child..child + node.prim_count as usize;
            limited_indices.extend_from_slice(&primitive_indices[range]);
            limited[target] = Bvh2Node::new(*node.aabb(), node.prim_count, first);
        } else if depth + sizes.inner_height[source] - 1 <= max_depth
            || (fits_in_a_median_split(child, depth + 1)
                && fits_in_a_median_split(child + 1, depth + 1))
        {
            let children = limited.len();
            limited.extend([Bvh2Node::default(); 2]);
            limited[target] = Bvh2Node::new(*node.aabb(), 0, children as u32);
            work.push((child + 1, children + 1, depth + 1));
            work.push((child, children, depth + 1));
        } else {
            let ids = subtree_primitives(nodes, primitive_indices, source);
            let boxes: Vec<Aabb> = ids.iter().map(|&id| triangle_box(mesh, id)).collect();
            let mut order: Vec<u32> = (0..ids.len() as u32).collect();
            median_split(&mut limited, target, &boxes, &mut order, first);
            limited_indices.extend(order.iter().map(|&local| ids[local as usize]));
        }
    }
    Some((limited, limited_indices))
}

/// Per node of a tree: the number of inner nodes on the longest path down
/// from it (0 for a leaf), and the triangles under it.
struct SubtreeSizes {
    inner_height: Vec<usize>,
    triangles: Vec<usize>,
}

impl SubtreeSizes {
    fn of(nodes: &[Bvh2Node]) -> SubtreeSizes {
        // Pre-order: every node comes after its parent, so the reverse visits
        // children first.
        let mut preorder = Vec::with_capacity(nodes.len());
        let mut work = vec![0usize];
        while let Some(index) = work.pop() {
            preorder.push(index);
            if !nodes[index].is_leaf() {
                let child = nodes[index].first_index as usize;
                work.extend([child, child + 1]);
            }
        }
        let mut sizes = SubtreeSizes {
            inner_height: vec![0; nodes.len()],
            triangles: vec![0; nodes.len()],
        };
        for &index in preorder.iter().rev() {
            let node = &nodes[index];
            if node.is_leaf() {
                sizes.triangles[index] = node.prim_count as usize;
            } else {
                let child = node.first_index as usize;
                sizes.inner_height[index] =
                    1 + sizes.inner_height[child].max(sizes.inner_height[child + 1]);
                sizes.triangles[index] = sizes.triangles[child] + sizes.triangles[child + 1];
            }
        }
        sizes
    }
}

/// The levels of inner nodes of a [`median_split`] of `triangles`.
const fn median_split_levels(triangles: usize) -> usize {
    if triangles <= MEDIAN_SPLIT_LEAF_SIZE {
        0
    } else {
        // The larger half has the rounded-up half.
        1 + median_split_levels(triangles.div_ceil(2))
    }
}

/// The triangle ids under `root`, in depth-first order.
fn subtree_primitives(nodes: &[Bvh2Node], primitive_indices: &[u32], root: usize) -> Vec<u32> {
    let mut ids = Vec::new();
    let mut work = vec![root];
    while let Some(index) = work.pop() {
        let node = &nodes[index];
        if node.is_leaf() {
            let range = node.first_index as usize..(node.first_index + node.prim_count) as usize;
            ids.extend_from_slice(&primitive_indices[range]);
        } else {
            let child = node.first_index as usize;
            work.extend([child + 1, child]);
        }
    }
    ids
}

/// Writes a balanced tree over the boxes `order` names (indices into `boxes`)
/// into `nodes`, rooted at `nodes[root]`: each inner node halves its range at
/// the median centroid along the centroids' longest axis, down to leaves of
/// [`MEDIAN_SPLIT_LEAF_SIZE`] ([`median_split_levels`] levels of inner nodes).
/// Reorders `order` into leaf order; a leaf's
/// `first_index` is `first_index` plus its range's start in `order`.
pub(super) fn median_split(
    nodes: &mut Vec<Bvh2Node>,
    root: usize,
    boxes: &[Aabb],
    order: &mut [u32],
    first_index: u32,
) {
    let mut work = vec![(root, 0usize, order.len())];
    while let Some((node, start, end)) = work.pop() {
        let range = &mut order[start..end];
        let bounds = range
            .iter()
            .fold(Aabb::INVALID, |b, &i| b.union(&boxes[i as usize]));
        if range.len() <= MEDIAN_SPLIT_LEAF_SIZE {
            nodes[node] = Bvh2Node::new(bounds, range.len() as u32, first_index + start as u32);
            continue;
        }
        let centroids = range.iter().fold(Aabb::INVALID, |mut b, &i| {
            b.extend(boxes[i as usize].center());
            b
        });
        let axis = centroids.largest_axis();
        let middle = range.len() / 2;
        range.select_nth_unstable_by(middle, |&a, &b| {
            let ca = boxes[a as usize].center_axis(axis);
            let cb = boxes[b as usize].center_axis(axis);
            ca.total_cmp(&cb)
        });
        let left = nodes.len();
        nodes.extend([Bvh2Node::default(); 2]);
        nodes[node] = Bvh2Node::new(bounds, 0, left as u32);
        work.push((left, start, start + middle));
        work.push((left + 1, start + middle, end));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// A zigzag strip of `count` triangles along x.
    fn strip(count: usize) -> TriangleMesh {
        TriangleMesh {
            positions: (0..count + 2)
                .map(|i| Vec3::new(i as f32 * 0.5, (i % 2) as f32, 0.0))
                .collect(),
            triangles: (0..count as u32).map(|i| [i, i + 1, i + 2]).collect(),
            normals: None,
            scalars: None,
        }
    }

    /// Writes a caterpillar over triangles `ids` at `nodes[root]`: each inner
    /// node has one triangle as a leaf and the rest of the chain as its other
    /// child, `ids.len() - 1` inner nodes deep. Leaves index `primitive_indices`,
    /// to which the ids are appended.
    fn caterpillar(
        nodes: &mut Vec<Bvh2Node>,
        root: usize,
        mesh: &TriangleMesh,
        ids: &[u32],
        primitive_indices: &mut Vec<u32>,
    ) {
        let mut current = root;
        for (position, &id) in ids.iter().enumerate() {
            let leaf = Bvh2Node::new(triangle_box(mesh, id), 1, primitive_indices.len() as u32);
            primitive_indices.push(id);
            if position + 1 == ids.len() {
                nodes[current] = leaf;
                break;
            }
            let rest = ids[position..]
                .iter()
                .fold(Aabb::INVALID, |b, &i| b.union(&triangle_box(mesh, i)));
            let first = nodes.len();
            nodes.extend([leaf, Bvh2Node::default()]);
            nodes[current] = Bvh2Node::new(rest, 0, first as u32);
            current = first + 1;
        }
    }

    /// A root whose left child is a median split of triangles `0..balanced` and
    /// whose right child is a caterpillar of the others.
    fn half_balanced_half_chain(mesh: &TriangleMesh, balanced: u32) -> (Vec<Bvh2Node>, Vec<u32>) {
        let count = mesh.triangles.len() as u32;
        let all = (0..count).fold(Aabb::INVALID, |b, i| b.union(&triangle_box(mesh, i)));
        let mut nodes = vec![
            Bvh2Node::new(all, 0, 1),
            Bvh2Node::default(),
            Bvh2Node::default(),
        ];
        let boxes: Vec<Aabb> = (0..balanced).map(|id| triangle_box(mesh, id)).collect();
        let mut indices: Vec<u32> = (0..balanced).collect();
        median_split(&mut nodes, 1, &boxes, &mut indices, 0);
        let chain: Vec<u32> = (balanced..count).collect();
        caterpillar(&mut nodes, 2, mesh, &chain, &mut indices);
        (nodes, indices)
    }

    /// The triangle ids of each leaf under `root`, in depth-first order.
    fn leaves(nodes: &[Bvh2Node], primitive_indices: &[u32], root: usize) -> Vec<Vec<u32>> {
        let mut leaves = Vec::new();
        let mut work = vec![root];
        while let Some(index) = work.pop() {
            let node = &nodes[index];
            if node.is_leaf() {
                let range =
                    node.first_index as usize..(node.first_index + node.prim_count) as usize;
                leaves.push(primitive_indices[range].to_vec());
            } else {
                work.extend([node.first_index as usize + 1, node.first_index as usize]);
            }
        }
        leaves
    }

    #[test]
    fn subtree_sizes_count_the_longest_chain_and_the_triangles() {
        let mesh = strip(300);
        let (nodes, _) = half_balanced_half_chain(&mesh, 100);
        let sizes = SubtreeSizes::of(&nodes);
        assert_eq!(sizes.inner_height[2], 199);
        assert_eq!(sizes.inner_height[1], median_split_levels(100));
        assert_eq!(median_split_levels(100), 5, "100 → 50 → 25 → 13 → 7 → 4");
        assert_eq!(sizes.inner_height[0], 200);
        assert_eq!(sizes.triangles[..3], [300, 100, 200]);
    }

    #[test]
    fn a_tree_within_the_limit_is_left_alone() {
        let mesh = strip(300);
        let (nodes, indices) = half_balanced_half_chain(&mesh, 100);
        assert!(limit_depth(&nodes, &indices, &mesh, 200).is_none());
        assert!(limit_depth(&nodes, &indices, &mesh, 199).is_some());
    }

    #[test]
    fn only_what_reaches_past_the_limit_is_rebuilt() {
        let mesh = strip(300);
        let (nodes, indices) = half_balanced_half_chain(&mesh, 100);
        let max_depth = 20;
        let (limited, limited_indices) = limit_depth(&nodes, &indices, &mesh, max_depth).unwrap();
        assert_eq!(SubtreeSizes::of(&limited).inner_height[0], max_depth);
        let mut ids: Vec<u32> = leaves(&limited, &limited_indices, 0).concat();
        ids.sort_unstable();
        assert_eq!(ids, (0..300).collect::<Vec<u32>>());
        // The balanced half is kept leaf for leaf.
        let left = limited[0].first_index as usize;
        assert_eq!(
            leaves(&limited, &limited_indices, left),
            leaves(&nodes, &indices, 1)
        );
        // The chain is kept while the rest of it still fits a median split: at
        // depth d its node holds triangle 98 + d as a leaf, and the 201 - d
        // triangles after it in its other child, at depth d + 1.
        let mut chain = left + 1;
        for depth in 2.. {
            let rest = 201 - depth;
            if depth + 1 + median_split_levels(rest) - 1 > max_depth {
                break;
            }
            let node = &limited[chain];
            let leaf = &limited[node.first_index as usize];
            assert!(leaf.is_leaf(), "depth {depth}");
            assert_eq!(
                limited_indices[leaf.first_index as usize],
                98 + depth as u32,
                "depth {depth}"
            );
            chain = node.first_index as usize + 1;
        }
        // Every box still holds its children's.
        for node in limited.iter().filter(|node| !node.is_leaf()) {
            let children = &limited[node.first_index as usize..][..2];
            let union = children[0].aabb().union(children[1].aabb());
            assert!(node.aabb().contains_point(union.min) && node.aabb().contains_point(union.max));
        }
    }
}
