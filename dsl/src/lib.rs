//! The `.dpp` pipeline language: grammar, parser, spanned AST and diagnostics.
//! This crate knows nothing of functors, plans or backends.

pub mod ast;
pub mod diagnostic;
pub mod source;

pub use diagnostic::{Diagnostic, Label};
pub use source::{FileId, SourceFile, SourceMap, Span};
