//! The parser never panics: on any input it returns a module or at least one
//! diagnostic whose spans lie inside the text on character boundaries, and
//! rendering those diagnostics does not panic either.

use dpp_dsl::{parse_module, render, Diagnostic, FileId, SourceMap};
use proptest::prelude::*;

const WORKLOAD3: &str = include_str!("../data/workload3.dpp");
const PRELUDE: &str = include_str!("../data/prelude.dpp");

/// Parses `text` and checks the result is well formed; returns the diagnostics.
fn check(text: &str) -> Vec<Diagnostic> {
    let file = FileId(0);
    let diagnostics = match parse_module(file, text) {
        Ok(module) => {
            assert_eq!(module.file, file);
            return Vec::new();
        }
        Err(diagnostics) => diagnostics,
    };
    assert!(
        !diagnostics.is_empty(),
        "an error without diagnostics for {text:?}"
    );
    for diagnostic in &diagnostics {
        assert!(!diagnostic.labels.is_empty(), "{diagnostic:?} has no label");
        for label in &diagnostic.labels {
            let span = label.span;
            assert_eq!(span.file, file);
            assert!(
                span.start <= span.end && span.end <= text.len(),
                "{span:?} outside {text:?}"
            );
            assert!(
                text.is_char_boundary(span.start) && text.is_char_boundary(span.end),
                "{span:?} splits a character of {text:?}"
            );
        }
    }
    let mut sources = SourceMap::default();
    sources.add("fuzz.dpp", text);
    assert!(!render(&diagnostics, &sources, false).is_empty());
    diagnostics
}

/// Byte offsets of the character boundaries of `text`, end included.
fn boundaries(text: &str) -> Vec<usize> {
    text.char_indices()
        .map(|(offset, _)| offset)
        .chain([text.len()])
        .collect()
}

/// Tokens of the language (and a few near misses) to build plausible inputs from.
const TOKENS: &[&str] = &[
    "use",
    "param",
    "fn",
    "pipeline",
    "out",
    "for",
    "in",
    "while",
    "if",
    "else",
    "break",
    "return",
    "true",
    "false",
    "x",
    "rays",
    "map",
    "camera",
    "0",
    "42",
    "0.5",
    "1e-3",
    "1e",
    "99999999999999999999",
    "\"p.dpp\"",
    "\"",
    "(",
    ")",
    "{",
    "}",
    "<",
    ">",
    "<f>",
    ",",
    ":",
    ";",
    "=",
    "==",
    "!=",
    "<=",
    ">=",
    "+",
    "-",
    "*",
    "/",
    "%",
    "!",
    "&&",
    "||",
    "->",
    "→",
    ".",
    "..",
    "// c\n",
    " ",
    "\n",
    "\t",
];

fn token_soup() -> impl Strategy<Value = String> {
    prop::collection::vec(prop::sample::select(TOKENS), 0..60).prop_map(|tokens| tokens.concat())
}

/// A valid file with one edit: a range deleted, text inserted, or a range repeated.
fn mutated_valid_file() -> impl Strategy<Value = String> {
    let base = prop::sample::select(vec![WORKLOAD3, PRELUDE]);
    (
        base,
        0..3u8,
        any::<prop::sample::Index>(),
        any::<prop::sample::Index>(),
        token_soup(),
    )
        .prop_map(|(base, edit, first, second, insertion)| {
            let cuts = boundaries(base);
            let (a, b) = (first.get(&cuts), second.get(&cuts));
            let (start, end) = (*a.min(b), *a.max(b));
            match edit {
                0 => format!("{}{}", &base[..start], &base[end..]),
                1 => format!("{}{insertion}{}", &base[..start], &base[start..]),
                _ => format!("{}{}", &base[..end], &base[start..]),
            }
        })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn arbitrary_strings(text in any::<String>()) {
        check(&text);
    }

    #[test]
    fn arbitrary_bytes(bytes in prop::collection::vec(any::<u8>(), 0..200)) {
        check(&String::from_utf8_lossy(&bytes));
    }

    #[test]
    fn characters_of_the_language(text in "[a-z0-9_ \t\n(){}<>=+*/%!&|.,:;\"→-]{0,120}") {
        check(&text);
    }

    #[test]
    fn token_sequences(text in token_soup()) {
        check(&text);
    }

    #[test]
    fn edits_of_valid_files(text in mutated_valid_file()) {
        check(&text);
    }
}

// ---- inputs that would exhaust the stack if depth were unbounded ----------------

fn codes(text: &str) -> Vec<&'static str> {
    check(text).iter().map(|d| d.code.as_str()).collect()
}

#[test]
fn the_spec_examples_parse() {
    assert!(check(WORKLOAD3).is_empty());
    assert!(check(PRELUDE).is_empty());
}

#[test]
fn nesting_up_to_the_limit_parses() {
    assert!(check(&format!(
        "param x = {}1{}",
        "(".repeat(200),
        ")".repeat(200)
    ))
    .is_empty());
    let blocks = format!(
        "pipeline p {{ {}{} }}",
        "if a { ".repeat(199),
        "}".repeat(199)
    );
    assert!(check(&blocks).is_empty());
    assert!(check(&format!("param x = 1{}", " + 1".repeat(198))).is_empty());
}

#[test]
fn deep_brackets_are_a_diagnostic() {
    assert_eq!(codes(&"(".repeat(100_000)), ["dpp::nesting"]);
    assert_eq!(
        codes(&format!("param x = {}", "{[(".repeat(50_000))),
        ["dpp::nesting"]
    );
    assert_eq!(
        codes(&format!("pipeline p {{ {} }}", "while a { ".repeat(10_000))),
        ["dpp::nesting"]
    );
}

#[test]
fn long_chains_are_a_diagnostic() {
    let nesting = ["dpp::nesting"];
    assert_eq!(
        codes(&format!("param x = 1{}", " + 1".repeat(5_000))),
        nesting
    );
    assert_eq!(codes(&format!("param x = {}1", "-".repeat(5_000))), nesting);
    assert_eq!(
        codes(&format!("param x = {}1", "! ".repeat(5_000))),
        nesting
    );
    assert_eq!(
        codes(&format!("param x = a{}", ".b".repeat(5_000))),
        nesting
    );
    assert_eq!(
        codes(&format!("param x = a{}", " → f".repeat(300))),
        ["dpp::syntax"; 300]
    );
    assert_eq!(
        codes(&format!("param x = a{}", " → f()".repeat(5_000))),
        nesting
    );
    let else_ifs = format!(
        "pipeline p {{ if a {{ }}{} }}",
        " else if a { }".repeat(2_000)
    );
    assert_eq!(codes(&else_ifs), nesting);
}

#[test]
fn many_items_and_errors() {
    let many_errors = "param = \n".repeat(300);
    assert_eq!(check(&many_errors).len(), 300);
    assert!(check(&"param a = 1\n".repeat(2_000)).is_empty());
}
