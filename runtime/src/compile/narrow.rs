//! Pass 5, before CSE: records are read, gathered and stored only in the
//! fields that are read.
//!
//! 1. A gathered record that is only read field by field gathers only those
//!    fields. `s = gather(i, surf)` followed by `s.normal` and `s.view`
//!    becomes `gather(i, surf.normal)` and `gather(i, surf.view)`: a gather
//!    copies every field of a record, where the shading of
//!    `pipelines/workload2_expressions.dpp` reads six of `Surface`'s ten. A
//!    field of a whole array is a view (no copy), so nothing else is added.
//!    Only where it cannot change a value: the record is written once and
//!    read nowhere but by field reads in the gather's own block, after it,
//!    and neither the index nor the source is written between the gather
//!    and its last field read.
//! 2. A record made by a map and read only field by field has those fields
//!    read right where it is made, and its readers read them instead: fusion
//!    then stores the fields that later stages read, where it would store
//!    the whole record (on the GPU, a storage buffer per field: a stage
//!    that stored all of `Surface` and `Material` needed 34 of the 32 that
//!    lavapipe allows). Only for a record written once.

use super::cse::{rename_in_host, rename_reads};
use super::ir::*;
use crate::types::ElemType;
use dpp_dsl::Span;

pub fn narrow_records(body: &mut Vec<Node>, vars: &mut Vec<VarInfo>) {
    let (reads, writes) = counts(body, vars);
    narrow_block(body, vars, &reads, &writes);
    let (reads, writes) = counts(body, vars);
    let mut renames = Vec::new();
    read_fields_where_made(body, vars, &reads, &writes, &mut renames);
    // Program-wide: a field read's output may be read outside its block.
    for (from, to) in renames {
        rename_reads(body, from, to);
        for info in vars.iter_mut() {
            if let Some(len) = &mut info.len {
                rename_in_host(len, from, to);
            }
        }
    }
}

/// How many nodes read and write each variable.
fn counts(body: &[Node], vars: &[VarInfo]) -> (Vec<usize>, Vec<usize>) {
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
    (reads, writes)
}

/// Part 2 of the pass, for every record a map makes in `nodes` or the
/// blocks nested in them.
fn read_fields_where_made(
    nodes: &mut Vec<Node>,
    vars: &mut Vec<VarInfo>,
    reads: &[usize],
    writes: &[usize],
    renames: &mut Vec<(VarId, VarId)>,
) {
    let mut position = 0;
    while position < nodes.len() {
        let record = match &nodes[position] {
            Node::Op(op) if op.kind == OpKind::Map => op
                .outputs
                .iter()
                .copied()
                .find(|r| only_read_by_fields(nodes, *r, vars, reads, writes)),
            _ => None,
        };
        let Some(record) = record else {
            position += 1;
            continue;
        };
        // Every field read of `record` in the whole program: outputs, fields.
        let mut field_reads: Vec<(VarId, String, Span)> = Vec::new();
        take_field_reads(nodes, record, &mut field_reads);
        let mut made: Vec<(String, VarId)> = Vec::new();
        let mut inserted = Vec::new();
        for (output, field, span) in field_reads {
            let read = match made.iter().find(|(f, _)| *f == field) {
                Some((_, read)) => *read,
                None => {
                    let read = VarId(vars.len() as u32);
                    // The first reader's name where the user gave one.
                    let name = match &vars[output.0 as usize].name {
                        name if !name.starts_with('%') => name.clone(),
                        _ => format!("{}.{field}", vars[record.0 as usize].name),
                    };
                    vars.push(VarInfo {
                        name,
                        span,
                        ty: vars[output.0 as usize].ty,
                        len: vars[record.0 as usize].len.clone(),
                    });
                    inserted.push(Node::Op(Op {
                        kind: OpKind::Field {
                            field: field.clone(),
                        },
                        functor: None,
                        inputs: vec![record],
                        outputs: vec![read],
                        named: Vec::new(),
                        span,
                    }));
                    made.push((field, read));
                    read
                }
            };
            renames.push((output, read));
        }
        let count = inserted.len();
        nodes.splice(position + 1..position + 1, inserted);
        position += 1 + count;
    }
    for node in nodes.iter_mut() {
        match node {
            Node::For { body, .. } | Node::While { body, .. } => {
                read_fields_where_made(body, vars, reads, writes, renames)
            }
            Node::If {
                then_body,
                else_body,
                ..
            } => {
                read_fields_where_made(then_body, vars, reads, writes, renames);
                read_fields_where_made(else_body, vars, reads, writes, renames);
            }
            _ => {}
        }
    }
}

/// Whether `record` (written once) is a record read only by field reads,
/// each written once, in `nodes` or the blocks nested in them.
fn only_read_by_fields(
    nodes: &[Node],
    record: VarId,
    vars: &[VarInfo],
    reads: &[usize],
    writes: &[usize],
) -> bool {
    if !matches!(
        vars[record.0 as usize].ty,
        VarType::Array(ElemType::Record(_))
    ) || writes[record.0 as usize] != 1
        || reads[record.0 as usize] == 0
    {
        return false;
    }
    let mut field_reads = 0;
    walk_nodes(nodes, &mut |node| {
        if let Node::Op(op) = node {
            if matches!(op.kind, OpKind::Field { .. })
                && op.inputs[0] == record
                && writes[op.outputs[0].0 as usize] == 1
            {
                field_reads += 1;
            }
        }
    });
    field_reads == reads[record.0 as usize]
}

/// Removes every field read of `record` from `nodes` and the blocks nested
/// in them, listing each one's output, field and span.
fn take_field_reads(nodes: &mut Vec<Node>, record: VarId, taken: &mut Vec<(VarId, String, Span)>) {
    nodes.retain(|node| match node {
        Node::Op(op) if op.inputs.first() == Some(&record) => match &op.kind {
            OpKind::Field { field } => {
                taken.push((op.outputs[0], field.clone(), op.span));
                false
            }
            _ => true,
        },
        _ => true,
    });
    for node in nodes.iter_mut() {
        match node {
            Node::For { body, .. } | Node::While { body, .. } => {
                take_field_reads(body, record, taken)
            }
            Node::If {
                then_body,
                else_body,
                ..
            } => {
                take_field_reads(then_body, record, taken);
                take_field_reads(else_body, record, taken);
            }
            _ => {}
        }
    }
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
        let field_type = vars[read.outputs[0].0 as usize].ty;
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
