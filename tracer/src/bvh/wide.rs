//! The CPU's eight-wide BVH: collapsed from the binary [`Bvh`] once, at build, and
//! traversed one ray at a time with eight box tests (and eight or sixteen triangle
//! tests) per step, or by packets of coherent rays (`packet.rs`). The binary layout
//! stays what the GPU reads; this one is CPU-only.
//!
//! Layout: a [`WideNode`] holds up to eight children's boxes as structure of arrays
//! (one 8-lane row per plane), so one step computes all eight slab tests. Children
//! are inner nodes, or leaves: a binary leaf, or a whole binary subtree of at most
//! [`MERGE_LIMIT`] triangles, stored as [`TriangleGroup`]s of up to sixteen
//! triangles in leaf order (vertices in SoA rows), tested eight or sixteen at once.
//!
//! Exactness: every box and triangle test does the scalar code's IEEE operations
//! in the same order ([`super::simd`]), so distances, culling and hits are bit for
//! bit those of the binary traversal. Only the order of visits differs, which
//! decides nothing: of triangles hit at exactly the same `t` (a ray through a
//! shared edge or vertex, or overlapping copies of a surface, as CAD meshes have)
//! every traversal keeps the one with the lowest leaf-order index.

use super::simd::{Lanes, Lanes8, LanesExt, Portable};
use super::{Bvh, BvhChild, BvhNode, BvhTriangle, PreparedRay, Ray, ROBUST_FAR_SCALE};
use crate::huge_pages::{collect_on_huge_pages, vec_on_huge_pages};
use packet::{is_packet, packet_key, single_rays_below, trace_packet, PacketStack, MAX_PACKET};

use rayon::prelude::*;

mod packet;

/// Children per node.
const WIDTH: usize = 8;

/// Triangles per group.
const GROUP: usize = 16;

/// Inner binary nodes with at most this many triangles below become one leaf:
/// testing sixteen triangles at once costs about what testing eight does.
const MERGE_LIMIT: usize = 16;

/// Stack entries a traversal can need: each of at most [`super::MAX_STACK_DEPTH`]
/// levels pushes at most `WIDTH - 1` entries ([`WideBvh::build`] checks it).
const STACK_ENTRIES: usize = (WIDTH - 1) * super::MAX_STACK_DEPTH + 1;

/// A child reference with this bit set is a leaf: the rest is its first group.
const LEAF: u32 = 1 << 31;

/// Up to eight children: the planes `[min x, min y, min z, max x, max y, max z]` of
/// their boxes, one lane per child; `children[i]` is a node index or `LEAF | group`.
/// Lanes past the last child are empty (inverted boxes, never entered). 256 bytes.
#[repr(C, align(64))]
#[derive(Clone, Copy, Debug)]
struct WideNode {
    planes: [[f32; WIDTH]; 6],
    children: [u32; WIDTH],
    /// Bit `i` set for each child that exists.
    valid: u32,
    _pad: [u32; 7],
}

/// Up to sixteen triangles of one leaf: `v[vertex][axis][lane]`; lane `i` is the
/// leaf-order triangle `first + i`. Unused lanes repeat lane 0 and are masked off.
#[repr(C, align(64))]
#[derive(Clone, Copy, Debug)]
struct TriangleGroup {
    v: [[[f32; GROUP]; 3]; 3],
    first: u32,
    /// Bit `i` set for each lane that holds a triangle.
    valid: u32,
    /// Whether this is the leaf's last group.
    last: bool,
}

#[derive(Clone, Debug)]
pub(super) struct WideBvh {
    nodes: Vec<WideNode>,
    groups: Vec<TriangleGroup>,
    /// The root's children's boxes together, as `[min x, min y, min z, max x,
    /// max y, max z]`: each plane is one of theirs, so a ray whose slab test
    /// rejects it rejects every box in the tree.
    bounds: [f32; 6],
}

#[derive(Clone, Copy, Debug, Default)]
struct StackEntry {
    node: u32,
    /// Entry distance of the child's box; skipped on pop if beyond the closest hit.
    t_entry: f32,
}

/// Scratch space for one traversal at a time (reused across a batch of rays).
struct Stack([StackEntry; STACK_ENTRIES]);

impl Stack {
    #[inline(always)]
    fn new() -> Stack {
        Stack([StackEntry::default(); STACK_ENTRIES])
    }
}

impl WideBvh {
    /// Collapses the binary tree: a wide node takes its binary node's two children
    /// and repeatedly opens the inner child with the largest surface area until it
    /// has eight children or only leaves. The subtrees under the root's wide node
    /// are laid out in parallel, each on one thread, and appended in lane order;
    /// the triangle groups (most of the bytes) are filled in parallel afterwards.
    pub(super) fn build(nodes: &[BvhNode], triangles: &[BvhTriangle]) -> WideBvh {
        let ranges = subtree_ranges(nodes);
        // A child's triangles if it becomes a leaf here: binary leaves, and inner
        // nodes whose whole subtree fits in one group.
        let as_leaf = |child: &BvhChild| {
            if child.count > 0 {
                Some((child.index, child.count))
            } else {
                ranges[child.index as usize].filter(|&(_, count)| count as usize <= MERGE_LIMIT)
            }
        };
        let mut root_children = Vec::with_capacity(WIDTH);
        open_children(nodes, &as_leaf, 0, &mut root_children);
        // Each lane: its leaf's triangles, or its subtree laid out.
        let lanes: Vec<Result<(u32, u32), WidePart>> = root_children
            .par_iter()
            .map(|child| as_leaf(child).ok_or_else(|| lay_out(nodes, &as_leaf, child.index)))
            .collect();
        // Every wide node takes at least one binary node; every leaf holds at
        // most one group that is not full.
        let mut wide_nodes = vec_on_huge_pages(nodes.len());
        let mut groups = Vec::with_capacity(nodes.len() + 1 + triangles.len() / GROUP);
        wide_nodes.push(WideNode::empty());
        let mut root = WideNode::empty();
        for (lane, (child, content)) in root_children.iter().zip(lanes).enumerate() {
            root.children[lane] = match content {
                Ok((first, count)) => place_leaf(&mut groups, first, count),
                Err(part) => part.append_to(&mut wide_nodes, &mut groups),
            };
            root.set_lane_box(lane, child);
        }
        wide_nodes[0] = root;
        let filled = collect_on_huge_pages(groups.par_iter().map(|place| place.fill(triangles)));
        let wide = WideBvh {
            bounds: root.union_of_children(),
            nodes: wide_nodes,
            groups: filled,
        };
        assert!(
            wide.stack_bound() <= STACK_ENTRIES,
            "wide BVH needs {} stack entries",
            wide.stack_bound()
        );
        wide
    }

    /// The most entries a traversal pushes: along any path, a node with `n`
    /// children pushes at most `n - 1`. Children come after their parents.
    fn stack_bound(&self) -> usize {
        let mut below = vec![0usize; self.nodes.len()];
        for index in (0..self.nodes.len()).rev() {
            let node = &self.nodes[index];
            let deepest = (0..WIDTH)
                .filter(|&lane| node.valid & (1 << lane) != 0 && node.children[lane] & LEAF == 0)
                .map(|lane| below[node.children[lane] as usize])
                .max()
                .unwrap_or(0);
            below[index] = node.valid.count_ones() as usize - 1 + deepest;
        }
        below[0] + 1
    }
}

/// A binary node's children for one wide node: its two, with the inner child
/// of the largest surface area opened in its place until there are
/// [`WIDTH`] or only leaves (`as_leaf`) are left; into `children`, emptied first.
fn open_children(
    nodes: &[BvhNode],
    as_leaf: &impl Fn(&BvhChild) -> Option<(u32, u32)>,
    binary: u32,
    children: &mut Vec<BvhChild>,
) {
    children.clear();
    children.extend_from_slice(&nodes[binary as usize].children);
    while children.len() < WIDTH {
        let widest = children
            .iter()
            .enumerate()
            .filter(|(_, child)| child.count == 0 && as_leaf(child).is_none())
            .max_by(|(_, a), (_, b)| half_area(a).total_cmp(&half_area(b)));
        let Some((open, _)) = widest else { break };
        let [first, second] = nodes[children[open].index as usize].children;
        children[open] = first;
        children.insert(open + 1, second);
    }
}

/// A wide subtree laid out on its own: its nodes, root first and every
/// node's children after it, and its groups' places, both numbered from 0.
struct WidePart {
    nodes: Vec<WideNode>,
    groups: Vec<GroupPlace>,
}

impl WidePart {
    /// Appends the part's nodes and groups, renumbered; returns its root's index.
    fn append_to(self, nodes: &mut Vec<WideNode>, groups: &mut Vec<GroupPlace>) -> u32 {
        let node_offset = nodes.len() as u32;
        let group_offset = groups.len() as u32;
        assert!(
            groups.len() + self.groups.len() <= LEAF as usize,
            "too many triangle groups"
        );
        nodes.extend(self.nodes.into_iter().map(|mut node| {
            let count = node.valid.count_ones() as usize;
            for child in &mut node.children[..count] {
                *child += if *child & LEAF == 0 {
                    node_offset
                } else {
                    group_offset
                };
            }
            node
        }));
        groups.extend(self.groups);
        node_offset
    }
}

/// The wide subtree for binary node `binary`, on one thread: each node's
/// inner children get consecutive numbers when the node is laid out.
fn lay_out(
    nodes: &[BvhNode],
    as_leaf: &impl Fn(&BvhChild) -> Option<(u32, u32)>,
    binary: u32,
) -> WidePart {
    let mut part = WidePart {
        nodes: vec![WideNode::empty()],
        groups: Vec::new(),
    };
    let mut work = vec![(binary, 0usize)];
    let mut children = Vec::with_capacity(WIDTH);
    while let Some((binary, index)) = work.pop() {
        open_children(nodes, as_leaf, binary, &mut children);
        let mut node = WideNode::empty();
        for (lane, child) in children.iter().enumerate() {
            node.children[lane] = if let Some((first, count)) = as_leaf(child) {
                place_leaf(&mut part.groups, first, count)
            } else {
                let below = part.nodes.len();
                part.nodes.push(WideNode::empty());
                work.push((child.index, below));
                below as u32
            };
            node.set_lane_box(lane, child);
        }
        part.nodes[index] = node;
    }
    part
}

/// Where a [`TriangleGroup`] comes from: `lanes` leaf-order triangles from `first`.
struct GroupPlace {
    first: u32,
    lanes: u32,
    last: bool,
}

impl GroupPlace {
    fn fill(&self, triangles: &[BvhTriangle]) -> TriangleGroup {
        let chunk = &triangles[self.first as usize..(self.first + self.lanes) as usize];
        let mut group = TriangleGroup {
            v: [[[0.0; GROUP]; 3]; 3],
            first: self.first,
            valid: (1 << self.lanes) - 1,
            last: self.last,
        };
        for lane in 0..GROUP {
            let triangle = chunk.get(lane).unwrap_or(&chunk[0]);
            for (vertex, position) in [triangle.v0, triangle.v1, triangle.v2]
                .into_iter()
                .enumerate()
            {
                for (row, coordinate) in group.v[vertex].iter_mut().zip(position) {
                    row[lane] = coordinate;
                }
            }
        }
        group
    }
}

/// Places a leaf's triangles in groups of up to [`GROUP`]; returns its child reference.
fn place_leaf(groups: &mut Vec<GroupPlace>, first: u32, count: u32) -> u32 {
    let reference = LEAF | groups.len() as u32;
    assert!(groups.len() < LEAF as usize, "too many triangle groups");
    let chunks = (count as usize).div_ceil(GROUP);
    for chunk_index in 0..chunks {
        let start = chunk_index * GROUP;
        groups.push(GroupPlace {
            first: first + start as u32,
            lanes: (count as usize - start).min(GROUP) as u32,
            last: chunk_index + 1 == chunks,
        });
    }
    reference
}

impl WideNode {
    /// Makes lane `lane` valid with the child's box.
    fn set_lane_box(&mut self, lane: usize, child: &BvhChild) {
        for axis in 0..3 {
            self.planes[axis][lane] = child.min[axis];
            self.planes[3 + axis][lane] = child.max[axis];
        }
        self.valid |= 1 << lane;
    }

    /// The planes of the box around every valid child (inverted if there is none).
    fn union_of_children(&self) -> [f32; 6] {
        std::array::from_fn(|plane| {
            let lanes = (0..WIDTH).filter(|lane| self.valid & 1 << lane != 0);
            let values = lanes.map(|lane| self.planes[plane][lane]);
            if plane < 3 {
                values.fold(f32::INFINITY, f32::min)
            } else {
                values.fold(f32::NEG_INFINITY, f32::max)
            }
        })
    }

    fn empty() -> WideNode {
        WideNode {
            planes: [
                [f32::INFINITY; WIDTH],
                [f32::INFINITY; WIDTH],
                [f32::INFINITY; WIDTH],
                [f32::NEG_INFINITY; WIDTH],
                [f32::NEG_INFINITY; WIDTH],
                [f32::NEG_INFINITY; WIDTH],
            ],
            children: [u32::MAX; WIDTH],
            valid: 0,
            _pad: [0; 7],
        }
    }
}

/// Each binary node's triangles, `(first, count)` in leaf order, when they are
/// one contiguous range (which `flatten`'s depth-first layout makes them).
fn subtree_ranges(nodes: &[BvhNode]) -> Vec<Option<(u32, u32)>> {
    let mut ranges = vec![None; nodes.len()];
    // Children come after their parents.
    for index in (0..nodes.len()).rev() {
        let [a, b] = nodes[index].children.map(|child| {
            if child.count > 0 {
                Some((child.index, child.count))
            } else if child.index as usize > index {
                ranges[child.index as usize]
            } else {
                None
            }
        });
        ranges[index] = match (a, b) {
            (Some((first_a, count_a)), Some((first_b, count_b))) => {
                let first = first_a.min(first_b);
                let end = (first_a + count_a).max(first_b + count_b);
                (end - first == count_a + count_b).then_some((first, end - first))
            }
            _ => None,
        };
    }
    ranges
}

/// Half a box's surface area (the collapse's priority).
fn half_area(child: &BvhChild) -> f32 {
    let [x, y, z] = [0, 1, 2].map(|a| child.max[a] - child.min[a]);
    x * y + y * z + z * x
}

/// Which SIMD implementation the wide traversal runs on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Isa {
    /// AVX-512 F + VL: boxes in 256-bit vectors with compares into mask
    /// registers, sixteen triangles per 512-bit vector.
    Avx512,
    Avx2,
    /// Plain Rust, any CPU.
    Portable,
}

impl Isa {
    /// The best implementation this CPU runs.
    pub fn detect() -> Isa {
        #[cfg(target_arch = "x86_64")]
        {
            if super::simd::Avx512::detect().is_some() {
                return Isa::Avx512;
            }
            if super::simd::Avx2::detect().is_some() {
                return Isa::Avx2;
            }
        }
        Isa::Portable
    }

    /// Every implementation this CPU runs, best first.
    pub fn available() -> Vec<Isa> {
        [Isa::Avx512, Isa::Avx2, Isa::Portable]
            .into_iter()
            .filter(|isa| isa.is_available())
            .collect()
    }

    pub fn is_available(self) -> bool {
        match self {
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => super::simd::Avx512::detect().is_some(),
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => super::simd::Avx2::detect().is_some(),
            Isa::Portable => true,
            #[allow(unreachable_patterns)]
            _ => false,
        }
    }
}

/// What a traversal found: the closest (or, for any-hit, some) hit as
/// `(leaf-order triangle, t, u, v)`.
pub(super) type Found = Option<(usize, f32, f32, f32)>;

/// Traces a batch of rays for their closest hits: `ray(i)` for `i` in
/// `0..count`, results to `sink` in order, a packet's worth (up to
/// [`MAX_PACKET`]) at a time, so that the caller's per-result work runs in one
/// loop and not behind a call per ray. Dead rays (`tmax` not above 0) are not
/// traversed.
pub(super) fn trace_batch(
    bvh: &Bvh,
    isa: Isa,
    count: usize,
    ray: impl Fn(usize) -> Ray,
    sink: impl FnMut(&[Found]),
) {
    let ray = |index| bvh.to_bvh_space(&ray(index));
    dispatch(isa, Batch::new(bvh, count, ray, sink, ClosestHits));
}

/// Whether each of the rays `ray(0..count)` is blocked (any hit), to `sink` in
/// order, an any-hit window's worth at a time ([`AnyHitWindow::trace`]). Dead rays
/// (`tmax` not above 0) are not traversed and never blocked; `tmax(i)` is ray
/// `i`'s, read first, so that `ray(i)` is called for live rays only.
pub(super) fn occluded_batch(
    bvh: &Bvh,
    isa: Isa,
    count: usize,
    tmax: impl Fn(usize) -> f32,
    ray: impl Fn(usize) -> Ray,
    sink: impl FnMut(&[bool]),
) {
    let ray = |index| bvh.to_bvh_space(&ray(index));
    dispatch(isa, Batch::new(bvh, count, ray, sink, AnyHits { tmax }));
}

/// A batch's traversal on the lanes an [`Isa`] gives: `S` tests boxes, `T`
/// triangles (and holds a packet's rays, one per lane).
trait BatchJob {
    fn run<S: Lanes8, T: Lanes>(self, boxes: S, triangles: T);
}

fn dispatch(isa: Isa, job: impl BatchJob) {
    match isa {
        #[cfg(target_arch = "x86_64")]
        Isa::Avx512 => {
            let lanes = super::simd::Avx512::detect().expect("AVX-512 is not available");
            // SAFETY: `lanes` proves the CPU has the features.
            unsafe { run_avx512(lanes, job) }
        }
        #[cfg(target_arch = "x86_64")]
        Isa::Avx2 => {
            let lanes = super::simd::Avx2::detect().expect("AVX2 is not available");
            // SAFETY: `lanes` proves the CPU has the features.
            unsafe { run_avx2(lanes, job) }
        }
        Isa::Portable => job.run(Portable, Portable),
        #[allow(unreachable_patterns)]
        _ => panic!("{isa:?} is not available on this CPU"),
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,avx512f,avx512vl")]
unsafe fn run_avx512(lanes: super::simd::Avx512, job: impl BatchJob) {
    job.run(lanes, lanes.x16())
}

/// Packets of sixteen rays in two registers, as on AVX-512. A camera's
/// closest-hit rays from one origin share their nodes (as Embree's 16-ray
/// packets): WORKLOAD1's `map<intersect>` takes 0.77-0.87 of the time it
/// takes in packets of eight. Any-hit rays from several points were as often
/// slower as faster in sixteen while their traversals sorted each node's
/// children; unsorted, sixteen take 0.92-0.97 of the time for occlusion rays
/// and 0.86-0.95 for shadow rays (docs/benchmarks.md).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn run_avx2(lanes: super::simd::Avx2, job: impl BatchJob) {
    job.run(lanes, lanes.x16())
}

/// Rays an any-hit batch sorts by [`packet_key`] at a time.
const ANY_HIT_WINDOW: usize = 1024;

/// Values a [`packet_key`] can take (5 bits).
const PACKET_KEYS: usize = 32;

/// What fills the unused places of ray arrays: a dead ray.
const UNUSED_RAY: Ray = Ray {
    origin: glam::Vec3::ZERO,
    direction: glam::Vec3::Z,
    tmax: 0.0,
};

/// Rays `ray(0..count)` of one kind of query ([`ClosestHits`] or [`AnyHits`]),
/// answers to `sink`.
struct Batch<'a, R, K, Query> {
    bvh: &'a Bvh,
    count: usize,
    ray: R,
    sink: K,
    query: Query,
}

impl<'a, R, K, Query> Batch<'a, R, K, Query> {
    fn new(bvh: &'a Bvh, count: usize, ray: R, sink: K, query: Query) -> Self {
        Batch {
            bvh,
            count,
            ray,
            sink,
            query,
        }
    }

    fn into_parts(self) -> (&'a Bvh, usize, R, K, Query) {
        (self.bvh, self.count, self.ray, self.sink, self.query)
    }
}

/// A [`Batch`] of closest-hit queries, answered as [`Found`]s.
struct ClosestHits;

/// A [`Batch`] of any-hit queries, answered as whether each ray is blocked;
/// `tmax(i)` is ray `i`'s, read alone so that a dead ray's other fields are
/// never read.
struct AnyHits<L> {
    tmax: L,
}

impl<R: Fn(usize) -> Ray, K: FnMut(&[Found])> BatchJob for Batch<'_, R, K, ClosestHits> {
    /// `T::N` rays at a time as a packet where they can ([`is_packet`]: the
    /// coherent rays of a camera), else one by one.
    #[inline(always)]
    fn run<S: Lanes8, T: Lanes>(self, boxes: S, triangles: T) {
        let (bvh, count, ray, mut sink, ClosestHits) = self.into_parts();
        let mut stack = Stack::new();
        let mut packet_stack = PacketStack::new();
        let mut index = 0;
        while count - index >= T::N {
            let mut rays = [UNUSED_RAY; MAX_PACKET];
            for (i, slot) in rays[..T::N].iter_mut().enumerate() {
                *slot = ray(index + i);
            }
            let rays = &rays[..T::N];
            let mut found = [None; MAX_PACKET];
            if is_packet(rays) {
                trace_packet::<S, T, false>(
                    boxes,
                    triangles,
                    bvh,
                    rays,
                    &mut packet_stack,
                    &mut stack,
                    &mut found,
                );
            } else {
                for (&ray, result) in rays.iter().zip(&mut found) {
                    *result = trace::<S, T, false>(boxes, triangles, bvh, ray, &mut stack);
                }
            }
            sink(&found[..T::N]);
            index += T::N;
        }
        // The rest (fewer than `T::N`) one by one.
        let mut found = [None; MAX_PACKET];
        let rest = count - index;
        for (i, result) in found[..rest].iter_mut().enumerate() {
            *result = trace::<S, T, false>(boxes, triangles, bvh, ray(index + i), &mut stack);
        }
        if rest > 0 {
            sink(&found[..rest]);
        }
    }
}

impl<R: Fn(usize) -> Ray, K: FnMut(&[bool]), L: Fn(usize) -> f32> BatchJob
    for Batch<'_, R, K, AnyHits<L>>
{
    #[inline(always)]
    fn run<S: Lanes8, T: Lanes>(self, boxes: S, triangles: T) {
        let (bvh, count, ray, mut sink, AnyHits { tmax }) = self.into_parts();
        let mut window = AnyHitWindow::new();
        let mut index = 0;
        while index < count {
            let len = (count - index).min(ANY_HIT_WINDOW);
            let blocked = window.trace(
                boxes,
                triangles,
                bvh,
                |i| tmax(index + i),
                |i| ray(index + i),
                len,
            );
            sink(blocked);
            index += len;
        }
    }
}

/// The places an any-hit window works in, kept from one window to the next so
/// that each window initialises only what it uses.
struct AnyHitWindow {
    stack: Stack,
    packet_stack: PacketStack,
    /// The window's live rays (`tmax > 0`), in window order.
    rays: [Ray; ANY_HIT_WINDOW],
    /// Where in the window each live ray is, and its [`packet_key`].
    place: [u16; ANY_HIT_WINDOW],
    keys: [u8; ANY_HIT_WINDOW],
    /// Live rays by key (the positions in `rays`).
    order: [u16; ANY_HIT_WINDOW],
    blocked: [bool; ANY_HIT_WINDOW],
}

impl AnyHitWindow {
    fn new() -> AnyHitWindow {
        AnyHitWindow {
            stack: Stack::new(),
            packet_stack: PacketStack::new(),
            rays: [UNUSED_RAY; ANY_HIT_WINDOW],
            place: [0; ANY_HIT_WINDOW],
            keys: [0; ANY_HIT_WINDOW],
            order: [0; ANY_HIT_WINDOW],
            blocked: [false; ANY_HIT_WINDOW],
        }
    }

    /// Any-hit rays `ray(0..len)` (`len` up to [`ANY_HIT_WINDOW`]): the live
    /// ones sorted by [`packet_key`] (their order kept within a key) and traced
    /// as packets of up to `T::N` rays of one key: shadow rays from
    /// neighbouring points to one light, or ambient-occlusion rays of one
    /// octant, start close together and share much of their way. Packets of a
    /// few rays go one by one. A ray's answer is the single-ray traversal's,
    /// whichever way it goes: any hit ends at the first triangle found, and
    /// which one does not matter. Dead rays are only marked not blocked: where
    /// most of the frame is background, most rays are.
    #[inline(always)]
    fn trace<S: Lanes8, T: Lanes>(
        &mut self,
        boxes: S,
        triangles: T,
        bvh: &Bvh,
        tmax: impl Fn(usize) -> f32,
        ray: impl Fn(usize) -> Ray,
        len: usize,
    ) -> &[bool] {
        // Positions of each key's rays: a counting sort.
        let mut starts = [0usize; PACKET_KEYS + 1];
        let mut live = 0;
        for i in 0..len {
            // False for NaN too.
            if tmax(i) > 0.0 {
                let ray = ray(i);
                let key = packet_key(&ray) as usize;
                self.rays[live] = ray;
                self.place[live] = i as u16;
                self.keys[live] = key as u8;
                starts[key + 1] += 1;
                live += 1;
            }
        }
        self.blocked[..len].fill(false);
        for key in 0..PACKET_KEYS {
            starts[key + 1] += starts[key];
        }
        let mut next = starts;
        for (j, &key) in self.keys[..live].iter().enumerate() {
            self.order[next[key as usize]] = j as u16;
            next[key as usize] += 1;
        }
        for key in 0..PACKET_KEYS {
            for members in self.order[starts[key]..starts[key + 1]].chunks(T::N) {
                if members.len() as u32 <= single_rays_below::<T>() {
                    for &j in members {
                        let j = j as usize;
                        self.blocked[self.place[j] as usize] = trace::<S, T, true>(
                            boxes,
                            triangles,
                            bvh,
                            self.rays[j],
                            &mut self.stack,
                        )
                        .is_some();
                    }
                    continue;
                }
                let mut packet = [UNUSED_RAY; MAX_PACKET];
                for (slot, &j) in packet.iter_mut().zip(members) {
                    *slot = self.rays[j as usize];
                }
                let mut packet_found = [None; MAX_PACKET];
                trace_packet::<S, T, true>(
                    boxes,
                    triangles,
                    bvh,
                    &packet[..members.len()],
                    &mut self.packet_stack,
                    &mut self.stack,
                    &mut packet_found,
                );
                for (&j, hit) in members.iter().zip(&packet_found) {
                    self.blocked[self.place[j as usize] as usize] = hit.is_some();
                }
            }
        }
        &self.blocked[..len]
    }
}

/// One ray, dispatched on its dominant axis like the binary traversal. Dead rays
/// (`tmax` not above 0) are not traversed.
#[inline(always)]
fn trace<S: Lanes8, T: Lanes, const ANY_HIT: bool>(
    boxes: S,
    triangles: T,
    bvh: &Bvh,
    ray: Ray,
    stack: &mut Stack,
) -> Found {
    let alive = ray.tmax > 0.0; // false for NaN too
    if !alive {
        return None;
    }
    let d = ray.direction.abs();
    if d.x >= d.y && d.x >= d.z {
        traverse::<S, T, 1, 2, 0, ANY_HIT>(boxes, triangles, bvh, ray, stack)
    } else if d.y >= d.z {
        traverse::<S, T, 2, 0, 1, ANY_HIT>(boxes, triangles, bvh, ray, stack)
    } else {
        traverse::<S, T, 0, 1, 2, ANY_HIT>(boxes, triangles, bvh, ray, stack)
    }
}

/// The ray's constants for box tests, splatted across lanes.
struct BoxRay<S: Lanes> {
    origin: [S::F; 3],
    inverse_direction: [S::F; 3],
    /// Rows of [`WideNode::planes`] the ray enters and leaves each slab through.
    near_plane: [usize; 3],
    far_plane: [usize; 3],
}

/// The ray's constants for triangle tests.
struct TriangleRay<T: Lanes> {
    origin: [T::F; 3],
    shear: [T::F; 3],
}

#[inline(always)]
fn traverse<
    S: Lanes8,
    T: Lanes,
    const KX: usize,
    const KY: usize,
    const KZ: usize,
    const ANY_HIT: bool,
>(
    lanes: S,
    triangle_lanes: T,
    bvh: &Bvh,
    ray: Ray,
    stack: &mut Stack,
) -> Found {
    let prepared = PreparedRay::new::<KX, KY, KZ>(&ray);
    let start = Walk {
        best: NO_HIT,
        closest: ray.tmax,
        u: 0.0,
        v: 0.0,
    };
    let Walk {
        best,
        closest,
        u,
        v,
    } = walk::<S, T, KX, KY, KZ, ANY_HIT>(lanes, triangle_lanes, bvh, &prepared, 0, start, stack);
    if best == NO_HIT {
        return None;
    }
    if ANY_HIT {
        return Some((0, 0.0, 0.0, 0.0));
    }
    let index = best as usize;
    debug_assert_eq!(
        prepared.intersect_triangle::<KX, KY, KZ>(&bvh.triangles[index], f32::INFINITY, false),
        Some((closest, u, v))
    );
    Some((index, closest, u, v))
}

/// Where a walk stands: the best hit's leaf-order triangle ([`NO_HIT`] if none)
/// and the distance it searches below (the best hit's).
#[derive(Clone, Copy, Debug)]
struct Walk {
    best: u32,
    closest: f32,
    /// The best hit's barycentrics.
    u: f32,
    v: f32,
}

const NO_HIT: u32 = u32::MAX;

/// One ray's walk of the subtree at `root`, from `start`. Any hit: stops at the
/// first hit, with `best` set to it.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn walk<
    S: Lanes8,
    T: Lanes,
    const KX: usize,
    const KY: usize,
    const KZ: usize,
    const ANY_HIT: bool,
>(
    lanes: S,
    triangle_lanes: T,
    bvh: &Bvh,
    prepared: &PreparedRay,
    root: u32,
    start: Walk,
    stack: &mut Stack,
) -> Walk {
    let [near_plane, far_plane] = planes(prepared.enters_at_max);
    let box_ray = BoxRay::<S> {
        origin: lanes.splat3(prepared.origin),
        inverse_direction: lanes.splat3(prepared.inverse_direction),
        near_plane,
        far_plane,
    };
    let triangle_ray = TriangleRay::<T> {
        origin: triangle_lanes.splat3(prepared.origin),
        shear: triangle_lanes.splat3(prepared.shear),
    };
    let wide = &bvh.wide;
    let stack = &mut stack.0;
    let mut stack_len = 0usize;
    let Walk {
        mut best,
        mut closest,
        mut u,
        mut v,
    } = start;
    let mut current = root;
    'visit: loop {
        if current & LEAF == 0 {
            let node = &wide.nodes[current as usize];
            let (hits, t_entry) = boxes(lanes, &box_ray, node, closest);
            if hits != 0 {
                let t_entry = lanes.store(t_entry);
                let first = hits.trailing_zeros() as usize;
                let others = hits & (hits - 1);
                if others == 0 {
                    current = node.children[first];
                    continue 'visit;
                }
                if ANY_HIT {
                    // Any hit: in lane order, unsorted, as an any-hit packet
                    // takes them (`traverse_packet` says why).
                    let mut remaining = hits;
                    while remaining != 0 {
                        let lane = remaining.trailing_zeros() as usize;
                        remaining &= remaining - 1;
                        stack[stack_len] = StackEntry {
                            node: node.children[lane],
                            t_entry: t_entry[lane],
                        };
                        stack_len += 1;
                    }
                    stack_len -= 1;
                    current = stack[stack_len].node;
                    continue 'visit;
                }
                if others & (others - 1) == 0 {
                    let second = others.trailing_zeros() as usize;
                    let (near, far) = if t_entry[second] < t_entry[first] {
                        (second, first)
                    } else {
                        (first, second)
                    };
                    stack[stack_len] = StackEntry {
                        node: node.children[far],
                        t_entry: t_entry[far],
                    };
                    stack_len += 1;
                    current = node.children[near];
                    continue 'visit;
                }
                // Three or more: push all, nearest on top (insertion sort).
                let base = stack_len;
                let mut remaining = hits;
                while remaining != 0 {
                    let lane = remaining.trailing_zeros() as usize;
                    remaining &= remaining - 1;
                    let entry = StackEntry {
                        node: node.children[lane],
                        t_entry: t_entry[lane],
                    };
                    let mut slot = stack_len;
                    while slot > base && stack[slot - 1].t_entry < entry.t_entry {
                        stack[slot] = stack[slot - 1];
                        slot -= 1;
                    }
                    stack[slot] = entry;
                    stack_len += 1;
                }
                stack_len -= 1;
                current = stack[stack_len].node;
                continue 'visit;
            }
        } else {
            let mut group_index = (current & !LEAF) as usize;
            loop {
                let group = &wide.groups[group_index];
                // Any hit: `t < tmax`. Closest: `t <= closest`, to see ties.
                let found = triangles::<T, KX, KY, KZ, ANY_HIT>(
                    triangle_lanes,
                    &triangle_ray,
                    group,
                    closest,
                );
                let (mut hits, t) = (found.hits, found.t);
                if ANY_HIT && hits != 0 {
                    let lane = hits.trailing_zeros();
                    return Walk {
                        best: group.first + lane,
                        closest,
                        u,
                        v,
                    };
                }
                while hits != 0 {
                    let lane = hits.trailing_zeros() as usize;
                    hits &= hits - 1;
                    let index = group.first + lane as u32;
                    // A tie goes to the lower leaf-order index (`best` is
                    // NO_HIT, the highest, only while `closest` is the ray's
                    // tmax, which no hit may reach). A lane of this group may
                    // also have become farther than `closest` since the test.
                    if t[lane] < closest || (t[lane] == closest && index < best && best != NO_HIT) {
                        closest = t[lane];
                        u = found.u[lane];
                        v = found.v[lane];
                        best = index;
                    }
                }
                if group.last {
                    break;
                }
                group_index += 1;
            }
        }
        loop {
            if stack_len == 0 {
                break 'visit;
            }
            stack_len -= 1;
            let entry = stack[stack_len];
            // An any-hit walk's `closest` never changes: it ends at a hit.
            if ANY_HIT || entry.t_entry <= closest * ROBUST_FAR_SCALE {
                current = entry.node;
                continue 'visit;
            }
        }
    }
    Walk {
        best,
        closest,
        u,
        v,
    }
}

/// Slab tests of all children, exactly as [`PreparedRay::entry_distance`] and
/// `is_entered_before` do them: the mask of children entered before `closest`
/// and their entry distances.
#[inline(always)]
fn boxes<S: Lanes8>(lanes: S, ray: &BoxRay<S>, node: &WideNode, closest: f32) -> (u32, S::F) {
    // No closures around intrinsics: see `LanesExt`.
    let [nx, ny, nz] = ray.near_plane;
    let [fx, fy, fz] = ray.far_plane;
    let near = [
        lanes.load(&node.planes[nx]),
        lanes.load(&node.planes[ny]),
        lanes.load(&node.planes[nz]),
    ];
    let far = [
        lanes.load(&node.planes[fx]),
        lanes.load(&node.planes[fy]),
        lanes.load(&node.planes[fz]),
    ];
    let (entered, t_enter) = slab_test(
        lanes,
        [near, far],
        &ray.origin,
        &ray.inverse_direction,
        lanes.splat(closest),
    );
    (entered & node.valid, t_enter)
}

/// The slab test lane by lane, each lane a box (`[near, far]` planes per
/// axis) and a ray, with the scalar test's IEEE operations: the lanes whose
/// ray enters the box before `closest` (with the robust test's margin), and
/// the entry distances. Eight boxes and one ray, or one box and a packet.
#[inline(always)]
pub(super) fn slab_test<L: Lanes>(
    lanes: L,
    [near, far]: [[L::F; 3]; 2],
    origin: &[L::F; 3],
    inverse_direction: &[L::F; 3],
    closest: L::F,
) -> (u32, L::F) {
    let mut t_enter = lanes.splat(0.0);
    let mut t_exit = closest;
    for axis in 0..3 {
        let t_near = lanes.mul(lanes.sub(near[axis], origin[axis]), inverse_direction[axis]);
        let t_far = lanes.mul(lanes.sub(far[axis], origin[axis]), inverse_direction[axis]);
        // NaN leaves the accumulators unchanged, as in the scalar test.
        t_enter = lanes.max_or_second(t_near, t_enter);
        t_exit = lanes.min_or_second(t_far, t_exit);
    }
    let limit = lanes.mul(t_exit, lanes.splat(ROBUST_FAR_SCALE));
    let entered = lanes.le(t_enter, limit) & lanes.lt(t_enter, lanes.splat(f32::INFINITY));
    (entered, t_enter)
}

/// Hits in a group: the mask of lanes hit, and per lane the distance and the
/// barycentrics (meaningful in hit lanes only).
struct GroupHits {
    hits: u32,
    t: [f32; GROUP],
    u: [f32; GROUP],
    v: [f32; GROUP],
}

/// The watertight test of [`PreparedRay::intersect_triangle`] on a group, `T::N`
/// lanes at a time: the lanes hit at `0 < t < tmax` (any hit) or `0 < t <= tmax`
/// (closest hit, to see ties).
#[inline(always)]
fn triangles<T: Lanes, const KX: usize, const KY: usize, const KZ: usize, const ANY_HIT: bool>(
    lanes: T,
    ray: &TriangleRay<T>,
    group: &TriangleGroup,
    tmax: f32,
) -> GroupHits {
    let mut found = GroupHits {
        hits: 0,
        t: [0.0; GROUP],
        u: [0.0; GROUP],
        v: [0.0; GROUP],
    };
    let zero = lanes.splat(0.0);
    for offset in (0..GROUP).step_by(T::N) {
        let valid = (group.valid >> offset) & ((1 << T::N) - 1);
        if valid == 0 {
            break;
        }
        let mut vertices = [[zero; 3]; 3];
        for (k, vertex) in vertices.iter_mut().enumerate() {
            for (axis, coordinate) in vertex.iter_mut().enumerate() {
                *coordinate = lanes.load_at(&group.v[k][axis], offset);
            }
        }
        let crossing = watertight::<T, KX, KY, KZ>(lanes, vertices, &ray.origin, &ray.shear, valid);
        if crossing.hits == 0 {
            continue;
        }
        let bound = lanes.splat(tmax);
        let before = if ANY_HIT {
            lanes.lt(crossing.t, bound)
        } else {
            lanes.le(crossing.t, bound)
        };
        let hits = crossing.hits & before;
        if hits != 0 {
            found.hits |= hits << offset;
            lanes.store_at(crossing.t, &mut found.t, offset);
            if !ANY_HIT {
                let (u, v) = crossing.barycentrics(lanes);
                lanes.store_at(u, &mut found.u, offset);
                lanes.store_at(v, &mut found.v, offset);
            }
        }
    }
    found
}

/// Rows of [`WideNode::planes`] a ray enters and leaves each slab through.
#[inline(always)]
fn planes(enters_at_max: [bool; 3]) -> [[usize; 3]; 2] {
    let [x, y, z] = enters_at_max.map(usize::from);
    [
        [3 * x, 1 + 3 * y, 2 + 3 * z],
        [3 - 3 * x, 4 - 3 * y, 5 - 3 * z],
    ]
}

/// The watertight test of [`PreparedRay::intersect_triangle`], lane by lane: a
/// triangle's `vertices[vertex][axis]`, the ray's origin and shear (one triangle
/// against many rays, or one ray against many triangles). Returns the mask of
/// `valid` lanes hit at some `t > 0` (the caller compares with its `tmax`) and
/// the distances (see [`Crossing`]).
#[inline(always)]
fn watertight<T: Lanes, const KX: usize, const KY: usize, const KZ: usize>(
    lanes: T,
    vertices: [[T::F; 3]; 3],
    origin: &[T::F; 3],
    shear: &[T::F; 3],
    valid: u32,
) -> Crossing<T> {
    let [sx, sy, sz] = *shear;
    let [a, b, c] = vertices;
    let pa = [
        lanes.sub(a[0], origin[0]),
        lanes.sub(a[1], origin[1]),
        lanes.sub(a[2], origin[2]),
    ];
    let pb = [
        lanes.sub(b[0], origin[0]),
        lanes.sub(b[1], origin[1]),
        lanes.sub(b[2], origin[2]),
    ];
    let pc = [
        lanes.sub(c[0], origin[0]),
        lanes.sub(c[1], origin[1]),
        lanes.sub(c[2], origin[2]),
    ];
    let ax = lanes.sub(pa[KX], lanes.mul(sx, pa[KZ]));
    let ay = lanes.sub(pa[KY], lanes.mul(sy, pa[KZ]));
    let az = lanes.mul(sz, pa[KZ]);
    let bx = lanes.sub(pb[KX], lanes.mul(sx, pb[KZ]));
    let by = lanes.sub(pb[KY], lanes.mul(sy, pb[KZ]));
    let bz = lanes.mul(sz, pb[KZ]);
    let cx = lanes.sub(pc[KX], lanes.mul(sx, pc[KZ]));
    let cy = lanes.sub(pc[KY], lanes.mul(sy, pc[KZ]));
    let cz = lanes.mul(sz, pc[KZ]);
    let mut u = lanes.sub(lanes.mul(cx, by), lanes.mul(cy, bx));
    let mut v = lanes.sub(lanes.mul(ax, cy), lanes.mul(ay, cx));
    let mut w = lanes.sub(lanes.mul(bx, ay), lanes.mul(by, ax));
    let zero = lanes.splat(0.0);
    let exact_zeros = (lanes.eq(u, zero) | lanes.eq(v, zero) | lanes.eq(w, zero)) & valid;
    if exact_zeros != 0 {
        // The scalar test re-evaluates all three in f64 where one is exactly zero.
        u = lanes.select(exact_zeros, lanes.edge_in_f64(cx, cy, bx, by), u);
        v = lanes.select(exact_zeros, lanes.edge_in_f64(ax, ay, cx, cy), v);
        w = lanes.select(exact_zeros, lanes.edge_in_f64(bx, by, ax, ay), w);
    }
    let negative = lanes.lt(u, zero) | lanes.lt(v, zero) | lanes.lt(w, zero);
    let positive = lanes.gt(u, zero) | lanes.gt(v, zero) | lanes.gt(w, zero);
    let inside = valid & !(negative & positive);
    if inside == 0 {
        // The usual case: the ray passes beside them.
        return Crossing {
            hits: 0,
            t: zero,
            v: zero,
            w: zero,
            determinant: zero,
        };
    }
    let determinant = lanes.add(lanes.add(u, v), w);
    let t = lanes.div(
        lanes.add(
            lanes.add(lanes.mul(u, az), lanes.mul(v, bz)),
            lanes.mul(w, cz),
        ),
        determinant,
    );
    Crossing {
        hits: inside & !lanes.eq(determinant, zero) & lanes.gt(t, zero),
        t,
        v,
        w,
        determinant,
    }
}

/// What [`watertight`] found: the lanes hit at some `t > 0`, their distances,
/// and what their barycentrics are made of.
struct Crossing<T: Lanes> {
    hits: u32,
    t: T::F,
    v: T::F,
    w: T::F,
    determinant: T::F,
}

impl<T: Lanes> Crossing<T> {
    /// The weights of the second and third vertices, as the scalar test has them.
    #[inline(always)]
    fn barycentrics(&self, lanes: T) -> (T::F, T::F) {
        (
            lanes.div(self.v, self.determinant),
            lanes.div(self.w, self.determinant),
        )
    }
}

#[cfg(test)]
impl WideBvh {
    /// Checks the collapse: every leaf-order triangle sits in exactly one group lane
    /// with its exact vertices, groups of a leaf are consecutive and end with `last`,
    /// every box contains what lies below it, and the stack bound holds.
    pub(super) fn validate(&self, triangles: &[BvhTriangle]) {
        let mut seen = vec![0u32; triangles.len()];
        let contains = |outer: (&[f32; 3], &[f32; 3]), p: [f32; 3]| {
            (0..3).all(|a| outer.0[a] <= p[a] && p[a] <= outer.1[a])
        };
        let mut reached = vec![false; self.nodes.len()];
        reached[0] = true;
        for (index, node) in self.nodes.iter().enumerate() {
            assert!(reached[index], "node {index} is unreachable");
            let count = node.valid.count_ones() as usize;
            assert!(
                count >= 2 && node.valid == (1 << count) - 1,
                "{:b}",
                node.valid
            );
            for lane in 0..WIDTH {
                let min = [0, 1, 2].map(|a| node.planes[a][lane]);
                let max = [0, 1, 2].map(|a| node.planes[3 + a][lane]);
                if lane >= count {
                    assert_eq!(min, [f32::INFINITY; 3]);
                    assert_eq!(max, [f32::NEG_INFINITY; 3]);
                    continue;
                }
                let child = node.children[lane];
                if child & LEAF == 0 {
                    let below = &self.nodes[child as usize];
                    assert!(child as usize > index, "children come after their parents");
                    reached[child as usize] = true;
                    for below_lane in 0..below.valid.count_ones() as usize {
                        let corner =
                            |row: usize| [0, 1, 2].map(|a| below.planes[row + a][below_lane]);
                        assert!(contains((&min, &max), corner(0)));
                        assert!(contains((&min, &max), corner(3)));
                    }
                    continue;
                }
                let mut group_index = (child & !LEAF) as usize;
                loop {
                    let group = &self.groups[group_index];
                    let lanes = group.valid.count_ones() as usize;
                    assert!(lanes >= 1 && group.valid == (1 << lanes) - 1);
                    for lane in 0..lanes {
                        let id = group.first as usize + lane;
                        seen[id] += 1;
                        let triangle = &triangles[id];
                        for (vertex, position) in
                            [triangle.v0, triangle.v1, triangle.v2].iter().enumerate()
                        {
                            assert_eq!(*position, [0, 1, 2].map(|a| group.v[vertex][a][lane]));
                            assert!(contains((&min, &max), *position));
                        }
                    }
                    if group.last {
                        break;
                    }
                    group_index += 1;
                }
            }
        }
        // A one-triangle mesh has its leaf twice (see `flatten`).
        let expected = if triangles.len() == 1 { 2 } else { 1 };
        assert!(seen.iter().all(|&n| n == expected), "{seen:?}");
        assert!(self.stack_bound() <= STACK_ENTRIES);
    }
}
