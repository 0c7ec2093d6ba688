//! Pass 5: common-subexpression elimination. An op that applies the same
//! primitive and functor to the same values as an earlier op (no input
//! rewritten in between) reuses the earlier op's results. Nested blocks see
//! what their enclosing blocks computed before them; a loop body sees none of
//! the values its iterations rewrite.

use super::ir::*;
use std::collections::HashMap;

pub fn eliminate_common_subexpressions(body: &mut Vec<Node>, vars: &mut [VarInfo]) {
    let mut definitions = vec![0u32; vars.len()];
    walk_nodes(body, &mut |node| {
        for v in node_writes(node) {
            definitions[v.0 as usize] += 1;
        }
    });
    let mut renames: Vec<(VarId, VarId)> = Vec::new();
    cse_block(body, &definitions, &mut renames, Available::default());
    for (from, to) in renames {
        rename_reads(body, from, to);
        for info in vars.iter_mut() {
            if let Some(len) = &mut info.len {
                rename_in_host(len, from, to);
            }
        }
    }
}

/// What is computed at a point of the program.
#[derive(Clone, Default)]
struct Available {
    /// How many times each variable has been written so far.
    generation: HashMap<VarId, u32>,
    /// Op keys and their results with the generation they were computed at.
    seen: HashMap<String, Vec<(VarId, u32)>>,
}

fn cse_block(
    nodes: &mut Vec<Node>,
    definitions: &[u32],
    renames: &mut Vec<(VarId, VarId)>,
    available: Available,
) {
    let Available {
        mut generation,
        mut seen,
    } = available;
    let mut kept = Vec::with_capacity(nodes.len());
    for mut node in nodes.drain(..) {
        // Earlier eliminations rename reads before the key is computed.
        for (from, to) in renames.iter() {
            rename_reads(std::slice::from_mut(&mut node), *from, *to);
        }
        match &mut node {
            Node::Op(op) => {
                let key = op_key(op, &generation);
                let reusable = seen.get(&key).filter(|previous| {
                    previous
                        .iter()
                        .all(|(v, g)| generation.get(v).copied().unwrap_or(0) == *g)
                });
                // Only single-definition results can be renamed program-wide, and
                // only to single-definition results: a slot may be rewritten later.
                if let Some(previous) = reusable {
                    if op
                        .outputs
                        .iter()
                        .chain(previous.iter().map(|(o, _)| o))
                        .all(|o| definitions[o.0 as usize] == 1)
                    {
                        for (new, (old, _)) in op.outputs.iter().zip(previous) {
                            renames.push((*new, *old));
                        }
                        continue;
                    }
                }
                for o in &op.outputs {
                    *generation.entry(*o).or_default() += 1;
                }
                let outputs = op.outputs.iter().map(|o| (*o, generation[o])).collect();
                seen.insert(key, outputs);
            }
            Node::For { body, .. } | Node::While { body, .. } => {
                // Values rewritten by any iteration differ from those before the loop.
                bump_nested_writes(body, &mut generation);
                let inside = Available {
                    generation: generation.clone(),
                    seen: seen.clone(),
                };
                cse_block(body, definitions, renames, inside);
            }
            Node::If {
                then_body,
                else_body,
                ..
            } => {
                let inside = Available {
                    generation: generation.clone(),
                    seen: seen.clone(),
                };
                cse_block(then_body, definitions, renames, inside.clone());
                cse_block(else_body, definitions, renames, inside);
                bump_nested_writes(then_body, &mut generation);
                bump_nested_writes(else_body, &mut generation);
            }
            Node::Composite(composite) => {
                // The blend sees only its pieces (a fn's body sees none of the
                // caller's names), so it starts from nothing computed.
                cse_block(
                    &mut composite.blend,
                    definitions,
                    renames,
                    Available::default(),
                );
                for v in node_writes(&node) {
                    *generation.entry(v).or_default() += 1;
                }
            }
            other => {
                for v in node_writes(other) {
                    *generation.entry(v).or_default() += 1;
                }
            }
        }
        kept.push(node);
    }
    *nodes = kept;
}

fn bump_nested_writes(body: &[Node], generation: &mut HashMap<VarId, u32>) {
    walk_nodes(body, &mut |node| {
        for v in node_writes(node) {
            *generation.entry(v).or_default() += 1;
        }
    });
}

/// A textual key of what an op computes, with the generation of every variable it reads.
fn op_key(op: &Op, generation: &HashMap<VarId, u32>) -> String {
    let mut reads = Vec::new();
    for v in op.array_reads() {
        reads.push(v);
    }
    for e in op.host_exprs() {
        e.visit_vars(&mut |v| reads.push(v));
    }
    let versions: Vec<String> = reads
        .iter()
        .map(|v| format!("{}@{}", v.0, generation.get(v).copied().unwrap_or(0)))
        .collect();
    format!(
        "{:?}|{:?}|{:?}|{:?}|{}",
        op.kind,
        op.functor,
        op.inputs,
        op.named,
        versions.join(",")
    )
}

/// Replaces every read of `from` with `to` in `nodes`, nested bodies included.
pub fn rename_reads(nodes: &mut [Node], from: VarId, to: VarId) {
    let swap = |v: &mut VarId| {
        if *v == from {
            *v = to;
        }
    };
    for node in nodes {
        match node {
            Node::Op(op) => rename_in_op(op, from, to),
            Node::Stage(stage) => stage
                .ops
                .iter_mut()
                .for_each(|op| rename_in_op(op, from, to)),
            Node::Host { expr, .. } => rename_in_host(expr, from, to),
            Node::Alias { src, .. } | Node::View { src, .. } => swap(src),
            Node::For {
                start, end, body, ..
            } => {
                rename_in_host(start, from, to);
                rename_in_host(end, from, to);
                rename_reads(body, from, to);
            }
            Node::While { cond, body, .. } => {
                rename_in_host(cond, from, to);
                rename_reads(body, from, to);
            }
            Node::If {
                cond,
                then_body,
                else_body,
                ..
            } => {
                rename_in_host(cond, from, to);
                rename_reads(then_body, from, to);
                rename_reads(else_body, from, to);
            }
            Node::Output { var, .. } => swap(var),
            Node::Composite(composite) => {
                composite.inputs.iter_mut().for_each(swap);
                composite.blended.iter_mut().for_each(swap);
                rename_in_host(&mut composite.visibility, from, to);
                rename_reads(&mut composite.blend, from, to);
            }
            Node::Break => {}
        }
    }
}

fn rename_in_op(op: &mut Op, from: VarId, to: VarId) {
    for v in op.inputs.iter_mut() {
        if *v == from {
            *v = to;
        }
    }
    match &mut op.kind {
        OpKind::Scatter { target, mask, .. } => {
            if let ScatterTarget::Into(dst) = target {
                if *dst == from {
                    *dst = to;
                }
            }
            if let ScatterTarget::Len(len) = target {
                rename_in_host(len, from, to);
            }
            if *mask == Some(from) {
                *mask = Some(to);
            }
        }
        OpKind::Scan { segments, .. } if *segments == Some(from) => *segments = Some(to),
        OpKind::Iota { count } => rename_in_host(count, from, to),
        OpKind::Fill { count, value } => {
            rename_in_host(count, from, to);
            rename_in_host(value, from, to);
        }
        OpKind::GroupGather { group: e } | OpKind::Expand { fanout: e } => {
            rename_in_host(e, from, to)
        }
        _ => {}
    }
    for (_, e) in op.named.iter_mut() {
        rename_in_host(e, from, to);
    }
}

pub(super) fn rename_in_host(expr: &mut HostExpr, from: VarId, to: VarId) {
    match expr {
        HostExpr::Var(v) | HostExpr::Len(v) => {
            if *v == from {
                *v = to;
            }
        }
        HostExpr::Unary(_, e) => rename_in_host(e, from, to),
        HostExpr::Binary(_, a, b) => {
            rename_in_host(a, from, to);
            rename_in_host(b, from, to);
        }
        HostExpr::Call(_, args) => args.iter_mut().for_each(|a| rename_in_host(a, from, to)),
        HostExpr::Const(_) | HostExpr::Uniform { .. } => {}
    }
}
