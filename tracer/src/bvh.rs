//! The bounding volume hierarchy: built by our binned SAH build
//! (`bvh/binned_sah.rs`, the default), by obvhs' PLOC or as a linear BVH
//! (`bvh/lbvh.rs`; both flattened here), in
//! our own two-wide layout, traversed by our own code (the same layout feeds
//! the GPU).
//!
//! Layout: every [`BvhNode`] is an inner node holding the boxes of both children
//! (64 bytes, Aila–Laine style), so one node visit tests two boxes and descends
//! the nearer. A child with `count == 0` is the inner node `nodes[index]`; a child
//! with `count > 0` is a leaf of triangles `index .. index + count` in
//! [`Bvh::triangles`], which are stored in leaf order with their vertices copied
//! (no index indirection in the hot loop). [`Bvh::triangle_ids`] maps a leaf-order
//! position back to the triangle's index in the input file. The root is `nodes[0]`.
//!
//! The CPU does not traverse this layout in its hot path: [`Bvh::build`] also
//! collapses it into an eight-wide tree (`bvh/wide.rs`, with SIMD box and triangle
//! tests from `bvh/simd.rs`, AVX-512 or AVX2 chosen at run time, else portable
//! code; batches of camera rays travel as packets, `bvh/wide/packet.rs`) that
//! gives bit-identical answers. The binary traversal stays as the reference
//! ([`Bvh::intersect_closest_binary`]), which the GPU shaders mirror.

use crate::mesh::{Bounds, MeshError, TriangleMesh};
use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use obvhs::aabb::Aabb;
use obvhs::bvh2::node::Bvh2Node;
use obvhs::bvh2::reinsertion::ReinsertionOptimizer;
use obvhs::bvh2::Bvh2;
use obvhs::ploc::{PlocBuilder, SortPrecision};
use rayon::prelude::*;
use std::mem::MaybeUninit;

mod binned_sah;
mod depth_limit;
mod lbvh;
mod simd;
mod wide;

pub use wide::Isa;

/// Entries in a traversal stack: the deepest chain of inner nodes a BVH may have.
/// The GPU shaders need a fixed bound too; [`Bvh::build`] guarantees it.
pub const MAX_STACK_DEPTH: usize = 64;

/// One child of a [`BvhNode`]: its box and what it points to. 32 bytes, laid out
/// like WGSL's `struct { min: vec3<f32>, index: u32, max: vec3<f32>, count: u32 }`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct BvhChild {
    pub min: [f32; 3],
    /// Inner child: node index. Leaf child: first triangle (leaf order).
    pub index: u32,
    pub max: [f32; 3],
    /// 0 for an inner child, else the number of triangles in the leaf.
    pub count: u32,
}

/// An inner node: both children's boxes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct BvhNode {
    pub children: [BvhChild; 2],
}

/// A triangle's vertices, copied in leaf order (36 bytes; WGSL: three `array<f32, 3>`).
/// The watertight test needs the exact input vertices, not edges derived from them.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct BvhTriangle {
    pub v0: [f32; 3],
    pub v1: [f32; 3],
    pub v2: [f32; 3],
}

/// A ray segment: hits count when `0 < t < tmax`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub origin: Vec3,
    /// Need not be normalised; `t` is in units of its length.
    pub direction: Vec3,
    pub tmax: f32,
}

/// The closest hit: distance, triangle in input file order, and the barycentric
/// weights `u` of `v1` and `v` of `v2` (the hit point is `(1-u-v) v0 + u v1 + v v2`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HitRecord {
    pub t: f32,
    pub prim: u32,
    pub u: f32,
    pub v: f32,
}

/// A ray's `prim` where it hits nothing.
pub const MISS_PRIM: u32 = u32::MAX;

/// Where [`Bvh::intersect_closest_into`] writes a batch's hits: one column
/// per field of [`HitRecord`], as the `Hit` record is stored.
pub struct HitPlaces<'a> {
    pub t: &'a mut [MaybeUninit<f32>],
    pub prim: &'a mut [MaybeUninit<u32>],
    pub u: &'a mut [MaybeUninit<f32>],
    pub v: &'a mut [MaybeUninit<f32>],
}

impl HitPlaces<'_> {
    /// Writes `hit` (or a miss) to place `index` of every column.
    #[inline(always)]
    pub fn write(&mut self, index: usize, hit: Option<HitRecord>) {
        self.write_from(index, std::iter::once(hit));
    }

    /// Writes `hits` to places `start..` of every column, one after another
    /// (each column's places checked once, not per hit).
    #[inline(always)]
    pub fn write_from(
        &mut self,
        start: usize,
        hits: impl ExactSizeIterator<Item = Option<HitRecord>>,
    ) {
        let end = start + hits.len();
        let places = self.t[start..end]
            .iter_mut()
            .zip(&mut self.prim[start..end])
            .zip(&mut self.u[start..end])
            .zip(&mut self.v[start..end]);
        for (hit, (((t, prim), u), v)) in hits.zip(places) {
            let fields = match hit {
                Some(hit) => (hit.t, hit.prim, hit.u, hit.v),
                None => (f32::INFINITY, MISS_PRIM, 0.0, 0.0),
            };
            t.write(fields.0);
            prim.write(fields.1);
            u.write(fields.2);
            v.write(fields.3);
        }
    }
}

/// How [`Bvh::build_with`] builds the binary tree (the eight-wide one is
/// collapsed from it either way).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum BvhBuilder {
    /// obvhs' PLOC, its reinsertion, and our collapse of its leaves.
    Ploc,
    /// Our top-down binned SAH build (`bvh/binned_sah.rs`).
    #[default]
    BinnedSah,
    /// Karras' linear BVH (`bvh/lbvh.rs`): Morton codes, a radix sort, the
    /// radix tree and the boxes bottom-up; the fastest build, and no surface
    /// areas but in the leaves, so its trees trace a little slower.
    Lbvh,
}

#[derive(Clone, Debug)]
pub struct Bvh {
    nodes: Vec<BvhNode>,
    triangles: Vec<BvhTriangle>,
    triangle_ids: Vec<u32>,
    stack_depth: usize,
    /// The power of two the stored vertices are multiplied by (1 for most
    /// scenes; see [`bvh_space_scale`]); rays enter multiplied by it too.
    scale: f32,
    /// The CPU's traversal structure, built from the fields above.
    wide: wide::WideBvh,
}

/// Coordinates whose largest magnitude lies in `2^-20 ..= 2^20` are traced as
/// they are; others are scaled by a power of two into `1 .. 2`.
const UNSCALED_EXPONENTS: std::ops::RangeInclusive<i32> = -20..=20;

/// The power of two that brings a mesh's largest coordinate magnitude into
/// `1 .. 2` when it lies far from 1. The watertight test multiplies three
/// coordinates together (its distance is a cubic), which overflows f32 for
/// scenes larger than about 1e12 and loses everything to underflow below
/// about 1e-13: such scenes would silently miss. Multiplying vertices, ray
/// origins and `tmax` by a power of two scales every intermediate result of
/// the box and triangle tests exactly, so the traversal visits the same nodes
/// and finds the same triangle, `u` and `v`, and `t` times the scale, which
/// [`Bvh::hit_record`] divides out exactly.
fn bvh_space_scale(bounds: &Bounds) -> f32 {
    let largest = bounds.min.abs().max(bounds.max.abs()).max_element();
    if largest == 0.0 {
        return 1.0;
    }
    // The exponent of `largest`, read from its bits (subnormals count as -127).
    let exponent = ((largest.to_bits() >> 23) & 0xff) as i32 - 127;
    if UNSCALED_EXPONENTS.contains(&exponent) {
        return 1.0;
    }
    // 2^-exponent, kept a normal f32 whose reciprocal is one too.
    let scale_exponent = (-exponent).clamp(-126, 126);
    f32::from_bits(((127 + scale_exponent) as u32) << 23)
}

impl Bvh {
    /// Builds the hierarchy for a mesh (validated first) with the default
    /// builder, [`BvhBuilder::BinnedSah`]; no inner node is deeper than
    /// [`MAX_STACK_DEPTH`] whichever builder makes it.
    pub fn build(mesh: &TriangleMesh) -> Result<Bvh, MeshError> {
        Bvh::build_with(mesh, BvhBuilder::default())
    }

    /// [`Bvh::build`] by a chosen builder.
    pub fn build_with(mesh: &TriangleMesh, builder: BvhBuilder) -> Result<Bvh, MeshError> {
        let bounds = mesh.validated_bounds()?;
        let scale = bvh_space_scale(&bounds);
        let mut bvh = if scale == 1.0 {
            Bvh::build_unscaled(mesh, builder)
        } else {
            Bvh::build_unscaled(
                &TriangleMesh {
                    positions: mesh.positions.iter().map(|&p| p * scale).collect(),
                    triangles: mesh.triangles.clone(),
                    normals: None,
                    scalars: None,
                },
                builder,
            )
        };
        bvh.scale = scale;
        Ok(bvh)
    }

    /// [`Bvh::build`] of a mesh whose coordinates need no scaling.
    fn build_unscaled(mesh: &TriangleMesh, builder: BvhBuilder) -> Bvh {
        let binary = match builder {
            BvhBuilder::BinnedSah => binned_sah::binned_sah_tree(mesh),
            BvhBuilder::Ploc => {
                let tree = ploc_tree(mesh);
                ploc_binary_tree(&tree.nodes, &tree.primitive_indices, mesh)
            }
            BvhBuilder::Lbvh => lbvh::lbvh_binary_tree(mesh),
        };
        Bvh::from_binary(binary, mesh)
    }

    /// Copies the triangles into leaf order (in parallel) and collapses the
    /// eight-wide tree.
    fn from_binary(binary: BinaryTree, mesh: &TriangleMesh) -> Bvh {
        let triangles =
            crate::huge_pages::collect_on_huge_pages(binary.triangle_ids.par_iter().map(|&id| {
                let [v0, v1, v2] = mesh.triangle_vertices(id as usize).map(|v| v.to_array());
                BvhTriangle { v0, v1, v2 }
            }));
        let wide = wide::WideBvh::build(&binary.nodes, &triangles);
        Bvh {
            nodes: binary.nodes,
            triangles,
            triangle_ids: binary.triangle_ids,
            stack_depth: binary.stack_depth,
            scale: 1.0,
            wide,
        }
    }

    pub fn nodes(&self) -> &[BvhNode] {
        &self.nodes
    }

    /// Triangle vertices in leaf order, multiplied by [`Bvh::scale`].
    pub fn triangles(&self) -> &[BvhTriangle] {
        &self.triangles
    }

    /// Input-file triangle index of each leaf-order triangle.
    pub fn triangle_ids(&self) -> &[u32] {
        &self.triangle_ids
    }

    /// The power of two that node boxes and [`Bvh::triangles`] are multiplied by
    /// (1 unless the scene's coordinates are very large or very small); every
    /// traversal multiplies ray origins and `tmax` by it on entry and divides
    /// hit distances by it.
    pub fn scale(&self) -> f32 {
        self.scale
    }

    /// A ray as the traversal sees it: origin and `tmax` times [`Bvh::scale`]
    /// (the direction is left alone, so `t` scales too).
    #[inline]
    fn to_bvh_space(&self, ray: &Ray) -> Ray {
        Ray {
            origin: ray.origin * self.scale,
            direction: ray.direction,
            tmax: ray.tmax * self.scale,
        }
    }

    /// The most stack entries a traversal of this tree can need (≤ [`MAX_STACK_DEPTH`]).
    pub fn stack_depth(&self) -> usize {
        self.stack_depth
    }

    /// The closest hit with `0 < t < ray.tmax`, if any. Of triangles hit at exactly
    /// the same distance, the one the binary traversal meets first wins.
    #[inline]
    pub fn intersect_closest(&self, ray: &Ray) -> Option<HitRecord> {
        self.intersect_closest_with(ray, Isa::detect())
    }

    /// Whether anything lies at `0 < t < tmax` (stops at the first hit found).
    #[inline]
    pub fn occluded(&self, ray: &Ray, tmax: f32) -> bool {
        self.occluded_with(&Ray { tmax, ..*ray }, Isa::detect())
    }

    /// [`Bvh::intersect_closest`] of rays `ray(0) .. ray(count - 1)`, handing each
    /// result to `sink` in order. Rays with `tmax` not above 0 miss without a
    /// traversal. Runs of 16 rays (8 without AVX-512) with one origin and
    /// direction octant travel as a packet: give camera rays in Morton order.
    pub fn intersect_closest_batch(
        &self,
        count: usize,
        ray: impl Fn(usize) -> Ray,
        sink: impl FnMut(Option<HitRecord>),
    ) {
        self.intersect_closest_batch_with(Isa::detect(), count, ray, sink);
    }

    /// [`Bvh::occluded`] of rays `ray(0) .. ray(count - 1)`, each up to its own
    /// `tmax`, results to `sink` in order (rays with `tmax` not above 0 are never
    /// blocked).
    /// Results go to `sink` a window of rays at a time, so that the caller
    /// copies them in one loop.
    pub fn occluded_batch(
        &self,
        count: usize,
        ray: impl Fn(usize) -> Ray,
        sink: impl FnMut(&[bool]),
    ) {
        self.occluded_batch_with(Isa::detect(), count, ray, sink);
    }

    /// [`Bvh::intersect_closest_batch`] on a chosen implementation of the wide
    /// traversal (panics if this CPU lacks it, see [`Isa::available`]).
    pub fn intersect_closest_batch_with(
        &self,
        isa: Isa,
        count: usize,
        ray: impl Fn(usize) -> Ray,
        mut sink: impl FnMut(Option<HitRecord>),
    ) {
        wide::trace_batch(self, isa, count, ray, |found| {
            for &found in found {
                sink(self.hit_record(found));
            }
        });
    }

    /// [`Bvh::intersect_closest_batch`], the hits written to `hits`' first
    /// `count` places field by field (a miss: `t` infinite, `prim`
    /// [`MISS_PRIM`], `u` and `v` 0); every one of them is written. Faster
    /// than a sink called per ray: a packet's hits are written in one tight
    /// loop.
    pub fn intersect_closest_into(
        &self,
        count: usize,
        ray: impl Fn(usize) -> Ray,
        hits: HitPlaces<'_>,
    ) {
        let mut hits = hits;
        let mut written = 0;
        let to_hit_record = self.hit_records();
        wide::trace_batch(self, Isa::detect(), count, ray, |found| {
            hits.write_from(written, found.iter().map(|&found| to_hit_record(found)));
            written += found.len();
        });
        // What callers rely on to treat the places as initialised.
        assert_eq!(written, count, "the traversal answered every ray");
    }

    /// [`Bvh::occluded_batch`], a ray's `tmax` read first: a dead ray's
    /// other fields are never read. Where the background fills most of a
    /// view, most occlusion and shadow rays are dead, and reading their
    /// origins and directions was most of what they cost.
    pub fn occluded_batch_skipping_dead(
        &self,
        count: usize,
        tmax: impl Fn(usize) -> f32,
        ray: impl Fn(usize) -> Ray,
        sink: impl FnMut(&[bool]),
    ) {
        wide::occluded_batch(self, Isa::detect(), count, tmax, ray, sink);
    }

    /// [`Bvh::occluded_batch`] on a chosen implementation.
    pub fn occluded_batch_with(
        &self,
        isa: Isa,
        count: usize,
        ray: impl Fn(usize) -> Ray,
        sink: impl FnMut(&[bool]),
    ) {
        wide::occluded_batch(self, isa, count, |i| ray(i).tmax, &ray, sink);
    }

    /// [`Bvh::intersect_closest`] on a chosen implementation of the wide traversal
    /// (panics if this CPU lacks it, see [`Isa::available`]).
    pub fn intersect_closest_with(&self, ray: &Ray, isa: Isa) -> Option<HitRecord> {
        let mut hit = None;
        wide::trace_batch(self, isa, 1, |_| *ray, |found| hit = found[0]);
        self.hit_record(hit)
    }

    /// [`Bvh::occluded`] (up to `ray.tmax`) on a chosen implementation.
    pub fn occluded_with(&self, ray: &Ray, isa: Isa) -> bool {
        let mut blocked = false;
        wide::occluded_batch(
            self,
            isa,
            1,
            |_| ray.tmax,
            |_| *ray,
            |found| blocked = found[0],
        );
        blocked
    }

    /// The reference: the closest hit by a scalar traversal of the binary layout
    /// (what the GPU shaders do). [`Bvh::intersect_closest`] gives the same answer.
    pub fn intersect_closest_binary(&self, ray: &Ray) -> Option<HitRecord> {
        self.hit_record(self.traverse::<false>(ray))
    }

    /// The reference any-hit test on the binary layout.
    pub fn occluded_binary(&self, ray: &Ray, tmax: f32) -> bool {
        let segment = Ray { tmax, ..*ray };
        self.traverse::<true>(&segment).is_some()
    }

    #[inline]
    fn hit_record(&self, found: wide::Found) -> Option<HitRecord> {
        self.hit_records()(found)
    }

    /// [`Bvh::hit_record`] with what it reads of the tree read once: for a
    /// loop over many hits, whose writes the compiler cannot tell apart from
    /// the tree's fields.
    #[inline(always)]
    fn hit_records(&self) -> impl Fn(wide::Found) -> Option<HitRecord> + '_ {
        // Exact: the scale is a power of two whose reciprocal is a normal f32.
        let inverse_scale = 1.0 / self.scale;
        let triangle_ids = &self.triangle_ids[..];
        move |found| {
            found.map(|(leaf_triangle, t, u, v)| HitRecord {
                t: t * inverse_scale,
                prim: triangle_ids[leaf_triangle],
                u,
                v,
            })
        }
    }

    /// Dispatches on the ray's dominant axis so that the triangle test's axis
    /// permutation is a compile-time constant (no indexing in the inner loop).
    #[inline]
    fn traverse<const ANY_HIT: bool>(&self, ray: &Ray) -> Option<(usize, f32, f32, f32)> {
        let ray = &self.to_bvh_space(ray);
        let d = ray.direction.abs();
        if d.x >= d.y && d.x >= d.z {
            self.traverse_axes::<1, 2, 0, ANY_HIT>(ray)
        } else if d.y >= d.z {
            self.traverse_axes::<2, 0, 1, ANY_HIT>(ray)
        } else {
            self.traverse_axes::<0, 1, 2, ANY_HIT>(ray)
        }
    }

    /// Stack-based traversal: test both children, intersect leaf children at once,
    /// descend into the nearer inner child and push the farther one with its entry
    /// distance (skipped on pop if a closer hit was found meanwhile).
    /// Returns (leaf-order triangle, t, u, v).
    fn traverse_axes<const KX: usize, const KY: usize, const KZ: usize, const ANY_HIT: bool>(
        &self,
        ray: &Ray,
    ) -> Option<(usize, f32, f32, f32)> {
        let prepared = PreparedRay::new::<KX, KY, KZ>(ray);
        let mut closest = ray.tmax;
        let mut best: Option<(usize, f32, f32, f32)> = None;
        let mut stack = [(0u32, 0f32); MAX_STACK_DEPTH];
        let mut stack_len = 0;
        let mut node = 0usize;
        loop {
            let [left, right] = &self.nodes[node].children;
            let t_left = prepared.entry_distance(left, closest);
            let t_right = prepared.entry_distance(right, closest);
            let (near, t_near, far, t_far) = if t_right < t_left {
                (right, t_right, left, t_left)
            } else {
                (left, t_left, right, t_right)
            };
            let mut inner = [(0u32, 0f32); 2];
            let mut inner_len = 0;
            for (child, t_entry) in [(near, t_near), (far, t_far)] {
                // Also culls the far child when the near leaf produced a closer hit.
                if !is_entered_before(t_entry, closest) {
                    continue;
                }
                if child.count == 0 {
                    inner[inner_len] = (child.index, t_entry);
                    inner_len += 1;
                    continue;
                }
                let first = child.index as usize;
                for index in first..first + child.count as usize {
                    // A hit at exactly `closest` wins if its leaf-order index is
                    // lower: the answer then depends on no order of visits.
                    let wins_ties = best.is_some_and(|(best_index, ..)| index < best_index);
                    if let Some((t, u, v)) = prepared.intersect_triangle::<KX, KY, KZ>(
                        &self.triangles[index],
                        closest,
                        wins_ties,
                    ) {
                        best = Some((index, t, u, v));
                        if ANY_HIT {
                            return best;
                        }
                        closest = t;
                    }
                }
            }
            match inner_len {
                2 => {
                    stack[stack_len] = inner[1];
                    stack_len += 1;
                    node = inner[0].0 as usize;
                }
                1 => node = inner[0].0 as usize,
                _ => loop {
                    if stack_len == 0 {
                        return best;
                    }
                    stack_len -= 1;
                    let (pending, t_entry) = stack[stack_len];
                    if is_entered_before(t_entry, closest) {
                        node = pending as usize;
                        break;
                    }
                },
            }
        }
    }
}

/// Whether a box entered at `t_entry` (+inf: missed) can hold a hit closer than
/// `closest` (which may be +inf itself).
#[inline(always)]
fn is_entered_before(t_entry: f32, closest: f32) -> bool {
    t_entry < f32::INFINITY && t_entry <= closest * ROBUST_FAR_SCALE
}

/// Scales a box's exit distance up so that rounding in the slab test never culls a
/// box the ray touches (Ize 2013, "Robust BVH Ray Traversal": 1 + 2γ₃).
const ROBUST_FAR_SCALE: f32 = 1.0 + 2.0 * gamma(3);

const fn gamma(n: u32) -> f32 {
    let epsilon = f32::EPSILON * 0.5;
    (n as f32 * epsilon) / (1.0 - n as f32 * epsilon)
}

/// Per-ray values precomputed once for all box and triangle tests.
#[derive(Clone, Copy)]
struct PreparedRay {
    origin: [f32; 3],
    /// `1 / direction`: ±inf for zero components, handled in [`Self::entry_distance`].
    inverse_direction: [f32; 3],
    /// Per axis, whether the ray enters a box through its max plane.
    enters_at_max: [bool; 3],
    /// The shear of Woop, Benthin, Wald (2013): `(Sx, Sy, Sz)`.
    shear: [f32; 3],
}

impl PreparedRay {
    #[inline(always)]
    fn new<const KX: usize, const KY: usize, const KZ: usize>(ray: &Ray) -> PreparedRay {
        let d = ray.direction.to_array();
        let inverse_direction = d.map(|c| 1.0 / c);
        PreparedRay {
            origin: ray.origin.to_array(),
            inverse_direction,
            // The sign bit, so that -0 (inverse -inf) enters at the max plane too.
            enters_at_max: d.map(|c| c.is_sign_negative()),
            shear: [d[KX] / d[KZ], d[KY] / d[KZ], 1.0 / d[KZ]],
        }
    }

    /// Distance at which the ray enters the child's box, or +inf if it misses it
    /// before `tmax` (a ray parallel to a slab outside it enters at +inf too). Near and far planes are chosen by direction sign, so a NaN
    /// (`0 * inf`: the ray lies in a slab plane) can only appear in one of them;
    /// the comparisons below ignore it, which keeps that slab unconstrained:
    /// conservative, never a false miss.
    #[inline(always)]
    fn entry_distance(&self, child: &BvhChild, tmax: f32) -> f32 {
        let mut t_enter = 0.0f32;
        let mut t_exit = tmax;
        for axis in 0..3 {
            let (near, far) = if self.enters_at_max[axis] {
                (child.max[axis], child.min[axis])
            } else {
                (child.min[axis], child.max[axis])
            };
            let t_near = (near - self.origin[axis]) * self.inverse_direction[axis];
            let t_far = (far - self.origin[axis]) * self.inverse_direction[axis];
            // `x > acc` is false for NaN, so NaN leaves the accumulator unchanged.
            if t_near > t_enter {
                t_enter = t_near;
            }
            if t_far < t_exit {
                t_exit = t_far;
            }
        }
        if t_enter <= t_exit * ROBUST_FAR_SCALE {
            t_enter
        } else {
            f32::INFINITY
        }
    }

    /// Watertight ray–triangle intersection (Woop, Benthin, Wald 2013, two-sided):
    /// vertices are sheared into ray space so that edge functions of a shared edge
    /// are computed from the same numbers by both triangles, and exact zeros are
    /// re-evaluated in double precision. Returns `(t, u, v)` for `0 < t < tmax`,
    /// or `0 < t <= tmax` with `up_to_tmax` (a hit that ties with the best one).
    #[inline(always)]
    fn intersect_triangle<const KX: usize, const KY: usize, const KZ: usize>(
        &self,
        triangle: &BvhTriangle,
        tmax: f32,
        up_to_tmax: bool,
    ) -> Option<(f32, f32, f32)> {
        let [sx, sy, sz] = self.shear;
        let relative = |v: &[f32; 3]| {
            let p = [
                v[0] - self.origin[0],
                v[1] - self.origin[1],
                v[2] - self.origin[2],
            ];
            (p[KX] - sx * p[KZ], p[KY] - sy * p[KZ], sz * p[KZ])
        };
        let (ax, ay, az) = relative(&triangle.v0);
        let (bx, by, bz) = relative(&triangle.v1);
        let (cx, cy, cz) = relative(&triangle.v2);

        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        if u == 0.0 || v == 0.0 || w == 0.0 {
            let edge = |px: f32, py: f32, qx: f32, qy: f32| {
                (f64::from(px) * f64::from(qy) - f64::from(py) * f64::from(qx)) as f32
            };
            u = edge(cx, cy, bx, by);
            v = edge(ax, ay, cx, cy);
            w = edge(bx, by, ax, ay);
        }
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let determinant = u + v + w;
        if determinant == 0.0 {
            return None;
        }
        let t = (u * az + v * bz + w * cz) / determinant;
        if t > 0.0 && (t < tmax || (up_to_tmax && t == tmax)) {
            Some((t, v / determinant, w / determinant))
        } else {
            None
        }
    }
}

/// obvhs' PLOC tree of a mesh, reinserted, with one triangle per leaf (leaves
/// are collapsed by [`flatten`]). The parameters are obvhs' `fast` preset's
/// with a little more reinsertion: on the test scenes its trees have the SAH
/// cost of the `medium` preset's within 0.2% (docs/benchmarks.md) and build in
/// less time. The leaves are made straight from the mesh, in parallel (obvhs'
/// `build_bvh2_from_tris` copies every triangle first, and makes the leaves on
/// one thread below 500k triangles).
fn ploc_tree(mesh: &TriangleMesh) -> Bvh2 {
    let leaves: Vec<Bvh2Node> = (0..mesh.triangles.len() as u32)
        .into_par_iter()
        .map(|id| Bvh2Node::new(depth_limit::triangle_box(mesh, id), 1, id))
        .collect();
    // Chunks of a fixed size, joined in order: the same box on any number of threads.
    let chunk_boxes: Vec<Aabb> = leaves
        .par_chunks(LEAF_BOX_CHUNK)
        .map(|chunk| {
            chunk
                .iter()
                .fold(Aabb::INVALID, |bounds, leaf| bounds.union(leaf.aabb()))
        })
        .collect();
    let bounds = chunk_boxes
        .iter()
        .fold(Aabb::INVALID, |bounds, chunk| bounds.union(chunk));
    let mut tree = Bvh2 {
        primitive_indices: (0..mesh.triangles.len() as u32).collect(),
        ..Bvh2::default()
    };
    let mut builder = PlocBuilder {
        current_nodes: leaves,
        ..PlocBuilder::new()
    };
    builder.build_ploc_from_leaves::<PLOC_SEARCH_DISTANCE, false>(
        &mut tree,
        bounds,
        SortPrecision::U64,
        PLOC_NEAREST_ONLY_PASSES,
    );
    ReinsertionOptimizer::default().run(&mut tree, REINSERTION_BATCH_RATIO, None);
    tree
}

/// PLOC's tree flattened, with subtrees too deep for the stacks rebuilt.
fn ploc_binary_tree(
    nodes: &[Bvh2Node],
    primitive_indices: &[u32],
    mesh: &TriangleMesh,
) -> BinaryTree {
    let mut binary = flatten(nodes, primitive_indices);
    // Checked on the flattened tree: too deep a tree is rare (PLOC's chains
    // of tiny triangles), and finding out costs a walk of its own.
    if binary.stack_depth > MAX_STACK_DEPTH {
        if let Some((nodes, primitive_indices)) =
            depth_limit::limit_depth(nodes, primitive_indices, mesh, MAX_STACK_DEPTH)
        {
            binary = flatten(&nodes, &primitive_indices);
        }
    }
    debug_assert!(
        binary.stack_depth <= MAX_STACK_DEPTH,
        "{}",
        binary.stack_depth
    );
    binary
}

/// How many neighbours on each side PLOC looks at for a node's best partner
/// (obvhs' `PlocSearchDistance::Low`; the `medium` preset's 14 builds slower
/// and no better here).
const PLOC_SEARCH_DISTANCE: usize = 6;

/// PLOC's first passes look at the nearest neighbours only (cheaper while
/// most nodes are still single triangles).
const PLOC_NEAREST_ONLY_PASSES: usize = 2;

/// The share of nodes that reinsertion tries to move to better places (the
/// `fast` preset has 0.02, the `medium` one 0.05 and again after its collapse).
const REINSERTION_BATCH_RATIO: f32 = 0.025;

/// Leaves per chunk when their boxes are joined in parallel.
const LEAF_BOX_CHUNK: usize = 1 << 16;

/// Our binary layout without the vertices: nodes, the input triangle of each
/// leaf-order position, and the depth of the deepest inner node.
#[derive(Default)]
struct BinaryTree {
    nodes: Vec<BvhNode>,
    triangle_ids: Vec<u32>,
    stack_depth: usize,
}

/// Most triangles a collapsed leaf holds (obvhs' presets' `max_prims_per_leaf`).
const MAX_LEAF_TRIANGLES: u32 = 8;

/// The cost of a node visit against a triangle test in the collapse's SAH
/// (obvhs' presets' `collapse_traversal_cost`).
const COLLAPSE_TRAVERSAL_COST: f32 = 3.0;

/// Whether two sibling leaves (boxes and triangle counts; a count of 0 is an
/// inner node) become one leaf of their parent's box: when they hold at most
/// [`MAX_LEAF_TRIANGLES`] together and the SAH says one leaf costs no more
/// than their parent and two leaves (obvhs' collapse rule).
fn collapses_into_one_leaf(parent: &Aabb, left: (Aabb, u32), right: (Aabb, u32)) -> bool {
    let ((left_box, left_count), (right_box, right_count)) = (left, right);
    let count = left_count + right_count;
    if left_count == 0 || right_count == 0 || count > MAX_LEAF_TRIANGLES {
        return false;
    }
    let as_one_leaf = parent.half_area() * (count as f32 - COLLAPSE_TRAVERSAL_COST);
    let as_two_leaves =
        left_box.half_area() * left_count as f32 + right_box.half_area() * right_count as f32;
    as_one_leaf <= as_two_leaves
}

/// A flattened subtree: a leaf of triangles `first .. first + count` (leaf
/// order), or our inner node (numbered in post-order until the end).
#[derive(Clone, Copy)]
enum Flattened {
    Leaf { first: u32, count: u32 },
    Inner(u32),
}

/// Converts an obvhs-style binary tree (root at 0, siblings at `first_index` and
/// `first_index + 1`, leaves indexing `primitive_indices`) into our layout, with
/// triangles in depth-first leaf order, and collapses leaves as it goes, as
/// obvhs' `collapse` does: two sibling leaves become one when they hold at most
/// [`MAX_LEAF_TRIANGLES`] and the SAH says one leaf costs no more than their
/// parent and two leaves. One walk of the tree (obvhs' own collapse walks it
/// several times and took over half as long as the PLOC build itself), its
/// subtrees at depth [`PARALLEL_FLATTEN_DEPTH`] walked in parallel and then
/// spliced, in order, into the walk of the levels above: the same tree as one
/// walk on one thread gives.
fn flatten(source: &[Bvh2Node], primitive_indices: &[u32]) -> BinaryTree {
    let mut frontier = Vec::new();
    let mut work = vec![(0u32, 1usize)];
    while let Some((index, depth)) = work.pop() {
        let node = &source[index as usize];
        if node.is_leaf() {
            continue;
        }
        if depth == PARALLEL_FLATTEN_DEPTH {
            frontier.push(index);
        } else {
            work.extend([
                (node.first_index + 1, depth + 1),
                (node.first_index, depth + 1),
            ]);
        }
    }
    let mut parts = frontier
        .par_iter()
        .map(|&root| {
            let mut part = BinaryTree::default();
            let flattened = walk(
                source,
                primitive_indices,
                (root, PARALLEL_FLATTEN_DEPTH),
                &mut part,
                &mut |_, _, _| None,
            );
            (part, flattened)
        })
        .collect::<Vec<_>>()
        .into_iter();
    let mut tree = BinaryTree {
        nodes: Vec::with_capacity(source.len() / 2 + 1),
        triangle_ids: Vec::with_capacity(primitive_indices.len()),
        stack_depth: 1,
    };
    // The walk meets the subtrees at that depth in the order they were found.
    let root = walk(
        source,
        primitive_indices,
        (0, 1),
        &mut tree,
        &mut |_, depth, tree| {
            (depth == PARALLEL_FLATTEN_DEPTH).then(|| {
                let (part, flattened) = parts.next().expect("a walked subtree");
                splice(tree, part, flattened)
            })
        },
    );
    root_first(tree, root, source[0].aabb())
}

/// A tree numbered in post-order, root last, renumbered so that every parent
/// comes before its children and the root is node 0. A tree that is a single
/// leaf (`root_bounds` its box) still needs an inner node: the leaf is split
/// in two (a one-triangle leaf appears twice, which is harmless).
fn root_first(mut tree: BinaryTree, root: Flattened, root_bounds: &Aabb) -> BinaryTree {
    match root {
        Flattened::Inner(_) => {
            let last = tree.nodes.len() as u32 - 1;
            tree.nodes.reverse();
            for node in &mut tree.nodes {
                for child in node.children.iter_mut().filter(|child| child.count == 0) {
                    child.index = last - child.index;
                }
            }
        }
        Flattened::Leaf { count, .. } => {
            let first_half = count.div_ceil(2);
            let half = |index: u32, count: u32| BvhChild {
                min: root_bounds.min.to_array(),
                index,
                max: root_bounds.max.to_array(),
                count,
            };
            let left = half(0, first_half);
            let right = if count > first_half {
                half(first_half, count - first_half)
            } else {
                left
            };
            tree.nodes.push(BvhNode {
                children: [left, right],
            });
        }
    }
    tree
}

/// The child entry for a flattened subtree with box `bounds`.
fn binary_child(flattened: Flattened, bounds: &Aabb) -> BvhChild {
    let (index, count) = match flattened {
        Flattened::Leaf { first, count } => (first, count),
        Flattened::Inner(index) => (index, 0),
    };
    BvhChild {
        min: bounds.min.to_array(),
        index,
        max: bounds.max.to_array(),
        count,
    }
}

/// The depth (the root's is 1) of the subtrees [`flatten`] walks in parallel:
/// up to 16 of them, enough to keep every core busy.
const PARALLEL_FLATTEN_DEPTH: usize = 5;

/// Walks the subtree at `(root, its depth)` in post-order, left first, appending
/// its triangles and its inner nodes (numbered in post-order) to `tree`, and
/// returns what it became. `splice(node, depth, tree)` may stand in for an inner
/// node's whole subtree.
fn walk(
    source: &[Bvh2Node],
    primitive_indices: &[u32],
    (root, root_depth): (u32, usize),
    tree: &mut BinaryTree,
    splice: &mut impl FnMut(u32, usize, &mut BinaryTree) -> Option<Flattened>,
) -> Flattened {
    // (source node, its depth, children done)
    let mut work = vec![(root, root_depth, false)];
    let mut done: Vec<Flattened> = Vec::new();
    while let Some((index, depth, children_done)) = work.pop() {
        let node = &source[index as usize];
        if node.is_leaf() {
            let first = tree.triangle_ids.len() as u32;
            let range = node.first_index as usize..(node.first_index + node.prim_count) as usize;
            tree.triangle_ids
                .extend_from_slice(&primitive_indices[range]);
            done.push(Flattened::Leaf {
                first,
                count: node.prim_count,
            });
            continue;
        }
        let first_child = node.first_index;
        if !children_done {
            if let Some(flattened) = splice(index, depth, tree) {
                done.push(flattened);
                continue;
            }
            work.extend([
                (index, depth, true),
                (first_child + 1, depth + 1, false),
                (first_child, depth + 1, false),
            ]);
            continue;
        }
        let right = done.pop().expect("the right child is flattened");
        let left = done.pop().expect("the left child is flattened");
        let sources = [
            &source[first_child as usize],
            &source[first_child as usize + 1],
        ];
        if let (
            Flattened::Leaf {
                first,
                count: left_count,
            },
            Flattened::Leaf {
                count: right_count, ..
            },
        ) = (left, right)
        {
            // The two leaves' triangles are consecutive in leaf order.
            if collapses_into_one_leaf(
                node.aabb(),
                (*sources[0].aabb(), left_count),
                (*sources[1].aabb(), right_count),
            ) {
                done.push(Flattened::Leaf {
                    first,
                    count: left_count + right_count,
                });
                continue;
            }
        }
        done.push(Flattened::Inner(tree.nodes.len() as u32));
        tree.nodes.push(BvhNode {
            children: [
                binary_child(left, sources[0].aabb()),
                binary_child(right, sources[1].aabb()),
            ],
        });
        tree.stack_depth = tree.stack_depth.max(depth);
    }
    done.pop().expect("the root is flattened")
}

/// Appends a subtree walked on its own to `tree`, where one walk would have put
/// it: its node and triangle numbers shifted by what `tree` already holds.
fn splice(tree: &mut BinaryTree, part: BinaryTree, flattened: Flattened) -> Flattened {
    let node_offset = tree.nodes.len() as u32;
    let triangle_offset = tree.triangle_ids.len() as u32;
    tree.nodes.extend(part.nodes.into_iter().map(|mut node| {
        for child in &mut node.children {
            child.index += if child.count == 0 {
                node_offset
            } else {
                triangle_offset
            };
        }
        node
    }));
    tree.triangle_ids.extend_from_slice(&part.triangle_ids);
    tree.stack_depth = tree.stack_depth.max(part.stack_depth);
    match flattened {
        Flattened::Leaf { first, count } => Flattened::Leaf {
            first: first + triangle_offset,
            count,
        },
        Flattened::Inner(index) => Flattened::Inner(index + node_offset),
    }
}

mod gpu;

#[cfg(test)]
mod tests;
