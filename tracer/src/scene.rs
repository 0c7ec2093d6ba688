//! The scene data a run traces against, built once before any frame.

use crate::builtin_scene::{builtin_scene, ResolutionOutOfRange};
use crate::bvh::{Bvh, BvhBuilder};
use crate::cache::{ArcKeyedCache, BuiltOnce};
use crate::camera::CameraSetup;
use crate::functors::wgsl::buffers::{
    CameraGpuBuffers, SceneGpuBuffers, ShadingGpuBuffers, VolumeGpuBuffers,
};
use crate::mesh::{Bounds, MeshError, TriangleMesh};
use crate::obj::{load_obj_with_materials, ObjError};
use crate::shading::{MeshMaterials, Shading};
use crate::volume::Volume;
use crate::MISS_PRIM;
use dpp_runtime::wgsl::GpuBuffer;
use dpp_runtime::FunctorError;
use glam::Vec3;
use std::path::Path;
use std::sync::Arc;
use thiserror::Error;

#[derive(Debug, Error)]
pub enum SceneError {
    #[error(transparent)]
    Obj(#[from] ObjError),
    #[error(transparent)]
    Builtin(#[from] ResolutionOutOfRange),
    #[error("invalid mesh: {0}")]
    Mesh(#[from] MeshError),
    #[error("invalid materials: {0}")]
    Materials(String),
    #[error("invalid global triangle ids: {0}")]
    GlobalIds(String),
}

/// Faces meeting at more than this angle keep a sharp edge between them when
/// normals are computed at load (a cube's edges; not an isosurface's bumps).
pub const CREASE_ANGLE_DEGREES: f32 = 60.0;

/// A validated mesh with its BVH and material table.
#[derive(Clone, Debug)]
pub struct TraceScene {
    /// The mesh, with `normals` and `scalars` always present: when the input has
    /// none, smooth area-weighted vertex normals that keep edges sharper than
    /// [`CREASE_ANGLE_DEGREES`] ([`TriangleMesh::add_crease_normals`]), and the
    /// vertices' y coordinates.
    pub mesh: TriangleMesh,
    pub bvh: Bvh,
    pub bounds: Bounds,
    /// The material table (entry 0 the default) and each triangle's material.
    pub materials: MeshMaterials,
    /// The fields above in the WGSL twins' layouts, built on first use (a
    /// scene is not changed once built).
    gpu_buffers: BuiltOnce<SceneGpuBuffers>,
    /// Each triangle's id in the whole data set, when the scene is one part of
    /// a distributed one ([`TraceScene::with_global_ids`]); `None`: the ids are
    /// the triangles' own indices.
    global_ids: Option<Arc<Vec<u32>>>,
    /// `global_ids` as `globalId`'s twin reads it, built on first use.
    global_id_buffer: BuiltOnce<GpuBuffer>,
}

impl TraceScene {
    /// Validates the mesh, fills in missing shading attributes and builds its BVH;
    /// every triangle gets the default material.
    pub fn new(mesh: TriangleMesh) -> Result<TraceScene, SceneError> {
        TraceScene::with_materials(mesh, MeshMaterials::default())
    }

    /// As [`TraceScene::new`], with a material table (checked against the mesh).
    pub fn with_materials(
        mesh: TriangleMesh,
        materials: MeshMaterials,
    ) -> Result<TraceScene, SceneError> {
        TraceScene::built_with(mesh, materials, BvhBuilder::default())
    }

    /// As [`TraceScene::with_materials`], the BVH made by a chosen builder.
    pub fn built_with(
        mut mesh: TriangleMesh,
        materials: MeshMaterials,
        builder: BvhBuilder,
    ) -> Result<TraceScene, SceneError> {
        let bvh = Bvh::build_with(&mesh, builder)?;
        // `build` validated the mesh, so it has triangles and therefore bounds.
        let bounds = mesh.bounds().ok_or(MeshError::NoTriangles)?;
        materials
            .validate(mesh.triangles.len())
            .map_err(SceneError::Materials)?;
        if mesh.normals.is_none() {
            mesh.add_crease_normals(CREASE_ANGLE_DEGREES.to_radians());
        }
        if mesh.scalars.is_none() {
            mesh.scalars = Some(mesh.positions.iter().map(|p: &Vec3| p.y).collect());
        }
        Ok(TraceScene {
            mesh,
            bvh,
            bounds,
            materials,
            gpu_buffers: BuiltOnce::default(),
            global_ids: None,
            global_id_buffer: BuiltOnce::default(),
        })
    }

    /// The scene as one part of a distributed data set: `ids[t]` is triangle
    /// `t`'s id in the whole data set (what the `globalId` functor gives for
    /// `prim = t`; `prim` itself stays local, the index into this mesh).
    /// There must be one id per triangle, none of them `u32::MAX` (a miss).
    pub fn with_global_ids(mut self, ids: Arc<Vec<u32>>) -> Result<TraceScene, SceneError> {
        if ids.len() != self.mesh.triangles.len() {
            return Err(SceneError::GlobalIds(format!(
                "{} ids for {} triangles",
                ids.len(),
                self.mesh.triangles.len()
            )));
        }
        if let Some(t) = ids.iter().position(|&id| id == MISS_PRIM) {
            return Err(SceneError::GlobalIds(format!(
                "triangle {t} has id {MISS_PRIM}, which marks a miss"
            )));
        }
        self.global_ids = Some(ids);
        self.global_id_buffer = BuiltOnce::default();
        Ok(self)
    }

    /// Each triangle's id in the whole data set, if the scene has a table.
    pub fn global_ids(&self) -> Option<&Arc<Vec<u32>>> {
        self.global_ids.as_ref()
    }

    /// The id in the whole data set of triangle `prim`: its entry in the
    /// table, `prim` itself without a table, [`MISS_PRIM`] for a miss;
    /// `None` for a triangle past the table's end.
    #[inline]
    pub fn global_id(&self, prim: u32) -> Option<u32> {
        if prim == MISS_PRIM {
            return Some(MISS_PRIM);
        }
        match &self.global_ids {
            None => Some(prim),
            Some(ids) => ids.get(prim as usize).copied(),
        }
    }

    /// The global id table as `globalId`'s twin reads it: word 0 is 1 when
    /// there is a table (0 without one), then the ids (built once).
    pub fn global_id_gpu_buffer(&self) -> &GpuBuffer {
        self.global_id_buffer.get_or_init(|| {
            let mut words = Vec::with_capacity(1 + self.mesh.triangles.len());
            match &self.global_ids {
                Some(ids) => {
                    words.push(1);
                    words.extend(ids.iter());
                }
                None => words.push(0),
            }
            GpuBuffer {
                name: "tracer_global_ids",
                wgsl_type: "array<u32>",
                data: Arc::from(words),
            }
        })
    }

    /// An OBJ file with its MTL materials (see [`load_obj_with_materials`]).
    pub fn from_obj(path: &Path) -> Result<TraceScene, SceneError> {
        let (mesh, materials) = load_obj_with_materials(path)?;
        TraceScene::with_materials(mesh, materials)
    }

    /// The built-in mixing-layer scene (see [`crate::builtin_scene`]).
    pub fn builtin(resolution: u32) -> Result<TraceScene, SceneError> {
        TraceScene::new(builtin_scene(resolution)?)
    }

    /// The material id of triangle `prim` (0 for an unknown triangle).
    #[inline]
    pub fn triangle_material(&self, prim: u32) -> u32 {
        self.materials.triangle_material(prim)
    }

    /// The mesh and BVH as the GPU twins read them, built once.
    pub fn gpu_buffers(&self) -> &SceneGpuBuffers {
        self.gpu_buffers
            .get_or_init(|| SceneGpuBuffers::new(&self.mesh, &self.bvh, &self.materials))
    }
}

/// Defined here rather than in [`crate::shading`], which sits below scenes and
/// knows only meshes' bounds, scalars and materials.
impl Shading {
    /// The defaults for a scene: [`Shading::for_mesh`] of its materials,
    /// bounds and vertex scalars.
    pub fn for_scene(scene: &TraceScene) -> Shading {
        Shading::for_mesh(
            &scene.materials,
            &scene.bounds,
            scene.mesh.scalars.as_deref().unwrap_or(&[]),
        )
    }
}

/// What the ray-tracing functors find in [`dpp_runtime::CallContext::resources`].
#[derive(Clone, Debug)]
pub struct TraceResources {
    pub scene: Arc<TraceScene>,
    pub camera: Arc<CameraSetup>,
    /// Materials, lights, colour map: [`Shading::for_scene`] unless the user changed them.
    pub shading: Arc<Shading>,
    /// The volume a volume-rendering pipeline marches through (the
    /// `volume*` functors of [`crate::functors::volume_render`]), if the run has one.
    pub volume: Option<Arc<Volume>>,
    /// GPU buffers of `camera` and `shading`, kept while those `Arc`s are the
    /// ones in the fields (set-up replaces them, e.g. through `Arc::make_mut`).
    camera_gpu_buffers: ArcKeyedCache<CameraSetup, CameraGpuBuffers>,
    shading_gpu_buffers: ArcKeyedCache<Shading, ShadingGpuBuffers>,
}

impl TraceResources {
    /// The scene and camera with the scene's default shading.
    pub fn new(scene: Arc<TraceScene>, camera: Arc<CameraSetup>) -> TraceResources {
        let shading = Arc::new(Shading::for_scene(&scene));
        TraceResources {
            scene,
            camera,
            shading,
            volume: None,
            camera_gpu_buffers: ArcKeyedCache::new(),
            shading_gpu_buffers: ArcKeyedCache::new(),
        }
    }

    /// The camera frame and pixel order as the GPU twins read them.
    pub fn camera_gpu_buffers(&self) -> CameraGpuBuffers {
        self.camera_gpu_buffers
            .get_or_build(&self.camera, CameraGpuBuffers::new)
    }

    /// Materials, lights and colour map as the GPU twins read them.
    pub fn shading_gpu_buffers(&self) -> ShadingGpuBuffers {
        self.shading_gpu_buffers
            .get_or_build(&self.shading, ShadingGpuBuffers::new)
    }

    /// The run's volume as the GPU twins read it, built once per volume; the
    /// errors name `functor`.
    pub fn volume_gpu_buffers(&self, functor: &str) -> Result<VolumeGpuBuffers, FunctorError> {
        VolumeGpuBuffers::of_volume(self.volume(functor)?)
            .map_err(|e| FunctorError::bad_input(format!("{functor}: {}", e.message)))
    }

    /// The uniforms of this scene, camera and shading (see [`crate::uniforms`]),
    /// and the `volume.*` ones of its volume.
    pub fn uniforms(&self) -> dpp_runtime::Uniforms {
        let mut uniforms = crate::uniforms(&self.scene, &self.camera, &self.shading);
        if let Some(volume) = &self.volume {
            let of_volume = crate::functors::isosurface::volume_uniforms(volume);
            uniforms.records.extend(of_volume.records);
        }
        uniforms
    }

    /// The run's volume, or an error saying that `functor` needs one.
    pub fn volume(&self, functor: &str) -> Result<&Arc<Volume>, FunctorError> {
        self.volume.as_ref().ok_or_else(|| {
            FunctorError::bad_input(format!(
                "{functor}: the run has no volume (give a volume as the scene)"
            ))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shading::{srgb_to_linear, Material, DEFAULT_BACKGROUND, DEFAULT_MATERIAL};

    fn scene() -> TraceScene {
        let mesh = TriangleMesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(0.0, 2.0, 0.0)],
            triangles: vec![[0, 1, 2]],
            normals: None,
            scalars: None,
        };
        TraceScene::new(mesh).unwrap()
    }

    #[test]
    fn defaults_follow_the_scene() {
        let scene = scene();
        let shading = Shading::for_scene(&scene);
        assert_eq!(shading.materials(), &[Material::named(DEFAULT_MATERIAL)]);
        assert_eq!(shading.colormap().name(), "viridis");
        // Scalars default to y.
        assert_eq!(shading.scalar_range(), [0.0, 2.0]);
        assert_eq!(shading.lights().len(), 2);
        let c = scene.bounds.center();
        let key = shading.lights()[0];
        assert!(key.position.y > scene.bounds.max.y && key.position.z > c.z);
        // The key light delivers 1.0 at the centre with falloff 1.
        let d = (key.position - c).length() / scene.bounds.diagonal();
        assert!((key.intensity / (1.0 + d * d) - 1.0).abs() < 1e-5);
        assert!((shading.background() - srgb_to_linear(DEFAULT_BACKGROUND)).length() < 1e-6);
    }
}
