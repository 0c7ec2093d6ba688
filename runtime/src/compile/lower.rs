//! Pass 3: lower the AST into plan nodes ([`Node::Op`] per primitive), with
//! names resolved to variable slots, `fn`s inlined at each call and `→` chains
//! desugared into leading arguments. Unknown names, functors and arguments,
//! wrong arity, `break` outside a loop and recursion are reported here.

use super::ir::*;
use super::resolve::{is_reserved, Program};
use crate::functor::FunctorLibrary;
use crate::host::HostValue;
use crate::signature::{FunctorKind, NamedParam, Signature};
use crate::types::HostType;
use dpp_dsl::ast::{self, Block, Call, ExprKind, Ident, StmtKind};
use dpp_dsl::{did_you_mean, Code, Diagnostic, Span};
use std::collections::{HashMap, HashSet};

pub struct Lowered {
    pub vars: Vec<VarInfo>,
    pub params: Vec<(String, VarId, Span)>,
    pub body: Vec<Node>,
    pub outputs: Vec<String>,
}

pub fn lower_program(
    program: &Program<'_>,
    library: &FunctorLibrary,
    diagnostics: &mut Vec<Diagnostic>,
) -> Lowered {
    let mut lowerer = Lowerer {
        program,
        library,
        diagnostics,
        vars: Vec::new(),
        scopes: Vec::new(),
        fn_stack: Vec::new(),
        outputs: Vec::new(),
        params: HashMap::new(),
        inlined: HashSet::new(),
        composited: None,
    };
    let mut params = Vec::new();
    let mut body = Vec::new();
    for param in &program.params {
        let value = lowerer.lower_host(&param.value, &mut body);
        let var = lowerer.new_var(&param.name.name, param.name.span, VarType::Unknown);
        body.push(Node::Host {
            dst: var,
            expr: value,
            span: param.span,
        });
        lowerer.params.insert(param.name.name.clone(), var);
        params.push((param.name.name.clone(), var, param.name.span));
    }
    lowerer.scopes.push(Scope::new(ScopeKind::Function));
    lowerer.lower_block_in_scope(&program.pipeline.body, &mut body);
    lowerer.scopes.pop();
    lowerer.check_uncalled_fns();
    Lowered {
        vars: lowerer.vars,
        params,
        body,
        outputs: lowerer.outputs,
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Binding {
    Array(VarId),
    Host(VarId),
    /// A parameter of a fn checked without a call: its kind and type are
    /// unknown, so whatever reads it is silently unknown too.
    Poisoned(VarId),
}

impl Binding {
    fn var(self) -> VarId {
        match self {
            Binding::Array(v) | Binding::Host(v) | Binding::Poisoned(v) => v,
        }
    }
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum ScopeKind {
    /// The pipeline's or an inlined fn's top level: names outside are invisible.
    Function,
    Loop,
    Block,
}

struct Scope {
    kind: ScopeKind,
    names: HashMap<String, Binding>,
}

impl Scope {
    fn new(kind: ScopeKind) -> Scope {
        Scope {
            kind,
            names: HashMap::new(),
        }
    }
}

/// What an expression lowers to.
#[derive(Clone, Debug)]
enum Value {
    Array(VarId),
    Host(HostExpr),
    /// Several arrays: a multi-output map, bound with `(x, y) = …` or piped on.
    Tuple(Vec<VarId>),
    /// Already diagnosed; keeps lowering going to report more errors.
    Error,
}

struct Lowerer<'a, 'p> {
    program: &'a Program<'p>,
    library: &'a FunctorLibrary,
    diagnostics: &'a mut Vec<Diagnostic>,
    vars: Vec<VarInfo>,
    scopes: Vec<Scope>,
    /// Names of the fns being inlined, to report recursion.
    fn_stack: Vec<String>,
    outputs: Vec<String>,
    params: HashMap<String, VarId>,
    /// Names of the fns inlined at least once.
    inlined: HashSet<String>,
    /// Where the pipeline composites, once it has.
    composited: Option<Span>,
}

impl Lowerer<'_, '_> {
    fn error(&mut self, diagnostic: Diagnostic) {
        self.diagnostics.push(diagnostic);
    }

    fn new_var(&mut self, name: &str, span: Span, ty: VarType) -> VarId {
        // Shadowing names stay distinct in the plan's text: `n`, `n#1`, …
        let taken = self
            .vars
            .iter()
            .filter(|v| v.name == name || v.name.starts_with(&format!("{name}#")))
            .count();
        let name = if taken == 0 {
            name.to_string()
        } else {
            format!("{name}#{taken}")
        };
        self.vars.push(VarInfo {
            name,
            span,
            ty,
            len: None,
        });
        VarId(self.vars.len() as u32 - 1)
    }

    fn new_temp(&mut self, span: Span) -> VarId {
        let name = format!("%{}", self.vars.len());
        self.new_var(&name, span, VarType::Unknown)
    }

    /// Looks a name up from the innermost scope out to the enclosing function
    /// boundary, then among the params. Returns the binding and whether it lives
    /// in the innermost scope.
    fn lookup(&self, name: &str) -> Option<(Binding, bool)> {
        for (depth, scope) in self.scopes.iter().enumerate().rev() {
            if let Some(binding) = scope.names.get(name) {
                return Some((*binding, depth == self.scopes.len() - 1));
            }
            if scope.kind == ScopeKind::Function {
                break;
            }
        }
        self.params.get(name).map(|v| (Binding::Host(*v), false))
    }

    fn visible_names(&self) -> Vec<String> {
        let mut names: Vec<String> = Vec::new();
        for scope in self.scopes.iter().rev() {
            names.extend(scope.names.keys().cloned());
            if scope.kind == ScopeKind::Function {
                break;
            }
        }
        names.extend(self.params.keys().cloned());
        names.extend(self.library.uniforms.records.keys().cloned());
        names
    }

    fn in_loop(&self) -> bool {
        for scope in self.scopes.iter().rev() {
            match scope.kind {
                ScopeKind::Loop => return true,
                ScopeKind::Function => return false,
                ScopeKind::Block => {}
            }
        }
        false
    }

    fn lower_block_in_scope(&mut self, block: &Block, out: &mut Vec<Node>) {
        for (index, stmt) in block.stmts.iter().enumerate() {
            if let StmtKind::Return(_) = stmt.kind {
                // A fn's return is handled by `inline_fn`; anywhere else it is misplaced.
                let message = if self.fn_stack.is_empty() {
                    "`return` outside a fn"
                } else if index + 1 != block.stmts.len() {
                    "`return` must be the last statement of a fn"
                } else {
                    "`return` must be at the top level of a fn, not inside a loop or branch"
                };
                self.error(Diagnostic::error(Code::Return, message, stmt.span));
                continue;
            }
            self.lower_stmt(stmt, out);
        }
    }

    fn lower_nested_block(&mut self, block: &Block, kind: ScopeKind) -> Vec<Node> {
        let mut nodes = Vec::new();
        self.scopes.push(Scope::new(kind));
        self.lower_block_in_scope(block, &mut nodes);
        self.scopes.pop();
        nodes
    }

    fn lower_stmt(&mut self, stmt: &ast::Stmt, out: &mut Vec<Node>) {
        match &stmt.kind {
            StmtKind::Bind { targets, value } => self.lower_binding(targets, value, out),
            StmtKind::Out { name, value } => {
                let var = match value {
                    Some(value) => {
                        self.lower_binding(std::slice::from_ref(name), value, out);
                        self.lookup(&name.name).map(|(b, _)| b.var())
                    }
                    None => match self.lookup(&name.name) {
                        Some((binding, _)) => Some(binding.var()),
                        None => {
                            self.unknown_name(name);
                            None
                        }
                    },
                };
                if let Some(var) = var {
                    // `out x` in several branches names one output.
                    if !self.outputs.contains(&name.name) {
                        self.outputs.push(name.name.clone());
                    }
                    out.push(Node::Output {
                        name: name.name.clone(),
                        var,
                    });
                }
            }
            StmtKind::For {
                var,
                start,
                end,
                body,
            } => {
                let start = self.lower_host(start, out);
                let end = self.lower_host(end, out);
                let counter = self.new_var(&var.name, var.span, VarType::Host(HostType::Int));
                self.scopes.push(Scope::new(ScopeKind::Loop));
                self.scopes
                    .last_mut()
                    .unwrap()
                    .names
                    .insert(var.name.clone(), Binding::Host(counter));
                let mut nodes = Vec::new();
                self.lower_block_in_scope(body, &mut nodes);
                self.scopes.pop();
                out.push(Node::For {
                    span: stmt.span,
                    var: counter,
                    start,
                    end,
                    body: nodes,
                });
            }
            StmtKind::While { cond, body } => {
                // The condition is re-evaluated before each iteration, so it may
                // only read values, not run primitives.
                let mut hoisted = Vec::new();
                let cond = self.lower_host(cond, &mut hoisted);
                if !hoisted.is_empty() {
                    self.error(
                        Diagnostic::error(
                            Code::WhileCondition,
                            "a `while` condition must be a host expression without primitives",
                            stmt.span,
                        )
                        .with_help(
                            "bind the value before the loop and update it at the end of the body",
                        ),
                    );
                }
                let body = self.lower_nested_block(body, ScopeKind::Loop);
                out.push(Node::While {
                    cond,
                    body,
                    span: stmt.span,
                });
            }
            StmtKind::If {
                cond,
                then_block,
                else_block,
            } => {
                let cond = self.lower_host(cond, out);
                let then_body = self.lower_nested_block(then_block, ScopeKind::Block);
                let else_body = else_block
                    .as_ref()
                    .map(|b| self.lower_nested_block(b, ScopeKind::Block))
                    .unwrap_or_default();
                out.push(Node::If {
                    span: stmt.span,
                    cond,
                    then_body,
                    else_body,
                });
            }
            StmtKind::Break => {
                if self.in_loop() {
                    out.push(Node::Break);
                } else {
                    self.error(Diagnostic::error(
                        Code::BreakOutsideLoop,
                        "`break` outside a loop",
                        stmt.span,
                    ));
                }
            }
            StmtKind::Return(_) => unreachable!("handled by lower_block_in_scope"),
        }
    }

    /// `x = e` / `(x, y) = e`. A name bound in an enclosing scope is updated in
    /// place (its slot); otherwise the binding gets a fresh variable.
    fn lower_binding(&mut self, targets: &[Ident], value: &ast::Expr, out: &mut Vec<Node>) {
        let first_new_var = self.vars.len();
        let nodes_before = out.len();
        let value = self.lower_expr(value, out);
        let values: Vec<Value> = match value {
            Value::Tuple(vars) if targets.len() > 1 => {
                if vars.len() != targets.len() {
                    let span = targets[0].span.to(targets[targets.len() - 1].span);
                    self.error(Diagnostic::error(
                        Code::Arity,
                        format!("{} names bound to {} values", targets.len(), vars.len()),
                        span,
                    ));
                    return self.poison(targets);
                }
                vars.into_iter().map(Value::Array).collect()
            }
            Value::Tuple(vars) => {
                self.error(Diagnostic::error(
                    Code::Arity,
                    format!(
                        "this expression has {} outputs; bind them with `(a, b) = …`",
                        vars.len()
                    ),
                    targets[0].span,
                ));
                return self.poison(targets);
            }
            Value::Error => return self.poison(targets),
            single if targets.len() == 1 => vec![single],
            _ => {
                let span = targets[0].span.to(targets[targets.len() - 1].span);
                self.error(Diagnostic::error(
                    Code::Arity,
                    format!("{} names bound to one value", targets.len()),
                    span,
                ));
                return self.poison(targets);
            }
        };
        for (target, value) in targets.iter().zip(values) {
            self.bind(target, value, first_new_var, nodes_before, out);
        }
    }

    /// Declares names whose value is in error, so that reading them later is
    /// silent instead of a second, misleading "unknown name".
    fn poison(&mut self, targets: &[Ident]) {
        for target in targets {
            let placeholder = self.new_var(&target.name, target.span, VarType::Unknown);
            self.scopes
                .last_mut()
                .expect("lowering always has a scope")
                .names
                .insert(target.name.clone(), Binding::Poisoned(placeholder));
        }
    }

    fn bind(
        &mut self,
        target: &Ident,
        value: Value,
        first_new_var: usize,
        nodes_before: usize,
        out: &mut Vec<Node>,
    ) {
        if is_reserved(&target.name) || self.library.uniforms.records.contains_key(&target.name) {
            self.error(Diagnostic::error(
                Code::Reserved,
                format!(
                    "`{}` is a name of the language and cannot be rebound",
                    target.name
                ),
                target.span,
            ));
            return;
        }
        let mut existing = self
            .lookup(&target.name)
            .filter(|(binding, _)| !matches!(binding, Binding::Poisoned(_)));
        let is_param =
            existing.is_some_and(|(b, _)| self.params.get(&target.name) == Some(&b.var()));
        if is_param && !self.fn_stack.is_empty() {
            // A fn's own names shadow params: its body cannot see the caller's state.
            existing = None;
        }
        if let Some((_, false)) = existing {
            if is_param {
                self.error(
                    Diagnostic::error(
                        Code::ParamRebind,
                        format!("`{}` is a param and cannot be rebound", target.name),
                        target.span,
                    )
                    .with_help(
                        "params are set in the file or with `--set`; bind a new name instead",
                    ),
                );
                return;
            }
        }
        let slot = match existing {
            Some((binding, false)) => Some(binding),
            _ => None,
        };
        match value {
            Value::Array(source) => {
                let dst = match slot {
                    Some(Binding::Array(v)) => v,
                    Some(Binding::Host(_)) => {
                        self.kind_change(target, "a host scalar", "an array");
                        return;
                    }
                    None | Some(Binding::Poisoned(_)) => {
                        self.new_var(&target.name, target.span, VarType::Unknown)
                    }
                };
                // A value computed by this very statement is written straight into
                // the binding's slot instead of through an alias.
                if !(source.0 as usize >= first_new_var
                    && rename_output(&mut out[nodes_before..], source, dst))
                {
                    out.push(Node::Alias { dst, src: source });
                }
                self.declare(target, Binding::Array(dst));
            }
            Value::Host(expr) => {
                let dst = match slot {
                    Some(Binding::Host(v)) => v,
                    Some(Binding::Array(_)) => {
                        self.kind_change(target, "an array", "a host scalar");
                        return;
                    }
                    None | Some(Binding::Poisoned(_)) => {
                        self.new_var(&target.name, target.span, VarType::Unknown)
                    }
                };
                out.push(Node::Host {
                    dst,
                    expr,
                    span: target.span,
                });
                self.declare(target, Binding::Host(dst));
            }
            Value::Tuple(_) | Value::Error => {}
        }
    }

    /// Records a binding in the innermost scope unless it updates an outer slot.
    fn declare(&mut self, target: &Ident, binding: Binding) {
        if let Some((existing, false)) = self.lookup(&target.name) {
            if existing == binding {
                return;
            }
        }
        self.scopes
            .last_mut()
            .expect("lowering always has a scope")
            .names
            .insert(target.name.clone(), binding);
    }

    fn kind_change(&mut self, target: &Ident, was: &str, now: &str) {
        self.error(Diagnostic::error(
            Code::TypeMismatch,
            format!(
                "`{}` is {was} outside this block; it cannot become {now} here",
                target.name
            ),
            target.span,
        ));
    }

    fn unknown_name(&mut self, name: &Ident) {
        let candidates = self.visible_names();
        let mut diagnostic = Diagnostic::error(
            Code::UnknownName,
            format!("unknown name `{}`", name.name),
            name.span,
        );
        if let Some(suggestion) = did_you_mean(&name.name, candidates.iter().map(String::as_str)) {
            diagnostic = diagnostic.with_help(format!("did you mean `{suggestion}`?"));
        }
        self.error(diagnostic);
    }

    /// Stands for a host operand already diagnosed: a variable that is never
    /// typed, so type checking stays silent about the expressions around it.
    fn error_host(&mut self, span: Span) -> HostExpr {
        HostExpr::Var(self.new_temp(span))
    }

    fn lower_host(&mut self, expr: &ast::Expr, out: &mut Vec<Node>) -> HostExpr {
        match self.lower_expr(expr, out) {
            Value::Host(e) => e,
            Value::Error => self.error_host(expr.span),
            Value::Array(_) | Value::Tuple(_) => {
                self.error(
                    Diagnostic::error(
                        Code::ExpectedScalar,
                        "expected a host scalar, found an array",
                        expr.span,
                    )
                    .with_help("arrays become scalars through `reduce<f>(a)` or `len(a)`"),
                );
                self.error_host(expr.span)
            }
        }
    }

    fn lower_array(&mut self, expr: &ast::Expr, out: &mut Vec<Node>) -> Option<VarId> {
        match self.lower_expr(expr, out) {
            Value::Array(v) => Some(v),
            Value::Error => None,
            Value::Host(_) => {
                self.error(
                    Diagnostic::error(
                        Code::ExpectedArray,
                        "expected an array, found a host scalar",
                        expr.span,
                    )
                    .with_help("make an array with `fill(n, value)` or `iota(n)`"),
                );
                None
            }
            Value::Tuple(vars) => {
                self.error(Diagnostic::error(
                    Code::Arity,
                    format!(
                        "expected one array, found {} (a multi-output map)",
                        vars.len()
                    ),
                    expr.span,
                ));
                None
            }
        }
    }

    fn lower_expr(&mut self, expr: &ast::Expr, out: &mut Vec<Node>) -> Value {
        match &expr.kind {
            ExprKind::Int(i) => Value::Host(HostExpr::Const(HostValue::Int(*i))),
            ExprKind::Float(f) => Value::Host(HostExpr::Const(HostValue::Float(*f))),
            ExprKind::Bool(b) => Value::Host(HostExpr::Const(HostValue::Bool(*b))),
            ExprKind::Name(name) => {
                match self.lookup(&name.name) {
                    Some((Binding::Array(v), _)) => Value::Array(v),
                    Some((Binding::Host(v), _)) => Value::Host(HostExpr::Var(v)),
                    Some((Binding::Poisoned(_), _)) => Value::Error,
                    None => {
                        if self.library.uniforms.records.contains_key(&name.name) {
                            self.error(Diagnostic::error(
                            Code::Uniform,
                            format!("`{}` is a uniform record; read one of its fields, like `{}.{}`", name.name, name.name,
                                self.library.uniforms.records[&name.name].keys().next().map_or("field", String::as_str)),
                            name.span,
                        ));
                        } else {
                            self.unknown_name(name);
                        }
                        Value::Error
                    }
                }
            }
            ExprKind::Field { base, field } => self.lower_field(expr, base, field, out),
            ExprKind::Tuple(elements) => {
                let mut vars = Vec::new();
                for element in elements {
                    let value = self.lower_expr(element, out);
                    match self.expect_array((value, element.span)) {
                        Some(var) => vars.push(var),
                        None => return Value::Error,
                    }
                }
                Value::Tuple(vars)
            }
            ExprKind::Call(call) => self.lower_call(call, expr.span, out),
            ExprKind::Unary { op, operand } => {
                let value = self.lower_expr(operand, out);
                match value {
                    Value::Host(operand) => Value::Host(HostExpr::Unary(*op, Box::new(operand))),
                    Value::Error => Value::Error,
                    value => {
                        let functor = match op {
                            ast::UnaryOp::Neg => "neg",
                            ast::UnaryOp::Not => "not",
                        };
                        let symbol = if functor == "neg" { "-" } else { "!" };
                        let operands = vec![(value, operand.span)];
                        self.elementwise(
                            functor,
                            Some(symbol),
                            operands,
                            Vec::new(),
                            expr.span,
                            out,
                        )
                    }
                }
            }
            ExprKind::Binary {
                op,
                op_span,
                lhs,
                rhs,
            } => {
                let l = self.lower_expr(lhs, out);
                let r = self.lower_expr(rhs, out);
                match (l, r) {
                    (Value::Host(l), Value::Host(r)) => {
                        Value::Host(HostExpr::Binary(*op, Box::new(l), Box::new(r)))
                    }
                    (Value::Error, _) | (_, Value::Error) => Value::Error,
                    (l, r) => {
                        let functor = match op {
                            ast::BinaryOp::Add => "add",
                            ast::BinaryOp::Sub => "sub",
                            ast::BinaryOp::Mul => "mul",
                            ast::BinaryOp::Div => "div",
                            ast::BinaryOp::Rem => "rem",
                            ast::BinaryOp::Eq => "eq",
                            ast::BinaryOp::Ne => "ne",
                            ast::BinaryOp::Lt => "lt",
                            ast::BinaryOp::Le => "le",
                            ast::BinaryOp::Gt => "gt",
                            ast::BinaryOp::Ge => "ge",
                            ast::BinaryOp::And => "and",
                            ast::BinaryOp::Or => "or",
                        };
                        let operands = vec![(l, lhs.span), (r, rhs.span)];
                        self.elementwise(
                            functor,
                            Some(op.symbol()),
                            operands,
                            Vec::new(),
                            *op_span,
                            out,
                        )
                    }
                }
            }
        }
    }

    /// An operator or functor call over arrays (and host scalars): one
    /// element-wise op, which type checking types and `desugar` turns into a
    /// `map` of `functor`, with host scalars broadcast.
    fn elementwise(
        &mut self,
        functor: &str,
        operator: Option<&'static str>,
        operands: Vec<(Value, Span)>,
        named: Vec<(String, HostExpr)>,
        span: Span,
        out: &mut Vec<Node>,
    ) -> Value {
        let Some(signature) = self.library.get(functor).map(|f| f.signature().clone()) else {
            self.error(Diagnostic::error(
                Code::UnknownFunctor,
                format!("`{functor}` over arrays needs the functor `{functor}`, which this library lacks"),
                span,
            ));
            return Value::Error;
        };
        let mut inputs = Vec::new();
        let mut lowered = Vec::with_capacity(operands.len());
        for (value, operand_span) in operands {
            match value {
                Value::Array(v) => {
                    inputs.push(v);
                    lowered.push(Operand::Array(v));
                }
                Value::Host(e) => lowered.push(Operand::Host(e)),
                Value::Error => return Value::Error,
                Value::Tuple(_) => {
                    return self
                        .expect_array((value, operand_span))
                        .map_or(Value::Error, Value::Array)
                }
            }
        }
        let outputs: Vec<VarId> = (0..signature.outputs.len().max(1))
            .map(|_| self.new_temp(span))
            .collect();
        out.push(Node::Op(Op {
            kind: OpKind::Elementwise {
                operands: lowered,
                operator,
            },
            functor: Some(functor.to_string()),
            inputs,
            outputs: outputs.clone(),
            named,
            span,
        }));
        if outputs.len() == 1 {
            Value::Array(outputs[0])
        } else {
            Value::Tuple(outputs)
        }
    }

    fn lower_field(
        &mut self,
        expr: &ast::Expr,
        base: &ast::Expr,
        field: &Ident,
        out: &mut Vec<Node>,
    ) -> Value {
        // `camera.pixels`: a uniform, unless a binding shadows the record's name.
        if let ExprKind::Name(record) = &base.kind {
            if self.lookup(&record.name).is_none() {
                if let Some(fields) = self.library.uniforms.records.get(&record.name) {
                    if fields.contains_key(&field.name) {
                        return Value::Host(HostExpr::Uniform {
                            record: record.name.clone(),
                            field: field.name.clone(),
                        });
                    }
                    let mut diagnostic = Diagnostic::error(
                        Code::UnknownField,
                        format!("`{}` has no field `{}`", record.name, field.name),
                        field.span,
                    );
                    if let Some(s) = did_you_mean(&field.name, fields.keys().map(String::as_str)) {
                        diagnostic = diagnostic.with_help(format!("did you mean `{s}`?"));
                    }
                    self.error(diagnostic);
                    return Value::Error;
                }
            }
        }
        match self.lower_expr(base, out) {
            Value::Array(src) => {
                let dst = self.new_temp(expr.span);
                self.vars[dst.0 as usize].name =
                    format!("{}.{}", self.vars[src.0 as usize].name, field.name);
                out.push(Node::Op(Op {
                    kind: OpKind::Field {
                        field: field.name.clone(),
                    },
                    functor: None,
                    inputs: vec![src],
                    outputs: vec![dst],
                    named: Vec::new(),
                    span: field.span,
                }));
                Value::Array(dst)
            }
            Value::Error => Value::Error,
            _ => {
                self.error(Diagnostic::error(
                    Code::UnknownField,
                    format!("host scalars have no fields (`.{}`)", field.name),
                    field.span,
                ));
                Value::Error
            }
        }
    }

    fn lower_call(&mut self, call: &Call, span: Span, out: &mut Vec<Node>) -> Value {
        let callee = call.callee.name.as_str();
        // Leading arrays from the left of an arrow.
        let mut positional: Vec<(Value, Span)> = Vec::new();
        if let Some(piped) = &call.piped {
            let value = self.lower_expr(piped, out);
            match value {
                Value::Tuple(vars) => {
                    positional.extend(vars.into_iter().map(|v| (Value::Array(v), piped.span)))
                }
                other => positional.push((other, piped.span)),
            }
        } else if call.args.is_none() {
            self.error(
                Diagnostic::error(
                    Code::Syntax,
                    format!("`{callee}` needs arguments in parentheses"),
                    span,
                )
                .with_help("only the right side of `→` may omit its parentheses"),
            );
            return Value::Error;
        }
        let mut named: Vec<(&Ident, &ast::Expr)> = Vec::new();
        for arg in call.args.iter().flatten() {
            match &arg.name {
                Some(name) => {
                    if named.iter().any(|(n, _)| n.name == name.name) {
                        self.error(Diagnostic::error(
                            Code::Duplicate,
                            format!("argument `{}` given twice", name.name),
                            name.span,
                        ));
                    }
                    named.push((name, &arg.value));
                }
                None => {
                    if !named.is_empty() {
                        self.error(Diagnostic::error(
                            Code::Syntax,
                            "positional arguments come before named ones",
                            arg.value.span,
                        ));
                    }
                    let value = self.lower_expr(&arg.value, out);
                    positional.push((value, arg.value.span));
                }
            }
        }

        if callee == COMPOSITE {
            return self.lower_composite(call, span, positional, named, out);
        }
        let primitive = Primitive::from_name(callee);
        if let Some(functor) = call.functor.as_ref().filter(|_| primitive.is_none()) {
            self.error(Diagnostic::error(
                Code::FunctorOnNonPrimitive,
                format!("`{callee}` is not a primitive and takes no functor"),
                functor.span,
            ));
            return Value::Error;
        }
        if let Some(primitive) = primitive {
            return self.lower_primitive(primitive, call, span, positional, named, out);
        }
        // A functor called by name (`sqrt(x)`, `dot(a, b)`, `random(i, seed: 2)`)
        // is element-wise; it may take its named arguments.
        let any_array = positional
            .iter()
            .any(|(v, _)| matches!(v, Value::Array(_) | Value::Tuple(_)));
        let host_function = HostFunction::ALL.iter().find(|(n, _)| *n == callee);
        let functor = self
            .library
            .get(callee)
            .map(|f| f.signature().clone())
            .filter(|s| matches!(s.kind, FunctorKind::Map | FunctorKind::Monoid(_)));
        let is_generator_or_fn =
            Generator::from_name(callee).is_some() || self.program.fns.contains_key(callee);
        if let (Some(signature), false, false) =
            (&functor, is_generator_or_fn, host_function.is_some())
        {
            if !any_array {
                self.error(
                    Diagnostic::error(
                        Code::ExpectedArray,
                        format!("`{callee}` is a functor: it applies element by element to arrays, and none of its arguments is one"),
                        span,
                    )
                    .with_help("give it at least one array; host scalars are broadcast"),
                );
                return Value::Error;
            }
            let Some(named_values) =
                self.named_arguments(callee, &signature.named, &named, &[], span, out)
            else {
                return Value::Error;
            };
            return self.elementwise(
                callee,
                None,
                positional,
                named_values,
                call.callee.span,
                out,
            );
        }
        // Everything else takes no named arguments.
        if let Some((name, _)) = named.first() {
            self.error(Diagnostic::error(
                Code::UnknownArgument,
                format!("`{callee}` takes no named arguments"),
                name.span,
            ));
            return Value::Error;
        }
        if let (Some((_, function)), true) = (host_function, any_array) {
            // The host functions over arrays: their element-wise functors.
            let functor = match (function, positional.len()) {
                (HostFunction::Vec2, 1) => "splat2",
                (HostFunction::Vec3, 1) => "splat3",
                (HostFunction::Vec4, 1) => "splat4",
                (HostFunction::Float, _) => "toF32",
                (function, _) => function.name(),
            };
            return self.elementwise(functor, None, positional, Vec::new(), call.callee.span, out);
        }
        match Generator::from_name(callee) {
            Some(generator @ (Generator::Iota | Generator::Fill)) => {
                let expected = if generator == Generator::Iota { 1 } else { 2 };
                if !self.check_count(callee, expected, positional.len(), span) {
                    return Value::Error;
                }
                let count = self.expect_host(positional[0].clone());
                let kind = if generator == Generator::Iota {
                    OpKind::Iota { count }
                } else {
                    OpKind::Fill {
                        count,
                        value: self.expect_host(positional[1].clone()),
                    }
                };
                let dst = self.new_temp(span);
                out.push(Node::Op(Op {
                    kind,
                    functor: None,
                    inputs: Vec::new(),
                    outputs: vec![dst],
                    named: Vec::new(),
                    span: call.callee.span,
                }));
                Value::Array(dst)
            }
            Some(Generator::Len) => {
                if !self.check_count("len", 1, positional.len(), span) {
                    return Value::Error;
                }
                match self.expect_array(positional[0].clone()) {
                    Some(v) => Value::Host(HostExpr::Len(v)),
                    None => Value::Error,
                }
            }
            None => {
                if let Some((_, function)) = HostFunction::ALL.iter().find(|(n, _)| *n == callee) {
                    let args = positional
                        .into_iter()
                        .map(|a| self.expect_host(a))
                        .collect();
                    return Value::Host(HostExpr::Call(*function, args));
                }
                if let Some(function) = self.program.fns.get(callee).copied() {
                    return self.inline_fn(function, call, span, positional, out);
                }
                let mut candidates: Vec<&str> = Primitive::ALL.map(Primitive::name).to_vec();
                candidates.extend(Generator::ALL.map(Generator::name));
                candidates.extend(HostFunction::ALL.iter().map(|(n, _)| *n));
                candidates.extend(self.program.fns.keys().copied());
                let mut diagnostic = Diagnostic::error(
                    Code::UnknownName,
                    format!("unknown function `{callee}`"),
                    call.callee.span,
                );
                if let Some(s) = did_you_mean(callee, candidates) {
                    diagnostic = diagnostic.with_help(format!("did you mean `{s}`?"));
                } else if self.library.get(callee).is_some() {
                    diagnostic = diagnostic.with_help(format!(
                        "`{callee}` is a functor: apply it with a primitive, like `map<{callee}>(…)`"
                    ));
                }
                self.error(diagnostic);
                Value::Error
            }
        }
    }

    /// A fn no call reaches is still checked for what does not depend on its
    /// arguments' types (unknown names, functors, arities), then discarded.
    fn check_uncalled_fns(&mut self) {
        let mut uncalled: Vec<&ast::FnItem> = self
            .program
            .fns
            .values()
            .copied()
            .filter(|f| !self.inlined.contains(&f.name.name))
            .collect();
        uncalled.sort_by_key(|f| (f.span.file, f.span.start));
        let vars_before = self.vars.len();
        for function in uncalled {
            let placeholder =
                self.new_var(&function.name.name, function.name.span, VarType::Unknown);
            let mut scope = Scope::new(ScopeKind::Function);
            for param in &function.params {
                scope
                    .names
                    .insert(param.name.clone(), Binding::Poisoned(placeholder));
            }
            self.fn_stack.push(function.name.name.clone());
            self.scopes.push(scope);
            let mut discarded = Vec::new();
            let stmts = &function.body.stmts;
            for (index, stmt) in stmts.iter().enumerate() {
                match &stmt.kind {
                    StmtKind::Return(expr) if index + 1 == stmts.len() => {
                        self.lower_expr(expr, &mut discarded);
                    }
                    _ => self.lower_block_in_scope(
                        &Block {
                            stmts: vec![stmt.clone()],
                            span: stmt.span,
                        },
                        &mut discarded,
                    ),
                }
            }
            self.scopes.pop();
            self.fn_stack.pop();
        }
        self.vars.truncate(vars_before);
    }

    fn check_count(&mut self, what: &str, expected: usize, found: usize, span: Span) -> bool {
        if expected == found {
            return true;
        }
        self.error(Diagnostic::error(
            Code::Arity,
            format!(
                "`{what}` takes {expected} argument{}, found {found}",
                if expected == 1 { "" } else { "s" }
            ),
            span,
        ));
        false
    }

    fn expect_host(&mut self, (value, span): (Value, Span)) -> HostExpr {
        match value {
            Value::Host(e) => e,
            Value::Error => self.error_host(span),
            _ => {
                self.error(Diagnostic::error(
                    Code::ExpectedScalar,
                    "expected a host scalar, found an array",
                    span,
                ));
                self.error_host(span)
            }
        }
    }

    fn expect_array(&mut self, (value, span): (Value, Span)) -> Option<VarId> {
        match value {
            Value::Array(v) => Some(v),
            Value::Error => None,
            Value::Host(_) => {
                self.error(Diagnostic::error(
                    Code::ExpectedArray,
                    "expected an array, found a host scalar",
                    span,
                ));
                None
            }
            Value::Tuple(v) => {
                self.error(Diagnostic::error(
                    Code::Arity,
                    format!("expected one array, found {}", v.len()),
                    span,
                ));
                None
            }
        }
    }

    fn inline_fn(
        &mut self,
        function: &ast::FnItem,
        call: &Call,
        span: Span,
        positional: Vec<(Value, Span)>,
        out: &mut Vec<Node>,
    ) -> Value {
        let name = function.name.name.clone();
        if self.fn_stack.contains(&name) {
            self.error(
                Diagnostic::error(
                    Code::Recursion,
                    format!("`{name}` calls itself; fns are inlined and cannot recurse"),
                    call.callee.span,
                )
                .with_label(function.name.span, "defined here"),
            );
            return Value::Error;
        }
        if positional.len() != function.params.len() {
            self.error(
                Diagnostic::error(
                    Code::Arity,
                    format!(
                        "`{name}` takes {} argument{}, found {}",
                        function.params.len(),
                        if function.params.len() == 1 { "" } else { "s" },
                        positional.len()
                    ),
                    span,
                )
                .with_label(function.name.span, "defined here"),
            );
            return Value::Error;
        }
        let mut scope = Scope::new(ScopeKind::Function);
        for (param, (value, arg_span)) in function.params.iter().zip(positional) {
            let binding = match value {
                // Arrays are immutable, so a parameter can share its argument's slot
                // unless the body rebinds it from a nested block (which updates the slot).
                Value::Array(v)
                    if !assigned_in_nested_block(&function.body, &param.name, false) =>
                {
                    Binding::Array(v)
                }
                Value::Array(v) => {
                    let copy = self.new_var(&param.name, param.span, VarType::Unknown);
                    out.push(Node::Alias { dst: copy, src: v });
                    Binding::Array(copy)
                }
                Value::Host(HostExpr::Var(v))
                    if !assigned_in_nested_block(&function.body, &param.name, false) =>
                {
                    Binding::Host(v)
                }
                Value::Host(expr) => {
                    let var = self.new_var(&param.name, param.span, VarType::Unknown);
                    out.push(Node::Host {
                        dst: var,
                        expr,
                        span: arg_span,
                    });
                    Binding::Host(var)
                }
                Value::Error => return Value::Error,
                Value::Tuple(_) => {
                    self.error(Diagnostic::error(
                        Code::Arity,
                        "a multi-output value cannot be a fn argument",
                        arg_span,
                    ));
                    return Value::Error;
                }
            };
            scope.names.insert(param.name.clone(), binding);
        }
        self.inlined.insert(name.clone());
        self.fn_stack.push(name.clone());
        self.scopes.push(scope);
        let stmts = &function.body.stmts;
        let result = match stmts.last() {
            Some(ast::Stmt {
                kind: StmtKind::Return(expr),
                ..
            }) => {
                for stmt in &stmts[..stmts.len() - 1] {
                    if let StmtKind::Return(_) = stmt.kind {
                        self.error(Diagnostic::error(
                            Code::Return,
                            "`return` must be the last statement of a fn",
                            stmt.span,
                        ));
                        continue;
                    }
                    self.lower_stmt(stmt, out);
                }
                self.lower_expr(expr, out)
            }
            _ => {
                self.error(Diagnostic::error(
                    Code::Return,
                    format!("`{name}` does not end with `return`"),
                    function.name.span,
                ));
                Value::Error
            }
        };
        self.scopes.pop();
        self.fn_stack.pop();
        result
    }

    /// `composite<blend>(a, b, …)`: the blend fn is inlined once, into the
    /// node's own body, with its first half of parameters bound to the front
    /// piece's arrays and its second half to the back piece's.
    fn lower_composite(
        &mut self,
        call: &Call,
        span: Span,
        positional: Vec<(Value, Span)>,
        named: Vec<(&Ident, &ast::Expr)>,
        out: &mut Vec<Node>,
    ) -> Value {
        let misplaced = |what: &str| {
            Diagnostic::error(Code::Composite, format!("`composite` {what}"), span).with_help(
                "composite once, at the top level of the pipeline: what follows runs on rank 0 alone",
            )
        };
        if !self.fn_stack.is_empty() || self.scopes.len() != 1 {
            self.error(misplaced(
                "must be at the top level of the pipeline, not in a fn, loop or branch",
            ));
            return Value::Error;
        }
        if let Some(first) = self.composited {
            self.error(misplaced("may appear only once").with_label(first, "the first one"));
            return Value::Error;
        }
        self.composited = Some(span);
        if let Some(output) = self.outputs.first() {
            self.error(misplaced(&format!(
                "comes after the output `{output}`, which would hold rank 0's part of the image only"
            )));
        }
        let Some(blend_name) = &call.functor else {
            self.error(
                Diagnostic::error(
                    Code::MissingFunctor,
                    "`composite` needs its blend: `composite<blend>(…)`, a fn of the file",
                    span,
                )
                .with_help("for opaque surfaces: `composite<nearestDepth>(depth, alpha, color)` with `use \"composite.dpp\"`"),
            );
            return Value::Error;
        };
        let Some(function) = self.program.fns.get(blend_name.name.as_str()).copied() else {
            let mut diagnostic = Diagnostic::error(
                Code::UnknownName,
                format!(
                    "the blend of `composite` must be a fn of the file; there is no fn `{}`",
                    blend_name.name
                ),
                blend_name.span,
            );
            if let Some(s) = did_you_mean(&blend_name.name, self.program.fns.keys().copied()) {
                diagnostic = diagnostic.with_help(format!("did you mean `{s}`?"));
            }
            self.error(diagnostic);
            return Value::Error;
        };
        let mut visibility = HostExpr::Const(HostValue::Bool(false));
        for (name, value) in named {
            if name.name == "visibility" {
                visibility = self.lower_host(value, out);
            } else {
                self.error(
                    Diagnostic::error(
                        Code::UnknownArgument,
                        format!("`composite` has no argument `{}`", name.name),
                        name.span,
                    )
                    .with_help("its one named argument is `visibility: BOOL`"),
                );
            }
        }
        let mut inputs = Vec::new();
        for argument in positional {
            match self.expect_array(argument) {
                Some(var) => inputs.push(var),
                None => return Value::Error,
            }
        }
        if inputs.is_empty() {
            self.error(Diagnostic::error(
                Code::Arity,
                "`composite` takes the arrays of this rank's image: at least one",
                span,
            ));
            return Value::Error;
        }
        let piece = |lowerer: &mut Self, side: &str| -> Vec<VarId> {
            (inputs.iter())
                .map(|&input| {
                    let name = format!("{side}.{}", lowerer.vars[input.0 as usize].name);
                    lowerer.new_var(&name, span, VarType::Unknown)
                })
                .collect()
        };
        let front = piece(self, "front");
        let back = piece(self, "back");
        let arguments = (front.iter().chain(&back))
            .map(|&v| (Value::Array(v), span))
            .collect();
        let mut blend = Vec::new();
        let blended = match self.inline_fn(function, call, span, arguments, &mut blend) {
            Value::Array(var) if inputs.len() == 1 => vec![var],
            Value::Tuple(vars) if vars.len() == inputs.len() => vars,
            Value::Error => return Value::Error,
            other => {
                let found = match other {
                    Value::Tuple(vars) => format!("{} arrays", vars.len()),
                    Value::Array(_) => "one array".to_string(),
                    _ => "a host scalar".to_string(),
                };
                self.error(
                    Diagnostic::error(
                        Code::Composite,
                        format!(
                            "the blend `{}` must return {} array{} (one per array composited), found {found}",
                            blend_name.name,
                            inputs.len(),
                            if inputs.len() == 1 { "" } else { "s" }
                        ),
                        span,
                    )
                    .with_label(function.name.span, "defined here"),
                );
                return Value::Error;
            }
        };
        let outputs: Vec<VarId> = (inputs.iter())
            .map(|&input| {
                let name = self.vars[input.0 as usize].name.clone();
                self.new_var(&name, span, VarType::Unknown)
            })
            .collect();
        out.push(Node::Composite(Box::new(Composite {
            blend_fn: blend_name.name.clone(),
            inputs,
            outputs: outputs.clone(),
            front,
            back,
            blend,
            blended,
            visibility,
            span,
        })));
        match outputs[..] {
            [single] => Value::Array(single),
            _ => Value::Tuple(outputs),
        }
    }

    fn lower_primitive(
        &mut self,
        primitive: Primitive,
        call: &Call,
        span: Span,
        positional: Vec<(Value, Span)>,
        named: Vec<(&Ident, &ast::Expr)>,
        out: &mut Vec<Node>,
    ) -> Value {
        let functor = match &call.functor {
            Some(f) => match self.library.get(&f.name) {
                Some(functor) => Some((f, functor.signature().clone())),
                None => {
                    let mut diagnostic = Diagnostic::error(
                        Code::UnknownFunctor,
                        format!("unknown functor `{}`", f.name),
                        f.span,
                    );
                    if let Some(s) = did_you_mean(&f.name, self.library.names()) {
                        diagnostic = diagnostic.with_help(format!("did you mean `{s}`?"));
                    } else {
                        diagnostic = diagnostic.with_help("`dpp functors` lists every functor");
                    }
                    self.error(diagnostic);
                    return Value::Error;
                }
            },
            None => None,
        };
        let arrays: Vec<Option<VarId>> = positional
            .into_iter()
            .map(|p| self.expect_array(p))
            .collect();
        if arrays.iter().any(Option::is_none) {
            return Value::Error;
        }
        let arrays: Vec<VarId> = arrays.into_iter().flatten().collect();

        // The primitive's own keys; every other named argument belongs to the functor.
        let primitive_keys: &[&str] = match (primitive, functor.as_ref().map(|(_, s)| s.kind)) {
            (Primitive::Gather, Some(_)) => &["group"],
            (Primitive::Scatter, Some(FunctorKind::Expand)) => &["fanout"],
            (Primitive::Scatter, _) => &["len", "into", "mask"],
            (Primitive::Scan | Primitive::ExclusiveScan, _) => &["segments"],
            _ => &[],
        };
        let mut keys: HashMap<&str, &ast::Expr> = HashMap::new();
        let mut functor_named: Vec<(&Ident, &ast::Expr)> = Vec::new();
        for (name, value) in named {
            if primitive_keys.contains(&name.name.as_str()) {
                keys.insert(name.name.as_str(), value);
            } else {
                functor_named.push((name, value));
            }
        }

        let (kind, expected_kinds, arity): (OpKind, &[&str], Option<usize>) = match primitive {
            Primitive::Map => (OpKind::Map, &["map", "monoid"], None),
            Primitive::Gather if functor.is_some() => {
                let Some(group) = self.required_key(&keys, "group", span, out) else {
                    return Value::Error;
                };
                (OpKind::GroupGather { group }, &["group"], Some(1))
            }
            Primitive::Gather => (OpKind::Gather, &[], Some(2)),
            Primitive::Scatter
                if matches!(
                    functor.as_ref().map(|(_, s)| s.kind),
                    Some(FunctorKind::Expand)
                ) =>
            {
                let Some(fanout) = self.required_key(&keys, "fanout", span, out) else {
                    return Value::Error;
                };
                (OpKind::Expand { fanout }, &["expand"], Some(1))
            }
            Primitive::Scatter => {
                let target = match (keys.get("len"), keys.get("into")) {
                    (Some(len), None) => ScatterTarget::Len(self.lower_host(len, out)),
                    (None, Some(into)) => match self.lower_array(into, out) {
                        Some(dst) => ScatterTarget::Into(dst),
                        None => return Value::Error,
                    },
                    (Some(_), Some(_)) => {
                        self.error(Diagnostic::error(
                            Code::ScatterTarget,
                            "`scatter` takes `len:` or `into:`, not both",
                            span,
                        ));
                        return Value::Error;
                    }
                    (None, None) => {
                        self.error(Diagnostic::error(
                            Code::ScatterTarget,
                            "`scatter` needs `len: m` (a new array) or `into: dst` (a copy of dst)",
                            span,
                        ));
                        return Value::Error;
                    }
                };
                if functor.is_some() && !matches!(target, ScatterTarget::Into(_)) {
                    self.error(Diagnostic::error(
                        Code::ScatterTarget,
                        "a combining `scatter<f>` needs `into: dst`",
                        span,
                    ));
                    return Value::Error;
                }
                let mask = match keys.get("mask") {
                    Some(mask) => match self.lower_array(mask, out) {
                        Some(m) => Some(m),
                        None => return Value::Error,
                    },
                    None => None,
                };
                let combine = functor.as_ref().and_then(|(_, s)| monoid(s));
                (
                    OpKind::Scatter {
                        target,
                        mask,
                        combine,
                    },
                    &["monoid", "expand"],
                    Some(2),
                )
            }
            // No functor: the order is the keys' own (docs/language.md §3, sort).
            Primitive::Sort | Primitive::SortByKey => {
                if let Some((f, _)) = &functor {
                    self.error(
                        Diagnostic::error(
                            Code::FunctorKind,
                            format!("`{primitive}` takes no functor"),
                            f.span,
                        )
                        .with_help("it sorts ascending by the keys' own order; map the keys first to order by something else"),
                    );
                    return Value::Error;
                }
                let by_key = primitive == Primitive::SortByKey;
                (OpKind::Sort { by_key }, &[], Some(1 + usize::from(by_key)))
            }
            Primitive::Reduce | Primitive::Scan | Primitive::ExclusiveScan => {
                let Some((f, signature)) = functor.as_ref() else {
                    self.error(Diagnostic::error(
                        Code::MissingFunctor,
                        format!(
                            "`{primitive}` needs an associative functor, like `{primitive}<add>`"
                        ),
                        call.callee.span,
                    ));
                    return Value::Error;
                };
                let Some(op) = monoid(signature) else {
                    self.error(Diagnostic::error(
                        Code::FunctorKind,
                        format!("`{}` is not associative; `{primitive}` takes add, mul, min, max, or, and", f.name),
                        f.span,
                    ));
                    return Value::Error;
                };
                let kind = if primitive == Primitive::Reduce {
                    OpKind::Reduce { op }
                } else {
                    let segments = match keys.get("segments") {
                        Some(flags) => match self.lower_array(flags, out) {
                            Some(v) => Some(v),
                            None => return Value::Error,
                        },
                        None => None,
                    };
                    OpKind::Scan {
                        op,
                        exclusive: primitive == Primitive::ExclusiveScan,
                        segments,
                    }
                };
                (kind, &["monoid"], Some(1))
            }
        };

        // The functor's kind must suit the primitive form.
        if let Some((f, signature)) = &functor {
            let kind_name = match signature.kind {
                FunctorKind::Map => "map",
                FunctorKind::Group => "group",
                FunctorKind::Expand => "expand",
                FunctorKind::Monoid(_) => "monoid",
            };
            if !expected_kinds.contains(&kind_name) {
                let hint = match signature.kind {
                    FunctorKind::Map | FunctorKind::Monoid(_) => {
                        format!("apply it with `map<{}>(…)`", f.name)
                    }
                    FunctorKind::Group => {
                        format!("apply it with `gather<{}>(src, group: k)`", f.name)
                    }
                    FunctorKind::Expand => {
                        format!("apply it with `scatter<{}>(src, fanout: k)`", f.name)
                    }
                };
                self.error(
                    Diagnostic::error(
                        Code::FunctorKind,
                        format!(
                            "`{}` is a {kind_name} functor and cannot be used with `{primitive}`",
                            f.name
                        ),
                        f.span,
                    )
                    .with_help(hint),
                );
                return Value::Error;
            }
        } else if primitive == Primitive::Map {
            self.error(Diagnostic::error(
                Code::MissingFunctor,
                "`map` needs a functor, like `map<add>(a, b)`",
                call.callee.span,
            ));
            return Value::Error;
        }

        // Arity: the functor's inputs for map, the primitive's own otherwise.
        let expected_arity = match (&kind, &functor) {
            (OpKind::Map, Some((_, s))) => s.inputs.len(),
            _ => arity.unwrap_or(0),
        };
        if arrays.len() != expected_arity {
            let what = match &functor {
                Some((f, _)) => format!("`{primitive}<{}>`", f.name),
                None => format!("`{primitive}`"),
            };
            let mut diagnostic = Diagnostic::error(
                Code::Arity,
                format!(
                    "{what} takes {expected_arity} array argument{}, found {}",
                    if expected_arity == 1 { "" } else { "s" },
                    arrays.len()
                ),
                span,
            );
            if let (OpKind::Map, Some((_, s))) = (&kind, &functor) {
                diagnostic = diagnostic.with_help(format!(
                    "signature: {}",
                    s.display(&self.library.records).trim()
                ));
            }
            self.error(diagnostic);
            return Value::Error;
        }

        let signature_named = functor
            .as_ref()
            .map(|(_, s)| s.named.clone())
            .unwrap_or_default();
        let functor_name = call.functor.as_ref().map_or("", |f| f.name.as_str());
        let Some(named_values) = self.named_arguments(
            functor_name,
            &signature_named,
            &functor_named,
            primitive_keys,
            span,
            out,
        ) else {
            return Value::Error;
        };

        let output_count = match (&kind, &functor) {
            (OpKind::Reduce { .. }, _) => 1,
            (OpKind::Sort { by_key: true }, _) => 2,
            (_, Some((_, s)))
                if matches!(
                    kind,
                    OpKind::Map | OpKind::GroupGather { .. } | OpKind::Expand { .. }
                ) =>
            {
                s.outputs.len()
            }
            _ => 1,
        };
        let outputs: Vec<VarId> = (0..output_count).map(|_| self.new_temp(span)).collect();
        let is_reduce = matches!(kind, OpKind::Reduce { .. });
        out.push(Node::Op(Op {
            kind,
            functor: functor.map(|(f, _)| f.name.clone()),
            inputs: arrays,
            outputs: outputs.clone(),
            named: named_values,
            span,
        }));
        if is_reduce {
            Value::Host(HostExpr::Var(outputs[0]))
        } else if outputs.len() == 1 {
            Value::Array(outputs[0])
        } else {
            Value::Tuple(outputs)
        }
    }

    /// A functor's named arguments in signature order, defaults filled in;
    /// `None` when one it needs is missing. `other_keys` are the primitive's
    /// own, offered when a name is unknown.
    fn named_arguments(
        &mut self,
        functor: &str,
        signature_named: &[NamedParam],
        given: &[(&Ident, &ast::Expr)],
        other_keys: &[&str],
        span: Span,
        out: &mut Vec<Node>,
    ) -> Option<Vec<(String, HostExpr)>> {
        for (name, _) in given {
            if !signature_named.iter().any(|p| p.name == name.name) {
                let mut candidates: Vec<&str> = signature_named.iter().map(|p| p.name).collect();
                candidates.extend(other_keys);
                let mut diagnostic = Diagnostic::error(
                    Code::UnknownArgument,
                    format!("unknown argument `{}`", name.name),
                    name.span,
                );
                if let Some(s) = did_you_mean(&name.name, candidates.iter().copied()) {
                    diagnostic = diagnostic.with_help(format!("did you mean `{s}`?"));
                } else if candidates.is_empty() {
                    diagnostic = diagnostic.with_help("this takes no named arguments");
                } else {
                    diagnostic =
                        diagnostic.with_help(format!("it takes: {}", candidates.join(", ")));
                }
                self.error(diagnostic);
            }
        }
        let mut values = Vec::new();
        for param in signature_named {
            match given.iter().find(|(n, _)| n.name == param.name) {
                Some((_, value)) => {
                    let expr = self.lower_host(value, out);
                    values.push((param.name.to_string(), expr));
                }
                None => match param.default {
                    Some(default) => {
                        values.push((param.name.to_string(), HostExpr::Const(default)))
                    }
                    None => {
                        self.error(Diagnostic::error(
                            Code::MissingArgument,
                            format!(
                                "`{functor}` needs the argument `{}: {}`",
                                param.name, param.ty
                            ),
                            span,
                        ));
                        return None;
                    }
                },
            }
        }
        Some(values)
    }

    fn required_key(
        &mut self,
        keys: &HashMap<&str, &ast::Expr>,
        key: &str,
        span: Span,
        out: &mut Vec<Node>,
    ) -> Option<HostExpr> {
        match keys.get(key) {
            Some(expr) => Some(self.lower_host(expr, out)),
            None => {
                self.error(Diagnostic::error(
                    Code::MissingArgument,
                    format!("this form needs `{key}: k`"),
                    span,
                ));
                None
            }
        }
    }
}

fn monoid(signature: &Signature) -> Option<crate::monoid::MonoidOp> {
    match signature.kind {
        FunctorKind::Monoid(op) => Some(op),
        _ => None,
    }
}

/// Renames output `from` of the op that defines it to `to`, when that op is the
/// last of `nodes` (the statement's) and no other node there reads `from`.
/// Renaming an earlier op would lose a later write of `from` (a fn's branch or
/// loop rebinding its result) or change what the later nodes read of `to`.
fn rename_output(nodes: &mut [Node], from: VarId, to: VarId) -> bool {
    let mut read = false;
    walk_nodes(nodes, &mut |node| {
        read |= node_reads(node).contains(&from);
    });
    if read {
        return false;
    }
    if let Some(Node::Op(op)) = nodes.last_mut() {
        if let Some(output) = op.outputs.iter_mut().find(|o| **o == from) {
            *output = to;
            return true;
        }
    }
    false
}

/// Whether `name` is bound inside a nested block (loop or branch) of `block`.
fn assigned_in_nested_block(block: &Block, name: &str, nested: bool) -> bool {
    block.stmts.iter().any(|stmt| match &stmt.kind {
        StmtKind::Bind { targets, .. } => nested && targets.iter().any(|t| t.name == name),
        StmtKind::Out { name: target, .. } => nested && target.name == name,
        StmtKind::For { body, .. } | StmtKind::While { body, .. } => {
            assigned_in_nested_block(body, name, true)
        }
        StmtKind::If {
            then_block,
            else_block,
            ..
        } => {
            assigned_in_nested_block(then_block, name, true)
                || else_block
                    .as_ref()
                    .is_some_and(|b| assigned_in_nested_block(b, name, true))
        }
        _ => false,
    })
}
