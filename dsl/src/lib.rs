//! The `.dpp` pipeline language: grammar, parser, spanned AST and diagnostics.
//! This crate knows nothing of functors, plans or backends.

pub mod ast;
pub mod diagnostic;
mod parser;
mod render;
pub mod source;
mod suggest;

pub use diagnostic::{Code, Diagnostic, Label};
pub use parser::parse_module;
pub use render::{location, render};
pub use source::{FileId, SourceFile, SourceMap, Span};
pub use suggest::did_you_mean;
