//! Every pipeline in `pipelines/` compiles, and its plan, fused and unfused, is
//! pinned by a snapshot (docs/language.md §6). A change to the compiler that changes a plan
//! shows up here as a readable diff.

use dpp_runtime::compile::ir::OpKind;
use dpp_runtime::compile::plan_text::plan_to_text;
use dpp_runtime::{compile_file, CompileOptions};

#[test]
fn plans_of_every_pipeline_fused_and_unfused() {
    let library = dpp_tracer::functor_library();
    let pipelines = crate::common::pipeline_files();
    assert!(
        pipelines.len() >= 4,
        "pipelines went missing: {pipelines:?}"
    );
    for path in pipelines {
        let name = crate::common::pipeline_name(&path);
        for fuse in [true, false] {
            let options = CompileOptions {
                fuse,
                ..CompileOptions::default()
            };
            let plan = compile_file(&path, &library, &options)
                .unwrap_or_else(|e| panic!("{}", e.render(false)));
            let suffix = if fuse { "fused" } else { "unfused" };
            insta::assert_snapshot!(format!("{name}.{suffix}"), plan_to_text(&plan, &library));
        }
    }
}

#[test]
fn fusion_never_adds_stages() {
    let library = dpp_tracer::functor_library();
    for path in crate::common::pipeline_files() {
        let compile = |fuse| {
            compile_file(
                &path,
                &library,
                &CompileOptions {
                    fuse,
                    ..CompileOptions::default()
                },
            )
            .unwrap()
        };
        let (fused, unfused) = (compile(true), compile(false));
        assert!(
            fused.stages().len() <= unfused.stages().len(),
            "{}",
            path.display()
        );
        // Field views are not primitives: a stage may compute one or the plan may view it.
        let primitives = |plan: &dpp_runtime::Plan| {
            plan.stages()
                .iter()
                .flat_map(|s| &s.ops)
                .filter(|op| !matches!(op.kind, OpKind::Field { .. }))
                .count()
        };
        assert_eq!(
            primitives(&fused),
            primitives(&unfused),
            "fusion must keep every primitive: {}",
            path.display()
        );
    }
}

#[test]
fn json_form_round_trips_through_serde() {
    let library = dpp_tracer::functor_library();
    let path = crate::common::repo().join("pipelines/workload1.dpp");
    let plan = compile_file(&path, &library, &CompileOptions::default()).unwrap();
    let json: serde_json::Value = serde_json::to_value(&plan).unwrap();
    assert_eq!(json["pipeline"], "workload1");
    assert_eq!(json["fused"], true);
    assert!(json["body"].as_array().is_some_and(|b| !b.is_empty()));
}
