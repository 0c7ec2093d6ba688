//! Pass 4, `typecheck`: the type and symbolic length of every variable, op
//! arguments against functor signatures (type variables bound per call),
//! record fields, host expression types, and length mismatches that are
//! certain at compile time.
//!
//! `check!(source, @"…")` compiles `source` and shows every typed variable of
//! the plan (`name: type, len = …` for arrays), then each stage's index space;
//! or every diagnostic, one per line.

use crate::common::{check, diagnostics_text, trim_indent};
use dpp_runtime::compile::ir::{node_reads, node_writes, walk_nodes, Plan, VarType};
use dpp_runtime::compile::plan_text::host_text;
use dpp_runtime::cpu::column_pool::ColumnPool;
use dpp_runtime::cpu::exec::{run_plan, RunContext};
use dpp_runtime::*;
use std::path::Path;

fn library() -> FunctorLibrary {
    let mut library = crate::common::library_with_pairs();
    library.uniforms.declare("camera", "pixels", HostType::Int);
    library.uniforms.declare("camera", "fov", HostType::Float);
    library
}

fn compile(source: &str, library: &FunctorLibrary) -> Result<Plan, CompileFailure> {
    let path = Path::new("typecheck.dpp");
    crate::common::compile(path, &trim_indent(source), library, true)
}

/// The typed variables and the stages' index spaces, or the diagnostics.
fn report(source: &str) -> String {
    let library = library();
    let plan = match compile(source, &library) {
        Ok(plan) => plan,
        Err(failure) => return diagnostics_text(&failure),
    };
    // The variables the plan reads or writes (not those CSE or lowering dropped).
    let mut used = vec![false; plan.vars.len()];
    walk_nodes(&plan.body, &mut |node| {
        for v in node_reads(node).into_iter().chain(node_writes(node)) {
            used[v.0 as usize] = true;
        }
    });
    let mut text = String::new();
    for (info, _) in plan.vars.iter().zip(&used).filter(|(_, used)| **used) {
        match info.ty {
            // Temporaries that lowering renamed away are never typed.
            VarType::Unknown => {}
            VarType::Host(ty) => text.push_str(&format!("{}: {ty}\n", info.name)),
            VarType::Array(ty) => {
                let len = info
                    .len
                    .as_ref()
                    .map_or("?".to_string(), |l| host_text(l, &plan));
                let ty = ty.name(&library.records);
                text.push_str(&format!("{}: {ty}, len = {len}\n", info.name));
            }
        }
    }
    text.push_str("---\n");
    for stage in plan.stages() {
        let over = stage
            .index_space
            .as_ref()
            .map_or("?".to_string(), |l| host_text(l, &plan));
        text.push_str(&format!("[{}] over {over}\n", stage.label()));
    }
    text
}

#[test]
fn type_variables_are_bound_at_each_call() {
    // `add(a: T0, b: T0) -> T0`: u32 at one call, f32 at the next; `select`'s
    // T0 admits any type, records included; `toF32` has an exact output.
    check!(
        r#"
        pipeline p {
            ints   = map<add>(iota(4), iota(4))
            floats = map<toF32>(ints) → map<add>(fill(4, 0.5))
            pairs  = map<makePair>(ints)
            picked = map<select>(map<lt>(ints, fill(4, 2)), pairs, pairs)
            out ints
            out floats
            out picked
        }
        "#,
        @"
    %0: u32, len = 4
    ints: u32, len = 4
    %4: f32, len = 4
    %5: f32, len = 4
    floats: f32, len = 4
    pairs: Pair, len = 4
    %10: u32, len = 4
    %11: bool, len = 4
    picked: Pair, len = 4
    ---
    [iota → map<add> → map<toF32> → fill → map<add> → map<makePair> → fill → map<lt> → map<select>] over 4
    "
    );
}

#[test]
fn arguments_that_do_not_fit_the_signature() {
    check!(
        r#"
        pipeline p {
            ints   = iota(4)
            floats = map<toF32>(ints)
            a = map<add>(ints, floats)
            b = map<add>(map<makePair>(ints), map<makePair>(ints))
            c = map<not>(ints)
            d = map<makePair>(floats)
            e = map<select>(ints, floats, floats)
            f = map<hash>(ints, seed: 1.5)
        }
        "#,
        @"
    dpp::type-mismatch at 4:9 `map<add>(ints, floats)`: argument 2 (`b`) of `add` must be u32, found f32
      help: signature: monoid add   add(a: T0:numeric, b: T0:numeric) -> (out: T0:numeric)
    dpp::type-mismatch at 5:9 `map<add>(map<makePair>(ints), map<makePair>(ints))`: argument 1 (`a`) of `add` must be numeric, found Pair
      help: signature: monoid add   add(a: T0:numeric, b: T0:numeric) -> (out: T0:numeric)
    dpp::type-mismatch at 6:9 `map<not>(ints)`: argument 1 (`x`) of `not` must be bool, found u32
      help: signature: map          not(x: bool) -> (out: bool)
    dpp::type-mismatch at 7:9 `map<makePair>(floats)`: argument 1 (`x`) of `makePair` must be u32, found f32
      help: signature: map          makePair(x: u32) -> (pair: Pair)
    dpp::type-mismatch at 8:9 `map<select>(ints, floats, floats)`: argument 1 (`cond`) of `select` must be bool, found u32
      help: signature: map          select(cond: bool, a: T0, b: T0) -> (out: T0)
    dpp::type-mismatch at 9:9 `map<hash>(ints, seed: 1.5)`: argument `seed` must be int, found float
    "
    );
}

#[test]
fn record_fields_have_the_fields_types_and_the_records_length() {
    check!(
        r#"
        param n = 5
        pipeline p {
            pairs = iota(n) → map<makePair>
            out a = pairs.a
            out b = map<add>(pairs.b, pairs.b)
        }
        "#,
        @r"
    n: int
    %1: u32, len = n
    pairs: Pair, len = n
    b: f32, len = n
    a: u32, len = n
    pairs.b: f32, len = n
    ---
    [iota → map<makePair> → .a → .b → map<add>] over n
    "
    );
}

#[test]
fn unknown_fields() {
    check!(
        r#"
        pipeline p {
            pairs = iota(3) → map<makePair>
            x = pairs.c
            y = pairs.bb
            z = iota(3).a
            w = camera.width
        }
        "#,
        @"
    dpp::unknown-field at 6:16 `width`: `camera` has no field `width`
    dpp::unknown-field at 3:15 `c`: `Pair` has no field `c`
      help: its fields: a, b
    dpp::unknown-field at 4:15 `bb`: `Pair` has no field `bb`
      help: did you mean `b`?
    dpp::type-mismatch at 5:17 `a`: `.a`: an array of u32 has no fields
    "
    );
}

#[test]
fn generators_and_reductions() {
    check!(
        r#"
        pipeline p {
            ones   = fill(3, 1)
            halves = fill(3, 0.5)
            flags  = fill(3, true)
            colors = fill(3, vec3(0))
            out count  = reduce<add>(ones)
            out total  = reduce<add>(halves)
            out any    = reduce<or>(flags)
            out lowest = reduce<min>(colors)
            out prefix = exclusiveScan<max>(halves, segments: flags)
        }
        "#,
        @"
    ones: u32, len = 3
    halves: f32, len = 3
    flags: bool, len = 3
    colors: vec3, len = 3
    %8: int
    count: int
    %10: float
    total: float
    %12: bool
    any: bool
    %14: vec3
    lowest: vec3
    prefix: f32, len = 3
    ---
    [fill → fill → fill → fill → reduce<add>] over 3
    [reduce<add>] over 3
    [reduce<or>] over 3
    [reduce<min>] over 3
    [exclusiveScan<max>] over 3
    "
    );
}

#[test]
fn primitive_rules() {
    check!(
        r#"
        pipeline p {
            ints   = iota(3)
            floats = fill(3, 1.0)
            flags  = fill(3, true)
            a = gather(floats, ints)
            b = scatter(floats, ints, len: 3)
            c = scatter(ints, ints, mask: ints, len: 3)
            d = scatter(ints, floats, into: ints)
            e = reduce<add>(flags)
            f = scan<or>(ints)
            g = scan<add>(ints, segments: floats)
            h = scatter<min>(ints, flags, into: flags)
        }
        "#,
        @"
    dpp::type-mismatch at 5:9 `gather(floats, ints)`: `gather` indices must be u32, found f32
    dpp::type-mismatch at 6:9 `scatter(floats, ints, len: 3)`: `scatter` indices must be u32, found f32
    dpp::type-mismatch at 7:9 `scatter(ints, ints, mask: ints, len: 3)`: `mask` must be an array of bool
    dpp::type-mismatch at 8:9 `scatter(ints, floats, into: ints)`: `into` must have the element type of the scattered values (f32), found array of u32
    dpp::type-mismatch at 9:9 `reduce<add>(flags)`: `add` cannot combine bool
    dpp::type-mismatch at 10:9 `scan<or>(ints)`: `or` cannot combine u32
    dpp::type-mismatch at 11:9 `scan<add>(ints, segments: floats)`: `segments` must be an array of bool
    dpp::type-mismatch at 12:9 `scatter<min>(ints, flags, into: flags)`: `min` cannot combine bool
    "
    );
}

#[test]
fn host_expression_types() {
    // int op int stays int (`/` too); a float operand makes a float;
    // comparisons give bools; vec constructors take 1 or N numbers.
    check!(
        r#"
        param n = 4
        pipeline p {
            a = 1 + 2
            b = 1 + 2.0
            c = 7 / 2
            d = 7 % 2.0
            e = 1 < 2.5
            f = n == 4.0
            g = !(a > 1) || e && true
            h = vec3(1, 2.5, n)
            i = vec2(1) * 2
            j = -vec4(1, 2, 3, 4) / 2.0
            k = min(1, 2.5)
            l = max(n, 3)
            m = floor(2.5) + ceil(0.5)
            o = sqrt(n) + abs(-3)
            q = camera.pixels * camera.fov
            r = len(iota(n)) * 2
            out all = fill(a + c + l + m, h * b)
            out flags = fill(n, g != f)
        }
        "#,
        @"
    n: int
    a: int
    b: float
    c: int
    d: float
    e: bool
    f: bool
    g: bool
    h: vec3
    i: vec2
    j: vec4
    k: float
    l: int
    m: int
    o: float
    q: float
    %16: u32, len = n
    r: int
    all: vec3, len = ((a + c) + l) + m
    flags: bool, len = n
    ---
    [iota] over n
    [fill] over n
    [fill] over ((a + c) + l) + m
    "
    );
}

#[test]
fn host_expression_type_errors() {
    check!(
        r#"
        pipeline p {
            a = vec2(1, 2, 3)
            b = true + 1
            c = vec3(1) + vec2(1)
            d = vec3(1) < 1
            e = 1 && true
            f = !1
            g = -true
            h = vec3(1) % 2
            i = min(vec2(1), 2)
            for i in 0..2.5 { }
            if 1 { }
            while n { }
            x = iota(1.5)
        }
        "#,
        @"
    dpp::unknown-name at 13:11 `n`: unknown name `n`
    dpp::type-mismatch at 2:5 `a`: `vec2` takes 1 or 2 numbers
    dpp::type-mismatch at 3:5 `b`: `+` cannot combine bool and int
    dpp::type-mismatch at 4:5 `c`: `+` cannot combine vec3 and vec2
    dpp::type-mismatch at 5:5 `d`: `<` compares numbers, found vec3 and int
    dpp::type-mismatch at 6:5 `e`: `&&` needs bools, found int and bool
    dpp::type-mismatch at 7:5 `f`: `!` needs a bool, found int
    dpp::type-mismatch at 8:5 `g`: cannot negate a bool
    dpp::type-mismatch at 9:5 `h`: `%` cannot combine vec3 and int
    dpp::type-mismatch at 10:5 `i`: `min` takes 2 numbers
    dpp::type-mismatch at 11:5 `for i in 0..2.5 { }`: a loop bound must be int, found float
    dpp::type-mismatch at 12:5 `if 1 { }`: a condition must be bool, found int
    dpp::type-mismatch at 14:9 `iota`: a length must be int, found float
    "
    );
}

#[test]
fn an_operand_in_error_is_reported_once() {
    // An unknown name or an array where a scalar belongs is one error, not
    // also a type mismatch of the expression around it.
    check!(
        r#"
        pipeline p {
            x = iota(3)
            if flag { }
            while 1 < missing { }
            if x { }
            y = fill(3, x)
            out z = fill(len(x), y + 1 > 2)
        }
        "#,
        @"
            dpp::unknown-name at 3:8 `flag`: unknown name `flag`
            dpp::unknown-name at 4:15 `missing`: unknown name `missing`
            dpp::expected-scalar at 5:8 `x`: expected a host scalar, found an array
              help: arrays become scalars through `reduce<f>(a)` or `len(a)`
            dpp::expected-scalar at 6:17 `x`: expected a host scalar, found an array
            dpp::expected-scalar at 7:26 `y + 1 > 2`: expected a host scalar, found an array
        "
    );
}

#[test]
fn symbolic_lengths_of_fan_out_group_gather_and_compaction() {
    // A fan-out multiplies the length, a group gather divides it, a gather
    // takes its indices' length, a scatter its `len:` or its `into:` array's.
    check!(
        r#"
        param n = 6
        param k = 3
        pipeline p {
            a = iota(n * k) → map<toF32>
            g = gather<sum>(a, group: k)
            e = scatter<repeat>(g, fanout: k)
            keep = map<lt>(e, fill(len(e), 2.5))
            kept = gather(compactIndex(keep), e)
            s = scatter(iota(n), g, len: n + 1)
            t = scatter<add>(iota(n), g, into: fill(n * 2, 0.0))
            out kept
            out s
            out t
        }
        fn compactIndex(keep) {
            slot = keep → map<toU32> → exclusiveScan<add>
            count = reduce<add>(keep → map<toU32>)
            return scatter(slot, iota(len(keep)), mask: keep, len: count)
        }
        "#,
        @"
    n: int
    k: int
    %2: u32, len = n * k
    a: f32, len = n * k
    g: f32, len = (n * k) / k
    e: f32, len = ((n * k) / k) * k
    %9: f32, len = len(e)
    keep: bool, len = ((n * k) / k) * k
    %12: u32, len = ((n * k) / k) * k
    slot: u32, len = ((n * k) / k) * k
    %16: int
    count: int
    %18: u32, len = len(keep)
    %19: u32, len = count
    kept: f32, len = count
    %22: u32, len = n
    s: f32, len = n + 1
    %26: f32, len = n * 2
    t: f32, len = n * 2
    ---
    [iota → map<toF32> → gather<sum>] over n
    [scatter<repeat> → fill → map<lt> → map<toU32> → exclusiveScan<add>] over n * k
    [reduce<add>] over n * k
    [iota → scatter] over n * k
    [iota → scatter] over n
    [gather] over count
    [fill] over n * 2
    [scatter<add>] over n
    "
    );
}

#[test]
fn a_slot_written_in_a_loop_has_its_own_length() {
    // `x` has two definitions, so its length is only `len(x)`; a value made
    // from it inherits that.
    check!(
        r#"
        pipeline p {
            x = iota(8)
            for i in 0..2 {
                x = gather(iota(len(x) / 2), x)
                y = map<add>(x, x)
                out y
            }
            out x
        }
        "#,
        @"
    x: u32, len = len(x)
    i: int
    %3: u32, len = len(x) / 2
    y: u32, len = len(x)
    ---
    [iota] over 8
    [iota → gather] over len(x) / 2
    [map<add>] over len(x)
    "
    );
}

#[test]
fn a_rebound_name_keeps_its_type() {
    check!(
        r#"
        pipeline p {
            x = iota(3)
            s = 0
            for i in 0..2 {
                x = map<toF32>(x)
                s = s + 0.5
            }
        }
        "#,
        @"
    dpp::type-mismatch at 5:13 `map<toF32>(x)`: `x` is array of u32 elsewhere but array of f32 here; a name rebound in a loop or branch keeps its type
      2:5 `x`: first bound here
    dpp::type-mismatch at 6:9 `s`: `s` is host int elsewhere but host float here; a name rebound in a loop or branch keeps its type
      3:5 `s`: first bound here
    "
    );
}

#[test]
fn lengths_that_fold_to_different_constants_are_an_error() {
    check!(
        r#"
        pipeline p {
            a = map<add>(iota(4), iota(5))
            b = map<add>(iota(2 * 2), fill(4, 1))
            c = scatter(iota(4), iota(3), len: 4)
            d = scatter(iota(4), iota(4), mask: fill(2 + 1, true), len: 4)
            e = scan<add>(iota(4), segments: fill(6 - 1, true))
        }
        "#,
        @"
    dpp::length-mismatch at 2:9 `map<add>(iota(4), iota(5))`: length mismatch: `%0` has 4 elements but `%1` has 5
    dpp::length-mismatch at 4:9 `scatter(iota(4), iota(3), len: 4)`: length mismatch: `%8` has 4 elements but `%9` has 3
    dpp::length-mismatch at 5:9 `scatter(iota(4), iota(4), mask: fill(2 + 1, true), len: 4)`: length mismatch: `%12` has 4 elements but `%14` has 3
    dpp::length-mismatch at 6:9 `scan<add>(iota(4), segments: fill(6 - 1, true))`: length mismatch: `%17` has 4 elements but `%18` has 5
    "
    );
}

#[test]
fn lengths_that_do_not_fold_are_checked_when_the_plan_runs() {
    // `n` is a param, so `iota(n)` has no constant length here: the mismatch
    // is left to the run, which reports it clearly.
    let source = r#"
        param n = 4
        pipeline p {
            out a = map<add>(iota(n), iota(5))
        }
        "#;
    check!(source, @"
    n: int
    %1: u32, len = n
    %2: u32, len = 5
    a: u32, len = n
    ---
    [iota] over 5
    [iota → map<add>] over n
    ");
    let library = library();
    let uniforms = Uniforms::default();
    let context = RunContext {
        library: &library,
        uniforms: &uniforms,
        resources: &(),
        chunk: 64,
        column_pool: &ColumnPool::new(),
        elementwise: dpp_runtime::cpu::compiled::Elementwise::default(),
    };
    let error = run_plan(&compile(source, &library).unwrap(), &context).unwrap_err();
    insta::assert_snapshot!(error.message, @"stage 2 [iota → map<add>]: length mismatch: `%2` has 5 elements, but the stage runs over 4");
}
