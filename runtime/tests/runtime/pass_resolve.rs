//! Passes 1–2, `load` and `resolve`: which files a program reads (each once,
//! `use` paths relative to the file that holds the `use`), and the items it
//! gathers from them (one pipeline, no duplicate or reserved names).
//!
//! Each case is a fixture of one or more files (`//- name.dpp` starts a file;
//! the first one is the entry). The files are written to a fresh temporary
//! folder, beside a copy of `pipelines/prelude.dpp`. The expectation lists the
//! files `load` read, in module order, then either a summary of the compiled
//! plan or every diagnostic, one per line.

use crate::common::{check, library, pipelines_path, trim_indent};
use dpp_runtime::compile::load::load_program;
use dpp_runtime::{compile_file, CompileOptions, Plan};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// Splits a fixture into `(path, text)` files; without markers it is `main.dpp`.
fn parse_fixture(fixture: &str) -> Vec<(String, String)> {
    let fixture = trim_indent(fixture);
    if !fixture.starts_with("//- ") {
        return vec![("main.dpp".to_string(), fixture)];
    }
    let mut files: Vec<(String, String)> = Vec::new();
    for line in fixture.lines() {
        if let Some(path) = line.strip_prefix("//- ") {
            files.push((path.trim().to_string(), String::new()));
        } else {
            let text = &mut files.last_mut().unwrap().1;
            text.push_str(line);
            text.push('\n');
        }
    }
    files
}

/// A folder of its own under the system's temporary folder, removed on drop.
struct TempDir(PathBuf);

impl TempDir {
    fn new() -> TempDir {
        static NEXT: AtomicUsize = AtomicUsize::new(0);
        let path = std::env::temp_dir().join(format!(
            "dpp-pass-resolve-{}-{}",
            std::process::id(),
            NEXT.fetch_add(1, Ordering::Relaxed)
        ));
        let _ = std::fs::remove_dir_all(&path);
        std::fs::create_dir_all(&path).unwrap();
        TempDir(path)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// `rel/path.dpp` for a path inside `dir` (the machine's folder removed).
fn relative(path: &Path, dir: &Path) -> String {
    path.strip_prefix(dir)
        .map(|p| p.display().to_string())
        .unwrap_or_else(|_| path.display().to_string())
}

/// The pipeline's name, params, every op in plan order (fns inlined) and outputs.
fn summary(plan: &Plan) -> String {
    let mut lines = vec![format!("pipeline {}", plan.pipeline)];
    for param in &plan.params {
        lines.push(format!(
            "param {}: {} = {}",
            param.name, param.ty, param.value
        ));
    }
    let ops: Vec<String> = plan
        .stages()
        .iter()
        .flat_map(|s| s.ops.iter().map(|op| op.label()))
        .collect();
    lines.push(format!("ops: {}", ops.join(", ")));
    lines.push(format!("outputs: {}", plan.outputs.join(", ")));
    lines.join("\n")
}

/// Writes the fixture, loads and compiles its entry file; returns the report.
fn report(fixture: &str) -> String {
    let dir = TempDir::new();
    std::fs::copy(pipelines_path("prelude.dpp"), dir.0.join("prelude.dpp")).unwrap();
    let files = parse_fixture(fixture);
    for (path, text) in &files {
        let path = dir.0.join(path);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, text).unwrap();
    }
    let entry = dir.0.join(&files[0].0);

    // Pass 1 on its own: the files read, each once.
    let mut sources = dpp_dsl::SourceMap::default();
    let mut diagnostics = Vec::new();
    let loaded = load_program(&entry, None, &mut sources, &mut diagnostics).unwrap();
    let modules: Vec<String> = loaded
        .modules
        .iter()
        .map(|m| relative(&sources.get(m.file).path, &dir.0))
        .collect();
    let mut report = format!("loaded: {}\n", modules.join(", "));

    // The whole compiler: resolve's diagnostics, or what it resolved.
    match compile_file(&entry, &library(), &CompileOptions::default()) {
        Ok(plan) => report.push_str(&summary(&plan)),
        Err(failure) => {
            for d in &failure.diagnostics {
                let at = |span: dpp_dsl::Span| {
                    let (line, col) = failure.sources.line_col(span.file, span.start);
                    let path = relative(&failure.sources.get(span.file).path, &dir.0);
                    let text = failure.sources.text(span);
                    let text = text.lines().next().unwrap_or("");
                    format!("{path}:{line}:{col} `{text}`")
                };
                report.push_str(&format!(
                    "{} at {}: {}\n",
                    d.code,
                    at(d.labels[0].span),
                    d.message
                ));
                for label in &d.labels[1..] {
                    report.push_str(&format!("  {}: {}\n", at(label.span), label.message));
                }
                if let Some(help) = &d.help {
                    report.push_str(&format!("  help: {help}\n"));
                }
            }
        }
    }
    report.replace(&format!("{}/", dir.0.display()), "")
}

#[test]
fn one_file_gives_its_pipeline_params_and_fns() {
    check!(
        r#"
        param n = 4
        param m = n * 2
        fn double(a) { return map<add>(a, a) }
        pipeline p {
            out r = double(iota(m))
        }
        "#,
        @"
    loaded: main.dpp
    pipeline p
    param n: int = 4
    param m: int = 8
    ops: iota, map<add>
    outputs: r
    "
    );
}

#[test]
fn duplicate_fns_and_params_are_all_reported() {
    check!(
        r#"
        param n = 1
        fn f(a) { return a }
        param n = 2
        fn f(b) { return b }
        fn n(c) { return c }
        pipeline p { out r = iota(n) }
        "#,
        @"
    loaded: main.dpp
    dpp::duplicate at main.dpp:3:7 `n`: `n` is defined twice
      main.dpp:1:7 `n`: first defined here
    dpp::duplicate at main.dpp:4:4 `f`: `f` is defined twice
      main.dpp:2:4 `f`: first defined here
    dpp::duplicate at main.dpp:5:4 `n`: `n` is defined twice
      main.dpp:3:7 `n`: first defined here
    "
    );
}

#[test]
fn a_file_holds_one_pipeline() {
    check!(
        r#"
        pipeline first { out a = iota(1) }
        pipeline second { out b = iota(2) }
        "#,
        @"
    loaded: main.dpp
    dpp::duplicate at main.dpp:2:10 `second`: a file holds one pipeline
      main.dpp:1:10 `first`: the first pipeline is here
    "
    );
}

#[test]
fn a_file_without_a_pipeline_is_an_error() {
    check!(
        r#"
        param n = 1
        fn f(a) { return a }
        "#,
        @"
    loaded: main.dpp
    dpp::no-pipeline at main.dpp:1:1 `param n = 1`: this file has no `pipeline` to run
      help: add `pipeline name { … }`
    "
    );
}

#[test]
fn names_of_the_language_cannot_be_redefined() {
    check!(
        r#"
        param iota = 3
        fn map(a) { return a }
        fn len(a) { return a }
        pipeline p { out r = fill(2, 1) }
        "#,
        @"
    loaded: main.dpp
    dpp::reserved at main.dpp:1:7 `iota`: `iota` is a name of the language and cannot be redefined
    dpp::reserved at main.dpp:2:4 `map`: `map` is a name of the language and cannot be redefined
    dpp::reserved at main.dpp:3:4 `len`: `len` is a name of the language and cannot be redefined
    "
    );
}

#[test]
fn use_of_the_prelude_from_another_folder() {
    // `use` paths are relative to the file holding the `use`.
    check!(
        r#"
        //- app/main.dpp
        use "../prelude.dpp"
        param n = 8
        pipeline compaction {
            values = iota(n)
            out kept = gather(compactIndex(map<lt>(values, fill(n, 3))), values)
        }
        "#,
        @"
    loaded: app/main.dpp, app/../prelude.dpp
    pipeline compaction
    param n: int = 8
    ops: iota, fill, map<lt>, map<toU32>, reduce<add>, iota, exclusiveScan<add>, iota, scatter, iota, gather
    outputs: kept
    "
    );
}

#[test]
fn nested_uses_resolve_against_their_own_folder() {
    check!(
        r#"
        //- main.dpp
        use "lib/a.dpp"
        pipeline p { out r = twice(iota(4)) }
        //- lib/a.dpp
        use "b.dpp"
        fn twice(x) { return double(x) }
        //- lib/b.dpp
        fn double(x) { return map<add>(x, x) }
        "#,
        @"
    loaded: main.dpp, lib/b.dpp, lib/a.dpp
    pipeline p
    ops: iota, map<add>
    outputs: r
    "
    );
}

#[test]
fn a_diamond_of_uses_loads_the_shared_file_once() {
    // Loading `common.dpp` twice would define `inc` twice.
    check!(
        r#"
        //- main.dpp
        use "a.dpp"
        use "b.dpp"
        pipeline p { out r = fromB(fromA(iota(4))) }
        //- a.dpp
        use "common.dpp"
        fn fromA(x) { return inc(x) }
        //- b.dpp
        use "lib/../common.dpp"
        fn fromB(x) { return inc(x) }
        //- common.dpp
        param one = 1
        fn inc(x) { return map<add>(x, fill(len(x), one)) }
        //- lib/.keep
        "#,
        @"
    loaded: main.dpp, common.dpp, a.dpp, b.dpp
    pipeline p
    param one: int = 1
    ops: iota, fill, map<add>, fill, map<add>
    outputs: r
    "
    );
}

#[test]
fn a_missing_use_file_is_reported_at_its_path() {
    check!(
        r#"
        //- main.dpp
        use "prelude.dpp"
        use "nowhere.dpp"
        use "lib/missing.dpp"
        pipeline p { out r = iota(4) }
        "#,
        @r#"
    loaded: main.dpp, prelude.dpp
    dpp::use-missing at main.dpp:2:5 `"nowhere.dpp"`: cannot read `nowhere.dpp`: No such file or directory (os error 2)
      help: `use` paths are relative to the file that holds the `use`
    dpp::use-missing at main.dpp:3:5 `"lib/missing.dpp"`: cannot read `lib/missing.dpp`: No such file or directory (os error 2)
      help: `use` paths are relative to the file that holds the `use`
    "#
    );
}

#[test]
fn a_cycle_of_uses_is_reported_once() {
    check!(
        r#"
        //- main.dpp
        use "a.dpp"
        pipeline p { out r = iota(4) }
        //- a.dpp
        use "b.dpp"
        fn fa(x) { return x }
        //- b.dpp
        use "a.dpp"
        fn fb(x) { return x }
        "#,
        @r#"
    loaded: main.dpp, b.dpp, a.dpp
    dpp::use-cycle at b.dpp:1:5 `"a.dpp"`: `use` cycle: a.dpp → b.dpp → a.dpp
    "#
    );
}

#[test]
fn a_used_files_pipeline_is_ignored() {
    check!(
        r#"
        //- main.dpp
        use "other.dpp"
        pipeline entry { out r = helper(iota(2)) }
        //- other.dpp
        fn helper(x) { return map<add>(x, x) }
        pipeline other { out s = iota(9) }
        "#,
        @"
    loaded: main.dpp, other.dpp
    pipeline entry
    ops: iota, map<add>
    outputs: r
    "
    );
}

#[test]
fn a_name_defined_in_two_files_is_a_duplicate() {
    check!(
        r#"
        //- main.dpp
        use "lib.dpp"
        param k = 2
        fn f(a) { return a }
        pipeline p { out r = f(iota(k)) }
        //- lib.dpp
        param k = 3
        fn f(a) { return map<add>(a, a) }
        "#,
        @"
    loaded: main.dpp, lib.dpp
    dpp::duplicate at lib.dpp:1:7 `k`: `k` is defined twice
      main.dpp:2:7 `k`: first defined here
    dpp::duplicate at lib.dpp:2:4 `f`: `f` is defined twice
      main.dpp:3:4 `f`: first defined here
    "
    );
}

#[test]
fn params_of_used_files_are_visible_entry_file_first() {
    // Params are evaluated in declaration order, entry file first, so a used
    // file's param may read the entry's params (not the other way round).
    check!(
        r#"
        //- main.dpp
        use "lib.dpp"
        param n = 3
        pipeline p { out r = iota(n + m) }
        //- lib.dpp
        param m = n * 10
        "#,
        @"
    loaded: main.dpp, lib.dpp
    pipeline p
    param n: int = 3
    param m: int = 30
    ops: iota
    outputs: r
    "
    );
}

#[test]
fn a_param_reads_only_earlier_params() {
    check!(
        r#"
        //- main.dpp
        use "lib.dpp"
        param a = b + 1
        param b = 2
        param c = fromLib
        pipeline p { out r = iota(a + c) }
        //- lib.dpp
        param fromLib = 5
        "#,
        @"
    loaded: main.dpp, lib.dpp
    dpp::unknown-name at main.dpp:2:11 `b`: unknown name `b`
    dpp::unknown-name at main.dpp:4:11 `fromLib`: unknown name `fromLib`
    "
    );
}
