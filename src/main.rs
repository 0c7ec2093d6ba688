//! `dpp`: run, inspect and check `.dpp` pipelines.
//!
//! Exit status (docs/language.md §5): 0 on success, 2 on input errors (a malformed
//! pipeline, bad arguments, an unreadable scene), 1 on run-time failures.

#[macro_use]
mod console;
mod bench;
mod colorbar;
mod distributed;
mod outputs;
mod progress;
mod scene_setup;
mod volume_setup;

use clap::{Parser, Subcommand, ValueEnum};
use dpp_gpu::{run_plan_gpu_observed, GpuContext, GpuRunContext};
use dpp_runtime::compile::plan_text::plan_to_text;
use dpp_runtime::cpu::column_pool::ColumnPool;
use dpp_runtime::cpu::compiled::Elementwise;
use dpp_runtime::cpu::exec::{run_plan_observed, RunContext};
use dpp_runtime::interpret::{
    listed_op_shares, OutputValue, RunError, RunHooks, StageStart, StageTiming,
};
use dpp_runtime::{compile_file, CompileOptions, FunctorLibrary, Plan};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

#[derive(Parser)]
#[command(
    name = "dpp",
    version,
    about = "A ray tracer for scientific visualisation built from data-parallel primitives"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Compile a pipeline and run it on a scene (the built-in one without SCENE).
    Run(Box<RunArgs>),
    /// Print the compiled plan of a pipeline.
    Plan(PlanArgs),
    /// Check pipelines for errors without running them.
    Check {
        #[arg(required = true)]
        files: Vec<PathBuf>,
    },
    /// List every functor with its signature, and the uniforms.
    Functors,
    /// Generate one of the paper's data sets procedurally, as a NIfTI volume.
    Gen(GenArgs),
    /// Extract an isosurface of a volume (with pipelines/isosurface.dpp) as a mesh.
    Iso(IsoArgs),
    /// Measure the workloads as the paper did (views, warm-up and measured rounds, fused and unfused).
    Bench(Box<bench::BenchArgs>),
}

#[derive(clap::Args)]
struct GenArgs {
    /// `rm` (Richtmyer–Meshkov mixing layer), `pbte` (lead telluride crystal) or `sphere`.
    name: String,
    /// Samples along x, y and z; the paper's grids are 128,128,128 to 400,400,256.
    #[arg(long, default_value = "128,128,128", value_parser = parse_grid)]
    grid: [u32; 3],
    /// Where to write the volume (.nii or .nii.gz).
    #[arg(short, long, value_name = "FILE.nii.gz")]
    output: PathBuf,
}

#[derive(clap::Args)]
struct IsoArgs {
    /// A NIfTI volume (.nii, .nii.gz), a VTK one (.vti, .pvti, legacy .vtk), or a raw brick with --raw.
    volume: PathBuf,
    /// The isovalue.
    #[arg(long, allow_hyphen_values = true)]
    level: f32,
    /// The layout of a raw brick: `XxYxZ:u8|u16|f32[:le|:be][:header=N][:spacing=SX,SY,SZ]`.
    #[arg(long, value_name = "SPEC")]
    raw: Option<String>,
    /// Where to write the mesh (.ply or .obj).
    #[arg(short, long, value_name = "FILE.ply")]
    output: PathBuf,
    /// An edited isosurface pipeline instead of the built-in pipelines/isosurface.dpp.
    #[arg(long = "iso-pipeline", value_name = "FILE.dpp")]
    iso_pipeline: Option<PathBuf>,
    /// For a VTK volume: the point array to use (`NAME`, `NAME:mag`, `NAME:0`).
    #[arg(long, value_name = "NAME[:mag|:N]")]
    field: Option<String>,
    #[arg(long)]
    no_fuse: bool,
    #[arg(long)]
    threads: Option<usize>,
}

#[derive(clap::Args)]
struct CompileArgs {
    /// Turn map fusion off (one stage per primitive).
    #[arg(long)]
    no_fuse: bool,
    /// Override a param: `--set maxDepth=1` (repeatable).
    #[arg(long = "set", value_name = "NAME=VALUE", value_parser = parse_assignment)]
    set: Vec<(String, String)>,
}

impl CompileArgs {
    fn options(&self) -> CompileOptions {
        CompileOptions {
            fuse: !self.no_fuse,
            overrides: self.set.clone(),
        }
    }
}

#[derive(clap::Args)]
struct RunArgs {
    pipeline: PathBuf,
    /// The scene: a mesh (.obj, .ply, gzipped too; VTK .vtp, .vtu, .pvtp,
    /// .pvtu, legacy .vtk), a volume (.nii, .nii.gz, VTK .vti, .pvti, legacy
    /// .vtk, a raw brick with --raw), a generated volume (`rm:X,Y,Z`, `pbte:X,Y,Z`,
    /// `sphere:X,Y,Z`) or `builtin[:RESOLUTION]` (the default); several mesh
    /// files are the pieces of one scene (dealt out to ranks under mpirun).
    #[arg(value_name = "SCENE")]
    scenes: Vec<String>,
    /// Where the `image` output goes (PNG). Default: `<pipeline name>.png`.
    #[arg(short, long, value_name = "FILE.png")]
    output: Option<PathBuf>,
    /// Write any output: `--out depth=depth.npy` (.npy for any array, .png for colours).
    #[arg(long = "out", value_name = "NAME=FILE", value_parser = parse_assignment)]
    outs: Vec<(String, String)>,
    /// Image size.
    #[arg(long, default_value = "1024x768", value_parser = parse_size)]
    size: (u32, u32),
    /// A standard view of the scene's bounds (docs/language.md §8).
    #[arg(long, default_value = "front")]
    view: String,
    /// Camera position (overrides the view's).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    eye: Option<[f32; 3]>,
    #[arg(long = "look-at", value_parser = parse_vec3, allow_hyphen_values = true)]
    look_at: Option<[f32; 3]>,
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    up: Option<[f32; 3]>,
    /// Vertical field of view in degrees.
    #[arg(long, default_value_t = 45.0)]
    fov: f32,
    /// A point light `X,Y,Z[,INTENSITY]` (repeatable; replaces the default lights).
    #[arg(long = "light", value_name = "X,Y,Z[,I]", allow_hyphen_values = true)]
    lights: Vec<String>,
    /// Colour map over the scalar: viridis, inferno, magma, plasma, cividis, turbo, cool-to-warm, grey.
    #[arg(long)]
    colormap: Option<String>,
    /// A volume's transfer function: a colour map name (opacity ramps 0 to 1)
    /// or a ParaView colour-map preset (`FILE.json`, `FILE.json:NAME`).
    #[arg(long, value_name = "FILE.json|NAME")]
    transfer: Option<String>,
    /// The scalar values at the two ends of the colour map: `A,B`.
    #[arg(long = "scalar-range", value_name = "A,B", allow_hyphen_values = true)]
    scalar_range: Option<String>,
    /// Lights, colour map and materials from a TOML file (default: SCENE.toml beside an OBJ).
    #[arg(long = "scene-file", value_name = "FILE.toml")]
    scene_file: Option<PathBuf>,
    /// `transparent` (PNG alpha from the pipeline's `alpha` output) or a display colour `R,G,B`.
    #[arg(long, value_name = "transparent|R,G,B")]
    background: Option<String>,
    /// Draw a colour bar with the scalar range into the image.
    #[arg(long)]
    colorbar: bool,
    /// For a volume scene: the isosurface level to render.
    #[arg(long, allow_hyphen_values = true)]
    iso: Option<f32>,
    /// For a raw-brick scene: `XxYxZ:u8|u16|f32[:le|:be][:header=N][:spacing=SX,SY,SZ]`.
    #[arg(long, value_name = "SPEC")]
    raw: Option<String>,
    /// For a volume scene: colour the surface by this second volume's values.
    #[arg(long = "color-by", value_name = "VOLUME")]
    color_by: Option<PathBuf>,
    /// For a volume scene: an edited isosurface pipeline.
    #[arg(long = "iso-pipeline", value_name = "FILE.dpp")]
    iso_pipeline: Option<PathBuf>,
    /// For a VTK scene: the array to colour by or to take the isosurface of
    /// (`NAME`, a vector's `NAME:mag` or `NAME:N`; default: the active
    /// scalars, else the first array).
    #[arg(long, value_name = "NAME[:mag|:N]")]
    field: Option<String>,
    /// Worker threads (default: one per core).
    #[arg(long)]
    threads: Option<usize>,
    /// How the BVH is built.
    #[arg(long, value_enum, default_value_t = BvhChoice::Sah)]
    bvh: BvhChoice,
    #[arg(long, value_enum, default_value_t = Backend::Cpu)]
    backend: Backend,
    /// How the CPU backend runs a fused stage's element-wise ops.
    #[arg(long, value_enum, default_value_t = CpuElementwise::Compiled)]
    cpu_elementwise: CpuElementwise,
    /// Under mpirun: each rank holds part of the data (`data`, the default) or
    /// renders part of the image with all of the data (`image`).
    #[arg(long, value_enum, default_value_t = distributed::Decompose::Data)]
    decompose: distributed::Decompose,
    /// Under mpirun with data decomposition: how the ranks composite their
    /// images: `direct`, `binary-swap`, `radix-k` or `radix-k:K`.
    #[arg(long, default_value = "radix-k", value_name = "SCHEDULE")]
    composite: dpp_dist::CompositeSchedule,
    /// Print the time spent in each stage.
    #[arg(long, short = 'v', visible_alias = "verbose")]
    profile: bool,
    /// No progress lines (they are shown only when stderr is a terminal).
    #[arg(long, short = 'q')]
    quiet: bool,
    #[command(flatten)]
    compile: CompileArgs,
}

/// The BVH builders (`dpp_tracer::bvh::BvhBuilder`), by their command-line names.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub(crate) enum BvhChoice {
    /// Top-down binned SAH (ours): the cheapest tree to trace, and a fast build.
    Sah,
    /// obvhs' PLOC, with reinsertion and our collapse of its leaves.
    Ploc,
    /// Karras' linear BVH (Morton codes, a radix sort, the radix tree): the fastest build; its trees trace at 0.72-1.0 of the SAH trees' rate (docs/benchmarks.md).
    Lbvh,
}

impl From<BvhChoice> for dpp_tracer::bvh::BvhBuilder {
    fn from(choice: BvhChoice) -> Self {
        match choice {
            BvhChoice::Sah => dpp_tracer::bvh::BvhBuilder::BinnedSah,
            BvhChoice::Ploc => dpp_tracer::bvh::BvhBuilder::Ploc,
            BvhChoice::Lbvh => dpp_tracer::bvh::BvhBuilder::Lbvh,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub(crate) enum Backend {
    /// rayon on every core.
    Cpu,
    /// wgpu on the first adapter found (`WGPU_BACKEND=vulkan|metal|dx12|gl` chooses).
    Gpu,
}

/// How the CPU backend runs a fused stage's element-wise ops (the maps of
/// generic functors, fills, iotas, fields and gathers between other ops).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub(crate) enum CpuElementwise {
    /// Each run of them compiled into one machine-code loop (Cranelift).
    Compiled,
    /// One op at a time over chunk-sized columns.
    Columns,
}

impl From<CpuElementwise> for Elementwise {
    fn from(choice: CpuElementwise) -> Elementwise {
        match choice {
            CpuElementwise::Compiled => Elementwise::Compiled,
            CpuElementwise::Columns => Elementwise::Columns,
        }
    }
}

#[derive(clap::Args)]
struct PlanArgs {
    pipeline: PathBuf,
    #[arg(long, value_enum, default_value_t = PlanFormat::Text)]
    format: PlanFormat,
    #[command(flatten)]
    compile: CompileArgs,
}

#[derive(Clone, Copy, ValueEnum)]
enum PlanFormat {
    Text,
    Json,
}

/// What went wrong, and so which exit status.
enum Failure {
    /// Bad input: status 2.
    Input(String),
    /// The run failed: status 1.
    Run(String),
}

/// A run's error decides its own exit status by its kind: bad input in the
/// user's data is status 2 even when only the run could find it.
impl From<RunError> for Failure {
    fn from(error: RunError) -> Failure {
        match error.kind.exit_status() {
            2 => Failure::Input(format!("error: {}", error.message)),
            _ => Failure::Run(error.message),
        }
    }
}

impl From<dpp_gpu::GpuError> for Failure {
    fn from(error: dpp_gpu::GpuError) -> Failure {
        Failure::from(RunError::from(error))
    }
}

fn main() -> ExitCode {
    // Before any thread starts: it may set an environment variable.
    dpp_gpu::quiet_headless_vulkan();
    let cli = Cli::parse();
    let library = dpp_tracer::functor_library();
    let result = match cli.command {
        Command::Run(args) => run(*args, &library),
        Command::Plan(args) => plan(args, &library),
        Command::Check { files } => check(&files, &library),
        Command::Gen(args) => generate(args),
        Command::Iso(args) => iso(args, &library),
        Command::Bench(args) => bench::bench(*args, &library),
        Command::Functors => {
            out!("{}", functor_listing(&library));
            Ok(())
        }
    };
    // A closed stdout only silenced the messages; any other failure to write
    // them fails the command once its work is done.
    let result = result.and_then(|()| match console::stdout_failure() {
        Some(failure) => Err(Failure::Run(format!("cannot write to stdout: {failure}"))),
        None => Ok(()),
    });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(failure) => {
            if !console::final_error_silenced() {
                report(&failure);
            }
            ExitCode::from(match failure {
                Failure::Input(_) => 2,
                Failure::Run(_) => 1,
            })
        }
    }
}

/// Most worker threads per core `--threads` may ask for: results never depend
/// on the thread count, and far beyond the cores threads only cost (2000 of
/// them took 7 s to draw a 64×64 image, 10000 did not finish in a minute).
const MAX_THREADS_PER_CORE: usize = 4;

/// The worker threads of a command: one per core, or `--threads`, capped at
/// [`MAX_THREADS_PER_CORE`] per core with a warning.
pub(crate) fn thread_pool(requested: Option<usize>) -> Result<rayon::ThreadPool, Failure> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let most = MAX_THREADS_PER_CORE * cores;
    let threads = match requested {
        Some(n) if n > most => {
            errln!(
                "warning: --threads {n} is more than {MAX_THREADS_PER_CORE} per core ({cores} cores here): using {most} (results do not depend on the thread count)"
            );
            most
        }
        Some(n) => n,
        None => 0,
    };
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| Failure::Run(format!("cannot start {threads} worker threads: {e}")))
}

fn compile(
    path: &std::path::Path,
    library: &FunctorLibrary,
    options: &CompileOptions,
) -> Result<Plan, Failure> {
    let color = std::io::IsTerminal::is_terminal(&std::io::stderr());
    compile_file(path, library, options).map_err(|failure| {
        let count = failure.diagnostics.len();
        Failure::Input(format!(
            "{}error: {} could not be compiled ({count} error{})",
            failure.render(color),
            path.display(),
            if count == 1 { "" } else { "s" }
        ))
    })
}

fn plan(args: PlanArgs, library: &FunctorLibrary) -> Result<(), Failure> {
    let plan = compile(&args.pipeline, library, &args.compile.options())?;
    match args.format {
        PlanFormat::Text => out!("{}", plan_to_text(&plan, library)),
        PlanFormat::Json => outln!(
            "{}",
            serde_json::to_string_pretty(&plan).map_err(|e| Failure::Run(e.to_string()))?
        ),
    }
    Ok(())
}

fn check(files: &[PathBuf], library: &FunctorLibrary) -> Result<(), Failure> {
    let mut failures = Vec::new();
    for file in files {
        match compile(file, library, &CompileOptions::default()) {
            Ok(_) => outln!("{}: ok", file.display()),
            Err(Failure::Input(message) | Failure::Run(message)) => failures.push(message),
        }
    }
    if failures.is_empty() {
        Ok(())
    } else {
        Err(Failure::Input(failures.join("\n")))
    }
}

fn functor_listing(library: &FunctorLibrary) -> String {
    let mut text = String::from("functors:\n");
    for functor in library.iter() {
        let signature = functor.signature();
        text.push_str(&format!(
            "  {}\n      {}\n",
            signature.display(&library.records),
            signature.doc
        ));
    }
    text.push_str("\nrecords:\n");
    for (_, record) in library.records.iter() {
        let fields: Vec<String> = record
            .fields
            .iter()
            .map(|(name, ty)| format!("{name}: {}", ty.name(&library.records)))
            .collect();
        text.push_str(&format!(
            "  {} {{ {} }}  {}\n",
            record.name,
            fields.join(", "),
            record.doc
        ));
    }
    text.push_str("\nuniforms:\n");
    for (record, fields) in &library.uniforms.records {
        for (field, ty) in fields {
            text.push_str(&format!("  {record}.{field}: {ty}\n"));
        }
    }
    text
}

/// What a run reads: a traced scene (a mesh, a volume's isosurface or the
/// built-in scene, with a camera), or, for a pipeline that reads `volume.*`
/// (marching cubes), the volume itself.
enum RunScene {
    Traced(Box<scene_setup::SceneSetup>),
    Volume(volume_setup::VolumeRun),
}

impl RunScene {
    fn uniforms(&self) -> &dpp_runtime::Uniforms {
        match self {
            RunScene::Traced(setup) => &setup.uniforms,
            RunScene::Volume(volume) => &volume.uniforms,
        }
    }

    fn resources(&self) -> &(dyn std::any::Any + Send + Sync) {
        match self {
            RunScene::Traced(setup) => &setup.resources,
            RunScene::Volume(volume) => &volume.resources,
        }
    }

    fn camera(&self) -> Option<&dpp_tracer::Camera> {
        match self {
            RunScene::Traced(setup) => Some(&setup.camera),
            RunScene::Volume(_) => None,
        }
    }

    fn description(&self) -> &str {
        match self {
            RunScene::Traced(setup) => &setup.description,
            RunScene::Volume(volume) => &volume.description,
        }
    }
}

fn run(args: RunArgs, library: &FunctorLibrary) -> Result<(), Failure> {
    // Under mpirun every rank runs this; a failure before the run is agreed
    // by every rank, so that all of them exit with the same error.
    let distribution =
        distributed::Distribution::init(args.decompose, args.composite).map_err(Failure::Run)?;
    let result = run_on(args, library, &distribution);
    distributed_end(&distribution, result)
}

/// The end of a command on every rank: rank 0 says the error, if any (every
/// rank has it: failures are agreed, or end the whole run), before any rank
/// exits, since mpirun ends the job as soon as one rank exits with an error.
fn distributed_end(
    distribution: &distributed::Distribution,
    result: Result<(), Failure>,
) -> Result<(), Failure> {
    if distribution.size() > 1 {
        match &result {
            Err(failure) if distribution.rank() == 0 => report(failure),
            _ => {}
        }
        console::silence_final_error();
        distribution.ranks().barrier();
    }
    result
}

/// Says what went wrong on stderr.
fn report(failure: &Failure) {
    match failure {
        Failure::Input(message) => errln!("{message}"),
        Failure::Run(message) => errln!("error: {message}"),
    }
}

fn run_on(
    args: RunArgs,
    library: &FunctorLibrary,
    distribution: &distributed::Distribution,
) -> Result<(), Failure> {
    distribution
        .check_same_command_line()
        .map_err(Failure::Input)?;
    let compiled = compile(&args.pipeline, library, &args.compile.options());
    let plan = agree_failure(distribution, compiled)?;
    let pool = agree_failure(distribution, thread_pool(args.threads))?;

    let is_root = distribution.rank() == 0;
    let progress = progress::Progress::on_terminal(args.quiet || !is_root);
    let setup_start = Instant::now();
    let scene = run_scene(&args, &plan, library, &progress, distribution)?;
    let setup_time = setup_start.elapsed();
    let observe = |stage: &StageStart<'_>| progress.stage(stage);
    let visibility_order = match &scene {
        RunScene::Traced(setup) if distribution.splits_data() => {
            let mine = setup
                .resources
                .scene
                .mesh
                .bounds()
                .unwrap_or(setup.resources.scene.bounds);
            distributed::visibility_order(&distribution.every_rank_bounds(mine), setup.camera.eye)
        }
        _ => (0..distribution.size()).collect(),
    };
    let width = scene.camera().map_or(0, |camera| camera.width);
    let compositor = distribution.compositor(&library.records, width, visibility_order);
    let hooks = RunHooks {
        observer: Some(&observe),
        compositor: compositor
            .as_ref()
            .map(|c| c as &dyn dpp_runtime::interpret::Compositor),
    };

    let mut description = scene.description().to_string();
    let (result, run_time) = match args.backend {
        Backend::Cpu => {
            let context = RunContext {
                library,
                uniforms: scene.uniforms(),
                resources: scene.resources(),
                chunk: dpp_runtime::cpu::kernels::DEFAULT_CHUNK,
                column_pool: &ColumnPool::new(),
                elementwise: args.cpu_elementwise.into(),
            };
            progress.phase(format!("running {}", plan.pipeline));
            let run_start = Instant::now();
            let result = pool.install(|| run_plan_observed(&plan, &context, hooks));
            (ended(distribution, result)?, run_start.elapsed())
        }
        Backend::Gpu => {
            progress.phase("opening the GPU");
            let gpu = GpuContext::new().map_err(Failure::from)?;
            description.push_str(&format!("\nGPU: {}", gpu.adapter_name()));
            let context = GpuRunContext {
                gpu: &gpu,
                library,
                uniforms: scene.uniforms(),
                resources: scene.resources(),
                profile: args.profile,
            };
            progress.phase(format!("running {} on the GPU", plan.pipeline));
            let run_start = Instant::now();
            let result = pool.install(|| run_plan_gpu_observed(&plan, &context, hooks));
            (ended(distribution, result)?, run_start.elapsed())
        }
    };

    if distribution.size() > 1 && args.profile {
        let triangles = match &scene {
            RunScene::Traced(setup) => setup.resources.scene.mesh.triangles.len(),
            RunScene::Volume(_) => 0,
        };
        let stats = compositor.as_ref().and_then(|c| c.stats());
        let table = distributed::rank_report(distribution, triangles, run_time, stats.as_ref());
        if !table.is_empty() {
            err!("{}\n", table.join("\n"));
        }
    }
    // Rank 0 holds the composited image and writes the outputs.
    if result.composited_elsewhere || !is_root {
        return Ok(());
    }
    let mut requests = args.outs.clone();
    let has_image = plan.outputs.iter().any(|o| o == "image");
    match (&args.output, has_image) {
        (Some(path), _) => requests.push(("image".into(), path.display().to_string())),
        (None, true) if !requests.iter().any(|(n, _)| n == "image") => {
            requests.push(("image".into(), format!("{}.png", plan.pipeline)))
        }
        _ => {}
    }
    for (name, value) in &result.outputs {
        if let OutputValue::Host(value) = value {
            progress.suspend(|| outln!("{name} = {value}"));
        }
    }
    for (name, path) in &requests {
        let Some((_, value)) = result.outputs.iter().find(|(n, _)| n == name) else {
            let names: Vec<&str> = result.outputs.iter().map(|(n, _)| n.as_str()).collect();
            return Err(Failure::Input(format!(
                "error: the pipeline has no output `{name}`; its outputs: {}",
                names.join(", ")
            )));
        };
        let finish = match &scene {
            RunScene::Traced(setup) if name == "image" => {
                image_finish(&args, &result.outputs, setup)?
            }
            _ => outputs::Finish::default(),
        };
        let path = std::path::Path::new(path);
        progress.phase(format!("writing {}", path.display()));
        outputs::write_output(name, value, path, scene.camera(), library, &finish)
            .map_err(Failure::Run)?;
        progress.suspend(|| outln!("wrote {name} to {}", path.display()));
    }
    progress.finish();
    if args.profile {
        err!(
            "{}",
            profile_report(&result.profile, setup_time, run_time, &description)
        );
    }
    Ok(())
}

/// A failure before the run, agreed by every rank (the ranks that did not
/// fail learn of it instead of waiting for the failing one).
fn agree_failure<T>(
    distribution: &distributed::Distribution,
    result: Result<T, Failure>,
) -> Result<T, Failure> {
    if distribution.size() == 1 {
        return result;
    }
    let (result, input) = match result {
        Ok(value) => (Ok(value), true),
        Err(Failure::Input(message)) => (Err(message), true),
        Err(Failure::Run(message)) => (Err(message), false),
    };
    distribution.agree(result).map_err(|message| match input {
        true => Failure::Input(message),
        false => Failure::Run(message),
    })
}

/// The end of a rank's run: a failure in the middle of a distributed run
/// ends every rank (the others may be waiting for this one to composite).
fn ended(
    distribution: &distributed::Distribution,
    result: Result<dpp_runtime::interpret::RunResult, RunError>,
) -> Result<dpp_runtime::interpret::RunResult, Failure> {
    match result {
        Err(error) if distribution.size() > 1 => {
            distributed::abort_on_failure(distribution, error.kind, &error.message)
        }
        other => other.map_err(Failure::from),
    }
}

/// The scene `plan` runs on, once it is sure to provide every uniform the
/// plan reads: a pipeline that reads `volume.*` runs on a volume given as
/// the scene, any other on a traced scene. A uniform the scene cannot provide
/// is a usage error (status 2) that says what to give, found before any work.
fn run_scene(
    args: &RunArgs,
    plan: &Plan,
    library: &FunctorLibrary,
    progress: &progress::Progress,
    distribution: &distributed::Distribution,
) -> Result<RunScene, Failure> {
    let pipeline = args.pipeline.display();
    let reads = plan.uniforms_read();
    let named = |record: &str| -> Vec<String> {
        reads
            .iter()
            .filter(|(r, _)| r == record)
            .map(|(r, f)| format!("`{r}.{f}`"))
            .collect()
    };
    let volume_reads = named("volume");
    let scenes = (args.scenes.iter())
        .map(|text| scene_setup::SceneSpec::parse(text))
        .collect::<Result<Vec<_>, _>>()
        .map_err(Failure::Input)?;
    let traced: Vec<String> = named("camera").into_iter().chain(named("scene")).collect();
    // A pipeline that reads the volume and the camera renders the volume
    // itself (pipelines/volume.dpp); one that reads only the volume runs on
    // its samples (marching cubes).
    let scene = if volume_reads.is_empty() || !traced.is_empty() {
        let shading = shading_overrides(args).map_err(Failure::Input)?;
        let setup = scene_setup::SceneSetup::new(
            &scene_setup::SceneRequest {
                scenes,
                size: args.size,
                view: args.view.clone(),
                eye: args.eye,
                look_at: args.look_at,
                up: args.up,
                fov: args.fov,
                scene_file: args.scene_file.clone(),
                shading,
                iso: args.iso,
                raw: args.raw.clone(),
                color_by: args.color_by.clone(),
                iso_pipeline: args.iso_pipeline.clone(),
                fuse: !args.compile.no_fuse,
                render_volume: !volume_reads.is_empty(),
                traces_surface: plan.stages().iter().any(|stage| {
                    (stage.ops.iter()).any(|op| op.functor.as_deref() == Some("intersect"))
                }),
                field: args.field.clone(),
                bvh: args.bvh.into(),
            },
            library,
            progress,
            distribution,
        )
        .map_err(Failure::Input)?;
        RunScene::Traced(Box::new(setup))
    } else {
        let volume = match &scenes[..] {
            [scene_setup::SceneSpec::File(path)]
                if volume_setup::is_volume_path(path) || args.raw.is_some() =>
            {
                path
            }
            given => {
                let given = match given {
                    [] => String::new(),
                    [one] => format!("; `{}` is not a volume file", one.name()),
                    _ => "; several scenes were given".to_string(),
                };
                return Err(Failure::Input(format!(
                    "error: {pipeline} reads {}: pass a volume to run it on (a .nii or .nii.gz file, or a raw brick with --raw XxYxZ:TYPE){given}",
                    volume_reads.join(", ")
                )));
            }
        };
        let given = [
            args.iso.is_some(),
            args.color_by.is_some(),
            args.iso_pipeline.is_some(),
        ];
        if let Some(option) = scene_setup::isosurface_option(given) {
            return Err(Failure::Input(format!(
                "error: {option} is for pipelines that trace a volume's isosurface; {pipeline} reads the volume itself ({}): set its params with --set NAME=VALUE",
                volume_reads.join(", ")
            )));
        }
        progress.phase(format!("loading {}", volume.display()));
        RunScene::Volume(
            volume_setup::volume_run(volume, args.raw.as_deref(), args.field.as_deref())
                .map_err(Failure::Input)?,
        )
    };
    let missing: Vec<String> = reads
        .iter()
        .filter(|(record, field)| scene.uniforms().get(record, field).is_none())
        .map(|(record, field)| format!("`{record}.{field}`"))
        .collect();
    if !missing.is_empty() {
        return Err(Failure::Input(format!(
            "error: {pipeline} reads {}, which {} does not provide",
            missing.join(", "),
            scene.description()
        )));
    }
    Ok(scene)
}

/// The transparent background and colour bar requested for the `image` output.
fn image_finish<'a>(
    args: &RunArgs,
    outputs: &'a [(String, OutputValue)],
    setup: &'a scene_setup::SceneSetup,
) -> Result<outputs::Finish<'a>, Failure> {
    let shading = &setup.resources.shading;
    let alpha = match args.background.as_deref() {
        Some("transparent") => match outputs.iter().find(|(n, _)| n == "alpha").map(|(_, v)| v) {
            Some(OutputValue::Array(column)) if column.elem_type() == dpp_runtime::ElemType::F32 => {
                Some(column.view().as_f32())
            }
            _ => {
                return Err(Failure::Input(
                    "error: --background transparent needs the pipeline to output `alpha` (coverage per pixel, f32)".into(),
                ))
            }
        },
        _ => None,
    };
    Ok(outputs::Finish {
        alpha,
        background: dpp_tracer::shading::linear_to_srgb(shading.background()),
        colorbar: args
            .colorbar
            .then(|| (shading.colormap().srgb(), shading.scalar_range())),
    })
}

fn shading_overrides(args: &RunArgs) -> Result<dpp_tracer::ShadingOverrides, String> {
    let background = match args.background.as_deref() {
        None | Some("transparent") => None,
        Some(spec) => {
            let parts: Vec<f32> = spec
                .split(',')
                .filter_map(|p| p.trim().parse().ok())
                .collect();
            match parts[..] {
                [r, g, b] => Some([r, g, b]),
                _ => {
                    return Err(format!(
                        "error: --background `{spec}` is not `transparent` or R,G,B"
                    ))
                }
            }
        }
    };
    let lights = args
        .lights
        .iter()
        .map(|spec| spec.parse::<dpp_tracer::PointLight>())
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| format!("error: {e}"))?;
    let scalar_range = args
        .scalar_range
        .as_deref()
        .map(dpp_tracer::shading::parse_scalar_range)
        .transpose()
        .map_err(|e| format!("error: {e}"))?;
    Ok(dpp_tracer::ShadingOverrides {
        lights: (!lights.is_empty()).then_some(lights),
        colormap: args.colormap.clone(),
        transfer: args.transfer.clone(),
        scalar_range,
        background,
    })
}

fn profile_report(
    profile: &[StageTiming],
    setup: std::time::Duration,
    run: std::time::Duration,
    scene: &str,
) -> String {
    let mut text = format!(
        "scene: {scene}\nscene set-up (load, BVH build, camera): {:.1} ms\n",
        setup.as_secs_f64() * 1e3
    );
    text.push_str("stage  runs  elements      time ms   share  ops\n");
    let total = run.as_secs_f64().max(1e-9);
    for timing in profile {
        let ms = timing.time.as_secs_f64() * 1e3;
        text.push_str(&format!(
            "{:>5}  {:>4}  {:>10}  {:>9.2}  {:>5.1}%  {}\n",
            timing.stage,
            timing.runs,
            timing.elements,
            ms,
            100.0 * timing.time.as_secs_f64() / total,
            timing.label
        ));
        text.push_str(&op_split(timing));
    }
    text.push_str(&format!("whole run: {:.2} ms\n", run.as_secs_f64() * 1e3));
    text
}

/// Where a fused stage's time went, op by op (CPU backend): the time its
/// chunks spent in each op, summed over threads, and that op's share of the
/// stage's op time (`listed_op_shares`: field views, and stages of one op
/// that store nothing, are left out).
fn op_split(timing: &StageTiming) -> String {
    let shares = listed_op_shares(&timing.ops);
    if shares.is_empty() {
        return String::new();
    }
    let mut text = format!(
        "{:>8}{:<28} {:>12}  {:>8}\n",
        "", "op", "thread ms", "of stage"
    );
    for (op, share) in shares {
        text.push_str(&format!(
            "{:>8}{:<28} {:>12.2}  {:>7.1}%\n",
            "",
            op.label,
            op.thread_time.as_secs_f64() * 1e3,
            100.0 * share
        ));
    }
    text
}

fn generate(args: GenArgs) -> Result<(), Failure> {
    let dataset = dpp_tracer::volume::generate::Dataset::from_name(&args.name)
        .map_err(|e| Failure::Input(format!("error: {e}")))?;
    let volume = dataset
        .generate(glam::UVec3::from(args.grid))
        .map_err(|e| Failure::Input(format!("error: {e}")))?;
    outputs::write_atomically(&args.output, |temporary| {
        volume.write_nifti(temporary).map_err(|e| match e {
            dpp_tracer::volume::VolumeError::Write { source, .. } => source.to_string(),
            other => other.to_string(),
        })
    })
    .map_err(Failure::Run)?;
    let (low, high) = volume.value_range().unwrap_or((0.0, 0.0));
    outln!(
        "wrote {} ({}x{}x{} samples, values {low} to {high}; try --iso {})",
        args.output.display(),
        args.grid[0],
        args.grid[1],
        args.grid[2],
        dataset.default_level()
    );
    Ok(())
}

fn iso(args: IsoArgs, library: &FunctorLibrary) -> Result<(), Failure> {
    let pool = thread_pool(args.threads)?;
    let volume =
        volume_setup::load_volume(&args.volume, args.raw.as_deref(), args.field.as_deref())
            .map_err(Failure::Input)?;
    let request = volume_setup::IsoRequest {
        level: args.level,
        pipeline: args.iso_pipeline.clone(),
        fuse: !args.no_fuse,
    };
    let start = Instant::now();
    let mesh = pool
        .install(|| volume_setup::isosurface(volume, &request, library))
        .map_err(Failure::Input)?;
    let elapsed = start.elapsed();
    let extension = args
        .output
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let write = match extension.as_str() {
        "ply" => dpp_tracer::mesh_write::write_ply,
        "obj" => dpp_tracer::mesh_write::write_obj,
        _ => {
            return Err(Failure::Input(format!(
                "error: cannot write `{}`: use a .ply or .obj file name",
                args.output.display()
            )))
        }
    };
    outputs::write_atomically(&args.output, |temporary| {
        write(&mesh, temporary).map_err(|e| e.to_string())
    })
    .map_err(Failure::Run)?;
    outln!(
        "wrote {} ({} triangles, {} vertices; isosurface in {:.1} ms)",
        args.output.display(),
        mesh.triangles.len(),
        mesh.positions.len(),
        elapsed.as_secs_f64() * 1e3
    );
    Ok(())
}

fn parse_grid(text: &str) -> Result<[u32; 3], String> {
    let parts: Vec<u32> = text
        .split([',', 'x'])
        .map(|p| p.trim().parse::<u32>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("`{text}` is not X,Y,Z"))?;
    match parts[..] {
        [x, y, z] => Ok([x, y, z]),
        _ => Err(format!("`{text}` is not three sizes X,Y,Z")),
    }
}

fn parse_assignment(text: &str) -> Result<(String, String), String> {
    match text.split_once('=') {
        Some((name, value)) if !name.trim().is_empty() => {
            Ok((name.trim().to_string(), value.trim().to_string()))
        }
        _ => Err(format!("`{text}` is not NAME=VALUE")),
    }
}

fn parse_size(text: &str) -> Result<(u32, u32), String> {
    let bad = || format!("`{text}` is not WIDTHxHEIGHT (like 1920x1080)");
    let (w, h) = text.split_once(['x', 'X']).ok_or_else(bad)?;
    let (w, h) = (
        w.trim().parse::<u32>().map_err(|_| bad())?,
        h.trim().parse::<u32>().map_err(|_| bad())?,
    );
    if w == 0 || h == 0 {
        return Err(format!("image size {w}x{h} is empty"));
    }
    // The camera's own limit, checked here so that the answer comes before
    // the scene is loaded.
    let most = dpp_tracer::camera::MAX_PIXELS;
    if u64::from(w) * u64::from(h) > most {
        return Err(format!(
            "image size {w}x{h} has {} pixels, more than the {most} (16384x16384) a camera may have",
            u64::from(w) * u64::from(h)
        ));
    }
    Ok((w, h))
}

fn parse_vec3(text: &str) -> Result<[f32; 3], String> {
    let parts: Vec<f32> = text
        .split(',')
        .map(|p| p.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("`{text}` is not X,Y,Z"))?;
    match parts.as_slice() {
        [x, y, z] if parts.iter().all(|v| v.is_finite()) => Ok([*x, *y, *z]),
        _ => Err(format!("`{text}` is not three finite numbers X,Y,Z")),
    }
}
