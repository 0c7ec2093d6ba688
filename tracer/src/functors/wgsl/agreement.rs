//! Every tracer functor's WGSL twin agrees with its Rust code: one table of
//! cases ([`cases`]), each the same input through `run_cpu` and through
//! [`run_functor_gpu`], compared element by element and field by field by
//! [`check`]. Inputs are realistic (camera rays of a small and a curved scene
//! and what the functors before a functor in the pipelines make of them, run on
//! the CPU) and edge cases (rays at triangle edges and vertices, dead rays,
//! misses, lights behind surfaces, NaN and infinite values, volume borders),
//! at sizes on both sides of a workgroup (64). Integers, bools and hit
//! triangles (`prim`) must agree exactly; floats within each case's stated
//! tolerance. Run with `--nocapture` for the largest differences measured.

use crate::camera::{Camera, CameraSetup};
use crate::functors::isosurface::{volume_uniforms, VolumeResources};
use crate::functors::test_support::{
    hit_column, ray, ray_column, read_surfaces, surface_column, Fixture,
};
use crate::functors::{RayRecord, SurfaceRecord};
use crate::mesh::TriangleMesh;
use crate::register_isosurface_functors;
use crate::scene::TraceScene;
use crate::shading::{Material, MeshMaterials, PointLight};
use crate::volume::Volume;
use dpp_gpu::agreement::{
    both_fail, cell_names, cell_text, compare_cells, Differences, Report, SplitMix64, Tolerance,
    Within,
};
use dpp_gpu::{gpu_for_tests, run_functor_gpu, GpuContext, GpuRunContext};
use dpp_runtime::column::Scalar as Cell;
use dpp_runtime::{
    CallContext, Column, FunctorError, FunctorLibrary, HostValue, TypePattern, Uniforms,
};
use glam::{UVec3, Vec3};
use std::any::Any;
use std::collections::BTreeSet;
use std::fmt::Write;
use std::sync::Arc;

// ---------------------------------------------------------------------------
// Tolerances

/// Relative 1e-5 (84 ULP), or absolute `abs` where cancellation leaves a
/// value near 0.
const fn within(abs: f32, why: &'static str) -> Within {
    Within {
        tolerance: Tolerance::Relative { rel: 1e-5, abs },
        why,
    }
}

// Why each tolerance: WGSL bounds `/` and `sqrt` to 2.5 ULP (the CPU rounds
// them correctly) and lets a compiler contract `a * b + c` into an `fma`, so
// a chain of a few such operations is a few ULP off, and a component that
// cancels to near 0 is that far off absolutely. (Lavapipe agrees in every bit
// on all of them but the transcendental functions.)
const CAMERA: Within = within(
    1e-6,
    "Camera::direction is + - * / and a normalize (sqrt, /): a few ULP of unit vectors",
);
const HIT: Within = within(
    1e-6,
    "t, u, v of the watertight test end in a / (2.5 ULP); barycentrics in [0, 1] near an edge cancel",
);
/// `HIT` where the GPU's division is correctly rounded. Where it is not,
/// the ray's shear (quotients of its direction) moves the sheared vertices by
/// an ulp, which the edge functions' cancellation amplifies in the
/// barycentrics: up to 2.0e-5 seen on an H100.
fn hit_tolerance(exact_division: bool) -> Within {
    if exact_division {
        HIT
    } else {
        within(
            1e-4,
            "t, u, v of the watertight test end in a / (2.5 ULP); the shear's / moves vertices by an ulp, which edge functions near an edge amplify",
        )
    }
}

const NORMAL: Within = within(
    1e-6,
    "a normalised (sqrt, /) cross product, * 0.5 + 0.5: a few ULP of 1",
);
const SURFACE: Within = within(
    1e-5,
    "barycentric sums of vertices up to 8 from the origin, normalize: a few ULP of 8",
);
const OFFSET: Within = within(
    1e-5,
    "position + epsilon * normal, a length and a / (a few ULP of positions up to 8); tmax = distance - epsilon",
);
const HEMISPHERE: Within = within(
    1e-5,
    "sin/cos of a hashed angle: WGSL promises only 2^-11 absolute; lavapipe is within 2.4e-7, 1e-5 leaves 40x room",
);
const SHADER: Within = Within {
    tolerance: Tolerance::Relative {
        rel: 1e-4,
        abs: 1e-6,
    },
    why: "pow(x, Ns) is exp2(Ns * log2(x)) in WGSL, log2 within 2^-21 absolutely: times Ns <= 100, 3.3e-5 relative",
};
const COLORMAP: Within = within(
    1e-6,
    "a lerp between table entries in [0, 1]: a GPU may fuse its multiply-adds, an ULP or two",
);
const SRGB: Within = within(
    1e-6,
    "pow(x, 1/2.4) = exp2(log2(x) / 2.4): log2's 2^-21 absolute over 2.4, a few ULP of exp2",
);
const MARCHING: Within = within(
    1e-5,
    "p0 + (p1 - p0) * t with t from a / (2.5 ULP) on positions up to 6, normalised gradients",
);
const MARCH: Within = Within {
    tolerance: Tolerance::Relative {
        rel: 1e-4,
        abs: 1e-5,
    },
    why: "slab divisions (2.5 ULP), trilinear sums and pow(1 - a, ratio) = exp2(ratio * log2(1 - a)) composited over a few samples",
};
const INTEGERS: Within = Within {
    tolerance: Tolerance::Exact,
    why: "integers, bools, and floats copied or from exact table lookups",
};
const DEAD: Within = Within {
    tolerance: Tolerance::Exact,
    why: "dead rays make misses: constants and copies",
};

// ---------------------------------------------------------------------------
// Where a case runs

/// A library with every tracer functor, the uniforms and resources of a run.
struct Env {
    name: &'static str,
    library: FunctorLibrary,
    uniforms: Uniforms,
    resources: Box<dyn Any + Send + Sync>,
}

impl Env {
    /// A fixture's scene, with `camera` in place of its own if given.
    fn trace(name: &'static str, mut fixture: Fixture, camera: Option<Camera>) -> Env {
        register_isosurface_functors(&mut fixture.library);
        if let Some(camera) = camera {
            fixture.resources.camera = Arc::new(CameraSetup::new(camera));
            fixture.uniforms = fixture.resources.uniforms();
        }
        Env {
            name,
            library: fixture.library,
            uniforms: fixture.uniforms,
            resources: Box::new(fixture.resources),
        }
    }

    fn volume(name: &'static str, volume: Volume) -> Env {
        let mut fixture = Fixture::new();
        register_isosurface_functors(&mut fixture.library);
        Env {
            name,
            library: fixture.library,
            uniforms: volume_uniforms(&volume),
            resources: Box::new(VolumeResources {
                volume: Arc::new(volume),
            }),
        }
    }

    fn trace_resources(&self) -> &crate::scene::TraceResources {
        self.resources
            .downcast_ref()
            .expect("a scene's environment")
    }

    /// Functor `name`'s Rust code over all of `inputs` at once (the first chunk).
    fn cpu(
        &self,
        name: &str,
        inputs: &[&Column],
        named: &[HostValue],
        group: usize,
    ) -> Result<Column, FunctorError> {
        let functor = self.library.get(name).unwrap();
        let signature = functor.signature();
        let mut values: Vec<HostValue> = named.to_vec();
        for param in &signature.named[named.len().min(signature.named.len())..] {
            values.push(param.default.expect("cases pass required parameters"));
        }
        let ctx = CallContext {
            named: &values,
            uniforms: &self.uniforms,
            resources: &*self.resources,
            first_index: 0,
            group,
            records: &self.library.records,
        };
        let mut outputs: Vec<Column> = signature
            .outputs
            .iter()
            .map(|output| match output.ty {
                TypePattern::Exact(ty) => Column::with_capacity(ty, 0, &self.library.records),
                TypePattern::Var(..) => unreachable!("tracer functors are monomorphic"),
            })
            .collect();
        let views: Vec<_> = inputs.iter().map(|c| c.view()).collect();
        functor.run_cpu(&ctx, &views, &mut outputs)?;
        Ok(outputs.swap_remove(0))
    }

    /// [`Env::cpu`] that must succeed: how cases make realistic inputs.
    fn make(&self, name: &str, inputs: &[&Column], named: &[HostValue], group: usize) -> Column {
        self.cpu(name, inputs, named, group)
            .unwrap_or_else(|e| panic!("{}: making the input with `{name}`: {e}", self.name))
    }

    fn gpu(
        &self,
        gpu: &GpuContext,
        name: &str,
        inputs: &[Column],
        named: &[HostValue],
        group: usize,
    ) -> Result<Column, String> {
        let context = GpuRunContext {
            gpu,
            library: &self.library,
            uniforms: &self.uniforms,
            resources: &*self.resources,
            profile: false,
        };
        run_functor_gpu(&context, name, inputs, named, group).map_err(|e| e.message)
    }

    fn rays(&self, rays: &[RayRecord]) -> Column {
        ray_column(&self.library.records, rays)
    }

    fn surfaces(&self, surfaces: &[SurfaceRecord]) -> Column {
        surface_column(&self.library.records, surfaces)
    }

    fn hits(&self, hits: &[(f32, u32, f32, f32)]) -> Column {
        hit_column(&self.library.records, hits)
    }
}

// ---------------------------------------------------------------------------
// Cases

/// What a case expects of the two backends.
#[derive(Clone, Copy, Debug)]
enum Expect {
    /// Floats `within`; a `Hit` output's `prim` equal on at least the
    /// fraction `prims` of the elements (the other fields of those are not
    /// compared), or with `edge_ties` another triangle at the same `t` (a ray
    /// on an edge both triangles share); everything else exactly.
    Agree {
        within: Within,
        prims: f64,
        edge_ties: bool,
    },
    /// Both fail, with messages that contain this text.
    Fail(&'static str),
}

/// A row of the table: functor `functor` over `inputs` in `env`.
struct Case<'e> {
    what: String,
    env: &'e Env,
    functor: &'static str,
    inputs: Vec<Column>,
    named: Vec<HostValue>,
    /// `k` of a gather's group or a scatter's fanout (1 for a map).
    group: usize,
    expect: Expect,
}

/// A case whose every float must be `within`, and `prim` exact.
fn agree<'e>(
    env: &'e Env,
    functor: &'static str,
    what: &str,
    inputs: &[&Column],
    named: &[HostValue],
    group: usize,
    within: Within,
) -> Case<'e> {
    Case {
        what: what.to_string(),
        env,
        functor,
        inputs: inputs.iter().map(|c| (*c).clone()).collect(),
        named: named.to_vec(),
        group,
        expect: Expect::Agree {
            within,
            prims: 1.0,
            edge_ties: false,
        },
    }
}

/// A case both backends must refuse with `text` in their messages.
fn fails<'e>(
    env: &'e Env,
    functor: &'static str,
    what: &str,
    inputs: &[&Column],
    named: &[HostValue],
    group: usize,
    text: &'static str,
) -> Case<'e> {
    Case {
        what: what.to_string(),
        env,
        functor,
        inputs: inputs.iter().map(|c| (*c).clone()).collect(),
        named: named.to_vec(),
        group,
        expect: Expect::Fail(text),
    }
}

/// The environments of the cases.
struct Envs {
    /// The fixture: two squares (z = 0 and z = -1), its 4×3 camera.
    simple: Env,
    /// The same squares seen by a 40×30 camera that also sees past them.
    wide: Env,
    /// The built-in mixing layer (curved, smooth normals, scalars) over a
    /// mirror floor, a third of its triangles reflective, four lights (one
    /// below everything), a 48×32 camera at an angle.
    curved: Env,
    /// A distance field on an anisotropic, offset grid, cut by its border; a
    /// brick (`first` not zero).
    sphere: Env,
    /// Small integers (levels hit samples exactly), a NaN and an infinity.
    integers: Env,
    /// Two samples thick: every cell on the border.
    thin: Env,
    /// The fixture's squares as a part of a larger data set: a global id table.
    part: Env,
    /// A distance field to volume-render: an anisotropic brick (`first` not
    /// zero), a 24×18 camera that sees past it, a transfer function
    /// transparent below the low end of its scalar range.
    render: Env,
}

fn envs() -> Envs {
    let wide_camera = Camera::new(
        Vec3::new(0.3, -0.2, 2.5),
        Vec3::new(0.0, 0.0, -0.5),
        Vec3::Y,
        100.0,
        40,
        30,
    )
    .unwrap();
    Envs {
        simple: Env::trace("simple", Fixture::new(), None),
        part: {
            let scene = (*Fixture::new().resources.scene).clone();
            let ids = Arc::new(vec![4_000_000_000, 17, 0, 123_456]);
            let scene = scene.with_global_ids(ids).unwrap();
            Env::trace("part", Fixture::with_scene(scene), None)
        },
        wide: Env::trace("wide", Fixture::new(), Some(wide_camera)),
        curved: curved_env(),
        sphere: Env::volume("sphere", {
            let mut v = Volume::from_fn(
                UVec3::new(9, 8, 7),
                Vec3::new(-1.1, 0.3, 2.0),
                Vec3::new(0.25, 0.3, 0.35),
                |p, _| (p - Vec3::new(-0.2, 1.3, 3.2)).length(),
            );
            // A brick of a larger volume: positions from global indices.
            v.first = UVec3::new(3, 1, 2);
            v
        }),
        integers: Env::volume("integers", {
            let mut v = Volume::from_fn(UVec3::new(7, 6, 5), Vec3::ZERO, Vec3::ONE, |_, s| {
                ((s.x * 7 + s.y * 3 + s.z * 5) % 11) as f32
            });
            v.values[40] = f32::NAN;
            v.values[77] = f32::INFINITY;
            v
        }),
        render: render_env(),
        thin: Env::volume(
            "thin",
            Volume::from_fn(
                UVec3::new(6, 2, 5),
                Vec3::new(1.0, -2.0, 0.5),
                Vec3::new(0.5, 2.0, 0.125),
                |p, _| p.x * p.x - p.y + 3.0 * p.z,
            ),
        ),
    }
}

/// See [`Envs::render`].
fn render_env() -> Env {
    let mut fixture = Fixture::new();
    let mut volume = Volume::from_fn(
        UVec3::new(9, 8, 7),
        Vec3::new(-1.0, -1.0, -1.0),
        Vec3::new(0.25, 0.3, 0.35),
        |p, _| (p - Vec3::new(0.2, 0.1, 0.6)).length(),
    );
    volume.first = UVec3::new(1, 0, 2);
    fixture.resources.volume = Some(Arc::new(volume));
    fixture.set_shading(|shading| {
        shading.set_colormap("cool-to-warm").unwrap();
        shading.set_scalar_range(0.3, 1.2).unwrap();
    });
    let camera = Camera::new(
        Vec3::new(0.3, 0.2, 5.0),
        Vec3::new(0.25, 0.05, 0.75),
        Vec3::Y,
        40.0,
        24,
        18,
    )
    .unwrap();
    Env::trace("render", fixture, Some(camera))
}

/// See [`Envs::curved`].
fn curved_env() -> Env {
    let mut mesh = crate::builtin_scene::builtin_scene(16).unwrap();
    let bounds = mesh.bounds().unwrap();
    let (center, diagonal) = (bounds.center(), bounds.diagonal());
    let layer = mesh.triangles.len();
    let first = mesh.positions.len() as u32;
    let floor = bounds.min.z - 0.05 * diagonal;
    for (x, y) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
        let corner = Vec3::new(center.x + x * diagonal, center.y + y * diagonal, floor);
        mesh.positions.push(corner);
        mesh.normals.as_mut().unwrap().push(Vec3::Z);
        mesh.scalars.as_mut().unwrap().push(0.0);
    }
    mesh.triangles.push([first, first + 1, first + 2]);
    mesh.triangles.push([first, first + 2, first + 3]);
    let mirror = Material {
        ks: Vec3::splat(0.5),
        ns: 100.0,
        reflectivity: 0.6,
        ..Material::named("mirror")
    };
    // Ns = 0: the specular term is 1 wherever the light is in front.
    let chrome = Material {
        ns: 0.0,
        reflectivity: 1.0,
        ..Material::named("chrome")
    };
    let materials = MeshMaterials {
        materials: vec![Material::named("default"), mirror, chrome],
        triangle_materials: (0..mesh.triangles.len())
            .map(|t| match t {
                t if t >= layer => 1,
                t if t % 3 == 0 => 1,
                t if t % 7 == 0 => 2,
                _ => 0,
            })
            .collect(),
    };
    let mut fixture = Fixture::with_scene(TraceScene::with_materials(mesh, materials).unwrap());
    let lights = vec![
        PointLight::new(center + diagonal * Vec3::new(-0.3, 0.6, 0.6), 1.5),
        // Below the floor: behind every surface the camera sees.
        PointLight::new(center + diagonal * Vec3::new(0.1, 0.0, -0.8), 1.0),
        // Level with the layer: grazing.
        PointLight::new(center + diagonal * Vec3::new(1.0, 0.0, 0.02), 0.7),
        PointLight {
            position: center + diagonal * Vec3::new(0.0, 0.1, 0.05),
            intensity: 0.3,
            color: Vec3::new(0.2, 0.5, 1.0),
        },
    ];
    fixture.set_shading(|shading| shading.set_lights(lights).unwrap());
    let camera = Camera::new(
        center + diagonal * Vec3::new(0.15, -0.55, 0.75),
        center,
        Vec3::Y,
        50.0,
        48,
        32,
    )
    .unwrap();
    Env::trace("curved", fixture, Some(camera))
}

/// A unit vector, roughly uniform.
fn direction(rng: &mut SplitMix64) -> Vec3 {
    loop {
        let v = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - 1.0;
        if (0.01..=1.0).contains(&v.length_squared()) {
            return v.normalize();
        }
    }
}

fn iota(n: usize) -> Column {
    Column::U32((0..n as u32).collect())
}

fn int(x: i64) -> HostValue {
    HostValue::Int(x)
}

fn float(x: f64) -> HostValue {
    HostValue::Float(x)
}

/// Rays of the fixture's squares at their vertices and edges (the small
/// square's diagonal is the edge its two triangles share), each straight down,
/// from the camera's eye, from below and obliquely; then rays that graze,
/// start on a surface, end exactly at a hit, have odd directions, or are dead.
///
/// Without `exact_division` (a GPU whose f32 division is not correctly
/// rounded, as WGSL allows), rays aimed exactly at the squares' outer border
/// are left out: whether such a ray hits an open mesh's border edge turns on
/// the last bit of the ray's shear, a quotient. (Inner edges stay: there a
/// ray hits one of the two triangles whatever the rounding, see
/// `rays_at_a_closed_meshs_vertices_and_edges_all_hit_on_the_gpu`.)
fn edge_rays(exact_division: bool) -> Vec<RayRecord> {
    let mut points = Vec::new();
    for (z, half) in [(0.0, 1.0), (-1.0, 5.0)] {
        for (x, y) in [
            (-1.0, -1.0),
            (1.0, -1.0),
            (1.0, 1.0),
            (-1.0, 1.0),
            (0.0, -1.0),
            (1.0, 0.0),
            (0.0, 1.0),
            (-1.0, 0.0),
            (0.0, 0.0),
            (0.5, 0.5),
            (-0.5, -0.5),
            (0.25, 0.25),
            (0.1, 0.1 + f32::EPSILON),
        ] {
            let on_border = f32::abs(x) == 1.0 || f32::abs(y) == 1.0;
            if exact_division || !on_border {
                points.push(Vec3::new(x * half, y * half, z));
            }
        }
    }
    if exact_division {
        // Just inside and just outside the small square's right edge.
        points.push(Vec3::new(1.0 - f32::EPSILON / 2.0, 0.3, 0.0));
        points.push(Vec3::new(1.0 + f32::EPSILON, 0.3, 0.0));
    }
    let eye = Vec3::new(0.0, 0.0, 2.0);
    let mut rays = Vec::new();
    for p in points {
        let below = p + Vec3::new(0.1, 0.2, -3.0);
        let oblique = Vec3::new(3.0, -2.0, 4.0);
        rays.push(ray(p + 2.0 * Vec3::Z, Vec3::NEG_Z, f32::INFINITY, 0));
        rays.push(ray(eye, (p - eye).normalize(), f32::INFINITY, 0));
        rays.push(ray(below, (p - below).normalize(), f32::INFINITY, 0));
        rays.push(ray(oblique, p - oblique, f32::INFINITY, 0));
    }
    let down = Vec3::new(0.25, 0.5, 2.0);
    let next_up = |x: f32| f32::from_bits(x.to_bits() + 1);
    rays.extend([
        // In the planes of the squares.
        ray(Vec3::new(-3.0, 0.5, 0.0), Vec3::X, f32::INFINITY, 0),
        ray(Vec3::new(-7.0, 0.5, -1.0), Vec3::X, f32::INFINITY, 0),
        // On the small square, going down: its own t = 0 does not count.
        ray(Vec3::new(0.2, 0.3, 0.0), Vec3::NEG_Z, f32::INFINITY, 0),
        // tmax exactly the hit distance (2), one ULP past it, short of the big square.
        ray(down, Vec3::NEG_Z, 2.0, 0),
        ray(down, Vec3::NEG_Z, next_up(2.0), 0),
        ray(down, Vec3::NEG_Z, 2.999_999_8, 0),
        ray(down, Vec3::NEG_Z, f32::from_bits(1), 0),
        ray(down, Vec3::NEG_Z, f32::MIN_POSITIVE, 0),
        ray(down, Vec3::NEG_Z, f32::MAX, 0),
        // Dead.
        ray(down, Vec3::NEG_Z, 0.0, 0),
        ray(down, Vec3::NEG_Z, -0.0, 0),
        ray(down, Vec3::NEG_Z, -1.0, 0),
        ray(down, Vec3::NEG_Z, f32::NAN, 0),
        ray(down, Vec3::NEG_Z, f32::NEG_INFINITY, 0),
        RayRecord::dead(7, 2),
        // Odd directions: zero, negative zeros, not unit, tiny components.
        ray(down, Vec3::ZERO, f32::INFINITY, 0),
        ray(down, Vec3::new(-0.0, -0.0, -1.0), f32::INFINITY, 0),
        ray(down, Vec3::new(0.0, 0.0, -10.0), f32::INFINITY, 0),
        ray(down, Vec3::new(1e-30, -1e-30, -1.0), f32::INFINITY, 0),
        // Origins on a bounding box's planes (0 * inf in the slab test), far away, between the squares.
        ray(Vec3::new(1.0, 0.5, 2.0), Vec3::NEG_Z, f32::INFINITY, 0),
        ray(Vec3::new(1.0, 1.0, 2.0), Vec3::NEG_Z, f32::INFINITY, 0),
        ray(Vec3::new(-5.0, 5.0, 2.0), Vec3::NEG_Z, f32::INFINITY, 0),
        ray(Vec3::new(0.0, 0.0, 1e6), Vec3::NEG_Z, f32::INFINITY, 0),
        ray(Vec3::new(0.0, 0.0, -0.5), Vec3::Z, f32::INFINITY, 0),
        // Not finite.
        ray(Vec3::new(f32::NAN, 0.5, 2.0), Vec3::NEG_Z, f32::INFINITY, 0),
        ray(
            Vec3::new(0.5, 0.5, f32::INFINITY),
            Vec3::NEG_Z,
            f32::INFINITY,
            0,
        ),
        ray(down, Vec3::new(f32::NAN, 0.0, -1.0), f32::INFINITY, 0),
        ray(down, Vec3::new(0.0, f32::INFINITY, -1.0), f32::INFINITY, 0),
        // Away from everything.
        ray(down, Vec3::Z, f32::INFINITY, 0),
        ray(Vec3::new(20.0, 0.0, 2.0), Vec3::NEG_Z, f32::INFINITY, 0),
    ]);
    for (i, ray) in rays.iter_mut().enumerate() {
        ray.sample = i as u32;
    }
    rays
}

/// Surfaces of every kind the shading functors can get, around `env`'s
/// scene: hits with normals facing the viewer or not, leaning away from the
/// geometric normal, exactly ±z (the sign of -0 picks the frame), at a light,
/// with NaN or infinite scalars, every material, depths up to `u32::MAX`;
/// and misses.
fn synthetic_surfaces(env: &Env, rng: &mut SplitMix64) -> Vec<SurfaceRecord> {
    let resources = env.trace_resources();
    let (center, diagonal) = (
        resources.scene.bounds.center(),
        resources.scene.bounds.diagonal(),
    );
    let lights = resources.shading.lights();
    let materials = resources.shading.materials().len() as u32;
    let normals = [
        Vec3::Z,
        Vec3::NEG_Z,
        Vec3::new(1.0, 0.0, -0.0),
        Vec3::new(0.0, 0.0, -0.0) + Vec3::NEG_Z,
        Vec3::new(1.0, 0.0, 0.1).normalize(),
        Vec3::new(-0.3, 0.4, 0.866).normalize(),
        Vec3::new(0.6, 0.0, -0.8),
    ];
    let geometrics = [Vec3::Z, Vec3::NEG_Z, Vec3::new(0.2, 0.1, 1.0).normalize()];
    let scalars = [0.0, -1.0, 1.0, 0.3, -7.0, 7.0, f32::NAN, f32::INFINITY];
    let depths = [0, 0, 1, 2, 3, u32::MAX];
    let mut surfaces = Vec::new();
    for i in 0..150 {
        let position = match i % 10 {
            // At a light.
            9 => lights[i / 10 % lights.len()].position,
            _ => {
                center
                    + diagonal
                        * 0.5
                        * Vec3::new(
                            rng.next_f32() - 0.5,
                            rng.next_f32() - 0.5,
                            rng.next_f32() - 0.5,
                        )
            }
        };
        let normal = normals[i % normals.len()];
        let geometric = geometrics[i / normals.len() % geometrics.len()];
        let view = if i % 3 == 0 {
            direction(rng)
        } else {
            (position - normal).normalize()
        };
        surfaces.push(SurfaceRecord {
            position,
            normal,
            view: if i % 5 == 0 { normal } else { view },
            scalar: rng.pick(&scalars),
            material: i as u32 % materials,
            hit: i % 11 != 4,
            sample: rng.next_u32(),
            weight: Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 1.5,
            depth: rng.pick(&depths),
            geometric,
        });
    }
    surfaces.push(SurfaceRecord::miss(3, Vec3::splat(0.5), 2));
    surfaces
}

/// Floats an encoder must map: out of range, NaN, infinities, the sRGB
/// linear limit and its neighbours, subnormals, 1 and its neighbours.
const COLOR_VALUES: [f32; 17] = [
    0.0,
    -0.0,
    1.0,
    0.5,
    1.5,
    -0.5,
    f32::NAN,
    f32::INFINITY,
    f32::NEG_INFINITY,
    0.003_130_8,
    0.003_130_9,
    0.003_130_7,
    1e-40,
    0.999_999_94,
    1.000_000_1,
    0.2,
    0.7,
];

fn colors(rng: &mut SplitMix64, n: usize) -> Column {
    Column::Vec3(
        (0..n)
            .map(|i| match i % 3 {
                0 => Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()),
                _ => Vec3::new(
                    rng.pick(&COLOR_VALUES),
                    rng.pick(&COLOR_VALUES),
                    rng.pick(&COLOR_VALUES),
                ),
            })
            .collect(),
    )
}

/// The cells of `env`'s volume with their triangle lanes, as the isosurface
/// pipeline expands them: `(cells, lanes)`.
fn triangle_lanes(env: &Env, level: f32) -> (Column, Column) {
    let volume = &env
        .resources
        .downcast_ref::<VolumeResources>()
        .unwrap()
        .volume;
    let all = iota(volume.cell_count() as usize);
    let cases = env.make("cubeCase", &[&all], &[float(level.into())], 1);
    let counts = env.make("caseTriangles", &[&cases], &[], 1);
    let (mut cells, mut lanes) = (Vec::new(), Vec::new());
    for (cell, &count) in counts.view().as_u32().iter().enumerate() {
        for lane in 0..count {
            cells.push(cell as u32);
            lanes.push(lane);
        }
    }
    (Column::U32(cells), Column::U32(lanes))
}

/// The table: every tracer functor on realistic and edge-case inputs.
/// The cases; see [`edge_rays`] and [`hit_tolerance`] for `exact_division`.
fn cases(envs: &Envs, exact_division: bool) -> Vec<Case<'_>> {
    let (simple, wide, curved) = (&envs.simple, &envs.wide, &envs.curved);
    let mut rng = SplitMix64::new(0x5eed);
    let mut cases = Vec::new();
    let pixels = |env: &Env| env.trace_resources().camera.camera.pixels() as usize;
    let lights = |env: &Env| env.trace_resources().shading.lights().len();

    // cameraRay: every pixel of three cameras (12, 1200, 1536 pixels), 1 and 4 spp.
    for env in [simple, wide, curved] {
        for spp in [1, 4] {
            cases.push(agree(
                env,
                "cameraRay",
                &format!("every pixel, spp {spp}"),
                &[&iota(pixels(env) * spp as usize)],
                &[int(spp)],
                1,
                CAMERA,
            ));
        }
    }
    cases.push(fails(
        simple,
        "cameraRay",
        "spp 2",
        &[&iota(4)],
        &[int(2)],
        1,
        "spp must be 1 or 4",
    ));
    cases.push(fails(
        simple,
        "cameraRay",
        "one index past the last ray",
        &[&Column::U32(vec![3, 48])],
        &[int(4)],
        1,
        "out of range",
    ));

    // The pipeline on the fixture and the wide camera: camera rays, hits,
    // surfaces, shadow rays.
    let edges = simple.rays(&edge_rays(exact_division));
    let hit = hit_tolerance(exact_division);
    let edge_hits = simple.make("intersect", &[&edges], &[], 1);
    let mut simple_rays = Vec::new();
    for (env, spp) in [(simple, 1), (simple, 4), (wide, 4)] {
        let rays = env.make(
            "cameraRay",
            &[&iota(pixels(env) * spp)],
            &[int(spp as i64)],
            1,
        );
        let hits = env.make("intersect", &[&rays], &[], 1);
        simple_rays.push((env, format!("camera rays, spp {spp}"), rays, hits));
    }
    simple_rays.push((simple, "edge and odd rays".into(), edges.clone(), edge_hits));

    for (env, what, rays, hits) in &simple_rays {
        let mut intersect = agree(env, "intersect", what, &[rays], &[], 1, hit);
        if let Expect::Agree { edge_ties, .. } = &mut intersect.expect {
            // The ray's shear rounds otherwise: on a shared edge, either side.
            *edge_ties = !exact_division;
        }
        cases.push(intersect);
        cases.push(agree(env, "occluded", what, &[rays], &[], 1, INTEGERS));
        cases.push(agree(
            env,
            "normalColor",
            what,
            &[rays, hits],
            &[],
            1,
            NORMAL,
        ));
        cases.push(agree(env, "surface", what, &[rays, hits], &[], 1, SURFACE));
        let surfaces = env.make("surface", &[rays, hits], &[], 1);
        let shadow = env.make("shadowRay", &[&surfaces], &[], lights(env));
        cases.push(agree(
            env,
            "shadowRay",
            what,
            &[&surfaces],
            &[],
            lights(env),
            OFFSET,
        ));
        cases.push(agree(
            env,
            "occluded",
            &format!("shadow rays of {what}"),
            &[&shadow],
            &[],
            1,
            INTEGERS,
        ));
        let blocked = env.make("occluded", &[&shadow], &[], 1);
        cases.push(agree(
            env,
            "visibleLights",
            &format!("shadow rays of {what}"),
            &[&blocked],
            &[],
            lights(env),
            INTEGERS,
        ));
    }
    // Rays that end short of the big square, or just past the small one.
    let mut short = crate::functors::test_support::read_rays(&simple_rays[2].2);
    for (i, ray) in short.iter_mut().enumerate() {
        ray.tmax = [2.5, 3.5, 2.0, 1.0][i % 4] * ray.tmax.min(1.0);
    }
    cases.push(agree(
        wide,
        "occluded",
        "camera rays with tmax 1 to 3.5",
        &[&wide.rays(&short)],
        &[],
        1,
        INTEGERS,
    ));
    cases.push(fails(
        simple,
        "surface",
        "a hit on triangle 4 of 4",
        &[
            &simple.rays(&edge_rays(true)[..1]),
            &simple.hits(&[(2.0, 4, 0.25, 0.25)]),
        ],
        &[],
        1,
        "triangle",
    ));
    cases.push(fails(
        simple,
        "normalColor",
        "a hit on triangle 4 of 4",
        &[
            &simple.rays(&edge_rays(true)[..1]),
            &simple.hits(&[(2.0, 4, 0.25, 0.25)]),
        ],
        &[],
        1,
        "triangle",
    ));
    // Dead rays with hits (a surface must ignore the hit).
    let dead: Vec<RayRecord> = (0..70)
        .map(|i| RayRecord {
            tmax: [0.0, -0.0, -1.0, f32::NAN][i % 4],
            ..edge_rays(true)[i]
        })
        .collect();
    let dead_hits: Vec<(f32, u32, f32, f32)> =
        (0..70).map(|i| (1.0, (i % 4) as u32, 0.25, 0.5)).collect();
    cases.push(agree(
        simple,
        "surface",
        "dead rays with hits",
        &[&simple.rays(&dead), &simple.hits(&dead_hits)],
        &[],
        1,
        DEAD,
    ));

    // The pipeline on the curved scene: camera rays (4 spp), hits, surfaces,
    // shadow and occlusion rays, shading, reflections and their hits.
    let n = pixels(curved) * 4;
    let k = lights(curved);
    let rays = curved.make("cameraRay", &[&iota(n)], &[int(4)], 1);
    let hits = curved.make("intersect", &[&rays], &[], 1);
    let surfaces = curved.make("surface", &[&rays, &hits], &[], 1);
    let shadow = curved.make("shadowRay", &[&surfaces], &[], k);
    let blocked = curved.make("occluded", &[&shadow], &[], 1);
    let mask = curved.make("visibleLights", &[&blocked], &[], k);
    let ao = curved.make("occRayGen", &[&surfaces], &[], 4);
    let ao_blocked = curved.make("occluded", &[&ao], &[], 1);
    let occlusion = Column::F32(
        ao_blocked
            .view()
            .as_bool()
            .chunks(4)
            .map(|g| g.iter().filter(|b| **b).count() as f32 / 4.0)
            .collect(),
    );
    let rgb = curved.make("shader", &[&surfaces, &occlusion, &mask], &[], 1);
    let bounce = curved.make("reflectRay", &[&surfaces], &[], 1);
    let bounce_hits = curved.make("intersect", &[&bounce], &[], 1);
    let bounce_surfaces = curved.make("surface", &[&bounce, &bounce_hits], &[], 1);
    let hit_ratio = |hits: &Column| {
        let prims = hits.view().field(1).as_u32().to_vec();
        prims.iter().filter(|p| **p != u32::MAX).count() as f32 / prims.len() as f32
    };
    eprintln!(
        "curved scene: {} triangles in {:?}, camera rays hit {:.0}%, reflections {:.0}%",
        curved.trace_resources().scene.mesh.triangles.len(),
        curved.trace_resources().scene.bounds,
        100.0 * hit_ratio(&hits),
        100.0 * hit_ratio(&bounce_hits)
    );
    let curved_hits = |what: &str, rays: &Column| Case {
        what: what.to_string(),
        env: curved,
        functor: "intersect",
        inputs: vec![rays.clone()],
        named: vec![],
        group: 1,
        expect: Expect::Agree {
            within: hit,
            // A curved mesh's shared edges are where rounding can send a
            // ray to the neighbouring triangle.
            prims: 0.999,
            edge_ties: !exact_division,
        },
    };
    cases.push(curved_hits("camera rays, spp 4", &rays));
    cases.push(curved_hits("reflection rays (dead ones too)", &bounce));
    cases.push(curved_hits("occlusion rays", &ao));
    for (what, rays) in [
        ("shadow rays", &shadow),
        ("occlusion rays", &ao),
        ("reflection rays", &bounce),
    ] {
        cases.push(agree(curved, "occluded", what, &[rays], &[], 1, INTEGERS));
    }
    for (what, rays) in [
        ("camera rays, spp 4", &rays),
        ("shadow rays", &shadow),
        ("occlusion rays", &ao),
        ("reflection rays, live and dead", &bounce),
    ] {
        cases.push(agree(
            curved,
            "rayOrderKey",
            what,
            &[rays],
            &[],
            1,
            INTEGERS,
        ));
    }
    for (what, rays, hits) in [
        ("camera rays", &rays, &hits),
        ("reflection rays", &bounce, &bounce_hits),
    ] {
        cases.push(agree(
            curved,
            "normalColor",
            what,
            &[rays, hits],
            &[],
            1,
            NORMAL,
        ));
        cases.push(agree(
            curved,
            "surface",
            what,
            &[rays, hits],
            &[],
            1,
            SURFACE,
        ));
    }
    cases.push(agree(
        curved,
        "shadowRay",
        "surfaces of camera rays, 4 lights (one behind)",
        &[&surfaces],
        &[],
        k,
        OFFSET,
    ));
    cases.push(agree(
        curved,
        "visibleLights",
        "shadow rays of camera rays",
        &[&blocked],
        &[],
        k,
        INTEGERS,
    ));
    for (fanout, range) in [(4, 0.05), (1, 0.2), (3, 0.0), (2, -1.0)] {
        cases.push(agree(
            curved,
            "occRayGen",
            &format!("surfaces of camera rays, range {range}"),
            &[&surfaces],
            &[float(range)],
            fanout,
            HEMISPHERE,
        ));
    }
    cases.push(agree(
        curved,
        "occRayGen",
        "surfaces of reflection rays",
        &[&bounce_surfaces],
        &[],
        4,
        HEMISPHERE,
    ));
    for named in [
        vec![],
        vec![float(0.4), float(0.0)],
        vec![float(0.0), float(25.0)],
    ] {
        cases.push(agree(
            curved,
            "shader",
            &format!("surfaces of camera rays, {named:?}"),
            &[&surfaces, &occlusion, &mask],
            &named,
            1,
            SHADER,
        ));
    }
    for max_depth in [3, 1, 2, 10] {
        for (what, surfaces) in [
            ("camera rays", &surfaces),
            ("reflection rays", &bounce_surfaces),
        ] {
            cases.push(agree(
                curved,
                "reflectRay",
                &format!("surfaces of {what}, maxDepth {max_depth}"),
                &[surfaces],
                &[int(max_depth)],
                1,
                OFFSET,
            ));
        }
    }
    let new_weights = Column::Vec3(
        (0..bounce.len())
            .map(|_| Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()))
            .collect(),
    );
    cases.push(agree(
        curved,
        "withWeight",
        "reflection rays, live and dead",
        &[&bounce, &new_weights],
        &[],
        1,
        INTEGERS,
    ));
    let ends = Column::F32(
        (0..bounce.len())
            .map(|i| match i % 4 {
                0 => f32::INFINITY,
                1 => f32::NAN,
                _ => rng.next_f32() * 4.0,
            })
            .collect(),
    );
    cases.push(agree(
        curved,
        "clipRay",
        "reflection rays, live and dead",
        &[&bounce, &ends],
        &[],
        1,
        INTEGERS,
    ));
    cases.push(agree(
        curved,
        "alive",
        "reflection rays",
        &[&bounce],
        &[],
        1,
        INTEGERS,
    ));
    for spp in [4, 1] {
        cases.push(agree(
            curved,
            "antiAlias",
            &format!("shaded camera rays, group {spp}"),
            &[&rgb],
            &[],
            spp,
            SRGB,
        ));
    }

    // Synthetic surfaces in the curved scene.
    let synthetic = curved.surfaces(&synthetic_surfaces(curved, &mut rng));
    let m = read_surfaces(&synthetic).len();
    let occlusion_values = [0.0, 0.25, 1.0, -0.5, 1.5, f32::NAN, 0.75];
    let synthetic_occlusion = Column::F32((0..m).map(|_| rng.pick(&occlusion_values)).collect());
    let synthetic_mask = Column::U32(
        (0..m)
            .map(|i| match i % 4 {
                0 => u32::MAX,
                1 => 0,
                _ => rng.next_u32(),
            })
            .collect(),
    );
    cases.push(agree(
        curved,
        "shader",
        "synthetic surfaces",
        &[&synthetic, &synthetic_occlusion, &synthetic_mask],
        &[],
        1,
        SHADER,
    ));
    // The shading tables a pipeline reads to write its own shading model.
    let synthetic_scalars = Column::F32(
        (0..m)
            .map(|i| match i % 7 {
                0 => f32::NAN,
                1 => -1.0e30,
                2 => 1.0e30,
                _ => rng.next_f32() * 2.0 - 0.5,
            })
            .collect(),
    );
    cases.push(agree(
        curved,
        "colormap",
        "scalars in and beyond the range",
        &[&synthetic_scalars],
        &[],
        1,
        COLORMAP,
    ));
    let lights = curved.trace_resources().shading.lights().len() as u32;
    cases.push(agree(
        curved,
        "light",
        "every light",
        &[&Column::U32((0..3 * lights).map(|i| i % lights).collect())],
        &[],
        1,
        INTEGERS,
    ));
    let materials = curved.trace_resources().shading.materials().len() as u32;
    cases.push(agree(
        curved,
        "material",
        "every material",
        &[&Column::U32(
            (0..3 * materials).map(|i| i % materials).collect(),
        )],
        &[],
        1,
        INTEGERS,
    ));
    cases.push(fails(
        curved,
        "light",
        "an index past the lights",
        &[&Column::U32(vec![0, lights])],
        &[],
        1,
        "light",
    ));
    cases.push(fails(
        curved,
        "material",
        "an id past the materials",
        &[&Column::U32(vec![0, materials])],
        &[],
        1,
        "material",
    ));
    cases.push(agree(
        curved,
        "shadowRay",
        "synthetic surfaces",
        &[&synthetic],
        &[],
        k,
        OFFSET,
    ));
    cases.push(agree(
        curved,
        "occRayGen",
        "synthetic surfaces",
        &[&synthetic],
        &[float(0.1)],
        4,
        HEMISPHERE,
    ));
    for max_depth in [3, 0, i64::from(i32::MAX)] {
        cases.push(agree(
            curved,
            "reflectRay",
            &format!("synthetic surfaces, maxDepth {max_depth}"),
            &[&synthetic],
            &[int(max_depth)],
            1,
            OFFSET,
        ));
    }
    let unknown_material = curved.surfaces(&[SurfaceRecord {
        material: 3,
        hit: true,
        depth: 0,
        ..read_surfaces(&synthetic)[0]
    }]);
    let (no_occlusion, one_light) = (Column::F32(vec![0.0]), Column::U32(vec![1]));
    for (functor, inputs) in [
        (
            "shader",
            &[&unknown_material, &no_occlusion, &one_light][..],
        ),
        ("reflectRay", &[&unknown_material][..]),
    ] {
        cases.push(fails(
            curved,
            functor,
            "material 3 of 3",
            inputs,
            &[],
            1,
            "material",
        ));
    }
    cases.push(fails(
        curved,
        "shadowRay",
        "fanout 3 for 4 lights",
        &[&synthetic],
        &[],
        3,
        "fanout",
    ));
    cases.push(fails(
        curved,
        "occRayGen",
        "range NaN",
        &[&synthetic],
        &[float(f64::NAN)],
        2,
        "range must be a finite number",
    ));

    // Flags and colours.
    let tmax_values = [
        0.0,
        -0.0,
        1.0,
        -1.0,
        f32::NAN,
        f32::from_bits(0xffc0_0000),
        f32::from_bits(0x7f80_0001),
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::from_bits(1),
        f32::from_bits(0x8000_0001),
        f32::MIN_POSITIVE,
        f32::MAX,
    ];
    let odd_rays: Vec<RayRecord> = (0..100)
        .map(|i| {
            ray(
                Vec3::ZERO,
                Vec3::Z,
                tmax_values[i % tmax_values.len()],
                i as u32,
            )
        })
        .collect();
    let prims = Column::U32(
        (0..200u32)
            .map(|i| match i % 5 {
                4 => crate::MISS_PRIM,
                _ => i % 4,
            })
            .collect(),
    );
    for env in [simple, &envs.part] {
        cases.push(agree(
            env,
            "globalId",
            "every triangle and misses",
            &[&prims],
            &[],
            1,
            INTEGERS,
        ));
    }
    cases.push(fails(
        &envs.part,
        "globalId",
        "a triangle past the table",
        &[&Column::U32(vec![0, 4])],
        &[],
        1,
        "triangle",
    ));
    cases.push(agree(
        simple,
        "alive",
        "every kind of tmax",
        &[&simple.rays(&odd_rays)],
        &[],
        1,
        INTEGERS,
    ));
    cases.push(agree(
        simple,
        "rayOrderKey",
        "every kind of tmax",
        &[&simple.rays(&odd_rays)],
        &[],
        1,
        INTEGERS,
    ));
    // Origins on cell boundaries of the 10 × 10 × 1 box (cells of 1/32),
    // outside it and not finite; directions with signed zeros and NaNs.
    let odd_values = [
        -5.0,
        -5.0 + 1.0 / 32.0,
        -1.0 / 64.0,
        0.0,
        -0.0,
        4.999,
        5.0,
        1e30,
        -1e30,
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
    ];
    let odd_origins: Vec<RayRecord> = (0..300)
        .map(|i| {
            let mut pick = || rng.pick(&odd_values);
            let origin = Vec3::new(pick(), pick(), pick());
            let dir = Vec3::new(pick(), pick(), pick());
            ray(origin, dir, 1.0, i)
        })
        .collect();
    cases.push(agree(
        simple,
        "rayOrderKey",
        "origins on cell boundaries, outside the box, not finite",
        &[&simple.rays(&odd_origins)],
        &[],
        1,
        INTEGERS,
    ));
    for k in [1, 4, 32] {
        cases.push(agree(
            simple,
            "visibleLights",
            &format!("random flags, group {k}"),
            &[&Column::Bool(
                (0..k * 100)
                    .map(|_| rng.next_u32().is_multiple_of(3))
                    .collect(),
            )],
            &[],
            k,
            INTEGERS,
        ));
        if k != 32 {
            cases.push(agree(
                simple,
                "antiAlias",
                &format!("edge-case colours, group {k}"),
                &[&colors(&mut rng, k * 100)],
                &[],
                k,
                SRGB,
            ));
        }
    }
    cases.push(fails(
        simple,
        "visibleLights",
        "group 33",
        &[&Column::Bool(vec![false; 66])],
        &[],
        33,
        "visibleLights",
    ));

    // Marching cubes: every cell of each volume at levels that cut it (one
    // that equals many samples of the integer field), every triangle.
    cases.push(agree(
        &envs.sphere,
        "caseTriangles",
        "every case",
        &[&iota(256)],
        &[],
        1,
        INTEGERS,
    ));
    cases.push(fails(
        &envs.sphere,
        "caseTriangles",
        "case 256",
        &[&Column::U32(vec![255, 256])],
        &[],
        1,
        "case",
    ));
    for (env, levels) in [
        (&envs.sphere, &[0.8, 1.7][..]),
        (&envs.integers, &[5.0, 0.5, 10.0][..]),
        (&envs.thin, &[1.0, 4.0][..]),
    ] {
        let volume = &env
            .resources
            .downcast_ref::<VolumeResources>()
            .unwrap()
            .volume;
        let cells = volume.cell_count() as usize;
        for &level in levels {
            let named = vec![float(level.into())];
            let what = format!("every cell, level {level}");
            cases.push(agree(
                env,
                "cubeCase",
                &what,
                &[&iota(cells)],
                &named.clone(),
                1,
                INTEGERS,
            ));
            let cases_column = env.make("cubeCase", &[&iota(cells)], &named, 1);
            cases.push(agree(
                env,
                "caseTriangles",
                &what,
                &[&cases_column],
                &[],
                1,
                INTEGERS,
            ));
            let (cell_column, lane_column) = triangle_lanes(env, level);
            cases.push(agree(
                env,
                "cubeTriangle",
                &format!("every triangle, level {level}"),
                &[&cell_column, &lane_column],
                &named,
                1,
                MARCHING,
            ));
        }
        cases.push(fails(
            env,
            "cubeCase",
            "the cell past the last",
            &[&Column::U32(vec![0, cells as u32])],
            &[float(levels[0].into())],
            1,
            "cell",
        ));
    }
    volume_render_cases(&envs.render, &mut rng, &mut cases);
    let (cells, lanes) = triangle_lanes(&envs.sphere, 0.8);
    let past: Vec<u32> = lanes.view().as_u32().iter().map(|l| l + 5).collect();
    cases.push(fails(
        &envs.sphere,
        "cubeTriangle",
        "lanes past the cells' triangles",
        &[&cells, &Column::U32(past)],
        &[float(0.8)],
        1,
        "triangle",
    ));
    cases
}

/// Volume rendering: every pixel's entry (plain and jittered) and rays that
/// miss, start inside or are dead; marches over several rounds, shaded and
/// not; which are live; colours over the background; bad named values.
fn volume_render_cases<'e>(env: &'e Env, rng: &mut SplitMix64, cases: &mut Vec<Case<'e>>) {
    let pixels = env.trace_resources().camera.camera.pixels() as usize;
    let step = float(0.1);
    let mut rays = env.make("cameraRay", &[&iota(pixels)], &[int(1)], 1);
    let odd = env.rays(&[
        ray(Vec3::new(0.2, 0.1, 0.6), Vec3::X, f32::INFINITY, 0),
        ray(Vec3::new(0.2, 0.1, 0.6), Vec3::NEG_Z, 0.3, 1),
        ray(Vec3::new(5.0, 0.1, 0.6), Vec3::Y, f32::INFINITY, 2),
        ray(Vec3::new(5.0, 0.1, 0.6), Vec3::NEG_X, f32::INFINITY, 3),
        RayRecord::dead(4, 0),
    ]);
    for (what, input) in [("every pixel", &rays), ("odd rays", &odd)] {
        for jitter in [false, true] {
            cases.push(agree(
                env,
                "volumeEntry",
                &format!("{what}, jitter {jitter}"),
                &[input],
                &[step, HostValue::Bool(jitter)],
                1,
                MARCH,
            ));
        }
    }
    rays = env.make("volumeEntry", &[&rays], &[step, HostValue::Bool(true)], 1);
    for round in 0..3 {
        for shade in [false, true] {
            cases.push(agree(
                env,
                "volumeMarch",
                &format!("round {round}, shade {shade}"),
                &[&rays],
                &[
                    step,
                    float(0.25),
                    int(6),
                    float(0.95),
                    HostValue::Bool(shade),
                ],
                1,
                MARCH,
            ));
        }
        cases.push(agree(
            env,
            "marchLive",
            &format!("round {round}"),
            &[&rays],
            &[],
            1,
            INTEGERS,
        ));
        let named = [
            step,
            float(0.25),
            int(6),
            float(0.95),
            HostValue::Bool(false),
        ];
        rays = env.make("volumeMarch", &[&rays], &named, 1);
    }
    cases.push(fails(
        env,
        "volumeMarch",
        "0 samples",
        &[&rays],
        &[step, float(0.25), int(0)],
        1,
        "samples",
    ));
    cases.push(fails(
        env,
        "volumeEntry",
        "step 0",
        &[&odd],
        &[float(0.0)],
        1,
        "step",
    ));
    // Empty-space skipping: every cell's range and block, blocks of 1 to 3
    // cells (the last ones cut by the border), ranges around the opacity's
    // zero end, marches in and out of empty blocks.
    let volume = env.trace_resources().volume.clone().unwrap();
    let cells = iota(volume.cell_count() as usize);
    cases.push(agree(
        env,
        "cellRange",
        "every cell",
        &[&cells],
        &[],
        1,
        INTEGERS,
    ));
    for size in [1, 3] {
        cases.push(agree(
            env,
            "cellBlock",
            &format!("every cell, size {size}"),
            &[&cells],
            &[int(size)],
            1,
            INTEGERS,
        ));
        cases.push(agree(
            env,
            "marchBlock",
            &format!("marches, size {size}"),
            &[&rays],
            &[int(size)],
            1,
            INTEGERS,
        ));
        let empty = Column::Bool((0..rays.len()).map(|i| i % 3 != 0).collect());
        cases.push(agree(
            env,
            "skipEmpty",
            &format!("marches, size {size}"),
            &[&rays, &empty],
            &[int(size), step],
            1,
            MARCH,
        ));
    }
    cases.push(fails(
        env,
        "cellBlock",
        "size 0",
        &[&cells],
        &[int(0)],
        1,
        "size",
    ));
    let ranges: Vec<glam::Vec2> = (0..400)
        .map(|i| {
            let lo = 0.25 + 0.1 * rng.next_f32();
            let hi = lo
                + if i % 4 == 0 {
                    -0.01
                } else {
                    0.2 * rng.next_f32()
                };
            glam::Vec2::new(lo, -hi)
        })
        .collect();
    cases.push(agree(
        env,
        "transparent",
        "ranges about the opacity's zero end",
        &[&Column::Vec2(ranges)],
        &[],
        1,
        INTEGERS,
    ));
    let alphas = Column::F32((0..300).map(|_| rng.next_f32()).collect());
    cases.push(agree(
        env,
        "overBackground",
        "random colours and opacities",
        &[&colors(rng, 300), &alphas],
        &[],
        1,
        within(1e-6, "one multiply-add: a contracted fma is an ULP off"),
    ));
}

// ---------------------------------------------------------------------------
// Running and comparing

/// Runs `case` on both backends and compares; the disagreements, described
/// with the input elements that produced them.
fn check(gpu: &GpuContext, case: &Case<'_>, differences: &mut Differences) -> Result<(), String> {
    let env = case.env;
    let inputs: Vec<&Column> = case.inputs.iter().collect();
    let cpu = env.cpu(case.functor, &inputs, &case.named, case.group);
    let on_gpu = env.gpu(gpu, case.functor, &case.inputs, &case.named, case.group);
    let label = format!(
        "`{}` on {} ({}, named {:?}, k = {})",
        case.functor, case.what, env.name, case.named, case.group
    );
    match (case.expect, cpu, on_gpu) {
        (Expect::Fail(text), cpu, gpu) => both_fail(&label, text, cpu.map_err(|e| e.message), gpu),
        (
            Expect::Agree {
                within,
                prims,
                edge_ties,
            },
            Ok(cpu),
            Ok(gpu),
        ) => compare(
            case,
            &cpu,
            &gpu,
            within.tolerance,
            (prims, edge_ties),
            differences,
        )
        .map_err(|e| format!("{label}, {:?} ({}):\n{e}", within.tolerance, within.why)),
        (_, cpu, gpu) => Err(format!("{label}: CPU {:?}, GPU {:?}", cpu.err(), gpu.err())),
    }
}

/// The input elements output element `i` of `case` reads.
fn inputs_at(case: &Case<'_>, i: usize) -> String {
    let kind = case.env.library.get(case.functor).unwrap().signature().kind;
    let k = case.group;
    let range = match kind {
        dpp_runtime::FunctorKind::Group => i * k..i * k + k,
        dpp_runtime::FunctorKind::Expand => i / k..i / k + 1,
        _ => i..i + 1,
    };
    let records = &case.env.library.records;
    let mut text = String::new();
    for (n, column) in case.inputs.iter().enumerate() {
        let names = cell_names(column.elem_type(), records);
        for j in range.clone() {
            let mut values = Vec::new();
            column.scalars_of(j, &mut values);
            let fields: Vec<String> = names
                .iter()
                .zip(&values)
                .map(|(name, value)| format!("{name} = {}", cell_text(*value)))
                .collect();
            let _ = writeln!(text, "    input {n}[{j}]: {}", fields.join(", "));
        }
    }
    text
}

fn compare(
    case: &Case<'_>,
    cpu: &Column,
    gpu: &Column,
    tolerance: Tolerance,
    (prims, edge_ties): (f64, bool),
    differences: &mut Differences,
) -> Result<(), String> {
    if cpu.elem_type() != gpu.elem_type() || cpu.len() != gpu.len() {
        return Err(format!(
            "  the CPU made {} × {:?}, the GPU {} × {:?}",
            cpu.len(),
            cpu.elem_type(),
            gpu.len(),
            gpu.elem_type()
        ));
    }
    let names = cell_names(cpu.elem_type(), &case.env.library.records);
    let prim = names.iter().position(|name| name == "prim");
    let t = names.iter().position(|name| name == "t");
    let mut other_triangle = Vec::new();
    let mut edge_tie_count = 0;
    let mut disagreements = Vec::new();
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for i in 0..cpu.len() {
        a.clear();
        b.clear();
        cpu.scalars_of(i, &mut a);
        gpu.scalars_of(i, &mut b);
        if let Some(p) = prim {
            if a[p] != b[p] {
                let same_t = t.is_some_and(|t| match (a[t], b[t]) {
                    (Cell::Float(x), Cell::Float(y)) => {
                        x.is_finite() && tolerance.floats_agree(x, y, false)
                    }
                    _ => false,
                });
                if edge_ties && same_t {
                    edge_tie_count += 1;
                } else {
                    other_triangle.push(i);
                }
                continue;
            }
        }
        let differing = compare_cells(&a, &b, &names, tolerance, false, differences, case.functor);
        if !differing.is_empty() {
            disagreements.push((i, differing.join("; ")));
        }
    }
    let agreeing = 1.0 - other_triangle.len() as f64 / cpu.len().max(1) as f64;
    let mut text = String::new();
    if !other_triangle.is_empty() {
        let _ = writeln!(
            text,
            "  {} of {} hits are on another triangle ({:.4}% agree, {:.4}% needed), e.g.:",
            other_triangle.len(),
            cpu.len(),
            100.0 * agreeing,
            100.0 * prims
        );
        for &i in other_triangle.iter().take(3) {
            a.clear();
            b.clear();
            cpu.scalars_of(i, &mut a);
            gpu.scalars_of(i, &mut b);
            let show = |c: &[Cell]| {
                c.iter()
                    .map(|x| cell_text(*x))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            let _ = write!(
                text,
                "  [{i}]: CPU ({}), GPU ({})\n{}",
                show(&a),
                show(&b),
                inputs_at(case, i)
            );
        }
    }
    if !disagreements.is_empty() {
        let _ = writeln!(
            text,
            "  {} of {} elements disagree, e.g.:",
            disagreements.len(),
            cpu.len()
        );
        for (i, what) in disagreements.iter().take(3) {
            let _ = write!(text, "  [{i}]: {what}\n{}", inputs_at(case, *i));
        }
    }
    if edge_tie_count > 0 {
        eprintln!(
            "(allowed) `{}` on {}: {edge_tie_count} hits on the neighbouring triangle at the same t",
            case.functor, case.what
        );
    }
    if disagreements.is_empty() && agreeing >= prims {
        if !other_triangle.is_empty() {
            eprintln!(
                "(within the allowance) `{}` on {}:\n{text}",
                case.functor, case.what
            );
        }
        return Ok(());
    }
    Err(text)
}

/// Whether the GPU's f32 division rounds like the CPU's, on quotients of
/// pseudo-random floats (lavapipe's does; an H100's does not).
fn divides_exactly(gpu: &GpuContext) -> bool {
    let mut library = dpp_runtime::FunctorLibrary::default();
    dpp_runtime::generic::register_generic_functors(&mut library);
    let context = GpuRunContext {
        gpu,
        library: &library,
        uniforms: &dpp_runtime::Uniforms::default(),
        resources: &(),
        profile: false,
    };
    let mut random = dpp_runtime::random::SplitMix64::new(17);
    let (a, b): (Vec<f32>, Vec<f32>) = (0..4096)
        .map(|_| (random.range(-4.0, 4.0), random.range(0.1, 4.0)))
        .unzip();
    let quotients: Vec<u32> = a.iter().zip(&b).map(|(a, b)| (a / b).to_bits()).collect();
    let on_gpu = run_functor_gpu(&context, "div", &[Column::F32(a), Column::F32(b)], &[], 1)
        .unwrap_or_else(|e| panic!("div on the GPU: {}", e.message));
    let on_gpu: Vec<u32> = on_gpu.view().as_f32().iter().map(|x| x.to_bits()).collect();
    quotients == on_gpu
}

/// Watertightness on the GPU, whatever its rounding of divisions and its
/// contractions of `a * b + c` (see `rounded_one` in `bvh.wgsl`): rays from
/// outside a closed mesh aimed exactly at its vertices and edges all hit it,
/// no later than their target, as closest hits and as any-hit rays. (The
/// CPU's million-ray version: `a_million_rays_at_vertices_and_edges_never_leak`.)
#[test]
fn rays_at_a_closed_meshs_vertices_and_edges_all_hit_on_the_gpu() {
    // At the unit cube's size, and at 2^50 (1e15) and 2^-47 (7e-15) times it
    // with the directions left at the unit cube's (so t scales too), where the
    // triangle test's products overflow or underflow unless the BVH rescales.
    for factor in [1.0, 2f32.powi(50), 2f32.powi(-47)] {
        rays_at_a_closed_meshs_vertices_and_edges_all_hit_on_the_gpu_at(factor);
    }
}

fn rays_at_a_closed_meshs_vertices_and_edges_all_hit_on_the_gpu_at(factor: f32) {
    use crate::test_meshes::{box_outward, subdivided_cube, vertex_and_edge_targets};
    let mesh = subdivided_cube(6);
    let bounds = mesh.bounds().unwrap();
    let targets = vertex_and_edge_targets(&mesh);
    let scaled = TriangleMesh {
        positions: mesh.positions.iter().map(|&p| p * factor).collect(),
        ..mesh
    };
    let scene = TraceScene::new(scaled).unwrap();
    let env = Env::trace("cube", Fixture::with_scene(scene), None);
    let Some(gpu) = gpu_for_tests() else { return };
    let mut random = dpp_runtime::random::SplitMix64::new(23);
    let mut rays = Vec::new();
    for &target in &targets {
        let outward = box_outward(target, &bounds);
        for _ in 0..4 {
            let tilt = Vec3::new(
                random.range(-1.0, 1.0),
                random.range(-1.0, 1.0),
                random.range(-1.0, 1.0),
            );
            let away = (outward + 0.35 * tilt.normalize_or_zero()).normalize();
            let origin = target + random.range(3.0, 12.0) * away;
            // Scaling by a power of two keeps the ray through the scaled
            // target; tmax just past it: any-hit rays must stop there.
            rays.push(ray(
                origin * factor,
                target - origin,
                (1.0 + 1e-5) * factor,
                0,
            ));
        }
    }
    let rays = env.rays(&rays);
    for functor in ["intersect", "occluded"] {
        let hits = env
            .gpu(gpu, functor, std::slice::from_ref(&rays), &[], 1)
            .unwrap_or_else(|e| panic!("{functor} on the GPU: {e}"));
        let leaks: Vec<usize> = match functor {
            "intersect" => {
                let prims = hits.view().field(1).as_u32().to_vec();
                (0..prims.len()).filter(|&i| prims[i] == u32::MAX).collect()
            }
            _ => {
                let blocked = hits.view().as_bool().to_vec();
                (0..blocked.len()).filter(|&i| !blocked[i]).collect()
            }
        };
        assert!(
            leaks.is_empty(),
            "`{functor}` at {factor} times the size: {} of {} rays aimed at vertices and edges leak on the GPU, e.g. {}",
            leaks.len(),
            rays.len(),
            leaks
                .iter()
                .take(3)
                .map(|&i| {
                    let mut cells = Vec::new();
                    rays.scalars_of(i, &mut cells);
                    format!("{cells:?}")
                })
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
}

#[test]
fn every_twin_agrees_with_its_rust_code() {
    let envs = envs();
    let cases = cases(&envs, true);
    let covered: BTreeSet<&str> = cases.iter().map(|case| case.functor).collect();
    let functors: BTreeSet<&str> = envs.simple.library.names().collect();
    assert_eq!(covered, functors, "every tracer functor has cases");
    let Some(gpu) = gpu_for_tests() else { return };
    let cases = if divides_exactly(gpu) {
        cases
    } else {
        eprintln!("the GPU's f32 division is not correctly rounded (WGSL allows 2.5 ULP)");
        self::cases(&envs, false)
    };
    let mut report = Report::default();
    for case in &cases {
        let failure = check(gpu, case, &mut report.differences).err();
        report.case(failure);
    }
    report.assert_agreement();
}
