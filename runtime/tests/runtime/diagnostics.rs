//! Every bad pipeline under `tests/bad/` fails to compile with rendered
//! diagnostics (file:line:col, the source line, the span marked), pinned by
//! snapshots. `use_cycle_b.dpp` is only reached through `use_cycle_a.dpp`.

use crate::common::library;
use dpp_runtime::{compile_file, CompileOptions};
use std::path::{Path, PathBuf};

fn bad_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/bad")
}

/// Compiles `file` (relative to `tests/bad`), asserts failure and returns the
/// rendered diagnostics with the machine-specific directory stripped.
fn check(file: &str, overrides: &[(&str, &str)]) -> String {
    let options = CompileOptions {
        fuse: true,
        overrides: overrides
            .iter()
            .map(|(n, v)| (n.to_string(), v.to_string()))
            .collect(),
    };
    let failure = match compile_file(&bad_dir().join(file), &library(), &options) {
        Ok(plan) => panic!("{file} compiled, but it should not: {plan:?}"),
        Err(failure) => failure,
    };
    assert!(!failure.diagnostics.is_empty());
    let text = failure.render(false);
    text.replace(&format!("{}/", bad_dir().display()), "")
}

#[test]
fn every_bad_pipeline_has_a_diagnostic() {
    let mut files: Vec<String> = std::fs::read_dir(bad_dir())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|name| name.ends_with(".dpp") && name != "use_cycle_b.dpp")
        .collect();
    files.sort();
    assert!(files.len() >= 15, "the corpus shrank: {files:?}");
    for file in files {
        let rendered = check(&file, &[]);
        insta::assert_snapshot!(file.trim_end_matches(".dpp").to_string(), rendered);
    }
}

#[test]
fn every_error_of_a_file_is_reported() {
    let rendered = check("many_errors.dpp", &[]);
    for expected in [
        "unknown functor `mull`",
        "`gather` takes 2 array arguments",
        "`sub` is not associative",
        "`return` outside a fn",
    ] {
        assert!(
            rendered.contains(expected),
            "missing `{expected}` in:\n{rendered}"
        );
    }
}

#[test]
fn unknown_set_parameter_is_reported_with_a_suggestion() {
    let rendered = check("../../../pipelines/examples/histogram.dpp", &[("bin", "3")]);
    insta::assert_snapshot!(rendered);
}

#[test]
fn set_value_of_the_wrong_type_is_reported() {
    let rendered = check(
        "../../../pipelines/examples/histogram.dpp",
        &[("bins", "2.5")],
    );
    insta::assert_snapshot!(rendered);
}
