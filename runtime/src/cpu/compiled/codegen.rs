//! Machine code for a [`Segment`]: one loop over the chunk's elements that
//! computes every op of the segment per element, in registers, and stores
//! only the values read after it.
//!
//! Every operation computes exactly what the generic functor's CPU kernel
//! computes (same IEEE operations in the same order, the same libm calls for
//! `pow`, `exp`, `log`, `sin` and `cos`), so a compiled stage equals the
//! column-at-a-time one bit for bit (`tests::agreement`). Where the kernel
//! would fail (an integer division by zero, a gather out of range) the
//! loop stops and returns the element's position plus one; the caller then
//! runs the segment column at a time, which reports the error itself.

use super::{Segment, SegmentStep};
use crate::host::HostValue;
use crate::types::{ElemType, RecordRegistry};
use cranelift_codegen::ir::condcodes::{FloatCC, IntCC};
use cranelift_codegen::ir::{
    types, AbiParam, Block, FuncRef, InstBuilder, MemFlagsData, Type, Value,
};
use cranelift_codegen::settings::{self, Configurable};
use cranelift_frontend::{FunctionBuilder, FunctionBuilderContext};
use cranelift_jit::{JITBuilder, JITModule};
use cranelift_module::{default_libcall_names, FuncId, Linkage, Module};
use std::collections::HashMap;

/// `(inputs, gathered lengths, outputs, params, n, first index) -> status`:
/// the leaf pointers of the element-wise inputs (already at the chunk's
/// start) then of the gathered arrays, one length per gathered array, the
/// output leaves, the fills' values (16 bytes each), the element count and
/// the chunk's first index. Status 0, or the failing element's position + 1.
pub(crate) type KernelEntry =
    unsafe extern "C" fn(*const *const u8, *const u64, *const *mut u8, *const u8, u64, u64) -> u64;

/// The libm functions the float kernels call, by name: the very functions the
/// generic functors' CPU kernels call, so that results agree to the bit.
extern "C" fn dpp_pow(a: f32, b: f32) -> f32 {
    a.powf(b)
}
extern "C" fn dpp_exp(x: f32) -> f32 {
    x.exp()
}
extern "C" fn dpp_log(x: f32) -> f32 {
    x.ln()
}
extern "C" fn dpp_sin(x: f32) -> f32 {
    x.sin()
}
extern "C" fn dpp_cos(x: f32) -> f32 {
    x.cos()
}

const UNARY_CALLS: [(&str, extern "C" fn(f32) -> f32); 4] = [
    ("exp", dpp_exp),
    ("log", dpp_log),
    ("sin", dpp_sin),
    ("cos", dpp_cos),
];

/// Whether the generic functor `name` compiles for these input types (its
/// output type follows from them, as the type checker found).
pub(super) fn supports(name: &str, inputs: &[ElemType]) -> bool {
    use ElemType::*;
    let float = |t: &ElemType| matches!(t, F32 | Vec2 | Vec3 | Vec4);
    let vector = |t: &ElemType| matches!(t, Vec2 | Vec3 | Vec4);
    let scalar = |t: &ElemType| matches!(t, U32 | I32 | F32);
    let all_same = inputs.windows(2).all(|w| w[0] == w[1]);
    match (name, inputs) {
        ("add" | "sub" | "mul" | "div" | "min" | "max", [a, _]) => {
            all_same && (float(a) || matches!(a, U32 | I32))
        }
        ("and" | "or", [Bool, Bool]) | ("not", [Bool]) => true,
        ("neg", [a]) => float(a) || *a == I32,
        ("rem", [a, _]) => all_same && scalar(a),
        (
            "abs" | "floor" | "ceil" | "fract" | "sqrt" | "rsqrt" | "exp" | "log" | "sin" | "cos",
            [a],
        ) => float(a),
        ("pow" | "step", [a, _]) | ("clamp" | "mix" | "smoothstep", [a, _, _]) => {
            all_same && float(a)
        }
        ("dot" | "distance" | "reflect", [a, _]) => all_same && vector(a),
        ("cross", [Vec3, Vec3]) => true,
        ("length" | "normalize" | "component", [a]) => vector(a),
        ("vec2", [F32, F32]) | ("vec3", [F32, F32, F32]) | ("vec4", [F32, F32, F32, F32]) => true,
        ("splat2" | "splat3" | "splat4", [F32]) => true,
        ("eq" | "ne", [a, _]) => all_same && (scalar(a) || *a == Bool),
        ("lt" | "le" | "gt" | "ge", [a, _]) => all_same && scalar(a),
        ("isZero" | "nonZero", [a]) => scalar(a),
        ("toF32" | "toU32" | "toI32", [a]) => scalar(a) || *a == Bool,
        ("select", [Bool, a, b]) => a == b && !matches!(a, Record(_)),
        ("identity", [a]) => !matches!(a, Record(_)),
        _ => false,
    }
}

/// SSA values per element: one per component, one for a bool.
fn lanes(ty: ElemType) -> usize {
    ty.components().max(1) as usize
}

fn lane_type(ty: ElemType) -> Type {
    match ty {
        ElemType::Bool => types::I8,
        ElemType::U32 | ElemType::I32 => types::I32,
        _ => types::F32,
    }
}

/// A value of the segment inside the loop's body.
#[derive(Clone)]
enum Val {
    /// A primitive: one SSA value per component (one for scalars and bools).
    Prim { lanes: Vec<Value> },
    /// A record not yet loaded: each field's column (its base pointer) and
    /// the element's position in them. A field is loaded when read.
    Record {
        fields: Vec<(ElemType, Value)>,
        index: Value,
    },
}

/// Compiles `segment` into machine code. The module is never freed: a kernel
/// lives as long as the process, in the cache of its segment's shape.
pub(super) fn compile(segment: &Segment, records: &RecordRegistry) -> Result<KernelEntry, String> {
    let mut flags = settings::builder();
    flags.set("opt_level", "speed").map_err(|e| e.to_string())?;
    let isa = cranelift_native::builder()
        .map_err(|e| e.to_string())?
        .finish(settings::Flags::new(flags))
        .map_err(|e| e.to_string())?;
    let mut jit = JITBuilder::with_isa(isa, default_libcall_names());
    jit.symbol("dpp_pow", dpp_pow as *const u8);
    for (name, function) in UNARY_CALLS {
        jit.symbol(format!("dpp_{name}"), function as *const u8);
    }
    let mut module = JITModule::new(jit);
    let pointer = module.target_config().pointer_type();
    let mut context = module.make_context();
    for _ in 0..6 {
        context.func.signature.params.push(AbiParam::new(pointer));
    }
    context
        .func
        .signature
        .returns
        .push(AbiParam::new(types::I64));
    let libm = declare_libm(&mut module)?;
    let mut builder_context = FunctionBuilderContext::new();
    {
        let mut builder = FunctionBuilder::new(&mut context.func, &mut builder_context);
        let calls = libm
            .iter()
            .map(|(name, id)| (*name, module.declare_func_in_func(*id, builder.func)))
            .collect();
        Emitter::emit(&mut builder, segment, records, calls)?;
        builder.seal_all_blocks();
        builder.finalize(module.target_config());
    }
    let id = module
        .declare_function("segment", Linkage::Export, &context.func.signature)
        .map_err(|e| e.to_string())?;
    module
        .define_function(id, &mut context)
        .map_err(|e| e.to_string())?;

    module.clear_context(&mut context);
    module.finalize_definitions().map_err(|e| e.to_string())?;
    let code = module.get_finalized_function(id);
    // Kept for the process's lifetime: the cache hands the entry out forever.
    std::mem::forget(module);
    // SAFETY: the function was declared with exactly this signature above.
    Ok(unsafe { std::mem::transmute::<*const u8, KernelEntry>(code) })
}

fn declare_libm(module: &mut JITModule) -> Result<Vec<(&'static str, FuncId)>, String> {
    let mut declared = Vec::new();
    let signature = |arity: usize| {
        let mut s = module.make_signature();
        for _ in 0..arity {
            s.params.push(AbiParam::new(types::F32));
        }
        s.returns.push(AbiParam::new(types::F32));
        s
    };
    let pow = signature(2);
    let unary = signature(1);
    declared.push((
        "pow",
        module
            .declare_function("dpp_pow", Linkage::Import, &pow)
            .map_err(|e| e.to_string())?,
    ));
    for (name, _) in UNARY_CALLS {
        let id = module
            .declare_function(&format!("dpp_{name}"), Linkage::Import, &unary)
            .map_err(|e| e.to_string())?;
        declared.push((name, id));
    }
    Ok(declared)
}

struct Emitter<'b, 'f> {
    b: &'b mut FunctionBuilder<'f>,
    records: &'b RecordRegistry,
    calls: HashMap<&'static str, FuncRef>,
    /// The loop's element position (i64) and the block a failure jumps to.
    position: Value,
    fail: Block,
    values: HashMap<u32, Val>,
}

impl Emitter<'_, '_> {
    fn emit(
        b: &mut FunctionBuilder<'_>,
        segment: &Segment,
        records: &RecordRegistry,
        calls: HashMap<&'static str, FuncRef>,
    ) -> Result<(), String> {
        let entry = b.create_block();
        let head = b.create_block();
        let body = b.create_block();
        let exit = b.create_block();
        let fail = b.create_block();
        b.append_block_params_for_function_params(entry);
        b.switch_to_block(entry);
        let [inputs, lengths, outputs, params, n, first] = b.block_params(entry) else {
            return Err("the kernel's signature".into());
        };
        let (inputs, lengths, outputs, params, n, first) =
            (*inputs, *lengths, *outputs, *params, *n, *first);
        let flags = MemFlagsData::trusted();
        // Everything that does not change per element is loaded once, here.
        let mut leaf = 0;
        let mut load_pointer = |b: &mut FunctionBuilder<'_>, base: Value| {
            let p = b.ins().load(types::I64, flags, base, 8 * leaf);
            leaf += 1;
            p
        };
        let elementwise: Vec<Vec<Value>> = segment
            .elementwise
            .iter()
            .map(|(_, ty)| {
                leaf_types(*ty, records)
                    .iter()
                    .map(|_| load_pointer(b, inputs))
                    .collect()
            })
            .collect();
        let gathered: Vec<(Vec<Value>, Value)> = segment
            .gathered
            .iter()
            .enumerate()
            .map(|(k, (_, ty))| {
                let leaves = leaf_types(*ty, records)
                    .iter()
                    .map(|_| load_pointer(b, inputs))
                    .collect();
                let len = b.ins().load(types::I64, flags, lengths, 8 * k as i32);
                (leaves, len)
            })
            .collect();
        let mut leaf = 0;
        let output_pointers: Vec<Vec<Value>> = segment
            .outputs
            .iter()
            .map(|(_, ty)| {
                leaf_types(*ty, records)
                    .iter()
                    .map(|_| {
                        let p = b.ins().load(types::I64, flags, outputs, 8 * leaf);
                        leaf += 1;
                        p
                    })
                    .collect()
            })
            .collect();
        let fills: Vec<Val> = segment
            .fills
            .iter()
            .enumerate()
            .map(|(k, ty)| {
                let lanes = (0..lanes(*ty))
                    .map(|lane| {
                        b.ins()
                            .load(lane_type(*ty), flags, params, (16 * k + 4 * lane) as i32)
                    })
                    .collect();
                Val::Prim { lanes }
            })
            .collect();
        let zero = b.ins().iconst(types::I64, 0);
        b.ins().jump(head, &[zero.into()]);

        b.append_block_param(head, types::I64);
        b.switch_to_block(head);
        let position = b.block_params(head)[0];
        let more = b.ins().icmp(IntCC::UnsignedLessThan, position, n);
        b.ins().brif(more, body, &[], exit, &[]);

        b.switch_to_block(body);
        let mut emitter = Emitter {
            b,
            records,
            calls,
            position,
            fail,
            values: HashMap::new(),
        };
        for (k, (var, ty)) in segment.elementwise.iter().enumerate() {
            let val = emitter.at(*ty, &elementwise[k], position);
            emitter.values.insert(var.0, val);
        }
        for step in &segment.steps {
            let val = match step {
                SegmentStep::Iota { .. } => {
                    let index = emitter.b.ins().iadd(first, position);
                    let index = emitter.b.ins().ireduce(types::I32, index);
                    Val::Prim { lanes: vec![index] }
                }
                SegmentStep::Fill { fill, .. } => fills[*fill].clone(),
                SegmentStep::Field { record, field, .. } => emitter.field(*record, *field)?,
                SegmentStep::Gather {
                    index, gathered: g, ..
                } => {
                    let index = emitter.prim(*index)?[0];
                    let index = emitter.b.ins().uextend(types::I64, index);
                    let (leaves, len) = &gathered[*g];
                    let inside = emitter.b.ins().icmp(IntCC::UnsignedLessThan, index, *len);
                    emitter.check(inside);
                    emitter.at(segment.gathered[*g].1, leaves, index)
                }
                SegmentStep::Map {
                    functor,
                    inputs,
                    output_type,
                    named,
                    ..
                } => emitter.map(functor, inputs, *output_type, named)?,
            };
            emitter.values.insert(step.output().0, val);
        }
        for ((var, ty), pointers) in segment.outputs.iter().zip(&output_pointers) {
            let val = emitter
                .values
                .get(&var.0)
                .cloned()
                .ok_or("an unknown output")?;
            emitter.store(*ty, val, pointers)?;
        }
        let next = emitter.b.ins().iadd_imm_s(position, 1);
        emitter.b.ins().jump(head, &[next.into()]);

        let b = emitter.b;
        b.switch_to_block(exit);
        let ok = b.ins().iconst(types::I64, 0);
        b.ins().return_(&[ok]);

        b.append_block_param(fail, types::I64);
        b.switch_to_block(fail);
        let failed_at = b.block_params(fail)[0];
        let status = b.ins().iadd_imm_s(failed_at, 1);
        b.ins().return_(&[status]);
        Ok(())
    }

    /// The element at `index` of the column(s) `leaves` of type `ty`: loaded
    /// now for a primitive, left to its fields' reads for a record.
    fn at(&mut self, ty: ElemType, leaves: &[Value], index: Value) -> Val {
        match ty {
            ElemType::Record(id) => Val::Record {
                fields: self
                    .records
                    .get(id)
                    .fields
                    .iter()
                    .zip(leaves)
                    .map(|((_, t), p)| (*t, *p))
                    .collect(),
                index,
            },
            primitive => Val::Prim {
                lanes: self.load(primitive, leaves[0], index),
            },
        }
    }

    fn address(&mut self, ty: ElemType, base: Value, index: Value) -> Value {
        let offset = self
            .b
            .ins()
            .imul_imm_s(index, ty.bytes(self.records) as i64);
        self.b.ins().iadd(base, offset)
    }

    fn load(&mut self, ty: ElemType, base: Value, index: Value) -> Vec<Value> {
        let address = self.address(ty, base, index);
        (0..lanes(ty))
            .map(|lane| {
                self.b.ins().load(
                    lane_type(ty),
                    MemFlagsData::trusted(),
                    address,
                    4 * lane as i32,
                )
            })
            .collect()
    }

    fn store(&mut self, ty: ElemType, val: Val, pointers: &[Value]) -> Result<(), String> {
        let position = self.position;
        match val {
            Val::Prim { lanes, .. } => {
                let address = self.address(ty, pointers[0], position);
                for (lane, value) in lanes.into_iter().enumerate() {
                    self.b
                        .ins()
                        .store(MemFlagsData::trusted(), value, address, 4 * lane as i32);
                }
            }
            Val::Record { fields, index } => {
                for ((field_ty, base), pointer) in fields.into_iter().zip(pointers) {
                    let lanes = self.load(field_ty, base, index);
                    self.store(field_ty, Val::Prim { lanes }, &[*pointer])?;
                }
            }
        }
        Ok(())
    }

    /// Continues where `holds` (an i8 truth value) is true; fails otherwise.
    fn check(&mut self, holds: Value) {
        let next = self.b.create_block();
        self.b
            .ins()
            .brif(holds, next, &[], self.fail, &[self.position.into()]);
        self.b.switch_to_block(next);
    }

    fn prim(&self, var: u32) -> Result<Vec<Value>, String> {
        match self.values.get(&var) {
            Some(Val::Prim { lanes, .. }) => Ok(lanes.clone()),
            _ => Err(format!("value {var} is not a primitive of the segment")),
        }
    }

    fn field(&mut self, record: u32, field: usize) -> Result<Val, String> {
        let Some(Val::Record { fields, index }) = self.values.get(&record).cloned() else {
            return Err(format!("value {record} is not a record of the segment"));
        };
        let (ty, base) = fields[field];
        Ok(Val::Prim {
            lanes: self.load(ty, base, index),
        })
    }

    fn map(
        &mut self,
        functor: &str,
        inputs: &[(u32, ElemType)],
        output: ElemType,
        named: &[HostValue],
    ) -> Result<Val, String> {
        let args: Vec<Vec<Value>> = inputs
            .iter()
            .map(|(v, _)| self.prim(*v))
            .collect::<Result<_, _>>()?;
        let ty = inputs[0].1;
        let lanes = self.operation(functor, ty, &args, named)?;
        if lanes.len() != self::lanes(output) {
            return Err(format!(
                "`{functor}` gave {} lanes for {output:?}",
                lanes.len()
            ));
        }
        Ok(Val::Prim { lanes })
    }

    /// `op` applied to each lane of `args` (all of `ty`'s shape).
    fn per_lane(
        &mut self,
        args: &[Vec<Value>],
        mut op: impl FnMut(&mut Self, &[Value]) -> Value,
    ) -> Vec<Value> {
        (0..args[0].len())
            .map(|lane| {
                let lane_args: Vec<Value> = args.iter().map(|a| a[lane]).collect();
                op(self, &lane_args)
            })
            .collect()
    }

    fn f32(&mut self, value: f32) -> Value {
        self.b.ins().f32const(value)
    }

    fn call(&mut self, name: &str, args: &[Value]) -> Value {
        let call = self.b.ins().call(self.calls[name], args);
        self.b.inst_results(call)[0]
    }

    /// Rust's `f32::min` / `f32::max` (LLVM's `minnum`/`maxnum` on x86):
    /// the other operand where one is NaN, `a` on a tie.
    fn nan_ignoring(&mut self, a: Value, b: Value, smaller: bool) -> Value {
        let better = if smaller {
            FloatCC::LessThan
        } else {
            FloatCC::GreaterThan
        };
        let b_better = self.b.ins().fcmp(better, b, a);
        let chosen = self.b.ins().select(b_better, b, a);
        let a_nan = self.b.ins().fcmp(FloatCC::Unordered, a, a);
        self.b.ins().select(a_nan, b, chosen)
    }

    fn sum_of_products(&mut self, a: &[Value], b: &[Value]) -> Value {
        let mut sum = self.b.ins().fmul(a[0], b[0]);
        for lane in 1..a.len() {
            let product = self.b.ins().fmul(a[lane], b[lane]);
            sum = self.b.ins().fadd(sum, product);
        }
        sum
    }

    fn operation(
        &mut self,
        functor: &str,
        ty: ElemType,
        args: &[Vec<Value>],
        named: &[HostValue],
    ) -> Result<Vec<Value>, String> {
        use ElemType::{Bool, F32, I32, U32};
        let float = !matches!(ty, Bool | U32 | I32);
        Ok(match functor {
            "add" if float => self.per_lane(args, |s, x| s.b.ins().fadd(x[0], x[1])),
            "sub" if float => self.per_lane(args, |s, x| s.b.ins().fsub(x[0], x[1])),
            "mul" if float => self.per_lane(args, |s, x| s.b.ins().fmul(x[0], x[1])),
            "div" if float => self.per_lane(args, |s, x| s.b.ins().fdiv(x[0], x[1])),
            "add" => self.per_lane(args, |s, x| s.b.ins().iadd(x[0], x[1])),
            "sub" => self.per_lane(args, |s, x| s.b.ins().isub(x[0], x[1])),
            "mul" => self.per_lane(args, |s, x| s.b.ins().imul(x[0], x[1])),
            "div" | "rem" if !float || ty == F32 => {
                vec![self.integer_division(functor, ty, args[0][0], args[1][0])]
            }
            "min" | "max" if float => {
                let smaller = functor == "min";
                self.per_lane(args, |s, x| s.nan_ignoring(x[0], x[1], smaller))
            }
            "min" if ty == U32 => vec![self.b.ins().umin(args[0][0], args[1][0])],
            "max" if ty == U32 => vec![self.b.ins().umax(args[0][0], args[1][0])],
            "min" => vec![self.b.ins().smin(args[0][0], args[1][0])],
            "max" => vec![self.b.ins().smax(args[0][0], args[1][0])],
            "and" => vec![self.b.ins().band(args[0][0], args[1][0])],
            "or" => vec![self.b.ins().bor(args[0][0], args[1][0])],
            "not" => vec![self.b.ins().bxor_imm_u(args[0][0], 1)],
            "neg" if float => self.per_lane(args, |s, x| s.b.ins().fneg(x[0])),
            "neg" => vec![self.b.ins().ineg(args[0][0])],
            "abs" => self.per_lane(args, |s, x| s.b.ins().fabs(x[0])),
            "floor" => self.per_lane(args, |s, x| s.b.ins().floor(x[0])),
            "ceil" => self.per_lane(args, |s, x| s.b.ins().ceil(x[0])),
            "sqrt" => self.per_lane(args, |s, x| s.b.ins().sqrt(x[0])),
            "fract" => self.per_lane(args, |s, x| {
                let floor = s.b.ins().floor(x[0]);
                s.b.ins().fsub(x[0], floor)
            }),
            "rsqrt" => self.per_lane(args, |s, x| {
                let one = s.f32(1.0);
                let root = s.b.ins().sqrt(x[0]);
                s.b.ins().fdiv(one, root)
            }),
            "exp" | "log" | "sin" | "cos" => {
                let name = UNARY_CALLS
                    .iter()
                    .find(|(n, _)| *n == functor)
                    .map(|(n, _)| *n)
                    .ok_or("an unknown call")?;
                self.per_lane(args, |s, x| s.call(name, &[x[0]]))
            }
            "pow" => self.per_lane(args, |s, x| s.call("pow", &[x[0], x[1]])),
            // `x.max(lo).min(hi)`.
            "clamp" => self.per_lane(args, |s, x| {
                let low = s.nan_ignoring(x[0], x[1], false);
                s.nan_ignoring(low, x[2], true)
            }),
            // `a * (1.0 - t) + b * t`.
            "mix" => self.per_lane(args, |s, x| {
                let one = s.f32(1.0);
                let rest = s.b.ins().fsub(one, x[2]);
                let left = s.b.ins().fmul(x[0], rest);
                let right = s.b.ins().fmul(x[1], x[2]);
                s.b.ins().fadd(left, right)
            }),
            "step" => self.per_lane(args, |s, x| {
                let reached = s.b.ins().fcmp(FloatCC::LessThanOrEqual, x[0], x[1]);
                let (one, zero) = (s.f32(1.0), s.f32(0.0));
                s.b.ins().select(reached, one, zero)
            }),
            // `t = ((x - lo) / (hi - lo)).max(0.0).min(1.0); t * t * (3.0 - 2.0 * t)`.
            "smoothstep" => self.per_lane(args, |s, x| {
                let above = s.b.ins().fsub(x[2], x[0]);
                let span = s.b.ins().fsub(x[1], x[0]);
                let q = s.b.ins().fdiv(above, span);
                let (zero, one, two, three) = (s.f32(0.0), s.f32(1.0), s.f32(2.0), s.f32(3.0));
                let low = s.nan_ignoring(q, zero, false);
                let t = s.nan_ignoring(low, one, true);
                let square = s.b.ins().fmul(t, t);
                let twice = s.b.ins().fmul(two, t);
                let rest = s.b.ins().fsub(three, twice);
                s.b.ins().fmul(square, rest)
            }),
            "dot" => vec![self.sum_of_products(&args[0], &args[1])],
            "length" => {
                let squared = self.sum_of_products(&args[0], &args[0]);
                vec![self.b.ins().sqrt(squared)]
            }
            "distance" => {
                let d = self.per_lane(args, |s, x| s.b.ins().fsub(x[0], x[1]));
                let squared = self.sum_of_products(&d, &d);
                vec![self.b.ins().sqrt(squared)]
            }
            "normalize" => {
                let squared = self.sum_of_products(&args[0], &args[0]);
                let length = self.b.ins().sqrt(squared);
                let zero = self.f32(0.0);
                let vanishes = self.b.ins().fcmp(FloatCC::Equal, length, zero);
                self.per_lane(args, |s, x| {
                    let scaled = s.b.ins().fdiv(x[0], length);
                    s.b.ins().select(vanishes, zero, scaled)
                })
            }
            // `i - (2.0 * dot(n, i)) * n`.
            "reflect" => {
                let dot = self.sum_of_products(&args[1], &args[0]);
                let two = self.f32(2.0);
                let twice = self.b.ins().fmul(two, dot);
                self.per_lane(args, |s, x| {
                    let along = s.b.ins().fmul(twice, x[1]);
                    s.b.ins().fsub(x[0], along)
                })
            }
            "cross" => {
                let (a, b) = (&args[0], &args[1]);
                let component = |s: &mut Self, i: usize, j: usize| {
                    let left = s.b.ins().fmul(a[i], b[j]);
                    let right = s.b.ins().fmul(b[i], a[j]);
                    s.b.ins().fsub(left, right)
                };
                vec![
                    component(self, 1, 2),
                    component(self, 2, 0),
                    component(self, 0, 1),
                ]
            }
            "component" => match named.first() {
                Some(HostValue::Int(i)) if (0..args[0].len() as i64).contains(i) => {
                    vec![args[0][*i as usize]]
                }
                _ => return Err("a component index out of range".into()),
            },
            "vec2" | "vec3" | "vec4" => args.iter().map(|a| a[0]).collect(),
            "splat2" => vec![args[0][0]; 2],
            "splat3" => vec![args[0][0]; 3],
            "splat4" => vec![args[0][0]; 4],
            "eq" | "ne" | "lt" | "le" | "gt" | "ge" => {
                vec![self.compare(functor, ty, args[0][0], args[1][0])?]
            }
            "isZero" | "nonZero" => {
                let zero = match ty {
                    F32 => self.f32(0.0),
                    _ => self.b.ins().iconst(types::I32, 0),
                };
                let relation = if functor == "isZero" { "eq" } else { "ne" };
                vec![self.compare(relation, ty, args[0][0], zero)?]
            }
            "toF32" | "toU32" | "toI32" => vec![self.convert(functor, ty, args[0][0])?],
            "select" => {
                let condition = args[0][0];
                (0..args[1].len())
                    .map(|lane| self.b.ins().select(condition, args[1][lane], args[2][lane]))
                    .collect()
            }
            "identity" => args[0].clone(),
            other => return Err(format!("`{other}` does not compile")),
        })
    }

    /// `div` and `rem` of integers (wrapping, failing on a zero divisor) and
    /// `rem` of floats (`a - b * trunc(a / b)`).
    fn integer_division(&mut self, functor: &str, ty: ElemType, a: Value, b: Value) -> Value {
        let rem = functor == "rem";
        match ty {
            ElemType::F32 => {
                let quotient = self.b.ins().fdiv(a, b);
                let truncated = self.b.ins().trunc(quotient);
                let product = self.b.ins().fmul(b, truncated);
                self.b.ins().fsub(a, product)
            }
            ElemType::U32 => {
                let nonzero = self.b.ins().icmp_imm_u(IntCC::NotEqual, b, 0);
                self.check(nonzero);
                match rem {
                    true => self.b.ins().urem(a, b),
                    false => self.b.ins().udiv(a, b),
                }
            }
            _ => {
                let nonzero = self.b.ins().icmp_imm_s(IntCC::NotEqual, b, 0);
                self.check(nonzero);
                // `i32::MIN / -1` traps in hardware: divide by 1 instead, which
                // gives `wrapping_rem`'s 0, and negate for `wrapping_div`.
                let minus_one = self.b.ins().icmp_imm_s(IntCC::Equal, b, -1);
                let one = self.b.ins().iconst(types::I32, 1);
                let divisor = self.b.ins().select(minus_one, one, b);
                if rem {
                    self.b.ins().srem(a, divisor)
                } else {
                    let quotient = self.b.ins().sdiv(a, divisor);
                    let negated = self.b.ins().ineg(a);
                    self.b.ins().select(minus_one, negated, quotient)
                }
            }
        }
    }

    fn compare(
        &mut self,
        relation: &str,
        ty: ElemType,
        a: Value,
        b: Value,
    ) -> Result<Value, String> {
        use ElemType::{Bool, F32, I32, U32};
        Ok(match ty {
            F32 => {
                // `!=` holds for NaN, the others do not (Rust's, and the functor's).
                let condition = match relation {
                    "eq" => FloatCC::Equal,
                    "ne" => FloatCC::NotEqual,
                    "lt" => FloatCC::LessThan,
                    "le" => FloatCC::LessThanOrEqual,
                    "gt" => FloatCC::GreaterThan,
                    _ => FloatCC::GreaterThanOrEqual,
                };
                self.b.ins().fcmp(condition, a, b)
            }
            Bool | U32 | I32 => {
                let signed = ty == I32;
                let condition = match (relation, signed) {
                    ("eq", _) => IntCC::Equal,
                    ("ne", _) => IntCC::NotEqual,
                    ("lt", false) => IntCC::UnsignedLessThan,
                    ("le", false) => IntCC::UnsignedLessThanOrEqual,
                    ("gt", false) => IntCC::UnsignedGreaterThan,
                    ("ge", false) => IntCC::UnsignedGreaterThanOrEqual,
                    ("lt", true) => IntCC::SignedLessThan,
                    ("le", true) => IntCC::SignedLessThanOrEqual,
                    ("gt", true) => IntCC::SignedGreaterThan,
                    _ => IntCC::SignedGreaterThanOrEqual,
                };
                self.b.ins().icmp(condition, a, b)
            }
            other => return Err(format!("no comparison of {other:?}")),
        })
    }

    /// The generic conversions: bool is 0 or 1; out of range saturates; NaN is 0.
    fn convert(&mut self, to: &str, from: ElemType, x: Value) -> Result<Value, String> {
        use ElemType::{Bool, F32, I32, U32};
        let b = &mut self.b;
        Ok(match (from, to) {
            (Bool, "toF32") => {
                let wide = b.ins().uextend(types::I32, x);
                b.ins().fcvt_from_uint(types::F32, wide)
            }
            (Bool, _) => b.ins().uextend(types::I32, x),
            (U32, "toF32") => b.ins().fcvt_from_uint(types::F32, x),
            (I32, "toF32") => b.ins().fcvt_from_sint(types::F32, x),
            (U32, "toI32") => {
                let most = b.ins().iconst(types::I32, i64::from(i32::MAX));
                b.ins().umin(x, most)
            }
            (I32, "toU32") => {
                let zero = b.ins().iconst(types::I32, 0);
                b.ins().smax(x, zero)
            }
            (F32, "toU32") => b.ins().fcvt_to_uint_sat(types::I32, x),
            (F32, "toI32") => b.ins().fcvt_to_sint_sat(types::I32, x),
            (U32 | I32 | F32, _) => x,
            (other, _) => return Err(format!("no conversion of {other:?}")),
        })
    }
}

/// The primitive columns an array of `ty` is made of: itself, or a record's fields.
pub(super) fn leaf_types(ty: ElemType, records: &RecordRegistry) -> Vec<ElemType> {
    match ty {
        ElemType::Record(id) => records.get(id).fields.iter().map(|(_, t)| *t).collect(),
        primitive => vec![primitive],
    }
}
