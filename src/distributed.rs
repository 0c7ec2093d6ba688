//! Runs across ranks (`mpirun -n N dpp run …`, one dpp per rank, every rank
//! given the same command line): which part of the data or of the image is
//! this rank's, the facts the ranks agree on (scene bounds, the colour map's
//! range, triangle ids), and the compositor that meets the other ranks where
//! the pipeline says `composite` (docs/language.md §3). A process started
//! without `mpirun`, or a build without the `mpi` feature, is one rank, and
//! nothing here changes what it does.
//!
//! Failures while setting up are agreed ([`Distribution::agree`]): every rank
//! learns that some rank failed and exits with that rank's message and exit
//! status, instead of waiting forever for it in the next collective.

use crate::progress::Progress;
use crate::scene_setup::{self, SceneRequest, SceneSpec};
use crate::volume_setup::{self, IsoRequest};
use clap::ValueEnum;
use dpp_dist::{composite, gather_pieces, CompositeSchedule, CompositeStats, Ranks};
use dpp_runtime::interpret::{Blend, Compositor, RunError};
use dpp_runtime::{Column, ErrorKind, FunctorLibrary, RecordRegistry};
use dpp_tracer::builtin_scene::{builtin_scene, DEFAULT_RESOLUTION};
use dpp_tracer::camera::tile_owner;
use dpp_tracer::functors::isosurface::{corner_bounds, welded_mesh};
use dpp_tracer::mesh::Bounds;
use dpp_tracer::partition::{
    assign_pieces, count_triangles, piece_offsets, spatial_part, split_materials, sub_mesh,
};
use dpp_tracer::shading::{default_scalar_range, MeshMaterials};
use dpp_tracer::volume::brick::{
    global_triangle_ids, kd_bricks, owned_triangles, triangle_summary,
};
use dpp_tracer::volume::raw::RawSpec;
use dpp_tracer::volume::Volume;
use dpp_tracer::vtk::VtkKind;
use dpp_tracer::{TraceScene, TriangleMesh};
use glam::UVec3;
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// How the work is shared out among the ranks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Decompose {
    /// Each rank holds only its part of the data and renders all of the
    /// image from it; the images are composited (sort-last).
    Data,
    /// Each rank holds all the data and renders its share of the image
    /// (interleaved tiles); rank 0 gathers the pieces.
    Image,
}

/// This process's place in a run, and how the run is shared out.
pub struct Distribution {
    ranks: Ranks,
    pub decompose: Decompose,
    pub schedule: CompositeSchedule,
}

impl Distribution {
    /// Joins the run's ranks (a single rank outside `mpirun`).
    pub fn init(decompose: Decompose, schedule: CompositeSchedule) -> Result<Distribution, String> {
        let ranks = Ranks::init().map_err(|e| format!("cannot join the ranks: {e}"))?;
        Ok(Distribution {
            ranks,
            decompose,
            schedule,
        })
    }

    pub fn rank(&self) -> usize {
        self.ranks.rank()
    }

    pub fn size(&self) -> usize {
        self.ranks.size()
    }

    pub fn ranks(&self) -> &Ranks {
        &self.ranks
    }

    /// Whether this rank holds only its part of the data.
    pub fn splits_data(&self) -> bool {
        self.size() > 1 && self.decompose == Decompose::Data
    }

    /// A step that may fail on some ranks, agreed: if any rank failed, every
    /// rank returns the lowest failing rank's message (as the set-up's errors
    /// are: `error: …`, the user's input, exit status 2).
    pub fn agree<T>(&self, result: Result<T, String>) -> Result<T, String> {
        if self.size() == 1 {
            return result;
        }
        let strip = |message: String| match message.strip_prefix("error: ") {
            Some(rest) => rest.to_string(),
            None => message,
        };
        let result = result.map_err(|message| RunError::bad_input(strip(message)));
        self.ranks
            .agree(result)
            .map_err(|error| format!("error: {}", error.message))
    }

    /// Checks that every rank was given the same command line: ranks that
    /// disagree would wait for each other in different collectives.
    pub fn check_same_command_line(&self) -> Result<(), String> {
        if self.size() == 1 {
            return Ok(());
        }
        let arguments: Vec<String> = std::env::args().skip(1).collect();
        self.ranks
            .same_on_every_rank("the command line", arguments.join("\0").as_bytes())
            .map_err(|e| format!("error: {}", e.message))
    }

    /// The compositor for a run on `width`-pixel-wide images; `None` for a
    /// single rank, whose `composite` is the identity.
    pub fn compositor<'a>(
        &'a self,
        records: &'a RecordRegistry,
        width: u32,
        visibility_order: Vec<usize>,
    ) -> Option<RankCompositor<'a>> {
        (self.size() > 1).then(|| RankCompositor {
            distribution: self,
            records,
            width,
            visibility_order,
            stats: Mutex::new(None),
        })
    }

    /// The box around every rank's data, from each rank's own (`None` for a rank without data).
    pub fn all_bounds(&self, mine: Option<Bounds>) -> Option<Bounds> {
        let mut low = mine.map_or([f32::INFINITY; 3], |b| b.min.to_array());
        let mut high = mine.map_or([f32::NEG_INFINITY; 3], |b| b.max.to_array());
        self.ranks.all_min_f32(&mut low);
        self.ranks.all_max_f32(&mut high);
        (low[0] <= high[0]).then(|| Bounds {
            min: low.into(),
            max: high.into(),
        })
    }

    /// Every rank's data bounds, in rank order (for the visibility order).
    pub fn every_rank_bounds(&self, mine: Bounds) -> Vec<Bounds> {
        let bytes: Vec<u8> = (mine.min.to_array().iter())
            .chain(&mine.max.to_array())
            .flat_map(|v| v.to_le_bytes())
            .collect();
        (self.ranks.all_gather_bytes(&bytes).iter())
            .map(|bytes| {
                let value = |i: usize| {
                    f32::from_le_bytes(bytes[4 * i..4 * i + 4].try_into().unwrap_or([0; 4]))
                };
                Bounds {
                    min: [value(0), value(1), value(2)].into(),
                    max: [value(3), value(4), value(5)].into(),
                }
            })
            .collect()
    }
}

/// Meets the other ranks at a pipeline's `composite`: the run's schedule
/// under data decomposition, the gathering of tiles under image decomposition.
pub struct RankCompositor<'a> {
    distribution: &'a Distribution,
    records: &'a RecordRegistry,
    width: u32,
    /// The ranks front to back from the camera, for `visibility: true`.
    visibility_order: Vec<usize>,
    stats: Mutex<Option<CompositeStats>>,
}

impl RankCompositor<'_> {
    /// What the compositing measured, once it ran (data decomposition).
    pub fn stats(&self) -> Option<CompositeStats> {
        self.stats.lock().ok()?.clone()
    }
}

impl Compositor for RankCompositor<'_> {
    fn composite(
        &self,
        fragments: Vec<Arc<Column>>,
        visibility: bool,
        blend: &mut Blend<'_>,
    ) -> Result<Option<Vec<Arc<Column>>>, RunError> {
        let ranks = self.distribution.ranks();
        match self.distribution.decompose {
            Decompose::Image => {
                let (width, size) = (self.width, ranks.size());
                let owner = |pixel: usize| tile_owner(pixel as u32, width, size);
                gather_pieces(ranks, fragments, &owner, self.records)
            }
            Decompose::Data => {
                let order: Vec<usize> = if visibility {
                    self.visibility_order.clone()
                } else {
                    (0..ranks.size()).collect()
                };
                let composited = composite(
                    ranks,
                    &self.distribution.schedule,
                    fragments,
                    &order,
                    self.records,
                    blend,
                )?;
                if let Ok(mut stats) = self.stats.lock() {
                    *stats = Some(composited.stats);
                }
                Ok(composited.image)
            }
        }
    }
}

/// The ranks front to back as seen from `eye`, for translucent compositing
/// of data split by a k-d tree: the boxes are split again by the plane that
/// separates them (a k-d split always leaves one), the side of the eye first.
pub fn visibility_order(boxes: &[Bounds], eye: glam::Vec3) -> Vec<usize> {
    fn order(boxes: &[Bounds], members: Vec<usize>, eye: glam::Vec3, out: &mut Vec<usize>) {
        if members.len() <= 1 {
            out.extend(members);
            return;
        }
        for axis in 0..3 {
            let mut planes: Vec<f32> = members.iter().map(|&i| boxes[i].max[axis]).collect();
            planes.sort_by(f32::total_cmp);
            for &plane in &planes {
                let (low, high): (Vec<usize>, Vec<usize>) =
                    members.iter().partition(|&&i| boxes[i].max[axis] <= plane);
                if low.is_empty() || high.is_empty() {
                    continue;
                }
                if high.iter().all(|&i| boxes[i].min[axis] >= plane) {
                    let (near, far) = if eye[axis] <= plane {
                        (low, high)
                    } else {
                        (high, low)
                    };
                    order(boxes, near, eye, out);
                    order(boxes, far, eye, out);
                    return;
                }
            }
        }
        // Boxes no plane separates (not a k-d split): nearest centre first.
        let mut members = members;
        members.sort_by(|&a, &b| {
            let distance = |i: usize| boxes[i].center().distance_squared(eye);
            distance(a).total_cmp(&distance(b)).then(a.cmp(&b))
        });
        out.extend(members);
    }
    let mut out = Vec::with_capacity(boxes.len());
    order(boxes, (0..boxes.len()).collect(), eye, &mut out);
    out
}

/// One rank's share of a distributed run, as a line of `--profile`'s table:
/// gathered on rank 0, empty elsewhere.
pub fn rank_report(
    distribution: &Distribution,
    triangles: usize,
    render: Duration,
    stats: Option<&CompositeStats>,
) -> Vec<String> {
    let rss = peak_rss_bytes().map_or("?".to_string(), |b| format!("{:.0}", b as f64 / 1e6));
    let (composite, rounds, sent) = match stats {
        Some(stats) => {
            let total = stats.rounds.iter().map(|r| r.time).sum::<Duration>() + stats.gather.time;
            let rounds: Vec<String> = (stats.rounds.iter())
                .map(|r| format!("{:.1}", r.time.as_secs_f64() * 1e3))
                .collect();
            let sent =
                stats.rounds.iter().map(|r| r.bytes_sent).sum::<u64>() + stats.gather.bytes_sent;
            (
                format!("{:.1}", total.as_secs_f64() * 1e3),
                rounds.join("+"),
                format!("{:.2}", sent as f64 / 1e6),
            )
        }
        None => ("-".into(), "-".into(), "-".into()),
    };
    let line = format!(
        "{:>5} {:>11} {:>10.1} {:>9} {:>16} {:>9} {:>9}",
        distribution.rank(),
        triangles,
        render.as_secs_f64() * 1e3,
        composite,
        rounds,
        sent,
        rss
    );
    let lines = distribution.ranks().all_gather_bytes(line.as_bytes());
    if !distribution.ranks().is_root() {
        return Vec::new();
    }
    let mut table = vec![format!(
        "{:>5} {:>11} {:>10} {:>9} {:>16} {:>9} {:>9}",
        "rank", "triangles", "run ms", "comp. ms", "rounds ms", "sent MB", "peak MB"
    )];
    table.extend(
        lines
            .iter()
            .map(|l| String::from_utf8_lossy(l).into_owned()),
    );
    table
}

/// The process's peak resident memory (VmHWM), where the system says it.
pub fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// A run-time failure on one rank in the middle of a distributed run: the
/// other ranks may be waiting for it in a collective, so the whole run ends
/// here (MPI_Abort) with this rank's message and exit status.
pub fn abort_on_failure(distribution: &Distribution, kind: ErrorKind, message: &str) -> ! {
    eprintln!("error: rank {}: {message}", distribution.rank());
    distribution.ranks().abort(i32::from(kind.exit_status()))
}

/// This rank's part of the data, ready to trace.
pub struct Part {
    /// Its triangles, with their ids in the whole data set, and the bounds
    /// of the whole data set (so the standard views and default lights are
    /// the single process's).
    pub scene: TraceScene,
    pub origin: String,
    /// The colour map's range over every rank's scalars.
    pub scalar_range: [f32; 2],
}

/// Loads only this rank's part of the data (data decomposition):
/// - a volume (a file, raw brick or generated data set): brick `rank` of a
///   k-d split of its cells, read (or generated) alone with one shared layer
///   of samples and one ghost layer, its isosurface's own triangles kept;
/// - several mesh files: the pieces dealt out to ranks, balanced by triangles;
/// - one mesh file or the built-in scene: every rank reads all of it and
///   keeps its region of a k-d split of the triangles.
///
/// Triangle ids, bounds and the colour map's range are the whole data set's.
pub fn load_part(
    request: &SceneRequest,
    library: &FunctorLibrary,
    progress: &Progress,
    distribution: &Distribution,
) -> Result<Part, String> {
    let builtin = [SceneSpec::Builtin(DEFAULT_RESOLUTION)];
    let scenes = if request.scenes.is_empty() {
        &builtin[..]
    } else {
        &request.scenes[..]
    };
    // A .pvtp or .pvtu is its piece files, dealt out as pieces.
    let expanded: Vec<SceneSpec>;
    let scenes = match scenes {
        [SceneSpec::File(path)] if VtkKind::of(path) == Some(VtkKind::Mesh { parallel: true }) => {
            let files = dpp_tracer::vtk::piece_files(path).map_err(|e| format!("error: {e}"));
            expanded = (distribution.agree(files)?.into_iter())
                .map(SceneSpec::File)
                .collect();
            &expanded[..]
        }
        other => other,
    };
    let (mut mesh, materials, ids, origin) = match scenes {
        [spec] if spec.is_volume(request.raw.as_deref()) => {
            let (mesh, ids) = volume_part(request, spec, library, progress, distribution)?;
            (mesh, MeshMaterials::default(), ids, spec.name())
        }
        [whole] => {
            let loaded = whole_mesh(whole, request.field.as_deref(), progress);
            let (mesh, materials) = distribution.agree(loaded)?;
            let ids = spatial_part(&mesh, distribution.size(), distribution.rank());
            let part = sub_mesh(&mesh, &ids);
            let materials = split_materials(&materials, &ids);
            (part, materials, ids, whole.name())
        }
        pieces => {
            let (mesh, ids) = piece_part(request, pieces, progress, distribution)?;
            let origin = format!("{} pieces", pieces.len());
            (mesh, MeshMaterials::default(), ids, origin)
        }
    };
    let Some(bounds) = distribution.all_bounds(mesh.bounds()) else {
        return Err(format!("error: {origin} has no triangles on any rank"));
    };
    let scalars: Vec<f32> = match &mesh.scalars {
        Some(scalars) => scalars.clone(),
        // A scene colours by height without scalars of its own.
        None => mesh.positions.iter().map(|p| p.y).collect(),
    };
    let mut low = [scalars
        .iter()
        .copied()
        .filter(|s| s.is_finite())
        .fold(f32::INFINITY, f32::min)];
    let mut high = [scalars
        .iter()
        .copied()
        .filter(|s| s.is_finite())
        .fold(f32::NEG_INFINITY, f32::max)];
    distribution.ranks().all_min_f32(&mut low);
    distribution.ranks().all_max_f32(&mut high);
    let scalar_range = default_scalar_range(&[low[0], high[0]]);
    if mesh.triangles.is_empty() {
        // A rank whose part holds no triangles still takes part in the run:
        // it traces one triangle of zero area, which no ray can hit.
        let point = bounds.center();
        mesh.positions = vec![point; 3];
        mesh.triangles = vec![[0, 1, 2]];
        mesh.normals = mesh.normals.as_ref().map(|_| vec![glam::Vec3::Y; 3]);
        mesh.scalars = mesh.scalars.as_ref().map(|_| vec![scalar_range[0]; 3]);
    }
    let triangles = mesh.triangles.len();
    let scene = scene_setup::trace_scene(mesh, materials, request.bvh, progress, |e| {
        format!(
            "error: the part of {origin} on rank {}: {e}",
            distribution.rank()
        )
    })
    .and_then(|scene| {
        let ids = if ids.len() == triangles {
            ids
        } else {
            vec![0; triangles]
        };
        scene
            .with_global_ids(Arc::new(ids))
            .map_err(|e| format!("error: {e}"))
    });
    let mut scene = distribution.agree(scene)?;
    scene.bounds = bounds;
    Ok(Part {
        scene,
        origin: format!(
            "{origin}, rank {} of {}",
            distribution.rank(),
            distribution.size()
        ),
        scalar_range,
    })
}

/// The whole of a one-file mesh or the built-in scene, with the vertex
/// normals the single process would compute (on the whole mesh, so that a
/// vertex on a part's border gets the same normal as in one process).
fn whole_mesh(
    spec: &SceneSpec,
    field: Option<&str>,
    progress: &Progress,
) -> Result<(TriangleMesh, MeshMaterials), String> {
    let (mut mesh, materials) = match spec {
        SceneSpec::Builtin(resolution) => {
            progress.phase("generating the built-in scene");
            let mesh = builtin_scene(*resolution)
                .map_err(|e| format!("error: the built-in scene failed: {e}"))?;
            (mesh, MeshMaterials::default())
        }
        SceneSpec::File(path) => {
            progress.phase(format!("loading {}", path.display()));
            scene_setup::load_mesh(path, field)?
        }
        SceneSpec::Generated(..) => return Err("error: a generated volume is not a mesh".into()),
    };
    if mesh.normals.is_none() {
        mesh.validate()
            .map_err(|e| format!("error: cannot use scene `{}`: {e}", spec.name()))?;
        mesh.add_crease_normals(dpp_tracer::scene::CREASE_ANGLE_DEGREES.to_radians());
    }
    Ok((mesh, materials))
}

/// This rank's pieces of a scene given as several mesh files, dealt out in
/// file order and balanced by their triangle counts (read from the files'
/// headers, or by a scan of an OBJ's faces), with every triangle's id in the
/// pieces' order.
fn piece_part(
    request: &SceneRequest,
    pieces: &[SceneSpec],
    progress: &Progress,
    distribution: &Distribution,
) -> Result<(TriangleMesh, Vec<u32>), String> {
    let paths = scene_setup::piece_paths(pieces, request.raw.as_deref());
    let paths = distribution.agree(paths)?;
    let counts: Result<Vec<u64>, String> = (paths.iter())
        .map(|path| count_triangles(path).map_err(|e| format!("error: {}: {e}", path.display())))
        .collect();
    let counts = distribution.agree(counts)?;
    let mine = assign_pieces(&counts, distribution.size())
        .into_iter()
        .nth(distribution.rank())
        .unwrap_or_default();
    let offsets = piece_offsets(&counts);
    let mut meshes = Vec::with_capacity(mine.len());
    let mut ids = Vec::new();
    let loaded: Result<(), String> = mine.iter().try_for_each(|&piece| {
        let path = &paths[piece];
        progress.phase(format!("loading {}", path.display()));
        let (mesh, _) = scene_setup::load_mesh(path, request.field.as_deref())?;
        if mesh.triangles.len() as u64 != counts[piece] {
            return Err(format!(
                "error: {}: its header counts {} triangles but it has {}",
                path.display(),
                counts[piece],
                mesh.triangles.len()
            ));
        }
        ids.extend((0..mesh.triangles.len() as u64).map(|t| (offsets[piece] + t) as u32));
        meshes.push(mesh);
        Ok(())
    });
    distribution.agree(loaded)?;
    Ok((scene_setup::concat_meshes(meshes), ids))
}

/// This rank's brick of a volume: its isosurface's own triangles (those of
/// the cells the brick owns) and their ids in the whole volume's numbering.
fn volume_part(
    request: &SceneRequest,
    spec: &SceneSpec,
    library: &FunctorLibrary,
    progress: &Progress,
    distribution: &Distribution,
) -> Result<(TriangleMesh, Vec<u32>), String> {
    let raw = (request.raw.as_deref())
        .map(|text| text.parse::<RawSpec>())
        .transpose()
        .map_err(|e| format!("error: {e}"));
    let raw = distribution.agree(raw)?;
    let dims = match spec {
        SceneSpec::Generated(_, grid) => Ok(UVec3::from(*grid)),
        SceneSpec::File(path) => Volume::read_dims(path, raw).map_err(|e| format!("error: {e}")),
        SceneSpec::Builtin(_) => Err("error: the built-in scene is not a volume".into()),
    };
    let dims = distribution.agree(dims)?;
    let cell_dims = dims.saturating_sub(UVec3::ONE);
    let brick = kd_bricks(cell_dims, distribution.size())[distribution.rank()];
    progress.phase(format!(
        "brick {} of {}: cells {}..{}",
        distribution.rank(),
        distribution.size(),
        brick.cells[0],
        brick.cells[1]
    ));
    let failed = |e: dpp_tracer::volume::VolumeError| format!("error: {e}");
    let volume = match spec {
        SceneSpec::Generated(dataset, _) => dataset.generate_brick(dims, &brick).map_err(failed),
        // A VTK file's chosen array: read whole (VTK has no brick reads anyway).
        SceneSpec::File(path) if request.field.is_some() => {
            volume_setup::load_volume(path, None, request.field.as_deref())
                .map(|whole| whole.sub_box(brick.samples[0], brick.samples[1]))
        }
        SceneSpec::File(path) => Volume::load_brick(path, raw, &brick).map_err(failed),
        SceneSpec::Builtin(_) => Err("error: the built-in scene is not a volume".into()),
    };
    let volume = distribution.agree(volume)?;
    let level = scene_setup::iso_level(request, spec, None);
    let level = distribution.agree(level)?;
    let iso = IsoRequest {
        level,
        pipeline: request.iso_pipeline.clone(),
        fuse: request.fuse,
    };
    progress.phase(format!("isosurface at level {level}"));
    // Where the brick's cells are, for numbering them globally (the samples
    // themselves go to the pipeline).
    let placement = Volume {
        dims: volume.dims,
        spacing: volume.spacing,
        origin: volume.origin,
        first: volume.first,
        values: Vec::new(),
    };
    let surface = volume_setup::isosurface_triangles(volume, &iso, library);
    let (triangles, cells) = distribution.agree(surface)?;
    let owned = owned_triangles(&cells, &placement, &brick);
    // Welded with the box around every rank's corners, as one process welds
    // the whole surface, so that the same collapsed triangles are dropped.
    let corners =
        corner_bounds(&triangles, Some(&owned.indices)).map_err(|e| format!("error: {}", e.0));
    let (low, high) = distribution.agree(corners)?;
    let (mut low, mut high) = (low.to_array(), high.to_array());
    distribution.ranks().all_min_f32(&mut low);
    distribution.ranks().all_max_f32(&mut high);
    let welded = welded_mesh(&triangles, Some(&owned.indices), (low.into(), high.into()))
        .map_err(|e| format!("error: {}", e.0));
    let (mut mesh, survivors) = distribution.agree(welded)?;
    let global_cells: Vec<UVec3> = (survivors.iter())
        .map(|&position| owned.global_cells[position as usize])
        .collect();
    let summary = triangle_summary(&brick, &global_cells);
    let bytes: Vec<u8> = summary.iter().flat_map(|w| w.to_le_bytes()).collect();
    let summaries: Vec<Vec<u32>> = (distribution.ranks().all_gather_bytes(&bytes).iter())
        .map(|bytes| {
            (bytes.chunks_exact(4))
                .map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]]))
                .collect()
        })
        .collect();
    let ids = global_triangle_ids(&summaries, distribution.rank(), cell_dims, &global_cells)
        .map_err(|e| format!("error: numbering the isosurface's triangles: {e}"));
    let ids = distribution.agree(ids)?;
    // The surface's own values all equal the level: colour by height.
    mesh.scalars = None;
    Ok((mesh, ids))
}

#[cfg(test)]
mod tests {
    use super::*;
    use dpp_dist::ranks::fnv1a;
    use dpp_tracer::volume::kd_bricks;
    use glam::Vec3;

    /// Boxes of a k-d split come front to back: of two boxes that only one
    /// axis separates (the pairs where "in front" means something for
    /// every eye), the one on the eye's side comes first.
    #[test]
    fn the_visibility_order_puts_the_eye_s_side_of_every_split_first() {
        for parts in 1..=9 {
            let boxes: Vec<Bounds> = kd_bricks(UVec3::new(40, 24, 16), parts)
                .iter()
                .map(|brick| Bounds {
                    min: brick.cells[0].as_vec3(),
                    max: brick.cells[1].as_vec3(),
                })
                .collect();
            for seed in 0..20u64 {
                // Eyes all around the grid, from a fixed sequence.
                let unit = |k: u64| (fnv1a(&(seed * 3 + k).to_le_bytes()) % 1000) as f32 / 1000.0;
                let eye = Vec3::new(unit(0), unit(1), unit(2)) * 100.0 - Vec3::splat(30.0);
                let order = visibility_order(&boxes, eye);
                let mut sorted = order.clone();
                sorted.sort_unstable();
                assert_eq!(sorted, (0..parts).collect::<Vec<_>>());
                let position = |i: usize| order.iter().position(|&r| r == i).unwrap();
                for a in 0..parts {
                    for b in 0..parts {
                        let separated: Vec<usize> = (0..3)
                            .filter(|&axis| boxes[a].max[axis] <= boxes[b].min[axis])
                            .collect();
                        let overlapping = (0..3).all(|axis| {
                            separated.contains(&axis)
                                || (boxes[a].max[axis] > boxes[b].min[axis]
                                    && boxes[b].max[axis] > boxes[a].min[axis])
                        });
                        // An eye between the two boxes could face either,
                        // as the split between them decides: skipped.
                        let between = |axis: usize| {
                            boxes[a].max[axis] < eye[axis] && eye[axis] < boxes[b].min[axis]
                        };
                        if let (&[axis], true) = (&separated[..], overlapping) {
                            if between(axis) {
                                continue;
                            }
                            let a_faces_the_eye = eye[axis] <= boxes[a].max[axis];
                            assert_eq!(
                                position(a) < position(b),
                                a_faces_the_eye,
                                "parts {parts}, eye {eye}, boxes {a} and {b} along axis {axis}: {order:?}"
                            );
                        }
                    }
                }
            }
        }
    }
}
