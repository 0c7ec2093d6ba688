use super::*;
use crate::builtin_scene::builtin_scene;
use crate::random::SplitMix64;

/// The watertight test applied to one file-order triangle, dispatched like `traverse`.
fn intersect_one(ray: &Ray, vertices: [Vec3; 3]) -> Option<(f32, f32, f32)> {
    let [v0, v1, v2] = vertices.map(|v| v.to_array());
    let triangle = BvhTriangle { v0, v1, v2 };
    let d = ray.direction.abs();
    if d.x >= d.y && d.x >= d.z {
        PreparedRay::new::<1, 2, 0>(ray).intersect_triangle::<1, 2, 0>(&triangle, ray.tmax)
    } else if d.y >= d.z {
        PreparedRay::new::<2, 0, 1>(ray).intersect_triangle::<2, 0, 1>(&triangle, ray.tmax)
    } else {
        PreparedRay::new::<0, 1, 2>(ray).intersect_triangle::<0, 1, 2>(&triangle, ray.tmax)
    }
}

/// Every hit along the ray: (file-order triangle, t).
fn brute_force_hits(mesh: &TriangleMesh, ray: &Ray) -> Vec<(u32, f32)> {
    (0..mesh.triangles.len())
        .filter_map(|i| {
            intersect_one(ray, mesh.triangle_vertices(i)).map(|(t, _, _)| (i as u32, t))
        })
        .collect()
}

/// Checks closest hit and occlusion of one ray against brute force.
fn check_against_brute_force(bvh: &Bvh, mesh: &TriangleMesh, ray: &Ray) {
    let hits = brute_force_hits(mesh, ray);
    let closest = hits.iter().map(|&(_, t)| t).fold(f32::INFINITY, f32::min);
    match bvh.intersect_closest(ray) {
        None => assert!(hits.is_empty(), "BVH missed {ray:?}; brute force {hits:?}"),
        Some(hit) => {
            assert_eq!(hit.t, closest, "{ray:?}");
            // Ties (a ray through a shared edge) may go to either triangle.
            let tied: Vec<u32> = hits
                .iter()
                .filter(|&&(_, t)| t <= closest * (1.0 + 1e-5))
                .map(|&(prim, _)| prim)
                .collect();
            assert!(tied.contains(&hit.prim), "{ray:?}: {hit:?} not in {tied:?}");
            let (t, u, v) = intersect_one(ray, mesh.triangle_vertices(hit.prim as usize)).unwrap();
            assert_eq!((t, u, v), (hit.t, hit.u, hit.v));
        }
    }
    assert_eq!(bvh.occluded(ray, ray.tmax), !hits.is_empty(), "{ray:?}");
    if let Some(&(_, t)) = hits.iter().max_by(|a, b| a.1.total_cmp(&b.1)) {
        // A segment that ends between hits sees only the hits before its end.
        let end = 0.5 * (closest + t);
        let any_before_end = hits.iter().any(|&(_, t)| t < end);
        assert_eq!(
            bvh.occluded(ray, end),
            any_before_end,
            "{ray:?} up to {end}"
        );
    }
}

fn random_point(random: &mut SplitMix64, low: f32, high: f32) -> Vec3 {
    Vec3::new(
        random.range(low, high),
        random.range(low, high),
        random.range(low, high),
    )
}

/// Random directions, a quarter of them with one or two zero components (exactly
/// +0 or -0) to exercise the infinite inverse directions of the slab test.
fn random_direction(random: &mut SplitMix64) -> Vec3 {
    let mut d = random_point(random, -1.0, 1.0);
    match random.next_u64() % 8 {
        0 => d.x = 0.0,
        1 => d.y = -0.0,
        2 => {
            d.x = -0.0;
            d.z = 0.0;
        }
        _ => {}
    }
    if d == Vec3::ZERO {
        Vec3::Y
    } else {
        d
    }
}

fn random_soup(random: &mut SplitMix64, count: usize) -> TriangleMesh {
    let mut mesh = TriangleMesh::default();
    for i in 0..count {
        let center = random_point(random, 0.0, 1.0);
        let size = random.range(0.005, 0.15);
        for _ in 0..3 {
            mesh.positions
                .push(center + size * random_point(random, -1.0, 1.0));
        }
        let first = 3 * i as u32;
        mesh.triangles.push([first, first + 1, first + 2]);
    }
    mesh
}

fn random_rays(random: &mut SplitMix64, count: usize, mesh: &TriangleMesh) -> Vec<Ray> {
    (0..count)
        .map(|i| {
            let origin = random_point(random, -0.5, 1.5);
            // Half the rays aim at a triangle so that most of them hit something.
            let direction = if i % 2 == 0 {
                let target = random.next_u64() as usize % mesh.triangles.len();
                let [a, b, c] = mesh.triangle_vertices(target);
                (a + b + c) / 3.0 - origin
            } else {
                random_direction(random)
            };
            let tmax = if i % 3 == 0 {
                random.range(0.0, 2.0)
            } else {
                f32::INFINITY
            };
            Ray {
                origin,
                direction,
                tmax,
            }
        })
        .collect()
}

#[test]
fn matches_brute_force_on_a_random_soup() {
    let mut random = SplitMix64::new(1);
    let mesh = random_soup(&mut random, 3000);
    let bvh = Bvh::build(&mesh).unwrap();
    for ray in random_rays(&mut random, 3000, &mesh) {
        check_against_brute_force(&bvh, &mesh, &ray);
    }
}

#[test]
fn matches_brute_force_on_the_builtin_scene() {
    let mesh = builtin_scene(24).unwrap();
    let bvh = Bvh::build(&mesh).unwrap();
    let mut random = SplitMix64::new(2);
    let bounds = mesh.bounds().unwrap();
    for i in 0..2000 {
        // Camera-like rays from outside the layer plus rays from inside it.
        let origin = if i % 2 == 0 {
            bounds.center() + Vec3::new(0.0, 0.0, bounds.diagonal())
        } else {
            random_point(&mut random, -1.0, 1.0) * Vec3::new(1.0, 1.0, 0.3)
        };
        let target = random_point(&mut random, -1.0, 1.0) * Vec3::new(1.0, 1.0, 0.3);
        let ray = Ray {
            origin,
            direction: if i % 5 == 0 {
                random_direction(&mut random)
            } else {
                target - origin
            },
            tmax: f32::INFINITY,
        };
        check_against_brute_force(&bvh, &mesh, &ray);
    }
}

#[test]
fn median_split_fallback_matches_brute_force() {
    let mut random = SplitMix64::new(3);
    let mesh = random_soup(&mut random, 1000);
    let bvh = Bvh::build_median_split(&mesh);
    check_structure(&bvh, &mesh);
    assert!(bvh.stack_depth() <= 10, "{}", bvh.stack_depth());
    for ray in random_rays(&mut random, 1000, &mesh) {
        check_against_brute_force(&bvh, &mesh, &ray);
    }
}

/// Every triangle appears exactly once and lies inside its leaf's box; child boxes
/// contain the boxes below them; the stack depth bound holds.
fn check_structure(bvh: &Bvh, mesh: &TriangleMesh) {
    let mut ids = bvh.triangle_ids().to_vec();
    ids.sort_unstable();
    assert_eq!(ids, (0..mesh.triangles.len() as u32).collect::<Vec<_>>());
    for (leaf_order, &id) in bvh.triangle_ids().iter().enumerate() {
        let [v0, v1, v2] = mesh.triangle_vertices(id as usize).map(|v| v.to_array());
        assert_eq!(bvh.triangles()[leaf_order], BvhTriangle { v0, v1, v2 });
    }
    let contains = |outer: &BvhChild, min: [f32; 3], max: [f32; 3]| {
        (0..3).all(|a| outer.min[a] <= min[a] && max[a] <= outer.max[a])
    };
    let mut depth_of = vec![0usize; bvh.nodes().len()];
    depth_of[0] = 1;
    let mut visited = 0;
    let mut work = vec![0usize];
    while let Some(node) = work.pop() {
        visited += 1;
        assert!(depth_of[node] <= bvh.stack_depth());
        for child in &bvh.nodes()[node].children {
            if child.count == 0 {
                let below = child.index as usize;
                depth_of[below] = depth_of[node] + 1;
                for grandchild in &bvh.nodes()[below].children {
                    assert!(contains(child, grandchild.min, grandchild.max));
                }
                work.push(below);
            } else {
                let range = child.index as usize..(child.index + child.count) as usize;
                for triangle in &bvh.triangles()[range] {
                    for v in [triangle.v0, triangle.v1, triangle.v2] {
                        assert!(contains(child, v, v));
                    }
                }
            }
        }
    }
    assert_eq!(visited, bvh.nodes().len());
    assert!(bvh.stack_depth() <= MAX_STACK_DEPTH);
}

#[test]
fn structure_of_built_trees() {
    let soup = random_soup(&mut SplitMix64::new(4), 5000);
    check_structure(&Bvh::build(&soup).unwrap(), &soup);
    let scene = builtin_scene(16).unwrap();
    check_structure(&Bvh::build(&scene).unwrap(), &scene);
}

#[test]
fn tiny_meshes_have_a_root_node() {
    for count in [1, 2, 3, 7] {
        let mesh = random_soup(&mut SplitMix64::new(count as u64), count);
        let bvh = Bvh::build(&mesh).unwrap();
        check_structure(&bvh, &mesh);
        if count == 1 {
            assert_eq!(bvh.nodes().len(), 1);
        }
        for i in 0..count {
            let [a, b, c] = mesh.triangle_vertices(i);
            let origin = Vec3::new(0.5, 0.5, -3.0);
            let ray = Ray {
                origin,
                direction: (a + b + c) / 3.0 - origin,
                tmax: f32::INFINITY,
            };
            assert!(bvh.intersect_closest(&ray).is_some());
            check_against_brute_force(&bvh, &mesh, &ray);
        }
    }
}

#[test]
fn empty_mesh_is_an_error() {
    assert_eq!(
        Bvh::build(&TriangleMesh::default()).unwrap_err(),
        MeshError::NoTriangles
    );
}

/// A closed, subdivided icosahedron (shared vertices, consistent winding).
fn icosphere(subdivisions: u32) -> TriangleMesh {
    let phi = (1.0 + 5f32.sqrt()) / 2.0;
    let mut positions: Vec<Vec3> = [
        (-1.0, phi, 0.0),
        (1.0, phi, 0.0),
        (-1.0, -phi, 0.0),
        (1.0, -phi, 0.0),
        (0.0, -1.0, phi),
        (0.0, 1.0, phi),
        (0.0, -1.0, -phi),
        (0.0, 1.0, -phi),
        (phi, 0.0, -1.0),
        (phi, 0.0, 1.0),
        (-phi, 0.0, -1.0),
        (-phi, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut triangles: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        let mut midpoints = std::collections::HashMap::new();
        let mut midpoint = |a: u32, b: u32, positions: &mut Vec<Vec3>| {
            *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
                positions.push(((positions[a as usize] + positions[b as usize]) * 0.5).normalize());
                positions.len() as u32 - 1
            })
        };
        triangles = triangles
            .iter()
            .flat_map(|&[a, b, c]| {
                let ab = midpoint(a, b, &mut positions);
                let bc = midpoint(b, c, &mut positions);
                let ca = midpoint(c, a, &mut positions);
                [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
            })
            .collect();
    }
    TriangleMesh {
        positions,
        triangles,
        normals: None,
        scalars: None,
    }
}

/// A unit grid in the plane z = 0: every box plane of the BVH lies on grid lines,
/// so axis-parallel rays run exactly in slab planes.
fn grid(cells: u32) -> TriangleMesh {
    let side = cells + 1;
    let positions = (0..side * side)
        .map(|i| Vec3::new((i % side) as f32, (i / side) as f32, 0.0))
        .collect();
    let triangles = (0..cells * cells)
        .flat_map(|cell| {
            let corner = cell / cells * side + cell % cells;
            [
                [corner, corner + 1, corner + side + 1],
                [corner, corner + side + 1, corner + side],
            ]
        })
        .collect();
    TriangleMesh {
        positions,
        triangles,
        normals: None,
        scalars: None,
    }
}

#[test]
fn rays_through_shared_vertices_and_edges_never_leak() {
    let sphere = icosphere(3);
    let bvh = Bvh::build(&sphere).unwrap();
    let mut random = SplitMix64::new(5);
    let mut targets: Vec<Vec3> = sphere.positions.clone();
    for &[a, b, _] in &sphere.triangles {
        let (pa, pb) = (sphere.positions[a as usize], sphere.positions[b as usize]);
        for s in [0.5, 0.25, 1.0 / 3.0] {
            targets.push(pa + s * (pb - pa));
        }
    }
    for target in targets {
        // From outside, within 30 degrees of the outward direction at the target (a
        // ray that only grazes a convex vertex may touch the mesh in that one point):
        // the first hit is no farther than the target point.
        let tilt = 0.5 * random_point(&mut random, -1.0, 1.0).normalize();
        let origin = 3.0 * (target.normalize() + tilt).normalize();
        let outside = Ray {
            origin,
            direction: target - origin,
            tmax: f32::INFINITY,
        };
        let hit = bvh.intersect_closest(&outside);
        assert!(
            hit.is_some_and(|h| h.t <= 1.0 + 1e-5),
            "leak at {target}: {hit:?}"
        );
        // From inside: the ray must not escape the closed surface.
        let inside = Ray {
            origin: random_point(&mut random, -0.2, 0.2),
            direction: target,
            tmax: f32::INFINITY,
        };
        let inside = Ray {
            direction: target - inside.origin,
            ..inside
        };
        assert!(
            bvh.intersect_closest(&inside).is_some(),
            "escape at {target}"
        );
        assert!(bvh.occluded(&inside, f32::INFINITY));
    }
}

#[test]
fn axis_parallel_rays_in_slab_planes_hit_the_grid() {
    let mesh = grid(16);
    let bvh = Bvh::build(&mesh).unwrap();
    let steps = [0.0, 0.5, 1.0, 2.0, 7.5, 8.0, 15.0, 16.0];
    for &x in &steps {
        for &y in &steps {
            for down in [Vec3::new(0.0, 0.0, -1.0), Vec3::new(-0.0, -0.0, -2.0)] {
                let ray = Ray {
                    origin: Vec3::new(x, y, 1.0),
                    direction: down,
                    tmax: f32::INFINITY,
                };
                let hit = bvh.intersect_closest(&ray);
                assert!(hit.is_some(), "missed the grid at ({x}, {y}) going {down}");
                assert!((hit.unwrap().t * down.length() - 1.0).abs() < 1e-6);
                check_against_brute_force(&bvh, &mesh, &ray);
            }
        }
    }
    // Beside the grid, still exactly in a slab plane: a miss.
    let beside = Ray {
        origin: Vec3::new(16.0, 16.5, 1.0),
        direction: Vec3::new(0.0, 1.0, -1.0),
        tmax: f32::INFINITY,
    };
    assert_eq!(bvh.intersect_closest(&beside), None);
}

/// Möller–Trumbore without epsilon, as an independent reference for the triangle test.
fn moller_trumbore(ray: &Ray, [v0, v1, v2]: [Vec3; 3]) -> Option<(f32, f32, f32)> {
    let (e1, e2) = ((v1 - v0).as_dvec3(), (v2 - v0).as_dvec3());
    let d = ray.direction.as_dvec3();
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 {
        return None;
    }
    let s = (ray.origin - v0).as_dvec3();
    let u = s.dot(p) / det;
    let q = s.cross(e1);
    let v = d.dot(q) / det;
    let t = e2.dot(q) / det;
    (u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t > 0.0 && t < ray.tmax as f64)
        .then_some((t as f32, u as f32, v as f32))
}

#[test]
fn watertight_test_agrees_with_moller_trumbore() {
    let mut random = SplitMix64::new(6);
    let mut hits = 0;
    for _ in 0..20000 {
        let triangle = [(); 3].map(|_| random_point(&mut random, -1.0, 1.0));
        let origin = random_point(&mut random, -3.0, 3.0);
        let target = triangle[0]
            + random.range(-0.2, 1.0) * (triangle[1] - triangle[0])
            + random.range(-0.2, 1.0) * (triangle[2] - triangle[0]);
        let ray = Ray {
            origin,
            direction: target - origin,
            tmax: f32::INFINITY,
        };
        let normal = (triangle[1] - triangle[0]).cross(triangle[2] - triangle[0]);
        if normal.normalize().dot(ray.direction.normalize()).abs() < 1e-2 {
            // Nearly parallel: t is ill-conditioned for any method.
            continue;
        }
        let reference = moller_trumbore(&ray, triangle);
        let got = intersect_one(&ray, triangle);
        match (reference, got) {
            (Some((t0, u0, v0)), Some((t1, u1, v1))) => {
                hits += 1;
                assert!(
                    (t0 - t1).abs() <= 1e-4 * t0.max(1.0),
                    "t {t0} vs {t1}: {ray:?} {triangle:?}"
                );
                assert!((u0 - u1).abs() < 1e-3 && (v0 - v1).abs() < 1e-3);
            }
            (None, None) => {}
            (Some((_, u, v)), None) | (None, Some((_, u, v))) => {
                // Only rays grazing an edge may disagree.
                let margin = u.min(v).min(1.0 - u - v).abs();
                assert!(margin < 1e-4, "disagreement away from edges: {ray:?}");
            }
        }
    }
    assert!(hits > 5000, "{hits}");
}
