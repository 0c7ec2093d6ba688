//! Pass 3, `lower`: the AST becomes plan ops with names resolved to variable
//! slots, fns inlined at each call and `→` chains desugared into leading
//! arguments; misplaced `break` and `return` are reported here.
//!
//! `check!(source, @"…")` shows the lowered nodes (before type checking, so
//! variables carry no types yet) or every diagnostic of the whole compiler,
//! one per line. A program that compiles is also RUN, fused and unfused (the
//! two must agree), and its outputs are listed after the nodes.

use crate::common::{check, compile, diagnostics_text, ops_text, plan, run, trim_indent};
use dpp_runtime::compile::{load, lower, resolve};
use dpp_runtime::*;
use std::path::Path;
use std::sync::Arc;

/// `split(x: u32) -> (lo: u32, hi: u32)`: `lo = x % 4`, `hi = x / 4`; the
/// generic library has no functor with two outputs.
struct Split {
    signature: Signature,
}

impl Functor for Split {
    fn signature(&self) -> &Signature {
        &self.signature
    }

    fn run_cpu(
        &self,
        _: &CallContext<'_>,
        inputs: &[ColumnView<'_>],
        outputs: &mut [Column],
    ) -> Result<(), FunctorError> {
        let x = inputs[0].as_u32();
        outputs[0] = Column::U32(x.iter().map(|v| v % 4).collect());
        outputs[1] = Column::U32(x.iter().map(|v| v / 4).collect());
        Ok(())
    }
}

fn library() -> FunctorLibrary {
    let mut library = crate::common::library();
    library.register(Arc::new(Split {
        signature: Signature::map("split")
            .input("x", ElemType::U32)
            .output("lo", ElemType::U32)
            .output("hi", ElemType::U32)
            .doc("x % 4 and x / 4"),
    }));
    library
}

/// Lowers `source`; returns the lowered nodes and the run's outputs, or the diagnostics.
fn report(source: &str) -> String {
    let source = trim_indent(source);
    let library = library();
    let path = Path::new("lower.dpp");
    let compiled = |fuse| compile(path, &source, &library, fuse);
    let fused = match compiled(true) {
        Ok(plan) => plan,
        Err(failure) => return diagnostics_text(&failure),
    };

    // Passes 1–3 on their own, to show lowering's output.
    let mut sources = dpp_dsl::SourceMap::default();
    let mut diagnostics = Vec::new();
    let loaded = load::load_program(path, Some(source.clone()), &mut sources, &mut diagnostics)
        .expect("the source text is given");
    let records: Vec<&str> = Vec::new();
    let program = resolve::resolve_program(&loaded, &records, &mut diagnostics).unwrap();
    let lowered = lower::lower_program(&program, &library, &mut diagnostics);
    assert!(diagnostics.is_empty(), "{diagnostics:?}");
    let plan = plan(
        &program.pipeline.name.name,
        lowered.vars,
        lowered.body,
        lowered.outputs,
    );
    let mut text = ops_text(&plan, &library);

    let outputs = run(&fused, &library);
    let unfused = run(&compiled(false).unwrap(), &library);
    assert_eq!(outputs, unfused, "fused and unfused runs differ");
    text.push_str("---\n");
    match outputs {
        Ok(outputs) => text.push_str(&outputs),
        Err(message) => text.push_str(&format!("run-time error: {message}\n")),
    }
    text
}

#[test]
fn a_name_rebound_in_a_loop_is_the_same_slot() {
    // Outside the loop `x` is rebound in the same block: a fresh `x#1`. Inside,
    // `x = …` updates that slot; `y` is the loop's own, and rebinding it there
    // gives `y#1`.
    check!(
        r#"
        pipeline p {
            x = iota(4)
            x = map<add>(x, x)
            for i in 0..2 {
                x = map<add>(x, x)
                y = map<add>(x, fill(4, 1))
                y = map<mul>(y, y)
                out last = y
            }
            out x
        }
        "#,
        @"
    op x = iota(4)
    op x#1 = map<add>(x, x)
    for i in 0..2 {
      op x#1 = map<add>(x#1, x#1)
      op %6 = fill(4, 1)
      op y = map<add>(x#1, %6)
      op y#1 = map<mul>(y, y)
      let last = y#1
      out last = last
    }
    out x = x#1
    ---
    last = [1, 81, 289, 625]
    x = [0, 8, 16, 24]
    "
    );
}

#[test]
fn branches_write_the_slot_of_an_outer_name() {
    check!(
        r#"
        param big = true
        pipeline p {
            total = 0
            x = iota(3)
            if big {
                x = map<mul>(x, fill(3, 10))
                total = total + 1
            } else {
                x = map<add>(x, x)
            }
            while total < 4 { total = total + len(x) }
            out x
            out total
        }
        "#,
        @"
    let big = true
    let total = 0
    op x = iota(3)
    if big {
      op %4 = fill(3, 10)
      op x = map<mul>(x, %4)
      let total = total + 1
    } else {
      op x = map<add>(x, x)
    }
    while total < 4 {
      let total = total + len(x)
    }
    out x = x
    out total = total
    ---
    x = [0, 10, 20]
    total = 4
    "
    );
}

#[test]
fn a_name_bound_in_a_block_is_not_seen_after_it() {
    check!(
        r#"
        pipeline p {
            for i in 0..2 { inner = iota(2) }
            out r = inner
        }
        "#,
        @"dpp::unknown-name at 3:13 `inner`: unknown name `inner`"
    );
}

#[test]
fn fns_are_inlined_with_their_arguments() {
    // An array argument shares the caller's slot; a host argument that is not
    // a plain variable is bound to the parameter's own variable.
    check!(
        r#"
        param n = 4
        fn axpy(a, x, y) {
            ax = map<mul>(fill(len(x), a), x)
            return map<add>(ax, y)
        }
        pipeline p {
            x = iota(n)
            out r = axpy(n + 1, x, x)
            out s = axpy(n, x, r)
        }
        "#,
        @"
    let n = 4
    op x = iota(n)
    let a = n + 1
    op %4 = fill(len(x), a)
    op ax = map<mul>(%4, x)
    op r = map<add>(ax, x)
    out r = r
    op %9 = fill(len(x), n)
    op ax#1 = map<mul>(%9, x)
    op s = map<add>(ax#1, r)
    out s = s
    ---
    r = [0, 6, 12, 18]
    s = [0, 10, 20, 30]
    "
    );
}

#[test]
fn fn_names_shadow_params() {
    // The parameter `n` shadows the param `n`; rebinding it at the fn's top
    // level gives a fresh `n#…`, and the param keeps its value.
    check!(
        r#"
        param n = 4
        fn own(n) {
            k = n * 2
            n = k + 1
            return iota(n)
        }
        fn local(a) {
            n = len(a) + 1
            return fill(n, 7)
        }
        pipeline p {
            out r = own(2)
            out s = local(iota(n))
            out t = iota(n)
        }
        "#,
        @"
    let n = 4
    let n#1 = 2
    let k = n#1 * 2
    let n#2 = k + 1
    op r = iota(n#2)
    out r = r
    op %6 = iota(n)
    let n#3 = len(%6) + 1
    op s = fill(n#3, 7)
    out s = s
    op t = iota(n)
    out t = t
    ---
    r = [0, 1, 2, 3, 4]
    s = [7, 7, 7, 7, 7]
    t = [0, 1, 2, 3]
    "
    );
}

#[test]
fn a_fn_does_not_see_the_callers_names() {
    check!(
        r#"
        fn peek(a) { return map<add>(a, hidden) }
        pipeline p {
            hidden = iota(4)
            out s = peek(hidden)
        }
        "#,
        @"dpp::unknown-name at 1:33 `hidden`: unknown name `hidden`"
    );
}

#[test]
fn a_fn_rebinding_its_parameter_in_a_block_leaves_the_caller_alone() {
    // `a` and `s` are rebound inside a branch or loop of the fn: they get their
    // own slots, copied from the arguments, so `x` and `t` keep their values.
    check!(
        r#"
        param on = true
        fn bump(a) {
            if on { a = map<add>(a, a) }
            return a
        }
        fn count(s) {
            for i in 0..3 { s = s + 1 }
            return s
        }
        pipeline p {
            x = iota(4)
            t = 10
            out y = bump(x)
            out u = count(t)
            out x
            out t
        }
        "#,
        @"
    let on = true
    op x = iota(4)
    let t = 10
    let a = x
    if on {
      op a = map<add>(a, a)
    }
    let y = a
    out y = y
    let s = t
    for i in 0..3 {
      let s = s + 1
    }
    let u = s
    out u = u
    out x = x
    out t = t
    ---
    y = [0, 2, 4, 6]
    u = 13
    x = [0, 1, 2, 3]
    t = 10
    "
    );
}

#[test]
fn a_fn_result_rewritten_in_a_block_is_returned_whole() {
    // `s` is bound, then overwritten in a branch without being read: the call
    // must return the branch's value, not the first one.
    check!(
        r#"
        param on = true
        fn pick(a) {
            s = map<add>(a, a)
            if on { s = map<mul>(a, a) }
            return s
        }
        pipeline p {
            out r = pick(iota(4))
        }
        "#,
        @"
    let on = true
    op %1 = iota(4)
    op s = map<add>(%1, %1)
    if on {
      op s = map<mul>(%1, %1)
    }
    let r = s
    out r = r
    ---
    r = [0, 1, 4, 9]
    "
    );
}

#[test]
fn a_fn_result_bound_to_a_slot_does_not_change_later_reads_of_it() {
    // In the loop `x = f(x)` writes the slot `x`; `sq` is computed in the fn
    // after the returned value, from the argument's old value.
    check!(
        r#"
        fn f(a) {
            b = map<add>(a, a)
            out sq = map<mul>(a, a)
            return b
        }
        pipeline p {
            x = iota(4)
            for i in 0..1 { x = f(x) }
            out x
        }
        "#,
        @"
    op x = iota(4)
    for i in 0..1 {
      op b = map<add>(x, x)
      op sq = map<mul>(x, x)
      out sq = sq
      let x = b
    }
    out x = x
    ---
    sq = [0, 1, 4, 9]
    x = [0, 2, 4, 6]
    "
    );
}

#[test]
fn chains_feed_every_output_of_a_multi_output_map() {
    check!(
        r#"
        pipeline p {
            x = iota(6)
            out sum = x → map<split> → map<add>
            (lo, hi) = x → map<split>
            out lo
            out hi
            out plus = lo -> map<add>(hi) → map<add>(fill(6, 100))
        }
        "#,
        @"
    op x = iota(6)
    op (%2, %3) = map<split>(x)
    op sum = map<add>(%2, %3)
    out sum = sum
    op (lo, hi) = map<split>(x)
    out lo = lo
    out hi = hi
    op %10 = map<add>(lo, hi)
    op %11 = fill(6, 100)
    op plus = map<add>(%10, %11)
    out plus = plus
    ---
    sum = [0, 1, 2, 3, 1, 2]
    lo = [0, 1, 2, 3, 0, 1]
    hi = [0, 0, 0, 0, 1, 1]
    plus = [100, 101, 102, 103, 101, 102]
    "
    );
}

#[test]
fn multi_output_arity_errors() {
    check!(
        r#"
        pipeline p {
            x = iota(6)
            one = map<split>(x)
            (a, b, c) = map<split>(x)
            (d, e) = iota(6)
            f = x → map<split> → map<add>(x)
            g = map<add>(map<split>(x), x)
        }
        "#,
        @"
    dpp::arity at 3:5 `one`: this expression has 2 outputs; bind them with `(a, b) = …`
    dpp::arity at 4:6 `a, b, c`: 3 names bound to 2 values
    dpp::arity at 5:6 `d, e`: 2 names bound to one value
    dpp::arity at 6:9 `x → map<split> → map<add>(x)`: `map<add>` takes 2 array arguments, found 3
      help: signature: monoid add   add(a: T0:numeric, b: T0:numeric) -> (out: T0:numeric)
    dpp::arity at 7:18 `map<split>(x)`: expected one array, found 2
    "
    );
}

#[test]
fn out_forms() {
    // `out name = e`, `out name` of a binding, a host scalar output, and one
    // output declared in both branches.
    check!(
        r#"
        param first = false
        pipeline p {
            x = iota(3)
            out doubled = map<add>(x, x)
            out x
            out total = reduce<add>(x)
            if first { out pick = x } else { out pick = doubled }
            out doubled
        }
        "#,
        @"
    let first = false
    op x = iota(3)
    op doubled = map<add>(x, x)
    out doubled = doubled
    out x = x
    op %5 = reduce<add>(x)
    let total = %5
    out total = total
    if first {
      let pick = x
      out pick = pick
    } else {
      let pick#1 = doubled
      out pick = pick#1
    }
    out doubled = doubled
    ---
    doubled = [0, 2, 4]
    x = [0, 1, 2]
    total = 3
    pick = [0, 2, 4]
    "
    );
}

#[test]
fn out_of_an_unknown_name() {
    check!(
        r#"
        pipeline p {
            xs = iota(3)
            out x
        }
        "#,
        @"dpp::unknown-name at 3:9 `x`: unknown name `x`"
    );
}

#[test]
fn break_and_return_placement() {
    check!(
        r#"
        fn early(a) {
            return a
            b = a
            return b
        }
        fn nested(a) {
            for i in 0..2 { return a }
            return a
        }
        fn stop(a) {
            break
            return a
        }
        fn none(a) { b = a }
        pipeline p {
            break
            for i in 0..2 { if true { break } }
            for i in 0..2 { y = stop(iota(2)) }
            out r = early(iota(1))
            out s = nested(iota(1))
            out t = none(iota(1))
            return iota(1)
        }
        "#,
        @"
    dpp::break-outside-loop at 16:5 `break`: `break` outside a loop
    dpp::break-outside-loop at 11:5 `break`: `break` outside a loop
    dpp::return at 2:5 `return a`: `return` must be the last statement of a fn
    dpp::return at 7:21 `return a`: `return` must be at the top level of a fn, not inside a loop or branch
    dpp::return at 14:4 `none`: `none` does not end with `return`
    dpp::return at 22:5 `return iota(1)`: `return` outside a fn
    "
    );
}

/// docs/language.md §5 asks for a diagnostic for every malformed input, each
/// reported once. A fn that is never called is still checked for unknown
/// names, functors and arities, and an error in a fn called twice is reported
/// once.
#[test]
fn every_fn_body_is_checked_once() {
    let text = report(
        r#"
        fn unused(a) { return map<nope>(a) }
        fn twice(a) { return map<add>(a, missing) }
        pipeline p {
            x = iota(2)
            out r = twice(x)
            out s = twice(x)
        }
        "#,
    );
    assert!(text.contains("unknown functor `nope`"), "{text}");
    assert_eq!(text.matches("unknown name `missing`").count(), 1, "{text}");
}
