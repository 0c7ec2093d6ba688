//! Pass 6: group ops into stages (spec §5). With fusion on, consecutive ops
//! over the same index space share a stage: map → map (rule 1), a gather's
//! indexed read moves into its consumer (rule 2), and a map runs inside the
//! scatter, reduce or scan that consumes it (rule 3). Stages end at the
//! barriers of rule 4. An intermediate that nothing outside its stage reads is
//! never materialised.

use super::ir::*;
use super::typecheck::node_writes;
use std::collections::HashSet;

pub fn form_stages(body: Vec<Node>, vars: &[VarInfo], fuse: bool) -> Vec<Node> {
    let mut usage = Usage {
        reads: vec![0; vars.len()],
        definitions: vec![0; vars.len()],
        outputs: HashSet::new(),
    };
    walk_nodes(&body, &mut |node| {
        let mut distinct: Vec<VarId> = node_reads(node);
        distinct.sort();
        distinct.dedup();
        for v in distinct {
            usage.reads[v.0 as usize] += 1;
        }
        for v in node_writes(node) {
            usage.definitions[v.0 as usize] += 1;
        }
        if let Node::Output { var, .. } = node {
            usage.outputs.insert(*var);
        }
    });
    let former = StageFormer { vars, usage, fuse };
    former.block(body)
}

struct Usage {
    /// Number of nodes (ops counted one by one) that read each variable.
    reads: Vec<u32>,
    definitions: Vec<u32>,
    outputs: HashSet<VarId>,
}

struct StageFormer<'a> {
    vars: &'a [VarInfo],
    usage: Usage,
    fuse: bool,
}

/// A stage being built.
struct OpenStage {
    ops: Vec<Op>,
    index_space: Option<HostExpr>,
    /// Variables written by the stage's ops.
    locals: HashSet<VarId>,
}

impl StageFormer<'_> {
    fn block(&self, nodes: Vec<Node>) -> Vec<Node> {
        let mut out = Vec::new();
        let mut open: Option<OpenStage> = None;
        for node in nodes {
            match node {
                Node::Op(op) => {
                    if let Some(stage) = open.take() {
                        match self.joins(&stage, &op) {
                            Ok(()) => open = Some(stage),
                            Err(barrier) => out.push(self.close(stage, barrier)),
                        }
                    }
                    let stage = open.get_or_insert_with(|| OpenStage {
                        index_space: self.index_space(&op),
                        ops: Vec::new(),
                        locals: HashSet::new(),
                    });
                    stage.locals.extend(op.outputs.iter().copied());
                    let sink = match op.kind {
                        OpKind::Scan { .. } => Some(Barrier::Scan),
                        OpKind::Reduce { .. } => Some(Barrier::Reduce),
                        OpKind::Scatter { .. } => Some(Barrier::Scatter),
                        _ => None,
                    };
                    stage.ops.push(op);
                    if !self.fuse {
                        out.push(self.close(open.take().unwrap(), Barrier::Unfused));
                    } else if let Some(barrier) = sink {
                        out.push(self.close(open.take().unwrap(), barrier));
                    }
                }
                other => {
                    if let Some(stage) = open.take() {
                        out.push(self.close(stage, Barrier::ControlFlow));
                    }
                    out.push(match other {
                        Node::For {
                            var,
                            start,
                            end,
                            body,
                            span,
                        } => Node::For {
                            var,
                            start,
                            end,
                            body: self.block(body),
                            span,
                        },
                        Node::While { cond, body, span } => Node::While {
                            cond,
                            body: self.block(body),
                            span,
                        },
                        Node::If {
                            span,
                            cond,
                            then_body,
                            else_body,
                        } => Node::If {
                            span,
                            cond,
                            then_body: self.block(then_body),
                            else_body: self.block(else_body),
                        },
                        other => other,
                    });
                }
            }
        }
        if let Some(stage) = open.take() {
            out.push(self.close(stage, Barrier::ControlFlow));
        }
        out
    }

    fn len_of(&self, var: VarId) -> HostExpr {
        self.vars[var.0 as usize]
            .len
            .clone()
            .unwrap_or(HostExpr::Len(var))
    }

    /// `len(v)` replaced by `v`'s symbolic length wherever type checking knows it,
    /// so `iota(len(keep))` and a map over `keep` have the same index space.
    fn canonical(&self, expr: HostExpr) -> HostExpr {
        match expr {
            HostExpr::Len(v) => match &self.vars[v.0 as usize].len {
                Some(len) if *len != HostExpr::Len(v) => self.canonical(len.clone()),
                _ => HostExpr::Len(v),
            },
            HostExpr::Unary(op, e) => HostExpr::Unary(op, Box::new(self.canonical(*e))),
            HostExpr::Binary(op, a, b) => HostExpr::Binary(
                op,
                Box::new(self.canonical(*a)),
                Box::new(self.canonical(*b)),
            ),
            HostExpr::Call(f, args) => {
                HostExpr::Call(f, args.into_iter().map(|a| self.canonical(a)).collect())
            }
            other => other,
        }
    }

    /// The number of elements an op runs over (its input side for sinks).
    fn index_space(&self, op: &Op) -> Option<HostExpr> {
        self.raw_index_space(op).map(|e| self.canonical(e))
    }

    fn raw_index_space(&self, op: &Op) -> Option<HostExpr> {
        match &op.kind {
            OpKind::Iota { count } | OpKind::Fill { count, .. } => Some(count.clone()),
            _ => op.outputs.first().and_then(|o| match op.kind {
                OpKind::Map
                | OpKind::Field { .. }
                | OpKind::GroupGather { .. }
                | OpKind::Expand { .. } => self.vars[o.0 as usize].len.clone(),
                _ => op.inputs.first().map(|i| self.len_of(*i)),
            }),
        }
    }

    /// Whether `op` may run inside `stage`, or the barrier that ends the stage.
    fn joins(&self, stage: &OpenStage, op: &Op) -> Result<(), Barrier> {
        if !self.fuse {
            return Err(Barrier::Unfused);
        }
        if matches!(op.kind, OpKind::GroupGather { .. } | OpKind::Expand { .. }) {
            return Err(Barrier::LengthChange);
        }
        if self.index_space(op) != stage.index_space || stage.index_space.is_none() {
            return Err(Barrier::LengthChange);
        }
        // Arrays read through an index, and host values, must exist before the stage starts.
        let mut needs_whole: Vec<VarId> = match &op.kind {
            OpKind::Gather => vec![op.inputs[1]],
            OpKind::Scatter {
                target: ScatterTarget::Into(dst),
                ..
            } => vec![*dst],
            _ => Vec::new(),
        };
        for e in op.host_exprs() {
            e.visit_vars(&mut |v| needs_whole.push(v));
        }
        if needs_whole.iter().any(|v| stage.locals.contains(v)) {
            return Err(Barrier::IndexedRead);
        }
        Ok(())
    }

    fn close(&self, stage: OpenStage, barrier: Barrier) -> Node {
        let mut reads_in_stage = vec![0u32; 0];
        reads_in_stage.resize(self.vars.len(), 0);
        for op in &stage.ops {
            let mut distinct = op.array_reads();
            for e in op.host_exprs() {
                e.visit_vars(&mut |v| distinct.push(v));
            }
            distinct.sort();
            distinct.dedup();
            for v in distinct {
                reads_in_stage[v.0 as usize] += 1;
            }
        }
        let mut materialises = Vec::new();
        let mut reads_direct = Vec::new();
        let mut reads_indexed = Vec::new();
        let mut reads_uniform = Vec::new();
        let mut written: HashSet<VarId> = HashSet::new();
        for op in &stage.ops {
            let (direct, indexed): (Vec<VarId>, Vec<VarId>) = match &op.kind {
                OpKind::Gather => (vec![op.inputs[0]], vec![op.inputs[1]]),
                OpKind::GroupGather { .. } | OpKind::Expand { .. } => {
                    (Vec::new(), op.inputs.clone())
                }
                OpKind::Scatter { target, mask, .. } => {
                    let mut direct = op.inputs.clone();
                    direct.extend(mask);
                    let indexed = match target {
                        ScatterTarget::Into(dst) => vec![*dst],
                        ScatterTarget::Len(_) => Vec::new(),
                    };
                    (direct, indexed)
                }
                OpKind::Scan { segments, .. } => {
                    let mut direct = op.inputs.clone();
                    direct.extend(segments);
                    (direct, Vec::new())
                }
                _ => (op.inputs.clone(), Vec::new()),
            };
            for v in direct {
                if !written.contains(&v) && !reads_direct.contains(&v) {
                    reads_direct.push(v);
                }
            }
            for v in indexed {
                if !reads_indexed.contains(&v) {
                    reads_indexed.push(v);
                }
            }
            for e in op.host_exprs() {
                collect_uniforms(e, self.vars, &mut reads_uniform);
            }
            for &o in &op.outputs {
                written.insert(o);
                let i = o.0 as usize;
                let read_elsewhere = self.usage.reads[i] > reads_in_stage[i];
                let keep = !self.fuse
                    || self.usage.definitions[i] > 1
                    || self.usage.outputs.contains(&o)
                    || read_elsewhere
                    || matches!(
                        op.kind,
                        OpKind::Reduce { .. } | OpKind::Scan { .. } | OpKind::Scatter { .. }
                    );
                if keep && !materialises.contains(&o) {
                    materialises.push(o);
                }
            }
        }
        Node::Stage(Stage {
            ops: stage.ops,
            index_space: stage.index_space,
            reads_direct,
            reads_indexed,
            reads_uniform,
            materialises,
            barrier,
        })
    }
}

fn collect_uniforms(expr: &HostExpr, vars: &[VarInfo], out: &mut Vec<String>) {
    let mut push = |name: String| {
        if !out.contains(&name) {
            out.push(name);
        }
    };
    match expr {
        HostExpr::Uniform { record, field } => push(format!("{record}.{field}")),
        HostExpr::Var(v) => push(vars[v.0 as usize].name.clone()),
        HostExpr::Len(v) => push(format!("len({})", vars[v.0 as usize].name)),
        HostExpr::Const(_) => {}
        HostExpr::Unary(_, e) => collect_uniforms(e, vars, out),
        HostExpr::Binary(_, a, b) => {
            collect_uniforms(a, vars, out);
            collect_uniforms(b, vars, out);
        }
        HostExpr::Call(_, args) => args.iter().for_each(|a| collect_uniforms(a, vars, out)),
    }
}
