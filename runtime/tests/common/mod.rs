//! Helpers shared by the runtime's integration tests.

// Every test file is its own crate and uses only some of these helpers.
#![allow(dead_code)]

use dpp_runtime::compile::ir::{Node, Plan, VarInfo};
use dpp_runtime::compile::plan_text::plan_to_text;
use dpp_runtime::cpu::column_pool::ColumnPool;
use dpp_runtime::cpu::exec::{run_plan, RunContext};
use dpp_runtime::interpret::OutputValue;
use dpp_runtime::*;
use std::path::{Path, PathBuf};

/// The generic functor library.
pub fn library() -> FunctorLibrary {
    let mut library = FunctorLibrary::default();
    dpp_runtime::generic::register_generic_functors(&mut library);
    library
}

/// [`library`] with `Pair { a: u32, b: f32 }` and `makePair(x: u32) -> Pair`
/// (`a = x`, `b = x / 2`), for the tests of records.
pub fn library_with_pairs() -> FunctorLibrary {
    let mut library = library();
    let pair = library.records.register(RecordType {
        name: "Pair".into(),
        fields: vec![("a".into(), ElemType::U32), ("b".into(), ElemType::F32)],
        doc: "a test record".into(),
    });
    let signature = Signature::map("makePair")
        .input("x", ElemType::U32)
        .output("pair", ElemType::Record(pair))
        .doc("a Pair from x");
    let make_pair =
        dpp_runtime::functor::ClosureFunctor::new(signature, move |_, inputs, outputs| {
            let x = inputs[0].as_u32();
            outputs[0] = Column::Record {
                ty: pair,
                fields: vec![
                    std::sync::Arc::new(Column::U32(x.to_vec())),
                    std::sync::Arc::new(Column::F32(x.iter().map(|v| *v as f32 / 2.0).collect())),
                ],
            };
            Ok(())
        });
    library.register(std::sync::Arc::new(make_pair));
    library
}

/// Removes the indentation common to every non-blank line, and a leading newline.
pub fn trim_indent(text: &str) -> String {
    let text = text.strip_prefix('\n').unwrap_or(text);
    let indent = text
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.len() - l.trim_start().len())
        .min()
        .unwrap_or(0);
    text.lines()
        .map(|l| if l.len() >= indent { &l[indent..] } else { "" })
        .collect::<Vec<_>>()
        .join("\n")
}

/// `pipelines/<name>`: a file beside `pipelines/prelude.dpp`, so that
/// `use "prelude.dpp"` works from it.
pub fn pipelines_path(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../pipelines")
        .join(name)
}

/// Compiles `source` as the file `path`, fused or not.
pub fn compile(
    path: &Path,
    source: &str,
    library: &FunctorLibrary,
    fuse: bool,
) -> Result<Plan, CompileFailure> {
    let options = CompileOptions {
        fuse,
        ..CompileOptions::default()
    };
    compile_text(path, source, library, &options)
}

/// An unfused plan without params of the given variables, body and outputs.
pub fn plan(pipeline: &str, vars: Vec<VarInfo>, body: Vec<Node>, outputs: Vec<String>) -> Plan {
    Plan {
        pipeline: pipeline.to_string(),
        fused: false,
        params: Vec::new(),
        vars,
        body,
        outputs,
    }
}

/// The text of `plan` without its first (`pipeline …`) line.
pub fn ops_text(plan: &Plan, library: &FunctorLibrary) -> String {
    let text = plan_to_text(plan, library);
    text.lines().skip(1).map(|l| format!("{l}\n")).collect()
}

/// Every diagnostic as `code at line:col `text`: message`, labels and help below.
pub fn diagnostics_text(failure: &CompileFailure) -> String {
    let mut text = String::new();
    let at = |span: dpp_dsl::Span| {
        let (line, col) = failure.sources.line_col(span.file, span.start);
        let source = failure.sources.text(span).lines().next().unwrap_or("");
        format!("{line}:{col} `{source}`")
    };
    for d in &failure.diagnostics {
        text.push_str(&format!(
            "{} at {}: {}\n",
            d.code,
            at(d.labels[0].span),
            d.message
        ));
        for label in &d.labels[1..] {
            text.push_str(&format!("  {}: {}\n", at(label.span), label.message));
        }
        if let Some(help) = &d.help {
            text.push_str(&format!("  help: {help}\n"));
        }
    }
    text
}

pub fn column_text(column: &Column) -> String {
    match column {
        Column::Bool(v) => format!("{v:?}"),
        Column::U32(v) => format!("{v:?}"),
        Column::I32(v) => format!("{v:?}"),
        Column::F32(v) => format!("{v:?}"),
        other => format!("{other:?}"),
    }
}

/// Runs `plan`; returns `name = value` lines, or the run-time error's message.
pub fn run(plan: &Plan, library: &FunctorLibrary) -> Result<String, String> {
    let uniforms = Uniforms::default();
    let context = RunContext {
        library,
        uniforms: &uniforms,
        resources: &(),
        chunk: 64,
        column_pool: &ColumnPool::new(),
        elementwise: dpp_runtime::cpu::compiled::Elementwise::default(),
    };
    let result = run_plan(plan, &context).map_err(|e| e.message)?;
    Ok(result
        .outputs
        .iter()
        .map(|(name, value)| match value {
            OutputValue::Array(column) => format!("{name} = {}\n", column_text(column)),
            OutputValue::Host(value) => format!("{name} = {value}\n"),
        })
        .collect())
}

/// [`run`]'s `name = value` lines, or `run-time error: …` as one line.
pub fn run_text(plan: &Plan, library: &FunctorLibrary) -> String {
    run(plan, library).unwrap_or_else(|message| format!("run-time error: {message}\n"))
}

/// `check!(source, @"expected")`: the test file's `report(source)` against an
/// inline snapshot. (Unused, like the helpers above, in some test files.)
#[allow(unused_macros)]
macro_rules! check {
    ($source:expr, @$expected:literal) => {
        insta::assert_snapshot!(report($source), @$expected)
    };
}
#[allow(unused_imports)]
pub(crate) use check;
