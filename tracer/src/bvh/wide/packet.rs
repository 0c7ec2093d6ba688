//! Packet traversal of the wide tree for coherent rays (a camera's primary rays:
//! one origin, neighbouring directions, handed over by the Morton order in tiles
//! of 16; or any-hit rays of one octant from nearby points, such as shadow rays
//! to a light). One ray per lane: each child box is tested against the whole
//! packet at once, and each triangle too, so the rays share a node's memory
//! traffic and control flow. Where few rays of the packet remain in a subtree,
//! they finish it one by one with the single-ray walk, which tests eight boxes
//! or sixteen triangles at once instead. An any-hit lane leaves the packet at
//! its first hit. Below its first two inner nodes a packet first tests the
//! eight children's boxes against its frustum (the range of its rays' origins
//! and inverse directions) and tests only the children that pass it ray by
//! ray: most children of a deep node are missed by every ray of the packet.
//!
//! Each lane does the scalar tests' IEEE operations on its own ray, so distances,
//! culling and hits per ray are exactly those of the single-ray traversal; ties
//! go to the lowest leaf-order index as there.

use super::super::simd::{Lanes, Lanes8, LanesExt};
use super::{
    planes, walk, watertight, Bvh, Found, PreparedRay, Ray, Stack, Walk, WideNode, LEAF, NO_HIT,
    ROBUST_FAR_SCALE, STACK_ENTRIES, WIDTH,
};

/// Inner nodes a packet visits before it culls children by its [`Frustum`]:
/// near the root most children are entered, and a packet that leaves early
/// (rays that miss the scene) would pay for the frustum and gain nothing
/// (measured: from the third node on is 0-11% faster than from the first,
/// which is slower on the bunny's front view).
const FRUSTUM_AFTER: u32 = 2;

/// The widest packet (AVX-512: 16 rays).
pub(super) const MAX_PACKET: usize = 16;

/// A subtree that at most a quarter of a packet's rays enter is finished by
/// single-ray walks (measured: 3 to 5 of 16 are about equally good).
pub(super) fn single_rays_below<T: Lanes>() -> u32 {
    (T::N / 4) as u32
}

/// Nodes still to visit: the node, the rays that entered its box, and their entry
/// distances (a ray is dropped on pop if it has found a closer hit since).
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
    let mut rows = [[0.0f32; MAX_PACKET]; 7];
    for (lane, ray) in rays.iter().enumerate() {
        for axis in 0..3 {
            rows[axis][lane] = ray.origin[axis];
            rows[3 + axis][lane] = ray.direction[axis];
        }
        rows[6][lane] = ray.tmax;
    }
    let origin = [
        lanes.load_row(&rows[0]),
        lanes.load_row(&rows[1]),
        lanes.load_row(&rows[2]),
    ];
    let direction = [
        lanes.load_row(&rows[3]),
        lanes.load_row(&rows[4]),
        lanes.load_row(&rows[5]),
    ];
    let one = lanes.splat(1.0);
    let inverse_direction = [
        lanes.div(one, direction[0]),
        lanes.div(one, direction[1]),
        lanes.div(one, direction[2]),
    ];
    let shear = [
        lanes.div(direction[KX], direction[KZ]),
        lanes.div(direction[KY], direction[KZ]),
        lanes.div(one, direction[KZ]),
    ];
    // The packet's rays share their direction signs.
    let [near_plane, far_plane] = planes(rays[0].direction.to_array().map(f32::is_sign_negative));
    let mut frustum = None;
    let mut inner_nodes_visited = 0;

    let mut closest = lanes.load_row(&rows[6]);
    let zero = lanes.splat(0.0);
    // The best hits' barycentrics.
    let (mut hit_u, mut hit_v) = (zero, zero);
    let mut best = [NO_HIT; MAX_PACKET];
    let scale = lanes.splat(ROBUST_FAR_SCALE);
    let infinity = lanes.splat(f32::INFINITY);

    let wide = &bvh.wide;
    let mut stack_len = 0usize;
    let mut current = 0u32;
    let mut active = (1u32 << rays.len()) - 1;
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
        } else if current & LEAF == 0 {
            let node = &wide.nodes[current as usize];
            let mut entered = [(0u32, 0u32, 0.0f32); WIDTH];
            let mut t_entry = [[0.0f32; MAX_PACKET]; WIDTH];
            let mut count = 0;
            inner_nodes_visited += 1;
            let mut children = node.valid;
            if inner_nodes_visited > FRUSTUM_AFTER {
                // No closure: see `LanesExt`.
                if frustum.is_none() {
                    frustum = Some(Frustum::new(
                        boxes,
                        lanes,
                        rays,
                        // Closest-hit packets share their origin (`is_packet`).
                        !ANY_HIT,
                        &origin,
                        &inverse_direction,
                    ));
                }
                if let Some(frustum) = &frustum {
                    children = frustum.children_entered(boxes, node);
                }
            }
            while children != 0 {
                let child = children.trailing_zeros() as usize;
                children &= children - 1;
                let mut t_enter = zero;
                let mut t_exit = closest;
                for axis in 0..3 {
                    let near = lanes.splat(node.planes[near_plane[axis]][child]);
                    let far = lanes.splat(node.planes[far_plane[axis]][child]);
                    let t_near = lanes.mul(lanes.sub(near, origin[axis]), inverse_direction[axis]);
                    let t_far = lanes.mul(lanes.sub(far, origin[axis]), inverse_direction[axis]);
                    // NaN leaves the accumulators unchanged, as in the scalar test.
                    t_enter = lanes.max_or_second(t_near, t_enter);
                    t_exit = lanes.min_or_second(t_far, t_exit);
                }
                let rays_in = lanes.le(t_enter, lanes.mul(t_exit, scale))
                    & lanes.lt(t_enter, infinity)
                    & active;
                if rays_in != 0 {
                    lanes.store_at(t_enter, &mut t_entry[count], 0);
                    // Ordered by the entry distance of the first ray in.
                    let key = t_entry[count][rays_in.trailing_zeros() as usize];
                    entered[count] = (node.children[child], rays_in, key);
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
                    stack.t_entry[stack_len] = t_entry[i];
                    stack_len += 1;
                }
                let nearest = order[count - 1];
                current = entered[nearest].0;
                active = entered[nearest].1;
                continue 'visit;
            }
        } else {
            let mut group_index = (current & !LEAF) as usize;
            'groups: loop {
                let group = &wide.groups[group_index];
                let mut triangles = group.valid;
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
                    }
                }
                if group.last {
                    break;
                }
                group_index += 1;
            }
        }
        let limit = lanes.mul(closest, scale);
        loop {
            if stack_len == 0 {
                break 'visit;
            }
            stack_len -= 1;
            let (node, rays_in) = stack.entries[stack_len];
            let t_entry = lanes.load_row(&stack.t_entry[stack_len]);
            let still = rays_in & lanes.le(t_entry, limit) & !done;
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
    /// The packet's largest `tmax`: no ray's closest hit is farther.
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
            farthest: rays.iter().fold(0.0f32, |bound, ray| bound.max(ray.tmax)),
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
    /// `tmax`.
    #[inline(always)]
    fn children_entered(&self, lanes: S, node: &WideNode) -> u32 {
        let mut t_enter = lanes.splat(0.0);
        let mut t_exit = lanes.splat(self.farthest);
        for axis in 0..3 {
            if !self.usable[axis] {
                continue;
            }
            let near = lanes.sub(
                lanes.load(&node.planes[self.near_plane[axis]]),
                self.near_origin[axis],
            );
            let far = lanes.sub(
                lanes.load(&node.planes[self.far_plane[axis]]),
                self.far_origin[axis],
            );
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
        lanes.le(t_enter, lanes.mul(t_exit, lanes.splat(ROBUST_FAR_SCALE))) & node.valid
    }
}
