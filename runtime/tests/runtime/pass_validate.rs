//! The plan validator (`compile::validate`), which runs after every pass in
//! debug builds: every pipeline of the repository passes it, fused and
//! unfused, and each deliberately broken plan below is caught with a message
//! that names what is wrong.

use crate::common::{library, pipelines_path};
use dpp_runtime::compile::ir::{Node, OpKind, Plan, VarId};
use dpp_runtime::compile::validate::{validate_plan, PlanPhase};

fn compiled(name: &str, fuse: bool) -> Plan {
    let path = pipelines_path(name);
    let source = std::fs::read_to_string(&path).unwrap();
    crate::common::compile(&path, &source, &library(), fuse).unwrap_or_else(|e| panic!("{e}"))
}

/// The validator's findings on the compaction example after `break_it`.
fn check(fuse: bool, break_it: impl FnOnce(&mut Plan)) -> Vec<String> {
    check_pipeline("examples/compaction.dpp", fuse, break_it)
}

/// The validator's findings on pipeline `name` after `break_it`.
fn check_pipeline(name: &str, fuse: bool, break_it: impl FnOnce(&mut Plan)) -> Vec<String> {
    // An unfused plan is made of stages too, one op each.
    let mut plan = compiled(name, fuse);
    let phase = PlanPhase::Fused;
    assert_eq!(
        validate_plan(&plan.vars, &plan.body, phase),
        Vec::<String>::new()
    );
    break_it(&mut plan);
    validate_plan(&plan.vars, &plan.body, phase)
}

fn stage_positions(plan: &Plan) -> Vec<usize> {
    (0..plan.body.len())
        .filter(|&i| matches!(plan.body[i], Node::Stage(_)))
        .collect()
}

/// The generic library's pipelines (the tracer's are validated by the
/// compiler itself in every test that compiles them: `tests/command/plans.rs`).
#[test]
fn every_example_pipeline_is_valid_fused_and_unfused() {
    for name in [
        "examples/compaction.dpp",
        "examples/histogram.dpp",
        "examples/prefix_sum.dpp",
        "examples/sample_counts.dpp",
    ] {
        for fuse in [true, false] {
            let plan = compiled(name, fuse);
            assert_eq!(
                validate_plan(&plan.vars, &plan.body, PlanPhase::Fused),
                Vec::<String>::new(),
                "{name}, fuse {fuse}"
            );
        }
    }
}

#[test]
fn a_read_before_its_write_is_caught() {
    let problems = check(true, |plan| {
        let stages = stage_positions(plan);
        let last = *stages.last().unwrap();
        let node = plan.body.remove(last);
        plan.body.insert(0, node);
    });
    assert!(
        problems.iter().any(|p| p.contains("before it is written")),
        "{problems:#?}"
    );
}

#[test]
fn a_bare_op_after_fusion_is_caught() {
    let problems = check(true, |plan| {
        let Node::Stage(stage) = &plan.body[stage_positions(plan)[0]] else {
            unreachable!()
        };
        let op = stage.ops[0].clone();
        plan.body.push(Node::Op(op));
    });
    assert!(
        problems
            .iter()
            .any(|p| p.contains("is outside a stage after fusion")),
        "{problems:#?}"
    );
}

#[test]
fn an_op_without_the_functor_its_kind_needs_is_caught() {
    let problems = check(false, |plan| {
        for node in &mut plan.body {
            if let Node::Stage(stage) = node {
                for op in &mut stage.ops {
                    if op.kind == OpKind::Map {
                        op.functor = None;
                    }
                }
            }
        }
    });
    assert!(
        problems
            .iter()
            .any(|p| p.starts_with("map lacks a functor")),
        "{problems:#?}"
    );
}

#[test]
fn a_variable_out_of_range_and_a_stray_break_are_caught() {
    let problems = check(true, |plan| {
        plan.body.push(Node::Break);
        plan.body.push(Node::Output {
            name: "ghost".into(),
            var: VarId(10_000),
        });
    });
    assert!(
        problems.contains(&"`break` outside a loop".to_string()),
        "{problems:#?}"
    );
    assert!(
        problems
            .iter()
            .any(|p| p.contains("names %10000 but the plan has")),
        "{problems:#?}"
    );
}

#[test]
fn a_stage_that_reads_its_own_sink_result_is_caught() {
    /// The first branch, however deeply nested, that holds stages.
    fn branch_with_stages(nodes: &mut [Node]) -> Option<Vec<Node>> {
        nodes.iter_mut().find_map(|node| match node {
            Node::If { then_body, .. } if then_body.iter().any(|n| matches!(n, Node::Stage(_))) => {
                Some(std::mem::take(then_body))
            }
            Node::If { then_body, .. } => branch_with_stages(then_body),
            _ => None,
        })
    }
    let problems = check(true, |plan| {
        // The scan of `compactIndex` and the scatter that reads its result
        // (the reverse index, in the branch taken when some element is kept
        // and some dropped), forced into one stage.
        let reverse_index = branch_with_stages(&mut plan.body).expect("compactIndex's branch");
        let first = stage_positions(plan)[0];
        if let Node::Stage(stage) = &mut plan.body[first] {
            for node in reverse_index {
                if let Node::Stage(scatter) = node {
                    stage.ops.extend(scatter.ops);
                }
            }
        }
    });
    assert!(
        problems
            .iter()
            .any(|p| p.contains("which a sink of the same stage completes only at its end")),
        "{problems:#?}"
    );
}

/// A nested stage's inner values stay inside it: storing one, or reading
/// one after the group gather that closes the level, is caught.
#[test]
fn an_inner_value_that_leaves_its_level_is_caught() {
    fn nested(plan: &mut Plan) -> &mut dpp_runtime::compile::ir::Stage {
        plan.body
            .iter_mut()
            .find_map(|node| match node {
                Node::Stage(stage) if stage.inner.is_some() => Some(stage),
                _ => None,
            })
            .expect("a nested stage")
    }
    let problems = check_pipeline("examples/sample_counts.dpp", true, |plan| {
        let stage = nested(plan);
        let inner_value = stage.ops[0].outputs[0];
        stage.materialises.push(inner_value);
        let last = stage.ops.len() - 1;
        stage.ops[last].inputs[0] = inner_value;
    });
    assert!(
        problems
            .iter()
            .any(|p| p.contains("materialises `pair` (%8), a value of its inner level")),
        "{problems:#?}"
    );
    assert!(
        problems
            .iter()
            .any(|p| p.contains("reduce<add> reads `pair` (%8), a value of its inner level")),
        "{problems:#?}"
    );
    let problems = check_pipeline("examples/sample_counts.dpp", true, |plan| {
        let stage = nested(plan);
        stage.inner.as_mut().unwrap().ops -= 1;
    });
    assert!(
        problems
            .iter()
            .any(|p| p.contains("does not gather groups of its inner level")),
        "{problems:#?}"
    );
}
