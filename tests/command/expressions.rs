//! Shading written as expressions in the pipeline against the `shader`
//! functor: `pipelines/workload2_expressions.dpp` and
//! `workload3_expressions.dpp` must give `workload2.dpp`'s and
//! `workload3.dpp`'s images within a few units of the last place, their
//! coverage (and WORKLOAD2's depth) bit for bit, on the built-in scene and
//! the small boxes scene, on the CPU and (where an adapter starts) the GPU.

use crate::common::{gpu_available, repo, run_pipeline_outputs, scene_dir, SCENE_VIEW};
use std::path::Path;

/// Largest difference of an sRGB-encoded pixel component. The pipeline sums
/// its lights' terms before adding the ambient one where `shader` adds them
/// one by one, normalises by a division where `shader` multiplies by a
/// reciprocal, and WGSL may fuse multiply-adds differently in its separate
/// maps: each moves a component by an ULP or two of values up to 1. Measured
/// (320×240 built-in scene, CPU): at most 9.5e-7, on 8% of components.
const IMAGE_TOLERANCE: f32 = 2e-6;

/// Runs `pipeline` with `args` on `backend`; returns the float arrays of `outputs`.
fn run(
    dir: &Path,
    pipeline: &str,
    args: &[&str],
    backend: &str,
    outputs: &[&str],
) -> Vec<Vec<f32>> {
    let mut all = args.to_vec();
    all.extend(["--backend", backend]);
    run_pipeline_outputs(dir, pipeline, &all, outputs)
}

fn check_equal_to_the_functor(backend: &str) {
    let dir = scene_dir();
    let mut boxes = vec!["scene.obj", "--size", "96x64"];
    boxes.extend_from_slice(SCENE_VIEW);
    let builtin = vec!["--size", "80x60"];
    let workloads: [(&str, &[&str], &[&str]); 2] = [
        ("workload2", &[], &["image", "alpha", "depth"]),
        ("workload3", &["--set", "spp=1"], &["image", "alpha"]),
    ];
    for (workload, extra, outputs) in workloads {
        for (scene, args) in [("built-in", &builtin), ("boxes", &boxes)] {
            let mut args = args.clone();
            args.extend_from_slice(extra);
            let run_one = |file: String| run(dir.path(), &file, &args, backend, outputs);
            let functor = run_one(format!("{workload}.dpp"));
            let written = run_one(format!("{workload}_expressions.dpp"));
            let what = format!("{workload} on the {scene} scene on {backend}");
            // Everything but the image (the first) is bit for bit.
            for (name, (a, b)) in outputs.iter().zip(functor.iter().zip(&written)).skip(1) {
                assert_eq!(a, b, "{what}: {name}");
            }
            let worst = functor[0]
                .iter()
                .zip(&written[0])
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f32, f32::max);
            assert!(
                worst <= IMAGE_TOLERANCE,
                "{what}: a pixel differs by {worst}"
            );
            assert!(functor[1].contains(&1.0), "{what}: nothing was hit");
        }
    }
}

#[test]
fn written_out_shading_equals_the_shader_functor_on_the_cpu() {
    check_equal_to_the_functor("cpu");
}

#[test]
fn written_out_shading_equals_the_shader_functor_on_the_gpu() {
    if gpu_available("the written-out shading on the GPU") {
        check_equal_to_the_functor("gpu");
    }
}

/// With `denseHits` 0 the written-out WORKLOAD2 shades every ray, misses
/// too, and keeps the background where they are (the path a view the
/// surface nearly fills takes); with 1 it compacts whenever a ray misses:
/// the same bits either way.
#[test]
fn the_written_out_workload2_without_compaction_gives_the_same_bits() {
    let dir = scene_dir();
    let outputs = ["image", "alpha", "depth"];
    let mut boxes = vec!["scene.obj", "--size", "96x64"];
    boxes.extend_from_slice(SCENE_VIEW);
    for args in [vec!["--size", "80x60"], boxes] {
        let with = |dense_hits: &'static str| {
            let mut args = args.clone();
            args.extend(["--set", dense_hits]);
            run(
                dir.path(),
                "workload2_expressions.dpp",
                &args,
                "cpu",
                &outputs,
            )
        };
        let compacted = with("denseHits=1");
        let dense = with("denseHits=0");
        for (name, (a, b)) in outputs.iter().zip(compacted.iter().zip(&dense)) {
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(a), bits(b), "{args:?}: {name}");
        }
        assert!(compacted[1].contains(&0.0), "{args:?}: nothing was missed");
    }
}

/// The CPU's compiled element-wise loops (the default) against running the
/// same ops one at a time over columns (`--cpu-elementwise columns`), on the
/// written-out pipelines, whose shading is almost all compiled: the same
/// images, coverage and depth, bit for bit (their floats are never NaN).
#[test]
fn compiled_and_column_at_a_time_shading_give_the_same_bits() {
    let dir = scene_dir();
    let workloads: [(&str, &[&str], &[&str]); 2] = [
        (
            "workload2_expressions.dpp",
            &[],
            &["image", "alpha", "depth"],
        ),
        (
            "workload3_expressions.dpp",
            &["--set", "spp=1"],
            &["image", "alpha"],
        ),
    ];
    for (pipeline, extra, outputs) in workloads {
        let mut args = vec!["--size", "80x60"];
        args.extend_from_slice(extra);
        let compiled = run(dir.path(), pipeline, &args, "cpu", outputs);
        args.extend(["--cpu-elementwise", "columns"]);
        let columns = run(dir.path(), pipeline, &args, "cpu", outputs);
        for (name, (a, b)) in outputs.iter().zip(compiled.iter().zip(&columns)) {
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(a), bits(b), "{pipeline}: {name}");
        }
        assert!(compiled[1].contains(&1.0), "{pipeline}: nothing was hit");
    }
}

/// docs/shading.md's two worked edits, made to copies of the pipelines: each
/// still runs, and only darkens the image (the specular term, and the
/// lights' share that occlusion now also takes, only add light).
#[test]
fn the_documented_shading_edits_run_and_only_darken() {
    let dir = tempfile::tempdir().unwrap();
    for file in [
        "prelude.dpp",
        "composite.dpp",
        "workload2_expressions.dpp",
        "workload3_expressions.dpp",
    ] {
        std::fs::copy(repo().join("pipelines").join(file), dir.path().join(file)).unwrap();
    }
    let edits = [
        (
            "workload2_expressions.dpp",
            "term     = select(inFront, falling * l.color * (sbase * diffuse + sm.specular * specular), vec3(0.0))",
            "term     = select(inFront, falling * l.color * sbase * diffuse, vec3(0.0))",
        ),
        (
            "workload3_expressions.dpp",
            "local = ambient * open * base + lit",
            "local = (ambient * base + lit) * open",
        ),
    ];
    let args = ["--size", "80x60", "--set", "spp=1"];
    for (file, before, after) in edits {
        let text = std::fs::read_to_string(dir.path().join(file)).unwrap();
        assert!(
            text.contains(before),
            "docs/shading.md's edit no longer matches {file}"
        );
        std::fs::write(dir.path().join("edited.dpp"), text.replace(before, after)).unwrap();
        let args: &[&str] = if file.starts_with("workload2") {
            &args[..2]
        } else {
            &args
        };
        let shipped = run(
            dir.path(),
            dir.path().join(file).to_str().unwrap(),
            args,
            "cpu",
            &["image"],
        );
        let edited = run(
            dir.path(),
            dir.path().join("edited.dpp").to_str().unwrap(),
            args,
            "cpu",
            &["image"],
        );
        let (shipped, edited) = (&shipped[0], &edited[0]);
        assert!(
            shipped.iter().zip(edited).all(|(s, e)| *e <= s + 1e-6),
            "{file}: the edit brightened a pixel"
        );
        let darker = shipped
            .iter()
            .zip(edited)
            .filter(|(s, e)| **e < **s - 1e-3)
            .count();
        assert!(
            darker > shipped.len() / 100,
            "{file}: the edit changed only {darker} components"
        );
    }
}
