//! Pass 5: element-wise expressions become maps (docs/language.md §4,
//! "Element-wise expressions").
//!
//! `lower` turns an operator or a functor call over arrays (`a * 2.0`, `-x`,
//! `sqrt(v)`) into an [`OpKind::Elementwise`] op, and keeps `v.xy` of a
//! vector array as a field op, because what they become depends on types:
//! type checking gives each one its types through [`broadcast`] and
//! [`swizzle`], and this pass, after it, rewrites them with the same two
//! functions into what backends run: a host scalar becomes a `fill` of the
//! array's element type, an `f32` array combined with a vector one becomes
//! `map<splatN>`, the op a `map` of its functor, and a swizzle
//! `map<component>` (and `map<vecN>` of several components). Fusion then
//! makes a whole expression one stage.

use super::ir::*;
use super::typecheck::host_type;
use crate::functor::FunctorLibrary;
use crate::host::HostValue;
use crate::signature::{Signature, TypePattern};
use crate::types::{ElemType, HostType, RecordRegistry};

/// An operand of an element-wise op, as type checking sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum OperandType {
    Array(ElemType),
    Host(HostType),
}

/// The element type every operand takes in the map, and the map's outputs.
#[derive(Clone, Debug, PartialEq)]
pub struct Broadcast {
    pub operands: Vec<ElemType>,
    pub outputs: Vec<ElemType>,
}

/// How `operands` meet `signature`. A type variable takes the type of its
/// array operands; `f32` arrays meet one vector type as that vector; host
/// scalars take their array's type (an `int` becomes `u32`, `i32`, `f32` or
/// a vector, a `float` `f32` or a vector); where a variable has only host
/// operands it takes their fill type (§2), `float` over `int`. `what` names
/// the operator or function for the error, which lists every operand's type.
pub fn broadcast(
    signature: &Signature,
    operands: &[OperandType],
    records: &RecordRegistry,
    what: &str,
) -> Result<Broadcast, String> {
    let describe = |t: &OperandType| match t {
        OperandType::Array(e) => format!("an array of {}", e.name(records)),
        OperandType::Host(h) => format!("a host {h}"),
    };
    let all_operands = || {
        let names: Vec<String> = operands.iter().map(describe).collect();
        match names.split_last() {
            Some((last, rest)) if !rest.is_empty() => format!("{} and {last}", rest.join(", ")),
            _ => names.join(""),
        }
    };
    if operands.len() != signature.inputs.len() {
        return Err(format!(
            "{what} takes {} argument{}, found {}",
            signature.inputs.len(),
            if signature.inputs.len() == 1 { "" } else { "s" },
            operands.len()
        ));
    }
    let mut bound: Vec<Option<ElemType>> = vec![None; 8];
    for (n, slot) in bound.iter_mut().enumerate() {
        let mut arrays: Vec<ElemType> = Vec::new();
        let mut hosts: Vec<HostType> = Vec::new();
        for (param, operand) in signature.inputs.iter().zip(operands) {
            if matches!(param.ty, TypePattern::Var(m, _) if m as usize == n) {
                match *operand {
                    OperandType::Array(t) if !arrays.contains(&t) => arrays.push(t),
                    OperandType::Host(h) => hosts.push(h),
                    OperandType::Array(_) => {}
                }
            }
        }
        *slot = match arrays.as_slice() {
            [] if hosts.is_empty() => continue,
            [] => Some(
                host_fill_type(&hosts)
                    .ok_or_else(|| format!("{what} cannot combine {}", all_operands()))?,
            ),
            [t] => Some(*t),
            [a, b] if *a == ElemType::F32 && b.is_vector() => Some(*b),
            [a, b] if *b == ElemType::F32 && a.is_vector() => Some(*a),
            _ => return Err(format!("{what} cannot combine {}", all_operands())),
        };
    }
    let mut targets = Vec::with_capacity(operands.len());
    for (param, operand) in signature.inputs.iter().zip(operands) {
        let target = match param.ty {
            TypePattern::Exact(t) => t,
            TypePattern::Var(n, constraint) => {
                let t = bound[n as usize].expect("bound above from this operand");
                if !constraint.admits(t) {
                    return Err(format!(
                        "{what} does not apply to {} (it takes {})",
                        all_operands(),
                        constraint.describe()
                    ));
                }
                t
            }
        };
        let fits = match *operand {
            OperandType::Array(t) => t == target || (t == ElemType::F32 && target.is_vector()),
            OperandType::Host(h) => host_converts(h, target),
        };
        if !fits {
            return Err(match operands {
                [only] => format!("{what} does not apply to {}", describe(only)),
                _ => format!("{what} cannot combine {}", all_operands()),
            });
        }
        targets.push(target);
    }
    let outputs = signature
        .outputs
        .iter()
        .map(|p| match p.ty {
            TypePattern::Exact(t) => t,
            TypePattern::Var(n, _) => bound[n as usize].unwrap_or(ElemType::F32),
        })
        .collect();
    Ok(Broadcast {
        operands: targets,
        outputs,
    })
}

/// The element type host scalars alone give a type variable: a vector's if
/// there is one (of one size), else `f32` if any is a `float`, else the fill
/// type of the first.
fn host_fill_type(hosts: &[HostType]) -> Option<ElemType> {
    let vectors: Vec<HostType> = hosts
        .iter()
        .copied()
        .filter(|h| h.elem_type().is_vector())
        .collect();
    match vectors.first() {
        Some(v) if vectors.iter().all(|w| w == v) => Some(v.elem_type()),
        Some(_) => None,
        None if hosts.contains(&HostType::Float) => Some(ElemType::F32),
        None => hosts.first().map(|h| h.elem_type()),
    }
}

/// Whether a host scalar of type `host` may stand for an array of `target`.
fn host_converts(host: HostType, target: ElemType) -> bool {
    match host {
        HostType::Int => target.is_numeric(),
        HostType::Float => target == ElemType::F32 || target.is_vector(),
        _ => host.elem_type() == target,
    }
}

/// The components `field` picks from a vector of `width` components
/// (`xy` → `[0, 1]`), or `None` when it is not a swizzle of that vector.
pub fn swizzle(field: &str, width: u32) -> Option<Vec<u32>> {
    if field.is_empty() || field.len() > 4 {
        return None;
    }
    field
        .chars()
        .map(|c| "xyzw".find(c).map(|i| i as u32).filter(|&i| i < width))
        .collect()
}

/// The vector of `width` components (`vec2`…`vec4`); `f32` for one.
pub fn vector_of_width(width: usize) -> ElemType {
    match width {
        2 => ElemType::Vec2,
        3 => ElemType::Vec3,
        4 => ElemType::Vec4,
        _ => ElemType::F32,
    }
}

/// Rewrites every element-wise op and vector swizzle of `body` (nested
/// blocks too) into fills and maps. Runs after type checking succeeded, so
/// a type it cannot resolve is a compiler bug: an internal error.
pub fn desugar_expressions(
    body: &mut Vec<Node>,
    vars: &mut Vec<VarInfo>,
    library: &FunctorLibrary,
) -> Result<(), String> {
    let mut desugarer = Desugarer { vars, library };
    desugarer.block(body)
}

struct Desugarer<'a> {
    vars: &'a mut Vec<VarInfo>,
    library: &'a FunctorLibrary,
}

impl Desugarer<'_> {
    fn block(&mut self, body: &mut Vec<Node>) -> Result<(), String> {
        let nodes = std::mem::take(body);
        for mut node in nodes {
            match &mut node {
                Node::Op(op) if matches!(op.kind, OpKind::Elementwise { .. }) => {
                    self.elementwise(op, body)?;
                    continue;
                }
                Node::Op(op) if self.vector_field(op).is_some() => {
                    self.swizzle(op, body)?;
                    continue;
                }
                Node::For { body: inner, .. } | Node::While { body: inner, .. } => {
                    self.block(inner)?
                }
                Node::If {
                    then_body,
                    else_body,
                    ..
                } => {
                    self.block(then_body)?;
                    self.block(else_body)?;
                }
                Node::Composite(composite) => self.block(&mut composite.blend)?,
                _ => {}
            }
            body.push(node);
        }
        Ok(())
    }

    fn array_type(&self, var: VarId) -> Result<ElemType, String> {
        match self.vars[var.0 as usize].ty {
            VarType::Array(t) => Ok(t),
            other => Err(format!(
                "internal error: `{}` is {other:?} in an element-wise op",
                self.vars[var.0 as usize].name
            )),
        }
    }

    /// A new compiler temporary of `ty`, `len` elements long.
    fn temp(&mut self, ty: ElemType, len: &HostExpr, span: dpp_dsl::Span) -> VarId {
        self.vars.push(VarInfo {
            name: format!("%{}", self.vars.len()),
            span,
            ty: VarType::Array(ty),
            len: Some(len.clone()),
        });
        VarId(self.vars.len() as u32 - 1)
    }

    fn map(
        &mut self,
        functor: &str,
        inputs: Vec<VarId>,
        output: VarId,
        span: dpp_dsl::Span,
    ) -> Node {
        Node::Op(Op {
            kind: OpKind::Map,
            functor: Some(functor.to_string()),
            inputs,
            outputs: vec![output],
            named: Vec::new(),
            span,
        })
    }

    fn elementwise(&mut self, op: &Op, out: &mut Vec<Node>) -> Result<(), String> {
        let OpKind::Elementwise { operands, .. } = &op.kind else {
            return Err("internal error: not an element-wise op".into());
        };
        let name = op.functor.as_deref().unwrap_or_default();
        let signature = self
            .library
            .get(name)
            .ok_or_else(|| format!("internal error: no functor `{name}`"))?
            .signature()
            .clone();
        let mut types = Vec::with_capacity(operands.len());
        for operand in operands {
            types.push(match operand {
                Operand::Array(v) => OperandType::Array(self.array_type(*v)?),
                Operand::Host(e) => match host_type(e, self.vars, &self.library.uniforms)? {
                    Some(h) => OperandType::Host(h),
                    None => return Err(format!("internal error: an untyped operand of `{name}`")),
                },
            });
        }
        let broadcast = broadcast(&signature, &types, &self.library.records, name)
            .map_err(|e| format!("internal error: {e}"))?;
        let first_array = op
            .inputs
            .first()
            .copied()
            .ok_or("internal error: an element-wise op without arrays")?;
        let len = self.vars[first_array.0 as usize]
            .len
            .clone()
            .unwrap_or(HostExpr::Len(first_array));
        let mut inputs = Vec::with_capacity(operands.len());
        for ((operand, ty), target) in operands.iter().zip(&types).zip(&broadcast.operands) {
            let input = match (operand, ty) {
                (Operand::Array(v), OperandType::Array(t)) if t == target => *v,
                (Operand::Array(v), _) => {
                    let splat = self.temp(*target, &len, op.span);
                    let functor = format!("splat{}", target.components());
                    out.push(self.map(&functor, vec![*v], splat, op.span));
                    splat
                }
                (Operand::Host(e), OperandType::Host(h)) => {
                    self.host_operand(e.clone(), *h, *target, &len, op.span, out)
                }
                (Operand::Host(_), OperandType::Array(_)) => {
                    return Err("internal error: a host operand typed as an array".into())
                }
            };
            inputs.push(input);
        }
        out.push(Node::Op(Op {
            kind: OpKind::Map,
            functor: op.functor.clone(),
            inputs,
            outputs: op.outputs.clone(),
            named: op.named.clone(),
            span: op.span,
        }));
        Ok(())
    }

    /// A host scalar as an array of `target`: a `fill`, converted first where
    /// the fill of its own type would be another element type.
    fn host_operand(
        &mut self,
        value: HostExpr,
        host: HostType,
        target: ElemType,
        len: &HostExpr,
        span: dpp_dsl::Span,
        out: &mut Vec<Node>,
    ) -> VarId {
        let as_float = |value: HostExpr| match value {
            HostExpr::Const(HostValue::Int(i)) => HostExpr::Const(HostValue::Float(i as f64)),
            other if host == HostType::Int => HostExpr::Call(HostFunction::Float, vec![other]),
            other => other,
        };
        let (value, fill_type) = match target {
            ElemType::F32 | ElemType::I32 => (as_float(value), ElemType::F32),
            ElemType::Vec2 | ElemType::Vec3 | ElemType::Vec4 if !host.elem_type().is_vector() => {
                let constructor = match target {
                    ElemType::Vec2 => HostFunction::Vec2,
                    ElemType::Vec3 => HostFunction::Vec3,
                    _ => HostFunction::Vec4,
                };
                (HostExpr::Call(constructor, vec![value]), target)
            }
            _ => (value, target),
        };
        let filled = self.temp(fill_type, len, span);
        out.push(Node::Op(Op {
            kind: OpKind::Fill {
                count: len.clone(),
                value,
            },
            functor: None,
            inputs: Vec::new(),
            outputs: vec![filled],
            named: Vec::new(),
            span,
        }));
        if target != ElemType::I32 {
            return filled;
        }
        // No `i32` array is filled from the host (§2): through `f32`, exact below 2^24.
        let converted = self.temp(ElemType::I32, len, span);
        out.push(self.map("toI32", vec![filled], converted, span));
        converted
    }

    /// The components a field op picks from a vector array, if it is one.
    fn vector_field(&self, op: &Op) -> Option<Vec<u32>> {
        let OpKind::Field { field } = &op.kind else {
            return None;
        };
        let ty = self.array_type(*op.inputs.first()?).ok()?;
        ty.is_vector()
            .then(|| swizzle(field, ty.components()))
            .flatten()
    }

    /// `v.y` → `map<component>(v, index: 1)`; `v.zyx` → three of those and `map<vec3>`.
    fn swizzle(&mut self, op: &Op, out: &mut Vec<Node>) -> Result<(), String> {
        let components = self
            .vector_field(op)
            .ok_or("internal error: not a swizzle")?;
        let source = op.inputs[0];
        let len = self.vars[source.0 as usize]
            .len
            .clone()
            .unwrap_or(HostExpr::Len(source));
        let mut picked = Vec::with_capacity(components.len());
        for &index in &components {
            let target = if components.len() == 1 {
                op.outputs[0]
            } else {
                self.temp(ElemType::F32, &len, op.span)
            };
            out.push(Node::Op(Op {
                kind: OpKind::Map,
                functor: Some("component".into()),
                inputs: vec![source],
                outputs: vec![target],
                named: vec![(
                    "index".into(),
                    HostExpr::Const(HostValue::Int(index.into())),
                )],
                span: op.span,
            }));
            picked.push(target);
        }
        if components.len() > 1 {
            let functor = format!("vec{}", components.len());
            out.push(self.map(&functor, picked, op.outputs[0], op.span));
        }
        Ok(())
    }
}
