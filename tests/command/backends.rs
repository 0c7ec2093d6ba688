//! The GPU backend against the CPU backend through the `dpp` command: every
//! pipeline in `pipelines/` at a small size. Triangle ids (`prim`) must be
//! identical on at least 99.9% of pixels and images within a mean FLIP of
//! [`BACKEND_TOLERANCE`]; integer outputs of the examples identical.
//!
//! Without a GPU adapter these tests skip with a printed reason, unless
//! `DPP_REQUIRE_GPU` is set (CI sets it and installs Mesa's lavapipe).

use crate::common::{mean_flip, read_npy, scene_dir, Image, SCENE_VIEW};
use std::path::Path;
use std::process::Command;

/// Largest mean FLIP between the backends' images. The GPU's float maths
/// rounds differently (fused multiply-adds, `sqrt`, `pow`), which moves a few
/// hits at silhouettes and shifts shading by a unit of the last place.
const BACKEND_TOLERANCE: f32 = 0.01;

/// Least fraction of pixels whose `prim` must be identical.
const PRIM_AGREEMENT: f64 = 0.999;

/// Runs `dpp run PIPELINE ARGS --backend BACKEND` in `dir`; returns its stdout.
fn run(dir: &Path, pipeline: &Path, args: &[String], backend: &str) -> String {
    let mut all = vec!["run".to_string(), pipeline.display().to_string()];
    all.extend(args.iter().cloned());
    all.extend(["--backend".to_string(), backend.to_string()]);
    let all: Vec<&str> = all.iter().map(String::as_str).collect();
    let output = crate::common::dpp(&all, dir);
    assert!(
        output.status.success(),
        "dpp {all:?}: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8_lossy(&output.stdout).into_owned()
}

/// The outputs each pipeline is compared on, and its arguments.
struct Comparison {
    args: Vec<String>,
    image: bool,
    prim: bool,
    /// Array outputs that must be identical, bit for bit.
    exact: Vec<&'static str>,
}

fn comparison(name: &str) -> Option<Comparison> {
    let scene = |extra: &[&str]| -> Vec<String> {
        ["scene.obj", "--size", "96x64"]
            .iter()
            .chain(SCENE_VIEW)
            .chain(extra)
            .map(|s| s.to_string())
            .collect()
    };
    Some(match name {
        "workload1" => Comparison {
            args: scene(&["--out", "prim=prim.npy"]),
            image: true,
            prim: true,
            exact: vec![],
        },
        "workload2"
        | "workload2_expressions"
        | "workload3"
        | "workload3_expressions"
        | "examples.translucent" => Comparison {
            args: scene(&[]),
            image: true,
            prim: false,
            exact: vec![],
        },
        "examples.histogram" => Comparison {
            args: vec!["--out".into(), "counts=counts.npy".into()],
            image: false,
            prim: false,
            exact: vec!["counts"],
        },
        "examples.sample_counts" => Comparison {
            args: vec!["--out".into(), "counts=counts.npy".into()],
            image: false,
            prim: false,
            exact: vec!["counts"],
        },
        "examples.compaction" => Comparison {
            args: vec!["--out".into(), "kept=kept.npy".into()],
            image: false,
            prim: false,
            exact: vec!["kept"],
        },
        "examples.prefix_sum" => Comparison {
            args: [
                "--out",
                "inclusive=inclusive.npy",
                "--out",
                "exclusive=exclusive.npy",
                "--out",
                "segmented=segmented.npy",
            ]
            .iter()
            .map(|s| s.to_string())
            .collect(),
            image: false,
            prim: false,
            exact: vec!["inclusive", "exclusive", "segmented"],
        },
        "examples.sort" => Comparison {
            args: ["sorted", "order", "restored"]
                .iter()
                .flat_map(|name| ["--out".to_string(), format!("{name}={name}.npy")])
                .collect(),
            image: false,
            prim: false,
            exact: vec!["sorted", "order", "restored"],
        },
        // Needs a volume: compared in tracer/tests/pipelines/isosurface.rs.
        "isosurface" => return None,
        // A generated volume, shaded and jittered: every volume functor.
        "volume" => Comparison {
            args: [
                "sphere:24",
                "--size",
                "64x48",
                "--set",
                "shade=true",
                "--set",
                "jitter=true",
            ]
            .iter()
            .map(|s| s.to_string())
            .collect(),
            image: true,
            prim: false,
            exact: vec![],
        },
        // The same, with the volume's isosurface inside it.
        "volume_surface" => Comparison {
            args: [
                "sphere:24",
                "--iso",
                "0.3",
                "--size",
                "64x48",
                "--set",
                "shade=true",
            ]
            .iter()
            .map(|s| s.to_string())
            .collect(),
            image: true,
            prim: false,
            exact: vec![],
        },
        other => panic!("pipeline `{other}` has no backend comparison: add one here"),
    })
}

fn compare(name: &str, pipeline: &Path, comparison: &Comparison) {
    let cpu = scene_dir();
    let gpu = scene_dir();
    let mut args = comparison.args.clone();
    if comparison.image {
        args.extend(["-o".to_string(), "image.png".to_string()]);
    }
    let cpu_stdout = run(cpu.path(), pipeline, &args, "cpu");
    let gpu_stdout = run(gpu.path(), pipeline, &args, "gpu");
    // Host outputs (`total = …`, `count = …`) are printed: they must agree.
    let host_lines = |text: &str| -> Vec<String> {
        text.lines()
            .filter(|l| l.contains(" = "))
            .map(str::to_string)
            .collect()
    };
    assert_eq!(host_lines(&cpu_stdout), host_lines(&gpu_stdout), "{name}");
    if comparison.prim {
        let a: Vec<u32> = read_npy(&cpu.path().join("prim.npy"));
        let b: Vec<u32> = read_npy(&gpu.path().join("prim.npy"));
        assert_eq!(a.len(), b.len());
        let same = a.iter().zip(&b).filter(|(x, y)| x == y).count();
        let agreement = same as f64 / a.len() as f64;
        eprintln!(
            "{name}: prim identical on {:.4}% of pixels",
            100.0 * agreement
        );
        assert!(
            agreement >= PRIM_AGREEMENT,
            "{name}: prim agreement {agreement}"
        );
    }
    if comparison.image {
        let a = Image::load(&cpu.path().join("image.png"));
        let b = Image::load(&gpu.path().join("image.png"));
        let error = mean_flip(&a, &b);
        eprintln!("{name}: mean FLIP between the backends {error:.5}");
        assert!(error <= BACKEND_TOLERANCE, "{name}: mean FLIP {error}");
    }
    for output in &comparison.exact {
        let file = format!("{output}.npy");
        let a = std::fs::read(cpu.path().join(&file)).unwrap();
        let b = std::fs::read(gpu.path().join(&file)).unwrap();
        assert!(a == b, "{name}: `{output}` differs between the backends");
    }
}

#[test]
fn every_pipeline_agrees_on_both_backends() {
    if !crate::common::gpu_available("the backend comparison") {
        return;
    }
    for pipeline in crate::common::pipeline_files() {
        let name = crate::common::pipeline_name(&pipeline);
        if let Some(comparison) = comparison(&name) {
            compare(&name, &pipeline, &comparison);
        }
    }
}

#[test]
fn the_builtin_scene_agrees_on_both_backends() {
    if !crate::common::gpu_available("the backend comparison") {
        return;
    }
    let pipeline = crate::common::repo().join("pipelines/workload1.dpp");
    let comparison = Comparison {
        args: ["--size", "128x96", "--out", "prim=prim.npy"]
            .iter()
            .map(|s| s.to_string())
            .collect(),
        image: true,
        prim: true,
        exact: vec![],
    };
    compare("builtin workload1", &pipeline, &comparison);
    let pipeline = crate::common::repo().join("pipelines/workload3.dpp");
    let comparison = Comparison {
        args: ["--size", "128x96"].iter().map(|s| s.to_string()).collect(),
        image: true,
        prim: false,
        exact: vec![],
    };
    compare("builtin workload3", &pipeline, &comparison);
}

#[test]
fn a_missing_gpu_is_a_clear_error() {
    // No adapter of a backend this build lacks: the run must fail cleanly.
    let dir = tempfile::tempdir().unwrap();
    let pipeline = crate::common::repo().join("pipelines/examples/prefix_sum.dpp");
    let output = Command::new(env!("CARGO_BIN_EXE_dpp"))
        .args(["run", pipeline.to_str().unwrap(), "--backend", "gpu"])
        .env("WGPU_BACKEND", "metal")
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert_eq!(output.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("no GPU adapter found"), "{stderr}");
}
