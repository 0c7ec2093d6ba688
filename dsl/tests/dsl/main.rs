//! The language crate's tests, one binary: parses, syntax errors, and a
//! parser that never panics.

mod never_panics;
mod parse;
mod syntax_errors;
