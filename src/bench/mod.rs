//! `dpp bench`: the paper's measurement method (its §5). Every scene is loaded
//! and its BVH built once (timed apart, never inside a frame); then for every
//! view each workload runs warm-up rounds and measured rounds, fused and
//! unfused, on the CPU backend or (`--backend gpu`) on the GPU backend, with one
//! device opened for the whole bench. WORKLOAD1's rate is primary rays over the
//! time of its `map<intersect>` stage (from the unfused plan, where that stage
//! does nothing else) and over the whole frame; WORKLOAD2 and WORKLOAD3 report
//! frames per second and the time of every stage. `--engine dpp,embree` (CPU
//! only) also runs WORKLOAD1 with Embree behind `intersect` (single rays and
//! 16-ray packets) and checks that both engines hit the same triangles, and
//! runs WORKLOAD3's fused plan with Embree behind `intersect` and `occluded`.
//! For the comparisons issue 26's bars are about (WORKLOAD1's intersection,
//! WORKLOAD3's frame, against Embree's packets) it also runs dpp's plan and
//! Embree's in turn, a frame of each per round, so that the machine's slow
//! spells fall on both: their ratio is the median of the rounds' ratios.
//!
//! On the CPU a frame's stage times come from the measured run itself. On the
//! GPU, profiling waits for the device after every stage, so the measured
//! frames run without it and the stage times come from as many further runs
//! with it (device time from timestamp queries where the adapter has them).

mod across_ranks;
mod chart;
mod report;
mod volume;

use crate::distributed::Distribution;
use crate::outputs::write_atomically;
use crate::scene_setup::{self, SceneRequest, SceneSetup, SceneSpec};
use crate::{volume_setup, Backend, Failure};
use dpp_dist::schedule::DEFAULT_RADIX;
use dpp_dist::CompositeSchedule;
use dpp_gpu::{run_plan_gpu, GpuContext, GpuRunContext};
use dpp_runtime::cpu::column_pool::ColumnPool;
use dpp_runtime::cpu::exec::{run_plan, RunContext};
use dpp_runtime::interpret::{OpTiming, OutputValue, RunResult, StageTiming};
use dpp_runtime::{CompileOptions, FunctorLibrary, Plan};
use dpp_tracer::builtin_scene::builtin_scene;
use dpp_tracer::bvh::BvhBuilder;
use dpp_tracer::camera::sample_offset;
use dpp_tracer::shading::MeshMaterials;
use dpp_tracer::{Camera, StandardView, TraceScene, TriangleMesh, MISS_PRIM};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

pub use report::{GpuInfo, Report};

/// Hits agree when, for at least this share of the rays, both engines name the
/// same triangle or (a tie between overlapping triangles) a different one at
/// the same distance, or one engine hits the ray at a triangle's border and the
/// other misses it; and when the rays that one engine hits and the other
/// misses are all at a triangle's border (give or take
/// [`ONE_SIDED_RAYS_PER_MILLION`]). A ray excused at a border is not held
/// against the share too: a lone triangle in a 64×64 frame has 16 such rays of
/// 4096 on its open edge, 0.4%.
pub const AGREEMENT: f64 = 0.999;

/// Rays in a million that may hit in one engine and miss in the other away from
/// any triangle's border (measured: at most one ray of the 2M of a 1080p frame,
/// in some views).
pub const ONE_SIDED_RAYS_PER_MILLION: u64 = 1;

/// A ray is at a triangle's border when it meets the triangle's plane within
/// this of the border, in barycentric coordinates (a ten-thousandth of the
/// triangle's size). There the two watertight tests round either way: on an
/// open border (a lone triangle's edge through a row of pixel centres) Embree's
/// robust test hits hundreds of rays that, in exact arithmetic, pass just
/// outside, and dpp misses them.
#[cfg_attr(not(feature = "embree"), allow(dead_code))]
const BORDER_BAND: f64 = 1e-4;

/// ... or within this many f32 rounding steps of an edge, in world units, a
/// step being `f32::EPSILON` times the farthest corner's distance from the
/// eye. Both tests round in coordinates taken
/// relative to the ray's origin, so their error scales with that distance,
/// not with the triangle: a sliver a thousandth as wide as it is long (as
/// marching cubes makes) is crossed by a band of a ten-thousandth of its width
/// that is narrower than one rounding step, and rays 2–3 steps from its long
/// edge (measured on a soup of such slivers) went either way. 16 steps is a
/// four-hundredth of a pixel of a standard 1080p view (45° field of view).
const BORDER_ROUNDING_STEPS: f64 = 16.0;

/// Most measured (or warm-up) rounds: a mean over more says nothing new, and
/// a mistyped count would run for days.
const MAX_ROUNDS: u32 = 1000;

/// At most this many rays on which the engines disagree are kept for the JSON report.
const MISMATCH_SAMPLES: usize = 8;

/// Two hit distances are the same when they differ by less than this, relatively.
const SAME_DISTANCE: f32 = 1e-6;

#[derive(clap::Args)]
pub struct BenchArgs {
    /// Scenes: `builtin` (the default), `builtin:RESOLUTION` (cells along x and y,
    /// 8 to 512), `rm:X,Y,Z`, `pbte:X,Y,Z`, `sphere:X,Y,Z` (a generated volume on
    /// that grid, at its default level unless --iso), or a mesh file (.obj, .ply,
    /// .obj.gz, .ply.gz; a volume with --iso).
    #[arg(value_name = "SCENE")]
    scenes: Vec<String>,
    /// Image size.
    #[arg(long, default_value = "1920x1080", value_parser = crate::parse_size)]
    size: (u32, u32),
    /// Standard views, comma-separated.
    #[arg(long, default_value = "front,back,zoom")]
    views: String,
    /// Workloads to run (1, 2, 3), comma-separated; or `volume` alone:
    /// pipelines/volume.dpp on volume scenes against a hand-written ray marcher.
    #[arg(long, default_value = "1,2,3")]
    workloads: String,
    /// The volume workload's transfer function: a colour map name or a
    /// ParaView preset (`FILE.json`, `FILE.json:NAME`).
    #[arg(long, value_name = "FILE.json|NAME")]
    transfer: Option<String>,
    /// The volume workload's scalar range `A,B` (default: the volume's values).
    #[arg(long = "scalar-range", value_name = "A,B", allow_hyphen_values = true,
          value_parser = |s: &str| dpp_tracer::shading::parse_scalar_range(s).map_err(|e| e.to_string()))]
    scalar_range: Option<[f32; 2]>,
    /// The volume workload's params: `--set block=0` (only `block`, which
    /// the hand-written loop has no counterpart of, keeps the images equal).
    #[arg(long = "set", value_name = "NAME=VALUE", value_parser = crate::parse_assignment)]
    set: Vec<(String, String)>,
    /// Unmeasured rounds before the measured ones, per view, workload and plan.
    #[arg(long, default_value_t = 1)]
    warmup: u32,
    /// Measured rounds (the reported time is their mean).
    #[arg(long, default_value_t = 3)]
    rounds: u32,
    /// Worker threads (default: one per core).
    #[arg(long)]
    threads: Option<usize>,
    /// How dpp's BVH is built.
    #[arg(long, value_enum, default_value_t = crate::BvhChoice::Sah)]
    bvh: crate::BvhChoice,
    /// The backend that runs the plans. `gpu` opens the first adapter wgpu
    /// offers once for the whole bench (`WGPU_BACKEND`, `WGPU_ADAPTER_NAME` choose).
    #[arg(long, value_enum, default_value_t = Backend::Cpu)]
    backend: Backend,
    /// How the CPU backend runs a fused stage's element-wise ops.
    #[arg(long, value_enum, default_value_t = crate::CpuElementwise::Compiled)]
    cpu_elementwise: crate::CpuElementwise,
    /// Intersection engines: `dpp`, or `dpp,embree` to compare WORKLOAD1 and
    /// WORKLOAD3 with Embree 3 behind `intersect` (and `occluded`) (needs a
    /// build with `--features embree`; CPU backend only).
    #[arg(long, default_value = "dpp")]
    engine: String,
    /// Embree's triangle test, with `--engine dpp,embree` (default: robust).
    #[arg(long, value_enum)]
    embree_test: Option<EmbreeTest>,
    /// The isosurface level for volume files.
    #[arg(long, allow_hyphen_values = true)]
    iso: Option<f32>,
    /// The folder with workload1.dpp, workload2.dpp and workload3.dpp
    /// (default: ./pipelines, else the source tree's).
    #[arg(long, value_name = "DIR")]
    pipelines: Option<PathBuf>,
    /// Measure FILE against the workload it stands for (the one workload
    /// --workloads names), side by side: their fused plans run frame by
    /// frame in turn on each view, with the warm-up and measured rounds set,
    /// and the report gives both frames and their ratio.
    #[arg(long, value_name = "FILE.dpp")]
    versus: Option<PathBuf>,
    /// Also write the markdown tables to FILE.
    #[arg(long, value_name = "FILE.md")]
    markdown: Option<PathBuf>,
    /// Write every measurement as JSON.
    #[arg(long, value_name = "FILE.json")]
    json: Option<PathBuf>,
    /// Draw WORKLOAD1's rates (or the frame rates) as a PNG bar chart.
    #[arg(long, value_name = "FILE.png")]
    chart: Option<PathBuf>,
    /// Under mpirun: each rank holds part of the data (`data`) or renders
    /// part of the image (`image`); the report is per rank.
    #[arg(long, value_enum, default_value_t = crate::distributed::Decompose::Data)]
    decompose: crate::distributed::Decompose,
    /// Under mpirun: the compositing schedules to measure, comma-separated
    /// (`direct`, `binary-swap`, `radix-k`, `radix-k:K`).
    #[arg(long, default_value = "radix-k", value_name = "SCHEDULES")]
    composite: String,
}

/// The triangle test of Embree's scene (`--embree-test`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum EmbreeTest {
    /// `RTC_SCENE_FLAG_ROBUST`: watertight, like dpp's, so that the hits can be
    /// compared ray by ray.
    Robust,
    /// Embree's default flags: its faster test, which lets a few rays through
    /// the edges two triangles share.
    Fast,
}

/// Embree's modes, the engines WORKLOAD1 is compared with: its scene built
/// at its default quality, or (`…High`) at `RTC_BUILD_QUALITY_HIGH`.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(not(feature = "embree"), allow(dead_code))]
// The names say which engine, as the reports print them.
#[allow(clippy::enum_variant_names)]
pub enum Engine {
    EmbreeSingle,
    EmbreePacket,
    EmbreeSingleHigh,
    EmbreePacketHigh,
}

impl Engine {
    pub fn name(self) -> &'static str {
        match self {
            Engine::EmbreeSingle => "embree-single",
            Engine::EmbreePacket => "embree-packet",
            Engine::EmbreeSingleHigh => "embree-single-high",
            Engine::EmbreePacketHigh => "embree-packet-high",
        }
    }

    /// Whether its scene was built at `RTC_BUILD_QUALITY_HIGH`.
    #[cfg_attr(not(feature = "embree"), allow(dead_code))]
    pub fn high_quality(self) -> bool {
        matches!(self, Engine::EmbreeSingleHigh | Engine::EmbreePacketHigh)
    }
}

/// Everything parsed and checked before anything runs.
struct Setup {
    scenes: Vec<SceneSpec>,
    views: Vec<(String, StandardView)>,
    workloads: Vec<u32>,
    /// `--workloads volume`: the volume workload instead of the three.
    volume: bool,
    embree: bool,
    embree_test: EmbreeTest,
    pipelines: PathBuf,
}

fn check(args: &BenchArgs) -> Result<Setup, String> {
    let list = |text: &str| -> Vec<String> {
        text.split(',')
            .map(|s| s.trim().to_string())
            .filter(|s| !s.is_empty())
            .collect()
    };
    let mut views = Vec::new();
    for name in list(&args.views) {
        let view: StandardView = name.parse().map_err(|e| format!("error: --views: {e}"))?;
        views.push((name, view));
    }
    if views.is_empty() {
        return Err("error: --views names no view (front, back, zoom)".into());
    }
    let mut workloads = Vec::new();
    let names = list(&args.workloads);
    let volume = names.iter().any(|name| name == "volume");
    if volume && names.len() > 1 {
        return Err(
            "error: --workloads volume runs alone (volume scenes, not the tracing workloads)"
                .into(),
        );
    }
    if (args.transfer.is_some() || args.scalar_range.is_some() || !args.set.is_empty()) && !volume {
        return Err(
            "error: --transfer, --scalar-range and --set are for --workloads volume".into(),
        );
    }
    for name in names.iter().filter(|_| !volume) {
        match name.trim_start_matches("workload").parse::<u32>() {
            Ok(n @ 1..=3) if !workloads.contains(&n) => workloads.push(n),
            Ok(1..=3) => {}
            _ => {
                return Err(format!(
                    "error: --workloads: unknown workload `{name}`; the workloads are 1, 2 and 3, or volume alone"
                ))
            }
        }
    }
    if workloads.is_empty() && !volume {
        return Err("error: --workloads names no workload (1, 2, 3, or volume)".into());
    }
    let mut embree = false;
    for name in list(&args.engine) {
        match name.as_str() {
            "dpp" => {}
            "embree" => embree = true,
            other => {
                return Err(format!(
                    "error: --engine: unknown engine `{other}`; the engines are dpp and embree"
                ))
            }
        }
    }
    if embree && args.backend != Backend::Cpu {
        return Err(
            "error: --engine embree runs on the CPU only: it cannot be combined with --backend gpu (use --engine dpp, or --backend cpu)".into(),
        );
    }
    if embree && !cfg!(feature = "embree") {
        return Err(
            "error: --engine embree: this dpp was built without Embree; rebuild with `cargo build --release --features embree` (needs libembree-dev)".into(),
        );
    }
    if embree && !workloads.contains(&1) && !workloads.contains(&3) {
        return Err(
            "error: --engine embree compares WORKLOAD1 and WORKLOAD3: add 1 or 3 to --workloads"
                .into(),
        );
    }
    if args.embree_test.is_some() && !embree {
        return Err("error: --embree-test chooses Embree's triangle test: add embree to --engine (--engine dpp,embree)".into());
    }
    if args.rounds == 0 {
        return Err("error: --rounds must be at least 1".into());
    }
    for (option, rounds) in [("--rounds", args.rounds), ("--warmup", args.warmup)] {
        if rounds > MAX_ROUNDS {
            return Err(format!(
                "error: {option} {rounds}: at most {MAX_ROUNDS} rounds (each view, workload and plan runs them all)"
            ));
        }
    }
    let specs: Vec<String> = if args.scenes.is_empty() {
        vec!["builtin".into()]
    } else {
        args.scenes.clone()
    };
    let scenes = specs
        .iter()
        .map(|s| SceneSpec::parse(s))
        .collect::<Result<Vec<_>, _>>()?;
    let pipelines = match &args.pipelines {
        Some(dir) => dir.clone(),
        None if Path::new("pipelines/workload1.dpp").is_file() => PathBuf::from("pipelines"),
        None => Path::new(env!("CARGO_MANIFEST_DIR")).join("pipelines"),
    };
    for workload in &workloads {
        let path = pipelines.join(format!("workload{workload}.dpp"));
        if !path.is_file() {
            return Err(format!(
                "error: cannot find {}; name the folder of the workload pipelines with --pipelines DIR",
                path.display()
            ));
        }
    }
    if let Some(versus) = &args.versus {
        if volume || workloads.len() != 1 {
            return Err(format!(
                "error: --versus {} is measured against one workload: name it alone in --workloads (1, 2 or 3)",
                versus.display()
            ));
        }
        if !versus.is_file() {
            return Err(format!("error: --versus: cannot find {}", versus.display()));
        }
    }
    if volume {
        let path = pipelines.join("volume.dpp");
        if !path.is_file() {
            return Err(format!(
                "error: cannot find {}; name the folder of the pipelines with --pipelines DIR",
                path.display()
            ));
        }
        if let Some(spec) = scenes.iter().find(|spec| !spec.is_volume(None)) {
            return Err(format!(
                "error: --workloads volume renders volumes: `{}` is not one (give rm:X,Y,Z, a .nii or .nii.gz file…)",
                spec.name()
            ));
        }
    }
    Ok(Setup {
        scenes,
        views,
        workloads,
        volume,
        embree,
        embree_test: args.embree_test.unwrap_or(EmbreeTest::Robust),
        pipelines,
    })
}

/// One plan run `warmup + rounds` times: the measured frames and the mean time
/// of every stage.
#[derive(Clone, Debug)]
pub struct Measurement {
    /// Wall time of each measured frame (`run_plan`, `run_plan_gpu`), in ms.
    pub frames_ms: Vec<f64>,
    /// Wall time of the plan's first frame on the view (the first warm-up
    /// round, or the first measured one without warm-up): no array of an
    /// earlier frame to reuse, as for a first image.
    pub first_frame_ms: f64,
    pub stages: Vec<StageTime>,
    /// On the GPU: wall time of each profiled run the stage times come from
    /// (profiling waits after every stage, so these are slower). Empty on the CPU.
    pub profiled_frames_ms: Vec<f64>,
}

#[derive(Clone, Debug)]
pub struct StageTime {
    pub stage: usize,
    pub label: String,
    /// Mean over the measured rounds.
    pub ms: f64,
    /// Where a CPU stage's time went, op by op (`StageTiming::ops`, each
    /// op's thread time a mean over the measured rounds); empty on the GPU.
    pub ops: Vec<OpTiming>,
}

impl Measurement {
    pub fn mean_ms(&self) -> f64 {
        self.frames_ms.iter().sum::<f64>() / self.frames_ms.len().max(1) as f64
    }

    pub fn fps(&self) -> f64 {
        1e3 / self.mean_ms()
    }

    /// The thread time (ms, summed over threads and stages) of the ops that
    /// call `functor` in a map (CPU profiles).
    pub fn map_thread_ms(&self, functor: &str) -> f64 {
        self.stages
            .iter()
            .flat_map(|s| &s.ops)
            .filter(|op| maps(op, functor))
            .map(|op| ms(op.thread_time))
            .sum()
    }

    /// The frame's wall time outside the traversal (`map<intersect>` and
    /// `map<occluded>`), in ns per pixel: what shading, compaction, scatters
    /// and the display encoding cost whatever traces the rays. Each stage's
    /// traversal time is its ops' share of the stage's op time (summed over
    /// threads) times the stage's wall time, as the op split tables give it.
    /// `None` where stages were not split op by op (the GPU).
    pub fn beyond_traversal_ns_per_pixel(&self, pixels: u64) -> Option<f64> {
        let is_traversal = |op: &OpTiming| maps(op, "intersect") || maps(op, "occluded");
        let mut traversal_ms = 0.0;
        let mut split = false;
        for stage in &self.stages {
            let total: f64 = stage
                .ops
                .iter()
                .map(|op| op.thread_time.as_secs_f64())
                .sum();
            if total <= 0.0 {
                continue;
            }
            split = true;
            let traversal: f64 = (stage.ops.iter().filter(|op| is_traversal(op)))
                .map(|op| op.thread_time.as_secs_f64())
                .sum();
            traversal_ms += stage.ms * traversal / total;
        }
        (split && pixels > 0).then(|| (self.mean_ms() - traversal_ms) * 1e6 / pixels as f64)
    }

    /// The mean time of the stage that is `map<intersect>` alone.
    pub fn intersect_ms(&self) -> Option<f64> {
        self.stages
            .iter()
            .find(|s| s.label == INTERSECT_STAGE)
            .map(|s| s.ms)
    }
}

/// The label of WORKLOAD1's unfused intersection stage, whose time its rate is of.
const INTERSECT_STAGE: &str = "map<intersect>";

/// Whether a profiled op is a `map` of `functor` (`hits = map<intersect>`).
fn maps(op: &OpTiming, functor: &str) -> bool {
    op.label
        .strip_suffix('>')
        .and_then(|label| label.strip_suffix(functor))
        .is_some_and(|label| label.ends_with("map<"))
}

/// A workload on one view: fused and unfused.
#[derive(Clone, Debug)]
pub struct WorkloadResult {
    pub workload: u32,
    pub fused: Measurement,
    pub unfused: Measurement,
}

impl WorkloadResult {
    /// How much faster the fused plan runs.
    pub fn fusion_gain(&self) -> f64 {
        self.unfused.mean_ms() / self.fused.mean_ms()
    }
}

/// WORKLOAD1 with one engine behind `intersect`, against dpp's own hits.
#[derive(Clone, Debug)]
pub struct EngineResult {
    pub engine: Engine,
    pub fused: Measurement,
    pub unfused: Measurement,
    /// Rays that hit something, with dpp's traversal and with this engine.
    pub hits_dpp: u64,
    pub hits_engine: u64,
    /// The share of rays for which both name the same triangle (or both miss).
    pub same_triangle: f64,
    /// The share of rays that hit different triangles at the same distance
    /// (overlapping or duplicated triangles: either is the closest hit).
    pub ties: f64,
    /// Rays in the frame.
    pub rays: u64,
    /// Rays that one engine hits and the other misses, and how many of those
    /// are at the border of the triangle that was hit (see [`BORDER_BAND`]).
    pub one_sided: u64,
    pub one_sided_at_border: u64,
    /// A few rays that one engine hits and the other misses away from a
    /// border: pixel (row-major), dpp's triangle and distance, the engine's.
    pub mismatches: Vec<(u32, u32, f32, u32, f32)>,
}

impl EngineResult {
    pub fn agrees(&self) -> bool {
        let allowed = self.rays * ONE_SIDED_RAYS_PER_MILLION / 1_000_000;
        let at_border = self.one_sided_at_border as f64 / self.rays.max(1) as f64;
        self.one_sided - self.one_sided_at_border <= allowed
            && self.same_triangle + self.ties + at_border >= AGREEMENT
    }
}

/// Whether the ray of row-major `pixel` (WORKLOAD1's: one sample at the pixel
/// centre) meets the plane of triangle `prim` within [`BORDER_BAND`] or
/// [`BORDER_ROUNDING_STEPS`] of the triangle's border, computed in f64; also
/// true for a ray in the plane.
#[cfg_attr(not(feature = "embree"), allow(dead_code))]
fn ray_at_border(camera: &Camera, mesh: &TriangleMesh, pixel: usize, prim: u32) -> bool {
    let Some(triangle) = mesh.triangles.get(prim as usize) else {
        return false;
    };
    let (x, y) = (pixel as u32 % camera.width, pixel as u32 / camera.width);
    let (sx, sy) = sample_offset(1, 0);
    let origin = camera.eye.as_dvec3();
    let dir = camera.direction(x, y, sx, sy).as_dvec3();
    let [p0, p1, p2] = triangle.map(|v| mesh.positions[v as usize].as_dvec3());
    // Möller–Trumbore's barycentric coordinates of the ray's point in the plane.
    let (e1, e2) = (p1 - p0, p2 - p0);
    let p = dir.cross(e2);
    let det = e1.dot(p);
    if det.abs() <= f64::EPSILON * e1.length() * e2.length() {
        return true;
    }
    let to_origin = origin - p0;
    let u = to_origin.dot(p) / det;
    let v = dir.dot(to_origin.cross(e1)) / det;
    if u.min(v).min(1.0 - u - v).abs() <= BORDER_BAND {
        return true;
    }
    let point = p0 + u * e1 + v * e2;
    let distance_to_edge = |a: glam::DVec3, b: glam::DVec3| {
        let along = ((point - a).dot(b - a) / (b - a).length_squared()).clamp(0.0, 1.0);
        (a + along * (b - a)).distance(point)
    };
    let nearest_edge = distance_to_edge(p0, p1)
        .min(distance_to_edge(p1, p2))
        .min(distance_to_edge(p2, p0));
    let farthest_corner = [p0, p1, p2]
        .map(|corner| corner.distance(origin))
        .into_iter()
        .fold(0.0, f64::max);
    nearest_edge <= BORDER_ROUNDING_STEPS * f32::EPSILON as f64 * farthest_corner
}

/// WORKLOAD1's `prim` and `depth` outputs (row-major pixels).
pub struct Hits {
    prim: Vec<u32>,
    depth: Vec<f32>,
}

/// WORKLOAD2's or WORKLOAD3's fused plan with one engine behind `intersect`
/// (and `occluded`).
#[derive(Clone, Debug)]
pub struct TracedByEngine {
    pub workload: u32,
    pub engine: Engine,
    pub fused: Measurement,
}

#[derive(Clone, Debug)]
pub struct ViewResult {
    pub view: String,
    pub rays: u64,
    pub workloads: Vec<WorkloadResult>,
    /// WORKLOAD1's intersection with each engine.
    pub engines: Vec<EngineResult>,
    /// WORKLOAD2 and WORKLOAD3 with each engine.
    pub engine_frames: Vec<TracedByEngine>,
    /// `--versus`: the other file against the workload.
    pub side_by_side: Option<SideBySide>,
    /// With Embree: WORKLOAD1's intersection (unfused) and WORKLOAD3's fused
    /// frame, dpp and Embree's packets (the bars' engine) in turn.
    pub engines_in_turn: Vec<SideBySide>,
}

/// Two plans measured in turn on one view: `--versus` (a pipeline file and
/// the workload it stands for, fused frames), or a workload with dpp and
/// with Embree's packets behind its traversal.
#[derive(Clone, Debug)]
pub struct SideBySide {
    pub workload: u32,
    /// The files' or engines' names, as the report prints them.
    pub own: String,
    pub versus: String,
    pub quantity: InTurn,
    /// Each measured round's `quantity` with the workload's plan and with the other.
    pub own_ms: Vec<f64>,
    pub versus_ms: Vec<f64>,
}

impl SideBySide {
    /// The other file's frame over the workload's, round by round: each
    /// ratio is of two frames run one after the other, so that a slow spell
    /// of the machine slows both.
    pub fn ratios(&self) -> Vec<f64> {
        (self.versus_ms.iter().zip(&self.own_ms))
            .map(|(versus, own)| versus / own)
            .collect()
    }
}

fn file_name(path: &Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |name| name.to_string_lossy().into_owned(),
    )
}

impl ViewResult {
    /// WORKLOAD1's intersection time (its unfused `map<intersect>` stage), if
    /// WORKLOAD1 ran.
    pub fn workload1_intersect_ms(&self) -> Option<f64> {
        self.workloads
            .iter()
            .find(|w| w.workload == 1)
            .and_then(|w| w.unfused.intersect_ms())
    }

    /// The same with `engine` behind `intersect`, if it ran.
    pub fn engine_workload1_intersect_ms(&self, engine: Engine) -> Option<f64> {
        self.engines
            .iter()
            .find(|e| e.engine == engine)
            .and_then(|e| e.unfused.intersect_ms())
    }

    /// The fused frame of `workload` with `engine` behind its traversal, if it ran.
    pub fn engine_frame(&self, workload: u32, engine: Engine) -> Option<&Measurement> {
        self.engine_frames
            .iter()
            .find(|r| r.workload == workload && r.engine == engine)
            .map(|r| &r.fused)
    }
}

#[derive(Clone, Debug)]
pub struct SceneResult {
    pub name: String,
    pub triangles: usize,
    /// Reading or generating the mesh.
    pub load_ms: f64,
    /// Vertex normals computed at load (meshes without normals).
    pub normals_ms: f64,
    /// dpp's BVH (obvhs build and flattening).
    pub bvh_ms: f64,
    /// Embree's scene (copy and BVH build), with `--engine embree`, at its
    /// default quality and at `RTC_BUILD_QUALITY_HIGH`.
    pub embree_build_ms: Option<f64>,
    pub embree_high_build_ms: Option<f64>,
    pub views: Vec<ViewResult>,
}

pub fn bench(args: BenchArgs, library: &FunctorLibrary) -> Result<(), Failure> {
    let mut distribution =
        Distribution::init(args.decompose, CompositeSchedule::RadixK(DEFAULT_RADIX))
            .map_err(Failure::Run)?;
    if distribution.size() > 1 {
        let mut across = || {
            distribution
                .check_same_command_line()
                .map_err(Failure::Input)?;
            let setup = crate::agree_failure(&distribution, check(&args).map_err(Failure::Input))?;
            if setup.embree || args.backend != Backend::Cpu {
                return Err(Failure::Input(
                    "error: across ranks dpp bench runs the CPU backend's engine only (no --engine embree, no --backend gpu)".into(),
                ));
            }
            if args.versus.is_some() {
                return Err(Failure::Input(
                    "error: --versus compares two files in one process; run it without mpirun"
                        .into(),
                ));
            }
            across_ranks::bench_across_ranks(&args, &setup, library, &mut distribution)
        };
        let result = across();
        return crate::distributed_end(&distribution, result);
    }
    let setup = check(&args).map_err(Failure::Input)?;
    let pool = crate::thread_pool(args.threads)?;
    let threads = pool.current_num_threads();
    // Opened once, before anything is measured: device creation is never part of a frame.
    let gpu = match args.backend {
        Backend::Cpu => None,
        Backend::Gpu => {
            Some(GpuContext::new().map_err(|e| Failure::Run(format!("--backend gpu: {e}")))?)
        }
    };
    let gpu = gpu.as_ref();
    if setup.volume {
        return volume::bench_volume(&args, &setup, library, &pool, gpu, &distribution);
    }

    let mut plans = Vec::new();
    // Part of WORKLOAD2's time to first image.
    let mut workload2_compile_ms = None;
    for &workload in &setup.workloads {
        let path = setup.pipelines.join(format!("workload{workload}.dpp"));
        let start = Instant::now();
        let fused = compile(&path, library, true)?;
        if workload == 2 {
            workload2_compile_ms = Some(ms(start.elapsed()));
        }
        let unfused = compile(&path, library, false)?;
        plans.push((workload, path, fused, unfused));
    }
    let versus = match &args.versus {
        Some(path) => Some((path, compile(path, library, true)?)),
        None => None,
    };

    // On the GPU the stage times come from as many profiled runs as measured ones.
    let profiled = if gpu.is_some() { args.rounds } else { 0 };
    let rounds = u64::from(args.warmup + args.rounds + profiled);
    // With Embree: WORKLOAD1 fused and unfused and WORKLOAD2 fused for each
    // of its two modes on each of its two scenes, WORKLOAD3 fused on the
    // default-quality scene.
    let embree_plans = |workload: u32, plans: u64, engines: u64| {
        if setup.embree && setup.workloads.contains(&workload) {
            engines * plans
        } else {
            0
        }
    };
    let per_view = 2 * setup.workloads.len() as u64
        + if versus.is_some() { 2 } else { 0 }
        + embree_plans(1, 2, 4)
        + embree_plans(2, 1, 4)
        + embree_plans(3, 1, 2)
        // dpp and Embree's packets in turn (WORKLOAD1 and WORKLOAD3).
        + embree_plans(1, 2, 1)
        + embree_plans(3, 2, 1);
    let total = setup.scenes.len() as u64 * setup.views.len() as u64 * per_view * rounds;
    let progress = progress_bar(total);

    let mut scenes = Vec::new();
    for spec in &setup.scenes {
        progress.set_message(format!("{}: loading", spec.name()));
        let loaded = load(spec, &args, library)?;
        let scene = Arc::new(loaded.scene);
        // Embree's scene at its default build quality and at its highest.
        #[cfg(feature = "embree")]
        let embree = if setup.embree {
            use dpp_tracer::functors::intersect_embree::{EmbreeQuality, EmbreeScene};
            let robust = setup.embree_test == EmbreeTest::Robust;
            // Embree starts its worker threads with its first scene: a
            // triangle's, so that neither timed build pays for that.
            let triangle = TriangleMesh {
                positions: vec![glam::Vec3::ZERO, glam::Vec3::X, glam::Vec3::Y],
                triangles: vec![[0, 1, 2]],
                normals: None,
                scalars: None,
            };
            EmbreeScene::build(&triangle, robust).map_err(|e| Failure::Run(e.to_string()))?;
            let mut built = Vec::new();
            for quality in [EmbreeQuality::Default, EmbreeQuality::High] {
                progress.set_message(format!(
                    "{}: building Embree's BVH ({quality:?} quality)",
                    spec.name()
                ));
                let scene = EmbreeScene::build_at(&scene.mesh, robust, quality)
                    .map_err(|e| Failure::Run(e.to_string()))?;
                built.push(Arc::new(scene));
            }
            Some((built[0].clone(), built[1].clone()))
        } else {
            None
        };
        #[cfg(not(feature = "embree"))]
        let embree: Option<()> = None;

        let mut result = SceneResult {
            name: spec.name(),
            triangles: scene.mesh.triangles.len(),
            load_ms: ms(loaded.load),
            normals_ms: ms(loaded.normals),
            bvh_ms: ms(loaded.bvh),
            #[cfg(feature = "embree")]
            embree_build_ms: embree.as_ref().map(|e| ms(e.0.build_time)),
            #[cfg(feature = "embree")]
            embree_high_build_ms: embree.as_ref().map(|e| ms(e.1.build_time)),
            #[cfg(not(feature = "embree"))]
            embree_build_ms: None,
            #[cfg(not(feature = "embree"))]
            embree_high_build_ms: None,
            views: Vec::new(),
        };
        for (view_name, _) in &setup.views {
            let request = scene_request(spec, view_name, args.size, args.iso);
            let view =
                SceneSetup::with_scene(scene.clone(), &spec.name(), &request, &Default::default())
                    .map_err(Failure::Input)?;
            let rays = u64::from(view.camera.pixels());
            let mut view_result = ViewResult {
                view: view_name.clone(),
                rays,
                workloads: Vec::new(),
                engines: Vec::new(),
                engine_frames: Vec::new(),
                side_by_side: None,
                engines_in_turn: Vec::new(),
            };
            let mut dpp_prims = None;
            for (workload, _, fused, unfused) in &plans {
                let label = |fusion: &str| {
                    format!("{} {view_name} workload{workload} {fusion}", spec.name())
                };
                progress.set_message(label("fused"));
                let (fused, _) =
                    measure(fused, library, &view, &pool, gpu, &args, &progress, false)?;
                progress.set_message(label("unfused"));
                let (unfused, prims) = measure(
                    unfused,
                    library,
                    &view,
                    &pool,
                    gpu,
                    &args,
                    &progress,
                    *workload == 1,
                )?;
                if *workload == 1 {
                    dpp_prims = prims;
                }
                view_result.workloads.push(WorkloadResult {
                    workload: *workload,
                    fused,
                    unfused,
                });
            }
            if let (Some((path, versus)), [(workload, own_path, own, _)]) = (&versus, &plans[..]) {
                progress.set_message(format!(
                    "{} {view_name} workload{workload} against {}",
                    spec.name(),
                    path.display()
                ));
                let runs =
                    |plan| FrameRuns::new(plan, library, &view, &pool, gpu, &args, &progress);
                let (own_ms, versus_ms) =
                    measure_side_by_side(&runs(own), &runs(versus), &args, InTurn::Frame)?;
                view_result.side_by_side = Some(SideBySide {
                    workload: *workload,
                    own: file_name(own_path),
                    versus: file_name(path),
                    quantity: InTurn::Frame,
                    own_ms,
                    versus_ms,
                });
            }
            #[cfg(feature = "embree")]
            if let Some((embree, embree_high)) = &embree {
                use dpp_tracer::functors::intersect_embree::{library_with_embree, EmbreeMode};
                let path_of = |workload: u32| plans.iter().find(|p| p.0 == workload).map(|p| &p.1);
                for (engine, mode, embree) in [
                    (Engine::EmbreeSingle, EmbreeMode::Single, embree),
                    (Engine::EmbreePacket, EmbreeMode::Packet16, embree),
                    (Engine::EmbreeSingleHigh, EmbreeMode::Single, embree_high),
                    (Engine::EmbreePacketHigh, EmbreeMode::Packet16, embree_high),
                ] {
                    let swapped = library_with_embree(library, embree.clone(), mode)
                        .map_err(|e| Failure::Run(e.message))?;
                    // The bars' comparison: dpp's plan and the same with
                    // Embree's packets, a frame of each in turn, so that a
                    // slow spell of the machine falls on both.
                    if engine == Engine::EmbreePacket {
                        for (workload, path, own_fused, own_unfused) in &plans {
                            let (quantity, own, fuse) = match workload {
                                1 => (InTurn::IntersectStage, own_unfused, false),
                                3 => (InTurn::Frame, own_fused, true),
                                _ => continue,
                            };
                            progress.set_message(format!(
                                "{} {view_name} workload{workload}: dpp and {} in turn",
                                spec.name(),
                                engine.name()
                            ));
                            let theirs = compile(path, &swapped, fuse)?;
                            let runs = |plan, library| {
                                FrameRuns::new(plan, library, &view, &pool, None, &args, &progress)
                            };
                            let (own_ms, versus_ms) = measure_side_by_side(
                                &runs(own, library),
                                &runs(&theirs, &swapped),
                                &args,
                                quantity,
                            )?;
                            view_result.engines_in_turn.push(SideBySide {
                                workload: *workload,
                                own: "dpp".into(),
                                versus: engine.name().into(),
                                quantity,
                                own_ms,
                                versus_ms,
                            });
                        }
                    }
                    // The high-quality scene is for the set-up tables: its
                    // trace rate (WORKLOAD1) and WORKLOAD2's first image.
                    let workloads: &[u32] = if engine.high_quality() { &[2] } else { &[2, 3] };
                    for &workload in workloads {
                        let Some(path) = path_of(workload) else {
                            continue;
                        };
                        progress.set_message(format!(
                            "{} {view_name} workload{workload} {}",
                            spec.name(),
                            engine.name()
                        ));
                        let fused = compile(path, &swapped, true)?;
                        let (fused, _) = measure(
                            &fused, &swapped, &view, &pool, None, &args, &progress, false,
                        )?;
                        view_result.engine_frames.push(TracedByEngine {
                            workload,
                            engine,
                            fused,
                        });
                    }
                    let (Some(path), Some(dpp_prims)) = (path_of(1), &dpp_prims) else {
                        continue;
                    };
                    let fused = compile(path, &swapped, true)?;
                    let unfused = compile(path, &swapped, false)?;
                    progress.set_message(format!(
                        "{} {view_name} workload1 {}",
                        spec.name(),
                        engine.name()
                    ));
                    let (fused, _) = measure(
                        &fused, &swapped, &view, &pool, None, &args, &progress, false,
                    )?;
                    let (unfused, prims) = measure(
                        &unfused, &swapped, &view, &pool, None, &args, &progress, true,
                    )?;
                    let prims = prims.expect("workload1 outputs prim and depth");
                    let at_border = |pixel: usize, prim: u32| {
                        ray_at_border(&view.camera, &scene.mesh, pixel, prim)
                    };
                    view_result.engines.push(compare(
                        engine, fused, unfused, dpp_prims, &prims, at_border,
                    ));
                }
            }
            let _ = (&embree, &dpp_prims);
            result.views.push(view_result);
        }
        scenes.push(result);
    }
    progress.finish_and_clear();

    let report = Report {
        workload2_compile_ms,
        cpu: cpu_model(),
        gpu: gpu.map(GpuInfo::of),
        threads,
        cpu_elementwise: args.cpu_elementwise,
        bvh: args.bvh,
        size: args.size,
        warmup: args.warmup,
        rounds: args.rounds,
        embree_test: setup.embree.then_some(setup.embree_test),
        scenes,
    };
    let markdown = report.markdown();
    out!("{markdown}");
    let write_text = |path: &Path, text: &str| {
        write_atomically(path, |temporary| {
            std::fs::write(temporary, text).map_err(|e| e.to_string())
        })
        .map_err(Failure::Run)
    };
    if let Some(path) = &args.markdown {
        write_text(path, &markdown)?;
    }
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&report.json())
            .map_err(|e| Failure::Run(e.to_string()))?;
        write_text(path, &(text + "\n"))?;
    }
    if let Some(path) = &args.chart {
        write_atomically(path, |temporary| chart::draw(&report, temporary))
            .map_err(Failure::Run)?;
    }
    let disagreements: Vec<String> = report
        .scenes
        .iter()
        .flat_map(|s| s.views.iter().map(move |v| (s, v)))
        .flat_map(|(s, v)| v.engines.iter().map(move |e| (s, v, e)))
        .filter(|(_, _, e)| !e.agrees())
        .map(|(s, v, e)| {
            format!(
                "{} {}: {} hits {} rays, dpp {}; {} rays hit in only one of them, {} of those at a triangle's border; same triangle on {:.4}% of the rays, a tie on {:.4}%",
                s.name,
                v.view,
                e.engine.name(),
                e.hits_engine,
                e.hits_dpp,
                e.one_sided,
                e.one_sided_at_border,
                100.0 * e.same_triangle,
                100.0 * e.ties
            )
        })
        .collect();
    if !disagreements.is_empty() {
        return Err(Failure::Run(format!(
            "the engines' hits disagree (need every ray that only one of them hits to be at a triangle's border, give or take {} ray(s) per million, and the same triangle or a tie on {}% of the rays):\n  {}",
            ONE_SIDED_RAYS_PER_MILLION,
            100.0 * AGREEMENT,
            disagreements.join("\n  ")
        )));
    }
    Ok(())
}

fn compile(path: &Path, library: &FunctorLibrary, fuse: bool) -> Result<Plan, Failure> {
    crate::compile(
        path,
        library,
        &CompileOptions {
            fuse,
            overrides: Vec::new(),
        },
    )
}

pub(crate) fn ms(duration: Duration) -> f64 {
    duration.as_secs_f64() * 1e3
}

fn progress_bar(total: u64) -> ProgressBar {
    let target = if std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        ProgressDrawTarget::stderr()
    } else {
        ProgressDrawTarget::hidden()
    };
    let bar = ProgressBar::with_draw_target(Some(total), target);
    if let Ok(style) =
        ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} frames  {msg}")
    {
        bar.set_style(style.progress_chars("=> "));
    }
    bar
}

/// What a run of `dpp run` would ask for, for one view of the scene.
fn scene_request(spec: &SceneSpec, view: &str, size: (u32, u32), iso: Option<f32>) -> SceneRequest {
    SceneRequest {
        scenes: vec![spec.clone()],
        size,
        view: view.to_string(),
        eye: None,
        look_at: None,
        up: None,
        fov: 45.0,
        scene_file: None,
        shading: Default::default(),
        iso,
        raw: None,
        color_by: None,
        field: None,
        iso_pipeline: None,
        fuse: true,
        render_volume: false,
        traces_surface: false,
        bvh: BvhBuilder::default(),
    }
}

struct Loaded {
    scene: TraceScene,
    load: Duration,
    normals: Duration,
    bvh: Duration,
}

/// Loads or generates a scene, timing the load, the vertex normals and the BVH apart.
fn load(spec: &SceneSpec, args: &BenchArgs, library: &FunctorLibrary) -> Result<Loaded, Failure> {
    let start = Instant::now();
    let (mut mesh, materials): (TriangleMesh, MeshMaterials) = match spec {
        SceneSpec::Builtin(resolution) => (
            builtin_scene(*resolution).map_err(|e| Failure::Input(format!("error: {e}")))?,
            MeshMaterials::default(),
        ),
        SceneSpec::Generated(dataset, grid) => {
            let volume = (dataset.generate(glam::UVec3::from(*grid)))
                .map_err(|e| Failure::Input(format!("error: {e}")))?;
            let level = args.iso.unwrap_or(dataset.default_level());
            (iso_mesh(volume, level, library)?, MeshMaterials::default())
        }
        SceneSpec::File(path) if volume_setup::is_volume_path(path) => {
            let Some(level) = args.iso else {
                return Err(Failure::Input(format!(
                    "error: `{}` is a volume: give the isosurface level with --iso LEVEL",
                    path.display()
                )));
            };
            let volume = volume_setup::load_volume(path, None, None).map_err(Failure::Input)?;
            (iso_mesh(volume, level, library)?, MeshMaterials::default())
        }
        SceneSpec::File(path) => scene_setup::load_mesh(path, None).map_err(Failure::Input)?,
    };
    let load = start.elapsed();
    let start = Instant::now();
    if mesh.normals.is_none() {
        mesh.validate()
            .map_err(|e| Failure::Input(format!("error: {}: {e}", spec.name())))?;
        mesh.add_crease_normals(dpp_tracer::scene::CREASE_ANGLE_DEGREES.to_radians());
    }
    let normals = start.elapsed();
    let start = Instant::now();
    let scene = TraceScene::built_with(mesh, materials, args.bvh.into())
        .map_err(|e| Failure::Input(format!("error: {}: {e}", spec.name())))?;
    let bvh = start.elapsed();
    Ok(Loaded {
        scene,
        load,
        normals,
        bvh,
    })
}

/// The isosurface of a volume, coloured by height.
fn iso_mesh(
    volume: dpp_tracer::volume::Volume,
    level: f32,
    library: &FunctorLibrary,
) -> Result<TriangleMesh, Failure> {
    let request = volume_setup::IsoRequest {
        level,
        pipeline: None,
        fuse: true,
    };
    let mut mesh = volume_setup::isosurface(volume, &request, library).map_err(Failure::Input)?;
    mesh.scalars = None;
    Ok(mesh)
}

/// One plan's frames on a view: the whole run on the host, from the
/// uniforms to the outputs in host memory (the GPU backend returns once they
/// are downloaded). The frames reuse each other's arrays, as an interactive
/// viewer's would.
struct FrameRuns<'a> {
    plan: &'a Plan,
    library: &'a FunctorLibrary,
    view: &'a SceneSetup,
    pool: &'a rayon::ThreadPool,
    gpu: Option<&'a GpuContext>,
    elementwise: crate::CpuElementwise,
    progress: &'a ProgressBar,
    frame_pool: ColumnPool,
}

impl<'a> FrameRuns<'a> {
    fn new(
        plan: &'a Plan,
        library: &'a FunctorLibrary,
        view: &'a SceneSetup,
        pool: &'a rayon::ThreadPool,
        gpu: Option<&'a GpuContext>,
        args: &BenchArgs,
        progress: &'a ProgressBar,
    ) -> FrameRuns<'a> {
        FrameRuns {
            plan,
            library,
            view,
            pool,
            gpu,
            elementwise: args.cpu_elementwise,
            progress,
            frame_pool: ColumnPool::new(),
        }
    }

    /// One frame and its wall time.
    fn frame(&self, profile: bool) -> Result<(RunResult, Duration), Failure> {
        let (plan, view) = (self.plan, self.view);
        let start = Instant::now();
        let result = match self.gpu {
            None => {
                let context = RunContext {
                    library: self.library,
                    uniforms: &view.uniforms,
                    resources: &view.resources,
                    chunk: dpp_runtime::cpu::kernels::DEFAULT_CHUNK,
                    column_pool: &self.frame_pool,
                    elementwise: self.elementwise.into(),
                };
                self.pool.install(|| run_plan(plan, &context))
            }
            Some(gpu) => {
                let context = GpuRunContext {
                    gpu,
                    library: self.library,
                    uniforms: &view.uniforms,
                    resources: &view.resources,
                    profile,
                };
                self.pool.install(|| run_plan_gpu(plan, &context))
            }
        }
        .map_err(|e| Failure::Run(format!("{}: {e}", plan.pipeline)))?;
        let elapsed = start.elapsed();
        self.progress.inc(1);
        Ok((result, elapsed))
    }

    /// Gives a CPU frame's output arrays to the pool the next frames take
    /// arrays from (the GPU backend allocates its own).
    fn give_back(&self, result: RunResult) {
        if self.gpu.is_some() {
            return;
        }
        for (_, value) in result.outputs {
            if let OutputValue::Array(column) = value {
                self.frame_pool.give(column);
            }
        }
    }
}

/// What a side-by-side measurement times in each frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InTurn {
    /// The whole frame (wall time).
    Frame,
    /// The unfused plan's `map<intersect>` stage (WORKLOAD1's intersection).
    #[cfg_attr(not(feature = "embree"), allow(dead_code))]
    IntersectStage,
}

impl InTurn {
    pub fn name(self) -> &'static str {
        match self {
            InTurn::Frame => "fused frame",
            InTurn::IntersectStage => "map<intersect> stage",
        }
    }
}

/// The warm-up and measured rounds of two plans in turn (`--versus`, or dpp
/// and Embree's packets), a frame of each per round, the first of the two
/// alternating from round to round so that neither always runs in the
/// other's wake; returns each plan's measured `quantity`, ms.
fn measure_side_by_side(
    own: &FrameRuns<'_>,
    versus: &FrameRuns<'_>,
    args: &BenchArgs,
    quantity: InTurn,
) -> Result<(Vec<f64>, Vec<f64>), Failure> {
    let frame = |runs: &FrameRuns<'_>| -> Result<f64, Failure> {
        let (result, elapsed) = runs.frame(false)?;
        let measured = match quantity {
            InTurn::Frame => ms(elapsed),
            InTurn::IntersectStage => (result.profile.iter())
                .find(|stage| stage.label == INTERSECT_STAGE)
                .map(|stage| ms(stage.time))
                .ok_or_else(|| {
                    Failure::Run(format!(
                        "{}: no `map<intersect>` stage to time",
                        runs.plan.pipeline
                    ))
                })?,
        };
        runs.give_back(result);
        Ok(measured)
    };
    let (mut own_ms, mut versus_ms) = (Vec::new(), Vec::new());
    for round in 0..args.warmup + args.rounds {
        let (own_frame, versus_frame) = if round % 2 == 0 {
            let own_frame = frame(own)?;
            (own_frame, frame(versus)?)
        } else {
            let versus_frame = frame(versus)?;
            (frame(own)?, versus_frame)
        };
        if round >= args.warmup {
            own_ms.push(own_frame);
            versus_ms.push(versus_frame);
        }
    }
    Ok((own_ms, versus_ms))
}

/// Runs `plan` for the warm-up and measured rounds; with `keep_prims`, also
/// returns the `prim` and `depth` outputs of the last measured round. On the
/// GPU (`gpu`), the measured rounds run without profiling (which would wait for
/// the device after every stage) and `args.rounds` profiled runs follow them
/// for the stage times.
#[allow(clippy::too_many_arguments)]
fn measure(
    plan: &Plan,
    library: &FunctorLibrary,
    view: &SceneSetup,
    pool: &rayon::ThreadPool,
    gpu: Option<&GpuContext>,
    args: &BenchArgs,
    progress: &ProgressBar,
    keep_prims: bool,
) -> Result<(Measurement, Option<Hits>), Failure> {
    let runs = FrameRuns::new(plan, library, view, pool, gpu, args, progress);
    let mut measurement = Measurement {
        frames_ms: Vec::new(),
        first_frame_ms: 0.0,
        stages: Vec::new(),
        profiled_frames_ms: Vec::new(),
    };
    let mut prims = None;
    for round in 0..args.warmup + args.rounds {
        let (result, elapsed) = runs.frame(false)?;
        if round == 0 {
            measurement.first_frame_ms = ms(elapsed);
        }
        if round < args.warmup {
            runs.give_back(result);
            continue;
        }
        measurement.frames_ms.push(ms(elapsed));
        if gpu.is_none() {
            add_stages(&mut measurement.stages, &result.profile, args.rounds);
        }
        if keep_prims && round + 1 == args.warmup + args.rounds {
            let output = |name: &str| {
                result
                    .outputs
                    .iter()
                    .find(|(output, _)| output == name)
                    .and_then(|(_, value)| match value {
                        OutputValue::Array(column) => Some(column.clone()),
                        OutputValue::Host(_) => None,
                    })
            };
            if let (Some(prim), Some(depth)) = (output("prim"), output("depth")) {
                prims = Some(Hits {
                    prim: prim.view().as_u32().to_vec(),
                    depth: depth.view().as_f32().to_vec(),
                });
            }
        }
        // A viewer draws the next frame into the last one's images.
        runs.give_back(result);
    }
    if gpu.is_some() {
        for _ in 0..args.rounds {
            let (result, elapsed) = runs.frame(true)?;
            measurement.profiled_frames_ms.push(ms(elapsed));
            add_stages(&mut measurement.stages, &result.profile, args.rounds);
        }
    }
    Ok((measurement, prims))
}

/// Adds one run's stage times to the means over `rounds` runs.
fn add_stages(stages: &mut Vec<StageTime>, profile: &[StageTiming], rounds: u32) {
    if stages.is_empty() {
        *stages = profile
            .iter()
            .map(|t| StageTime {
                stage: t.stage,
                label: t.label.clone(),
                ms: 0.0,
                ops: t
                    .ops
                    .iter()
                    .map(|op| OpTiming {
                        label: op.label.clone(),
                        thread_time: Duration::ZERO,
                    })
                    .collect(),
            })
            .collect();
    }
    for (stage, timing) in stages.iter_mut().zip(profile) {
        stage.ms += ms(timing.time) / f64::from(rounds);
        for (op, measured) in stage.ops.iter_mut().zip(&timing.ops) {
            op.thread_time += measured.thread_time / rounds;
        }
    }
}

/// Hit counts, and the shares of rays on which both engines name the same
/// triangle, or different triangles at the same distance.
#[cfg_attr(not(feature = "embree"), allow(dead_code))]
fn compare(
    engine: Engine,
    fused: Measurement,
    unfused: Measurement,
    dpp: &Hits,
    other: &Hits,
    at_border: impl Fn(usize, u32) -> bool,
) -> EngineResult {
    let hits = |h: &Hits| h.prim.iter().filter(|&&p| p != MISS_PRIM).count() as u64;
    let rays = dpp.prim.len();
    let comparable = rays > 0 && rays == other.prim.len() && rays == dpp.depth.len();
    let (mut same, mut ties) = (0usize, 0usize);
    let (mut one_sided, mut one_sided_at_border) = (0u64, 0u64);
    let mut mismatches = Vec::new();
    for i in 0..rays.min(other.prim.len()) {
        let (dpp_hits, other_hits) = (dpp.prim[i] != MISS_PRIM, other.prim[i] != MISS_PRIM);
        if dpp_hits == other_hits {
            // Neither or both.
        } else if at_border(i, if dpp_hits { dpp.prim[i] } else { other.prim[i] }) {
            one_sided += 1;
            one_sided_at_border += 1;
        } else {
            one_sided += 1;
            if mismatches.len() < MISMATCH_SAMPLES {
                mismatches.push((
                    i as u32,
                    dpp.prim[i],
                    dpp.depth[i],
                    other.prim[i],
                    other.depth[i],
                ));
            }
        }
        if dpp.prim[i] == other.prim[i] {
            same += 1;
        } else if dpp.prim[i] != MISS_PRIM
            && other.prim[i] != MISS_PRIM
            && (dpp.depth[i] - other.depth[i]).abs() <= SAME_DISTANCE * dpp.depth[i].abs()
        {
            ties += 1;
        }
    }
    let share = |count: usize| {
        if comparable {
            count as f64 / rays as f64
        } else {
            0.0
        }
    };
    EngineResult {
        engine,
        fused,
        unfused,
        hits_dpp: hits(dpp),
        hits_engine: hits(other),
        same_triangle: share(same),
        ties: share(ties),
        rays: rays as u64,
        one_sided,
        one_sided_at_border,
        mismatches,
    }
}

/// The CPU's model name from /proc/cpuinfo, when there is one.
fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|text| {
            text.lines()
                .find(|line| line.starts_with("model name"))
                .and_then(|line| line.split_once(':'))
                .map(|(_, name)| name.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use dpp_tracer::builtin_scene::DEFAULT_RESOLUTION;
    use dpp_tracer::volume::generate::Dataset;
    use glam::Vec3;

    #[test]
    fn the_cost_beyond_the_traversal_takes_each_stages_traversal_share() {
        let op = |label: &str, ms: u64| OpTiming {
            label: label.into(),
            thread_time: Duration::from_millis(ms),
        };
        let stage = |ms: f64, ops: Vec<OpTiming>| StageTime {
            stage: 0,
            label: String::new(),
            ms,
            ops,
        };
        let measurement = |stages: Vec<StageTime>| Measurement {
            frames_ms: vec![100.0, 140.0],
            first_frame_ms: 200.0,
            stages,
            profiled_frames_ms: Vec::new(),
        };
        // A 60 ms stage whose ops took 30 + 90 thread-ms, three quarters of it
        // in the traversal (45 ms of its wall time), and a 40 ms stage with
        // none: 120 - 45 = 75 ms over 1000 pixels.
        let traced = measurement(vec![
            stage(
                60.0,
                vec![
                    op("rays = map<cameraRay>", 10),
                    op("hits = map<intersect>", 60),
                    op("blocked = map<occluded>", 30),
                    op("rgb = map<shader>", 20),
                ],
            ),
            stage(40.0, vec![op("map<antiAlias>", 50)]),
        ]);
        let ns = traced.beyond_traversal_ns_per_pixel(1000).unwrap();
        assert!((ns - 75e3).abs() < 1e-6, "{ns}");
        // Stages never split op by op (the GPU's) give no figure.
        let unsplit = measurement(vec![stage(60.0, Vec::new())]);
        assert_eq!(unsplit.beyond_traversal_ns_per_pixel(1000), None);
    }

    #[test]
    fn scene_specs() {
        assert_eq!(
            SceneSpec::parse("builtin"),
            Ok(SceneSpec::Builtin(DEFAULT_RESOLUTION))
        );
        assert_eq!(SceneSpec::parse("builtin:64"), Ok(SceneSpec::Builtin(64)));
        assert_eq!(
            SceneSpec::parse("rm:128,64,32"),
            Ok(SceneSpec::Generated(
                Dataset::RichtmyerMeshkov,
                [128, 64, 32]
            ))
        );
        assert_eq!(
            SceneSpec::parse("rm:96"),
            Ok(SceneSpec::Generated(Dataset::RichtmyerMeshkov, [96; 3]))
        );
        assert_eq!(
            SceneSpec::parse("sphere:16,8,8"),
            Ok(SceneSpec::Generated(Dataset::Sphere, [16, 8, 8]))
        );
        for bad in [
            "builtin:2",
            "builtin:x",
            "rm:",
            "rm:1,2",
            "rm:2000",
            "pbte:x",
            "/no/such.ply",
        ] {
            assert!(SceneSpec::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn agreement_needs_equal_hit_counts_and_ids() {
        let m = Measurement {
            frames_ms: vec![1.0],
            first_frame_ms: 1.0,
            stages: vec![],
            profiled_frames_ms: vec![],
        };
        let miss = MISS_PRIM;
        let prim: Vec<u32> = (0..2000)
            .map(|i| if i % 3 == 0 { miss } else { i })
            .collect();
        let depth: Vec<f32> = prim
            .iter()
            .map(|&p| if p == miss { f32::INFINITY } else { p as f32 })
            .collect();
        let dpp = Hits {
            prim: prim.clone(),
            depth: depth.clone(),
        };
        let engine = Engine::EmbreeSingle;
        let nowhere = |_: usize, _: u32| false;
        let result = compare(engine, m.clone(), m.clone(), &dpp, &dpp, nowhere);
        assert!(result.agrees());
        assert_eq!((result.same_triangle, result.ties), (1.0, 0.0));
        // Another triangle, farther away: 99.95% still agree.
        let mut other = Hits { prim, depth };
        other.prim[1] = 7;
        other.depth[1] = 9.0;
        let result = compare(engine, m.clone(), m.clone(), &dpp, &other, nowhere);
        assert!(result.agrees());
        assert_eq!((result.same_triangle, result.ties), (0.9995, 0.0));
        // Many ties: different triangles at the same distance.
        for i in (2..400).filter(|i| i % 3 != 0) {
            other.prim[i] += 1;
        }
        let result = compare(engine, m.clone(), m.clone(), &dpp, &other, nowhere);
        assert!(result.same_triangle < 0.9 && result.agrees());
        // A miss became a hit.
        other.prim[0] = 7;
        other.depth[0] = 7.0;
        let result = compare(engine, m.clone(), m.clone(), &dpp, &other, nowhere);
        assert!(!result.agrees());
        assert_eq!(result.hits_engine, result.hits_dpp + 1);
        assert_eq!((result.one_sided, result.one_sided_at_border), (1, 0));
        assert_eq!(result.mismatches, vec![(0, miss, f32::INFINITY, 7, 7.0)]);
        // ... at the border of the triangle it hit: they agree.
        let at_border = |pixel: usize, prim: u32| (pixel, prim) == (0, 7);
        let result = compare(engine, m.clone(), m.clone(), &dpp, &other, at_border);
        assert!(result.agrees());
        assert_eq!((result.one_sided, result.one_sided_at_border), (1, 1));
        assert!(result.mismatches.is_empty());
        // Many rays that one engine hits at a border (1.5% of them, the share
        // of the same triangle below 99.9%) still agree, as a lone triangle's
        // open edge through a small frame's pixel centres makes them ...
        let mut along_an_edge = Hits {
            prim: dpp.prim.clone(),
            depth: dpp.depth.clone(),
        };
        for pixel in (0..30).map(|i| 3 * i) {
            along_an_edge.prim[pixel] = 7;
            along_an_edge.depth[pixel] = 7.0;
        }
        let at_border = |pixel: usize, prim: u32| prim == 7 && pixel % 3 == 0;
        let result = compare(
            engine,
            m.clone(),
            m.clone(),
            &dpp,
            &along_an_edge,
            at_border,
        );
        assert!(result.same_triangle < AGREEMENT);
        assert!(result.agrees());
        // ... but as many rays that hit two different triangles do not.
        let mut different = Hits {
            prim: dpp.prim.clone(),
            depth: dpp.depth.clone(),
        };
        for pixel in (0..30).map(|i| 3 * i + 1) {
            different.prim[pixel] = 7;
            different.depth[pixel] = 7.0;
        }
        let result = compare(engine, m.clone(), m, &dpp, &different, nowhere);
        assert!(!result.agrees());
    }

    #[test]
    fn rays_at_a_triangles_border_are_told_from_rays_inside_and_outside() {
        // The unit right triangle in z = 0, seen from above by a 3x3 camera
        // whose centre pixel's ray runs down the z axis.
        let mesh = TriangleMesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            triangles: vec![[0, 1, 2]],
            normals: None,
            scalars: None,
        };
        let camera = |eye: Vec3| Camera::new(eye, eye - Vec3::Z, Vec3::Y, 10.0, 3, 3).unwrap();
        let centre = 4;
        // Through the hypotenuse, inside, outside, and through a vertex.
        assert!(ray_at_border(
            &camera(Vec3::new(0.5, 0.5, 1.0)),
            &mesh,
            centre,
            0
        ));
        assert!(!ray_at_border(
            &camera(Vec3::new(0.25, 0.25, 1.0)),
            &mesh,
            centre,
            0
        ));
        assert!(!ray_at_border(
            &camera(Vec3::new(0.6, 0.6, 1.0)),
            &mesh,
            centre,
            0
        ));
        assert!(ray_at_border(
            &camera(Vec3::new(0.0, 0.0, 1.0)),
            &mesh,
            centre,
            0
        ));
        // A sliver a thousandth as wide as long: a ray about 4 rounding steps
        // (at the eye's distance, about 1) outside its long edge is at the
        // border, though that is half a thousandth of the sliver's width, more
        // than BORDER_BAND; one a tenth of its width outside is not.
        let sliver = TriangleMesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(0.5, 1e-3, 0.0)],
            ..mesh.clone()
        };
        assert!(ray_at_border(
            &camera(Vec3::new(0.5, -4.0 * f32::EPSILON, 1.0)),
            &sliver,
            centre,
            0
        ));
        assert!(!ray_at_border(
            &camera(Vec3::new(0.5, -1e-4, 1.0)),
            &sliver,
            centre,
            0
        ));
        // A triangle the scene does not have.
        assert!(!ray_at_border(
            &camera(Vec3::new(0.5, 0.5, 1.0)),
            &mesh,
            centre,
            1
        ));
    }
}
