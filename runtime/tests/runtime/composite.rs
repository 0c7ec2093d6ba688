//! `composite<blend>(…)` (docs/language.md §3): the node a pipeline's ranks
//! meet at, run here with compositors that stand in for the other ranks
//! (the real schedule over MPI is `dist/`'s, tested under mpirun): the
//! identity with one rank, the blend a compositor calls, the run that ends on
//! a rank whose image went elsewhere, the blends of `pipelines/composite.dpp`,
//! and the diagnostics of a misplaced composite or a blend that does not fit.

use crate::common::*;
use dpp_runtime::cpu::column_pool::ColumnPool;
use dpp_runtime::cpu::exec::{run_plan_observed, RunContext};
use dpp_runtime::interpret::{Blend, Compositor, OutputValue, RunError, RunHooks, RunResult};
use dpp_runtime::*;
use std::sync::Arc;

/// Two fragments per pixel: depth and an id, composited by nearest depth.
const NEAREST: &str = r#"
use "composite.dpp"
pipeline p {
    depth = fill(4, 2.0)
    id = fill(4, 7)
    other = fill(4, 0.5)
    (depth, id, other) = composite<nearestDepth>(depth, id, other)
    out depth
    out id
}
"#;

fn compiled(source: &str) -> Plan {
    compile(&pipelines_path("test.dpp"), source, &library(), true)
        .unwrap_or_else(|failure| panic!("{}", failure.render(false)))
}

fn run_with(plan: &Plan, compositor: &dyn Compositor) -> Result<RunResult, RunError> {
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
    let hooks = RunHooks {
        observer: None,
        compositor: Some(compositor),
    };
    run_plan_observed(plan, &context, hooks)
}

fn outputs_text(result: &RunResult) -> String {
    (result.outputs.iter())
        .map(|(name, value)| match value {
            OutputValue::Array(column) => format!("{name} = {}\n", column_text(column)),
            OutputValue::Host(value) => format!("{name} = {value}\n"),
        })
        .collect()
}

/// Rank 0 of two: its pieces at the front, a second rank's given here behind,
/// blended by the plan's own blend; the whole image is the blend's.
struct FrontOfTwo {
    back: Vec<Arc<Column>>,
}

impl Compositor for FrontOfTwo {
    fn composite(
        &self,
        fragments: Vec<Arc<Column>>,
        _visibility: bool,
        blend: &mut Blend<'_>,
    ) -> Result<Option<Vec<Arc<Column>>>, RunError> {
        blend(&fragments, &self.back).map(Some)
    }
}

/// A rank other than 0: its pieces leave, nothing comes back.
struct SentAway;

impl Compositor for SentAway {
    fn composite(
        &self,
        _: Vec<Arc<Column>>,
        _: bool,
        _: &mut Blend<'_>,
    ) -> Result<Option<Vec<Arc<Column>>>, RunError> {
        Ok(None)
    }
}

#[test]
fn one_rank_keeps_its_own_image_and_never_blends() {
    let plan = compiled(NEAREST);
    insta::assert_snapshot!(run_text(&plan, &library()), @r"
    depth = [2.0, 2.0, 2.0, 2.0]
    id = [7, 7, 7, 7]
    ");
}

#[test]
fn the_blend_combines_this_rank_with_the_piece_behind_it() {
    let plan = compiled(NEAREST);
    // Nearer, a tie (the front piece keeps it), farther, nearer.
    let back = vec![
        Arc::new(Column::F32(vec![1.0, 2.0, 3.0, 0.5])),
        Arc::new(Column::U32(vec![1, 2, 3, 4])),
        Arc::new(Column::F32(vec![9.0; 4])),
    ];
    let result = run_with(&plan, &FrontOfTwo { back }).unwrap();
    assert!(!result.composited_elsewhere);
    insta::assert_snapshot!(outputs_text(&result), @r"
    depth = [1.0, 2.0, 2.0, 0.5]
    id = [1, 7, 7, 4]
    ");
}

#[test]
fn a_rank_whose_image_went_elsewhere_stops_there_without_outputs() {
    let plan = compiled(NEAREST);
    let result = run_with(&plan, &SentAway).unwrap();
    assert!(result.composited_elsewhere);
    assert!(result.outputs.is_empty());
}

#[test]
fn pieces_that_do_not_fit_the_blend_are_an_error_not_a_panic() {
    let plan = compiled(NEAREST);
    let too_few = vec![Arc::new(Column::F32(vec![1.0; 4]))];
    let of_another_type = vec![
        Arc::new(Column::F32(vec![1.0; 4])),
        Arc::new(Column::I32(vec![1; 4])),
        Arc::new(Column::F32(vec![1.0; 4])),
    ];
    for back in [too_few, of_another_type] {
        let error = run_with(&plan, &FrontOfTwo { back }).unwrap_err();
        assert_eq!(error.kind, ErrorKind::Internal, "{error}");
        assert!(error.message.contains("composite<nearestDepth>"), "{error}");
    }
}

#[test]
fn over_blends_premultiplied_colour_front_to_back() {
    // A half-covering front over a fully covering back: colour 0.5 + 0.5 × 0.2,
    // coverage 0.5 + 0.5 × 1.
    let plan = compiled(
        r#"
        use "composite.dpp"
        pipeline p {
            (color, alpha) = over(fill(2, vec3(0.5)), fill(2, vec3(0.5)), fill(2, vec3(0.2)), fill(2, vec3(1.0)))
            out color
            out alpha
        }
        "#,
    );
    insta::assert_snapshot!(run_text(&plan, &library()), @r"
    color = Vec3([Vec3(0.6, 0.6, 0.6), Vec3(0.6, 0.6, 0.6)])
    alpha = Vec3([Vec3(1.0, 1.0, 1.0), Vec3(1.0, 1.0, 1.0)])
    ");
}

/// `code at line:col: message` for a pipeline that must not compile.
fn errors(source: &str) -> String {
    match compile(&pipelines_path("test.dpp"), source, &library(), true) {
        Ok(_) => panic!("compiled, but it should not:\n{source}"),
        Err(failure) => diagnostics_text(&failure),
    }
}

#[test]
fn a_misplaced_composite_or_a_blend_that_does_not_fit_is_a_diagnostic() {
    let header = "use \"composite.dpp\"\nfn first(a, b) { return a }\nfn swapped(a, b, c, d) { return (map<toF32>(b), a) }\n";
    let cases = [
        "pipeline p { a = fill(2, 1.0)\n for i in 0..2 { a = composite<first>(a) } }",
        "pipeline p { a = fill(2, 1.0)\n a = composite<first>(a)\n a = composite<first>(a) }",
        "pipeline p { out a = fill(2, 1.0)\n b = composite<first>(a) }",
        "pipeline p { a = fill(2, 1.0)\n b = composite<nope>(a) }",
        "pipeline p { a = fill(2, 1.0)\n b = composite(a) }",
        "pipeline p { a = fill(2, 1.0)\n (b, c) = composite<first>(a, a) }",
        "pipeline p { a = fill(2, 1.0)\n c = fill(2, 1)\n (b, d) = composite<swapped>(a, c) }",
    ];
    let report: String = (cases.iter())
        .map(|case| format!("{}\n", errors(&format!("{header}{case}"))))
        .collect();
    insta::assert_snapshot!(report);
}
