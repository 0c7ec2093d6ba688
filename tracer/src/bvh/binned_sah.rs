//! A top-down binned SAH build (Wald 2007, "On fast construction of SAH-based
//! bounding volume hierarchies"), the kind Embree's default builder is: each
//! node's triangles are binned by centroid along every axis, the split with the
//! lowest surface area cost is taken, and the triangles are partitioned in
//! place. obvhs' PLOC build and its reinsertion took longer than Embree's
//! build; this one builds faster and makes trees of lower cost
//! (docs/benchmarks.md). It makes our binary layout straight away, with
//! leaves decided by the same cost rule the PLOC path's collapse applies, so
//! nothing is flattened or collapsed afterwards.
//!
//! The tree depends only on the mesh, never on the number of threads: unions of
//! boxes are exact in any order, counts are integers, and each node's costs are
//! summed on one thread.

use super::{
    binary_child, root_first, splice, BinaryTree, BvhNode, Flattened, COLLAPSE_TRAVERSAL_COST,
    MAX_LEAF_TRIANGLES, MAX_STACK_DEPTH,
};
use crate::huge_pages::{collect_on_huge_pages, vec_on_huge_pages};
use crate::mesh::TriangleMesh;
use glam::{BVec3A, BVec4A, Vec3A, Vec4};
use obvhs::aabb::Aabb;
use rayon::prelude::*;

/// The binary tree of a (validated) mesh, leaves in depth-first order.
pub(super) fn binned_sah_tree(mesh: &TriangleMesh) -> BinaryTree {
    let count = mesh.triangles.len();
    let mut references = collect_on_huge_pages((0..count as u32).into_par_iter().map(|id| {
        let vertices = mesh.triangle_vertices(id as usize).map(Vec3A::from);
        let bounds = Aabb::from_points(&vertices);
        PrimitiveReference {
            min_and_id: bounds.min.extend(f32::from_bits(id)),
            max: bounds.max.extend(0.0),
        }
    }));
    let root = bounds_of(&references);
    let mut scratch = collect_on_huge_pages(references.par_iter().copied());
    let whole = NodeReferences {
        held: &mut references,
        spare: &mut scratch,
        held_in_scratch: false,
        first: 0,
    };
    let subtree = build_subtree(whole, root, 1);
    let mut tree = BinaryTree {
        nodes: vec_on_huge_pages(references.len()),
        triangle_ids: Vec::new(),
        stack_depth: 1,
    };
    let flattened = assemble(subtree, &mut tree);
    tree.triangle_ids = references.par_iter().map(|r| r.id()).collect();
    root_first(tree, flattened, &root.bounds)
}

/// A triangle as the build moves it: its box, and its index in the mesh in the
/// fourth lane of the box's corner (bits, never computed with). 32 bytes, so
/// the partitions move little memory and read it in order.
#[derive(Clone, Copy)]
#[repr(C)]
struct PrimitiveReference {
    min_and_id: Vec4,
    max: Vec4,
}

impl PrimitiveReference {
    /// The box's lower corner, its fourth lane zeroed by a bitwise select: the
    /// index's bits there read as a subnormal float, and arithmetic on
    /// subnormals can take a slow microcode path on some CPUs.
    #[inline(always)]
    fn min(&self) -> Vec3A {
        Vec3A::from_vec4(Vec4::select(XYZ, self.min_and_id, Vec4::ZERO))
    }

    #[inline(always)]
    fn max(&self) -> Vec3A {
        Vec3A::from_vec4(self.max)
    }

    fn id(&self) -> u32 {
        self.min_and_id.w.to_bits()
    }

    /// Twice the box's centre (the factor changes no comparison and saves a multiply).
    #[inline(always)]
    fn doubled_centroid(&self) -> Vec3A {
        self.min() + self.max()
    }
}

/// The first three lanes.
const XYZ: BVec4A = BVec4A::new(true, true, true, false);

/// A node's triangles' boxes joined, and the box of their doubled centroids.
#[derive(Clone, Copy)]
struct NodeBounds {
    bounds: Aabb,
    centroids: Aabb,
}

impl NodeBounds {
    const EMPTY: NodeBounds = NodeBounds {
        bounds: Aabb::INVALID,
        centroids: Aabb::INVALID,
    };

    #[inline(always)]
    fn add(&mut self, reference: &PrimitiveReference) {
        self.bounds.min = self.bounds.min.min(reference.min());
        self.bounds.max = self.bounds.max.max(reference.max());
        self.centroids.extend(reference.doubled_centroid());
    }

    fn union(&self, other: &NodeBounds) -> NodeBounds {
        NodeBounds {
            bounds: self.bounds.union(&other.bounds),
            centroids: self.centroids.union(&other.centroids),
        }
    }
}

/// [`NodeBounds`] of `references`, in parallel chunks where there are many.
fn bounds_of(references: &[PrimitiveReference]) -> NodeBounds {
    let chunk = |chunk: &[PrimitiveReference]| {
        let mut bounds = NodeBounds::EMPTY;
        chunk.iter().for_each(|reference| bounds.add(reference));
        bounds
    };
    if references.len() < PARALLEL_PASS_MIN {
        return chunk(references);
    }
    references
        .par_chunks(PARALLEL_PASS_CHUNK)
        .map(chunk)
        .reduce(|| NodeBounds::EMPTY, |a, b| a.union(&b))
}

/// The most bins per axis.
const MAX_BINS: usize = 16;

/// Bins per axis for a node of `count` triangles: fewer in small nodes, where
/// the sweep over the bins costs as much as binning the triangles. (32 bins
/// in the largest nodes gave the dragon's tree a 0.3% lower cost, and took
/// longer.)
fn bins_for(count: usize) -> usize {
    let bins = if count >= FEWER_BINS_BELOW {
        MAX_BINS
    } else {
        MAX_BINS / 2
    };
    bins.min(count)
}

const FEWER_BINS_BELOW: usize = 128;

/// Nodes with fewer triangles are built on one thread, into a part of their own.
const PARALLEL_SUBTREE_MIN: usize = 8192;

/// Binning and bounds of at least this many triangles run in parallel chunks.
const PARALLEL_PASS_MIN: usize = 1 << 16;
const PARALLEL_PASS_CHUNK: usize = 1 << 14;

/// What [`build_subtree`] made of a range of triangles: the nodes near the root,
/// built in parallel, point at the parts below them, each built on one thread;
/// [`assemble`] lays them out as one walk would have.
enum Subtree {
    Part(BinaryTree, Flattened),
    Split {
        children: Box<[Subtree; 2]>,
        bounds: [Aabb; 2],
        depth: usize,
    },
}

/// A node's references: `held` holds them, in the whole array or in the
/// scratch array (a partition moves them from one to the other, and the
/// children go on from there), and `spare` is the same range of the other.
/// They sit at `first` in both (the leaves' triangle numbers).
struct NodeReferences<'a> {
    held: &'a mut [PrimitiveReference],
    spare: &'a mut [PrimitiveReference],
    held_in_scratch: bool,
    first: u32,
}

impl NodeReferences<'_> {
    /// The node as a leaf, its references put back in the whole array if
    /// the last partition left them in the scratch one.
    fn leaf(self) -> Flattened {
        if self.held_in_scratch {
            self.spare.copy_from_slice(self.held);
        }
        Flattened::Leaf {
            first: self.first,
            count: self.held.len() as u32,
        }
    }
}

/// Builds the subtree over a node's references at `depth` (the root's is 1).
fn build_subtree(references: NodeReferences<'_>, node: NodeBounds, depth: usize) -> Subtree {
    if references.held.len() < PARALLEL_SUBTREE_MIN {
        let mut part = BinaryTree::default();
        let mut bins = [[Bin::EMPTY; MAX_BINS]; 3];
        let flattened = build_serial(references, node, depth, &mut part, &mut bins);
        return Subtree::Part(part, flattened);
    }
    let mut bins = [[Bin::EMPTY; MAX_BINS]; 3];
    let split = choose_split(references.held, references.spare, &node, depth, &mut bins)
        .expect("a node too large for a leaf always splits");
    let [(left, left_bounds), (right, right_bounds)] = sides(references, &split);
    let (left_subtree, right_subtree) = rayon::join(
        || build_subtree(left, left_bounds, depth + 1),
        || build_subtree(right, right_bounds, depth + 1),
    );
    Subtree::Split {
        children: Box::new([left_subtree, right_subtree]),
        bounds: split.children.map(|child| child.bounds),
        depth,
    }
}

/// Builds the subtree over `references` into `tree`, in post-order (`bins`:
/// scratch space, used before the children are built).
fn build_serial(
    references: NodeReferences<'_>,
    node: NodeBounds,
    depth: usize,
    tree: &mut BinaryTree,
    bins: &mut Bins,
) -> Flattened {
    let Some(split) = choose_split(references.held, references.spare, &node, depth, bins) else {
        return references.leaf();
    };
    let [(left, left_bounds), (right, right_bounds)] = sides(references, &split);
    let left = build_serial(left, left_bounds, depth + 1, tree, bins);
    let right = build_serial(right, right_bounds, depth + 1, tree, bins);
    push_inner_node(
        tree,
        [left, right],
        &split.children.map(|child| child.bounds),
        depth,
    )
}

/// A split node's sides: each one's references and bounds.
fn sides<'a>(
    references: NodeReferences<'a>,
    split: &Split,
) -> [(NodeReferences<'a>, NodeBounds); 2] {
    let NodeReferences {
        held,
        spare,
        held_in_scratch,
        first,
    } = references;
    // A partition left the references in the other array.
    let (held, spare, held_in_scratch) = if split.moved {
        (spare, held, !held_in_scratch)
    } else {
        (held, spare, held_in_scratch)
    };
    let (left, right) = held.split_at_mut(split.left_count);
    let (left_spare, right_spare) = spare.split_at_mut(split.left_count);
    [
        (
            NodeReferences {
                held: left,
                spare: left_spare,
                held_in_scratch,
                first,
            },
            split.children[0],
        ),
        (
            NodeReferences {
                held: right,
                spare: right_spare,
                held_in_scratch,
                first: first + split.left_count as u32,
            },
            split.children[1],
        ),
    ]
}

/// Appends the inner node over two flattened children (post-order numbering).
fn push_inner_node(
    tree: &mut BinaryTree,
    children: [Flattened; 2],
    bounds: &[Aabb; 2],
    depth: usize,
) -> Flattened {
    let index = tree.nodes.len() as u32;
    tree.nodes.push(BvhNode {
        children: [
            binary_child(children[0], &bounds[0]),
            binary_child(children[1], &bounds[1]),
        ],
    });
    tree.stack_depth = tree.stack_depth.max(depth);
    Flattened::Inner(index)
}

/// Lays the subtree out in `tree` in post-order, each part copied once.
fn assemble(subtree: Subtree, tree: &mut BinaryTree) -> Flattened {
    match subtree {
        // The parts' leaves already carry their final triangle numbers, and no
        // triangle ids (those are read from the references at the end), so the
        // splice shifts their node numbers only.
        Subtree::Part(part, flattened) => splice(tree, part, flattened),
        Subtree::Split {
            children,
            bounds,
            depth,
        } => {
            let [left, right] = *children;
            let left = assemble(left, tree);
            let right = assemble(right, tree);
            push_inner_node(tree, [left, right], &bounds, depth)
        }
    }
}

/// A node's split: how many triangles go left (they are moved to the front),
/// both sides' bounds, and whether the references were moved to the other
/// array (a partition) or reordered where they are (a median split).
struct Split {
    left_count: usize,
    children: [NodeBounds; 2],
    moved: bool,
}

/// Partitions `references` by the cheapest split (into `scratch`, or where
/// they are for a median split), or returns `None` where one
/// leaf costs no more (it must hold at most [`MAX_LEAF_TRIANGLES`]). Where the
/// depth left could not take a tree of unbalanced splits, or all centroids
/// coincide, it splits at the median instead, so no inner node is deeper than
/// [`MAX_STACK_DEPTH`]. `bins` is scratch space.
fn choose_split(
    references: &mut [PrimitiveReference],
    scratch: &mut [PrimitiveReference],
    node: &NodeBounds,
    depth: usize,
    bins: &mut Bins,
) -> Option<Split> {
    let count = references.len();
    // One leaf of up to that many costs no more than any split: its cost is
    // at most 0 and a split's is never below 0.
    if count as f32 <= COLLAPSE_TRAVERSAL_COST {
        return None;
    }
    // A median split from here adds at most ceil(log2(count)) - 1 levels of inner nodes.
    let levels_for_median = (usize::BITS - (count - 1).leading_zeros()) as usize;
    if depth + levels_for_median > MAX_STACK_DEPTH {
        return Some(median_split(references, node));
    }
    let Some(binned) = cheapest_binned_split(references, node, bins) else {
        return (count > MAX_LEAF_TRIANGLES as usize).then(|| median_split(references, node));
    };
    let area = node.bounds.half_area();
    let as_leaf = area * (count as f32 - COLLAPSE_TRAVERSAL_COST);
    if count <= MAX_LEAF_TRIANGLES as usize && as_leaf <= binned.cost {
        return None;
    }
    let (left_count, centroids) =
        partition(references, scratch, |centroid| binned.goes_left(centroid));
    debug_assert_eq!(left_count, binned.left_count);
    Some(Split {
        left_count,
        children: [0, 1].map(|side| NodeBounds {
            // The bins joined give the boxes exactly.
            bounds: binned.bounds[side],
            centroids: centroids[side],
        }),
        moved: true,
    })
}

/// Splits at the middle triangle by centroid along the centroids' widest axis
/// (ties by mesh index, so the order is the mesh's alone).
fn median_split(references: &mut [PrimitiveReference], node: &NodeBounds) -> Split {
    let axis = node.centroids.largest_axis();
    let middle = references.len() / 2;
    references.select_nth_unstable_by(middle, |a, b| {
        a.doubled_centroid()[axis]
            .total_cmp(&b.doubled_centroid()[axis])
            .then(a.id().cmp(&b.id()))
    });
    let (left, right) = references.split_at(middle);
    Split {
        left_count: middle,
        children: [bounds_of(left), bounds_of(right)],
        moved: false,
    }
}

/// Moves the references whose doubled centroid `goes_left` takes to the front of `scratch` and the
/// others to its back, returning how many went to the front, and the boxes
/// of both sides' doubled centroids. Without branches on the side (it is as
/// good as random): each reference is written to the next free place at the
/// front or the back (the back fills backwards). The children go on in
/// `scratch`, so nothing is copied back (a leaf puts its few back).
fn partition(
    references: &[PrimitiveReference],
    scratch: &mut [PrimitiveReference],
    goes_left: impl Fn(Vec3A) -> bool,
) -> (usize, [Aabb; 2]) {
    let (mut left, mut right) = (0, references.len());
    let (mut left_box, mut right_box) = (Aabb::INVALID, Aabb::INVALID);
    for reference in references.iter() {
        let centroid = reference.doubled_centroid();
        let is_left = goes_left(centroid);
        scratch[if is_left { left } else { right - 1 }] = *reference;
        left += usize::from(is_left);
        right -= usize::from(!is_left);
        // Both boxes stay in registers, each grown or kept by a select: with
        // the side's box picked by index, each update waited on the store
        // of the one before it.
        let to_left = BVec3A::splat(is_left);
        left_box.min = Vec3A::select(to_left, left_box.min.min(centroid), left_box.min);
        left_box.max = Vec3A::select(to_left, left_box.max.max(centroid), left_box.max);
        right_box.min = Vec3A::select(to_left, right_box.min, right_box.min.min(centroid));
        right_box.max = Vec3A::select(to_left, right_box.max, right_box.max.max(centroid));
    }
    (left, [left_box, right_box])
}

/// A bin: the boxes of the triangles whose centroids fall in it, and their number.
#[derive(Clone, Copy)]
struct Bin {
    bounds: Aabb,
    count: u32,
}

impl Bin {
    const EMPTY: Bin = Bin {
        bounds: Aabb::INVALID,
        count: 0,
    };
}

/// Every axis's bins.
type Bins = [[Bin; MAX_BINS]; 3];

/// Where a centroid falls: `bin = floor((centroid - offset) * scale)`, clamped
/// to the last bin, per axis (the scale is 0 along an axis where all centroids
/// coincide).
#[derive(Clone, Copy)]
struct Binning {
    offset: Vec3A,
    scale: Vec3A,
    last_bin: f32,
}

impl Binning {
    /// The bin along each axis (the fourth lane is meaningless).
    #[inline(always)]
    fn bins_of(&self, reference: &PrimitiveReference) -> [i32; 4] {
        // Clamped while a float (the offset makes it at least 0), so that the
        // conversion needs no saturation.
        let position = ((reference.doubled_centroid() - self.offset) * self.scale)
            .min(Vec3A::splat(self.last_bin));
        truncate(position)
    }

    /// Whether [`Binning::bins_of`] of a reference with this doubled
    /// centroid is below `bin` (at most the last bin) along `axis`: the same
    /// operations, compared before the clamp and the truncation, which change
    /// no such comparison. All lanes are compared and the axis's bit is read
    /// from the mask, so no lane leaves its register.
    #[inline(always)]
    fn is_below(&self, doubled_centroid: Vec3A, axis: usize, bin: f32) -> bool {
        let position = (doubled_centroid - self.offset) * self.scale;
        position.cmplt(Vec3A::splat(bin)).bitmask() & (1 << axis) != 0
    }
}

/// Each lane truncated to an integer (lanes in `0 ..= MAX_BINS`), in one
/// instruction where there is one.
#[inline(always)]
fn truncate(lanes: Vec3A) -> [i32; 4] {
    #[cfg(target_arch = "x86_64")]
    {
        // SAFETY: SSE2 is part of every x86-64 target.
        bytemuck::cast(unsafe { std::arch::x86_64::_mm_cvttps_epi32(lanes.into()) })
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        [lanes.x as i32, lanes.y as i32, lanes.z as i32, 0]
    }
}

/// The cheapest split between bins: along `axis`, the bins below `first_right_bin` go left.
struct BinnedSplit {
    binning: Binning,
    axis: usize,
    first_right_bin: f32,
    /// `left area × left count + right area × right count`.
    cost: f32,
    left_count: usize,
    bounds: [Aabb; 2],
}

impl BinnedSplit {
    #[inline(always)]
    fn goes_left(&self, doubled_centroid: Vec3A) -> bool {
        self.binning
            .is_below(doubled_centroid, self.axis, self.first_right_bin)
    }
}

/// The cheapest split between bins, or `None` where the centroids all coincide.
/// The bins are filled into `bins` (only as many as are used).
fn cheapest_binned_split(
    references: &[PrimitiveReference],
    node: &NodeBounds,
    bins: &mut Bins,
) -> Option<BinnedSplit> {
    let bin_count = bins_for(references.len());
    let extent = node.centroids.diagonal();
    if extent.max_element() <= 0.0 {
        return None;
    }
    // Just under `bin_count` bins a unit, so that the largest centroid lands
    // in the last bin rather than past it (the clamp catches what rounds up).
    let bins_per_unit = bin_count as f32 * (1.0 - f32::EPSILON);
    let binning = Binning {
        offset: node.centroids.min,
        scale: Vec3A::select(
            extent.cmpgt(Vec3A::ZERO),
            Vec3A::splat(bins_per_unit) / extent,
            Vec3A::ZERO,
        ),
        last_bin: (bin_count - 1) as f32,
    };
    if references.len() < PARALLEL_PASS_MIN {
        bin(references, &binning, bin_count, bins);
    } else {
        *bins = references
            .par_chunks(PARALLEL_PASS_CHUNK)
            .map(|chunk| {
                let mut bins = [[Bin::EMPTY; MAX_BINS]; 3];
                bin(chunk, &binning, bin_count, &mut bins);
                bins
            })
            .reduce(|| [[Bin::EMPTY; MAX_BINS]; 3], |a, b| merge_bins(&a, &b));
    }
    // Area times count of bins i.. joined (i ≥ 1), per axis. The three axes'
    // sweeps are independent chains, interleaved.
    let mut right_costs = [[0.0f32; 3]; MAX_BINS];
    let mut right = [Bin::EMPTY; 3];
    for i in (1..bin_count).rev() {
        for axis in 0..3 {
            right[axis] = joined_bins(&right[axis], &bins[axis][i]);
            right_costs[i][axis] = side_cost(&right[axis]);
        }
    }
    // (cost, axis, first right bin)
    let mut best: Option<(f32, usize, usize)> = None;
    let mut left = [Bin::EMPTY; 3];
    for i in 1..bin_count {
        for axis in 0..3 {
            left[axis] = joined_bins(&left[axis], &bins[axis][i - 1]);
            let count = left[axis].count as usize;
            if count == 0 || count == references.len() {
                continue;
            }
            let cost = side_cost(&left[axis]) + right_costs[i][axis];
            if best.is_none_or(|(best_cost, ..)| cost < best_cost) {
                best = Some((cost, axis, i));
            }
        }
    }
    let (cost, axis, first_right_bin) = best?;
    let [left, right] = [
        &bins[axis][..first_right_bin],
        &bins[axis][first_right_bin..bin_count],
    ]
    .map(|side| {
        side.iter()
            .fold(Bin::EMPTY, |joined, bin| joined_bins(&joined, bin))
    });
    Some(BinnedSplit {
        binning,
        axis,
        first_right_bin: first_right_bin as f32,
        cost,
        left_count: left.count as usize,
        bounds: [left.bounds, right.bounds],
    })
}

/// A side's share of the cost: its area times its triangles (0 for none).
#[inline(always)]
fn side_cost(side: &Bin) -> f32 {
    if side.count == 0 {
        0.0
    } else {
        side.bounds.half_area() * side.count as f32
    }
}

/// Adds `references` to the first `bin_count` bins of every axis, emptied
/// first. Neighbouring triangles often share a bin: in large nodes, alternate
/// ones go to two sets of bins, joined at the end, so that each update need
/// not wait for the one before it.
fn bin(references: &[PrimitiveReference], binning: &Binning, bin_count: usize, bins: &mut Bins) {
    for axis_bins in bins.iter_mut() {
        axis_bins[..bin_count].fill(Bin::EMPTY);
    }
    let add = |bins: &mut Bins, reference: &PrimitiveReference| {
        let at = binning.bins_of(reference);
        for (axis, axis_bins) in bins.iter_mut().enumerate() {
            let bin = &mut axis_bins[at[axis] as usize];
            bin.bounds.min = bin.bounds.min.min(reference.min());
            bin.bounds.max = bin.bounds.max.max(reference.max());
            bin.count += 1;
        }
    };
    if references.len() < TWO_BIN_SETS_MIN {
        references.iter().for_each(|reference| add(bins, reference));
        return;
    }
    let mut odd = [[Bin::EMPTY; MAX_BINS]; 3];
    let mut pairs = references.chunks_exact(2);
    for pair in &mut pairs {
        add(bins, &pair[0]);
        add(&mut odd, &pair[1]);
    }
    if let [last] = pairs.remainder() {
        add(bins, last);
    }
    for (axis_bins, odd_bins) in bins.iter_mut().zip(&odd) {
        for (bin, odd_bin) in axis_bins[..bin_count].iter_mut().zip(odd_bins) {
            *bin = joined_bins(bin, odd_bin);
        }
    }
}

/// Nodes with fewer triangles use one set of bins (the second one's set-up
/// would cost more than it saves).
const TWO_BIN_SETS_MIN: usize = 1024;

fn merge_bins(a: &Bins, b: &Bins) -> Bins {
    std::array::from_fn(|axis| std::array::from_fn(|i| joined_bins(&a[axis][i], &b[axis][i])))
}

#[inline(always)]
fn joined_bins(a: &Bin, b: &Bin) -> Bin {
    Bin {
        bounds: a.bounds.union(&b.bounds),
        count: a.count + b.count,
    }
}
