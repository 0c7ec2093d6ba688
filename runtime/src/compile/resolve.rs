//! Pass 2: gather the items of all loaded modules into one [`Program`]: the
//! entry file's pipeline, every `param` and every `fn`. Duplicates and a
//! missing pipeline are diagnostics.

use super::ir::{Generator, Primitive, COMPOSITE};
use super::load::LoadedProgram;
use dpp_dsl::ast::{FnItem, Item, ParamItem, PipelineItem};
use dpp_dsl::{Code, Diagnostic, Span};
use std::collections::HashMap;

/// Whether a `fn`, `param` or binding may not take `name`.
pub fn is_reserved(name: &str) -> bool {
    Primitive::from_name(name).is_some()
        || Generator::from_name(name).is_some()
        || name == COMPOSITE
}

pub struct Program<'a> {
    pub pipeline: &'a PipelineItem,
    /// In declaration order (entry file first, then used files).
    pub params: Vec<&'a ParamItem>,
    pub fns: HashMap<&'a str, &'a FnItem>,
}

pub fn resolve_program<'a>(
    loaded: &'a LoadedProgram,
    uniform_records: &[&str],
    diagnostics: &mut Vec<Diagnostic>,
) -> Option<Program<'a>> {
    let mut pipeline: Option<&PipelineItem> = None;
    let mut params: Vec<&ParamItem> = Vec::new();
    let mut fns: HashMap<&str, &FnItem> = HashMap::new();
    let mut defined: HashMap<&str, Span> = HashMap::new();

    for (index, module) in loaded.modules.iter().enumerate() {
        for item in &module.items {
            let (name, span) = match item {
                Item::Use(_) => continue,
                Item::Pipeline(p) => {
                    // Only the entry file's pipeline runs; a used file's pipeline is ignored.
                    if index == 0 {
                        if let Some(first) = pipeline {
                            diagnostics.push(
                                Diagnostic::error(
                                    Code::Duplicate,
                                    "a file holds one pipeline",
                                    p.name.span,
                                )
                                .with_label(first.name.span, "the first pipeline is here"),
                            );
                        } else {
                            pipeline = Some(p);
                        }
                    }
                    continue;
                }
                Item::Param(p) => {
                    params.push(p);
                    (p.name.name.as_str(), p.name.span)
                }
                Item::Fn(f) => {
                    fns.insert(f.name.name.as_str(), f);
                    (f.name.name.as_str(), f.name.span)
                }
            };
            if is_reserved(name) || uniform_records.contains(&name) {
                diagnostics.push(Diagnostic::error(
                    Code::Reserved,
                    format!("`{name}` is a name of the language and cannot be redefined"),
                    span,
                ));
            } else if let Some(first) = defined.insert(name, span) {
                diagnostics.push(
                    Diagnostic::error(Code::Duplicate, format!("`{name}` is defined twice"), span)
                        .with_label(first, "first defined here"),
                );
            }
        }
    }

    match pipeline {
        Some(pipeline) => Some(Program {
            pipeline,
            params,
            fns,
        }),
        None => {
            let entry = &loaded.modules[0];
            let end = entry.items.last().map_or(0, item_end);
            diagnostics.push(
                Diagnostic::error(
                    Code::NoPipeline,
                    "this file has no `pipeline` to run",
                    Span::new(entry.file, 0, end),
                )
                .with_help("add `pipeline name { … }`"),
            );
            None
        }
    }
}

fn item_end(item: &Item) -> usize {
    match item {
        Item::Use(u) => u.span.end,
        Item::Param(p) => p.span.end,
        Item::Fn(f) => f.span.end,
        Item::Pipeline(p) => p.span.end,
    }
}
