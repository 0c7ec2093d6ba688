//! Evaluation of host scalar expressions, shared by the compiler (params) and
//! the backends (loop bounds, lengths, named arguments).

use super::ir::{HostExpr, HostFunction, VarId};
use crate::host::{HostValue, Uniforms};
use dpp_dsl::ast::{BinaryOp, UnaryOp};

/// What a host expression can read.
pub trait HostEnvironment {
    fn host_var(&self, var: VarId) -> Option<HostValue>;
    fn array_len(&self, var: VarId) -> Option<usize>;
    fn uniforms(&self) -> &Uniforms;
}

pub fn eval_host(expr: &HostExpr, env: &dyn HostEnvironment) -> Result<HostValue, String> {
    use HostValue::*;
    Ok(match expr {
        HostExpr::Const(v) => *v,
        HostExpr::Var(v) => env
            .host_var(*v)
            .ok_or_else(|| format!("host value %{} read before it was computed", v.0))?,
        HostExpr::Uniform { record, field } => env
            .uniforms()
            .get(record, field)
            .ok_or_else(|| format!("uniform `{record}.{field}` has no value in this run"))?,
        HostExpr::Len(v) => Int(env
            .array_len(*v)
            .ok_or_else(|| format!("length of %{} read before it was computed", v.0))?
            as i64),
        HostExpr::Unary(op, e) => match (op, eval_host(e, env)?) {
            (UnaryOp::Neg, Int(i)) => Int(i.checked_neg().ok_or("integer overflow")?),
            (UnaryOp::Neg, Float(f)) => Float(-f),
            (UnaryOp::Neg, v) => vec_map(v, |x| -x)?,
            (UnaryOp::Not, Bool(b)) => Bool(!b),
            (op, v) => return Err(format!("cannot apply {op:?} to {v}")),
        },
        HostExpr::Binary(op, a, b) => binary(*op, eval_host(a, env)?, eval_host(b, env)?)?,
        HostExpr::Call(function, args) => {
            let args: Vec<HostValue> = args
                .iter()
                .map(|a| eval_host(a, env))
                .collect::<Result<_, _>>()?;
            call(*function, &args)?
        }
    })
}

fn vec_map(v: HostValue, f: impl Fn(f32) -> f32) -> Result<HostValue, String> {
    Ok(match v {
        HostValue::Vec2(a) => HostValue::Vec2(a.map(f)),
        HostValue::Vec3(a) => HostValue::Vec3(a.map(f)),
        HostValue::Vec4(a) => HostValue::Vec4(a.map(f)),
        other => return Err(format!("expected a vector, found {other}")),
    })
}

fn binary(op: BinaryOp, a: HostValue, b: HostValue) -> Result<HostValue, String> {
    use HostValue::*;
    let overflow = || format!("integer overflow in `{a} {} {b}`", op.symbol());
    Ok(match (op, a, b) {
        (BinaryOp::And, Bool(x), Bool(y)) => Bool(x && y),
        (BinaryOp::Or, Bool(x), Bool(y)) => Bool(x || y),
        (BinaryOp::Eq, Bool(x), Bool(y)) => Bool(x == y),
        (BinaryOp::Ne, Bool(x), Bool(y)) => Bool(x != y),
        (_, Int(x), Int(y)) => match op {
            BinaryOp::Add => Int(x.checked_add(y).ok_or_else(overflow)?),
            BinaryOp::Sub => Int(x.checked_sub(y).ok_or_else(overflow)?),
            BinaryOp::Mul => Int(x.checked_mul(y).ok_or_else(overflow)?),
            BinaryOp::Div | BinaryOp::Rem if y == 0 => {
                return Err(format!("division by zero in `{x} {} {y}`", op.symbol()))
            }
            BinaryOp::Div => Int(x.div_euclid(y)),
            BinaryOp::Rem => Int(x.rem_euclid(y)),
            _ => Bool(compare(op, x, y)?),
        },
        (_, Int(_) | Float(_), Int(_) | Float(_)) => {
            let (x, y) = (a.as_f64().unwrap(), b.as_f64().unwrap());
            match op {
                BinaryOp::Add => Float(x + y),
                BinaryOp::Sub => Float(x - y),
                BinaryOp::Mul => Float(x * y),
                BinaryOp::Div => Float(x / y),
                BinaryOp::Rem => Float(x.rem_euclid(y)),
                _ => Bool(compare(op, x, y)?),
            }
        }
        (op, v, Int(_) | Float(_)) | (op, Int(_) | Float(_), v)
            if matches!(op, BinaryOp::Mul | BinaryOp::Div) =>
        {
            let scalar = if matches!(a, Int(_) | Float(_)) { a } else { b }
                .as_f32()
                .unwrap();
            let scalar_first = matches!(a, Int(_) | Float(_));
            vec_map(v, |x| match (op, scalar_first) {
                (BinaryOp::Mul, _) => x * scalar,
                (_, false) => x / scalar,
                (_, true) => scalar / x,
            })?
        }
        (BinaryOp::Add | BinaryOp::Sub | BinaryOp::Mul | BinaryOp::Div, Vec2(x), Vec2(y)) => {
            Vec2(zip(op, x, y))
        }
        (BinaryOp::Add | BinaryOp::Sub | BinaryOp::Mul | BinaryOp::Div, Vec3(x), Vec3(y)) => {
            Vec3(zip(op, x, y))
        }
        (BinaryOp::Add | BinaryOp::Sub | BinaryOp::Mul | BinaryOp::Div, Vec4(x), Vec4(y)) => {
            Vec4(zip(op, x, y))
        }
        (BinaryOp::Eq, x, y) => Bool(x == y),
        (BinaryOp::Ne, x, y) => Bool(x != y),
        _ => return Err(format!("`{}` cannot combine {a} and {b}", op.symbol())),
    })
}

fn compare<T: PartialOrd>(op: BinaryOp, x: T, y: T) -> Result<bool, String> {
    Ok(match op {
        BinaryOp::Eq => x == y,
        BinaryOp::Ne => x != y,
        BinaryOp::Lt => x < y,
        BinaryOp::Le => x <= y,
        BinaryOp::Gt => x > y,
        BinaryOp::Ge => x >= y,
        _ => return Err(format!("`{}` needs bools", op.symbol())),
    })
}

fn zip<const N: usize>(op: BinaryOp, x: [f32; N], y: [f32; N]) -> [f32; N] {
    std::array::from_fn(|i| match op {
        BinaryOp::Add => x[i] + y[i],
        BinaryOp::Sub => x[i] - y[i],
        BinaryOp::Mul => x[i] * y[i],
        _ => x[i] / y[i],
    })
}

fn call(function: HostFunction, args: &[HostValue]) -> Result<HostValue, String> {
    use HostValue::*;
    let number = |i: usize| {
        args.get(i)
            .and_then(HostValue::as_f64)
            .ok_or_else(|| format!("`{}` takes numbers", function.name()))
    };
    let component = |i: usize, n: usize| -> Result<f32, String> {
        Ok(if args.len() == 1 {
            number(0)?
        } else if args.len() == n {
            number(i)?
        } else {
            return Err(format!("`{}` takes 1 or {n} numbers", function.name()));
        } as f32)
    };
    Ok(match function {
        HostFunction::Vec2 => Vec2([component(0, 2)?, component(1, 2)?]),
        HostFunction::Vec3 => Vec3([component(0, 3)?, component(1, 3)?, component(2, 3)?]),
        HostFunction::Vec4 => Vec4([
            component(0, 4)?,
            component(1, 4)?,
            component(2, 4)?,
            component(3, 4)?,
        ]),
        HostFunction::Min | HostFunction::Max => match (args.first(), args.get(1)) {
            (Some(Int(x)), Some(Int(y))) => Int(if function == HostFunction::Min {
                *x.min(y)
            } else {
                *x.max(y)
            }),
            _ => {
                let (x, y) = (number(0)?, number(1)?);
                Float(if function == HostFunction::Min {
                    x.min(y)
                } else {
                    x.max(y)
                })
            }
        },
        HostFunction::Abs => match args.first() {
            Some(Int(x)) => Int(x.checked_abs().ok_or("integer overflow")?),
            _ => Float(number(0)?.abs()),
        },
        HostFunction::Floor | HostFunction::Ceil => {
            let x = number(0)?;
            let y = if function == HostFunction::Floor {
                x.floor()
            } else {
                x.ceil()
            };
            if !y.is_finite() || y.abs() > 9.0e15 {
                return Err(format!("`{}` of {x} is not an integer", function.name()));
            }
            Int(y as i64)
        }
        HostFunction::Sqrt => Float(number(0)?.sqrt()),
        HostFunction::Float => Float(number(0)?),
    })
}
