//! The plan validator: the invariants every pass must leave behind, checked
//! after each pass in debug builds (and so in every test), as rustc validates
//! MIR between passes. A violation is a compiler bug, reported as an internal
//! error naming the pass, never as a user's mistake and never as a panic.
//!
//! What the plan's types cannot say and this checks:
//! - every variable is written before it is read, on every path (a loop's body
//!   may run no time; a branch's definitions count after it only when both
//!   sides make them), and every variable id is in range;
//! - each op has the inputs, outputs and functor its kind takes;
//! - `break` only inside a loop;
//! - after type checking, every variable a node touches has a type;
//! - before fusion there are only ops, after it only stages: none empty, a
//!   stage of several ops has a known index space, what it materialises is
//!   made by its ops, and no op of a stage reads through an index, or at all,
//!   a result that a sink of the same stage completes only at its end.

use super::ir::*;
use std::collections::HashSet;

/// How far compilation has come: which invariants hold.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlanPhase {
    /// Out of `lower`: ops, types not yet inferred.
    Lowered,
    /// Out of `desugar` or `cse`: ops (no element-wise ones), every variable typed.
    Typed,
    /// Out of `fuse`: stages, no bare ops.
    Fused,
}

/// Every invariant of `phase` that `body` breaks, as messages (empty: valid).
pub fn validate_plan(vars: &[VarInfo], body: &[Node], phase: PlanPhase) -> Vec<String> {
    let mut validator = Validator {
        vars,
        phase,
        problems: Vec::new(),
    };
    let mut defined = HashSet::new();
    validator.block(body, &mut defined, 0);
    validator.problems
}

struct Validator<'a> {
    vars: &'a [VarInfo],
    phase: PlanPhase,
    problems: Vec<String>,
}

impl Validator<'_> {
    fn name(&self, var: VarId) -> String {
        match self.vars.get(var.0 as usize) {
            Some(info) => format!("`{}` (%{})", info.name, var.0),
            None => format!("%{}", var.0),
        }
    }

    fn problem(&mut self, message: String) {
        self.problems.push(message);
    }

    fn block(&mut self, nodes: &[Node], defined: &mut HashSet<VarId>, loop_depth: usize) {
        for node in nodes {
            self.node(node, defined, loop_depth);
        }
    }

    fn node(&mut self, node: &Node, defined: &mut HashSet<VarId>, loop_depth: usize) {
        let what = node_name(node);
        // A stage's ops read what earlier ops of the stage make: checked op by op.
        if !matches!(node, Node::Stage(_)) {
            self.check_reads(what, &node_reads(node), defined);
        }
        for var in node_writes(node) {
            self.check_var(var, what);
        }
        match node {
            Node::Op(op) => {
                if self.phase == PlanPhase::Fused {
                    self.problem(format!("{} is outside a stage after fusion", op.label()));
                }
                self.op(op);
            }
            Node::Stage(stage) => {
                if self.phase != PlanPhase::Fused {
                    self.problem(format!("stage `{}` before fusion", stage.label()));
                }
                self.stage(stage, defined);
            }
            Node::For { var, body, .. } => {
                let mut inside = defined.clone();
                inside.insert(*var);
                self.block(body, &mut inside, loop_depth + 1);
            }
            Node::While { body, .. } => {
                self.block(body, &mut defined.clone(), loop_depth + 1);
            }
            Node::If {
                then_body,
                else_body,
                ..
            } => {
                let mut then_defined = defined.clone();
                self.block(then_body, &mut then_defined, loop_depth);
                let mut else_defined = defined.clone();
                self.block(else_body, &mut else_defined, loop_depth);
                defined.extend(then_defined.intersection(&else_defined));
            }
            Node::Composite(composite) => {
                let mut inside = defined.clone();
                inside.extend(composite.front.iter().chain(&composite.back));
                self.block(&composite.blend, &mut inside, 0);
                self.check_reads("the blend's result", &composite.blended, &inside);
                let pieces = [
                    &composite.outputs,
                    &composite.front,
                    &composite.back,
                    &composite.blended,
                ];
                if pieces.iter().any(|p| p.len() != composite.inputs.len()) {
                    self.problem(format!(
                        "`composite<{}>` has pieces of different arities",
                        composite.blend_fn
                    ));
                }
            }
            Node::Break if loop_depth == 0 => self.problem("`break` outside a loop".into()),
            _ => {}
        }
        defined.extend(node_writes(node));
    }

    fn check_reads(&mut self, what: &str, reads: &[VarId], defined: &HashSet<VarId>) {
        for &var in reads {
            self.check_var(var, what);
            if !defined.contains(&var) {
                let name = self.name(var);
                self.problem(format!("{what} reads {name} before it is written"));
            }
        }
    }

    /// `var` exists, and has a type once types are inferred.
    fn check_var(&mut self, var: VarId, what: &str) {
        match self.vars.get(var.0 as usize) {
            None => self.problem(format!(
                "{what} names %{} but the plan has {} variables",
                var.0,
                self.vars.len()
            )),
            Some(info) if self.phase != PlanPhase::Lowered && info.ty == VarType::Unknown => {
                let name = self.name(var);
                self.problem(format!("{what} touches {name}, which has no type"));
            }
            Some(_) => {}
        }
    }

    /// The inputs, outputs and functor each kind of op takes.
    fn op(&mut self, op: &Op) {
        let (inputs, functor) = match &op.kind {
            OpKind::Iota { .. } | OpKind::Fill { .. } => (Some(0), Some(false)),
            OpKind::Field { .. } => (Some(1), Some(false)),
            OpKind::Map => (None, Some(true)),
            OpKind::Elementwise { .. } => {
                if self.phase != PlanPhase::Lowered {
                    self.problem(format!(
                        "the element-wise op `{}` was not desugared into maps",
                        op.label()
                    ));
                }
                (None, Some(true))
            }
            OpKind::Gather => (Some(2), Some(false)),
            OpKind::GroupGather { .. } | OpKind::Expand { .. } => (Some(1), Some(true)),
            OpKind::Scatter { combine, .. } => (Some(2), Some(combine.is_some())),
            OpKind::Reduce { .. } | OpKind::Scan { .. } => (Some(1), Some(true)),
            OpKind::Sort { by_key } => (Some(1 + usize::from(*by_key)), Some(false)),
        };
        let label = op.label();
        if let Some(expected) = inputs.filter(|&n| n != op.inputs.len()) {
            self.problem(format!(
                "{label} has {} inputs, its kind takes {expected}",
                op.inputs.len()
            ));
        }
        if functor.is_some_and(|needed| needed != op.functor.is_some()) {
            self.problem(format!(
                "{label} {} a functor, against its kind",
                if op.functor.is_some() { "has" } else { "lacks" }
            ));
        }
        let outputs_ok = match op.kind {
            OpKind::Map | OpKind::Elementwise { .. } => !op.outputs.is_empty(),
            // One sorted array per input.
            OpKind::Sort { .. } => op.outputs.len() == op.inputs.len(),
            _ => op.outputs.len() == 1,
        };
        if !outputs_ok {
            self.problem(format!("{label} has {} outputs", op.outputs.len()));
        }
    }

    fn stage(&mut self, stage: &Stage, defined: &HashSet<VarId>) {
        let label = stage.label();
        if stage.ops.is_empty() {
            self.problem("an empty stage".into());
            return;
        }
        if stage.ops.len() > 1 && stage.index_space.is_none() {
            self.problem(format!(
                "stage `{label}` fuses ops without a known index space"
            ));
        }
        let mut made: HashSet<VarId> = HashSet::new();
        let mut completed_at_end: HashSet<VarId> = HashSet::new();
        let mut defined_inside = defined.clone();
        for op in &stage.ops {
            self.op(op);
            self.check_reads(&op.label(), &op.reads(), &defined_inside);
            defined_inside.extend(&op.outputs);
            for var in op.array_reads() {
                if completed_at_end.contains(&var) {
                    let name = self.name(var);
                    self.problem(format!(
                        "{} in stage `{label}` reads {name}, which a sink of the same stage completes only at its end",
                        op.label()
                    ));
                }
            }
            made.extend(&op.outputs);
            if op.is_sink() {
                completed_at_end.extend(&op.outputs);
            }
        }
        for &var in &stage.materialises {
            if !made.contains(&var) {
                let name = self.name(var);
                self.problem(format!(
                    "stage `{label}` materialises {name}, which none of its ops makes"
                ));
            }
        }
        for &var in &stage.reads_indexed {
            if made.contains(&var) && !defined.contains(&var) {
                let name = self.name(var);
                self.problem(format!(
                    "stage `{label}` reads {name} through an index in the stage that makes it"
                ));
            }
        }
        if let Some(inner) = &stage.inner {
            self.inner_level(stage, inner);
        }
    }

    /// A nested stage's inner values stay inside it: no sink among its inner
    /// ops, none of their values materialised, and only the closing group
    /// gather reads one from the outer level.
    fn inner_level(&mut self, stage: &Stage, inner: &InnerLevel) {
        let label = stage.label();
        let Some(closing) = stage.ops.get(inner.ops) else {
            self.problem(format!(
                "stage `{label}` has no op to close its inner level"
            ));
            return;
        };
        let inner_values: HashSet<VarId> = stage.ops[..inner.ops]
            .iter()
            .flat_map(|op| op.outputs.iter().copied())
            .collect();
        if !matches!(closing.kind, OpKind::GroupGather { .. })
            || !inner_values.contains(&closing.inputs[0])
        {
            self.problem(format!(
                "stage `{label}`: {} does not gather groups of its inner level",
                closing.label()
            ));
        }
        if let Some(sink) = stage.ops[..inner.ops].iter().find(|op| op.is_sink()) {
            self.problem(format!(
                "stage `{label}`: {} is a sink inside an inner level",
                sink.label()
            ));
        }
        for &var in &stage.materialises {
            if inner_values.contains(&var) {
                let name = self.name(var);
                self.problem(format!(
                    "stage `{label}` materialises {name}, a value of its inner level"
                ));
            }
        }
        for op in &stage.ops[inner.ops + 1..] {
            if let Some(&var) = op.reads().iter().find(|v| inner_values.contains(v)) {
                let name = self.name(var);
                self.problem(format!(
                    "stage `{label}`: {} reads {name}, a value of its inner level",
                    op.label()
                ));
            }
        }
    }
}

fn node_name(node: &Node) -> &'static str {
    match node {
        Node::Op(_) => "an op",
        Node::Stage(_) => "a stage",
        Node::Host { .. } => "a host binding",
        Node::View { .. } => "a view",
        Node::Alias { .. } => "an alias",
        Node::For { .. } => "a `for` loop",
        Node::While { .. } => "a `while` loop",
        Node::If { .. } => "an `if`",
        Node::Break => "`break`",
        Node::Composite(_) => "a `composite`",
        Node::Output { .. } => "an `out`",
    }
}
