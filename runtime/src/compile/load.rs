//! Pass 1: load the entry file and every file it `use`s, transitively.
//! Each file is parsed once; a cycle of `use`s is a diagnostic.

use dpp_dsl::ast::{Item, Module};
use dpp_dsl::{Code, Diagnostic, FileId, SourceMap};
use std::path::{Path, PathBuf};

/// The modules of a program, entry first, each file once.
pub struct LoadedProgram {
    pub modules: Vec<Module>,
}

/// Loads `entry` (its text given, or read from disk) and its `use`s.
pub fn load_program(
    entry: &Path,
    entry_text: Option<String>,
    sources: &mut SourceMap,
    diagnostics: &mut Vec<Diagnostic>,
) -> Option<LoadedProgram> {
    let text = match entry_text {
        Some(text) => text,
        None => match std::fs::read_to_string(entry) {
            Ok(text) => text,
            Err(error) => {
                let file = sources.add("<command line>", entry.display().to_string());
                let span = dpp_dsl::Span::new(file, 0, entry.display().to_string().len());
                diagnostics.push(Diagnostic::error(
                    Code::Io,
                    format!("cannot read `{}`: {error}", entry.display()),
                    span,
                ));
                return None;
            }
        },
    };
    let mut loader = Loader {
        sources,
        diagnostics,
        modules: Vec::new(),
        stack: Vec::new(),
    };
    let file = loader.sources.add(entry, text);
    loader.parse_and_follow(file);
    Some(LoadedProgram {
        modules: loader.modules,
    })
}

struct Loader<'a> {
    sources: &'a mut SourceMap,
    diagnostics: &'a mut Vec<Diagnostic>,
    modules: Vec<Module>,
    /// Files whose `use`s are being followed, to detect cycles.
    stack: Vec<PathBuf>,
}

impl Loader<'_> {
    fn parse_and_follow(&mut self, file: FileId) {
        let path = self.sources.get(file).path.clone();
        let module = match dpp_dsl::parse_module(file, &self.sources.get(file).text) {
            Ok(module) => module,
            Err(errors) => {
                self.diagnostics.extend(errors);
                return;
            }
        };
        self.stack.push(canonical(&path));
        let base = path.parent().map(Path::to_path_buf).unwrap_or_default();
        for item in &module.items {
            let Item::Use(use_item) = item else { continue };
            let target = base.join(&use_item.path);
            let key = canonical(&target);
            if let Some(position) = self.stack.iter().position(|p| *p == key) {
                let cycle: Vec<String> = self.stack[position..]
                    .iter()
                    .chain(std::iter::once(&key))
                    .map(|p| file_name(p))
                    .collect();
                self.diagnostics.push(
                    Diagnostic::error(
                        Code::UseCycle,
                        format!("`use` cycle: {}", cycle.join(" → ")),
                        use_item.path_span,
                    )
                    .with_primary_message("this `use` closes the cycle"),
                );
                continue;
            }
            if self
                .modules
                .iter()
                .any(|m| canonical(&self.sources.get(m.file).path) == key)
            {
                continue; // already loaded through another `use`
            }
            match std::fs::read_to_string(&target) {
                Ok(text) => {
                    let used = self.sources.add(target, text);
                    self.parse_and_follow(used);
                }
                Err(error) => self.diagnostics.push(
                    Diagnostic::error(
                        Code::UseMissing,
                        format!("cannot read `{}`: {error}", target.display()),
                        use_item.path_span,
                    )
                    .with_help("`use` paths are relative to the file that holds the `use`"),
                ),
            }
        }
        self.stack.pop();
        // The entry module stays first: it is inserted before the modules it used.
        let insert_at = if self.stack.is_empty() {
            0
        } else {
            self.modules.len()
        };
        self.modules.insert(insert_at, module);
    }
}

fn canonical(path: &Path) -> PathBuf {
    std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf())
}

fn file_name(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| path.display().to_string())
}
