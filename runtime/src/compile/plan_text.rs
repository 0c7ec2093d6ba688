//! The plan's stable, human-readable text form (`dpp plan FILE`). Snapshot
//! tests pin it, so it holds no addresses, timings or hash-map order.

use super::ir::*;
use crate::functor::FunctorLibrary;
use crate::host::HostValue;
use std::fmt::Write;

pub fn plan_to_text(plan: &Plan, library: &FunctorLibrary) -> String {
    let mut text = String::new();
    let mode = if plan.fused { "fused" } else { "unfused" };
    let _ = writeln!(
        text,
        "pipeline {} ({mode}, {} stages)",
        plan.pipeline,
        plan.stages().len()
    );
    for param in &plan.params {
        let set = if param.overridden { "  (--set)" } else { "" };
        let _ = writeln!(
            text,
            "param {}: {} = {}{set}",
            param.name, param.ty, param.value
        );
    }
    let mut printer = Printer {
        plan,
        library,
        text,
        stage_number: 0,
    };
    printer.nodes(&plan.body, 0);
    printer.text
}

struct Printer<'a> {
    plan: &'a Plan,
    library: &'a FunctorLibrary,
    text: String,
    stage_number: usize,
}

impl Printer<'_> {
    fn name(&self, var: VarId) -> String {
        self.plan.var(var).name.clone()
    }

    fn names(&self, vars: &[VarId]) -> String {
        if vars.is_empty() {
            return "-".into();
        }
        vars.iter()
            .map(|v| self.typed(*v))
            .collect::<Vec<_>>()
            .join(", ")
    }

    fn typed(&self, var: VarId) -> String {
        let info = self.plan.var(var);
        match info.ty {
            VarType::Array(t) => format!("{}: {}", info.name, t.name(&self.library.records)),
            VarType::Host(t) => format!("{}: {t}", info.name),
            VarType::Unknown => info.name.clone(),
        }
    }

    fn line(&mut self, depth: usize, line: &str) {
        let _ = writeln!(self.text, "{}{line}", "  ".repeat(depth));
    }

    fn nodes(&mut self, nodes: &[Node], depth: usize) {
        for node in nodes {
            match node {
                Node::Stage(stage) => self.stage(stage, depth),
                Node::Op(op) => {
                    let line = format!("op {}", self.op(op));
                    self.line(depth, &line);
                }
                Node::Host { dst, expr, .. } => {
                    let line = format!("let {} = {}", self.typed(*dst), host_text(expr, self.plan));
                    self.line(depth, &line);
                }
                Node::View { dst, src, field } => {
                    let line = format!("view {} = {}.{field}", self.name(*dst), self.name(*src));
                    self.line(depth, &line);
                }
                Node::Alias { dst, src } => {
                    let line = format!("let {} = {}", self.name(*dst), self.name(*src));
                    self.line(depth, &line);
                }
                Node::For {
                    var,
                    start,
                    end,
                    body,
                    ..
                } => {
                    let line = format!(
                        "for {} in {}..{} {{",
                        self.name(*var),
                        host_text(start, self.plan),
                        host_text(end, self.plan)
                    );
                    self.line(depth, &line);
                    self.nodes(body, depth + 1);
                    self.line(depth, "}");
                }
                Node::While { cond, body, .. } => {
                    let line = format!("while {} {{", host_text(cond, self.plan));
                    self.line(depth, &line);
                    self.nodes(body, depth + 1);
                    self.line(depth, "}");
                }
                Node::If {
                    cond,
                    then_body,
                    else_body,
                    ..
                } => {
                    let line = format!("if {} {{", host_text(cond, self.plan));
                    self.line(depth, &line);
                    self.nodes(then_body, depth + 1);
                    if !else_body.is_empty() {
                        self.line(depth, "} else {");
                        self.nodes(else_body, depth + 1);
                    }
                    self.line(depth, "}");
                }
                Node::Break => self.line(depth, "break"),
                Node::Composite(composite) => self.composite(composite, depth),
                Node::Output { name, var } => {
                    let line = format!("out {name} = {}", self.name(*var));
                    self.line(depth, &line);
                }
            }
        }
    }

    /// ```text
    /// composite (color#1, depth#1) = composite<nearestDepth>(color, depth) {   // rank order
    ///   blend (front.color, front.depth) over (back.color, back.depth) {
    ///     stage …
    ///   } → (%40, %41)
    /// }   // only rank 0 goes on
    /// ```
    fn composite(&mut self, composite: &Composite, depth: usize) {
        let names = |printer: &Self, vars: &[VarId]| {
            let names: Vec<String> = vars.iter().map(|v| printer.name(*v)).collect();
            format!("({})", names.join(", "))
        };
        let order = match &composite.visibility {
            HostExpr::Const(HostValue::Bool(false)) => "rank order, ties to the lower rank".into(),
            HostExpr::Const(HostValue::Bool(true)) => "visibility order".into(),
            other => format!("visibility order if {}", host_text(other, self.plan)),
        };
        let line = format!(
            "composite {} = composite<{}>{} {{   // front to back in {order}",
            names(self, &composite.outputs),
            composite.blend_fn,
            names(self, &composite.inputs)
        );
        self.line(depth, &line);
        let line = format!(
            "blend front {} with back {} {{",
            names(self, &composite.front),
            names(self, &composite.back)
        );
        self.line(depth + 1, &line);
        self.nodes(&composite.blend, depth + 2);
        let line = format!("}} → {}", names(self, &composite.blended));
        self.line(depth + 1, &line);
        self.line(depth, "}   // only rank 0 runs on from here");
    }

    /// `hits = map<intersect>(rays)`
    fn op(&self, op: &Op) -> String {
        let mut args: Vec<String> = op.inputs.iter().map(|v| self.name(*v)).collect();
        match &op.kind {
            OpKind::Iota { count } => args.push(host_text(count, self.plan)),
            OpKind::Fill { count, value } => {
                args.push(host_text(count, self.plan));
                args.push(host_text(value, self.plan));
            }
            OpKind::GroupGather { group } => {
                args.push(format!("group: {}", host_text(group, self.plan)))
            }
            OpKind::Expand { fanout } => {
                args.push(format!("fanout: {}", host_text(fanout, self.plan)))
            }
            OpKind::Scatter { target, mask, .. } => {
                match target {
                    ScatterTarget::Len(len) => {
                        args.push(format!("len: {}", host_text(len, self.plan)))
                    }
                    ScatterTarget::Into(dst) => args.push(format!("into: {}", self.name(*dst))),
                }
                if let Some(mask) = mask {
                    args.push(format!("mask: {}", self.name(*mask)));
                }
            }
            OpKind::Scan {
                segments: Some(flags),
                ..
            } => args.push(format!("segments: {}", self.name(*flags))),
            _ => {}
        }
        for (name, value) in &op.named {
            args.push(format!("{name}: {}", host_text(value, self.plan)));
        }
        let outputs: Vec<String> = op.outputs.iter().map(|v| self.name(*v)).collect();
        let outputs = if outputs.len() == 1 {
            outputs[0].clone()
        } else {
            format!("({})", outputs.join(", "))
        };
        if let OpKind::Field { field } = &op.kind {
            return format!("{outputs} = field {field} of {}", self.name(op.inputs[0]));
        }
        format!("{outputs} = {}({})", op.label(), args.join(", "))
    }

    fn stage(&mut self, stage: &Stage, depth: usize) {
        self.stage_number += 1;
        let header = format!("stage {} [{}] {{", self.stage_number, stage.label());
        self.line(depth, &header);
        let over = stage
            .index_space
            .as_ref()
            .map_or("?".to_string(), |e| host_text(e, self.plan));
        self.line(depth + 1, &format!("over {over}"));
        // A nested stage's inner ops, a group of them for each element.
        let inner_ops = stage.inner_ops();
        if let Some(inner) = &stage.inner {
            let over = inner
                .index_space
                .as_ref()
                .map_or("?".to_string(), |e| host_text(e, self.plan));
            self.line(depth + 1, &format!("inner level over {over} {{"));
            for op in &stage.ops[..inner.ops] {
                let line = self.op(op);
                self.line(depth + 2, &line);
            }
            let direct = self.names(&inner.reads_direct);
            self.line(depth + 2, &format!("reads direct: {direct}"));
            self.line(depth + 1, "}");
        }
        for op in &stage.ops[inner_ops..] {
            let line = self.op(op);
            self.line(depth + 1, &line);
        }
        let direct = self.names(&stage.reads_direct);
        let indexed = self.names(&stage.reads_indexed);
        let uniforms = if stage.reads_uniform.is_empty() {
            "-".to_string()
        } else {
            stage.reads_uniform.join(", ")
        };
        self.line(
            depth + 1,
            &format!("reads direct: {direct}; indexed: {indexed}; uniform: {uniforms}"),
        );
        let writes = self.names(&stage.materialises);
        self.line(depth + 1, &format!("materialises {writes}"));
        self.line(depth + 1, &format!("ends at {}", stage.barrier.describe()));
        self.line(depth, "}");
    }
}

/// A host expression as source-like text.
pub fn host_text(expr: &HostExpr, plan: &Plan) -> String {
    match expr {
        HostExpr::Const(v) => v.to_string(),
        HostExpr::Var(v) => plan.var(*v).name.clone(),
        HostExpr::Uniform { record, field } => format!("{record}.{field}"),
        HostExpr::Len(v) => format!("len({})", plan.var(*v).name),
        HostExpr::Unary(op, e) => {
            let symbol = match op {
                dpp_dsl::ast::UnaryOp::Neg => "-",
                dpp_dsl::ast::UnaryOp::Not => "!",
            };
            format!("{symbol}{}", operand_text(e, plan))
        }
        HostExpr::Binary(op, a, b) => {
            format!(
                "{} {} {}",
                operand_text(a, plan),
                op.symbol(),
                operand_text(b, plan)
            )
        }
        HostExpr::Call(function, args) => {
            let args: Vec<String> = args.iter().map(|a| host_text(a, plan)).collect();
            format!("{}({})", function.name(), args.join(", "))
        }
    }
}

fn operand_text(expr: &HostExpr, plan: &Plan) -> String {
    match expr {
        HostExpr::Binary(..) => format!("({})", host_text(expr, plan)),
        _ => host_text(expr, plan),
    }
}
