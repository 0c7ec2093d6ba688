//! The plan compiler: a chain of small passes, one per file.
//!
//! `load` (files and `use`s) → `resolve` (items) → `lower` (AST to ops, names,
//! fn inlining) → `typecheck` (types and symbolic lengths) → `desugar`
//! (element-wise expressions to maps) → `cse` → `fuse` (stages). Each pass reports diagnostics instead of stopping at the first.
//! In debug builds (so in every test) `validate` checks the plan's invariants
//! after each pass that makes or changes one.

pub mod cse;
pub mod desugar;
pub mod fuse;
pub mod host_eval;
pub mod ir;
pub mod load;
pub mod lower;
pub mod narrow;
pub mod plan_text;
pub mod resolve;
pub mod typecheck;
pub mod validate;

use crate::functor::FunctorLibrary;
use crate::host::{HostValue, Uniforms};
use crate::types::HostType;
use dpp_dsl::{did_you_mean, Code, Diagnostic, SourceMap, Span};
use host_eval::{eval_host, HostEnvironment};
use ir::{Node, ParamInfo, Plan, VarId, VarType};
use std::collections::HashMap;
use std::path::Path;
use validate::PlanPhase;

#[derive(Clone, Debug)]
pub struct CompileOptions {
    /// Fusion on (the default) or off (`--no-fuse`).
    pub fuse: bool,
    /// `--set name=value` overrides of params, as typed.
    pub overrides: Vec<(String, String)>,
}

impl Default for CompileOptions {
    fn default() -> Self {
        CompileOptions {
            fuse: true,
            overrides: Vec::new(),
        }
    }
}

/// Diagnostics and the sources they point into.
#[derive(Debug)]
pub struct CompileFailure {
    pub sources: SourceMap,
    pub diagnostics: Vec<Diagnostic>,
}

impl CompileFailure {
    pub fn render(&self, color: bool) -> String {
        dpp_dsl::render(&self.diagnostics, &self.sources, color)
    }
}

impl std::fmt::Display for CompileFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.render(false))
    }
}

impl std::error::Error for CompileFailure {}

pub fn compile_file(
    path: &Path,
    library: &FunctorLibrary,
    options: &CompileOptions,
) -> Result<Plan, CompileFailure> {
    compile(path, None, library, options)
}

/// Compiles `text` as if it were the file `path` (whose folder resolves `use`s).
pub fn compile_text(
    path: &Path,
    text: &str,
    library: &FunctorLibrary,
    options: &CompileOptions,
) -> Result<Plan, CompileFailure> {
    compile(path, Some(text.to_string()), library, options)
}

fn compile(
    path: &Path,
    text: Option<String>,
    library: &FunctorLibrary,
    options: &CompileOptions,
) -> Result<Plan, CompileFailure> {
    let mut sources = SourceMap::default();
    let mut diagnostics = Vec::new();
    let fail = |sources, diagnostics| {
        Err(CompileFailure {
            sources,
            diagnostics,
        })
    };

    let Some(loaded) = load::load_program(path, text, &mut sources, &mut diagnostics) else {
        return fail(sources, diagnostics);
    };
    if loaded.modules.is_empty() {
        return fail(sources, diagnostics);
    }
    let records: Vec<&str> = library
        .uniforms
        .records
        .keys()
        .map(String::as_str)
        .collect();
    let Some(program) = resolve::resolve_program(&loaded, &records, &mut diagnostics) else {
        return fail(sources, diagnostics);
    };
    let pipeline_span = program.pipeline.span;
    let mut lowered = lower::lower_program(&program, library, &mut diagnostics);
    if diagnostics.is_empty() {
        diagnostics.extend(validated(
            "lower",
            &lowered.vars,
            &lowered.body,
            PlanPhase::Lowered,
            pipeline_span,
        ));
    }
    typecheck::typecheck(&mut lowered.vars, &lowered.body, library, &mut diagnostics);
    let params = evaluate_params(&lowered, &options.overrides, &mut sources, &mut diagnostics);
    // A fn inlined at several calls reports each of its errors once.
    let mut unique: Vec<Diagnostic> = Vec::with_capacity(diagnostics.len());
    for diagnostic in diagnostics {
        if !unique.contains(&diagnostic) {
            unique.push(diagnostic);
        }
    }
    let diagnostics = unique;
    if !diagnostics.is_empty() {
        return fail(sources, diagnostics);
    }
    // Params become constants: a plan is compiled for one set of values.
    let mut body = lowered.body;
    for param in &params {
        for node in body.iter_mut() {
            if let Node::Host { dst, expr, .. } = node {
                if *dst == param.var {
                    *expr = ir::HostExpr::Const(param.value);
                }
            }
        }
    }
    let mut internal: Vec<Diagnostic> = Vec::new();
    if let Err(message) = desugar::desugar_expressions(&mut body, &mut lowered.vars, library) {
        internal.push(Diagnostic::error(Code::Internal, message, pipeline_span));
        return fail(sources, internal);
    }
    internal.extend(validated(
        "desugar",
        &lowered.vars,
        &body,
        PlanPhase::Typed,
        pipeline_span,
    ));
    narrow::narrow_records(&mut body, &mut lowered.vars);
    internal.extend(validated(
        "narrow",
        &lowered.vars,
        &body,
        PlanPhase::Typed,
        pipeline_span,
    ));
    cse::eliminate_common_subexpressions(&mut body, &mut lowered.vars);
    internal.extend(validated(
        "cse",
        &lowered.vars,
        &body,
        PlanPhase::Typed,
        pipeline_span,
    ));
    let body = fuse::form_stages(body, &lowered.vars, options.fuse);
    internal.extend(validated(
        "fuse",
        &lowered.vars,
        &body,
        PlanPhase::Fused,
        pipeline_span,
    ));
    if !internal.is_empty() {
        return fail(sources, internal);
    }
    Ok(Plan {
        pipeline: program.pipeline.name.name.clone(),
        fused: options.fuse,
        params,
        vars: lowered.vars,
        body,
        outputs: lowered.outputs,
    })
}

/// In debug builds, the plan validator's findings after `pass` as one
/// internal-error diagnostic at the pipeline (a compiler bug, not the user's).
fn validated(
    pass: &str,
    vars: &[ir::VarInfo],
    body: &[Node],
    phase: PlanPhase,
    span: Span,
) -> Option<Diagnostic> {
    if !cfg!(debug_assertions) {
        return None;
    }
    let problems = validate::validate_plan(vars, body, phase);
    (!problems.is_empty()).then(|| {
        Diagnostic::error(
            Code::Internal,
            format!("internal error: the plan is invalid after pass `{pass}`"),
            span,
        )
        .with_help(problems.join("\n"))
    })
}

/// Params are host constants: their file values may use earlier params; `--set`
/// replaces a value with one of a fitting type.
fn evaluate_params(
    lowered: &lower::Lowered,
    overrides: &[(String, String)],
    sources: &mut SourceMap,
    diagnostics: &mut Vec<Diagnostic>,
) -> Vec<ParamInfo> {
    struct ParamEnvironment {
        values: HashMap<VarId, HostValue>,
        uniforms: Uniforms,
    }
    impl HostEnvironment for ParamEnvironment {
        fn host_var(&self, var: VarId) -> Option<HostValue> {
            self.values.get(&var).copied()
        }
        fn array_len(&self, _: VarId) -> Option<usize> {
            None
        }
        fn uniforms(&self) -> &Uniforms {
            &self.uniforms
        }
    }
    let mut environment = ParamEnvironment {
        values: HashMap::new(),
        uniforms: Uniforms::default(),
    };
    let mut params = Vec::new();
    let mut override_spans = HashMap::new();
    for (name, value) in overrides {
        let text = format!("--set {name}={value}");
        let file = sources.add("<command line>", text.clone());
        override_spans.insert(name.clone(), Span::new(file, 6, text.len()));
    }
    for (name, var, span) in &lowered.params {
        let Some(expr) = lowered.body.iter().find_map(|n| match n {
            Node::Host { dst, expr, .. } if dst == var => Some(expr),
            _ => None,
        }) else {
            continue;
        };
        let VarType::Host(ty) = lowered.vars[var.0 as usize].ty else {
            continue; // already diagnosed by type checking
        };
        let mut value = match eval_host(expr, &environment) {
            Ok(value) => value,
            Err(message) => {
                diagnostics.push(Diagnostic::error(
                    Code::Param,
                    format!("param `{name}` must be a constant: {message}"),
                    *span,
                ));
                continue;
            }
        };
        let mut overridden = false;
        if let Some((_, text)) = overrides.iter().find(|(n, _)| n == name) {
            match parse_override(text, ty) {
                Ok(v) => {
                    value = v;
                    overridden = true;
                }
                Err(message) => diagnostics.push(
                    Diagnostic::error(Code::Set, message, override_spans[name])
                        .with_label(*span, format!("`{name}` is declared here as {ty}")),
                ),
            }
        }
        environment.values.insert(*var, value);
        params.push(ParamInfo {
            name: name.clone(),
            var: *var,
            ty,
            value,
            overridden,
        });
    }
    for (name, _) in overrides {
        if !lowered.params.iter().any(|(n, _, _)| n == name) {
            let mut diagnostic = Diagnostic::error(
                Code::Set,
                format!("`--set {name}`: the pipeline has no param `{name}`"),
                override_spans[name],
            );
            let names = lowered.params.iter().map(|(n, _, _)| n.as_str());
            if let Some(s) = did_you_mean(name, names) {
                diagnostic = diagnostic.with_help(format!("did you mean `{s}`?"));
            } else {
                let all: Vec<&str> = lowered.params.iter().map(|(n, _, _)| n.as_str()).collect();
                diagnostic = diagnostic.with_help(if all.is_empty() {
                    "it has no params".to_string()
                } else {
                    format!("its params: {}", all.join(", "))
                });
            }
            diagnostics.push(diagnostic);
        }
    }
    params
}

/// Parses a `--set` value for a param of type `ty`.
pub fn parse_override(text: &str, ty: HostType) -> Result<HostValue, String> {
    let text = text.trim();
    let floats = || -> Result<Vec<f32>, String> {
        text.split(',')
            .map(|p| {
                p.trim()
                    .parse::<f32>()
                    .map_err(|_| format!("`{text}` is not a list of numbers"))
            })
            .collect()
    };
    let wrong = |what: &str| Err(format!("`{text}` is not {what}"));
    match ty {
        HostType::Bool => match text {
            "true" => Ok(HostValue::Bool(true)),
            "false" => Ok(HostValue::Bool(false)),
            _ => wrong("`true` or `false`"),
        },
        HostType::Int => text
            .parse()
            .map(HostValue::Int)
            .or_else(|_| wrong("an integer")),
        HostType::Float => match text.parse::<f64>() {
            Ok(f) if f.is_finite() => Ok(HostValue::Float(f)),
            _ => wrong("a finite number"),
        },
        HostType::Vec2 | HostType::Vec3 | HostType::Vec4 => {
            let v = floats()?;
            match (ty, v.as_slice()) {
                (HostType::Vec2, [x, y]) => Ok(HostValue::Vec2([*x, *y])),
                (HostType::Vec3, [x, y, z]) => Ok(HostValue::Vec3([*x, *y, *z])),
                (HostType::Vec4, [x, y, z, w]) => Ok(HostValue::Vec4([*x, *y, *z, *w])),
                _ => wrong(&format!("a {ty} (comma-separated components)")),
            }
        }
    }
}
