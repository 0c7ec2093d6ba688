//! Pass 6, `fuse`: ops grouped into stages by the rules of docs/language.md §6.
//!
//! 1. `map → map` over the same index space share a stage; an intermediate
//!    that nothing else reads is not materialised, one read elsewhere is.
//! 2. `gather(idx, src) → map`: the indexed read moves into the consumer.
//! 3. `map → scatter`, `map → reduce`, `map → scan`, `map → sort` run in one stage.
//! 4. Barriers: scan, sort, reduce, a length change, a loop or branch boundary.
//! 5. A group gather of values only its stage reads closes that stage's inner level.
//!
//! `check!(source, @"…")` shows the fused plan's text. It also checks that the
//! unfused plan (`--no-fuse`) has one op per stage and the same ops, and RUNS
//! both: their outputs must be identical, and are listed after the plan.

use crate::common::{check, library, pipelines_path, run_text, trim_indent};
use dpp_runtime::compile::ir::Plan;
use dpp_runtime::compile::plan_text::plan_to_text;
use dpp_runtime::FunctorLibrary;

fn compile(source: &str, fuse: bool, library: &FunctorLibrary) -> Plan {
    crate::common::compile(&pipelines_path("fuse_test.dpp"), source, library, fuse)
        .unwrap_or_else(|e| panic!("{e}"))
}

/// The fused plan's text and the outputs of the fused and unfused runs.
fn report(source: &str) -> String {
    let source = trim_indent(source);
    let library = library();
    let fused = compile(&source, true, &library);
    let unfused = compile(&source, false, &library);

    // `--no-fuse`: one op per stage, the same ops (fusion may run an independent
    // op of another length before a stage, so only the multiset must match).
    let labels = |plan: &Plan| -> Vec<String> {
        let mut labels: Vec<String> = plan
            .stages()
            .iter()
            .flat_map(|s| s.ops.iter().map(|op| op.label()))
            .collect();
        labels.sort();
        labels
    };
    assert!(unfused.stages().iter().all(|s| s.ops.len() == 1));
    assert_eq!(labels(&fused), labels(&unfused));

    let mut text = plan_to_text(&fused, &library);
    let outputs = run_text(&fused, &library);
    let unfused_outputs = run_text(&unfused, &library);
    assert_eq!(
        outputs, unfused_outputs,
        "fused and unfused runs differ\n{text}"
    );
    text.push_str("---\n");
    text.push_str(&outputs);
    text
}

#[test]
fn rule1_a_map_chain_is_one_stage_without_its_intermediates() {
    check!(
        r#"
        param n = 6
        pipeline p {
            a = iota(n) → map<toF32>
            b = map<add>(a, a)
            c = map<mul>(b, b)
            out d = map<sub>(c, b)
        }
        "#,
        @"
    pipeline p (fused, 1 stages)
    param n: int = 6
    let n: int = 6
    stage 1 [iota → map<toF32> → map<add> → map<mul> → map<sub>] {
      over n
      %1 = iota(n)
      a = map<toF32>(%1)
      b = map<add>(a, a)
      c = map<mul>(b, b)
      d = map<sub>(c, b)
      reads direct: -; indexed: -; uniform: n
      materialises d: f32
      ends at control flow
    }
    out d = d
    ---
    d = [0.0, 2.0, 12.0, 30.0, 56.0, 90.0]
    "
    );
}

/// A host value between two maps that reads nothing the stage makes (here
/// a `fn`'s host argument and a param's arithmetic) is computed before the
/// stage and does not end it; one that reads a value the stage makes
/// (`len(b)`) does.
#[test]
fn rule1_a_host_value_of_earlier_values_does_not_end_the_stage() {
    check!(
        r#"
        param n = 6
        fn scaled(a, k) {
            return a * k
        }
        pipeline p {
            a = iota(n) → map<toF32>
            b = scaled(a, 2.0)
            twice = n * 2
            c = b + a * float(twice)
            m = len(b)
            out d = c * float(m)
        }
        "#,
        @"
    pipeline p (fused, 2 stages)
    param n: int = 6
    let n: int = 6
    let k: float = 2.0
    let twice: int = n * 2
    stage 1 [iota → map<toF32> → fill → map<mul> → fill → map<mul> → map<add>] {
      over n
      %1 = iota(n)
      a = map<toF32>(%1)
      %14 = fill(n, k)
      b = map<mul>(a, %14)
      %15 = fill(n, float(twice))
      %8 = map<mul>(a, %15)
      c = map<add>(b, %8)
      reads direct: -; indexed: -; uniform: n, k, twice
      materialises b: f32, c: f32
      ends at control flow
    }
    let m: int = len(b)
    stage 2 [fill → map<mul>] {
      over n
      %16 = fill(n, float(m))
      d = map<mul>(c, %16)
      reads direct: c: f32; indexed: -; uniform: n, m
      materialises d: f32
      ends at control flow
    }
    out d = d
    ---
    d = [0.0, 84.0, 168.0, 252.0, 336.0, 420.0]
    "
    );
}

#[test]
fn rule1_an_intermediate_read_elsewhere_is_materialised() {
    // `b` is read again after the stage ends (at the output): it is
    // materialised; `a` is not.
    check!(
        r#"
        param n = 6
        pipeline p {
            a = iota(n) → map<toF32>
            b = map<add>(a, a)
            out c = map<mul>(b, b)
            out total = reduce<add>(b)
        }
        "#,
        @"
    pipeline p (fused, 1 stages)
    param n: int = 6
    let n: int = 6
    stage 1 [iota → map<toF32> → map<add> → map<mul> → reduce<add>] {
      over n
      %1 = iota(n)
      a = map<toF32>(%1)
      b = map<add>(a, a)
      c = map<mul>(b, b)
      %8 = reduce<add>(b)
      reads direct: -; indexed: -; uniform: n
      materialises c: f32, %8: float
      ends at reduce result read by the host
    }
    out c = c
    let total: float = %8
    out total = total
    ---
    c = [0.0, 4.0, 16.0, 36.0, 64.0, 100.0]
    total = 30.0
    "
    );
}

#[test]
fn rule1_maps_over_different_lengths_do_not_fuse() {
    check!(
        r#"
        pipeline p {
            a = iota(4) → map<toF32>
            b = iota(5) → map<toF32>
            c = map<add>(b, b)
            out a
            out c
        }
        "#,
        @"
    pipeline p (fused, 2 stages)
    stage 1 [iota → map<toF32> → map<add>] {
      over 5
      %3 = iota(5)
      b = map<toF32>(%3)
      c = map<add>(b, b)
      reads direct: -; indexed: -; uniform: -
      materialises c: f32
      ends at control flow
    }
    out c = c
    stage 2 [iota → map<toF32>] {
      over 4
      %0 = iota(4)
      a = map<toF32>(%0)
      reads direct: -; indexed: -; uniform: -
      materialises a: f32
      ends at control flow
    }
    out a = a
    ---
    a = [0.0, 1.0, 2.0, 3.0]
    c = [0.0, 2.0, 4.0, 6.0, 8.0]
    "
    );
}

#[test]
fn rule2_a_gather_moves_into_its_consumer() {
    check!(
        r#"
        param n = 5
        pipeline p {
            src = iota(10) → map<toF32>
            idx = iota(n) → map<add>(fill(n, 3))
            g = gather(idx, src)
            out r = map<mul>(g, g)
        }
        "#,
        @"
    pipeline p (fused, 2 stages)
    param n: int = 5
    let n: int = 5
    stage 1 [iota → map<toF32>] {
      over 10
      %1 = iota(10)
      src = map<toF32>(%1)
      reads direct: -; indexed: -; uniform: -
      materialises src: f32
      ends at length change
    }
    stage 2 [iota → fill → map<add> → gather → map<mul>] {
      over n
      %4 = iota(n)
      %5 = fill(n, 3)
      idx = map<add>(%4, %5)
      g = gather(idx, src)
      r = map<mul>(g, g)
      reads direct: -; indexed: src: f32; uniform: n
      materialises r: f32
      ends at control flow
    }
    out r = r
    ---
    r = [9.0, 16.0, 25.0, 36.0, 49.0]
    "
    );
}

#[test]
fn rule2_a_gather_from_a_value_of_the_same_stage_starts_a_new_one() {
    check!(
        r#"
        param n = 5
        pipeline p {
            a = iota(n) → map<toF32>
            reversed = map<sub>(fill(n, n - 1), iota(n))
            out r = gather(reversed, a) → map<add>(a)
        }
        "#,
        @"
    pipeline p (fused, 2 stages)
    param n: int = 5
    let n: int = 5
    stage 1 [iota → map<toF32> → fill → map<sub>] {
      over n
      %1 = iota(n)
      a = map<toF32>(%1)
      %4 = fill(n, n - 1)
      reversed = map<sub>(%4, %1)
      reads direct: -; indexed: -; uniform: n
      materialises a: f32, reversed: u32
      ends at indexed read of a value made here
    }
    stage 2 [gather → map<add>] {
      over n
      %8 = gather(reversed, a)
      r = map<add>(%8, a)
      reads direct: reversed: u32, a: f32; indexed: a: f32; uniform: -
      materialises r: f32
      ends at control flow
    }
    out r = r
    ---
    r = [4.0, 4.0, 4.0, 4.0, 4.0]
    "
    );
}

#[test]
fn rule3_maps_run_inside_scatter_reduce_and_scan() {
    check!(
        r#"
        param n = 8
        pipeline p {
            x = iota(n)
            out total = map<mul>(x, x) → reduce<add>
            out prefix = map<add>(x, fill(n, 1)) → scan<add>
            out reversed = scatter(map<sub>(fill(n, n - 1), x), map<toF32>(x), len: n)
            out counts = scatter<add>(map<lt>(x, fill(n, 3)) → map<toU32>, fill(n, 1), into: fill(2, 0))
        }
        "#,
        @"
    pipeline p (fused, 4 stages)
    param n: int = 8
    let n: int = 8
    stage 1 [iota → map<mul> → reduce<add>] {
      over n
      x = iota(n)
      %3 = map<mul>(x, x)
      %4 = reduce<add>(%3)
      reads direct: -; indexed: -; uniform: n
      materialises x: u32, %4: int
      ends at reduce result read by the host
    }
    let total: int = %4
    out total = total
    stage 2 [fill → map<add> → scan<add>] {
      over n
      %6 = fill(n, 1)
      %7 = map<add>(x, %6)
      prefix = scan<add>(%7)
      reads direct: x: u32; indexed: -; uniform: n
      materialises %6: u32, prefix: u32
      ends at scan
    }
    out prefix = prefix
    stage 3 [fill] {
      over 2
      %19 = fill(2, 0)
      reads direct: -; indexed: -; uniform: -
      materialises %19: u32
      ends at control flow
    }
    stage 4 [fill → map<sub> → map<toF32> → scatter → fill → map<lt> → map<toU32> → scatter<add>] {
      over n
      %10 = fill(n, n - 1)
      %11 = map<sub>(%10, x)
      %12 = map<toF32>(x)
      reversed = scatter(%11, %12, len: n)
      %15 = fill(n, 3)
      %16 = map<lt>(x, %15)
      %17 = map<toU32>(%16)
      counts = scatter<add>(%17, %6, into: %19)
      reads direct: x: u32, %6: u32; indexed: %19: u32; uniform: n
      materialises reversed: f32, counts: u32
      ends at control flow
    }
    out reversed = reversed
    out counts = counts
    ---
    total = 140
    prefix = [1, 3, 6, 10, 15, 21, 28, 36]
    reversed = [7.0, 6.0, 5.0, 4.0, 3.0, 2.0, 1.0, 0.0]
    counts = [5, 3]
    "
    );
}

#[test]
fn rule4_scan_and_reduce_end_their_stages() {
    check!(
        r#"
        param n = 6
        pipeline p {
            x = iota(n)
            s = scan<add>(x)
            y = map<add>(s, x)
            t = reduce<max>(y)
            out z = map<add>(y, fill(n, t))
        }
        "#,
        @"
    pipeline p (fused, 3 stages)
    param n: int = 6
    let n: int = 6
    stage 1 [iota → scan<add>] {
      over n
      x = iota(n)
      s = scan<add>(x)
      reads direct: -; indexed: -; uniform: n
      materialises x: u32, s: u32
      ends at scan
    }
    stage 2 [map<add> → reduce<max>] {
      over n
      y = map<add>(s, x)
      %7 = reduce<max>(y)
      reads direct: s: u32, x: u32; indexed: -; uniform: -
      materialises y: u32, %7: int
      ends at reduce result read by the host
    }
    let t: int = %7
    stage 3 [fill → map<add>] {
      over n
      %9 = fill(n, t)
      z = map<add>(y, %9)
      reads direct: y: u32; indexed: -; uniform: n, t
      materialises z: u32
      ends at control flow
    }
    out z = z
    ---
    z = [20, 22, 25, 29, 34, 40]
    "
    );
}

#[test]
fn rule4_a_sort_ends_the_stage_of_its_keys_and_values() {
    // The maps that make the keys and values run in the sort's stage; the
    // sorted arrays are whole arrays for the next stage (f32 keys: -0 before
    // +0, equal keys in their order).
    check!(
        r#"
        param n = 6
        pipeline p {
            x = iota(n) → map<toF32>
            k = map<mul>(map<sub>(fill(n, 2.0), x), map<sub>(x, fill(n, 2.0)))
            (sk, sx) = sortByKey(map<neg>(map<abs>(k)), x)
            out sx
            out s = map<add>(sk, sx)
            out u = sort(iota(n))
        }
        "#,
        @"
    pipeline p (fused, 2 stages)
    param n: int = 6
    let n: int = 6
    stage 1 [iota → map<toF32> → fill → map<sub> → map<sub> → map<mul> → map<abs> → map<neg> → sortByKey] {
      over n
      %1 = iota(n)
      x = map<toF32>(%1)
      %4 = fill(n, 2.0)
      %5 = map<sub>(%4, x)
      %7 = map<sub>(x, %4)
      k = map<mul>(%5, %7)
      %10 = map<abs>(k)
      %11 = map<neg>(%10)
      (sk, sx) = sortByKey(%11, x)
      reads direct: -; indexed: -; uniform: n
      materialises %1: u32, sk: f32, sx: f32
      ends at sort
    }
    out sx = sx
    stage 2 [map<add> → sort] {
      over n
      s = map<add>(sk, sx)
      u = sort(%1)
      reads direct: sk: f32, sx: f32, %1: u32; indexed: -; uniform: -
      materialises s: f32, u: u32
      ends at sort
    }
    out s = s
    out u = u
    ---
    sx = [5.0, 0.0, 4.0, 1.0, 3.0, 2.0]
    s = [-4.0, -4.0, 0.0, 0.0, 2.0, 2.0]
    u = [0, 1, 2, 3, 4, 5]
    "
    );
}

#[test]
fn rule4_fan_out_and_group_gather_change_the_length() {
    // A stage ends before each length change; the op that changes it heads
    // the next stage, where maps over the new length join it. The sums of
    // `n * k` elements in groups of `k` run over `n`: `h` reads `x` there.
    // (`e` is an output too, so the group gather cannot close a level.)
    check!(
        r#"
        param n = 4
        param k = 3
        pipeline p {
            x = iota(n) → map<toF32>
            e = scatter<repeat>(x, fanout: k) → map<add>(fill(n * k, 0.5))
            g = gather<sum>(e, group: k)
            out h = map<mul>(g, x)
            out e
        }
        "#,
        @"
    pipeline p (fused, 3 stages)
    param n: int = 4
    param k: int = 3
    let n: int = 4
    let k: int = 3
    stage 1 [iota → map<toF32>] {
      over n
      %2 = iota(n)
      x = map<toF32>(%2)
      reads direct: -; indexed: -; uniform: n
      materialises x: f32
      ends at length change
    }
    stage 2 [scatter<repeat> → fill → map<add>] {
      over n * k
      %5 = scatter<repeat>(x, fanout: k)
      %6 = fill(n * k, 0.5)
      e = map<add>(%5, %6)
      reads direct: -; indexed: x: f32; uniform: k, n
      materialises e: f32
      ends at length change
    }
    out e = e
    stage 3 [gather<sum> → map<mul>] {
      over n
      g = gather<sum>(e, group: k)
      h = map<mul>(g, x)
      reads direct: x: f32; indexed: e: f32; uniform: k
      materialises h: f32
      ends at control flow
    }
    out h = h
    ---
    h = [0.0, 4.5, 15.0, 31.5]
    e = [0.5, 0.5, 0.5, 1.5, 1.5, 1.5, 2.5, 2.5, 2.5, 3.5, 3.5, 3.5]
    "
    );
}

#[test]
fn rule5_a_group_gather_closes_the_inner_level_of_its_elements() {
    // `e` is read only by the group gather: the fan-out, its maps and the
    // sums share one stage over `n`, whose inner level runs over `n * k`.
    check!(
        r#"
        param n = 4
        param k = 3
        pipeline p {
            x = iota(n) → map<toF32>
            e = scatter<repeat>(x, fanout: k) → map<add>(fill(n * k, 0.5))
            g = gather<sum>(e, group: k)
            out h = map<mul>(g, x)
        }
        "#,
        @"
    pipeline p (fused, 2 stages)
    param n: int = 4
    param k: int = 3
    let n: int = 4
    let k: int = 3
    stage 1 [iota → map<toF32>] {
      over n
      %2 = iota(n)
      x = map<toF32>(%2)
      reads direct: -; indexed: -; uniform: n
      materialises x: f32
      ends at length change
    }
    stage 2 [scatter<repeat> → fill → map<add> → gather<sum> → map<mul>] {
      over n
      inner level over n * k {
        %5 = scatter<repeat>(x, fanout: k)
        %6 = fill(n * k, 0.5)
        e = map<add>(%5, %6)
        reads direct: -
      }
      g = gather<sum>(e, group: k)
      h = map<mul>(g, x)
      reads direct: x: f32; indexed: x: f32; uniform: k, n
      materialises h: f32
      ends at control flow
    }
    out h = h
    ---
    h = [0.0, 4.5, 15.0, 31.5]
    "
    );
}

#[test]
fn rule5_pairs_of_points_and_lights_summed_per_point() {
    // The idiom of the written-out shading: pair `j` is point `j / k` with
    // light `j % k`; the pairs' terms are summed per point in the stage
    // that makes them, and the points' work goes on in it.
    check!(
        r#"
        param n = 5
        param k = 2
        pipeline p {
            points = iota(n) → map<toF32>
            lights = iota(k) → map<toF32> → map<add>(fill(k, 1.0))
            pair = iota(n * k)
            term = map<mul>(gather(pair / k, points), gather(pair % k, lights))
            lit = gather<sum>(term, group: k)
            out shaded = map<add>(lit, fill(n, 0.25))
        }
        "#,
        @"
    pipeline p (fused, 3 stages)
    param n: int = 5
    param k: int = 2
    let n: int = 5
    let k: int = 2
    stage 1 [iota → map<toF32> → fill → map<add>] {
      over k
      %5 = iota(k)
      %6 = map<toF32>(%5)
      %7 = fill(k, 1.0)
      lights = map<add>(%6, %7)
      reads direct: -; indexed: -; uniform: k
      materialises lights: f32
      ends at length change
    }
    stage 2 [iota → map<toF32>] {
      over n
      %2 = iota(n)
      points = map<toF32>(%2)
      reads direct: -; indexed: -; uniform: n
      materialises points: f32
      ends at length change
    }
    stage 3 [iota → fill → map<div> → gather → map<rem> → gather → map<mul> → gather<sum> → fill → map<add>] {
      over n
      inner level over n * k {
        pair = iota(n * k)
        %23 = fill(n * k, k)
        %12 = map<div>(pair, %23)
        %13 = gather(%12, points)
        %14 = map<rem>(pair, %23)
        %15 = gather(%14, lights)
        term = map<mul>(%13, %15)
        reads direct: -
      }
      lit = gather<sum>(term, group: k)
      %20 = fill(n, 0.25)
      shaded = map<add>(lit, %20)
      reads direct: -; indexed: points: f32, lights: f32; uniform: n, k
      materialises shaded: f32
      ends at control flow
    }
    out shaded = shaded
    ---
    shaded = [0.25, 3.25, 6.25, 9.25, 12.25]
    "
    );
}

#[test]
fn rule5_no_level_when_an_inner_value_is_read_after_the_sums() {
    // `t` is read by the last map too: it is stored, and the sums start a stage.
    check!(
        r#"
        param n = 3
        param k = 2
        pipeline p {
            t = iota(n * k) → map<toF32>
            s = gather<sum>(t, group: k)
            out r = map<add>(s, gather(iota(n), t))
        }
        "#,
        @"
    pipeline p (fused, 2 stages)
    param n: int = 3
    param k: int = 2
    let n: int = 3
    let k: int = 2
    stage 1 [iota → map<toF32>] {
      over n * k
      %2 = iota(n * k)
      t = map<toF32>(%2)
      reads direct: -; indexed: -; uniform: n, k
      materialises t: f32
      ends at length change
    }
    stage 2 [gather<sum> → iota → gather → map<add>] {
      over n
      s = gather<sum>(t, group: k)
      %7 = iota(n)
      %8 = gather(%7, t)
      r = map<add>(s, %8)
      reads direct: -; indexed: t: f32; uniform: k, n
      materialises r: f32
      ends at control flow
    }
    out r = r
    ---
    r = [1.0, 6.0, 11.0]
    "
    );
}

#[test]
fn rule5_no_level_under_a_scatter_or_a_fan_out_of_another_size() {
    // A scatter's target is complete only at its stage's end, so a stage
    // with one has no inner level; nor does a fan-out by 2 summed in
    // groups of 4 (a chunk of the sums would split a point's copies).
    check!(
        r#"
        param n = 4
        pipeline p {
            t = iota(n * 2) → map<toF32>
            hist = scatter(iota(n * 2), t, len: n * 2)
            s = gather<sum>(t, group: 2)
            e = scatter<repeat>(iota(n) → map<toF32>, fanout: 2) → map<add>(fill(n * 2, 1.0))
            q = gather<sum>(e, group: 4)
            out s
            out q
            out hist
        }
        "#,
        @"
    pipeline p (fused, 4 stages)
    param n: int = 4
    let n: int = 4
    stage 1 [iota → map<toF32> → scatter] {
      over n * 2
      %1 = iota(n * 2)
      t = map<toF32>(%1)
      hist = scatter(%1, t, len: n * 2)
      reads direct: -; indexed: -; uniform: n
      materialises t: f32, hist: f32
      ends at length change
    }
    stage 2 [gather<sum> → iota → map<toF32>] {
      over n
      s = gather<sum>(t, group: 2)
      %9 = iota(n)
      %10 = map<toF32>(%9)
      reads direct: -; indexed: t: f32; uniform: n
      materialises s: f32, %10: f32
      ends at length change
    }
    stage 3 [scatter<repeat> → fill → map<add>] {
      over n * 2
      %11 = scatter<repeat>(%10, fanout: 2)
      %12 = fill(n * 2, 1.0)
      e = map<add>(%11, %12)
      reads direct: -; indexed: %10: f32; uniform: n
      materialises e: f32
      ends at length change
    }
    out s = s
    out hist = hist
    stage 4 [gather<sum>] {
      over (n * 2) / 4
      q = gather<sum>(e, group: 4)
      reads direct: -; indexed: e: f32; uniform: -
      materialises q: f32
      ends at control flow
    }
    out q = q
    ---
    s = [1.0, 5.0, 9.0, 13.0]
    q = [6.0, 14.0]
    hist = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]
    "
    );
}

#[test]
fn a_gather_of_groups_of_one_changes_no_length_and_fuses_like_a_map() {
    // `group: 1` written as a literal: each element reads only its own source
    // element, after a map and before a scatter of the same stage, even reading
    // a value that a scatter of the stage also reads. A group size that is 1
    // only at run time still ends the stage.
    check!(
        r#"
        param n = 4
        param one = 1
        pipeline p {
            x = iota(n) → map<toF32>
            y = map<mul>(x, x)
            back = map<sub>(fill(n, 3), iota(n))
            first = scatter(back, y, len: n)
            g = gather<sum>(y, group: 1)
            out s = scatter(back, map<add>(g, x), len: n)
            out first = first
            out h = gather<sum>(y, group: one)
        }
        "#,
        @"
    pipeline p (fused, 2 stages)
    param n: int = 4
    param one: int = 1
    let n: int = 4
    let one: int = 1
    stage 1 [iota → map<toF32> → map<mul> → fill → map<sub> → scatter → gather<sum> → map<add> → scatter] {
      over n
      %2 = iota(n)
      x = map<toF32>(%2)
      y = map<mul>(x, x)
      %7 = fill(n, 3)
      back = map<sub>(%7, %2)
      first = scatter(back, y, len: n)
      g = gather<sum>(y, group: 1)
      %15 = map<add>(g, x)
      s = scatter(back, %15, len: n)
      reads direct: -; indexed: -; uniform: n
      materialises y: f32, first: f32, s: f32
      ends at control flow
    }
    out s = s
    let first#1 = first
    out first = first#1
    stage 2 [gather<sum>] {
      over n / one
      h = gather<sum>(y, group: one)
      reads direct: -; indexed: y: f32; uniform: one
      materialises h: f32
      ends at control flow
    }
    out h = h
    ---
    s = [12.0, 6.0, 2.0, 0.0]
    first = [9.0, 4.0, 1.0, 0.0]
    h = [0.0, 1.0, 4.0, 9.0]
    "
    );
}

#[test]
fn rule4_compaction_changes_the_length() {
    check!(
        r#"
        use "prelude.dpp"
        param n = 10
        pipeline p {
            x = iota(n) → map<toF32>
            keep = map<lt>(x, fill(n, 4.5))
            kept = gather(compactIndex(keep), x)
            out r = map<add>(kept, kept)
        }
        "#,
        @"
    pipeline p (fused, 6 stages)
    param n: int = 10
    let n: int = 10
    let dense: float = 1.0
    stage 1 [iota → map<toF32> → fill → map<lt> → map<toU32> → reduce<add>] {
      over n
      %1 = iota(n)
      x = map<toF32>(%1)
      %4 = fill(n, 4.5)
      keep = map<lt>(x, %4)
      %8 = map<toU32>(keep)
      %9 = reduce<add>(%8)
      reads direct: -; indexed: -; uniform: n
      materialises x: f32, keep: bool, %8: u32, %9: int
      ends at reduce result read by the host
    }
    let n#1: int = %9
    stage 2 [iota] {
      over 0
      at = iota(0)
      reads direct: -; indexed: -; uniform: -
      materialises at: u32
      ends at control flow
    }
    if n#1 > 0 {
      if float(n#1) < (dense * float(len(keep))) {
        stage 3 [exclusiveScan<add>] {
          over n
          slot = exclusiveScan<add>(%8)
          reads direct: %8: u32; indexed: -; uniform: -
          materialises slot: u32
          ends at scan
        }
        stage 4 [iota → scatter] {
          over n
          %16 = iota(len(keep))
          at = scatter(slot, %16, len: n#1, mask: keep)
          reads direct: slot: u32, keep: bool; indexed: -; uniform: len(keep), n#1
          materialises at: u32
          ends at control flow
        }
      } else {
        stage 5 [iota] {
          over n
          at = iota(len(keep))
          reads direct: -; indexed: -; uniform: len(keep)
          materialises at: u32
          ends at control flow
        }
      }
    }
    stage 6 [gather → map<add>] {
      over len(at)
      kept = gather(at, x)
      r = map<add>(kept, kept)
      reads direct: at: u32; indexed: x: f32; uniform: -
      materialises r: f32
      ends at control flow
    }
    out r = r
    ---
    r = [0.0, 2.0, 4.0, 6.0, 8.0]
    "
    );
}

#[test]
fn rule4_loops_and_branches_are_boundaries() {
    check!(
        r#"
        param on = true
        pipeline p {
            x = iota(4) → map<toF32>
            for i in 0..2 { x = map<add>(x, x) → map<mul>(x) }
            if on { x = map<add>(x, x) }
            out y = map<mul>(x, x)
        }
        "#,
        @"
    pipeline p (fused, 4 stages)
    param on: bool = true
    let on: bool = true
    stage 1 [iota → map<toF32>] {
      over 4
      %1 = iota(4)
      x = map<toF32>(%1)
      reads direct: -; indexed: -; uniform: -
      materialises x: f32
      ends at control flow
    }
    for i in 0..2 {
      stage 2 [map<add> → map<mul>] {
        over len(x)
        %5 = map<add>(x, x)
        x = map<mul>(%5, x)
        reads direct: x: f32; indexed: -; uniform: -
        materialises x: f32
        ends at control flow
      }
    }
    if on {
      stage 3 [map<add>] {
        over len(x)
        x = map<add>(x, x)
        reads direct: x: f32; indexed: -; uniform: -
        materialises x: f32
        ends at control flow
      }
    }
    stage 4 [map<mul>] {
      over len(x)
      y = map<mul>(x, x)
      reads direct: x: f32; indexed: -; uniform: -
      materialises y: f32
      ends at control flow
    }
    out y = y
    ---
    y = [0.0, 256.0, 65536.0, 1679616.0]
    "
    );
}

#[test]
fn no_fuse_gives_one_op_per_stage() {
    let source = trim_indent(
        r#"
        param n = 6
        pipeline p {
            a = iota(n) → map<toF32>
            b = map<add>(a, a)
            out total = reduce<add>(b)
        }
        "#,
    );
    let library = library();
    let plan = compile(&source, false, &library);
    insta::assert_snapshot!(plan_to_text(&plan, &library), @"
    pipeline p (unfused, 4 stages)
    param n: int = 6
    let n: int = 6
    stage 1 [iota] {
      over n
      %1 = iota(n)
      reads direct: -; indexed: -; uniform: n
      materialises %1: u32
      ends at unfused
    }
    stage 2 [map<toF32>] {
      over n
      a = map<toF32>(%1)
      reads direct: %1: u32; indexed: -; uniform: -
      materialises a: f32
      ends at unfused
    }
    stage 3 [map<add>] {
      over n
      b = map<add>(a, a)
      reads direct: a: f32; indexed: -; uniform: -
      materialises b: f32
      ends at unfused
    }
    stage 4 [reduce<add>] {
      over n
      %6 = reduce<add>(b)
      reads direct: b: f32; indexed: -; uniform: -
      materialises %6: float
      ends at unfused
    }
    let total: float = %6
    out total = total
    ");
}

#[test]
fn a_slot_written_from_another_length_does_not_join_the_stage() {
    // `x = map<add>(z, z)` runs over `len(z)` = 4, not over the old `len(x)` = 8.
    check!(
        r#"
        pipeline p {
            x = iota(8)
            z = iota(4)
            for i in 0..1 {
                y = map<toF32>(x)
                x = map<add>(z, z)
                out y
            }
            out x
        }
        "#,
        @"
    pipeline p (fused, 4 stages)
    stage 1 [iota] {
      over 4
      z = iota(4)
      reads direct: -; indexed: -; uniform: -
      materialises z: u32
      ends at control flow
    }
    stage 2 [iota] {
      over 8
      x = iota(8)
      reads direct: -; indexed: -; uniform: -
      materialises x: u32
      ends at control flow
    }
    for i in 0..1 {
      stage 3 [map<toF32>] {
        over len(x)
        y = map<toF32>(x)
        reads direct: x: u32; indexed: -; uniform: -
        materialises y: f32
        ends at length change
      }
      out y = y
      stage 4 [map<add>] {
        over 4
        x = map<add>(z, z)
        reads direct: z: u32; indexed: -; uniform: -
        materialises x: u32
        ends at control flow
      }
    }
    out x = x
    ---
    y = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]
    x = [0, 2, 4, 6]
    "
    );
}

#[test]
fn a_length_recorded_before_its_slot_was_rewritten_is_not_reused() {
    // `a` has the length `x` had before the gather: `b` runs over 8 elements,
    // `c` over the new `len(x)` = 4.
    check!(
        r#"
        pipeline p {
            x = iota(8)
            for i in 0..1 {
                a = map<toF32>(x)
                x = gather(iota(4), x)
                b = map<add>(a, a)
                c = iota(len(x))
                out b
                out c
            }
        }
        "#,
        @"
    pipeline p (fused, 5 stages)
    stage 1 [iota] {
      over 8
      x = iota(8)
      reads direct: -; indexed: -; uniform: -
      materialises x: u32
      ends at control flow
    }
    for i in 0..1 {
      stage 2 [map<toF32>] {
        over len(x)
        a = map<toF32>(x)
        reads direct: x: u32; indexed: -; uniform: -
        materialises a: f32
        ends at length change
      }
      stage 3 [map<add>] {
        over len(a)
        b = map<add>(a, a)
        reads direct: a: f32; indexed: -; uniform: -
        materialises b: f32
        ends at length change
      }
      stage 4 [iota → gather] {
        over 4
        %5 = iota(4)
        x = gather(%5, x)
        reads direct: -; indexed: x: u32; uniform: -
        materialises x: u32
        ends at length change
      }
      out b = b
      stage 5 [iota] {
        over len(x)
        c = iota(len(x))
        reads direct: -; indexed: -; uniform: len(x)
        materialises c: u32
        ends at control flow
      }
      out c = c
    }
    ---
    b = [0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0, 14.0]
    c = [0, 1, 2, 3]
    "
    );
}

#[test]
fn a_length_that_reads_a_rebound_host_value_is_not_reused() {
    // `a` has `m` = 4 elements; `m` is 5 by the time `c = iota(m)` runs.
    check!(
        r#"
        pipeline p {
            m = 4
            for i in 0..1 {
                a = iota(m)
                m = m + 1
                b = map<toF32>(a)
                c = iota(m)
                out b
                out c
            }
        }
        "#,
        @"
    pipeline p (fused, 3 stages)
    let m: int = 4
    for i in 0..1 {
      stage 1 [iota] {
        over m
        a = iota(m)
        reads direct: -; indexed: -; uniform: m
        materialises a: u32
        ends at control flow
      }
      let m: int = m + 1
      stage 2 [iota] {
        over m
        c = iota(m)
        reads direct: -; indexed: -; uniform: m
        materialises c: u32
        ends at control flow
      }
      out c = c
      stage 3 [map<toF32>] {
        over len(a)
        b = map<toF32>(a)
        reads direct: a: u32; indexed: -; uniform: -
        materialises b: f32
        ends at control flow
      }
      out b = b
    }
    ---
    b = [0.0, 1.0, 2.0, 3.0]
    c = [0, 1, 2, 3, 4]
    "
    );
}

/// Rule 3, `map → scatter`: the maps that make a combining scatter's indices
/// should run inside the scatter's stage. Here (the histogram pattern) the
/// `into:` array is made between them, over another length, and that ends the
/// maps' stage first: the indices are materialised and the scatter runs alone.
#[test]
fn rule3_a_scatter_fuses_with_its_maps_past_the_into_array() {
    let source = trim_indent(
        r#"
        param n = 8
        pipeline p {
            x = iota(n)
            bin = map<lt>(x, fill(n, 3)) → map<toU32>
            out counts = scatter<add>(bin, fill(n, 1), into: fill(2, 0))
        }
        "#,
    );
    let library = library();
    let plan = compile(&source, true, &library);
    let text = plan_to_text(&plan, &library);
    assert!(
        plan.stages().iter().any(|s| {
            let labels: Vec<String> = s.ops.iter().map(|op| op.label()).collect();
            labels.contains(&"map<toU32>".to_string())
                && labels.contains(&"scatter<add>".to_string())
        }),
        "{text}"
    );
}

/// A scatter is not a barrier (rule 4 does not list it): several scatters over
/// the rays of one pass share its stage, and the values only they read are
/// never materialised. Reading a scatter's result needs the whole of it, so
/// the op that does starts a new stage; an `out` moves after its stage.
#[test]
fn scatters_share_a_stage_until_one_is_read() {
    check!(
        r#"
        param n = 6
        pipeline p {
            x = iota(n)
            y = map<mul>(x, x) → map<toF32>
            back = map<sub>(fill(n, n - 1), x)
            out a = scatter(back, y, len: n)
            out b = scatter(back, x, len: n)
            out c = map<add>(a, fill(len(y), 1.0))
        }
        "#,
        @"
    pipeline p (fused, 2 stages)
    param n: int = 6
    let n: int = 6
    stage 1 [iota → map<mul> → map<toF32> → fill → map<sub> → scatter → scatter → fill] {
      over n
      x = iota(n)
      %3 = map<mul>(x, x)
      y = map<toF32>(%3)
      %6 = fill(n, n - 1)
      back = map<sub>(%6, x)
      a = scatter(back, y, len: n)
      b = scatter(back, x, len: n)
      %13 = fill(n, 1.0)
      reads direct: -; indexed: -; uniform: n
      materialises a: f32, b: u32, %13: f32
      ends at scatter
    }
    out a = a
    out b = b
    stage 2 [map<add>] {
      over n
      c = map<add>(a, %13)
      reads direct: a: f32, %13: f32; indexed: -; uniform: -
      materialises c: f32
      ends at control flow
    }
    out c = c
    ---
    a = [25.0, 16.0, 9.0, 4.0, 1.0, 0.0]
    b = [5, 4, 3, 2, 1, 0]
    c = [26.0, 17.0, 10.0, 5.0, 2.0, 1.0]
    "
    );
}

/// `len(v)` of a value the stage makes becomes `v`'s symbolic length, so the
/// `fill` joins the stage instead of waiting for `v` to be stored.
#[test]
fn the_length_of_a_value_of_the_stage_is_its_symbolic_length() {
    check!(
        r#"
        param n = 5
        pipeline p {
            x = iota(n) → map<toF32>
            out y = map<add>(x, fill(len(x), 0.5))
        }
        "#,
        @"
    pipeline p (fused, 1 stages)
    param n: int = 5
    let n: int = 5
    stage 1 [iota → map<toF32> → fill → map<add>] {
      over n
      %1 = iota(n)
      x = map<toF32>(%1)
      %4 = fill(n, 0.5)
      y = map<add>(x, %4)
      reads direct: -; indexed: -; uniform: n
      materialises y: f32
      ends at control flow
    }
    out y = y
    ---
    y = [0.5, 1.5, 2.5, 3.5, 4.5]
    "
    );
}

/// What a scatter reads, and its result, must keep their values until its
/// stage ends: an op over the same length that rewrites them (loop slots)
/// starts a new stage.
#[test]
fn rewriting_what_a_scatter_reads_starts_a_new_stage() {
    check!(
        r#"
        param n = 4
        pipeline p {
            x = iota(n) → map<toF32>
            s = fill(n, 0.0)
            for k in 0..2 {
                s = scatter(iota(n), x, len: n)
                x = fill(n, 2.0)
                s = map<add>(fill(n, 1.0), fill(n, 1.0))
            }
            out s = s
            out x = x
        }
        "#,
        @"
    pipeline p (fused, 3 stages)
    param n: int = 4
    let n: int = 4
    stage 1 [iota → map<toF32> → fill] {
      over n
      %1 = iota(n)
      x = map<toF32>(%1)
      s = fill(n, 0.0)
      reads direct: -; indexed: -; uniform: n
      materialises %1: u32, x: f32, s: f32
      ends at control flow
    }
    for k in 0..2 {
      stage 2 [scatter] {
        over n
        s = scatter(%1, x, len: n)
        reads direct: %1: u32, x: f32; indexed: -; uniform: n
        materialises s: f32
        ends at scatter
      }
      stage 3 [fill → fill → map<add>] {
        over n
        x = fill(n, 2.0)
        %10 = fill(n, 1.0)
        s = map<add>(%10, %10)
        reads direct: -; indexed: -; uniform: n
        materialises x: f32, s: f32
        ends at control flow
      }
    }
    let s#1 = s
    out s = s#1
    let x#1 = x
    out x = x#1
    ---
    s = [2.0, 2.0, 2.0, 2.0]
    x = [2.0, 2.0, 2.0, 2.0]
    "
    );
}

/// The histogram pattern: the `into:` array is made over the bins, before the
/// scatter's stage (a side stage of another length); the reduce over the bins
/// that follows fits that side stage but reads the scatter's result. The side
/// stage must still run first, so both stages end there.
#[test]
fn a_side_stage_the_open_stage_reads_runs_first() {
    check!(
        r#"
        param n = 8
        pipeline p {
            bin = iota(n) → map<lt>(fill(n, 3)) → map<toU32>
            out counts = scatter<add>(bin, fill(n, 1), into: fill(2, 0))
            out total = reduce<add>(counts)
        }
        "#,
        @"
    pipeline p (fused, 3 stages)
    param n: int = 8
    let n: int = 8
    stage 1 [fill] {
      over 2
      %7 = fill(2, 0)
      reads direct: -; indexed: -; uniform: -
      materialises %7: u32
      ends at length change
    }
    stage 2 [iota → fill → map<lt> → map<toU32> → fill → scatter<add>] {
      over n
      %1 = iota(n)
      %2 = fill(n, 3)
      %3 = map<lt>(%1, %2)
      bin = map<toU32>(%3)
      %6 = fill(n, 1)
      counts = scatter<add>(bin, %6, into: %7)
      reads direct: -; indexed: %7: u32; uniform: n
      materialises counts: u32
      ends at length change
    }
    out counts = counts
    stage 3 [reduce<add>] {
      over 2
      %10 = reduce<add>(counts)
      reads direct: counts: u32; indexed: -; uniform: -
      materialises %10: int
      ends at reduce result read by the host
    }
    let total: int = %10
    out total = total
    ---
    counts = [5, 3]
    total = 8
    "
    );
}

/// Sinks that finish after their stage (a combining scatter, a segmented scan,
/// a sort by key) reading values their stage made, over sixteen chunks of the
/// tests' 64 elements: the fused run keeps those values in stage-wide arrays,
/// not the chunks' columns (`key` is also read after its stage, so it is
/// materialised anyway), and must agree with the unfused run bit for bit
/// (the float sums fold in a fixed order).
#[test]
fn sinks_after_the_stage_read_the_values_it_made_from_every_chunk() {
    let source = trim_indent(
        r#"
        param n = 1000
        pipeline p {
            x = iota(n)
            out key = map<rem>(map<hash>(x), fill(n, 37))
            out sums = scatter<add>(key, map<random>(x, seed: 3), into: fill(37, 0.0))
            starts = map<eq>(map<rem>(x, fill(n, 100)), fill(n, 0))
            out prefix = scan<add>(map<random>(x, seed: 5), segments: starts)
            sortKey = map<rem>(map<hash>(x, seed: 1), fill(n, 37))
            (sortedKeys, sortedWeights) = sortByKey(sortKey, map<random>(x, seed: 7))
            out sortedKeys
            out sortedWeights
        }
        "#,
    );
    let library = library();
    let fused = compile(&source, true, &library);
    let plan = plan_to_text(&fused, &library);
    // The sinks share stages with the maps that make what they read.
    for sink in [
        "map<random> → scatter<add>",
        "map<random> → scan<add>",
        "map<random> → sortByKey",
    ] {
        assert!(plan.contains(sink), "no `{sink}` in\n{plan}");
    }
    let unfused = compile(&source, false, &library);
    let (outputs, unfused_outputs) = (run_text(&fused, &library), run_text(&unfused, &library));
    assert!(!outputs.starts_with("run-time error"), "{outputs}");
    assert_eq!(outputs, unfused_outputs);
}
