//! Pass 5, before CSE: a gathered record that is only read field by field
//! gathers only those fields. `s = gather(i, surf)` followed by `s.normal`
//! and `s.view` becomes `gather(i, surf.normal)` and `gather(i, surf.view)`:
//! a gather copies every field of a record, where the shading of
//! `pipelines/workload2_expressions.dpp` reads six of `Surface`'s ten. A
//! field of a whole array is a view (no copy), so nothing else is added.
//!
//! Only where it cannot change a value: the record is written once and read
//! nowhere but by field reads in the gather's own block, after it, and
//! neither the index nor the source is written between the gather and its
//! last field read.

use super::ir::*;
use crate::types::ElemType;

pub fn narrow_record_gathers(body: &mut Vec<Node>, vars: &mut Vec<VarInfo>) {
    let mut reads = vec![0usize; vars.len()];
    let mut writes = vec![0usize; vars.len()];
    walk_nodes(body, &mut |node| {
        node_reads(node)
            .iter()
            .for_each(|v| reads[v.0 as usize] += 1);
        node_writes(node)
            .iter()
            .for_each(|v| writes[v.0 as usize] += 1);
    });
    narrow_block(body, vars, &reads, &writes);
}

fn narrow_block(nodes: &mut Vec<Node>, vars: &mut Vec<VarInfo>, reads: &[usize], writes: &[usize]) {
    for node in nodes.iter_mut() {
        match node {
            Node::For { body, .. } | Node::While { body, .. } => {
                narrow_block(body, vars, reads, writes)
            }
            Node::If {
                then_body,
                else_body,
                ..
            } => {
                narrow_block(then_body, vars, reads, writes);
                narrow_block(else_body, vars, reads, writes);
            }
            _ => {}
        }
    }
    let mut position = 0;
    while position < nodes.len() {
        match narrowable(nodes, position, vars, reads, writes) {
            Some(field_reads) => narrow(nodes, position, &field_reads, vars),
            None => position += 1,
        }
    }
}

/// The positions of the field reads of the gather at `position`, if it can be narrowed.
fn narrowable(
    nodes: &[Node],
    position: usize,
    vars: &[VarInfo],
    reads: &[usize],
    writes: &[usize],
) -> Option<Vec<usize>> {
    let Node::Op(gather) = &nodes[position] else {
        return None;
    };
    if gather.kind != OpKind::Gather {
        return None;
    }
    let (index, source, record) = (gather.inputs[0], gather.inputs[1], gather.outputs[0]);
    if !matches!(
        vars[record.0 as usize].ty,
        VarType::Array(ElemType::Record(_))
    ) || writes[record.0 as usize] != 1
    {
        return None;
    }
    let field_reads: Vec<usize> = (position + 1..nodes.len())
        .filter(|&p| {
            matches!(&nodes[p], Node::Op(op)
                if matches!(op.kind, OpKind::Field { .. }) && op.inputs[0] == record)
        })
        .collect();
    let last = *field_reads.last()?;
    if field_reads.len() != reads[record.0 as usize] {
        return None;
    }
    let mut rewritten = false;
    walk_nodes(&nodes[position + 1..last], &mut |node| {
        rewritten |= node_writes(node)
            .iter()
            .any(|v| *v == index || *v == source);
    });
    (!rewritten).then_some(field_reads)
}

/// Replaces each field read `x = g.f` by `y = source.f; x = gather(index, y)`
/// and drops the gather.
fn narrow(nodes: &mut Vec<Node>, position: usize, field_reads: &[usize], vars: &mut Vec<VarInfo>) {
    let Node::Op(gather) = nodes.remove(position) else {
        unreachable!("`narrowable` found a gather here")
    };
    let (index, source) = (gather.inputs[0], gather.inputs[1]);
    // Each later node moved one place back; each replacement adds one node.
    for (added, &p) in field_reads.iter().enumerate() {
        let at = p - 1 + added;
        let Node::Op(read) = nodes.remove(at) else {
            unreachable!("`narrowable` found a field read here")
        };
        let field_type = vars[read.outputs[0].0 as usize].ty.clone();
        let view = VarId(vars.len() as u32);
        let OpKind::Field { field } = &read.kind else {
            unreachable!("`narrowable` found a field read here")
        };
        vars.push(VarInfo {
            name: format!("{}.{field}", vars[source.0 as usize].name),
            span: read.span,
            ty: field_type,
            len: vars[source.0 as usize].len.clone(),
        });
        let field_of_source = Op {
            inputs: vec![source],
            outputs: vec![view],
            ..read.clone()
        };
        let gathered = Op {
            kind: OpKind::Gather,
            functor: None,
            inputs: vec![index, view],
            outputs: read.outputs,
            named: Vec::new(),
            span: read.span,
        };
        nodes.insert(at, Node::Op(gathered));
        nodes.insert(at, Node::Op(field_of_source));
    }
}
