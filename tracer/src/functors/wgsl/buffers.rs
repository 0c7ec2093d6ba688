//! Scene data in the layouts the WGSL twins read, built once per scene,
//! camera, shading set-up or volume and handed out as clones of the same
//! `Arc`s (a backend uploads each once). Every buffer is 32-bit words; `vec4`
//! layouts keep 16-byte strides.
//!
//! | name | WGSL type | words |
//! |---|---|---|
//! | `tracer_bvh_nodes` | `array<vec4<f32>>` | [`Bvh::nodes`] as they are: 4 per node, per child `(min.xyz, bits of index)`, `(max.xyz, bits of count)` |
//! | `tracer_bvh_triangles` | `array<f32>` | [`Bvh::triangles`] as they are: 9 per leaf-order triangle |
//! | `tracer_bvh_triangle_ids` | `array<u32>` | [`Bvh::triangle_ids`]: file-order id per leaf-order triangle |
//! | `tracer_mesh_triangles` | `array<vec4<u32>>` | per file-order triangle: vertex indices, material id |
//! | `tracer_mesh_vertices` | `array<vec4<f32>>` | 2 per vertex: `(position, scalar)`, `(normal, 0)` |
//! | `tracer_global_ids` | `array<u32>` | 1 with a global id table (0 without), then each triangle's id in the whole data set ([`crate::TraceScene::global_id_gpu_buffer`]) |
//! | `tracer_shading_constants` | `array<vec4<f32>>` | `(min, max, 1 / (max - min), 0)` of the scalar range, `(background, 0)` (linear) |
//! | `tracer_colormap` | `array<vec4<f32>>` | 256 linear colours and opacities `(r, g, b, a)` |
//! | `tracer_materials` | `array<vec4<f32>>` | 2 per material: `(Kd, Ns)`, `(Ks, reflectivity)` |
//! | `tracer_lights` | `array<vec4<f32>>` | 2 per light: `(position, intensity)`, `(colour, 0)` |
//! | `tracer_camera` | `array<vec4<f32>>` | `(eye, tan(fov/2))`, `(forward, aspect)`, `(right, width)`, `(true up, height)` |
//! | `tracer_camera_morton_pixels` | `array<u32>` | [`CameraSetup::morton_pixels`] |
//! | `tracer_volume_grid` | `array<vec4<u32>>` | `(dims, cell count)`, bits of `(origin, 0)`, bits of `(spacing, 0)`, `(first, 0)` |
//! | `tracer_volume_values` | `array<f32>` | the samples, x fastest |
//! | `tracer_mc_case_triangle_counts` | `array<u32>` | 256 triangle counts |
//! | `tracer_mc_case_triangles` | `array<u32>` | 5 per case: `e0 \| e1 << 8 \| e2 << 16` |
//! | `tracer_mc_edge_corners` | `array<u32>` | 12: `lo \| hi << 8` |

use crate::bvh::Bvh;
use crate::cache::ArcKeyedCache;
use crate::camera::{Camera, CameraSetup};
use crate::marching_cubes_tables::{tables, EDGES, MAX_CELL_TRIANGLES};
use crate::mesh::TriangleMesh;
use crate::shading::{MeshMaterials, Shading};
use crate::volume::Volume;
use dpp_runtime::wgsl::GpuBuffer;
use dpp_runtime::FunctorError;
use glam::Vec3;
use std::sync::{Arc, OnceLock};

fn buffer(name: &'static str, wgsl_type: &'static str, words: Vec<u32>) -> GpuBuffer {
    GpuBuffer {
        name,
        wgsl_type,
        data: Arc::from(words),
    }
}

/// `(x, y, z, w)` as the words of a `vec4<f32>`.
fn vec4_words(xyz: Vec3, w: f32) -> [u32; 4] {
    [xyz.x, xyz.y, xyz.z, w].map(f32::to_bits)
}

/// The mesh and its BVH ([`crate::bvh`] layouts as they are).
#[derive(Clone, Debug)]
pub struct SceneGpuBuffers {
    pub bvh_nodes: GpuBuffer,
    pub bvh_triangles: GpuBuffer,
    pub bvh_triangle_ids: GpuBuffer,
    pub mesh_triangles: GpuBuffer,
    pub mesh_vertices: GpuBuffer,
    /// [`Bvh::scale`]: the BVH's boxes and triangles are multiplied by it.
    pub bvh_scale: f32,
}

impl SceneGpuBuffers {
    pub fn new(mesh: &TriangleMesh, bvh: &Bvh, materials: &MeshMaterials) -> SceneGpuBuffers {
        let mesh_triangles = mesh
            .triangles
            .iter()
            .enumerate()
            .flat_map(|(prim, &[a, b, c])| [a, b, c, materials.triangle_material(prim as u32)])
            .collect();
        // A mesh without normals interpolates to zero (the face normal is used);
        // without scalars the scalar is y, whose interpolation is the hit's y
        // computed as the CPU computes it.
        let mesh_vertices = mesh
            .positions
            .iter()
            .enumerate()
            .flat_map(|(vertex, &position)| {
                let normal = mesh.normals.as_ref().map_or(Vec3::ZERO, |n| n[vertex]);
                let scalar = mesh.scalars.as_ref().map_or(position.y, |s| s[vertex]);
                let [p0, p1, p2, p3] = vec4_words(position, scalar);
                let [n0, n1, n2, n3] = vec4_words(normal, 0.0);
                [p0, p1, p2, p3, n0, n1, n2, n3]
            })
            .collect();
        SceneGpuBuffers {
            bvh_nodes: buffer("tracer_bvh_nodes", "array<vec4<f32>>", bvh.gpu_node_words()),
            bvh_triangles: buffer(
                "tracer_bvh_triangles",
                "array<f32>",
                bvh.gpu_triangle_words(),
            ),
            bvh_triangle_ids: buffer(
                "tracer_bvh_triangle_ids",
                "array<u32>",
                bvh.triangle_ids().to_vec(),
            ),
            mesh_triangles: buffer("tracer_mesh_triangles", "array<vec4<u32>>", mesh_triangles),
            mesh_vertices: buffer("tracer_mesh_vertices", "array<vec4<f32>>", mesh_vertices),
            bvh_scale: bvh.scale(),
        }
    }
}

/// Materials, lights, colour map, scalar range and background.
#[derive(Clone, Debug)]
pub struct ShadingGpuBuffers {
    pub constants: GpuBuffer,
    pub colormap: GpuBuffer,
    pub materials: GpuBuffer,
    pub lights: GpuBuffer,
}

impl ShadingGpuBuffers {
    pub fn new(shading: &Shading) -> ShadingGpuBuffers {
        let [low, high] = shading.scalar_range();
        // The reciprocal as the CPU shader computes it (a GPU division may round otherwise).
        let inverse_range = 1.0 / (high - low);
        let mut constants = Vec::with_capacity(8);
        constants.extend([low, high, inverse_range, 0.0].map(f32::to_bits));
        constants.extend(vec4_words(shading.background(), 0.0));
        let map = shading.colormap();
        let colormap = (map.linear().iter().zip(map.opacity()))
            .flat_map(|(&color, &opacity)| vec4_words(color, opacity))
            .collect();
        let materials = shading
            .materials()
            .iter()
            .flat_map(|m| {
                let [a, b, c, d] = vec4_words(m.kd, m.ns);
                let [e, f, g, h] = vec4_words(m.ks, m.reflectivity);
                [a, b, c, d, e, f, g, h]
            })
            .collect();
        let lights = shading
            .lights()
            .iter()
            .flat_map(|light| {
                let [a, b, c, d] = vec4_words(light.position, light.intensity);
                let [e, f, g, h] = vec4_words(light.color, 0.0);
                [a, b, c, d, e, f, g, h]
            })
            .collect();
        ShadingGpuBuffers {
            constants: buffer("tracer_shading_constants", "array<vec4<f32>>", constants),
            colormap: buffer("tracer_colormap", "array<vec4<f32>>", colormap),
            materials: buffer("tracer_materials", "array<vec4<f32>>", materials),
            lights: buffer("tracer_lights", "array<vec4<f32>>", lights),
        }
    }
}

/// The camera's frame, as [`Camera::new`] computed it (a test checks through
/// [`Camera::direction`] that the twin's order of operations gives its bits).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraFrame {
    pub forward: Vec3,
    pub right: Vec3,
    pub true_up: Vec3,
    pub half_height: f32,
    pub aspect: f32,
}

impl CameraFrame {
    pub fn new(camera: &Camera) -> CameraFrame {
        CameraFrame {
            forward: camera.forward,
            right: camera.right,
            true_up: camera.true_up,
            half_height: camera.half_height,
            aspect: camera.aspect,
        }
    }

    /// [`Camera::direction`] on this frame, in the twin's order of operations.
    pub fn direction(&self, camera: &Camera, x: u32, y: u32, sx: f32, sy: f32) -> Vec3 {
        let horizontal = 2.0 * (x as f32 + sx) / camera.width as f32 - 1.0;
        let vertical = 1.0 - 2.0 * (y as f32 + sy) / camera.height as f32;
        (self.forward
            + horizontal * self.half_height * self.aspect * self.right
            + vertical * self.half_height * self.true_up)
            .normalize()
    }
}

/// The camera frame and the Morton order of the pixels.
#[derive(Clone, Debug)]
pub struct CameraGpuBuffers {
    pub camera: GpuBuffer,
    pub morton_pixels: GpuBuffer,
}

impl CameraGpuBuffers {
    pub fn new(setup: &CameraSetup) -> CameraGpuBuffers {
        let camera = &setup.camera;
        let frame = CameraFrame::new(camera);
        let mut words = Vec::with_capacity(16);
        words.extend(vec4_words(camera.eye, frame.half_height));
        words.extend(vec4_words(frame.forward, frame.aspect));
        words.extend(vec4_words(frame.right, camera.width as f32));
        words.extend(vec4_words(frame.true_up, camera.height as f32));
        CameraGpuBuffers {
            camera: buffer("tracer_camera", "array<vec4<f32>>", words),
            morton_pixels: buffer(
                "tracer_camera_morton_pixels",
                "array<u32>",
                setup.morton_pixels.clone(),
            ),
        }
    }
}

/// The volume's grid and samples.
#[derive(Clone, Debug)]
pub struct VolumeGpuBuffers {
    pub grid: GpuBuffer,
    pub values: GpuBuffer,
}

/// The GPU buffers of each live volume twins were built for. Process-wide and
/// keyed by the volume's `Arc`, because users build the isosurface functors'
/// `VolumeResources` with a struct literal, which leaves it no room for a
/// cache of its own.
static VOLUME_GPU_BUFFERS: ArcKeyedCache<Volume, VolumeGpuBuffers> = ArcKeyedCache::new();

/// Frees the cached GPU copy of a volume that is gone (a volume can be large,
/// and a run traces its isosurface after dropping it).
pub(crate) fn release_gpu_buffers_of_dropped_volumes() {
    VOLUME_GPU_BUFFERS.release_orphans();
}

impl VolumeGpuBuffers {
    /// The buffers of `volume`, built once per volume (see [`VolumeGpuBuffers::new`]).
    pub fn of_volume(volume: &Arc<Volume>) -> Result<VolumeGpuBuffers, FunctorError> {
        VOLUME_GPU_BUFFERS.get_or_try_build(volume, VolumeGpuBuffers::new)
    }

    /// Fails for a volume whose samples do not match its dimensions (as the
    /// CPU functors do) or whose sample indices do not fit the GPU's `u32`.
    pub fn new(volume: &Volume) -> Result<VolumeGpuBuffers, FunctorError> {
        let dims = volume.dims;
        let samples = dims.x as u64 * dims.y as u64 * dims.z as u64;
        if volume.values.len() as u64 != samples {
            return Err(FunctorError::bad_input(format!(
                "the volume has {} values for {}×{}×{} samples",
                volume.values.len(),
                dims.x,
                dims.y,
                dims.z
            )));
        }
        let cells = u32::try_from(volume.cell_count())
            .ok()
            .filter(|_| samples <= u32::MAX as u64);
        let Some(cells) = cells else {
            return Err(FunctorError::bad_input(format!(
                "a {}×{}×{} volume has too many samples for the GPU's 32-bit indices",
                dims.x, dims.y, dims.z
            )));
        };
        let mut grid = vec![dims.x, dims.y, dims.z, cells];
        grid.extend(vec4_words(volume.origin, 0.0));
        grid.extend(vec4_words(volume.spacing, 0.0));
        grid.extend([volume.first.x, volume.first.y, volume.first.z, 0]);
        let values = volume.values.iter().map(|v| v.to_bits()).collect();
        Ok(VolumeGpuBuffers {
            grid: buffer("tracer_volume_grid", "array<vec4<u32>>", grid),
            values: buffer("tracer_volume_values", "array<f32>", values),
        })
    }
}

/// The marching-cubes tables (the same for every volume).
#[derive(Clone, Debug)]
pub struct MarchingCubesGpuBuffers {
    pub case_triangle_counts: GpuBuffer,
    pub case_triangles: GpuBuffer,
    pub edge_corners: GpuBuffer,
}

impl MarchingCubesGpuBuffers {
    /// Built on first use and shared by every run.
    pub fn get() -> &'static MarchingCubesGpuBuffers {
        static BUFFERS: OnceLock<MarchingCubesGpuBuffers> = OnceLock::new();
        BUFFERS.get_or_init(|| {
            let tables = tables();
            let counts = tables.counts.iter().map(|&c| u32::from(c)).collect();
            let triangles = tables
                .triangles
                .iter()
                .flat_map(|case| {
                    case.iter().map(|&[e0, e1, e2]| {
                        u32::from(e0) | u32::from(e1) << 8 | u32::from(e2) << 16
                    })
                })
                .collect::<Vec<u32>>();
            debug_assert_eq!(triangles.len(), 256 * MAX_CELL_TRIANGLES);
            let edges = EDGES
                .iter()
                .map(|&[lo, hi]| u32::from(lo) | u32::from(hi) << 8)
                .collect();
            MarchingCubesGpuBuffers {
                case_triangle_counts: buffer(
                    "tracer_mc_case_triangle_counts",
                    "array<u32>",
                    counts,
                ),
                case_triangles: buffer("tracer_mc_case_triangles", "array<u32>", triangles),
                edge_corners: buffer("tracer_mc_edge_corners", "array<u32>", edges),
            }
        })
    }
}
