//! Pass 4: infer the type and symbolic length of every variable, and check
//! every op against its functor's signature and its primitive's rules.

use super::desugar::{broadcast, swizzle, vector_of_width, OperandType};
use super::ir::*;
use crate::functor::FunctorLibrary;
use crate::host::HostValue;
use crate::monoid::monoid_supports;
use crate::signature::TypePattern;
use crate::types::{ElemType, HostType, RecordRegistry};
use dpp_dsl::ast::{BinaryOp, UnaryOp};
use dpp_dsl::{did_you_mean, Code, Diagnostic, Span};

pub fn typecheck(
    vars: &mut [VarInfo],
    body: &[Node],
    library: &FunctorLibrary,
    diagnostics: &mut Vec<Diagnostic>,
) {
    let mut definitions = vec![0u32; vars.len()];
    walk_nodes(body, &mut |node| {
        for v in node_writes(node) {
            definitions[v.0 as usize] += 1;
        }
    });
    let mut checker = Checker {
        vars,
        library,
        diagnostics,
        definitions,
    };
    checker.check_nodes(body);
}

struct Checker<'a> {
    vars: &'a mut [VarInfo],
    library: &'a FunctorLibrary,
    diagnostics: &'a mut Vec<Diagnostic>,
    definitions: Vec<u32>,
}

/// The host type a reduction of `ty` elements produces.
pub fn host_type_of_elem(ty: ElemType) -> Option<HostType> {
    Some(match ty {
        ElemType::Bool => HostType::Bool,
        ElemType::U32 | ElemType::I32 => HostType::Int,
        ElemType::F32 => HostType::Float,
        ElemType::Vec2 => HostType::Vec2,
        ElemType::Vec3 => HostType::Vec3,
        ElemType::Vec4 => HostType::Vec4,
        ElemType::Record(_) => return None,
    })
}

impl Checker<'_> {
    fn records(&self) -> &RecordRegistry {
        &self.library.records
    }

    fn type_name(&self, ty: VarType) -> String {
        match ty {
            VarType::Unknown => "unknown".into(),
            VarType::Array(e) => format!("array of {}", e.name(self.records())),
            VarType::Host(h) => format!("host {h}"),
        }
    }

    /// Gives `var` its type; a slot defined again with another type is an error.
    fn assign(&mut self, var: VarId, ty: VarType, len: Option<HostExpr>, span: Span) {
        let info = &self.vars[var.0 as usize];
        if info.ty != VarType::Unknown && info.ty != ty && ty != VarType::Unknown {
            let message = format!(
                "`{}` is {} elsewhere but {} here; a name rebound in a loop or branch keeps its type",
                info.name,
                self.type_name(info.ty),
                self.type_name(ty)
            );
            let first = info.span;
            self.diagnostics.push(
                Diagnostic::error(Code::TypeMismatch, message, span)
                    .with_label(first, "first bound here"),
            );
            return;
        }
        let single_definition = self.definitions[var.0 as usize] <= 1;
        let info = &mut self.vars[var.0 as usize];
        info.ty = ty;
        // A slot written several times (loop state) has no single symbolic length.
        info.len = if matches!(ty, VarType::Array(_)) {
            Some(match len {
                Some(len) if single_definition => len,
                _ => HostExpr::Len(var),
            })
        } else {
            None
        };
    }

    fn array_type(&self, var: VarId) -> Option<ElemType> {
        match self.vars[var.0 as usize].ty {
            VarType::Array(t) => Some(t),
            _ => None,
        }
    }

    fn symbolic_len(&self, var: VarId) -> HostExpr {
        self.vars[var.0 as usize]
            .len
            .clone()
            .unwrap_or(HostExpr::Len(var))
    }

    fn check_nodes(&mut self, nodes: &[Node]) {
        for node in nodes {
            match node {
                Node::Op(op) => self.check_op(op),
                Node::Stage(stage) => stage.ops.iter().for_each(|op| self.check_op(op)),
                Node::Host { dst, expr, span } => {
                    let ty = self.host_type(expr, *span);
                    if let Some(ty) = ty {
                        self.assign(*dst, VarType::Host(ty), None, *span);
                    }
                }
                Node::Alias { dst, src } => {
                    let ty = self.vars[src.0 as usize].ty;
                    let len = self.symbolic_len(*src);
                    let span = self.vars[dst.0 as usize].span;
                    self.assign(*dst, ty, Some(len), span);
                }
                Node::For {
                    start,
                    end,
                    body,
                    span,
                    ..
                } => {
                    self.expect_host(start, HostType::Int, *span, "a loop bound");
                    self.expect_host(end, HostType::Int, *span, "a loop bound");
                    self.check_nodes(body);
                }
                Node::While { cond, body, span } => {
                    self.expect_host(cond, HostType::Bool, *span, "a condition");
                    self.check_nodes(body);
                }
                Node::If {
                    cond,
                    then_body,
                    else_body,
                    span,
                } => {
                    self.expect_host(cond, HostType::Bool, *span, "a condition");
                    self.check_nodes(then_body);
                    self.check_nodes(else_body);
                }
                Node::Composite(composite) => self.check_composite(composite),
                Node::Break | Node::Output { .. } | Node::View { .. } => {}
            }
        }
    }

    /// The pieces a blend combines have the types of the arrays composited,
    /// and so must what it returns: the composited image has them too.
    fn check_composite(&mut self, composite: &Composite) {
        let span = composite.span;
        self.expect_host(&composite.visibility, HostType::Bool, span, "`visibility:`");
        // Both pieces are ranges of the same pixels: one length for all their
        // arrays, so that the blend's maps fuse into one stage.
        let piece_len = composite.front.first().map(|&front| HostExpr::Len(front));
        for (index, &input) in composite.inputs.iter().enumerate() {
            let ty = self.vars[input.0 as usize].ty;
            self.assign(composite.front[index], ty, piece_len.clone(), span);
            self.assign(composite.back[index], ty, piece_len.clone(), span);
        }
        self.check_nodes(&composite.blend);
        for (index, &input) in composite.inputs.iter().enumerate() {
            let (ty, blended) = (
                self.vars[input.0 as usize].ty,
                self.vars[composite.blended[index].0 as usize].ty,
            );
            if blended != VarType::Unknown && ty != VarType::Unknown && blended != ty {
                let message = format!(
                    "the blend `{}` returns {} as its value number {}, but the array composited there, `{}`, is {}",
                    composite.blend_fn,
                    self.type_name(blended),
                    index + 1,
                    self.vars[input.0 as usize].name,
                    self.type_name(ty)
                );
                self.diagnostics
                    .push(Diagnostic::error(Code::Composite, message, span));
            }
            let len = self.symbolic_len(input);
            self.assign(composite.outputs[index], ty, Some(len), span);
        }
    }

    fn expect_host(&mut self, expr: &HostExpr, expected: HostType, span: Span, what: &str) {
        if let Some(found) = self.host_type(expr, span) {
            if !found.fits(expected) {
                self.diagnostics.push(Diagnostic::error(
                    Code::TypeMismatch,
                    format!("{what} must be {expected}, found {found}"),
                    span,
                ));
            }
        }
    }

    fn host_type(&mut self, expr: &HostExpr, span: Span) -> Option<HostType> {
        match host_type(expr, self.vars, &self.library.uniforms) {
            Ok(ty) => ty,
            Err(message) => {
                self.diagnostics
                    .push(Diagnostic::error(Code::TypeMismatch, message, span));
                None
            }
        }
    }

    fn mismatch(&mut self, span: Span, message: String) {
        self.diagnostics
            .push(Diagnostic::error(Code::TypeMismatch, message, span));
    }

    /// Lengths that fold to different constants are a compile-time error.
    fn check_same_length(&mut self, op: &Op, arrays: &[VarId]) {
        let mut first: Option<(VarId, i64)> = None;
        for &a in arrays {
            let Some(n) = fold_constant(&self.symbolic_len(a)) else {
                continue;
            };
            match first {
                None => first = Some((a, n)),
                Some((b, m)) if m != n => {
                    let message = format!(
                        "length mismatch: `{}` has {m} elements but `{}` has {n}",
                        self.vars[b.0 as usize].name, self.vars[a.0 as usize].name
                    );
                    self.diagnostics.push(Diagnostic::error(
                        Code::LengthMismatch,
                        message,
                        op.span,
                    ));
                    return;
                }
                _ => {}
            }
        }
    }

    fn check_op(&mut self, op: &Op) {
        for &input in &op.array_reads() {
            if self.array_type(input).is_none() {
                // Reading a variable whose type is unknown: an earlier error.
                return;
            }
        }
        let signature = op
            .functor
            .as_ref()
            .and_then(|f| self.library.get(f))
            .map(|f| f.signature().clone());
        if let Some(signature) = &signature {
            for ((name, expr), param) in op.named.iter().zip(&signature.named) {
                if let Some(found) = self.host_type(expr, op.span) {
                    if !found.fits(param.ty) {
                        self.mismatch(
                            op.span,
                            format!("argument `{name}` must be {}, found {found}", param.ty),
                        );
                    }
                }
            }
        }
        let input_types: Vec<ElemType> = op
            .inputs
            .iter()
            .filter_map(|v| self.array_type(*v))
            .collect();
        let first_len = op.inputs.first().map(|v| self.symbolic_len(*v));
        match &op.kind {
            OpKind::Field { field } if input_types[0].is_vector() => {
                let width = input_types[0].components();
                match swizzle(field, width) {
                    Some(components) => {
                        let ty = vector_of_width(components.len());
                        self.assign(op.outputs[0], VarType::Array(ty), first_len, op.span);
                    }
                    None => {
                        let ty = input_types[0].name(self.records());
                        let letters = &"xyzw"[..width as usize];
                        self.diagnostics.push(
                            Diagnostic::error(
                                Code::UnknownField,
                                format!("`.{field}`: an array of {ty} has no such components"),
                                op.span,
                            )
                            .with_help(format!(
                                "pick up to 4 of its components {}, like `.x` or `.{}`",
                                letters
                                    .chars()
                                    .map(|c| format!("`{c}`"))
                                    .collect::<Vec<_>>()
                                    .join(", "),
                                letters.chars().rev().collect::<String>()
                            )),
                        );
                    }
                }
            }
            OpKind::Elementwise { operands, .. } => {
                let Some(signature) = signature else { return };
                let mut types = Vec::with_capacity(operands.len());
                for operand in operands {
                    types.push(match operand {
                        Operand::Array(v) => match self.array_type(*v) {
                            Some(t) => OperandType::Array(t),
                            None => return,
                        },
                        Operand::Host(e) => match self.host_type(e, op.span) {
                            Some(h) => OperandType::Host(h),
                            None => return,
                        },
                    });
                }
                let what = elementwise_name(op);
                match broadcast(&signature, &types, self.records(), &what) {
                    Ok(broadcast) => {
                        self.check_same_length(op, &op.inputs);
                        for (output, ty) in op.outputs.iter().zip(broadcast.outputs) {
                            self.assign(*output, VarType::Array(ty), first_len.clone(), op.span);
                        }
                    }
                    Err(message) => self.diagnostics.push(
                        Diagnostic::error(Code::TypeMismatch, message, op.span).with_help(format!(
                            "signature: {}",
                            signature.display(self.records()).trim()
                        )),
                    ),
                }
            }
            OpKind::Field { field } => {
                let ElemType::Record(id) = input_types[0] else {
                    let ty = input_types[0].name(self.records());
                    self.mismatch(
                        op.span,
                        format!("`.{field}`: an array of {ty} has no fields"),
                    );
                    return;
                };
                let record = self.records().get(id).clone();
                match record.field_index(field) {
                    Some(index) => {
                        let ty = record.fields[index].1;
                        self.assign(op.outputs[0], VarType::Array(ty), first_len, op.span);
                    }
                    None => {
                        let mut diagnostic = Diagnostic::error(
                            Code::UnknownField,
                            format!("`{}` has no field `{field}`", record.name),
                            op.span,
                        );
                        let names = record.fields.iter().map(|(n, _)| n.as_str());
                        if let Some(s) = did_you_mean(field, names) {
                            diagnostic = diagnostic.with_help(format!("did you mean `{s}`?"));
                        } else {
                            let all: Vec<&str> =
                                record.fields.iter().map(|(n, _)| n.as_str()).collect();
                            diagnostic =
                                diagnostic.with_help(format!("its fields: {}", all.join(", ")));
                        }
                        self.diagnostics.push(diagnostic);
                    }
                }
            }
            OpKind::Iota { count } => {
                self.expect_host(count, HostType::Int, op.span, "a length");
                self.assign(
                    op.outputs[0],
                    VarType::Array(ElemType::U32),
                    Some(count.clone()),
                    op.span,
                );
            }
            OpKind::Fill { count, value } => {
                self.expect_host(count, HostType::Int, op.span, "a length");
                if let Some(ty) = self.host_type(value, op.span) {
                    self.assign(
                        op.outputs[0],
                        VarType::Array(ty.elem_type()),
                        Some(count.clone()),
                        op.span,
                    );
                }
            }
            OpKind::Map | OpKind::GroupGather { .. } | OpKind::Expand { .. } => {
                let Some(signature) = signature else { return };
                let Some(outputs) = self.instantiate(op, &signature, &input_types) else {
                    return;
                };
                let len = match &op.kind {
                    OpKind::Map => {
                        self.check_same_length(op, &op.inputs);
                        first_len
                    }
                    OpKind::GroupGather { group } => {
                        self.expect_host(group, HostType::Int, op.span, "`group`");
                        first_len.map(|l| {
                            HostExpr::Binary(BinaryOp::Div, Box::new(l), Box::new(group.clone()))
                        })
                    }
                    OpKind::Expand { fanout } => {
                        self.expect_host(fanout, HostType::Int, op.span, "`fanout`");
                        first_len.map(|l| {
                            HostExpr::Binary(BinaryOp::Mul, Box::new(l), Box::new(fanout.clone()))
                        })
                    }
                    _ => unreachable!(),
                };
                for (output, ty) in op.outputs.iter().zip(outputs) {
                    self.assign(*output, VarType::Array(ty), len.clone(), op.span);
                }
            }
            OpKind::Gather => {
                if input_types[0] != ElemType::U32 {
                    let ty = input_types[0].name(self.records());
                    self.mismatch(op.span, format!("`gather` indices must be u32, found {ty}"));
                    return;
                }
                self.assign(
                    op.outputs[0],
                    VarType::Array(input_types[1]),
                    first_len,
                    op.span,
                );
            }
            OpKind::Scatter {
                target,
                mask,
                combine,
            } => {
                if input_types[0] != ElemType::U32 {
                    let ty = input_types[0].name(self.records());
                    self.mismatch(
                        op.span,
                        format!("`scatter` indices must be u32, found {ty}"),
                    );
                    return;
                }
                let source = input_types[1];
                self.check_same_length(op, &op.inputs);
                if let Some(mask) = mask {
                    if self.array_type(*mask) != Some(ElemType::Bool) {
                        self.mismatch(op.span, "`mask` must be an array of bool".into());
                        return;
                    }
                    self.check_same_length(op, &[op.inputs[0], *mask]);
                }
                if let Some(combine) = combine {
                    if !monoid_supports(*combine, source) {
                        let ty = source.name(self.records());
                        self.mismatch(
                            op.span,
                            format!("`{combine:?}` cannot combine {ty}").to_lowercase(),
                        );
                        return;
                    }
                }
                let len = match target {
                    ScatterTarget::Len(len) => {
                        self.expect_host(len, HostType::Int, op.span, "`len`");
                        Some(len.clone())
                    }
                    ScatterTarget::Into(dst) => {
                        if self.array_type(*dst) != Some(source) {
                            let message = format!(
                                "`into` must have the element type of the scattered values ({}), found {}",
                                source.name(self.records()),
                                self.type_name(self.vars[dst.0 as usize].ty)
                            );
                            self.mismatch(op.span, message);
                            return;
                        }
                        Some(self.symbolic_len(*dst))
                    }
                };
                self.assign(op.outputs[0], VarType::Array(source), len, op.span);
            }
            OpKind::Sort { by_key } => {
                let keys = input_types[0];
                if !is_sort_key(keys) {
                    let ty = keys.name(self.records());
                    let primitive = op.label();
                    self.mismatch(
                        op.span,
                        format!("`{primitive}` keys must be u32, i32 or f32, found {ty}"),
                    );
                    return;
                }
                if *by_key {
                    self.check_same_length(op, &op.inputs);
                }
                for (output, ty) in op.outputs.iter().zip(input_types) {
                    self.assign(*output, VarType::Array(ty), first_len.clone(), op.span);
                }
            }
            OpKind::Reduce { op: monoid } | OpKind::Scan { op: monoid, .. } => {
                let ty = input_types[0];
                if !monoid_supports(*monoid, ty) {
                    let name = ty.name(self.records());
                    let functor = op.functor.clone().unwrap_or_default();
                    self.mismatch(op.span, format!("`{functor}` cannot combine {name}"));
                    return;
                }
                match &op.kind {
                    OpKind::Reduce { .. } => {
                        let host = host_type_of_elem(ty).expect("monoids take no records");
                        self.assign(op.outputs[0], VarType::Host(host), None, op.span);
                    }
                    OpKind::Scan { segments, .. } => {
                        if let Some(flags) = segments {
                            if self.array_type(*flags) != Some(ElemType::Bool) {
                                self.mismatch(
                                    op.span,
                                    "`segments` must be an array of bool".into(),
                                );
                                return;
                            }
                            self.check_same_length(op, &[op.inputs[0], *flags]);
                        }
                        self.assign(op.outputs[0], VarType::Array(ty), first_len, op.span);
                    }
                    _ => unreachable!(),
                }
            }
        }
    }

    /// Binds the signature's type variables from the inputs; returns the output types.
    fn instantiate(
        &mut self,
        op: &Op,
        signature: &crate::signature::Signature,
        inputs: &[ElemType],
    ) -> Option<Vec<ElemType>> {
        let mut bound: Vec<Option<ElemType>> = vec![None; 8];
        for (index, (param, &actual)) in signature.inputs.iter().zip(inputs).enumerate() {
            let ok = match param.ty {
                TypePattern::Exact(expected) => expected == actual,
                TypePattern::Var(n, constraint) => {
                    let slot = &mut bound[n as usize];
                    match slot {
                        Some(previous) => *previous == actual,
                        None if constraint.admits(actual) => {
                            *slot = Some(actual);
                            true
                        }
                        None => false,
                    }
                }
            };
            if !ok {
                let expected = match param.ty {
                    TypePattern::Exact(t) => t.name(self.records()),
                    TypePattern::Var(n, c) => match bound[n as usize] {
                        Some(t) => t.name(self.records()),
                        None => c.describe().to_string(),
                    },
                };
                let message = format!(
                    "argument {} (`{}`) of `{}` must be {expected}, found {}",
                    index + 1,
                    param.name,
                    signature.name,
                    actual.name(self.records())
                );
                self.diagnostics.push(
                    Diagnostic::error(Code::TypeMismatch, message, op.span).with_help(format!(
                        "signature: {}",
                        signature.display(self.records()).trim()
                    )),
                );
                return None;
            }
        }
        signature
            .outputs
            .iter()
            .map(|p| match p.ty {
                TypePattern::Exact(t) => Some(t),
                TypePattern::Var(n, _) => bound[n as usize],
            })
            .collect()
    }
}

/// Whether `sort` and `sortByKey` order keys of this type (docs/language.md §3, sort).
pub fn is_sort_key(ty: ElemType) -> bool {
    matches!(ty, ElemType::U32 | ElemType::I32 | ElemType::F32)
}

/// The type of a host expression; `Ok(None)` when an operand is already in error.
pub fn host_type(
    expr: &HostExpr,
    vars: &[VarInfo],
    uniforms: &crate::host::UniformSchema,
) -> Result<Option<HostType>, String> {
    use HostType::*;
    let recurse = |e: &HostExpr| host_type(e, vars, uniforms);
    Ok(Some(match expr {
        HostExpr::Const(v) => v.host_type(),
        HostExpr::Var(v) => match vars[v.0 as usize].ty {
            VarType::Host(t) => t,
            _ => return Ok(None),
        },
        HostExpr::Uniform { record, field } => {
            match uniforms.records.get(record).and_then(|r| r.get(field)) {
                Some(t) => *t,
                None => return Err(format!("unknown uniform `{record}.{field}`")),
            }
        }
        HostExpr::Len(_) => Int,
        HostExpr::Unary(op, e) => {
            let Some(t) = recurse(e)? else {
                return Ok(None);
            };
            match (op, t) {
                (UnaryOp::Neg, Int | Float | Vec2 | Vec3 | Vec4) => t,
                (UnaryOp::Not, Bool) => Bool,
                (UnaryOp::Neg, _) => return Err(format!("cannot negate a {t}")),
                (UnaryOp::Not, _) => return Err(format!("`!` needs a bool, found {t}")),
            }
        }
        HostExpr::Binary(op, a, b) => {
            let (Some(l), Some(r)) = (recurse(a)?, recurse(b)?) else {
                return Ok(None);
            };
            let is_vec = |t: HostType| matches!(t, Vec2 | Vec3 | Vec4);
            let is_num = |t: HostType| matches!(t, Int | Float);
            match op {
                BinaryOp::Add | BinaryOp::Sub | BinaryOp::Mul | BinaryOp::Div | BinaryOp::Rem => {
                    match (l, r) {
                        (Int, Int) => Int,
                        (Int | Float, Int | Float) => Float,
                        (v, w) if is_vec(v) && v == w && *op != BinaryOp::Rem => v,
                        (v, n) | (n, v)
                            if is_vec(v)
                                && is_num(n)
                                && matches!(op, BinaryOp::Mul | BinaryOp::Div) =>
                        {
                            v
                        }
                        _ => return Err(format!("`{}` cannot combine {l} and {r}", op.symbol())),
                    }
                }
                BinaryOp::Lt | BinaryOp::Le | BinaryOp::Gt | BinaryOp::Ge => {
                    if is_num(l) && is_num(r) {
                        Bool
                    } else {
                        return Err(format!(
                            "`{}` compares numbers, found {l} and {r}",
                            op.symbol()
                        ));
                    }
                }
                BinaryOp::Eq | BinaryOp::Ne => {
                    if l == r || (is_num(l) && is_num(r)) {
                        Bool
                    } else {
                        return Err(format!("`{}` cannot compare {l} and {r}", op.symbol()));
                    }
                }
                BinaryOp::And | BinaryOp::Or => {
                    if l == Bool && r == Bool {
                        Bool
                    } else {
                        return Err(format!("`{}` needs bools, found {l} and {r}", op.symbol()));
                    }
                }
            }
        }
        HostExpr::Call(function, args) => {
            let mut types = Vec::new();
            for a in args {
                match recurse(a)? {
                    Some(t) => types.push(t),
                    None => return Ok(None),
                }
            }
            let numbers = types.iter().all(|t| matches!(t, Int | Float));
            let name = function.name();
            let arity_error = |n: &str| Err(format!("`{name}` takes {n}"));
            match function {
                HostFunction::Vec2 | HostFunction::Vec3 | HostFunction::Vec4 => {
                    let (dims, ty) = match function {
                        HostFunction::Vec2 => (2, Vec2),
                        HostFunction::Vec3 => (3, Vec3),
                        _ => (4, Vec4),
                    };
                    if !numbers || (types.len() != 1 && types.len() != dims) {
                        return arity_error(&format!("1 or {dims} numbers"));
                    }
                    ty
                }
                HostFunction::Min | HostFunction::Max => {
                    if !numbers || types.len() != 2 {
                        return arity_error("2 numbers");
                    }
                    if types.iter().all(|t| *t == Int) {
                        Int
                    } else {
                        Float
                    }
                }
                HostFunction::Abs => {
                    if !numbers || types.len() != 1 {
                        return arity_error("1 number");
                    }
                    types[0]
                }
                HostFunction::Floor | HostFunction::Ceil => {
                    if !numbers || types.len() != 1 {
                        return arity_error("1 number");
                    }
                    Int
                }
                HostFunction::Sqrt | HostFunction::Float => {
                    if !numbers || types.len() != 1 {
                        return arity_error("1 number");
                    }
                    Float
                }
            }
        }
    }))
}

/// Folds an integer expression of constants (and nothing else) to its value.
pub fn fold_constant(expr: &HostExpr) -> Option<i64> {
    match expr {
        HostExpr::Const(HostValue::Int(i)) => Some(*i),
        HostExpr::Binary(op, a, b) => {
            let (a, b) = (fold_constant(a)?, fold_constant(b)?);
            match op {
                BinaryOp::Add => a.checked_add(b),
                BinaryOp::Sub => a.checked_sub(b),
                BinaryOp::Mul => a.checked_mul(b),
                BinaryOp::Div => a.checked_div(b),
                _ => None,
            }
        }
        _ => None,
    }
}

/// How an element-wise op is named in its errors: as written, its operator
/// (`` `+` ``) or its function (`` `sqrt` ``).
fn elementwise_name(op: &Op) -> String {
    match &op.kind {
        OpKind::Elementwise {
            operator: Some(operator),
            ..
        } => format!("`{operator}`"),
        _ => format!("`{}`", op.functor.as_deref().unwrap_or_default()),
    }
}
