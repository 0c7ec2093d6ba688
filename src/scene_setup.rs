//! From command-line arguments to what a run reads: the scene (a mesh, the
//! isosurface of a volume, or the built-in scene; BVH built once, outside any
//! frame), the camera, the shading and the uniforms.

use crate::progress::Progress;
use crate::volume_setup::{self, IsoRequest};
use dpp_runtime::{FunctorLibrary, Uniforms};
use dpp_tracer::builtin_scene::{builtin_scene, DEFAULT_RESOLUTION};
use dpp_tracer::shading::MeshMaterials;
use dpp_tracer::{
    Camera, CameraSetup, SceneFile, ShadingOverrides, StandardView, TraceResources, TraceScene,
    TriangleMesh,
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
    /// For a volume: the isosurface level, a raw brick's layout (`XxYxZ:TYPE…`),
    /// a second field to colour by, an edited isosurface pipeline, fusion.
    pub iso: Option<f32>,
    pub raw: Option<String>,
    pub color_by: Option<PathBuf>,
    pub iso_pipeline: Option<PathBuf>,
    pub fuse: bool,
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
    /// Each phase of the loading is shown on `progress`.
    pub fn new(
        request: &SceneRequest,
        library: &FunctorLibrary,
        progress: &Progress,
    ) -> Result<SceneSetup, String> {
        let (scene, origin) = load_scene(request, library, progress)?;
        SceneSetup::with_scene(Arc::new(scene), &origin, request)
    }

    /// The camera, shading and uniforms of an already loaded scene (`dpp bench`
    /// builds each scene once and looks at it from several views).
    pub fn with_scene(
        scene: Arc<TraceScene>,
        origin: &str,
        request: &SceneRequest,
    ) -> Result<SceneSetup, String> {
        let camera = camera(request, &scene).map_err(|e| format!("error: bad camera: {e}"))?;
        let description = format!(
            "{origin} ({} triangles), {}x{}",
            scene.mesh.triangles.len(),
            camera.width,
            camera.height
        );
        let mut resources = TraceResources::new(scene, Arc::new(CameraSetup::new(camera.clone())));
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
        Ok(SceneSetup {
            uniforms,
            resources,
            camera,
            description,
        })
    }
}

/// The scene a request names, its BVH built, and where it came from (for messages).
pub fn load_scene(
    request: &SceneRequest,
    library: &FunctorLibrary,
    progress: &Progress,
) -> Result<(TraceScene, String), String> {
    match &request.scene {
        None => {
            progress.phase("generating the built-in scene");
            let failed =
                |e: &dyn std::fmt::Display| format!("error: the built-in scene failed: {e}");
            let mesh = builtin_scene(DEFAULT_RESOLUTION).map_err(|e| failed(&e))?;
            let scene = trace_scene(mesh, MeshMaterials::default(), progress, failed)?;
            Ok((scene, "built-in mixing layer".to_string()))
        }
        Some(path) if volume_setup::is_volume_path(path) || request.raw.is_some() => Ok((
            volume_scene(request, path, library, progress)?,
            path.display().to_string(),
        )),
        Some(path) => {
            progress.phase(format!("loading {}", path.display()));
            let (mesh, materials) = load_mesh(path)?;
            let scene = trace_scene(mesh, materials, progress, |e| {
                format!("error: cannot use scene `{}`: {e}", path.display())
            })?;
            Ok((scene, path.display().to_string()))
        }
    }
}

/// A loaded mesh made ready to trace, in the phases `progress` shows: vertex
/// normals (for a mesh without them), then the BVH. `failed` words an error.
fn trace_scene(
    mut mesh: TriangleMesh,
    materials: MeshMaterials,
    progress: &Progress,
    failed: impl Fn(&dyn std::fmt::Display) -> String,
) -> Result<TraceScene, String> {
    if mesh.normals.is_none() {
        // Checked first (the BVH build checks it too): normals of a broken
        // mesh are not worth computing. The same words as the build's.
        mesh.validate()
            .map_err(|e| failed(&dpp_tracer::scene::SceneError::Mesh(e)))?;
        progress.phase(format!(
            "vertex normals of {} triangles",
            mesh.triangles.len()
        ));
        mesh.add_crease_normals(dpp_tracer::scene::CREASE_ANGLE_DEGREES.to_radians());
    }
    progress.phase(format!("BVH over {} triangles", mesh.triangles.len()));
    TraceScene::with_materials(mesh, materials).map_err(|e| failed(&e))
}

/// A mesh file by its extension: `.obj` (with its MTL materials), `.ply`, or
/// either gzip-compressed (`.obj.gz`: no materials).
pub fn load_mesh(path: &Path) -> Result<(TriangleMesh, MeshMaterials), String> {
    let cannot =
        |e: &dyn std::fmt::Display| format!("error: cannot use scene `{}`: {e}", path.display());
    let name = path.to_string_lossy().to_ascii_lowercase();
    if name.ends_with(".obj") {
        dpp_tracer::obj::load_obj_with_materials(path).map_err(|e| cannot(&e))
    } else if name.ends_with(".obj.gz") {
        let mut reader = dpp_tracer::ply::open_maybe_gzipped(path)
            .map_err(|e| format!("error: cannot open {}: {e}", path.display()))?;
        let mesh = dpp_tracer::obj::read_obj(&mut reader).map_err(|e| cannot(&e))?;
        Ok((mesh, MeshMaterials::default()))
    } else if name.ends_with(".ply") || name.ends_with(".ply.gz") {
        let mesh = dpp_tracer::ply::load_ply(path).map_err(|e| format!("error: {e}"))?;
        Ok((mesh, MeshMaterials::default()))
    } else {
        Err(format!(
            "error: cannot read scene `{}`: dpp reads .obj and .ply meshes (also gzip-compressed, .obj.gz, .ply.gz) and .nii/.nii.gz volumes (raw bricks with --raw)",
            path.display()
        ))
    }
}

/// The isosurface of a volume, coloured by height or by a second field.
pub fn volume_scene(
    request: &SceneRequest,
    path: &Path,
    library: &FunctorLibrary,
    progress: &Progress,
) -> Result<TraceScene, String> {
    progress.phase(format!("loading {}", path.display()));
    let volume = volume_setup::load_volume(path, request.raw.as_deref())?;
    let Some(level) = request.iso else {
        let range = volume.value_range().map_or(String::new(), |(lo, hi)| {
            format!(" (its values run from {lo} to {hi})")
        });
        return Err(format!(
            "error: `{}` is a volume: give the isosurface level with --iso LEVEL{range}",
            path.display()
        ));
    };
    let iso = IsoRequest {
        level,
        pipeline: request.iso_pipeline.clone(),
        fuse: request.fuse,
    };
    progress.phase(format!("isosurface at level {level}"));
    let mut mesh = volume_setup::isosurface(volume, &iso, library)?;
    // The surface's own values all equal the level: colour by height, or by a second field.
    mesh.scalars = None;
    if let Some(field) = &request.color_by {
        progress.phase(format!("colouring by {}", field.display()));
        let field = volume_setup::load_volume(field, None)?;
        volume_setup::color_by(&mut mesh, &field);
    }
    trace_scene(mesh, MeshMaterials::default(), progress, |e| {
        format!("error: the isosurface of `{}`: {e}", path.display())
    })
}

/// The scene file given, or `mesh.toml` beside `mesh.obj` (`mesh.ply`, `mesh.obj.gz`…) when there is one.
fn scene_file(request: &SceneRequest) -> Option<PathBuf> {
    if request.scene_file.is_some() {
        return request.scene_file.clone();
    }
    let scene = request.scene.as_deref()?;
    let stem = scene.file_name()?.to_string_lossy();
    let stem = stem.strip_suffix(".gz").unwrap_or(&stem);
    let beside = scene.with_file_name(Path::new(stem).with_extension("toml"));
    beside.exists().then_some(beside)
}

/// A standard view of the scene's bounds, with any of eye, look-at and up
/// replaced. With both eye and look-at given no standard view is needed (a
/// scene too large for one can still be seen).
fn camera(request: &SceneRequest, scene: &TraceScene) -> Result<Camera, String> {
    let view: StandardView = request.view.parse().map_err(|e| format!("{e}"))?;
    let (width, height) = request.size;
    let pick = |given: Option<[f32; 3]>, default: Vec3| given.map_or(default, Vec3::from);
    let (eye, look_at, up) = match (request.eye, request.look_at) {
        (Some(eye), Some(look_at)) => (Vec3::from(eye), Vec3::from(look_at), Vec3::Y),
        _ => {
            let standard =
                Camera::standard(view, &scene.bounds, width, height).map_err(|e| e.to_string())?;
            (
                pick(request.eye, standard.eye),
                pick(request.look_at, standard.look_at),
                standard.up,
            )
        }
    };
    Camera::new(
        eye,
        look_at,
        pick(request.up, up),
        request.fov,
        width,
        height,
    )
    .map_err(|e| e.to_string())
}
