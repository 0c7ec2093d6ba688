//! From command-line arguments to what a run reads: the scene (a mesh, the
//! isosurface of a volume, or the built-in scene; BVH built once, outside any
//! frame), the camera, the shading and the uniforms.

use crate::distributed::{self, Distribution};
use crate::progress::Progress;
use crate::volume_setup::{self, IsoRequest};
use dpp_runtime::{FunctorLibrary, Uniforms};
use dpp_tracer::builtin_scene::{builtin_scene, DEFAULT_RESOLUTION};
use dpp_tracer::bvh::BvhBuilder;
use dpp_tracer::camera::tile_owner;
use dpp_tracer::shading::MeshMaterials;
use dpp_tracer::volume::generate::Dataset;
use dpp_tracer::{
    Camera, CameraSetup, SceneFile, ShadingOverrides, StandardView, TraceResources, TraceScene,
    TriangleMesh,
};
use glam::Vec3;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// A scene as the command line names it (`dpp run` and `dpp bench` alike).
#[derive(Clone, Debug, PartialEq)]
pub enum SceneSpec {
    /// `builtin`, `builtin:RESOLUTION`: the built-in mixing layer.
    Builtin(u32),
    /// `rm:X,Y,Z`, `pbte:X,Y,Z`, `sphere:X,Y,Z` (or one size for all three):
    /// one of the paper's data sets generated on that grid, as a volume.
    Generated(Dataset, [u32; 3]),
    /// A mesh or volume file.
    File(PathBuf),
}

impl SceneSpec {
    pub fn parse(text: &str) -> Result<SceneSpec, String> {
        if text == "builtin" {
            return Ok(SceneSpec::Builtin(DEFAULT_RESOLUTION));
        }
        if let Some(resolution) = text.strip_prefix("builtin:") {
            let resolution: u32 = resolution.parse().map_err(|_| {
                format!("error: `{text}`: the built-in scene's resolution is a whole number (like builtin:224)")
            })?;
            let range = dpp_tracer::builtin_scene::MIN_RESOLUTION
                ..=dpp_tracer::builtin_scene::MAX_RESOLUTION;
            if !range.contains(&resolution) {
                return Err(format!(
                    "error: `{text}`: the built-in scene's resolution must be in {}..={}",
                    range.start(),
                    range.end()
                ));
            }
            return Ok(SceneSpec::Builtin(resolution));
        }
        let path = PathBuf::from(text);
        if let Some((name, grid)) = text.split_once(':').filter(|_| !path.exists()) {
            if let Ok(dataset) = Dataset::from_name(name) {
                let grid = match crate::parse_grid(grid) {
                    Ok(grid) => grid,
                    Err(_) => match grid.parse::<u32>() {
                        Ok(n) => [n; 3],
                        Err(_) => {
                            return Err(format!(
                                "error: `{text}`: give the volume's grid as {name}:X,Y,Z (like {name}:128,128,128)"
                            ))
                        }
                    },
                };
                if grid.iter().any(|&n| !(4..=1024).contains(&n)) {
                    return Err(format!(
                        "error: `{text}`: each grid size must be in 4..=1024"
                    ));
                }
                return Ok(SceneSpec::Generated(dataset, grid));
            }
        }
        if !path.is_file() {
            return Err(format!(
                "error: scene `{text}` is not a file (nor builtin, builtin:RESOLUTION, or a generated volume rm:X,Y,Z, pbte:X,Y,Z, sphere:X,Y,Z)"
            ));
        }
        Ok(SceneSpec::File(path))
    }

    pub fn name(&self) -> String {
        match self {
            SceneSpec::Builtin(resolution) => format!("builtin:{resolution}"),
            SceneSpec::Generated(dataset, [x, y, z]) => {
                format!("{}:{x},{y},{z}", dataset_name(*dataset))
            }
            SceneSpec::File(path) => path.file_name().map_or_else(
                || path.display().to_string(),
                |n| n.to_string_lossy().into(),
            ),
        }
    }

    /// Whether the scene is a volume, made a mesh by an isosurface.
    pub fn is_volume(&self, raw: Option<&str>) -> bool {
        match self {
            SceneSpec::Builtin(_) => false,
            SceneSpec::Generated(..) => true,
            SceneSpec::File(path) => volume_setup::is_volume_path(path) || raw.is_some(),
        }
    }
}

pub struct SceneRequest {
    /// The scene, or its pieces (mesh files, loaded together in one process
    /// and dealt out to ranks in a distributed run); empty: the built-in one.
    pub scenes: Vec<SceneSpec>,
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
    /// The pipeline renders a volume directly (it reads `volume.*` besides
    /// the camera): the volume goes to the functors, its box is the scene.
    pub render_volume: bool,
    /// The pipeline intersects a surface (`map<intersect>`): a volume it
    /// renders has its isosurface (`--iso`) inside (pipelines/volume_surface.dpp).
    pub traces_surface: bool,
    /// For a VTK file: the array to use (`NAME`, `NAME:mag`, `NAME:0`).
    pub field: Option<String>,
    /// How the BVH is built.
    pub bvh: BvhBuilder,
}

/// What a rank's share of a distributed run changes in its set-up.
#[derive(Clone, Debug, Default)]
pub struct RankShare {
    /// The colour map's range over the whole data, agreed by the ranks
    /// (before a scene file or `--scalar-range` replaces it).
    pub scalar_range: Option<[f32; 2]>,
    /// Image decomposition: `(rank, ranks)`, tracing only this rank's tiles.
    pub traced_tiles: Option<(usize, usize)>,
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
        distribution: &Distribution,
    ) -> Result<SceneSetup, String> {
        if request.render_volume {
            return distribution.agree(volume_rendering(request, library, progress, distribution));
        }
        let (scene, origin, share) = load_share(request, library, progress, distribution)?;
        distribution.agree(SceneSetup::with_scene(
            Arc::new(scene),
            &origin,
            request,
            &share,
        ))
    }

    /// The camera, shading and uniforms of an already loaded scene (`dpp bench`
    /// builds each scene once and looks at it from several views), with what
    /// this rank's share of a distributed run changes.
    pub fn with_scene(
        scene: Arc<TraceScene>,
        origin: &str,
        request: &SceneRequest,
        share: &RankShare,
    ) -> Result<SceneSetup, String> {
        let camera = camera(request, &scene).map_err(|e| format!("error: bad camera: {e}"))?;
        let description = format!(
            "{origin} ({} triangles), {}x{}",
            scene.mesh.triangles.len(),
            camera.width,
            camera.height
        );
        let camera_setup = match share.traced_tiles {
            Some((rank, ranks)) => CameraSetup::tracing_only(camera.clone(), |pixel| {
                tile_owner(pixel, camera.width, ranks) == rank
            }),
            None => CameraSetup::new(camera.clone()),
        };
        let mut resources = TraceResources::new(scene, Arc::new(camera_setup));
        let shading = Arc::make_mut(&mut resources.shading);
        if let Some([min, max]) = share.scalar_range {
            shading
                .set_scalar_range(min, max)
                .map_err(|e| format!("error: {e}"))?;
        }
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

/// This rank's scene (all of it, or only its part under data decomposition),
/// where it came from, and what its share changes in the set-up.
pub fn load_share(
    request: &SceneRequest,
    library: &FunctorLibrary,
    progress: &Progress,
    distribution: &Distribution,
) -> Result<(TraceScene, String, RankShare), String> {
    if distribution.splits_data() {
        let part = distributed::load_part(request, library, progress, distribution)?;
        let share = RankShare {
            scalar_range: Some(part.scalar_range),
            traced_tiles: None,
        };
        return Ok((part.scene, part.origin, share));
    }
    let share = RankShare {
        scalar_range: None,
        traced_tiles: (distribution.size() > 1).then(|| (distribution.rank(), distribution.size())),
    };
    let loaded = load_scene(request, library, progress);
    let (scene, origin) = distribution.agree(loaded)?;
    Ok((scene, origin, share))
}

/// The isosurface level of a volume scene: `--iso`, else a generated data
/// set's own; `range` (the volume's values, where known) helps choose one.
pub fn iso_level(
    request: &SceneRequest,
    spec: &SceneSpec,
    range: Option<(f32, f32)>,
) -> Result<f32, String> {
    match (request.iso, spec) {
        (Some(level), _) => Ok(level),
        (None, SceneSpec::Generated(dataset, _)) => Ok(dataset.default_level()),
        (None, _) => {
            let range = range.map_or(String::new(), |(lo, hi)| {
                format!(" (its values run from {lo} to {hi})")
            });
            Err(format!(
                "error: `{}` is a volume: give the isosurface level with --iso LEVEL{range}",
                spec.name()
            ))
        }
    }
}

/// The scene a request names, its BVH built, and where it came from (for messages).
pub fn load_scene(
    request: &SceneRequest,
    library: &FunctorLibrary,
    progress: &Progress,
) -> Result<(TraceScene, String), String> {
    let builtin = [SceneSpec::Builtin(DEFAULT_RESOLUTION)];
    let scenes = if request.scenes.is_empty() {
        &builtin[..]
    } else {
        &request.scenes[..]
    };
    match scenes {
        [SceneSpec::Builtin(resolution)] => {
            progress.phase("generating the built-in scene");
            let failed =
                |e: &dyn std::fmt::Display| format!("error: the built-in scene failed: {e}");
            let mesh = builtin_scene(*resolution).map_err(|e| failed(&e))?;
            let scene = trace_scene(
                mesh,
                MeshMaterials::default(),
                request.bvh,
                progress,
                failed,
            )?;
            Ok((scene, "built-in mixing layer".to_string()))
        }
        [spec] if spec.is_volume(request.raw.as_deref()) => {
            Ok((volume_scene(request, spec, library, progress)?, spec.name()))
        }
        [SceneSpec::File(path)] => {
            progress.phase(format!("loading {}", path.display()));
            let (mesh, materials) = load_mesh(path, request.field.as_deref())?;
            let scene = trace_scene(mesh, materials, request.bvh, progress, |e| {
                format!("error: cannot use scene `{}`: {e}", path.display())
            })?;
            Ok((scene, path.display().to_string()))
        }
        pieces => {
            let paths = piece_paths(pieces, request.raw.as_deref())?;
            let mut meshes = Vec::with_capacity(paths.len());
            for path in &paths {
                progress.phase(format!("loading {}", path.display()));
                meshes.push(load_mesh(path, request.field.as_deref())?.0);
            }
            let origin = format!("{} pieces", paths.len());
            let scene = trace_scene(
                concat_meshes(meshes),
                MeshMaterials::default(),
                request.bvh,
                progress,
                |e| format!("error: cannot use the pieces: {e}"),
            )?;
            Ok((scene, origin))
        }
    }
}

/// The files of a scene given as several pieces: mesh files only.
pub fn piece_paths(pieces: &[SceneSpec], raw: Option<&str>) -> Result<Vec<PathBuf>, String> {
    pieces
        .iter()
        .map(|piece| match piece {
            SceneSpec::File(path) if !piece.is_volume(raw) => Ok(path.clone()),
            other => Err(format!(
                "error: `{}`: a scene in several pieces is mesh files only (.obj, .ply, gzipped too, VTK meshes); give a volume or a built-in scene alone",
                other.name()
            )),
        })
        .collect()
}

/// One mesh of several, in their order: triangle ids run on from piece to
/// piece, as `prim` numbers them. Normals and scalars stay only where every
/// piece has them (they are computed for the whole otherwise); the pieces'
/// own materials are not kept.
pub fn concat_meshes(meshes: Vec<TriangleMesh>) -> TriangleMesh {
    let all_have = |has: fn(&TriangleMesh) -> bool| meshes.iter().all(has);
    let (with_normals, with_scalars) = (
        all_have(|m| m.normals.is_some()),
        all_have(|m| m.scalars.is_some()),
    );
    let mut whole = TriangleMesh {
        positions: Vec::new(),
        triangles: Vec::new(),
        normals: with_normals.then(Vec::new),
        scalars: with_scalars.then(Vec::new),
    };
    for mesh in meshes {
        let first = whole.positions.len() as u32;
        whole.positions.extend(&mesh.positions);
        (whole.triangles).extend(mesh.triangles.iter().map(|t| t.map(|v| v + first)));
        if let (Some(all), Some(own)) = (&mut whole.normals, &mesh.normals) {
            all.extend(own);
        }
        if let (Some(all), Some(own)) = (&mut whole.scalars, &mesh.scalars) {
            all.extend(own);
        }
    }
    whole
}

/// A loaded mesh made ready to trace, in the phases `progress` shows: vertex
/// normals (for a mesh without them), then the BVH. `failed` words an error.
pub fn trace_scene(
    mut mesh: TriangleMesh,
    materials: MeshMaterials,
    bvh: BvhBuilder,
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
    TraceScene::built_with(mesh, materials, bvh).map_err(|e| failed(&e))
}

/// A mesh file by its extension: `.obj` (with its MTL materials), `.ply`, or
/// either gzip-compressed (`.obj.gz`: no materials), or VTK (`.vtp`, `.vtu`,
/// a legacy `.vtk`, the pieces of a `.pvtp` or `.pvtu` joined in order),
/// whose array `field` chooses becomes the scalars.
pub fn load_mesh(
    path: &Path,
    field: Option<&str>,
) -> Result<(TriangleMesh, MeshMaterials), String> {
    let cannot =
        |e: &dyn std::fmt::Display| format!("error: cannot use scene `{}`: {e}", path.display());
    let name = path.to_string_lossy().to_ascii_lowercase();
    if dpp_tracer::vtk::VtkKind::of(path).is_some() {
        let choice = volume_setup::field_choice(field)?;
        let pieces = dpp_tracer::vtk::mesh::read_mesh_pieces(path, &choice)
            .map_err(|e| format!("error: {e}"))?;
        return Ok((concat_meshes(pieces), MeshMaterials::default()));
    }
    if let Some(field) = field {
        return Err(format!(
            "error: --field {field} chooses an array of a VTK file; {} has none",
            path.display()
        ));
    }
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
            "error: cannot read scene `{}`: dpp reads .obj and .ply meshes (also gzip-compressed, .obj.gz, .ply.gz), VTK meshes (.vtp, .vtu, .pvtp, .pvtu, legacy .vtk), .nii/.nii.gz and VTK volumes (.vti, .pvti, legacy .vtk; raw bricks with --raw)",
            path.display()
        ))
    }
}

/// The set-up of a pipeline that renders the volume itself: the volume with
/// the functors, the scalar range its values' by default, and its box as the
/// scene.
fn volume_rendering(
    request: &SceneRequest,
    library: &FunctorLibrary,
    progress: &Progress,
    distribution: &Distribution,
) -> Result<SceneSetup, String> {
    let spec = match &request.scenes[..] {
        [spec] if spec.is_volume(request.raw.as_deref()) => spec,
        _ => {
            return Err(
                "error: a pipeline that reads `volume.*` and the camera renders a volume: give one volume as the scene (a .nii or .nii.gz file, a raw brick with --raw, or a generated rm:X,Y,Z, pbte:X,Y,Z, sphere:X,Y,Z)"
                    .into(),
            )
        }
    };
    if distribution.size() > 1 {
        return Err("error: volume rendering runs in one process (not under mpirun yet)".into());
    }
    let given = [
        request.iso.is_some(),
        request.color_by.is_some(),
        request.iso_pipeline.is_some(),
    ];
    match (isosurface_option(given), request.traces_surface) {
        (Some(option), false) => {
            return Err(format!(
                "error: {option} is for pipelines that trace a volume's isosurface; a volume-rendering pipeline renders the volume itself (its params: --set NAME=VALUE)"
            ))
        }
        (None, true) if request.iso.is_none() => {
            return Err("error: this pipeline renders a volume with its isosurface inside: give the surface's level with --iso LEVEL".into())
        }
        _ => {}
    }
    let volume = load_volume_spec(request, spec, progress)?;
    let range = dpp_tracer::shading::default_scalar_range(&volume.values);
    let origin = spec.name();
    let scene = if request.traces_surface {
        // The surface takes the transfer function's colour at its level,
        // unless --color-by gives another field.
        isosurface_scene(request, spec, volume.clone(), library, progress, true)?
    } else {
        trace_scene(
            box_mesh(&volume.bounds()),
            MeshMaterials::default(),
            request.bvh,
            progress,
            |e| format!("error: the box of `{origin}`: {e}"),
        )?
    };
    let share = RankShare {
        scalar_range: Some(range),
        traced_tiles: None,
    };
    let description = format!(
        "the volume {} ({}x{}x{} samples)",
        spec.name(),
        volume.dims.x,
        volume.dims.y,
        volume.dims.z
    );
    let mut setup = SceneSetup::with_scene(Arc::new(scene), &origin, request, &share)?;
    setup.resources.volume = Some(Arc::new(volume));
    setup.uniforms = setup.resources.uniforms();
    setup.description = format!("{description}, {}", setup.description);
    Ok(setup)
}

/// The first of `--iso`, `--color-by`, `--iso-pipeline` that `given` says
/// was given: options for tracing a volume's isosurface, which a pipeline
/// that reads the volume itself refuses.
pub fn isosurface_option(given: [bool; 3]) -> Option<&'static str> {
    let options = ["--iso", "--color-by", "--iso-pipeline"];
    options
        .into_iter()
        .zip(given)
        .find(|(_, given)| *given)
        .map(|(option, _)| option)
}

/// The 12 triangles of a box: the scene of a volume rendered without a
/// surface (the camera's standard views frame it).
fn box_mesh(bounds: &dpp_tracer::mesh::Bounds) -> TriangleMesh {
    let corner = |i: u32| {
        let pick = |bit: u32, lo: f32, hi: f32| if i >> bit & 1 == 1 { hi } else { lo };
        Vec3::new(
            pick(0, bounds.min.x, bounds.max.x),
            pick(1, bounds.min.y, bounds.max.y),
            pick(2, bounds.min.z, bounds.max.z),
        )
    };
    // Two triangles per face, counter-clockwise seen from outside.
    let faces = [
        [0, 4, 6, 2],
        [1, 3, 7, 5],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 2, 3, 1],
        [4, 5, 7, 6],
    ];
    TriangleMesh {
        positions: (0..8).map(corner).collect(),
        triangles: faces
            .iter()
            .flat_map(|[a, b, c, d]| [[*a, *b, *c], [*a, *c, *d]])
            .collect(),
        normals: None,
        scalars: None,
    }
}

/// A volume scene's samples: a generated data set or a file.
fn load_volume_spec(
    request: &SceneRequest,
    spec: &SceneSpec,
    progress: &Progress,
) -> Result<dpp_tracer::volume::Volume, String> {
    match spec {
        SceneSpec::Generated(dataset, grid) => {
            progress.phase(format!("generating {}", spec.name()));
            (dataset.generate(glam::UVec3::from(*grid))).map_err(|e| format!("error: {e}"))
        }
        SceneSpec::File(path) => {
            progress.phase(format!("loading {}", path.display()));
            volume_setup::load_volume(path, request.raw.as_deref(), request.field.as_deref())
        }
        SceneSpec::Builtin(_) => Err("error: the built-in scene is not a volume".into()),
    }
}

/// The isosurface of a volume, coloured by height or by a second field.
pub fn volume_scene(
    request: &SceneRequest,
    spec: &SceneSpec,
    library: &FunctorLibrary,
    progress: &Progress,
) -> Result<TraceScene, String> {
    let volume = load_volume_spec(request, spec, progress)?;
    isosurface_scene(request, spec, volume, library, progress, false)
}

/// The isosurface of `volume` at the run's level as the traced scene,
/// coloured by `--color-by`'s field, else by height, or, `at_level`, by the
/// level itself (every vertex's scalar).
fn isosurface_scene(
    request: &SceneRequest,
    spec: &SceneSpec,
    volume: dpp_tracer::volume::Volume,
    library: &FunctorLibrary,
    progress: &Progress,
    at_level: bool,
) -> Result<TraceScene, String> {
    let level = iso_level(request, spec, volume.value_range())?;
    let iso = IsoRequest {
        level,
        pipeline: request.iso_pipeline.clone(),
        fuse: request.fuse,
    };
    progress.phase(format!("isosurface at level {level}"));
    let mut mesh = volume_setup::isosurface(volume, &iso, library)?;
    // The surface's own values all equal the level: colour by height, or by a second field.
    mesh.scalars = at_level.then(|| vec![level; mesh.positions.len()]);
    if let Some(field) = &request.color_by {
        progress.phase(format!("colouring by {}", field.display()));
        let field = volume_setup::load_volume(field, None, None)?;
        volume_setup::color_by(&mut mesh, &field);
    }
    trace_scene(mesh, MeshMaterials::default(), request.bvh, progress, |e| {
        format!("error: the isosurface of `{}`: {e}", spec.name())
    })
}

/// The scene file given, or `mesh.toml` beside `mesh.obj` (`mesh.ply`, `mesh.obj.gz`…) when there is one.
fn scene_file(request: &SceneRequest) -> Option<PathBuf> {
    if request.scene_file.is_some() {
        return request.scene_file.clone();
    }
    let [SceneSpec::File(scene)] = &request.scenes[..] else {
        return None;
    };
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

/// The short name a generated data set goes by on the command line.
fn dataset_name(dataset: Dataset) -> &'static str {
    match dataset {
        Dataset::RichtmyerMeshkov => "rm",
        Dataset::LeadTelluride => "pbte",
        Dataset::Sphere => "sphere",
    }
}
