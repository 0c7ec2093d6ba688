//! From command-line arguments to what a run reads: the scene (loaded or
//! built-in, BVH built once, outside any frame), the camera and the uniforms.

use dpp_runtime::Uniforms;
use dpp_tracer::builtin_scene::DEFAULT_RESOLUTION;
use dpp_tracer::{
    Camera, CameraSetup, SceneFile, ShadingOverrides, StandardView, TraceResources, TraceScene,
};
use glam::Vec3;
use std::path::{Path, PathBuf};
use std::sync::Arc;

pub struct SceneRequest {
    pub scene: Option<PathBuf>,
    pub size: (u32, u32),
    pub view: String,
    pub eye: Option<[f32; 3]>,
    pub look_at: Option<[f32; 3]>,
    pub up: Option<[f32; 3]>,
    pub fov: f32,
    /// A scene file (TOML); without one, `SCENE.toml` beside an OBJ if it exists.
    pub scene_file: Option<PathBuf>,
    pub shading: ShadingOverrides,
}

pub struct SceneSetup {
    pub uniforms: Uniforms,
    pub resources: TraceResources,
    pub camera: Camera,
    /// One line for `--profile`: where the scene came from and its size.
    pub description: String,
}

impl SceneSetup {
    /// Errors are the user's input (a bad file, a bad camera): exit status 2.
    pub fn new(request: &SceneRequest) -> Result<SceneSetup, String> {
        let scene = match &request.scene {
            None => TraceScene::builtin(DEFAULT_RESOLUTION),
            Some(path) => match path
                .extension()
                .and_then(|e| e.to_str())
                .map(str::to_ascii_lowercase)
                .as_deref()
            {
                Some("obj") => TraceScene::from_obj(path),
                _ => {
                    return Err(format!(
                        "error: cannot read scene `{}`: dpp reads .obj files",
                        path.display()
                    ))
                }
            },
        }
        .map_err(|e| match &request.scene {
            Some(path) => format!("error: cannot use scene `{}`: {e}", path.display()),
            None => format!("error: the built-in scene failed: {e}"),
        })?;
        let camera = camera(request, &scene).map_err(|e| format!("error: bad camera: {e}"))?;
        let mut resources =
            TraceResources::new(Arc::new(scene), Arc::new(CameraSetup::new(camera.clone())));
        let shading = Arc::make_mut(&mut resources.shading);
        if let Some(path) = scene_file(request) {
            let file = SceneFile::load(&path).map_err(|e| format!("error: {e}"))?;
            shading
                .apply(&file)
                .map_err(|e| format!("error: {}: {e}", path.display()))?;
        }
        shading
            .apply_overrides(&request.shading)
            .map_err(|e| format!("error: {e}"))?;
        let uniforms = resources.uniforms();
        let scene = &resources.scene;
        let description = format!(
            "{} ({} triangles), {}x{}",
            request
                .scene
                .as_ref()
                .map_or("built-in mixing layer".to_string(), |p| p
                    .display()
                    .to_string()),
            scene.mesh.triangles.len(),
            camera.width,
            camera.height
        );
        Ok(SceneSetup {
            uniforms,
            resources,
            camera,
            description,
        })
    }
}

/// The scene file given, or `mesh.toml` beside `mesh.obj` when there is one.
fn scene_file(request: &SceneRequest) -> Option<PathBuf> {
    if request.scene_file.is_some() {
        return request.scene_file.clone();
    }
    let beside = request.scene.as_deref()?.with_extension("toml");
    Path::exists(&beside).then_some(beside)
}

/// A standard view of the scene's bounds, with any of eye, look-at and up replaced.
fn camera(request: &SceneRequest, scene: &TraceScene) -> Result<Camera, String> {
    let view: StandardView = request.view.parse().map_err(|e| format!("{e}"))?;
    let (width, height) = request.size;
    let standard =
        Camera::standard(view, &scene.bounds, width, height).map_err(|e| e.to_string())?;
    let pick = |given: Option<[f32; 3]>, default: Vec3| given.map_or(default, Vec3::from);
    Camera::new(
        pick(request.eye, standard.eye),
        pick(request.look_at, standard.look_at),
        pick(request.up, standard.up),
        request.fov,
        width,
        height,
    )
    .map_err(|e| e.to_string())
}
