//! `dpp bench` as a user runs it: the markdown tables, the JSON file and the
//! chart of a tiny run on the built-in scene, and its answers to bad input.

use crate::common::{dpp, text};

use std::process::Command;

fn pipelines() -> String {
    crate::common::repo()
        .join("pipelines")
        .display()
        .to_string()
}

/// Every number under `value` (recursively) with its path.
fn numbers(value: &serde_json::Value, path: &str, out: &mut Vec<(String, f64)>) {
    match value {
        serde_json::Value::Number(n) => out.push((path.to_string(), n.as_f64().unwrap())),
        serde_json::Value::Array(items) => {
            for (i, item) in items.iter().enumerate() {
                numbers(item, &format!("{path}[{i}]"), out);
            }
        }
        serde_json::Value::Object(fields) => {
            for (name, item) in fields {
                numbers(item, &format!("{path}.{name}"), out);
            }
        }
        _ => {}
    }
}

/// `dpp bench` of one measured round on the 16-cell built-in scene at 48×32,
/// on 2 threads, in `dir`, with `more` arguments.
fn tiny_bench(more: &[&str], dir: &std::path::Path) -> std::process::Output {
    let pipelines = pipelines();
    let mut args = vec![
        "bench",
        "builtin:16",
        "--size",
        "48x32",
        "--warmup",
        "0",
        "--rounds",
        "1",
        "--threads",
        "2",
        "--pipelines",
        &pipelines,
    ];
    args.extend_from_slice(more);
    dpp(&args, dir)
}

/// The JSON report a bench wrote to `bench.json` in `dir`.
fn bench_json(dir: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("bench.json")).unwrap()).unwrap()
}

/// Two plans measured in turn (a JSON `side_by_side` entry): `rounds`
/// measured rounds of each, every ratio the other's time over the own one's;
/// returns the ratios.
fn check_rounds_in_turn(pair: &serde_json::Value, rounds: usize) -> Vec<f64> {
    let numbers = |name: &str| -> Vec<f64> {
        (pair[name].as_array().unwrap().iter())
            .map(|v| v.as_f64().unwrap())
            .collect()
    };
    let (own, versus, ratios) = (numbers("own_ms"), numbers("versus_ms"), numbers("ratios"));
    assert_eq!(
        (own.len(), versus.len(), ratios.len()),
        (rounds, rounds, rounds),
        "{pair}"
    );
    for ((own, versus), ratio) in own.iter().zip(&versus).zip(&ratios) {
        assert!(*own > 0.0 && *versus > 0.0, "{pair}");
        assert!((ratio - versus / own).abs() < 1e-9, "{pair}");
    }
    ratios
}

#[test]
fn a_tiny_bench_writes_tables_json_and_a_chart() {
    let dir = tempfile::tempdir().unwrap();
    let output = tiny_bench(
        &[
            "--views",
            "front,zoom",
            "--markdown",
            "bench.md",
            "--json",
            "bench.json",
            "--chart",
            "bench.png",
        ],
        dir.path(),
    );
    let stdout = text(&output.stdout);
    assert!(
        output.status.success(),
        "{}\n{stdout}",
        text(&output.stderr)
    );
    // Progress goes to a terminal only: nothing on stderr here.
    assert_eq!(text(&output.stderr), "");

    let markdown = std::fs::read_to_string(dir.path().join("bench.md")).unwrap();
    assert_eq!(markdown, stdout, "the markdown file is what stdout shows");
    for heading in [
        "## Scenes",
        "## WORKLOAD1 (primary rays), Mrays/s",
        "## WORKLOAD2 and WORKLOAD3, frames per second",
        "## Time per stage",
        "## BVH builds and their trace rates",
        "## Time to first image: WORKLOAD2",
    ] {
        assert!(markdown.contains(heading), "{heading} missing:\n{markdown}");
    }
    assert!(
        !markdown.contains("Embree"),
        "no engine comparison without --engine embree"
    );
    // A table row per view of WORKLOAD1, and one per view of WORKLOAD2 and 3.
    assert_eq!(markdown.matches("| builtin:16 | front | 1536 |").count(), 1);
    assert_eq!(
        markdown.matches("| builtin:16 | zoom | WORKLOAD").count(),
        2
    );
    for row in markdown.lines().filter(|l| l.starts_with("| builtin:16")) {
        let cells = row.split('|').count();
        assert!(cells >= 7, "{row}");
    }
    // The unfused WORKLOAD1 plan has `map<intersect>` as a stage of its own.
    assert!(markdown.contains("| 3 | `map<intersect>` |"), "{markdown}");
    // Fused stages are split op by op: WORKLOAD2's one tracing stage shows
    // what its intersection and its shading each cost.
    assert!(markdown.contains("Inside stage 1: "), "{markdown}");
    for op in ["| `hits = map<intersect>` |", "| `rgb = map<shader>` |"] {
        assert!(markdown.contains(op), "{op} missing:\n{markdown}");
    }

    let json = bench_json(dir.path());
    assert_eq!(json["backend"], "cpu");
    assert!(json.get("adapter").is_none());
    assert_eq!(json["threads"], 2);
    assert_eq!(json["size"], serde_json::json!([48, 32]));
    let scene = &json["scenes"][0];
    assert_eq!(scene["name"], "builtin:16");
    assert_eq!(scene["views"].as_array().unwrap().len(), 2);
    let view = &scene["views"][0];
    assert_eq!(view["view"], "front");
    assert_eq!(view["primary_rays"], 1536);
    let workloads = view["workloads"].as_array().unwrap();
    assert_eq!(
        workloads
            .iter()
            .map(|w| w["workload"].as_u64().unwrap())
            .collect::<Vec<_>>(),
        [1, 2, 3]
    );
    let w1 = &workloads[0];
    // WORKLOAD2 and 3 relate their fused frame to WORKLOAD1's intersection
    // time (the bar), in the JSON and in the table's last column.
    let intersect_ms = w1["unfused"]["intersect_ms"].as_f64().unwrap();
    assert!(w1["fused_over_workload1_intersect"].is_null());
    for w in &workloads[1..] {
        let over = w["fused_over_workload1_intersect"].as_f64().unwrap();
        let fused_ms = w["fused"]["mean_frame_ms"].as_f64().unwrap();
        assert!((over - fused_ms / intersect_ms).abs() < 1e-9 * over, "{w}");
        let cell = format!("| {:.2}× |", over);
        let row = format!("| builtin:16 | front | WORKLOAD{} |", w["workload"]);
        let line = markdown.lines().find(|l| l.starts_with(&row)).unwrap();
        assert!(line.ends_with(&cell), "{line} should end with {cell}");
        // What the frame costs outside the traversal, per pixel: part of
        // the frame, and the cell before the last.
        let beyond = w["beyond_traversal_ns_per_pixel"].as_f64().unwrap();
        let frame_ns_per_pixel = fused_ms * 1e6 / 1536.0;
        assert!(beyond > 0.0 && beyond < frame_ns_per_pixel, "{w}");
        let cells: Vec<&str> = line.split(" | ").collect();
        assert_eq!(cells[cells.len() - 2], format!("{beyond:.1}"), "{line}");
    }
    assert!(w1["unfused"]["intersect_mrays_per_s"].as_f64().unwrap() > 0.0);
    assert!(w1["fused"]["frame_mrays_per_s"].as_f64().unwrap() > 0.0);
    // Time to first image: WORKLOAD2's parts add up to the table's total.
    let part = |value: &serde_json::Value| value.as_f64().unwrap();
    let total = part(&json["workload2_compile_ms"])
        + part(&scene["load_ms"])
        + part(&scene["normals_ms"])
        + part(&scene["bvh_build_ms"])
        + part(&workloads[1]["fused"]["first_frame_ms"]);
    let row = (markdown.lines())
        .find(|l| l.starts_with("| builtin:16 | front | dpp |"))
        .unwrap();
    assert!(row.ends_with(&format!("| {total:.1} | 1.00 |")), "{row}");
    assert_eq!(w1["fused"]["frames_ms"].as_array().unwrap().len(), 1);
    assert!(w1["unfused"]["stages"].as_array().unwrap().len() > 3);
    // The JSON has the same op split: one entry per op of the stage.
    let w2_stage = &workloads[1]["fused"]["stages"][0];
    let ops = w2_stage["op_thread_ms"].as_array().unwrap();
    assert_eq!(
        ops.len(),
        w2_stage["ops"].as_str().unwrap().split(" → ").count(),
        "{w2_stage}"
    );
    let intersect = ops
        .iter()
        .find(|op| op["op"] == "hits = map<intersect>")
        .unwrap();
    assert!(intersect["thread_ms"].as_f64().unwrap() > 0.0, "{w2_stage}");
    let mut all = Vec::new();
    numbers(&json, "", &mut all);
    assert!(all.len() > 50);
    for (path, value) in &all {
        // Counts of rounds, and the time of an empty step, may be zero.
        let may_be_zero = path.ends_with("warmup_rounds")
            || path.ends_with("normals_ms")
            || path.ends_with("].ms")
            || path.ends_with("].thread_ms");
        assert!(value.is_finite() && *value >= 0.0, "{path} = {value}");
        assert!(
            may_be_zero || *value > 0.0,
            "{path} = {value} is not positive"
        );
    }
    let timings = all
        .iter()
        .filter(|(path, _)| path.ends_with("].ms"))
        .map(|(_, v)| v);
    assert!(timings.sum::<f64>() > 0.0);

    let chart = image::open(dir.path().join("bench.png")).unwrap();
    assert!(chart.width() >= 640 && chart.height() == 480);
    // Labels and bars make it more than a blank page.
    let rgb = chart.to_rgb8();
    let dark = rgb.pixels().filter(|p| p.0.iter().all(|&c| c < 60)).count();
    let blue = rgb.pixels().filter(|p| p.0 == [0x1f, 0x77, 0xb4]).count();
    assert!(dark > 200, "{dark} dark pixels: no text?");
    assert!(blue > 100, "{blue} bar pixels");
}

#[test]
fn the_bvh_builder_is_chosen_and_reported() {
    let dir = tempfile::tempdir().unwrap();
    for (choice, label) in [
        (None, "| dpp (binned SAH) |"),
        (Some("sah"), "| dpp (binned SAH) |"),
        (Some("ploc"), "| dpp (obvhs PLOC) |"),
        (Some("lbvh"), "| dpp (linear BVH) |"),
    ] {
        let mut more = vec!["--workloads", "1", "--json", "bench.json"];
        more.extend(choice.iter().flat_map(|choice| ["--bvh", choice]));
        let output = tiny_bench(&more, dir.path());
        assert!(output.status.success(), "{}", text(&output.stderr));
        let markdown = text(&output.stdout);
        assert!(markdown.contains(label), "{choice:?}: {markdown}");
        let json = bench_json(dir.path());
        assert_eq!(json["bvh"], choice.unwrap_or("sah"));
        assert!(json["scenes"][0]["bvh_build_ms"].as_f64().unwrap() > 0.0);
    }
}

/// `--versus`: the written-out WORKLOAD2 and workload2.dpp, a frame of each
/// per round, in a table and in the JSON report.
#[test]
fn a_bench_versus_a_file_measures_both_frame_by_frame() {
    let dir = tempfile::tempdir().unwrap();
    let versus = crate::common::repo().join("pipelines/workload2_expressions.dpp");
    let pipelines = pipelines();
    #[rustfmt::skip]
    let args = [
        "bench", "builtin:16", "--size", "48x32", "--threads", "2",
        "--pipelines", &pipelines, "--views", "front,back", "--workloads", "2",
        "--warmup", "1", "--rounds", "3", "--versus", versus.to_str().unwrap(),
        "--json", "bench.json",
    ];
    let output = dpp(&args, dir.path());
    assert!(output.status.success(), "{}", text(&output.stderr));
    let stdout = text(&output.stdout);
    assert!(
        stdout.contains(
            "## `workload2_expressions.dpp` against `workload2.dpp` (WORKLOAD2), fused frame ms, side by side"
        ),
        "{stdout}"
    );
    let rows = stdout
        .lines()
        .filter(|line| {
            line.starts_with("| builtin:16 | front |") || line.starts_with("| builtin:16 | back |")
        })
        .filter(|line| line.split('|').count() == 14)
        .count();
    assert_eq!(rows, 2, "{stdout}");
    let report = bench_json(dir.path());
    for view in report["scenes"][0]["views"].as_array().unwrap() {
        let pair = &view["side_by_side"];
        assert_eq!(pair["workload"], 2);
        assert_eq!(pair["versus"], "workload2_expressions.dpp");
        // The measured rounds only: the warm-up round is not among them.
        let ratios = check_rounds_in_turn(pair, 3);
        let mut sorted = ratios.clone();
        sorted.sort_by(f64::total_cmp);
        assert_eq!(pair["median_ratio"].as_f64().unwrap(), sorted[1]);
    }
}

#[test]
fn bad_bench_input_is_exit_status_2() {
    let dir = tempfile::tempdir().unwrap();
    let pipelines = pipelines();
    let base = ["bench", "--pipelines", &pipelines];
    let cases: &[(&[&str], &str)] = &[
        (&["missing.ply"], "scene `missing.ply` is not a file"),
        (&["--views", "side"], "unknown view `side`"),
        (&["--engine", "optix"], "unknown engine `optix`"),
        (&["--workloads", "4"], "unknown workload `4`"),
        (&["--rounds", "0"], "--rounds must be at least 1"),
        (&["builtin:3"], "resolution must be in 8..=512"),
        (&["rm:1,2"], "rm:X,Y,Z"),
        (&["--size", "0x10"], "is empty"),
        (&["--backend", "tpu"], "invalid value 'tpu'"),
        (&["--embree-test", "fast"], "add embree to --engine"),
        (&["--embree-test", "exact"], "invalid value 'exact'"),
        (&["--bvh", "karras"], "invalid value 'karras'"),
        (
            &["--versus", "nowhere.dpp", "--workloads", "2"],
            "--versus: cannot find nowhere.dpp",
        ),
        (&["--versus", "nowhere.dpp"], "name it alone in --workloads"),
    ];
    for (args, expected) in cases {
        let mut all: Vec<&str> = base.to_vec();
        all.extend_from_slice(args);
        let output = dpp(&all, dir.path());
        let stderr = text(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
    }
    // A file that is not a mesh.
    std::fs::write(dir.path().join("notes.txt"), "hello").unwrap();
    let mut all: Vec<&str> = base.to_vec();
    all.push("notes.txt");
    let output = dpp(&all, dir.path());
    assert_eq!(output.status.code(), Some(2));
    assert!(text(&output.stderr).contains("dpp reads .obj and .ply meshes"));
    // Embree without the feature, or without WORKLOAD1 or WORKLOAD3.
    let mut all: Vec<&str> = base.to_vec();
    all.extend_from_slice(&["--engine", "dpp,embree", "--workloads", "2"]);
    let output = dpp(&all, dir.path());
    assert_eq!(output.status.code(), Some(2));
    let expected = if cfg!(feature = "embree") {
        "add 1 or 3 to --workloads"
    } else {
        "built without Embree"
    };
    assert!(
        text(&output.stderr).contains(expected),
        "{}",
        text(&output.stderr)
    );
}

#[test]
fn a_ply_mesh_runs_through_workload1() {
    let dir = tempfile::tempdir().unwrap();
    // A unit square facing the camera, as binary little-endian PLY with a scalar.
    let mut bytes = b"ply\nformat binary_little_endian 1.0\nelement vertex 4\n\
property float x\nproperty float y\nproperty float z\nproperty float intensity\n\
element face 1\nproperty list uchar int vertex_indices\nend_header\n"
        .to_vec();
    for [x, y] in [[0.0f32, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]] {
        for value in [x, y, 0.0, x + y] {
            bytes.extend(value.to_le_bytes());
        }
    }
    bytes.push(4);
    for index in [0i32, 1, 2, 3] {
        bytes.extend(index.to_le_bytes());
    }
    std::fs::write(dir.path().join("square.ply"), &bytes).unwrap();
    let workload1 = crate::common::repo().join("pipelines/workload1.dpp");
    let output = dpp(
        &[
            "run",
            workload1.to_str().unwrap(),
            "square.ply",
            "--size",
            "16x16",
            "-o",
            "square.png",
        ],
        dir.path(),
    );
    assert!(output.status.success(), "{}", text(&output.stderr));
    assert!(dir.path().join("square.png").is_file());
    // A truncated copy is bad input.
    std::fs::write(dir.path().join("cut.ply"), &bytes[..bytes.len() - 5]).unwrap();
    let output = dpp(
        &[
            "run",
            workload1.to_str().unwrap(),
            "cut.ply",
            "--size",
            "8x8",
        ],
        dir.path(),
    );
    assert_eq!(output.status.code(), Some(2));
    assert!(text(&output.stderr).contains("cut.ply: malformed PLY"));
}

/// With Embree, WORKLOAD1's intersection and WORKLOAD3's fused frame run
/// again with Embree behind `intersect` and `occluded`, in both of its modes:
/// the hits agree, and every stage that traces still has its thread time.
#[cfg(feature = "embree")]
#[test]
fn an_embree_bench_compares_every_workload() {
    let dir = tempfile::tempdir().unwrap();
    let more = [
        "--views",
        "front",
        "--workloads",
        "1,2,3",
        "--engine",
        "dpp,embree",
        "--json",
        "bench.json",
    ];
    // Embree's fast test is named in both reports.
    let output = tiny_bench(
        &[&more[..], &["--embree-test", "fast"]].concat(),
        dir.path(),
    );
    assert!(output.status.success(), "{}", text(&output.stderr));
    assert!(text(&output.stdout).contains("`--embree-test fast`"));
    assert_eq!(bench_json(dir.path())["embree_test"], "fast");
    let output = tiny_bench(&more, dir.path());
    let markdown = text(&output.stdout);
    assert!(output.status.success(), "{}", text(&output.stderr));
    for heading in [
        "## WORKLOAD1: dpp against Embree",
        "## WORKLOAD2: dpp against Embree, fused frame ms",
        "## WORKLOAD3: dpp against Embree, fused frame ms",
    ] {
        assert!(markdown.contains(heading), "{heading} missing:\n{markdown}");
    }
    assert!(
        markdown.contains("robust, watertight triangle test"),
        "{markdown}"
    );
    let json = bench_json(dir.path());
    assert_eq!(json["embree_test"], "robust");
    let view = &json["scenes"][0]["views"][0];
    let engines = view["engines"].as_array().unwrap();
    assert_eq!(engines.len(), 4);
    // Embree's BVH at both qualities: each build timed, each traced.
    let scene = &json["scenes"][0];
    for build in ["embree_build_ms", "embree_high_build_ms"] {
        assert!(scene[build].as_f64().unwrap() > 0.0, "{build}");
    }
    for heading in ["| dpp (binned SAH) |", "| Embree high, 16-ray packets |"] {
        assert!(markdown.contains(heading), "{heading} missing:\n{markdown}");
    }
    // Time to first image: a row for dpp and for each of Embree's BVHs.
    for bvh in [
        "| front | dpp |",
        "| front | Embree default |",
        "| front | Embree high |",
    ] {
        assert_eq!(markdown.matches(bvh).count(), 1, "{bvh}:\n{markdown}");
    }
    assert!(engines.iter().all(|e| e["agree"] == true), "{engines:?}");
    let traced = view["engine_frames"].as_array().unwrap();
    let runs: Vec<(u64, &str)> = traced
        .iter()
        .map(|e| {
            let workload = e["workload"].as_u64().unwrap();
            (workload, e["engine"].as_str().unwrap())
        })
        .collect();
    assert_eq!(
        runs,
        [
            (2, "embree-single"),
            (3, "embree-single"),
            (2, "embree-packet"),
            (3, "embree-packet"),
            (2, "embree-single-high"),
            (2, "embree-packet-high"),
        ]
    );
    for engine in traced {
        assert!(engine["engine_over_dpp"].as_f64().unwrap() > 0.0);
        assert!(engine["intersect_thread_ms"].as_f64().unwrap() > 0.0);
        assert!(engine["fused_over_workload1_intersect"].as_f64().unwrap() > 0.0);
        // Outside the traversal, Embree's frame is still dpp's plan.
        assert!(engine["beyond_traversal_ns_per_pixel"].as_f64().unwrap() > 0.0);
        // Only WORKLOAD3 traces any-hit rays.
        let occluded = engine["occluded_thread_ms"].as_f64().unwrap();
        assert_eq!(occluded > 0.0, engine["workload"] == 3, "{engine}");
    }
    // The bars' comparison: WORKLOAD1's intersection and WORKLOAD3's frame,
    // dpp and Embree's packets in turn, each round a ratio.
    assert!(
        markdown.contains("## dpp and Embree's packets in turn, ms"),
        "{markdown}"
    );
    let in_turn = view["engines_in_turn"].as_array().unwrap();
    let measured: Vec<(u64, &str, &str)> = (in_turn.iter())
        .map(|pair| {
            assert_eq!(pair["own"], "dpp");
            check_rounds_in_turn(pair, 1);
            (
                pair["workload"].as_u64().unwrap(),
                pair["versus"].as_str().unwrap(),
                pair["measured"].as_str().unwrap(),
            )
        })
        .collect();
    assert_eq!(
        measured,
        [
            (1, "embree-packet", "map<intersect> stage"),
            (3, "embree-packet", "fused frame"),
        ]
    );
}

#[test]
fn embree_on_the_gpu_is_exit_status_2() {
    // Checked before any device is opened: the same answer with or without a GPU.
    let dir = tempfile::tempdir().unwrap();
    let pipelines = pipelines();
    for engine in ["embree", "dpp,embree"] {
        let output = dpp(
            &[
                "bench",
                "--pipelines",
                &pipelines,
                "--backend",
                "gpu",
                "--engine",
                engine,
            ],
            dir.path(),
        );
        let stderr = text(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "{engine}: {stderr}");
        assert!(
            stderr.contains("--engine embree runs on the CPU only"),
            "{engine}: {stderr}"
        );
        assert_eq!(text(&output.stdout), "", "nothing was measured");
    }
}

#[test]
fn a_gpu_bench_without_an_adapter_is_a_clear_error() {
    // No adapter of a backend this build lacks.
    let dir = tempfile::tempdir().unwrap();
    let output = Command::new(env!("CARGO_BIN_EXE_dpp"))
        .args(["bench", "--pipelines", &pipelines(), "--backend", "gpu"])
        .env("WGPU_BACKEND", "metal")
        .current_dir(dir.path())
        .output()
        .unwrap();
    let stderr = text(&output.stderr);
    assert_eq!(output.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("no GPU adapter found"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(text(&output.stdout), "");
}

#[test]
fn a_tiny_gpu_bench_names_the_adapter_and_times_stages() {
    if !crate::common::gpu_available("the GPU bench") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let output = dpp(
        &[
            "bench",
            "builtin:16",
            "--backend",
            "gpu",
            "--size",
            "64x48",
            "--views",
            "front",
            "--workloads",
            "1,2",
            "--warmup",
            "0",
            "--rounds",
            "1",
            "--pipelines",
            &pipelines(),
            "--json",
            "bench.json",
            "--chart",
            "bench.png",
        ],
        dir.path(),
    );
    let stdout = text(&output.stdout);
    assert!(
        output.status.success(),
        "{}\n{stdout}",
        text(&output.stderr)
    );

    let json = bench_json(dir.path());
    assert_eq!(json["backend"], "gpu");
    let adapter = json["adapter"]["name"].as_str().unwrap();
    assert!(!adapter.is_empty());
    assert!(json["adapter"]["backend"].is_string());
    assert!(json["adapter"]["driver"].is_string());
    let timing = json["stage_timing"].as_str().unwrap();
    assert!(["timestamp queries", "host"].contains(&timing), "{timing}");
    // The markdown header names the backend and the adapter, and how stages were timed.
    assert!(stdout.contains("GPU backend: "), "{stdout}");
    assert!(stdout.contains(adapter), "{stdout}");
    assert!(stdout.contains("warm-up rounds absorb both"), "{stdout}");

    let view = &json["scenes"][0]["views"][0];
    assert_eq!(view["primary_rays"], 64 * 48);
    let workloads = view["workloads"].as_array().unwrap();
    assert_eq!(workloads.len(), 2);
    for w in workloads {
        for plan in ["fused", "unfused"] {
            let m = &w[plan];
            assert_eq!(m["frames_ms"].as_array().unwrap().len(), 1, "{m}");
            assert_eq!(m["profiled_frames_ms"].as_array().unwrap().len(), 1, "{m}");
            assert!(m["mean_frame_ms"].as_f64().unwrap() > 0.0, "{m}");
            let stages = m["stages"].as_array().unwrap();
            assert!(!stages.is_empty(), "{m}");
            let total: f64 = stages.iter().map(|s| s["ms"].as_f64().unwrap()).sum();
            assert!(total > 0.0, "stage times: {m}");
            // A GPU stage is one kernel: not split by op.
            for stage in stages {
                assert_eq!(stage["op_thread_ms"], serde_json::json!([]), "{stage}");
            }
        }
    }
    // WORKLOAD1's `map<intersect>` rate comes from the unfused plan's stage.
    let unfused = &workloads[0]["unfused"];
    let intersect = unfused["stages"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["ops"] == "map<intersect>")
        .expect("the unfused plan has `map<intersect>` alone");
    assert_eq!(unfused["intersect_ms"], intersect["ms"]);
    assert!(unfused["intersect_mrays_per_s"].as_f64().unwrap() > 0.0);
    assert!(image::open(dir.path().join("bench.png")).unwrap().height() == 480);
}
