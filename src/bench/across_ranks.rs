//! `dpp bench` under `mpirun`: every rank loads its part of each scene once
//! (its brick, pieces or region; with `--decompose image` all of it and its
//! tiles), then runs each fused workload from each view, warm-up and measured
//! rounds, once per compositing schedule asked for (`--composite`). Rank 0
//! prints, per measurement, a row per rank: its triangles, its mean frame
//! time (the rounds start together, after a barrier), the last round's
//! compositing time and rounds, the bytes it sent, its peak memory so far.

use super::{compile, scene_request, BenchArgs, Setup};
use crate::distributed::{self, Decompose, Distribution};
use crate::scene_setup::{load_share, SceneSetup};
use crate::Failure;
use dpp_dist::CompositeSchedule;
use dpp_runtime::cpu::column_pool::ColumnPool;
use dpp_runtime::cpu::exec::{run_plan_observed, RunContext};
use dpp_runtime::interpret::{Compositor, RunHooks};
use dpp_runtime::FunctorLibrary;
use std::sync::Arc;
use std::time::{Duration, Instant};

pub fn bench_across_ranks(
    args: &BenchArgs,
    setup: &Setup,
    library: &FunctorLibrary,
    distribution: &mut Distribution,
) -> Result<(), Failure> {
    let schedules = (args.composite.split(','))
        .map(|name| name.trim().parse::<CompositeSchedule>())
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| Failure::Input(format!("error: --composite: {}", e.0)));
    let schedules = crate::agree_failure(distribution, schedules)?;
    let pool = crate::agree_failure(distribution, crate::thread_pool(args.threads))?;
    let is_root = distribution.rank() == 0;
    let say = |text: String| {
        if is_root {
            outln!("{text}");
        }
    };
    say(format!(
        "# dpp bench across {} ranks ({} decomposition), {}x{}, {} warm-up and {} measured rounds",
        distribution.size(),
        match distribution.decompose {
            Decompose::Data => "data",
            Decompose::Image => "image",
        },
        args.size.0,
        args.size.1,
        args.warmup,
        args.rounds
    ));
    let plans = setup
        .workloads
        .iter()
        .map(|&workload| {
            let path = setup.pipelines.join(format!("workload{workload}.dpp"));
            compile(&path, library, true).map(|plan| (workload, plan))
        })
        .collect::<Result<Vec<_>, _>>();
    let plans = crate::agree_failure(distribution, plans)?;
    let progress = crate::progress::Progress::on_terminal(true);
    for spec in &setup.scenes {
        let (first_view, _) = &setup.views[0];
        let request = scene_request(spec, first_view, args.size, args.iso);
        let start = Instant::now();
        let (scene, origin, share) =
            load_share(&request, library, &progress, distribution).map_err(Failure::Input)?;
        let load = start.elapsed();
        let scene = Arc::new(scene);
        let triangles = scene.mesh.triangles.len();
        say(format!(
            "\n## {} (loaded in {:.0} ms on rank 0)",
            spec.name(),
            load.as_secs_f64() * 1e3
        ));
        for (view_name, _) in &setup.views {
            let request = scene_request(spec, view_name, args.size, args.iso);
            let view = SceneSetup::with_scene(scene.clone(), &origin, &request, &share);
            let view = distribution.agree(view).map_err(Failure::Input)?;
            let mine = (scene.mesh.bounds()).unwrap_or(scene.bounds);
            let order = match distribution.decompose {
                Decompose::Data => distributed::visibility_order(
                    &distribution.every_rank_bounds(mine),
                    view.camera.eye,
                ),
                Decompose::Image => (0..distribution.size()).collect(),
            };
            for (workload, plan) in &plans {
                for schedule in &schedules {
                    distribution.schedule = *schedule;
                    let compositor =
                        distribution.compositor(&library.records, view.camera.width, order.clone());
                    let hooks = RunHooks {
                        observer: None,
                        compositor: compositor.as_ref().map(|c| c as &dyn Compositor),
                    };
                    let context = RunContext {
                        library,
                        uniforms: &view.uniforms,
                        resources: &view.resources,
                        chunk: dpp_runtime::cpu::kernels::DEFAULT_CHUNK,
                        column_pool: &ColumnPool::new(),
                        elementwise: dpp_runtime::cpu::compiled::Elementwise::default(),
                    };
                    let mut measured = Duration::ZERO;
                    for round in 0..args.warmup + args.rounds {
                        distribution.ranks().barrier();
                        let start = Instant::now();
                        let result = pool.install(|| run_plan_observed(plan, &context, hooks));
                        let elapsed = start.elapsed();
                        crate::ended(distribution, result)?;
                        if round >= args.warmup {
                            measured += elapsed;
                        }
                    }
                    let mean = measured / args.rounds;
                    let stats = compositor.as_ref().and_then(|c| c.stats());
                    let table =
                        distributed::rank_report(distribution, triangles, mean, stats.as_ref());
                    say(format!(
                        "\n{view_name}, WORKLOAD{workload}, {schedule}:\n```\n{}\n```",
                        table.join("\n")
                    ));
                }
            }
        }
    }
    Ok(())
}
