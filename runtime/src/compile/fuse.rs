//! Pass 6: group ops into stages (docs/language.md §6). With fusion on,
//! consecutive ops over the same index space share a stage:
//! map → map (rule 1), a gather's indexed read moves into its consumer
//! (rule 2), and a map runs inside the scatter, reduce, scan or sort that
//! consumes it (rule 3). Stages end at the barriers of rule 4. An intermediate that
//! nothing outside its stage reads is never materialised. A group gather
//! whose groups are made by the open stage, and read by nothing else, closes
//! an inner level of it (rule 5): the stage goes on over the groups.
//!
//! A scatter is not a barrier (rule 4 does not list it): ops after it go on
//! in its stage, so one stage can end in several scatters (a tracer's
//! colour, depth and alpha images from one pass over the rays). Its result is
//! complete only when the stage ends, so an op that reads it, or rewrites what
//! it reads or writes, starts a new stage. An `out` statement does not end a
//! stage either: it moves after the stage that makes its value.

use super::ir::*;
use crate::host::HostValue;
use dpp_dsl::ast::BinaryOp;
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
        match node {
            Node::Output { var, .. } => {
                usage.outputs.insert(*var);
            }
            // What a blend returns leaves it for the compositor, as an output does.
            Node::Composite(composite) => usage.outputs.extend(&composite.blended),
            _ => {}
        }
    });
    let mut mentioned_by = vec![Vec::new(); vars.len()];
    for (index, info) in vars.iter().enumerate() {
        if let Some(len) = &info.len {
            len.visit_vars(&mut |v| {
                if v.0 as usize != index {
                    mentioned_by[v.0 as usize].push(VarId(index as u32));
                }
            });
        }
    }
    let mut former = StageFormer {
        vars,
        usage,
        fuse,
        mentioned_by,
        stale: HashSet::new(),
    };
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
    /// For each variable, the variables whose symbolic length mentions it.
    mentioned_by: Vec<Vec<VarId>>,
    /// Variables whose symbolic length no longer holds at this point of the
    /// program: a slot or host value it mentions was written since.
    stale: HashSet<VarId>,
}

/// A stage being built.
struct OpenStage {
    ops: Vec<Op>,
    index_space: Option<HostExpr>,
    /// Once a group gather has closed an inner level (rule 5): the number of
    /// ops before it and their index space.
    inner: Option<(usize, Option<HostExpr>)>,
    /// Variables written by the stage's ops.
    locals: HashSet<VarId>,
    /// Results of the stage's scatters, complete only when the stage ends.
    scattered: HashSet<VarId>,
    /// Arrays the stage's scatters read: they must keep their values until it ends.
    scatter_reads: HashSet<VarId>,
    /// `out` statements of values the stage makes, placed after it.
    outputs: Vec<Node>,
}

impl OpenStage {
    /// Whether an op of the stage reads `var`.
    fn reads(&self, var: VarId) -> bool {
        self.ops
            .iter()
            .any(|op| node_reads(&Node::Op(op.clone())).contains(&var))
    }

    fn output_vars(&self) -> impl Iterator<Item = VarId> + '_ {
        self.outputs.iter().filter_map(|node| match node {
            Node::Output { var, .. } => Some(*var),
            _ => None,
        })
    }
}

impl StageFormer<'_> {
    /// `var` gets a new value: its own length holds again, and the lengths that
    /// mention it no longer do.
    fn wrote(&mut self, var: VarId) {
        self.stale.remove(&var);
        for &other in &self.mentioned_by[var.0 as usize] {
            self.stale.insert(other);
        }
    }

    fn block(&mut self, nodes: Vec<Node>) -> Vec<Node> {
        let mut out = Vec::new();
        // The stage being built, and a second one over another length whose ops
        // share nothing with it: it runs first, so an op between a map and its
        // scatter (`into: fill(m, 0)`) does not split them.
        let mut open: Option<OpenStage> = None;
        let mut side: Option<OpenStage> = None;
        for node in nodes {
            match node {
                // A field of an array made before the open stages is a view: no
                // stage, no copy (placed before them; they do not touch its source).
                Node::Op(op)
                    if matches!(op.kind, OpKind::Field { .. })
                        && [&open, &side].iter().all(|stage| {
                            !stage.as_ref().is_some_and(|s| {
                                s.locals.contains(&op.inputs[0]) || s.reads(op.outputs[0])
                            })
                        }) =>
                {
                    self.wrote(op.outputs[0]);
                    let OpKind::Field { field } = op.kind else {
                        unreachable!()
                    };
                    out.push(Node::View {
                        dst: op.outputs[0],
                        src: op.inputs[0],
                        field,
                    });
                }
                // A host value that reads nothing the open stages make, which
                // they do not read as it was, is computed before them (a `fn`'s
                // host argument, a param's arithmetic): it does not end them.
                Node::Host { dst, .. }
                    if self.fuse
                        && [&open, &side].iter().all(|stage| {
                            !stage.as_ref().is_some_and(|s| {
                                s.reads(dst)
                                    || node_reads(&node).iter().any(|v| s.locals.contains(v))
                            })
                        }) =>
                {
                    self.wrote(dst);
                    out.push(node);
                }
                Node::Output { var, .. } if self.fuse => {
                    // After the stage that makes the value, or here if none open does.
                    match [&mut side, &mut open]
                        .into_iter()
                        .flatten()
                        .find(|stage| stage.locals.contains(&var))
                    {
                        Some(stage) => stage.outputs.push(node),
                        None => out.push(node),
                    }
                }
                Node::Op(mut op) => {
                    // A group gather that closes an inner level turns the stage
                    // that makes its input into a nested one, over the groups.
                    if let Some(stage) = open.as_mut().filter(|stage| self.closes_level(stage, &op))
                    {
                        // The side stage runs before the open one anyway.
                        if let Some(side) = side.take() {
                            out.extend(self.close(side, Barrier::LengthChange));
                        }
                        self.open_level(stage, &op);
                    } else if let Some(stage) =
                        side.as_mut().filter(|stage| self.closes_level(stage, &op))
                    {
                        self.open_level(stage, &op);
                    }
                    let joins_open = open.as_ref().map(|stage| self.joins(stage, &op));
                    let independent = open
                        .as_ref()
                        .is_some_and(|stage| self.independent_of(stage, &op));
                    let side_fits = side
                        .as_ref()
                        .is_some_and(|stage| self.joins(stage, &op).is_ok());
                    let into_side = match (joins_open, independent, side.is_some()) {
                        (Some(Ok(())), _, _) => false,
                        _ if independent && side_fits => true,
                        (Some(Err(_)), true, false) => true,
                        // It needs the open stage's results: that stage ends, and the
                        // side stage (independent of it) carries on as the open one,
                        // unless the open stage reads what the side stage makes: then
                        // the side stage must run first, and both end.
                        _ if side_fits => {
                            let side_first =
                                open.as_ref()
                                    .zip(side.as_ref())
                                    .is_some_and(|(open, side)| {
                                        side.locals.iter().any(|&v| open.reads(v))
                                    });
                            if side_first {
                                for stage in [side.take(), open.take()].into_iter().flatten() {
                                    out.extend(self.close(stage, Barrier::LengthChange));
                                }
                            } else {
                                if let Some(stage) = open.take() {
                                    out.extend(self.close(stage, Barrier::LengthChange));
                                }
                                open = side.take();
                            }
                            false
                        }
                        (joins_open, _, _) => {
                            let barrier = match joins_open {
                                Some(Err(barrier)) => barrier,
                                _ => Barrier::ControlFlow,
                            };
                            for stage in [side.take(), open.take()].into_iter().flatten() {
                                out.extend(self.close(stage, barrier));
                            }
                            false
                        }
                    };
                    let target = if into_side { &mut side } else { &mut open };
                    let stage = target.get_or_insert_with(|| OpenStage {
                        index_space: self.index_space(&op),
                        inner: None,
                        ops: Vec::new(),
                        locals: HashSet::new(),
                        scattered: HashSet::new(),
                        scatter_reads: HashSet::new(),
                        outputs: Vec::new(),
                    });
                    // `len(v)` of a value the stage makes does not exist before
                    // the stage runs: `joins` checked that its symbolic length does.
                    let reads_before = node_reads(&Node::Op(op.clone()));
                    for expr in op.host_exprs_mut() {
                        *expr = self.detached(expr, &stage.locals);
                    }
                    let reads_after = node_reads(&Node::Op(op.clone()));
                    let mut no_longer_read: Vec<VarId> = reads_before
                        .into_iter()
                        .filter(|v| !reads_after.contains(v))
                        .collect();
                    no_longer_read.sort();
                    no_longer_read.dedup();
                    for v in no_longer_read {
                        self.usage.reads[v.0 as usize] -= 1;
                    }
                    stage.locals.extend(op.outputs.iter().copied());
                    if matches!(op.kind, OpKind::Scatter { .. }) {
                        stage.scattered.extend(op.outputs.iter().copied());
                        stage.scatter_reads.extend(op.array_reads());
                    }
                    for &output in &op.outputs {
                        self.wrote(output);
                    }
                    let sink = match op.kind {
                        OpKind::Scan { .. } => Some(Barrier::Scan),
                        OpKind::Sort { .. } => Some(Barrier::Sort),
                        OpKind::Reduce { .. } => Some(Barrier::Reduce),
                        _ => None,
                    };
                    stage.ops.push(op);
                    let barrier = if self.fuse {
                        sink
                    } else {
                        Some(Barrier::Unfused)
                    };
                    if let Some(barrier) = barrier {
                        // The side stage always runs before the open one.
                        if let Some(stage) = side.take() {
                            let side_barrier = if into_side {
                                barrier
                            } else {
                                Barrier::LengthChange
                            };
                            out.extend(self.close(stage, side_barrier));
                        }
                        if !into_side {
                            if let Some(stage) = open.take() {
                                out.extend(self.close(stage, barrier));
                            }
                        }
                    }
                }
                other => {
                    for stage in [side.take(), open.take()].into_iter().flatten() {
                        out.extend(self.close(stage, Barrier::ControlFlow));
                    }
                    // A loop body runs again after its own writes: what it writes
                    // is rewritten before its first node too.
                    for var in node_writes(&other) {
                        self.wrote(var);
                    }
                    let body = match &other {
                        Node::For { body, .. } | Node::While { body, .. } => Some(body),
                        // A blend runs once per exchange, like a loop body.
                        Node::Composite(composite) => Some(&composite.blend),
                        _ => None,
                    };
                    if let Some(body) = body {
                        let mut written = Vec::new();
                        walk_nodes(body, &mut |node| written.extend(node_writes(node)));
                        for var in written {
                            self.wrote(var);
                        }
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
                        Node::Composite(mut composite) => {
                            composite.blend = self.block(std::mem::take(&mut composite.blend));
                            Node::Composite(composite)
                        }
                        other => other,
                    });
                }
            }
        }
        for stage in [side.take(), open.take()].into_iter().flatten() {
            out.extend(self.close(stage, Barrier::ControlFlow));
        }
        out
    }

    /// `len(v)` replaced by `v`'s symbolic length wherever type checking knows it
    /// and it still holds, so `iota(len(keep))` and a map over `keep` have the
    /// same index space.
    fn canonical(&self, expr: HostExpr) -> HostExpr {
        match expr {
            HostExpr::Len(v) => match &self.vars[v.0 as usize].len {
                Some(len) if *len != HostExpr::Len(v) && !self.stale.contains(&v) => {
                    self.canonical(len.clone())
                }
                _ => HostExpr::Len(v),
            },
            HostExpr::Unary(op, e) => HostExpr::Unary(op, Box::new(self.canonical(*e))),
            // `n / 1` and `n * 1`, the lengths of groups and fan-outs of one, are `n`.
            HostExpr::Binary(BinaryOp::Div | BinaryOp::Mul, a, b)
                if *b == HostExpr::Const(HostValue::Int(1)) =>
            {
                self.canonical(*a)
            }
            HostExpr::Binary(op, a, b) => {
                let (a, b) = (self.canonical(*a), self.canonical(*b));
                match (op, &a) {
                    // `n * k / k` is `n`: a group gather's sums of a fan-out's
                    // `len(points) * k` pairs run over the points.
                    (BinaryOp::Div, HostExpr::Binary(BinaryOp::Mul, n, k)) if **k == b => {
                        (**n).clone()
                    }
                    (BinaryOp::Div, HostExpr::Binary(BinaryOp::Mul, k, n)) if **k == b => {
                        (**n).clone()
                    }
                    _ => HostExpr::Binary(op, Box::new(a), Box::new(b)),
                }
            }
            HostExpr::Call(f, args) => {
                HostExpr::Call(f, args.into_iter().map(|a| self.canonical(a)).collect())
            }
            other => other,
        }
    }

    /// `expr` with `len(v)` of each value `v` in `locals` replaced by `v`'s
    /// symbolic length, where that is known and still holds.
    fn detached(&self, expr: &HostExpr, locals: &HashSet<VarId>) -> HostExpr {
        match expr {
            HostExpr::Len(v) if locals.contains(v) => self.canonical(expr.clone()),
            HostExpr::Unary(op, e) => HostExpr::Unary(*op, Box::new(self.detached(e, locals))),
            HostExpr::Binary(op, a, b) => HostExpr::Binary(
                *op,
                Box::new(self.detached(a, locals)),
                Box::new(self.detached(b, locals)),
            ),
            HostExpr::Call(f, args) => {
                HostExpr::Call(*f, args.iter().map(|a| self.detached(a, locals)).collect())
            }
            other => other.clone(),
        }
    }

    /// The number of elements an op runs over (its input side for sinks).
    fn index_space(&self, op: &Op) -> Option<HostExpr> {
        self.raw_index_space(op).map(|e| self.canonical(e))
    }

    /// From the first input's length, not the output's: an output may be a slot,
    /// whose recorded length is only `len` of its previous value.
    fn raw_index_space(&self, op: &Op) -> Option<HostExpr> {
        let input = || Some(HostExpr::Len(*op.inputs.first()?));
        match &op.kind {
            OpKind::Iota { count } | OpKind::Fill { count, .. } => Some(count.clone()),
            OpKind::GroupGather { group } => Some(HostExpr::Binary(
                BinaryOp::Div,
                Box::new(input()?),
                Box::new(group.clone()),
            )),
            OpKind::Expand { fanout } => Some(HostExpr::Binary(
                BinaryOp::Mul,
                Box::new(input()?),
                Box::new(fanout.clone()),
            )),
            _ => input(),
        }
    }

    /// Whether `op` may run inside `stage`, or the barrier that ends the stage.
    fn joins(&self, stage: &OpenStage, op: &Op) -> Result<(), Barrier> {
        if !self.fuse {
            return Err(Barrier::Unfused);
        }
        let closes_inner = stage.inner.as_ref().map(|(ops, _)| *ops) == Some(stage.ops.len());
        if matches!(op.kind, OpKind::GroupGather { .. } | OpKind::Expand { .. })
            && !is_elementwise_group(op)
            && !closes_inner
        {
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
            self.detached(e, &stage.locals)
                .visit_vars(&mut |v| needs_whole.push(v));
        }
        if needs_whole.iter().any(|v| stage.locals.contains(v)) {
            return Err(Barrier::IndexedRead);
        }
        // A scatter's result is complete, and what it reads free to change, only
        // once its stage has ended.
        if op.array_reads().iter().any(|v| stage.scattered.contains(v))
            || op
                .outputs
                .iter()
                .any(|v| stage.scattered.contains(v) || stage.scatter_reads.contains(v))
        {
            return Err(Barrier::Scatter);
        }
        // An `out` placed after the stage must see the value it named.
        if op
            .outputs
            .iter()
            .any(|v| stage.output_vars().any(|o| o == *v))
        {
            return Err(Barrier::ControlFlow);
        }
        Ok(())
    }

    /// Whether the group gather `op` closes an inner level of `stage` (rule
    /// 5): it sums (or otherwise folds) groups of a value `stage` makes, and
    /// nothing but `op` and the stage's own ops reads any value the stage
    /// makes, so the stage may run a group's elements inside `op`'s element.
    fn closes_level(&self, stage: &OpenStage, op: &Op) -> bool {
        let OpKind::GroupGather { group } = &op.kind else {
            return false;
        };
        if !self.fuse
            || is_elementwise_group(op)
            || stage.inner.is_some()
            || stage.index_space.is_none()
            || self.index_space(op).is_none()
            || !stage.locals.contains(&op.inputs[0])
            || stage.ops.iter().any(Op::is_sink)
        {
            return false;
        }
        // A chunk of the stage's elements holds whole groups of the inner
        // level; a fan-out at its head must then hand out groups of the same size.
        if let OpKind::Expand { fanout } = &stage.ops[0].kind {
            if self.canonical(fanout.clone()) != self.canonical(group.clone()) {
                return false;
            }
        }
        let reads_in_stage = self.reads_in(stage.ops.iter().chain([op]));
        stage.locals.iter().all(|&v| {
            let i = v.0 as usize;
            self.usage.definitions[i] == 1
                && !self.usage.outputs.contains(&v)
                && self.usage.reads[i] == reads_in_stage[i]
        })
    }

    /// `stage`'s ops so far become its inner level, and the stage runs over
    /// the groups the group gather `op` closes.
    fn open_level(&self, stage: &mut OpenStage, op: &Op) {
        stage.inner = Some((stage.ops.len(), stage.index_space.take()));
        stage.index_space = self.index_space(op);
    }

    /// For each variable, the number of `ops` that read it.
    fn reads_in<'o>(&self, ops: impl Iterator<Item = &'o Op>) -> Vec<u32> {
        let mut reads = vec![0u32; self.vars.len()];
        for op in ops {
            let mut distinct = op.array_reads();
            for e in op.host_exprs() {
                e.visit_vars(&mut |v| distinct.push(v));
            }
            distinct.sort();
            distinct.dedup();
            for v in distinct {
                reads[v.0 as usize] += 1;
            }
        }
        reads
    }

    /// Whether `op` cannot join `stage` because it runs over another length, and
    /// may run before the whole stage: it reads nothing the stage writes and
    /// writes nothing the stage reads or writes.
    fn independent_of(&self, stage: &OpenStage, op: &Op) -> bool {
        if !self.fuse
            || matches!(
                op.kind,
                OpKind::GroupGather { .. } | OpKind::Expand { .. } | OpKind::Field { .. }
            )
            || self.joins(stage, op) != Err(Barrier::LengthChange)
        {
            return false;
        }
        let reads = node_reads(&Node::Op(op.clone()));
        !reads.iter().any(|v| stage.locals.contains(v))
            && !op
                .outputs
                .iter()
                .any(|o| stage.locals.contains(o) || stage.reads(*o))
    }

    /// The finished stage, then views of record fields it computed that later
    /// nodes read (the record itself is materialised instead of the field).
    fn close(&self, stage: OpenStage, barrier: Barrier) -> Vec<Node> {
        let reads_in_stage = self.reads_in(stage.ops.iter());
        let inner_ops = stage.inner.as_ref().map_or(0, |(ops, _)| *ops);
        let mut materialises = Vec::new();
        let mut inner_reads_direct = Vec::new();
        let mut reads_direct = Vec::new();
        let mut reads_indexed = Vec::new();
        let mut reads_uniform = Vec::new();
        let mut written: HashSet<VarId> = HashSet::new();
        let mut views = Vec::new();
        for (position, op) in stage.ops.iter().enumerate() {
            let (direct, indexed): (Vec<VarId>, Vec<VarId>) = match &op.kind {
                // The closing gather of an inner level reads the level's own values.
                _ if stage.inner.is_some() && position == inner_ops => (Vec::new(), Vec::new()),
                OpKind::Gather => (vec![op.inputs[0]], vec![op.inputs[1]]),
                _ if is_elementwise_group(op) => (op.inputs.clone(), Vec::new()),
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
            let level_reads_direct = if position < inner_ops {
                &mut inner_reads_direct
            } else {
                &mut reads_direct
            };
            for v in direct {
                if !written.contains(&v) && !level_reads_direct.contains(&v) {
                    level_reads_direct.push(v);
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
                    || op.is_sink();
                if !keep {
                    continue;
                }
                // A field of a record that is stored anyway, or was made
                // before the stage, is a view of it; otherwise only the
                // field is stored, not the whole record.
                if let OpKind::Field { field } = &op.kind {
                    let src = op.inputs[0];
                    if materialises.contains(&src) || !stage.locals.contains(&src) {
                        views.push(Node::View {
                            dst: o,
                            src,
                            field: field.clone(),
                        });
                        continue;
                    }
                }
                if !materialises.contains(&o) {
                    materialises.push(o);
                }
            }
        }
        let mut nodes = vec![Node::Stage(Stage {
            ops: stage.ops,
            index_space: stage.index_space,
            reads_direct,
            reads_indexed,
            reads_uniform,
            materialises,
            barrier,
            inner: stage.inner.map(|(ops, index_space)| InnerLevel {
                ops,
                index_space,
                reads_direct: inner_reads_direct,
            }),
        })];
        nodes.extend(views);
        nodes.extend(stage.outputs);
        nodes
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

/// A group gather of groups of one (`gather<f>(a, group: 1)`, the group a
/// literal): element `i` reads only `a[i]`, so it runs over `a`'s index space
/// like a map and fuses like one (docs/language.md §6: it changes no length).
pub(crate) fn is_elementwise_group(op: &Op) -> bool {
    matches!(
        &op.kind,
        OpKind::GroupGather {
            group: HostExpr::Const(HostValue::Int(1))
        }
    )
}
