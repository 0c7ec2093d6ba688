//! The scene data a run traces against, built once before any frame.

use crate::builtin_scene::{builtin_scene, ResolutionOutOfRange};
use crate::bvh::Bvh;
use crate::camera::CameraSetup;
use crate::mesh::{Bounds, MeshError, TriangleMesh};
use crate::obj::{load_obj, ObjError};
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
}

/// A validated mesh with its BVH.
#[derive(Clone, Debug)]
pub struct TraceScene {
    pub mesh: TriangleMesh,
    pub bvh: Bvh,
    pub bounds: Bounds,
}

impl TraceScene {
    /// Validates the mesh and builds its BVH.
    pub fn new(mesh: TriangleMesh) -> Result<TraceScene, SceneError> {
        let bvh = Bvh::build(&mesh)?;
        // `build` validated the mesh, so it has triangles and therefore bounds.
        let bounds = mesh.bounds().ok_or(MeshError::NoTriangles)?;
        Ok(TraceScene { mesh, bvh, bounds })
    }

    pub fn from_obj(path: &Path) -> Result<TraceScene, SceneError> {
        TraceScene::new(load_obj(path)?)
    }

    /// The built-in mixing-layer scene (see [`crate::builtin_scene`]).
    pub fn builtin(resolution: u32) -> Result<TraceScene, SceneError> {
        TraceScene::new(builtin_scene(resolution)?)
    }
}

/// What the ray-tracing functors find in [`dpp_runtime::CallContext::resources`].
#[derive(Clone, Debug)]
pub struct TraceResources {
    pub scene: Arc<TraceScene>,
    pub camera: Arc<CameraSetup>,
}
