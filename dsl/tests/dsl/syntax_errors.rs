//! Malformed `.dpp` inputs and their rendered diagnostics, as insta snapshots.
//! Each snapshot shows the input, then the report a user would see.

use dpp_dsl::{location, parse_module, render, Diagnostic, SourceMap, Span};

const WORKLOAD3: &str = include_str!("../data/workload3.dpp");

/// Parses `source`, which must fail, and snapshots the rendered diagnostics.
fn check(name: &str, source: &str) {
    let mut sources = SourceMap::default();
    let file = sources.add("broken.dpp", source);
    let diagnostics = match parse_module(file, source) {
        Ok(module) => panic!("expected a syntax error, got {module:#?}"),
        Err(diagnostics) => diagnostics,
    };
    assert!(!diagnostics.is_empty());
    let locations: Vec<String> = diagnostics.iter().map(|d| location(d, &sources)).collect();
    let report = render(&diagnostics, &sources, false);
    insta::assert_snapshot!(
        name,
        format!("{source}\n---\n{}\n---\n{report}", locations.join("\n"))
    );
}

macro_rules! cases {
    ($($name:ident => $source:expr,)*) => {
        $(
            #[test]
            fn $name() {
                check(stringify!($name), &$source);
            }
        )*
    };
}

cases! {
    missing_closing_brace => "pipeline p {\n    x = 1\n    out x\n",
    missing_opening_brace => "pipeline p\n    x = 1\n}",
    stray_token => "pipeline p {\n    x = 1 )\n}",
    missing_expression => "pipeline p {\n    x =\n}",
    missing_comma_in_args => "pipeline p {\n    x = map<f>(a b)\n}",
    missing_comma_in_params => "fn f(a b) { return a }",
    missing_in => "pipeline p {\n    for i 0..3 { }\n}",
    missing_range => "pipeline p {\n    for i in 3 { }\n}",
    unterminated_string => "use \"prelude.dpp\nparam x = 1",
    string_as_value => "param name = \"hello\"",
    arrow_into_name => "pipeline p {\n    y = x -> occluded\n}",
    arrow_into_field => "pipeline p {\n    y = x → camera.pixels\n}",
    keyword_as_param_name => "param for = 3",
    keyword_as_binding => "pipeline p {\n    in = 3\n}",
    keyword_as_fn_param => "fn f(a, while) { return a }",
    misspelled_item_keyword => "pipelin p { out x = 1 }",
    statement_at_top_level => "x = 1\npipeline p { out x }",
    integer_overflow => "param big = 99999999999999999999",
    float_overflow => "param huge = 1e999",
    malformed_numbers => "pipeline p {\n    a = 12abc\n    b = 1.5.2\n    c = 1e\n}",
    chained_comparison => "pipeline p {\n    if a < b < c { break }\n}",
    missing_return_value => "fn f(a) {\n    return\n}",
    call_across_lines_is_not_a_call => "pipeline p {\n    x = f\n    (a)\n}",
    functor_with_spaces => "pipeline p {\n    x = map< f >(a)\n}",
    else_without_if => "pipeline p {\n    else { x = 1 }\n}",
    two_broken_items => "param a = \n\nfn f(x) {\n    return x +\n}\n\npipeline p {\n    out y = (1\n}\n",
    broken_item_after_unclosed_block => "pipeline p {\n    x = 1\n\nfn f(a) { return ) }\n",
    errors_in_spec_example => WORKLOAD3.replace("→ map<occluded> →", "→ occluded →").replace("param spp       = 4", "param spp       = 4x"),
    unicode_before_error => "pipeline p {\n    y = x → map<f> → ∑\n}",
    control_character => "param a = 1\u{1}",
    only_garbage => "}}}",
    else_without_block => "pipeline p {\n    if x { y = 1 } else\n}",
    bare_call_statement => "pipeline p {\n    map<f>(x)\n}",
    tuple_without_closing_parenthesis => "pipeline p {\n    x = (a, b\n}",
    use_without_quotes => "use prelude.dpp\npipeline p { out x = 1 }",
    deep_brackets => format!("param x = {}1{}", "(".repeat(201), ")".repeat(201)),
}

// ---- rendering beyond syntax errors -------------------------------------------

#[test]
fn color_output_is_styled_and_plain_output_is_not() {
    let mut sources = SourceMap::default();
    let source = "param = 1";
    let file = sources.add("broken.dpp", source);
    let diagnostics = parse_module(file, source).unwrap_err();
    assert!(render(&diagnostics, &sources, true).contains('\u{1b}'));
    assert!(!render(&diagnostics, &sources, false).contains('\u{1b}'));
}

/// The plan compiler reports diagnostics spanning several files, e.g. a call in
/// the pipeline and the `fn` it calls in the prelude.
#[test]
fn labels_in_several_files() {
    let mut sources = SourceMap::default();
    let main_source = "use \"prelude.dpp\"\npipeline p {\n    out x = compactIndex(a, b)\n}\n";
    let prelude_source = "fn compactIndex(keep) {\n    return keep\n}\n";
    let main = sources.add("main.dpp", main_source);
    let prelude = sources.add("lib/prelude.dpp", prelude_source);
    let call_start = main_source.find("compactIndex").unwrap();
    let call = Span::new(main, call_start, main_source.find(")\n}").unwrap() + 1);
    let params = Span::new(prelude, 15, 21);
    let diagnostic = Diagnostic::error(
        dpp_dsl::Code::Arity,
        "`compactIndex` takes 1 argument but 2 were given",
        call,
    )
    .with_primary_message("2 arguments")
    .with_label(params, "defined with 1 parameter here")
    .with_help("remove the extra argument");
    let no_label = Diagnostic {
        code: dpp_dsl::Code::NoPipeline,
        message: "no `pipeline` in the file".into(),
        labels: Vec::new(),
        help: None,
    };
    let diagnostics = [diagnostic, no_label];
    let locations: Vec<String> = diagnostics.iter().map(|d| location(d, &sources)).collect();
    let report = render(&diagnostics, &sources, false);
    insta::assert_snapshot!(
        "labels_in_several_files",
        format!("{}\n---\n{report}", locations.join("\n"))
    );
}
