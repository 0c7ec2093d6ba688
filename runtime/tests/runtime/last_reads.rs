//! `interpret::last_reads`: the arrays a stage reads for the last time, which
//! a backend may then reuse (the CPU scatters `into:` such an array in place
//! instead of copying it). Only reads at the plan's top level count: a value
//! read inside a loop or branch may be read again, and one that is an output
//! is read after every stage.

use crate::common::{compile, library, pipelines_path, run_text, trim_indent};
use dpp_runtime::interpret::last_reads;

#[test]
fn only_an_array_read_last_by_a_top_level_stage_is_listed() {
    let source = trim_indent(
        r#"
        param n = 4
        pipeline p {
            x = iota(n) → map<toF32>
            y = fill(n, 2.0)
            z = scatter(iota(n), map<add>(x, x), into: y)
            w = map<add>(x, z)
            for i in 0..2 {
                w = map<mul>(w, x)
            }
            out z
            out w
        }
        "#,
    );
    let library = library();
    let plan = compile(
        &pipelines_path("last_reads_test.dpp"),
        &source,
        &library,
        true,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let names: Vec<String> = last_reads(&plan)
        .iter()
        .flatten()
        .map(|v| plan.var(*v).name.clone())
        .collect();
    // `y` is read last by the scatter; `x` is read in the loop, `z` and `w`
    // by the outputs (the compiler's own temporaries may be listed too).
    assert!(names.contains(&"y".to_string()), "{names:?}");
    for never in ["x", "z", "w", "n"] {
        assert!(!names.contains(&never.to_string()), "{never} in {names:?}");
    }
    // The scatter into `y` leaves it and `x` as they were for their readers.
    assert_eq!(
        run_text(&plan, &library),
        "z = [0.0, 2.0, 4.0, 6.0]\nw = [0.0, 3.0, 24.0, 81.0]\n"
    );
}
