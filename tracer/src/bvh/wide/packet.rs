//! Packet traversal of the wide tree for coherent rays (a camera's primary rays:
//! one origin, neighbouring directions, handed over by the Morton order in tiles
//! of 16; or any-hit rays of one octant from nearby points, such as shadow rays
//! to a light). One ray per lane: each child box is tested against the whole
//! packet at once, and each triangle too, so the rays share a node's memory
//! traffic and control flow. Where few rays of the packet remain in a subtree,
//! they finish it one by one with the single-ray walk, which tests eight boxes
//! or sixteen triangles at once instead. An any-hit lane leaves the packet at
//! its first hit.
//!
//! Culling before the ray-by-ray tests, each conservative:
//! - a packet none of whose rays enters the tree's box ends at once;
//! - a packet tests a node's eight children's boxes against its frustum (the
//!   range of its rays' origins and inverse directions, up to its farthest
//!   closest hit so far); a closest-hit packet visits those that pass nearest
//!   first by the frustum's entry distance, an any-hit packet in lane order
//!   (most of its rays visit them all). A closest-hit packet (a camera's
//!   rays from one origin) goes by the frustum alone where it bounds all
//!   three axes, as
//!   Embree's coherent packets do: its rays' own box tests dropped 0.4% of
//!   the children the frustum passed on the bunny and cost more than the
//!   visits they saved (without them the traversal is 1.10-1.22x as fast).
//!   An any-hit packet (rays from many origins, a looser frustum) tests the
//!   children that pass ray by ray, and its rays leave where they miss (the
//!   frustum alone made shadow and occlusion rays 1.1-1.6 times slower);
//! - at a leaf, it tests the triangles' own boxes against the frustum the same
//!   way, and only those that pass ray by ray (a leaf holds up to sixteen
//!   triangles, and a packet of a zoomed view's pixels sees a few of them).
//!
//! Each lane does the scalar tests' IEEE operations on its own ray, so distances,
//! culling and hits per ray are exactly those of the single-ray traversal; ties
//! go to the lowest leaf-order index as there.

use super::super::simd::{Lanes, Lanes8, LanesExt};
use super::{
    planes, slab_test, walk, watertight, Bvh, Found, PreparedRay, Ray, Stack, TriangleGroup, Walk,
    WideNode, GROUP, LEAF, NO_HIT, ROBUST_FAR_SCALE, STACK_ENTRIES, WIDTH,
};

/// The widest packet (16 rays: AVX-512's, and AVX2's in pairs of registers).
pub(super) const MAX_PACKET: usize = 16;

/// A subtree that at most a quarter of a packet's rays enter is finished by
/// single-ray walks (measured: 3 to 5 of 16 are about equally good).
pub(super) fn single_rays_below<T: Lanes>() -> u32 {
    (T::N / 4) as u32
}

/// Nodes still to visit: the node, the rays that entered its box, and (for
/// closest hits) their entry distances: a ray is dropped on pop if it has
/// found a closer hit since.
pub(super) struct PacketStack {
    entries: Vec<(u32, u32)>,
    t_entry: Vec<[f32; MAX_PACKET]>,
}

impl PacketStack {
    pub(super) fn new() -> PacketStack {
        PacketStack {
            entries: vec![(0, 0); STACK_ENTRIES],
            t_entry: vec![[0.0; MAX_PACKET]; STACK_ENTRIES],
        }
    }
}

/// The case of `trace`'s dispatch (dominant axis) and the signs of a ray's
/// direction: rays with equal keys and origins can travel together.
#[inline(always)]
pub(super) fn packet_key(ray: &Ray) -> u32 {
    let d = ray.direction.abs();
    let axis = if d.x >= d.y && d.x >= d.z {
        0
    } else if d.y >= d.z {
        1
    } else {
        2
    };
    let [x, y, z] = ray.direction.to_array().map(f32::is_sign_negative);
    axis | u32::from(x) << 2 | u32::from(y) << 3 | u32::from(z) << 4
}

/// Whether `rays` can travel as a packet: all alive, one origin, one key.
#[inline(always)]
pub(super) fn is_packet(rays: &[Ray]) -> bool {
    let key = packet_key(&rays[0]);
    let origin = rays[0].origin.to_array().map(f32::to_bits);
    rays.iter().all(|ray| {
        ray.tmax > 0.0
            && ray.origin.to_array().map(f32::to_bits) == origin
            && packet_key(ray) == key
    })
}

/// Traces up to `T::N` live rays with one [`packet_key`] (for closest hits,
/// `T::N` that pass [`is_packet`]), each result to `found`.
#[inline(always)]
pub(super) fn trace_packet<S: Lanes8, T: Lanes, const ANY_HIT: bool>(
    boxes: S,
    lanes: T,
    bvh: &Bvh,
    rays: &[Ray],
    stack: &mut PacketStack,
    single_stack: &mut Stack,
    found: &mut [Found; MAX_PACKET],
) {
    macro_rules! on_axes {
        ($kx:literal, $ky:literal, $kz:literal) => {
            traverse_packet::<S, T, $kx, $ky, $kz, ANY_HIT>(
                boxes,
                lanes,
                bvh,
                rays,
                stack,
                single_stack,
                found,
            )
        };
    }
    match packet_key(&rays[0]) & 3 {
        0 => on_axes!(1, 2, 0),
        1 => on_axes!(2, 0, 1),
        _ => on_axes!(0, 1, 2),
    }
}

#[inline(always)]
fn traverse_packet<
    S: Lanes8,
    T: Lanes,
    const KX: usize,
    const KY: usize,
    const KZ: usize,
    const ANY_HIT: bool,
>(
    boxes: S,
    lanes: T,
    bvh: &Bvh,
    rays: &[Ray],
    stack: &mut PacketStack,
    single_stack: &mut Stack,
    found: &mut [Found; MAX_PACKET],
) {
    // The packet's constants, as `PreparedRay::new` computes them per ray;
    // lanes without a ray (any-hit packets may be short) stay zero and are
    // never active, so no test's mask takes them.
    // A macro, not a closure: see `LanesExt`.
    macro_rules! row {
        ($ray:ident => $value:expr) => {
            lanes.lanes_of(|lane| rays.get(lane).map_or(0.0, |$ray| $value))
        };
    }
    let origin = if ANY_HIT {
        [
            row!(ray => ray.origin.x),
            row!(ray => ray.origin.y),
            row!(ray => ray.origin.z),
        ]
    } else {
        // One origin (`is_packet`).
        lanes.splat3(rays[0].origin.to_array())
    };
    let direction = [
        row!(ray => ray.direction.x),
        row!(ray => ray.direction.y),
        row!(ray => ray.direction.z),
    ];
    let one = lanes.splat(1.0);
    let inverse_direction = [
        lanes.div(one, direction[0]),
        lanes.div(one, direction[1]),
        lanes.div(one, direction[2]),
    ];
    // The packet's rays share their direction signs.
    let [near_plane, far_plane] = planes(rays[0].direction.to_array().map(f32::is_sign_negative));

    let mut closest = row!(ray => ray.tmax);
    let zero = lanes.splat(0.0);
    // The best hits' barycentrics.
    let (mut hit_u, mut hit_v) = (zero, zero);
    let mut best = [NO_HIT; MAX_PACKET];
    let scale = lanes.splat(ROBUST_FAR_SCALE);
    let box_rays = PacketBoxTest {
        origin,
        inverse_direction,
        near_plane,
        far_plane,
    };

    let wide = &bvh.wide;
    let mut stack_len = 0usize;
    let mut current = 0u32;
    // Rays that miss the tree's box miss every box in it (`WideBvh::bounds`):
    // where the mesh leaves most of the frame empty, most packets end here,
    // before the root's eight children are tested ray by ray.
    let mut active = box_rays
        .enter(
            lanes,
            |plane| wide.bounds[plane],
            closest,
            (1u32 << rays.len()) - 1,
        )
        .0;
    if active == 0 {
        found[..rays.len()].fill(None);
        return;
    }
    let mut frustum = Frustum::new(
        boxes,
        lanes,
        rays,
        // Closest-hit packets share their origin (`is_packet`).
        !ANY_HIT,
        &origin,
        &inverse_direction,
        closest,
    );
    // A closest-hit packet's children go by the frustum alone where it
    // bounds all three axes: with a direction along a slab (an infinite
    // inverse), it bounds two, a whole slab of the scene passes, and the
    // rays' own tests are what keeps the packet near its rays.
    let frustum_alone = !ANY_HIT && frustum.usable == [true; 3];
    let shear = [
        lanes.div(direction[KX], direction[KZ]),
        lanes.div(direction[KY], direction[KZ]),
        lanes.div(one, direction[KZ]),
    ];
    // Any hit: the lanes that have found one, and left the packet.
    let mut done = 0u32;
    'visit: loop {
        if active.count_ones() <= single_rays_below::<T>() {
            // Few rays left here: each finishes this subtree on its own.
            let mut closest_row = lanes.store_row(closest);
            let mut u_row = lanes.store_row(hit_u);
            let mut v_row = lanes.store_row(hit_v);
            let mut remaining = active;
            while remaining != 0 {
                let lane = remaining.trailing_zeros() as usize;
                remaining &= remaining - 1;
                let start = Walk {
                    best: best[lane],
                    closest: closest_row[lane],
                    u: u_row[lane],
                    v: v_row[lane],
                };
                let prepared = PreparedRay::new::<KX, KY, KZ>(&rays[lane]);
                let end = walk::<S, T, KX, KY, KZ, ANY_HIT>(
                    boxes,
                    lanes,
                    bvh,
                    &prepared,
                    current,
                    start,
                    single_stack,
                );
                best[lane] = end.best;
                if ANY_HIT && end.best != NO_HIT {
                    done |= 1 << lane;
                }
                closest_row[lane] = end.closest;
                u_row[lane] = end.u;
                v_row[lane] = end.v;
            }
            closest = lanes.load_row(&closest_row);
            hit_u = lanes.load_row(&u_row);
            hit_v = lanes.load_row(&v_row);
            frustum.farthest = lanes.greatest(closest);
        } else if ANY_HIT && current & LEAF == 0 {
            // Unless it is blocked, an any-hit ray visits every box it enters,
            // whatever the order, and most are not blocked: the children go on
            // the stack as they come (taken nearest first, occlusion rays took
            // 1.02-1.07 and shadow rays 1.07-1.56 times as long).
            let node = &wide.nodes[current as usize];
            let pushed_from = stack_len;
            let mut children = frustum.children_entered(boxes, node).0;
            while children != 0 {
                let child = children.trailing_zeros() as usize;
                children &= children - 1;
                let rays_in = box_rays
                    .enter(lanes, |plane| node.planes[plane][child], closest, active)
                    .0;
                if rays_in != 0 {
                    // No entry distance: see the pop below.
                    stack.entries[stack_len] = (node.children[child], rays_in);
                    stack_len += 1;
                }
            }
            if stack_len > pushed_from {
                stack_len -= 1;
                (current, active) = stack.entries[stack_len];
                continue 'visit;
            }
        } else if current & LEAF == 0 {
            let node = &wide.nodes[current as usize];
            let mut entered = [(0u32, 0u32, 0.0f32); WIDTH];
            let mut t_entry = [zero; WIDTH];
            let mut count = 0;
            // Closest hits: children are taken nearest first by the frustum's
            // entry distance (a bound on their rays', as Embree orders a
            // coherent packet's).
            let (mut children, frustum_entry) = frustum.children_entered(boxes, node);
            while children != 0 {
                let child = children.trailing_zeros() as usize;
                children &= children - 1;
                let (rays_in, t_enter) = if frustum_alone {
                    // The frustum's bound stands in for each ray's entry.
                    (active, lanes.splat(frustum_entry[child]))
                } else {
                    box_rays.enter(lanes, |plane| node.planes[plane][child], closest, active)
                };
                if rays_in != 0 {
                    t_entry[count] = t_enter;
                    entered[count] = (node.children[child], rays_in, frustum_entry[child]);
                    count += 1;
                }
            }
            if count > 0 {
                // Nearest last on the stack, so taken first (insertion sort).
                let mut order = [0usize; WIDTH];
                for i in 0..count {
                    let mut slot = i;
                    while slot > 0 && entered[order[slot - 1]].2 < entered[i].2 {
                        order[slot] = order[slot - 1];
                        slot -= 1;
                    }
                    order[slot] = i;
                }
                for &i in &order[..count - 1] {
                    stack.entries[stack_len] = (entered[i].0, entered[i].1);
                    lanes.store_at(t_entry[i], &mut stack.t_entry[stack_len], 0);
                    stack_len += 1;
                }
                let nearest = order[count - 1];
                current = entered[nearest].0;
                active = entered[nearest].1;
                continue 'visit;
            }
        } else {
            let mut group_index = (current & !LEAF) as usize;
            // Whether some ray's closest hit came nearer: the frustum's far
            // bound follows the packet's farthest closest hit.
            let mut closer_in_leaf = false;
            'groups: loop {
                let group = &wide.groups[group_index];
                let mut triangles = frustum.triangles_entered(boxes, group);
                while triangles != 0 {
                    let lane = triangles.trailing_zeros() as usize;
                    triangles &= triangles - 1;
                    let mut vertices = [[zero; 3]; 3];
                    for (k, vertex) in vertices.iter_mut().enumerate() {
                        for (axis, coordinate) in vertex.iter_mut().enumerate() {
                            *coordinate = lanes.splat(group.v[k][axis][lane]);
                        }
                    }
                    let crossing =
                        watertight::<T, KX, KY, KZ>(lanes, vertices, &origin, &shear, active);
                    if ANY_HIT {
                        // `t < tmax`, as the single-ray any-hit test.
                        let hits = crossing.hits & lanes.lt(crossing.t, closest);
                        let mut newly = hits;
                        while newly != 0 {
                            let ray = newly.trailing_zeros() as usize;
                            newly &= newly - 1;
                            best[ray] = group.first + lane as u32;
                        }
                        done |= hits;
                        active &= !hits;
                        if active == 0 {
                            break 'groups;
                        }
                        continue;
                    }
                    let hits = crossing.hits & lanes.le(crossing.t, closest);
                    if hits == 0 {
                        continue;
                    }
                    let closer = hits & lanes.lt(crossing.t, closest);
                    // Rays that take this triangle: those it is closer for, and
                    // those it ties with a hit of a higher leaf-order index.
                    let index = group.first + lane as u32;
                    let mut taken = closer;
                    let mut updated = hits;
                    while updated != 0 {
                        let ray = updated.trailing_zeros() as usize;
                        updated &= updated - 1;
                        if closer & (1 << ray) != 0 || (best[ray] != NO_HIT && index < best[ray]) {
                            best[ray] = index;
                            taken |= 1 << ray;
                        }
                    }
                    if taken != 0 {
                        closest = lanes.select(taken, crossing.t, closest);
                        let (u, v) = crossing.barycentrics(lanes);
                        hit_u = lanes.select(taken, u, hit_u);
                        hit_v = lanes.select(taken, v, hit_v);
                        closer_in_leaf = true;
                    }
                }
                if group.last {
                    break;
                }
                group_index += 1;
            }
            if closer_in_leaf {
                frustum.farthest = lanes.greatest(closest);
            }
        }
        let limit = lanes.mul(closest, scale);
        loop {
            if stack_len == 0 {
                break 'visit;
            }
            stack_len -= 1;
            let (node, rays_in) = stack.entries[stack_len];
            // An any-hit ray's `closest` is its `tmax` until it is done, so it
            // still enters every box it entered when pushed.
            let still = if ANY_HIT {
                rays_in & !done
            } else {
                let t_entry = lanes.load_row(&stack.t_entry[stack_len]);
                rays_in & lanes.le(t_entry, limit)
            };
            if still != 0 {
                current = node;
                active = still;
                continue 'visit;
            }
        }
    }

    let closest = lanes.store_row(closest);
    let (u, v) = (lanes.store_row(hit_u), lanes.store_row(hit_v));
    for (lane, (ray, result)) in rays.iter().zip(found.iter_mut()).enumerate() {
        *result = if best[lane] == NO_HIT {
            None
        } else if ANY_HIT {
            // What the single-ray any-hit traversal returns.
            Some((0, 0.0, 0.0, 0.0))
        } else {
            let index = best[lane] as usize;
            debug_assert_eq!(
                PreparedRay::new::<KX, KY, KZ>(ray).intersect_triangle::<KX, KY, KZ>(
                    &bvh.triangles[index],
                    f32::INFINITY,
                    false
                ),
                Some((closest[lane], u[lane], v[lane]))
            );
            Some((index, closest[lane], u[lane], v[lane]))
        };
    }
}

/// The packet's slab test of one box, ray by ray exactly as the scalar test.
struct PacketBoxTest<T: Lanes> {
    origin: [T::F; 3],
    inverse_direction: [T::F; 3],
    near_plane: [usize; 3],
    far_plane: [usize; 3],
}

impl<T: Lanes> PacketBoxTest<T> {
    /// The `active` rays that enter the box whose plane `p` (a row of
    /// [`WideNode::planes`]) is `plane(p)` before their `closest`, and every
    /// lane's entry distance.
    #[inline(always)]
    fn enter(
        &self,
        lanes: T,
        plane: impl Fn(usize) -> f32,
        closest: T::F,
        active: u32,
    ) -> (u32, T::F) {
        let near = self.near_plane.map(&plane);
        let far = self.far_plane.map(plane);
        let (entered, t_enter) = slab_test(
            lanes,
            [lanes.splat3(near), lanes.splat3(far)],
            &self.origin,
            &self.inverse_direction,
            closest,
        );
        (entered & active, t_enter)
    }
}

/// What the packet's rays have in common, to see, for eight children at once,
/// which of them no ray of the packet can enter: per axis the range of the
/// rays' origins and of their inverse directions (of one sign). A ray's slab
/// distance `(plane - origin) * inverse` is, rounding included, monotonic in
/// both, so the range's corners bound every ray's distance, and a child whose
/// bounds fail the entry test fails it for every ray: culling it changes no
/// result. An axis on which some ray's inverse direction or origin is not
/// finite (a direction parallel to the slab) bounds nothing and is skipped.
struct Frustum<S: Lanes> {
    usable: [bool; 3],
    /// The origin bound that gives the least near-plane distance, and the one
    /// that gives the greatest far-plane distance.
    near_origin: [S::F; 3],
    far_origin: [S::F; 3],
    inverse_low: [S::F; 3],
    inverse_high: [S::F; 3],
    near_plane: [usize; 3],
    far_plane: [usize; 3],
    /// The packet's farthest closest hit so far (at first its largest
    /// `tmax`): no ray's closest hit is farther.
    farthest: f32,
}

impl<S: Lanes8> Frustum<S> {
    #[inline(always)]
    fn new<T: Lanes>(
        lanes: S,
        packet_lanes: T,
        rays: &[Ray],
        one_origin: bool,
        origin: &[T::F; 3],
        inverse_direction: &[T::F; 3],
        closest: T::F,
    ) -> Frustum<S> {
        let negative = rays[0].direction.to_array().map(f32::is_sign_negative);
        let [near_plane, far_plane] = planes(negative);
        let zero = lanes.splat(0.0);
        let mut frustum = Frustum {
            usable: [false; 3],
            near_origin: [zero; 3],
            far_origin: [zero; 3],
            inverse_low: [zero; 3],
            inverse_high: [zero; 3],
            near_plane,
            far_plane,
            farthest: packet_lanes.greatest(closest),
        };
        let lanes_in_use = (1u32 << rays.len()) - 1;
        let whole = rays.len() == T::N;
        for axis in 0..3 {
            let (mut origin, mut inverse) = (origin[axis], inverse_direction[axis]);
            // `x - x` is 0 only for finite `x`.
            let zero = packet_lanes.splat(0.0);
            let finite = packet_lanes.eq(packet_lanes.sub(origin, origin), zero)
                & packet_lanes.eq(packet_lanes.sub(inverse, inverse), zero);
            frustum.usable[axis] = finite & lanes_in_use == lanes_in_use;
            if !frustum.usable[axis] {
                continue;
            }
            if !whole {
                // Lanes past the packet's rays repeat its first ray.
                let first = rays[0];
                origin = packet_lanes.select(
                    lanes_in_use,
                    origin,
                    packet_lanes.splat(first.origin[axis]),
                );
                inverse = packet_lanes.select(
                    lanes_in_use,
                    inverse,
                    packet_lanes.splat(1.0 / first.direction[axis]),
                );
            }
            let (origin_low, origin_high) = if one_origin {
                (rays[0].origin[axis], rays[0].origin[axis])
            } else {
                (packet_lanes.least(origin), packet_lanes.greatest(origin))
            };
            // A positive inverse makes the distance grow with `plane - origin`,
            // so the least near distance comes from the highest origin.
            let (near, far) = if negative[axis] {
                (origin_low, origin_high)
            } else {
                (origin_high, origin_low)
            };
            frustum.near_origin[axis] = lanes.splat(near);
            frustum.far_origin[axis] = lanes.splat(far);
            frustum.inverse_low[axis] = lanes.splat(packet_lanes.least(inverse));
            frustum.inverse_high[axis] = lanes.splat(packet_lanes.greatest(inverse));
        }
        frustum
    }

    /// The children of `node` some ray of the packet may enter before its
    /// `tmax`, and a bound below each one's rays' entry distances.
    #[inline(always)]
    fn children_entered(&self, lanes: S, node: &WideNode) -> (u32, [f32; 8]) {
        // No closures around intrinsics: see `LanesExt`.
        let planes = [
            lanes.load(&node.planes[0]),
            lanes.load(&node.planes[1]),
            lanes.load(&node.planes[2]),
            lanes.load(&node.planes[3]),
            lanes.load(&node.planes[4]),
            lanes.load(&node.planes[5]),
        ];
        let (entered, t_enter) = self.boxes_entered(lanes, &planes);
        (entered & node.valid, lanes.store(t_enter))
    }

    /// The triangles of `group` some ray of the packet may hit: those whose
    /// bounding boxes it may enter. Each box is a leaf's box, had the leaf held
    /// that triangle alone, so the robust box test's guarantee holds for it: a
    /// ray that hits the triangle enters its box. Where a leaf spans several
    /// pixels' worth of small triangles, most are outside a packet's frustum.
    #[inline(always)]
    fn triangles_entered(&self, lanes: S, group: &TriangleGroup) -> u32 {
        let mut entered = 0;
        for half in 0..GROUP / 8 {
            let lanes_in_half = group.valid >> (8 * half) & 0xff;
            if lanes_in_half == 0 {
                break;
            }
            let corner = |vertex: usize, axis: usize| -> &[f32; 8] {
                group.v[vertex][axis][8 * half..8 * half + 8]
                    .try_into()
                    .expect("eight lanes")
            };
            let mut planes = [lanes.splat(0.0); 6];
            for axis in 0..3 {
                let a = lanes.load(corner(0, axis));
                let b = lanes.load(corner(1, axis));
                let c = lanes.load(corner(2, axis));
                planes[axis] = lanes.min_or_second(lanes.min_or_second(a, b), c);
                planes[3 + axis] = lanes.max_or_second(lanes.max_or_second(a, b), c);
            }
            entered |= (self.boxes_entered(lanes, &planes).0 & lanes_in_half) << (8 * half);
        }
        entered
    }

    /// Which of eight boxes, given by their planes (the rows of
    /// [`WideNode::planes`]), some ray of the packet may enter before its
    /// closest hit, and a bound below their entry distances.
    #[inline(always)]
    fn boxes_entered(&self, lanes: S, planes: &[S::F; 6]) -> (u32, S::F) {
        let mut t_enter = lanes.splat(0.0);
        let mut t_exit = lanes.splat(self.farthest);
        for axis in 0..3 {
            if !self.usable[axis] {
                continue;
            }
            let near = lanes.sub(planes[self.near_plane[axis]], self.near_origin[axis]);
            let far = lanes.sub(planes[self.far_plane[axis]], self.far_origin[axis]);
            // Finite times finite: no NaN.
            let least_near = lanes.min_or_second(
                lanes.mul(near, self.inverse_low[axis]),
                lanes.mul(near, self.inverse_high[axis]),
            );
            let greatest_far = lanes.max_or_second(
                lanes.mul(far, self.inverse_low[axis]),
                lanes.mul(far, self.inverse_high[axis]),
            );
            t_enter = lanes.max_or_second(least_near, t_enter);
            t_exit = lanes.min_or_second(greatest_far, t_exit);
        }
        let entered = lanes.le(t_enter, lanes.mul(t_exit, lanes.splat(ROBUST_FAR_SCALE)));
        (entered, t_enter)
    }
}
