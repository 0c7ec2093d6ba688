//! `dpp bench --workloads volume`: `pipelines/volume.dpp` fused and unfused
//! on each volume scene and view, against a hand-written ray marcher of the
//! same volume and transfer function (one loop per pixel, rayon over rows, no
//! primitives; the same sampling code, [`dpp_tracer::functors::volume_render`],
//! so the images must agree): what writing the algorithm as primitives costs.

use super::{measure, ms, progress_bar, BenchArgs, Setup};
use crate::scene_setup::{SceneRequest, SceneSetup, SceneSpec};
use crate::Failure;
use dpp_gpu::GpuContext;
use dpp_runtime::cpu::column_pool::ColumnPool;
use dpp_runtime::cpu::exec::{run_plan, RunContext};
use dpp_runtime::interpret::OutputValue;
use dpp_runtime::FunctorLibrary;
use dpp_tracer::camera::sample_offset;
use dpp_tracer::functors::volume_render::{entry, march, MarchParams, MarchRecord};
use glam::Vec3;
use rayon::prelude::*;
use std::time::Instant;

/// `pipelines/volume.dpp`'s defaults, which the hand-written loop uses too
/// (the image comparison shows it if they drift apart).
const STEP_IN_CELLS: f32 = 0.5;
const CUTOFF: f32 = 0.99;

/// The mean frame times of one scene and view, in ms.
struct Row {
    scene: String,
    view: String,
    fused: f64,
    unfused: f64,
    loop_ms: f64,
    /// The largest difference between the fused frame's image and the loop's (sRGB, 0–1).
    difference: f32,
}

pub(super) fn bench_volume(
    args: &BenchArgs,
    setup: &Setup,
    library: &FunctorLibrary,
    pool: &rayon::ThreadPool,
    gpu: Option<&GpuContext>,
    distribution: &crate::distributed::Distribution,
) -> Result<(), Failure> {
    let path = setup.pipelines.join("volume.dpp");
    let compile = |fuse: bool| {
        let options = dpp_runtime::CompileOptions {
            fuse,
            overrides: args.set.clone(),
        };
        crate::compile(&path, library, &options)
    };
    let (fused, unfused) = (compile(true)?, compile(false)?);
    let rounds = u64::from(args.warmup + args.rounds) * if gpu.is_some() { 3 } else { 2 };
    let progress = progress_bar(setup.scenes.len() as u64 * setup.views.len() as u64 * rounds);
    let mut rows = Vec::new();
    for spec in &setup.scenes {
        for (view_name, _) in &setup.views {
            let request = volume_request(spec, view_name, args);
            let view = SceneSetup::new(
                &request,
                library,
                &crate::progress::Progress::on_terminal(true),
                distribution,
            )
            .map_err(Failure::Input)?;
            let label = |what: &str| format!("{} {view_name} volume {what}", spec.name());
            progress.set_message(label("fused"));
            let (f, _) = measure(&fused, library, &view, pool, gpu, args, &progress, false)?;
            progress.set_message(label("unfused"));
            let (u, _) = measure(&unfused, library, &view, pool, gpu, args, &progress, false)?;
            progress.set_message(label("hand-written loop"));
            let mut image = Vec::new();
            let mut times = Vec::new();
            for round in 0..args.warmup + args.rounds {
                let start = Instant::now();
                image = pool.install(|| hand_written_frame(&view));
                if round >= args.warmup {
                    times.push(ms(start.elapsed()));
                }
                progress.inc(u64::from(gpu.is_none()) + 1);
            }
            let context = RunContext {
                library,
                uniforms: &view.uniforms,
                resources: &view.resources,
                chunk: dpp_runtime::cpu::kernels::DEFAULT_CHUNK,
                column_pool: &ColumnPool::new(),
                elementwise: dpp_runtime::cpu::compiled::Elementwise::default(),
            };
            let result = pool
                .install(|| run_plan(&fused, &context))
                .map_err(|e| Failure::Run(format!("{}: {e}", fused.pipeline)))?;
            let Some((_, OutputValue::Array(pipeline_image))) =
                result.outputs.iter().find(|(name, _)| name == "image")
            else {
                return Err(Failure::Run("volume.dpp has no `image` output".into()));
            };
            let difference = (pipeline_image.view().as_vec3().iter().zip(&image))
                .map(|(a, b)| (*a - *b).abs().max_element())
                .fold(0.0, f32::max);
            let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
            rows.push(Row {
                scene: spec.name(),
                view: view_name.clone(),
                fused: mean(&f.frames_ms),
                unfused: mean(&u.frames_ms),
                loop_ms: mean(&times),
                difference,
            });
        }
    }
    progress.finish_and_clear();
    let backend = if gpu.is_some() { "GPU" } else { "CPU" };
    let set: Vec<String> = args
        .set
        .iter()
        .map(|(n, v)| format!(" --set {n}={v}"))
        .collect();
    let mut text = format!(
        "volume.dpp{} at {}x{} ({backend} backend; the loop on the CPU), mean of {} frames\n\n",
        set.concat(),
        args.size.0,
        args.size.1,
        args.rounds
    );
    text.push_str("| scene | view | fused ms (fps) | unfused ms (fps) | hand-written loop ms (fps) | fused / loop | largest image difference |\n");
    text.push_str("| --- | --- | --- | --- | --- | --- | --- |\n");
    for row in &rows {
        let fps = |t: f64| format!("{t:.1} ({:.2})", 1e3 / t);
        text.push_str(&format!(
            "| {} | {} | {} | {} | {} | {:.2} | {:.1e} |\n",
            row.scene,
            row.view,
            fps(row.fused),
            fps(row.unfused),
            fps(row.loop_ms),
            row.fused / row.loop_ms,
            row.difference
        ));
    }
    outln!("{text}");
    if let Some(path) = &args.markdown {
        crate::outputs::write_atomically(path, |temporary| {
            std::fs::write(temporary, &text).map_err(|e| e.to_string())
        })
        .map_err(Failure::Run)?;
    }
    Ok(())
}

fn volume_request(spec: &SceneSpec, view: &str, args: &BenchArgs) -> SceneRequest {
    let mut request = super::scene_request(spec, view, args.size, None);
    request.render_volume = true;
    request.shading.transfer = args.transfer.clone();
    request.shading.scalar_range = args.scalar_range;
    request
}

/// The image `volume.dpp` makes at its defaults, as one loop per pixel:
/// sRGB colours, row-major.
fn hand_written_frame(view: &SceneSetup) -> Vec<Vec3> {
    let resources = &view.resources;
    let volume = resources
        .volume
        .as_ref()
        .expect("a volume-rendering set-up");
    let shading = &resources.shading;
    let [low, high] = shading.scalar_range();
    let unit = volume.spacing.abs().min_element();
    let params = MarchParams {
        step: STEP_IN_CELLS * unit,
        unit,
        samples: u32::MAX,
        cutoff: CUTOFF,
        shade: false,
        low,
        inverse_range: 1.0 / (high - low),
    };
    let camera = &view.camera;
    let (sx, sy) = sample_offset(1, 0);
    let background = shading.background();
    let width = camera.width as usize;
    let mut image = vec![Vec3::ZERO; width * camera.height as usize];
    image
        .par_chunks_mut(width)
        .enumerate()
        .for_each(|(y, row)| {
            for (x, pixel) in row.iter_mut().enumerate() {
                let dir = camera.direction(x as u32, y as u32, sx, sy);
                let (o, d, t, t_end) = entry(volume, camera.eye, dir, f32::INFINITY);
                let mut m = MarchRecord::missed(o, d, 0);
                if t <= t_end {
                    m.t = t;
                    m.t_end = t_end;
                    m = march(volume, shading.colormap(), &params, m);
                }
                let rgb = m.color + background * (1.0 - m.alpha);
                *pixel = dpp_tracer::shading::linear_to_srgb(rgb.clamp(Vec3::ZERO, Vec3::ONE));
            }
        });
    image
}
