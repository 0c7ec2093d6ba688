//! The linear BVH (`--bvh lbvh`): Karras' construction ("Maximizing
//! parallelism in the construction of BVHs, octrees, and k-d trees", HPG
//! 2012), in the data-parallel steps a GPU would run, but for the last:
//!
//! 1. a map and a reduce: the box of the triangles' centres;
//! 2. a map: each triangle's key, the Morton code of its centre above its
//!    index;
//! 3. a radix sort of the keys (all distinct), and a gather of the triangles'
//!    boxes in their order;
//! 4. a map over the `n - 1` inner nodes: each finds its range of sorted
//!    leaves and where it splits (the radix tree of the keys), from its
//!    neighbours' keys alone;
//! 5. the boxes bottom-up: every leaf climbs towards the root, and the second
//!    child to arrive at a node joins the two boxes, decides whether the node
//!    becomes one leaf (the rule `flatten` applies to PLOC's trees,
//!    [`super::collapses_into_one_leaf`]) and climbs on;
//! 6. a walk that numbers the inner nodes left in depth-first order, and a
//!    map that writes them in our layout, children's boxes inside. (A stream
//!    compaction in the radix tree's order made the eight-wide collapse that
//!    follows slower by more than the walk costs: 0.92 of the SAH build's
//!    time on the brain's isosurface instead of 0.82, docs/benchmarks.md.)
//!
//! Every node's leaves are consecutive in sorted order, so a node made a leaf
//! is the range its leftmost leaf starts, and the sorted order is the leaf
//! order. No step looks at a surface area but the collapse, so its trees trace
//! slower than the binned SAH build's (at 0.89-1.00 of its rate on the bench
//! scenes, docs/benchmarks.md).
//!
//! Depth: each inner node's keys share a longer prefix than its parent's, so
//! no inner node is deeper than the keys' 64 bits, which the traversal stacks
//! hold (asserted below): the depth limit never has to rebuild a linear BVH.
//!
//! Determinism: the keys are distinct, so the sort has one result; the radix
//! tree is a function of the sorted keys; a box is a minimum and maximum, which
//! no order of joining changes. The tree is the same on any number of threads.

use super::depth_limit::triangle_box;
use super::{binary_child, collapses_into_one_leaf, root_first, BinaryTree, BvhNode, Flattened};
use crate::huge_pages::collect_on_huge_pages;
use crate::mesh::TriangleMesh;
use obvhs::aabb::Aabb;
use obvhs::ploc::morton::morton_encode_u64;
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, Ordering};

/// A child reference of [`radix_tree_node`] with this bit set is a leaf (a
/// sorted position); otherwise an inner node.
const LEAF: u32 = 1 << 31;

/// No parent: the root.
const NO_PARENT: u32 = u32::MAX;

/// Most Morton bits per axis (obvhs' 64-bit codes have 21).
const MAX_AXIS_BITS: u32 = 21;

const _: () = assert!(u64::BITS as usize <= super::MAX_STACK_DEPTH);

/// The linear BVH of a mesh in our binary layout.
pub(super) fn lbvh_binary_tree(mesh: &TriangleMesh) -> BinaryTree {
    let count = mesh.triangles.len() as u32;
    let keys = SortedKeys::new(mesh);
    let triangle_ids = collect_on_huge_pages(keys.words.par_iter().map(|&w| keys.triangle(w)));
    // The boxes in sorted order: the steps below read neighbours. (Every
    // array here is on huge pages: this VM faults each fresh 4 KiB page at a
    // cost of about 4 µs.)
    let leaf_boxes =
        collect_on_huge_pages(triangle_ids.par_iter().map(|&id| triangle_box(mesh, id)));
    // A tree that is one leaf (one triangle, or a root collapsed) still needs
    // an inner node, which `root_first` makes, as for PLOC's trees.
    let one_leaf = |triangle_ids| {
        let root_box = leaf_boxes.iter().fold(Aabb::INVALID, |a, b| a.union(b));
        let tree = BinaryTree {
            nodes: Vec::new(),
            triangle_ids,
            stack_depth: 1,
        };
        root_first(tree, Flattened::Leaf { first: 0, count }, &root_box)
    };
    if count == 1 {
        return one_leaf(triangle_ids);
    }
    let radix_nodes = collect_on_huge_pages(
        (0..count - 1)
            .into_par_iter()
            .map(|node| radix_tree_node(&keys.words, node)),
    );
    drop(keys);
    let inner = InnerNodes::bottom_up(&radix_nodes, &leaf_boxes);
    if inner.leaf_count(0) > 0 {
        return one_leaf(triangle_ids);
    }
    let (kept, new_index, stack_depth) = inner.depth_first(&radix_nodes);
    let child = |child: u32| {
        if child & LEAF != 0 {
            let position = child & !LEAF;
            let leaf = Flattened::Leaf {
                first: position,
                count: 1,
            };
            return binary_child(leaf, &leaf_boxes[position as usize]);
        }
        let flattened = match inner.leaf_count(child) {
            0 => Flattened::Inner(new_index[child as usize]),
            count => Flattened::Leaf {
                first: radix_nodes[child as usize].first,
                count,
            },
        };
        binary_child(flattened, &inner.get(child))
    };
    let nodes = collect_on_huge_pages(kept.par_iter().map(|&node| BvhNode {
        children: radix_nodes[node as usize].children.map(child),
    }));
    BinaryTree {
        nodes,
        triangle_ids,
        stack_depth,
    }
}

/// The triangles' keys in ascending order, one `u64` word each: the Morton
/// code of the box's centre, on a grid of cubic cells over the box of all
/// centres, above the triangle's index, so that triangles whose centres share
/// a cell still have distinct keys. The index takes the bits the triangle
/// count needs, the code the rest (14 bits per axis up to 4Mi triangles, 21
/// at most).
struct SortedKeys {
    words: Vec<u64>,
    index_bits: u32,
}

impl SortedKeys {
    fn new(mesh: &TriangleMesh) -> SortedKeys {
        let count = mesh.triangles.len() as u32;
        let index_bits = (u32::BITS - count.leading_zeros()).max(1);
        let axis_bits = ((u64::BITS - index_bits) / 3).min(MAX_AXIS_BITS);
        let cells = f64::from(1u32 << axis_bits);
        // Boxes are recomputed where needed rather than kept: an array of
        // them would be 32 bytes a triangle of fresh pages.
        let centre = |id: u32| triangle_box(mesh, id).center();
        let centres = (0..count)
            .into_par_iter()
            .map(|id| Aabb::from_point(centre(id)))
            .reduce(|| Aabb::INVALID, |a, b| a.union(&b));
        let low = centres.min.as_dvec3();
        // Cubic cells, the box's longest side cut in `cells`: cells stretched
        // along a thin axis made it split that axis as often as the long ones
        // (measured: the built-in layer's trees traced 17-25% slower). All
        // centres in one point map to cell 0, not to a NaN.
        let longest = (centres.max.as_dvec3() - low).max_element();
        let scale = [if longest > 0.0 { cells / longest } else { 0.0 }; 3];
        let mut words = collect_on_huge_pages((0..count).into_par_iter().map(|id| {
            let offset = (centre(id).as_dvec3() - low).to_array();
            let [x, y, z] = [0, 1, 2]
                .map(|axis| ((offset[axis] * scale[axis]) as u32).min((1 << axis_bits) - 1));
            morton_encode_u64(x, y, z) << index_bits | u64::from(id)
        }));
        // Distinct words: one ascending order, whatever the sort.
        rdst::RadixSort::radix_sort_unstable(&mut words);
        SortedKeys { words, index_bits }
    }

    fn triangle(&self, word: u64) -> u32 {
        (word & ((1 << self.index_bits) - 1)) as u32
    }
}

/// The length of the common prefix of the words at sorted positions `i` and
/// `j`, or `-1` where `j` is outside.
#[inline]
fn common_prefix(words: &[u64], i: usize, j: i64) -> i32 {
    match words.get(usize::try_from(j).unwrap_or(usize::MAX)) {
        Some(other) => (words[i] ^ other).leading_zeros() as i32,
        None => -1,
    }
}

/// An inner node of the radix tree: its two children, and the first sorted
/// position of its leaves.
#[derive(Clone, Copy)]
struct RadixNode {
    children: [u32; 2],
    first: u32,
}

/// Inner node `node`'s two children (Karras' algorithm 4): its range of sorted
/// leaves extends from `node` towards the neighbour it shares the longer
/// prefix with, as far as the keys share more than with the other neighbour;
/// it splits where the prefix of the whole range ends.
fn radix_tree_node(words: &[u64], node: u32) -> RadixNode {
    let i = node as usize;
    let at = |j: i64| common_prefix(words, i, j);
    let here = i as i64;
    let direction: i64 = if at(here + 1) > at(here - 1) { 1 } else { -1 };
    let least = at(here - direction);
    let mut reach: i64 = 2;
    while at(here + reach * direction) > least {
        reach *= 2;
    }
    let mut length: i64 = 0;
    let mut step = reach / 2;
    while step >= 1 {
        if at(here + (length + step) * direction) > least {
            length += step;
        }
        step /= 2;
    }
    let end = here + length * direction;
    let range_prefix = at(end);
    let mut split: i64 = 0;
    let mut step = length;
    loop {
        step = (step + 1) / 2;
        if at(here + (split + step) * direction) > range_prefix {
            split += step;
        }
        if step == 1 {
            break;
        }
    }
    let gamma = (here + split * direction + direction.min(0)) as u32;
    let (first, last) = (here.min(end) as u32, here.max(end) as u32);
    let left = if first == gamma { LEAF | gamma } else { gamma };
    let right = if last == gamma + 1 {
        LEAF | (gamma + 1)
    } else {
        gamma + 1
    };
    RadixNode {
        children: [left, right],
        first,
    }
}

/// What the bottom-up pass keeps of an inner node: its parent, how many of
/// its children have arrived, its box (six planes, `min` then `max`), and the
/// triangles of the one leaf it became (0: it stays an inner node).
struct InnerNode {
    parent: AtomicU32,
    arrivals: AtomicU32,
    planes: [AtomicU32; 6],
    leaf_count: AtomicU32,
}

/// The inner nodes' boxes, and which of them became leaves.
struct InnerNodes(Vec<InnerNode>);

impl InnerNodes {
    /// Each leaf climbs from its parent up; at every node the first child to
    /// arrive stops, and the second (which then sees its sibling's box and
    /// leaf count) joins the two and climbs on.
    fn bottom_up(radix_nodes: &[RadixNode], leaf_boxes: &[Aabb]) -> InnerNodes {
        let inner = InnerNodes(collect_on_huge_pages(
            (0..radix_nodes.len()).into_par_iter().map(|_| InnerNode {
                parent: AtomicU32::new(NO_PARENT),
                arrivals: AtomicU32::new(0),
                planes: std::array::from_fn(|_| AtomicU32::new(0)),
                leaf_count: AtomicU32::new(0),
            }),
        ));
        let leaf_parent = collect_on_huge_pages(
            (0..leaf_boxes.len())
                .into_par_iter()
                .map(|_| AtomicU32::new(NO_PARENT)),
        );
        radix_nodes
            .par_iter()
            .enumerate()
            .for_each(|(node, radix)| {
                for &child in &radix.children {
                    let parent = if child & LEAF != 0 {
                        &leaf_parent[(child & !LEAF) as usize]
                    } else {
                        &inner.0[child as usize].parent
                    };
                    parent.store(node as u32, Ordering::Relaxed);
                }
            });
        // A child's box and the triangles of the leaf it is (0: inner).
        let read = |child: u32| {
            if child & LEAF != 0 {
                (leaf_boxes[(child & !LEAF) as usize], 1)
            } else {
                (inner.get(child), inner.leaf_count(child))
            }
        };
        (0..leaf_boxes.len()).into_par_iter().for_each(|leaf| {
            let mut node = leaf_parent[leaf].load(Ordering::Relaxed);
            // The release of one arrival's results and the acquire of the other's.
            while node != NO_PARENT
                && inner.0[node as usize]
                    .arrivals
                    .fetch_add(1, Ordering::AcqRel)
                    == 1
            {
                let [left, right] = radix_nodes[node as usize].children.map(read);
                let joined = left.0.union(&right.0);
                let at = &inner.0[node as usize];
                if collapses_into_one_leaf(&joined, left, right) {
                    at.leaf_count.store(left.1 + right.1, Ordering::Relaxed);
                }
                let values = joined
                    .min
                    .to_array()
                    .into_iter()
                    .chain(joined.max.to_array());
                for (plane, value) in at.planes.iter().zip(values) {
                    plane.store(value.to_bits(), Ordering::Relaxed);
                }
                node = at.parent.load(Ordering::Relaxed);
            }
        });
        inner
    }

    /// Inner node `node`'s box (once [`InnerNodes::bottom_up`] has made it).
    fn get(&self, node: u32) -> Aabb {
        let planes = &self.0[node as usize].planes;
        let at = |k: usize| f32::from_bits(planes[k].load(Ordering::Relaxed));
        Aabb::new([at(0), at(1), at(2)].into(), [at(3), at(4), at(5)].into())
    }

    /// The triangles of the leaf inner node `node` became, or 0.
    fn leaf_count(&self, node: u32) -> u32 {
        self.0[node as usize].leaf_count.load(Ordering::Relaxed)
    }

    /// The nodes that stay inner (none below a node made a leaf can: it
    /// would have kept its parent inner) in depth-first order, each one's
    /// index in that order, and the depth of the deepest.
    fn depth_first(&self, radix_nodes: &[RadixNode]) -> (Vec<u32>, Vec<u32>, usize) {
        let mut order = Vec::with_capacity(self.0.len());
        let mut new_index = vec![0u32; self.0.len()];
        let mut deepest = 0;
        let mut work = vec![(0u32, 1usize)];
        while let Some((node, depth)) = work.pop() {
            new_index[node as usize] = order.len() as u32;
            order.push(node);
            deepest = deepest.max(depth);
            for &child in radix_nodes[node as usize].children.iter().rev() {
                if child & LEAF == 0 && self.leaf_count(child) == 0 {
                    work.push((child, depth + 1));
                }
            }
        }
        (order, new_index, deepest)
    }
}
