//! Pass 5, `cse`: an op that applies the same primitive and functor to the
//! same values as an earlier op of its block (no input rewritten in between)
//! reuses the earlier op's results.
//!
//! `check!(source, @"…")` runs passes 1–5 and shows the ops after CSE (types
//! included), then RUNS the program three ways: without CSE (passes 1–4, then
//! unfused stages), and through the whole compiler fused and unfused. All
//! three must give the same outputs, which are listed last.

use crate::common::{check, compile, ops_text, pipelines_path, plan, run_text, trim_indent};
use dpp_runtime::compile::{cse, fuse, load, lower, resolve, typecheck};

/// The ops after CSE and the outputs of the runs (which must agree).
fn report(source: &str) -> String {
    let source = trim_indent(source);
    let library = crate::common::library();
    let path = pipelines_path("cse_test.dpp");

    // Passes 1–4, as the driver runs them.
    let mut sources = dpp_dsl::SourceMap::default();
    let mut diagnostics = Vec::new();
    let loaded = load::load_program(&path, Some(source.clone()), &mut sources, &mut diagnostics)
        .expect("the source text is given");
    let program = resolve::resolve_program(&loaded, &[], &mut diagnostics).unwrap();
    let mut lowered = lower::lower_program(&program, &library, &mut diagnostics);
    typecheck::typecheck(&mut lowered.vars, &lowered.body, &library, &mut diagnostics);
    assert!(diagnostics.is_empty(), "{diagnostics:?}");
    let name = program.pipeline.name.name.clone();

    // Pass 5.
    let mut body = lowered.body.clone();
    let mut vars = lowered.vars.clone();
    cse::eliminate_common_subexpressions(&mut body, &mut vars);
    let after = plan(&name, vars, body, lowered.outputs.clone());
    let mut text = ops_text(&after, &library);

    // The same program without CSE, and through the whole compiler.
    let stages = fuse::form_stages(lowered.body, &lowered.vars, false);
    let without_cse = run_text(
        &plan(&name, lowered.vars, stages, lowered.outputs),
        &library,
    );
    for fuse in [true, false] {
        let compiled = compile(&path, &source, &library, fuse).unwrap();
        assert_eq!(
            run_text(&compiled, &library),
            without_cse,
            "CSE changed the outputs (fuse: {fuse})\n{text}"
        );
    }
    text.push_str("---\n");
    text.push_str(&without_cse);
    text
}

#[test]
fn the_preludes_compaction_converts_keep_once() {
    // compactIndex writes `keep → map<toU32>` twice (for the scan and the
    // reduce): it is computed once.
    check!(
        r#"
        use "prelude.dpp"
        pipeline p {
            values = iota(10)
            keep   = map<lt>(values, fill(10, 4))
            out kept = gather(compactIndex(keep), values)
        }
        "#,
        @"
    op values = iota(10)
    op %2 = fill(10, 4)
    op keep = map<lt>(values, %2)
    let dense: float = 1.0
    op %6 = map<toU32>(keep)
    op %7 = reduce<add>(%6)
    let n: int = %7
    op at = iota(0)
    if n > 0 {
      if float(n) < (dense * float(len(keep))) {
        op slot = exclusiveScan<add>(%6)
        op %14 = iota(len(keep))
        op at = scatter(slot, %14, len: n, mask: keep)
      } else {
        op at = iota(len(keep))
      }
    }
    op kept = gather(at, values)
    out kept = kept
    ---
    kept = [0, 1, 2, 3]
    "
    );
}

#[test]
fn the_same_op_on_the_same_values_is_computed_once() {
    // Generators, maps, reductions and scatters alike; a host expression that
    // read the dropped reduce reads the kept one.
    check!(
        r#"
        param n = 5
        pipeline p {
            a = iota(n)
            b = iota(n)
            x = map<mul>(a, a)
            y = map<mul>(a, b)
            s = reduce<add>(x)
            t = reduce<add>(y)
            i = scatter(a, x, len: n)
            j = scatter(b, y, len: n)
            out sum = s + t
            out i
            out j
        }
        "#,
        @"
    let n: int = 5
    op a = iota(n)
    op x = map<mul>(a, a)
    op %9 = reduce<add>(x)
    let s: int = %9
    let t: int = %9
    op i = scatter(a, x, len: n)
    let sum: int = s + t
    out sum = sum
    out i = i
    out j = i
    ---
    sum = 60
    i = [0, 1, 4, 9, 16]
    j = [0, 1, 4, 9, 16]
    "
    );
}

#[test]
fn different_functors_arguments_or_order_are_not_merged() {
    check!(
        r#"
        param n = 4
        pipeline p {
            a = iota(n)
            b = fill(n, 1)
            out plus   = map<add>(a, b)
            out swap   = map<add>(b, a)
            out minus  = map<sub>(a, b)
            out seeded = map<hash>(a, seed: 1)
            out other  = map<hash>(a, seed: 2)
            out short  = scatter(a, b, len: n)
            out long   = scatter(a, b, len: n + 1)
        }
        "#,
        @"
    let n: int = 4
    op a = iota(n)
    op b = fill(n, 1)
    op plus = map<add>(a, b)
    out plus = plus
    op swap = map<add>(b, a)
    out swap = swap
    op minus = map<sub>(a, b)
    out minus = minus
    op seeded = map<hash>(a, seed: 1)
    out seeded = seeded
    op other = map<hash>(a, seed: 2)
    out other = other
    op short = scatter(a, b, len: n)
    out short = short
    op long = scatter(a, b, len: n + 1)
    out long = long
    ---
    plus = [1, 2, 3, 4]
    swap = [1, 2, 3, 4]
    minus = [4294967295, 0, 1, 2]
    seeded = [3911864714, 2979142878, 3752912895, 2231463006]
    other = [2047839475, 2112726488, 3056950591, 1164873718]
    short = [1, 1, 1, 1]
    long = [1, 1, 1, 1, 0]
    "
    );
}

#[test]
fn an_input_rebound_in_between_prevents_merging() {
    // `x` and `s` are slots: the second `map<add>(x, x)` and `fill(4, s)` read
    // newer values than the first.
    check!(
        r#"
        pipeline p {
            x = iota(4)
            s = 1
            for i in 0..1 {
                a = map<add>(x, x)
                f = fill(4, s)
                x = map<mul>(x, x)
                s = s + 1
                b = map<add>(x, x)
                g = fill(4, s)
                out a
                out b
                out f
                out g
            }
        }
        "#,
        @"
    op x = iota(4)
    let s: int = 1
    for i in 0..1 {
      op a = map<add>(x, x)
      op f = fill(4, s)
      op x = map<mul>(x, x)
      let s: int = s + 1
      op b = map<add>(x, x)
      op g = fill(4, s)
      out a = a
      out b = b
      out f = f
      out g = g
    }
    ---
    a = [0, 2, 4, 6]
    b = [0, 2, 8, 18]
    f = [1, 1, 1, 1]
    g = [2, 2, 2, 2]
    "
    );
}

#[test]
fn ops_around_a_loop_that_rewrites_an_input_are_not_merged() {
    // The loop rewrites `x`, not `y`: after it only `map<mul>(y, y)` may reuse
    // the value computed before it.
    check!(
        r#"
        pipeline p {
            x = iota(4)
            y = iota(4) → map<add>(fill(4, 1))
            before  = map<add>(x, x)
            squared = map<mul>(y, y)
            for i in 0..2 { x = map<add>(x, y) }
            out after   = map<add>(x, x)
            out again   = map<mul>(y, y)
            out before
            out squared
        }
        "#,
        @"
    op x = iota(4)
    op %2 = iota(4)
    op %3 = fill(4, 1)
    op y = map<add>(%2, %3)
    op before = map<add>(x, x)
    op squared = map<mul>(y, y)
    for i in 0..2 {
      op x = map<add>(x, y)
    }
    op after = map<add>(x, x)
    out after = after
    out again = squared
    out before = before
    out squared = squared
    ---
    after = [4, 10, 16, 22]
    again = [1, 4, 9, 16]
    before = [0, 2, 4, 6]
    squared = [1, 4, 9, 16]
    "
    );
}

#[test]
fn a_loop_body_is_its_own_block() {
    // Inside the loop, the body's duplicates merge; each iteration computes
    // them afresh from the slot's current value.
    check!(
        r#"
        pipeline p {
            x = iota(4)
            for i in 0..3 {
                a = map<add>(x, fill(4, 1))
                b = map<add>(x, fill(4, 1))
                x = map<add>(a, b)
            }
            out x
        }
        "#,
        @"
    op x = iota(4)
    for i in 0..3 {
      op %3 = fill(4, 1)
      op a = map<add>(x, %3)
      op x = map<add>(a, a)
    }
    out x = x
    ---
    x = [14, 22, 30, 38]
    "
    );
}

#[test]
fn duplicates_inside_a_branch_merge() {
    check!(
        r#"
        param on = true
        pipeline p {
            x = iota(4)
            r = x
            if on {
                a = map<mul>(x, x)
                b = map<mul>(x, x)
                r = map<add>(a, b)
            } else {
                r = map<mul>(x, x)
            }
            out r
        }
        "#,
        @"
    let on: bool = true
    op x = iota(4)
    let r = x
    if on {
      op a = map<mul>(x, x)
      op r = map<add>(a, a)
    } else {
      op r = map<mul>(x, x)
    }
    out r = r
    ---
    r = [0, 2, 8, 18]
    "
    );
}

#[test]
fn a_reused_result_is_not_a_slot_rewritten_later() {
    // In the branch `a` is the outer slot; `c` would reuse it, but `a` is
    // rewritten before `c` is read, so `c` must keep its own value.
    check!(
        r#"
        param on = true
        pipeline p {
            x = iota(4)
            a = iota(4)
            if on {
                a = map<add>(x, x)
                c = map<add>(x, x)
                a = map<mul>(a, a)
                out r = c
            }
            out a
        }
        "#,
        @"
    let on: bool = true
    op x = iota(4)
    op a = iota(4)
    if on {
      op a = map<add>(x, x)
      op c = map<add>(x, x)
      op a = map<mul>(a, a)
      let r = c
      out r = r
    }
    out a = a
    ---
    r = [0, 2, 4, 6]
    a = [0, 4, 16, 36]
    "
    );
}

#[test]
fn fn_calls_with_the_same_arguments_share_their_ops() {
    // Each call is inlined; the second call's ops repeat the first's.
    check!(
        r#"
        fn norm(v) { return map<mul>(v, v) → reduce<add> }
        pipeline p {
            a = iota(3)
            out first  = norm(a)
            out second = norm(a) + norm(map<add>(a, a))
        }
        "#,
        @"
    op a = iota(3)
    op %2 = map<mul>(a, a)
    op %3 = reduce<add>(%2)
    let first: int = %3
    out first = first
    op %7 = map<add>(a, a)
    op %8 = map<mul>(%7, %7)
    op %9 = reduce<add>(%8)
    let second: int = %3 + %9
    out second = second
    ---
    first = 5
    second = 25
    "
    );
}

/// docs/language.md §6: an op that applies the same primitive to the same
/// values as an earlier one is computed once. Nested blocks see what their
/// enclosing block computed before them: an op inside a branch reuses the same
/// op computed before the branch.
#[test]
fn an_op_in_a_branch_reuses_the_same_op_before_it() {
    let text = report(
        r#"
        param on = true
        pipeline p {
            x = iota(4)
            a = map<mul>(x, x)
            r = a
            if on { r = map<mul>(x, x) → map<add>(a) }
            out r
        }
        "#,
    );
    assert_eq!(text.matches("map<mul>").count(), 1, "{text}");
}
