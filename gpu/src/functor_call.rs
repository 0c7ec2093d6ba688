//! One functor applied once on the GPU to given arrays: how a functor's tests
//! run its twin on the same input as its Rust code.

use crate::array::upload;
use crate::exec::{run_plan_gpu_with_inputs, GpuRunContext};
use dpp_dsl::Span;
use dpp_runtime::column::Column;
use dpp_runtime::compile::ir::*;
use dpp_runtime::host::HostValue;
use dpp_runtime::interpret::{OutputValue, RunError};
use dpp_runtime::signature::{FunctorKind, TypePattern};
use dpp_runtime::types::ElemType;

/// `map<name>(inputs…)`, `gather<name>(inputs[0], group: k)` or
/// `scatter<name>(inputs[0], fanout: k)` by the functor's kind, with named
/// arguments `named` (defaults for those left out); returns its one output.
pub fn run_functor_gpu(
    context: &GpuRunContext<'_>,
    name: &str,
    inputs: &[Column],
    named: &[HostValue],
    group: usize,
) -> Result<Column, RunError> {
    let functor = context
        .library
        .get(name)
        .ok_or_else(|| RunError::bad_input(format!("no functor `{name}`")))?;
    let signature = functor.signature();
    // Type variables take the type of the first input declared with them.
    let bind = |pattern: &TypePattern| -> Result<ElemType, RunError> {
        match pattern {
            TypePattern::Exact(ty) => Ok(*ty),
            TypePattern::Var(n, _) => signature
                .inputs
                .iter()
                .zip(inputs)
                .find(|(p, _)| {
                    p.ty == *pattern || matches!(p.ty, TypePattern::Var(m, _) if m == *n)
                })
                .map(|(_, column)| column.elem_type())
                .ok_or_else(|| {
                    RunError::bad_input(format!("`{name}`: cannot bind type variable T{n}"))
                }),
        }
    };
    let output_type = bind(&signature.outputs[0].ty)?;
    let array = |ty: ElemType, name: &str| VarInfo {
        name: name.to_string(),
        span: Span::default(),
        ty: VarType::Array(ty),
        len: None,
    };
    let mut vars: Vec<VarInfo> = inputs
        .iter()
        .enumerate()
        .map(|(i, column)| array(column.elem_type(), &format!("in{i}")))
        .collect();
    let output = VarId(vars.len() as u32);
    vars.push(array(output_type, "out"));
    let input_vars: Vec<VarId> = (0..inputs.len() as u32).map(VarId).collect();
    let mut named_args = Vec::new();
    for (i, param) in signature.named.iter().enumerate() {
        let value = named
            .get(i)
            .copied()
            .or(param.default)
            .ok_or_else(|| RunError::bad_input(format!("`{name}` needs `{}`", param.name)))?;
        named_args.push((param.name.to_string(), HostExpr::Const(value)));
    }
    let k = HostExpr::Const(HostValue::Int(group as i64));
    let (kind, indexed) = match signature.kind {
        FunctorKind::Map | FunctorKind::Monoid(_) => (OpKind::Map, false),
        FunctorKind::Group => (OpKind::GroupGather { group: k }, true),
        FunctorKind::Expand => (OpKind::Expand { fanout: k }, true),
    };
    let op = Op {
        kind,
        functor: Some(name.to_string()),
        inputs: input_vars.clone(),
        outputs: vec![output],
        named: named_args,
        span: Span::default(),
    };
    let stage = Stage {
        ops: vec![op],
        index_space: None,
        reads_direct: if indexed {
            Vec::new()
        } else {
            input_vars.clone()
        },
        reads_indexed: if indexed {
            input_vars.clone()
        } else {
            Vec::new()
        },
        reads_uniform: Vec::new(),
        materialises: vec![output],
        barrier: Barrier::ControlFlow,
        inner: None,
    };
    let plan = Plan {
        pipeline: format!("run {name}"),
        fused: true,
        params: Vec::new(),
        vars,
        body: vec![
            Node::Stage(stage),
            Node::Output {
                name: "out".into(),
                var: output,
            },
        ],
        outputs: vec!["out".into()],
    };
    let uploaded = input_vars
        .iter()
        .zip(inputs)
        .map(|(var, column)| Ok((*var, upload(context.gpu, column).map_err(RunError::from)?)))
        .collect::<Result<Vec<_>, RunError>>()?;
    let result = run_plan_gpu_with_inputs(&plan, context, uploaded, Default::default())?;
    match result.outputs.into_iter().next() {
        Some((_, OutputValue::Array(column))) => Ok(std::sync::Arc::unwrap_or_clone(column)),
        _ => Err(RunError::internal("the functor produced no array")),
    }
}
