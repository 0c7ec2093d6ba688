//! Pass 5a, `narrow`: a gathered record read only field by field gathers
//! only those fields (`gather(i, p).a` → `gather(i, p.a)`), and only where
//! that cannot change a value.
//!
//! `check!(source, @"…")` shows the compiled plan's ops, then the outputs,
//! run fused and unfused (which must agree).

use crate::common::{
    check, compile, diagnostics_text, library_with_pairs, ops_text, run_text, trim_indent,
};
use std::path::Path;

fn report(source: &str) -> String {
    let library = library_with_pairs();
    let path = Path::new("narrow.dpp");
    let source = trim_indent(source);
    let fused = match compile(path, &source, &library, true) {
        Ok(plan) => plan,
        Err(failure) => return diagnostics_text(&failure),
    };
    let unfused = compile(path, &source, &library, false).expect("it compiled fused");
    let outputs = run_text(&fused, &library);
    assert_eq!(
        outputs,
        run_text(&unfused, &library),
        "fused and unfused differ"
    );
    format!("{}---\n{outputs}", ops_text(&fused, &library))
}

#[test]
fn field_reads_of_a_gathered_record_gather_only_their_fields() {
    check!("
        pipeline p {
            pairs = iota(8) → map<makePair>
            g = gather(iota(4) * 2, pairs)
            out a = g.a
            out b = g.b * 2.0
        }
    ", @r"
    stage 1 [iota → map<makePair> → .a → .b] {
      over 8
      %0 = iota(8)
      pairs = map<makePair>(%0)
      pairs.a = field a of pairs
      pairs.b = field b of pairs
      reads direct: -; indexed: -; uniform: -
      materialises pairs.a: u32, pairs.b: f32
      ends at length change
    }
    stage 2 [iota → fill → map<mul> → gather → gather → fill → map<mul>] {
      over 4
      %3 = iota(4)
      %12 = fill(4, 2)
      %4 = map<mul>(%3, %12)
      a = gather(%4, pairs.a)
      g.b = gather(%4, pairs.b)
      %13 = fill(4, 2.0)
      b = map<mul>(g.b, %13)
      reads direct: -; indexed: pairs.a: u32, pairs.b: f32; uniform: -
      materialises a: u32, b: f32
      ends at control flow
    }
    out a = a
    out b = b
    ---
    a = [0, 2, 4, 6]
    b = [0.0, 2.0, 4.0, 6.0]
    ");
}

#[test]
fn a_record_read_whole_is_gathered_whole() {
    check!("
        pipeline p {
            pairs = iota(8) → map<makePair>
            g = gather(iota(4) * 2, pairs)
            h = map<identity>(g)
            out a = g.a + h.a
        }
    ", @r"
    stage 1 [iota → map<makePair>] {
      over 8
      %0 = iota(8)
      pairs = map<makePair>(%0)
      reads direct: -; indexed: -; uniform: -
      materialises pairs: Pair
      ends at length change
    }
    stage 2 [iota → fill → map<mul> → gather → map<identity> → .a → .a → map<add>] {
      over 4
      %3 = iota(4)
      %13 = fill(4, 2)
      %4 = map<mul>(%3, %13)
      g = gather(%4, pairs)
      h = map<identity>(g)
      h.a = field a of h
      g.a = field a of g
      a = map<add>(g.a, h.a)
      reads direct: -; indexed: pairs: Pair; uniform: -
      materialises a: u32
      ends at control flow
    }
    out a = a
    ---
    a = [0, 4, 8, 12]
    ");
}

#[test]
fn a_source_rebound_after_the_gather_is_read_as_it_was_gathered() {
    check!("
        pipeline p {
            pairs = iota(8) → map<makePair>
            i = iota(4) * 2
            g = gather(i, pairs)
            a = g.a
            pairs = iota(8) → map<add>(fill(8, 100)) → map<makePair>
            out b = g.b + toF32(a) + gather(i, pairs).b
        }
    ", @r"
    stage 1 [iota → map<makePair> → .a → .b] {
      over 8
      %0 = iota(8)
      pairs = map<makePair>(%0)
      pairs.a = field a of pairs
      pairs.b = field b of pairs
      reads direct: -; indexed: -; uniform: -
      materialises %0: u32, pairs.a: u32, pairs.b: f32
      ends at length change
    }
    stage 2 [iota → fill → map<mul> → gather] {
      over 4
      %3 = iota(4)
      %22 = fill(4, 2)
      i = map<mul>(%3, %22)
      a = gather(i, pairs.a)
      reads direct: -; indexed: pairs.a: u32; uniform: -
      materialises i: u32, a: u32
      ends at length change
    }
    stage 3 [fill → map<add> → map<makePair> → .b] {
      over 8
      %11 = fill(8, 100)
      %12 = map<add>(%0, %11)
      pairs#1 = map<makePair>(%12)
      pairs#1.b = field b of pairs#1
      reads direct: %0: u32; indexed: -; uniform: -
      materialises pairs#1.b: f32
      ends at length change
    }
    stage 4 [gather → map<toF32> → map<add> → gather → map<add>] {
      over 4
      g.b = gather(i, pairs.b)
      %16 = map<toF32>(a)
      %17 = map<add>(g.b, %16)
      %18.b = gather(i, pairs#1.b)
      b = map<add>(%17, %18.b)
      reads direct: i: u32, a: u32; indexed: pairs.b: f32, pairs#1.b: f32; uniform: -
      materialises b: f32
      ends at control flow
    }
    out b = b
    ---
    b = [50.0, 54.0, 58.0, 62.0]
    ");
}
