//! Machine code for a [`Segment`]: a loop over the chunk's elements that
//! computes every op of the segment per element, in registers, and stores
//! only the values read after it. The loop takes [`BLOCK`] elements at a
//! time, one per lane of 128-bit vectors (Cranelift's widest on x86), then
//! the chunk's last few elements one at a time. A segment with the pair
//! idiom ([`FanOut`]) takes the chunk's whole points in blocks of [`BLOCK`]
//! with one item at a time, and the loop above does the chunk's ends.
//!
//! Every operation computes exactly what the generic functor's CPU kernel
//! computes (same IEEE operations in the same order, lane by lane; the same
//! libm calls for `pow`, `exp`, `log`, `sin` and `cos`), so a compiled stage
//! equals the column-at-a-time one bit for bit (`tests::agreement`). What
//! has no vector instruction (integer division, the libm calls, the loads
//! of a gather) is computed lane by lane with the one-element code. Where
//! the kernel would fail (an integer division by zero, a gather out of
//! range) the loop stops and returns a nonzero status (the position of the
//! element or block, plus one); the caller then runs the segment column at
//! a time, which reports the error itself.

use super::skipped_sides::{self, SkippableSides};
use super::{Segment, SegmentStep};
use crate::host::HostValue;
use crate::types::{ElemType, RecordRegistry};
use cranelift_codegen::ir::condcodes::{FloatCC, IntCC};
use cranelift_codegen::ir::{
    types, AbiParam, Block, ConstantData, Endianness, FuncRef, InstBuilder, MemFlagsData,
    StackSlot, StackSlotData, StackSlotKind, Type, Value,
};
use cranelift_codegen::settings::{self, Configurable};
use cranelift_frontend::{FunctionBuilder, FunctionBuilderContext};
use cranelift_jit::{JITBuilder, JITModule};
use cranelift_module::{default_libcall_names, FuncId, Linkage, Module};
use std::collections::{BTreeMap, HashMap, HashSet};

/// `(inputs, gathered lengths, outputs, params, n, first index) -> status`:
/// the leaf pointers of the element-wise inputs (already at the chunk's
/// start) then of the gathered arrays, one length per gathered array, the
/// output leaves, the fills' values (16 bytes each), the element count and
/// the chunk's first index. Status 0, or the failing element's position + 1.
pub(crate) type KernelEntry =
    unsafe extern "C" fn(*const *const u8, *const u64, *const *mut u8, *const u8, u64, u64) -> u64;

/// The libm functions the float kernels call, by name: the very functions the
/// generic functors' CPU kernels call, so that results agree to the bit.
/// Never inlined: `f32::powf` and the others are intrinsics LLVM may
/// speculate, and inlined into a block call it computed all four lanes and
/// masked the unwanted ones, which is the work a `select` was to spare.
#[inline(never)]
extern "C" fn dpp_pow(a: f32, b: f32) -> f32 {
    a.powf(b)
}
#[inline(never)]
extern "C" fn dpp_exp(x: f32) -> f32 {
    x.exp()
}
#[inline(never)]
extern "C" fn dpp_log(x: f32) -> f32 {
    x.ln()
}
#[inline(never)]
extern "C" fn dpp_sin(x: f32) -> f32 {
    x.sin()
}
#[inline(never)]
extern "C" fn dpp_cos(x: f32) -> f32 {
    x.cos()
}

/// A block's floats, as the block calls read and write them.
type Lanes = [f32; BLOCK as usize];
const LANES_BYTES: u32 = std::mem::size_of::<Lanes>() as u32;
/// Which lanes of a block call are wanted (nonzero): a block's bool mask.
type Wanted = [i32; BLOCK as usize];

/// The same for a block: arguments, the wanted lanes and the result in
/// [`BLOCK`]-element arrays (the kernel's stack), so that the vector loop
/// makes one call per block, not one per lane, and saves its live vectors
/// around it once. A lane not wanted (a `select` discards it) is not
/// computed: 0.
macro_rules! block_calls {
    ($($block:ident = $scalar:ident($($arg:ident),+);)+) => {$(
        /// # Safety
        /// Every pointer addresses a [`Lanes`] or [`Wanted`] (the kernel's stack slot).
        unsafe extern "C" fn $block($($arg: *const Lanes,)+ wanted: *const Wanted, out: *mut Lanes) {
            // SAFETY: the caller's contract above.
            let ($($arg,)+ wanted) = unsafe { ($(*$arg,)+ *wanted) };
            let result = std::array::from_fn(|e| match wanted[e] {
                0 => 0.0,
                _ => $scalar($($arg[e]),+),
            });
            // SAFETY: the caller's contract above.
            unsafe { *out = result };
        }
    )+};
}
block_calls! {
    dpp_pow_block = dpp_pow(a, b);
    dpp_exp_block = dpp_exp(x);
    dpp_log_block = dpp_log(x);
    dpp_sin_block = dpp_sin(x);
    dpp_cos_block = dpp_cos(x);
}

/// The calls by functor name: the element's function and the block's.
type UnaryBlock = unsafe extern "C" fn(*const Lanes, *const Wanted, *mut Lanes);
const UNARY_CALLS: [(&str, extern "C" fn(f32) -> f32, UnaryBlock); 4] = [
    ("exp", dpp_exp, dpp_exp_block),
    ("log", dpp_log, dpp_log_block),
    ("sin", dpp_sin, dpp_sin_block),
    ("cos", dpp_cos, dpp_cos_block),
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

/// Elements per iteration of the vector loop: 32-bit lanes of a 128-bit vector.
const BLOCK: u32 = 4;

/// SSA values per element: one per component, one for a bool.
fn components(ty: ElemType) -> usize {
    ty.components().max(1) as usize
}

/// The type of one component of one element.
fn scalar_type(ty: ElemType) -> Type {
    match ty {
        ElemType::Bool => types::I8,
        ElemType::U32 | ElemType::I32 => types::I32,
        _ => types::F32,
    }
}

/// Vector stores: columns are aligned to their scalars only.
fn vector_flags() -> MemFlagsData {
    MemFlagsData::new().with_notrap()
}

/// Loads of the segment's inputs, which nothing writes while the kernel
/// runs, from places always inside them (gathers are clamped): free of
/// effects, so that Cranelift computes each where it is used (a gathered
/// scalar straight into its vector lane, not held in a register from an
/// early load) or hoists it out of the loop.
fn input_flags(vector: bool) -> MemFlagsData {
    let flags = match vector {
        true => vector_flags(),
        false => MemFlagsData::trusted(),
    };
    flags.with_readonly().with_can_move()
}

/// A value of the segment inside the loop's body: for the elements of one
/// iteration (one, or a block of [`BLOCK`] in the lanes of each vector).
#[derive(Clone)]
enum Val {
    /// A primitive: one SSA value per component (one for scalars and bools).
    /// One element's bool is an `i8` 0 or 1, a block's an `i32x4` mask.
    Prim { components: Vec<Value> },
    /// A record not yet loaded: each field's column (its base pointer) and
    /// the elements' places in them. A field is loaded when read.
    Record {
        fields: Vec<(ElemType, Value)>,
        places: Places,
    },
}

/// The libm calls (`pow`, `exp`, ...) of `segment` whose values only
/// `select`s read, all with the same condition, computed before the call,
/// and the same side: each with that condition and whether the select takes
/// it where the condition holds. Their block calls compute only those lanes
/// (in `select(dot(n, v) > 0.0, pow(...), 0.0)`, only where the surface
/// faces the viewer).
fn selected_calls(segment: &Segment) -> HashMap<u32, (u32, bool)> {
    let defined_before = |var: u32, position: usize| {
        segment.elementwise.iter().any(|(v, _)| v.0 == var)
            || segment.steps[..position]
                .iter()
                .any(|step| step.output().0 == var)
    };
    let mut selected = HashMap::new();
    for (position, step) in segment.steps.iter().enumerate() {
        let SegmentStep::Map {
            functor, output, ..
        } = step
        else {
            continue;
        };
        let call = functor == "pow" || UNARY_CALLS.iter().any(|(name, _, _)| name == functor);
        if !call || segment.outputs.iter().any(|(v, _)| *v == *output) {
            continue;
        }
        let mut side = None;
        let all_selected = segment.steps.iter().all(|reader| {
            if !reader.reads().contains(&output.0) {
                return true;
            }
            let SegmentStep::Map {
                functor, inputs, ..
            } = reader
            else {
                return false;
            };
            let this_side = match inputs[..] {
                [(condition, _), (a, _), (b, _)]
                    if functor == "select" && condition != output.0 =>
                {
                    match (a == output.0, b == output.0) {
                        (true, false) => (condition, true),
                        (false, true) => (condition, false),
                        _ => return false,
                    }
                }
                _ => return false,
            };
            *side.get_or_insert(this_side) == this_side
        });
        if let Some((condition, when)) = side.filter(|_| all_selected) {
            if defined_before(condition, position) {
                selected.insert(output.0, (condition, when));
            }
        }
    }
    selected
}

/// Where an iteration's elements are in a column.
#[derive(Clone)]
enum Places {
    /// Consecutive, from this position (an `i64`).
    From(Value),
    /// One position (an `i64`) per element: a gather's.
    Each(Vec<Value>),
    /// The same position (an `i64`) for every element: loaded once.
    Same(Value),
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
    jit.symbol("dpp_pow_block", dpp_pow_block as *const u8);
    for (name, function, block) in UNARY_CALLS {
        jit.symbol(format!("dpp_{name}"), function as *const u8);
        jit.symbol(format!("dpp_{name}_block"), block as *const u8);
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
            .map(|(name, element, block)| {
                let element = module.declare_func_in_func(*element, builder.func);
                let block = module.declare_func_in_func(*block, builder.func);
                (*name, (element, block))
            })
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

/// Each libm function by functor name: the element's and the block's.
type Libm = Vec<(&'static str, FuncId, FuncId)>;

fn declare_libm(module: &mut JITModule) -> Result<Libm, String> {
    let pointer = module.target_config().pointer_type();
    let mut declare = |name: &str, arity: usize| {
        let mut element = module.make_signature();
        let mut block = module.make_signature();
        for _ in 0..arity {
            element.params.push(AbiParam::new(types::F32));
            block.params.push(AbiParam::new(pointer));
        }
        element.returns.push(AbiParam::new(types::F32));
        // The wanted lanes and the result.
        block.params.push(AbiParam::new(pointer));
        block.params.push(AbiParam::new(pointer));
        let element = module.declare_function(&format!("dpp_{name}"), Linkage::Import, &element);
        let block = module.declare_function(&format!("dpp_{name}_block"), Linkage::Import, &block);
        match (element, block) {
            (Ok(element), Ok(block)) => Ok((element, block)),
            (Err(e), _) | (_, Err(e)) => Err(e.to_string()),
        }
    };
    let mut declared = Vec::new();
    let (element, block) = declare("pow", 2)?;
    declared.push(("pow", element, block));
    for (name, _, _) in UNARY_CALLS {
        let (element, block) = declare(name, 1)?;
        declared.push((name, element, block));
    }
    Ok(declared)
}

/// The bound of an index that the segment gathers with: every element
/// gathers from each of the index's arrays, so it fails exactly where the
/// index reaches the shortest. One check and one clamp serve them all.
struct IndexLimit {
    /// The shortest length (i64), and the same capped at `u32::MAX` (i32)
    /// for the vector loop's check: an index equal to that cap fails there,
    /// which only sends the chunk to the column run.
    len: Value,
    len_u32: Value,
}

/// What the loop's bodies read that does not change per element, loaded
/// once before the loop.
struct Invariants {
    /// Each element-wise input's leaf pointers, at the chunk's start.
    elementwise: Vec<Vec<Value>>,
    /// Each gathered array's leaf pointers.
    gathered: Vec<Vec<Value>>,
    /// By index variable.
    limits: BTreeMap<u32, IndexLimit>,
    /// Each output's leaf pointers, at the chunk's start.
    outputs: Vec<Vec<Value>>,
    /// Each fill's value for one element, and splatted for a block.
    fills: Vec<(Val, Val)>,
    /// The chunk's first index in the whole array (for `iota`).
    first: Value,
}

struct Emitter<'b, 'f> {
    b: &'b mut FunctionBuilder<'f>,
    records: &'b RecordRegistry,
    /// The libm functions: for one element, and for a block.
    calls: HashMap<&'static str, (FuncRef, FuncRef)>,
    /// Elements per iteration of the body being emitted: 1 or [`BLOCK`].
    width: u32,
    /// The iteration's first element position (i64) and the block a
    /// failure jumps to.
    position: Value,
    fail: Block,
    values: HashMap<u32, Val>,
    /// The places of each index variable's gathers in this iteration.
    places_by_index: HashMap<u32, Places>,
    /// Whether every check of the iteration so far holds (see [`Self::require`]).
    valid: Option<Value>,
    /// Room for a block call's arguments, wanted lanes and result (four vectors).
    call_slot: StackSlot,
    /// The libm calls that only a `select` reads (see [`selected_calls`]).
    selected_calls: HashMap<u32, (u32, bool)>,
    /// The selects' sides a block may skip (see [`skipped_sides`]).
    skippable: SkippableSides,
    /// The lanes the block calls being emitted must compute (a mask), if not all.
    wanted: Option<Value>,
    /// The segment's fan-out, if it has one (see [`FanOut`]).
    fan_out: Option<FanOut>,
    /// In a fan-out iteration: its lanes' values of the idiom.
    fan_lanes: Option<FanLanes>,
}

/// The pair idiom `k = iota(len(points) * n)`, `k / n`, `k % n` (`n` a u32
/// fill): each point meets each of `n` items. Its loop can take the pairs
/// of [`BLOCK`] consecutive points with one item at a time instead of
/// [`BLOCK`] consecutive pairs, so that a gather by `k / n` reads
/// consecutive elements (no index to check or take apart per lane) and one
/// by `k % n` reads one element for the whole block. Each pair is computed
/// by the same operations as before, only in another order, so the results
/// are the same bits.
struct FanOut {
    /// The fill `n`, by its index among the segment's fills.
    fill: usize,
    quotients: Vec<u32>,
    remainders: Vec<u32>,
    /// Whether each step depends on the point alone (not on the item, `k`
    /// or an element-wise input): computed once per block of points, before
    /// the loop over the items.
    point_steps: Vec<bool>,
}

impl FanOut {
    /// The idiom in `segment`: an iota divided by a u32 fill, and perhaps
    /// taken modulo the same fill.
    fn find(segment: &Segment) -> Option<FanOut> {
        let iota = segment.steps.iter().find_map(|step| match step {
            SegmentStep::Iota { output } => Some(output.0),
            _ => None,
        })?;
        let fill_of = |var: u32| {
            segment.steps.iter().find_map(|step| match step {
                SegmentStep::Fill { fill, output }
                    if output.0 == var && segment.fills[*fill] == ElemType::U32 =>
                {
                    Some(*fill)
                }
                _ => None,
            })
        };
        let mut fan = None::<FanOut>;
        for step in &segment.steps {
            let SegmentStep::Map {
                functor,
                inputs,
                output,
                ..
            } = step
            else {
                continue;
            };
            let [(numerator, ElemType::U32), (divisor, ElemType::U32)] = inputs[..] else {
                continue;
            };
            let Some(fill) = fill_of(divisor).filter(|_| numerator == iota) else {
                continue;
            };
            if fan.as_ref().is_some_and(|f| f.fill != fill) {
                continue;
            }
            let fan = fan.get_or_insert(FanOut {
                fill,
                quotients: Vec::new(),
                remainders: Vec::new(),
                point_steps: Vec::new(),
            });
            match functor.as_str() {
                "div" => fan.quotients.push(output.0),
                "rem" => fan.remainders.push(output.0),
                _ => {}
            }
        }
        let mut fan = fan.filter(|f| !f.quotients.is_empty())?;
        let mut per_item: HashSet<u32> = segment.elementwise.iter().map(|(v, _)| v.0).collect();
        per_item.extend(&fan.remainders);
        fan.point_steps = segment
            .steps
            .iter()
            .map(|step| {
                let output = step.output().0;
                let item = match step {
                    SegmentStep::Iota { .. } => true,
                    SegmentStep::Fill { .. } => false,
                    SegmentStep::Field { record, .. } => per_item.contains(record),
                    SegmentStep::Gather { index, .. } => per_item.contains(index),
                    SegmentStep::Map { .. } if fan.quotients.contains(&output) => false,
                    SegmentStep::Map { inputs, .. } => {
                        inputs.iter().any(|(v, _)| per_item.contains(v))
                    }
                };
                if item {
                    per_item.insert(output);
                }
                !item
            })
            .collect();
        Some(fan)
    }
}

/// A fan-out iteration's idiom values and places: the points
/// `point .. point + BLOCK`, and once the loop over the items has begun,
/// their pairs with one item.
struct FanLanes {
    /// `k / n` per lane (i32x4).
    quotient: Value,
    item: Option<ItemLanes>,
}

struct ItemLanes {
    /// `k` and `k % n` per lane (i32x4).
    iota: Value,
    remainder: Value,
    /// Each lane's position in the chunk (i64).
    positions: Vec<Value>,
}

/// Where a chunk's fan-out loop runs: the chunk's positions before it
/// (`..head_end`), the points it takes (`first_point..points_end`, a
/// multiple of [`BLOCK`]) and the position where the rest begins. Where it
/// cannot run it takes no points and the rest is the whole chunk.
struct FanPlan {
    head_end: Value,
    first_point: Value,
    points_end: Value,
    rest_start: Value,
    items: Value,
}

impl Emitter<'_, '_> {
    fn emit(
        b: &mut FunctionBuilder<'_>,
        segment: &Segment,
        records: &RecordRegistry,
        calls: HashMap<&'static str, (FuncRef, FuncRef)>,
    ) -> Result<(), String> {
        let entry = b.create_block();
        let block_head = b.create_block();
        let block_body = b.create_block();
        let element_head = b.create_block();
        let element_body = b.create_block();
        let after = b.create_block();
        let exit = b.create_block();
        let fail = b.create_block();
        b.append_block_params_for_function_params(entry);
        b.switch_to_block(entry);
        let [inputs, lengths, outputs, params, n, first] = b.block_params(entry) else {
            return Err("the kernel's signature".into());
        };
        let (inputs, lengths, outputs, params, n, first) =
            (*inputs, *lengths, *outputs, *params, *n, *first);
        let zero = b.ins().iconst(types::I64, 0);
        let call_slot = b.create_sized_stack_slot(StackSlotData::new(
            StackSlotKind::ExplicitSlot,
            4 * LANES_BYTES,
            4,
        ));
        let mut emitter = Emitter {
            call_slot,
            b,
            records,
            calls,
            width: 1,
            position: zero,
            fail,
            values: HashMap::new(),
            places_by_index: HashMap::new(),
            valid: None,
            fan_out: FanOut::find(segment),
            fan_lanes: None,
            selected_calls: selected_calls(segment),
            skippable: SkippableSides::default(),
            wanted: None,
        };
        let point_steps = emitter.fan_out.as_ref().map(|fan| fan.point_steps.clone());
        emitter.skippable = skipped_sides::find(segment, |k, p| {
            point_steps
                .as_ref()
                .is_none_or(|steps| steps[k] == steps[p])
        });
        let invariants = emitter.invariants(segment, inputs, lengths, outputs, params, first);
        let b = &mut emitter.b;
        // Every element gathers, so an empty array it gathers from fails the
        // first, and no loop runs: the clamped gathers (some hoisted out of
        // the loop) then always read inside.
        let mut empty = None;
        for limit in invariants.limits.values() {
            let this_empty = b.ins().icmp_imm_u(IntCC::Equal, limit.len, 0);
            empty = Some(match empty {
                Some(any) => b.ins().bor(any, this_empty),
                None => this_empty,
            });
        }
        if let Some(empty) = empty {
            let (nothing_to_gather, go_on) = (b.create_block(), b.create_block());
            b.ins().brif(empty, nothing_to_gather, &[], go_on, &[]);
            b.switch_to_block(nothing_to_gather);
            let elements = b.ins().icmp_imm_u(IntCC::NotEqual, n, 0);
            b.ins().brif(elements, fail, &[zero.into()], exit, &[]);
            b.switch_to_block(go_on);
        }
        let plan = emitter.fan_plan(&invariants, n, first);
        for head in [block_head, element_head] {
            // The position, the range's end, and 0 before a fan-out loop or 1 after it.
            for _ in 0..3 {
                emitter.b.append_block_param(head, types::I64);
            }
        }
        let b = &mut emitter.b;
        let (head_end, before) = match &plan {
            Some(plan) => (plan.head_end, zero),
            None => (n, b.ins().iconst(types::I64, 1)),
        };
        b.ins()
            .jump(block_head, &[zero.into(), head_end.into(), before.into()]);

        // A range of positions: whole blocks, then the rest element by element.
        for (width, head, body, next_head) in [
            (BLOCK, block_head, block_body, element_head),
            (1, element_head, element_body, after),
        ] {
            let b = &mut emitter.b;
            b.switch_to_block(head);
            let [position, end, phase] = b.block_params(head)[..] else {
                return Err("a loop head's parameters".into());
            };
            let last = b.ins().iadd_imm_s(position, i64::from(width));
            let more = b.ins().icmp(IntCC::UnsignedLessThanOrEqual, last, end);
            let args: &[_] = match width == BLOCK {
                true => &[position.into(), end.into(), phase.into()],
                false => &[phase.into()],
            };
            b.ins().brif(more, body, &[], next_head, args);
            b.switch_to_block(body);
            emitter.width = width;
            emitter.position = position;
            emitter.body(segment, &invariants)?;
            emitter
                .b
                .ins()
                .jump(head, &[last.into(), end.into(), phase.into()]);
        }
        let b = &mut emitter.b;
        b.append_block_param(after, types::I64);
        b.switch_to_block(after);
        let phase = b.block_params(after)[0];
        match &plan {
            Some(plan) => {
                let fan_head = b.create_block();
                b.ins()
                    .brif(phase, exit, &[], fan_head, &[plan.first_point.into()]);
                emitter.fan_loop(segment, &invariants, plan, fan_head, block_head, n, first)?;
            }
            None => {
                b.ins().jump(exit, &[]);
            }
        }

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

    fn invariants(
        &mut self,
        segment: &Segment,
        inputs: Value,
        lengths: Value,
        outputs: Value,
        params: Value,
        first: Value,
    ) -> Invariants {
        let flags = MemFlagsData::trusted();
        let records = self.records;
        let mut leaf = 0;
        let mut load_pointer = |b: &mut FunctionBuilder<'_>, base: Value| {
            let p = b.ins().load(types::I64, flags, base, 8 * leaf);
            leaf += 1;
            p
        };
        let mut pointers = |b: &mut FunctionBuilder<'_>, ty: ElemType, base: Value| {
            leaf_types(ty, records)
                .iter()
                .map(|_| load_pointer(b, base))
                .collect::<Vec<_>>()
        };
        let elementwise = segment
            .elementwise
            .iter()
            .map(|(_, ty)| pointers(self.b, *ty, inputs))
            .collect();
        let gathered: Vec<(Vec<Value>, Value)> = segment
            .gathered
            .iter()
            .enumerate()
            .map(|(k, (_, ty))| {
                let leaves = pointers(self.b, *ty, inputs);
                let len = self.b.ins().load(types::I64, flags, lengths, 8 * k as i32);
                (leaves, len)
            })
            .collect();
        let (gathered, lens): (Vec<_>, Vec<_>) = gathered.into_iter().unzip();
        let mut shortest: BTreeMap<u32, Value> = BTreeMap::new();
        for step in &segment.steps {
            if let SegmentStep::Gather {
                index, gathered: g, ..
            } = step
            {
                let len = match shortest.get(index) {
                    Some(&other) => self.b.ins().umin(other, lens[*g]),
                    None => lens[*g],
                };
                shortest.insert(*index, len);
            }
        }
        let cap = self.b.ins().iconst(types::I64, i64::from(u32::MAX));
        let limits = shortest
            .into_iter()
            .map(|(index, len)| {
                let capped = self.b.ins().umin(len, cap);
                let len_u32 = self.b.ins().ireduce(types::I32, capped);
                (index, IndexLimit { len, len_u32 })
            })
            .collect();
        let mut leaf = 0;
        let outputs = segment
            .outputs
            .iter()
            .map(|(_, ty)| {
                leaf_types(*ty, records)
                    .iter()
                    .map(|_| {
                        let p = self.b.ins().load(types::I64, flags, outputs, 8 * leaf);
                        leaf += 1;
                        p
                    })
                    .collect()
            })
            .collect();
        let fills = segment
            .fills
            .iter()
            .enumerate()
            .map(|(k, ty)| {
                let one: Vec<Value> = (0..components(*ty))
                    .map(|c| {
                        let offset = (16 * k + 4 * c) as i32;
                        self.b.ins().load(scalar_type(*ty), flags, params, offset)
                    })
                    .collect();
                self.width = BLOCK;
                let block = self.broadcast(*ty, &one);
                self.width = 1;
                (
                    Val::Prim { components: one },
                    Val::Prim { components: block },
                )
            })
            .collect();
        Invariants {
            elementwise,
            gathered,
            limits,
            outputs,
            fills,
            first,
        }
    }

    /// One iteration: the segment's steps over `self.width` elements from
    /// `self.position`, and the stores of its outputs.
    fn body(&mut self, segment: &Segment, invariants: &Invariants) -> Result<(), String> {
        self.values.clear();
        self.places_by_index.clear();
        self.load_elementwise(segment, invariants);
        self.steps(segment, invariants, |_| true)?;
        self.finish(segment, invariants)
    }

    /// The element-wise inputs at the iteration's places.
    fn load_elementwise(&mut self, segment: &Segment, invariants: &Invariants) {
        let places = self.chunk_places();
        for (k, (var, ty)) in segment.elementwise.iter().enumerate() {
            let val = self.at(*ty, &invariants.elementwise[k], places.clone());
            self.values.insert(var.0, val);
        }
    }

    /// The steps at the positions `chosen` takes, in order; in a block, a
    /// select's skippable side where the select comes.
    fn steps(
        &mut self,
        segment: &Segment,
        invariants: &Invariants,
        chosen: impl Fn(usize) -> bool,
    ) -> Result<(), String> {
        for position in 0..segment.steps.len() {
            let in_a_side = self.width > 1 && self.skippable.emitted_by.contains_key(&position);
            if chosen(position) && !in_a_side {
                self.step(segment, invariants, position)?;
            }
        }
        Ok(())
    }

    /// The select at `select`'s skippable side: its steps, in a branch that
    /// the block takes unless no lane takes the side (see [`skipped_sides`]);
    /// where it is skipped, the select gets its other input for both.
    fn skippable_side(
        &mut self,
        segment: &Segment,
        invariants: &Invariants,
        select: usize,
    ) -> Result<(), String> {
        let Some(side) = self.skippable.sides.get(&select) else {
            return Ok(());
        };
        let (taken_where_true, value) = (side.taken_where_true, side.value);
        let steps: Vec<usize> = side
            .steps
            .iter()
            .copied()
            .filter(|step| self.skippable.emitted_by.get(step) == Some(&select))
            .collect();
        let SegmentStep::Map { inputs, .. } = &segment.steps[select] else {
            return Err("a skippable side of a step that is not a select".into());
        };
        let (condition, other) = match taken_where_true {
            true => (inputs[0].0, inputs[2].0),
            false => (inputs[0].0, inputs[1].0),
        };
        // The block's checks so far fail it before it branches.
        self.check();
        let mask = self.prim(condition)?[0];
        let (compute, skipped, merge) = (
            self.b.create_block(),
            self.b.create_block(),
            self.b.create_block(),
        );
        if taken_where_true {
            let any = self.b.ins().vany_true(mask);
            self.b.ins().brif(any, compute, &[], skipped, &[]);
        } else {
            let all = self.b.ins().vall_true(mask);
            self.b.ins().brif(all, skipped, &[], compute, &[]);
        }
        self.b.switch_to_block(compute);
        for step in steps {
            self.step(segment, invariants, step)?;
        }
        let taken = self.prim(value)?;
        self.check();
        let args: Vec<_> = taken.iter().map(|v| (*v).into()).collect();
        self.b.ins().jump(merge, &args);
        self.b.switch_to_block(skipped);
        let other = self.prim(other)?;
        let args: Vec<_> = other.iter().map(|v| (*v).into()).collect();
        self.b.ins().jump(merge, &args);
        for v in &taken {
            let ty = self.b.func.dfg.value_type(*v);
            self.b.append_block_param(merge, ty);
        }
        self.b.switch_to_block(merge);
        let components = self.b.block_params(merge).to_vec();
        // The side's other values do not reach past the branch.
        for &step in &self.skippable.sides[&select].steps {
            self.values.remove(&segment.steps[step].output().0);
        }
        self.values.insert(value, Val::Prim { components });
        Ok(())
    }

    /// The step at `position`.
    fn step(
        &mut self,
        segment: &Segment,
        invariants: &Invariants,
        position: usize,
    ) -> Result<(), String> {
        let step = &segment.steps[position];
        if let Some(val) = self.fan_value(step) {
            self.values.insert(step.output().0, val);
            return Ok(());
        }
        if self.width > 1 {
            self.skippable_side(segment, invariants, position)?;
        }
        let val = match step {
            SegmentStep::Iota { .. } => {
                let index = self.iota(invariants.first);
                Val::Prim {
                    components: vec![index],
                }
            }
            SegmentStep::Fill { fill, .. } => {
                let (one, block) = &invariants.fills[*fill];
                if self.width == 1 { one } else { block }.clone()
            }
            SegmentStep::Field { record, field, .. } => self.field(*record, *field)?,
            SegmentStep::Gather {
                index, gathered: g, ..
            } => {
                let places = match self.places_by_index.get(index) {
                    Some(places) => places.clone(),
                    None => {
                        let limit = invariants.limits.get(index).ok_or("a gather's limit")?;
                        let index_value = self.prim(*index)?[0];
                        let places = self.gathered_places(index_value, limit);
                        self.places_by_index.insert(*index, places.clone());
                        places
                    }
                };
                let leaves = &invariants.gathered[*g];
                self.at(segment.gathered[*g].1, leaves, places)
            }
            SegmentStep::Map {
                functor,
                inputs,
                output_type,
                named,
                output,
            } => {
                // A fan-out's point steps come before an item's condition: all lanes then.
                let condition = self
                    .selected_calls
                    .get(&output.0)
                    .filter(|_| self.width > 1)
                    .and_then(|&(condition, when)| Some((self.prim(condition).ok()?, when)));
                self.wanted = match condition {
                    Some((mask, true)) => Some(mask[0]),
                    Some((mask, false)) => Some(self.b.ins().bnot(mask[0])),
                    None => None,
                };
                let val = self.map(functor, inputs, *output_type, named);
                self.wanted = None;
                val?
            }
        };
        self.values.insert(step.output().0, val);
        Ok(())
    }

    /// Fails the iteration where a check of its steps so far did not hold.
    fn check(&mut self) {
        if let Some(valid) = self.valid.take() {
            let next = self.b.create_block();
            let position = self.position.into();
            self.b.ins().brif(valid, next, &[], self.fail, &[position]);
            self.b.switch_to_block(next);
        }
    }

    /// The end of an iteration: its checks, then the stores of its outputs.
    fn finish(&mut self, segment: &Segment, invariants: &Invariants) -> Result<(), String> {
        self.check();
        let places = self.chunk_places();
        for ((var, ty), pointers) in segment.outputs.iter().zip(&invariants.outputs) {
            let val = self
                .values
                .get(&var.0)
                .cloned()
                .ok_or("an unknown output")?;
            self.store(*ty, val, pointers, &places)?;
        }
        Ok(())
    }

    /// The places of the iteration's elements in the chunk's columns.
    fn chunk_places(&self) -> Places {
        match self
            .fan_lanes
            .as_ref()
            .and_then(|lanes| lanes.item.as_ref())
        {
            Some(item) => Places::Each(item.positions.clone()),
            None => Places::From(self.position),
        }
    }

    /// In a fan-out iteration, the value of `step` if it is the idiom's.
    fn fan_value(&self, step: &SegmentStep) -> Option<Val> {
        let (fan, lanes) = (self.fan_out.as_ref()?, self.fan_lanes.as_ref()?);
        let output = step.output().0;
        let value = match (step, &lanes.item) {
            (SegmentStep::Iota { .. }, Some(item)) => item.iota,
            (SegmentStep::Map { .. }, _) if fan.quotients.contains(&output) => lanes.quotient,
            (SegmentStep::Map { .. }, Some(item)) if fan.remainders.contains(&output) => {
                item.remainder
            }
            _ => return None,
        };
        Some(Val::Prim {
            components: vec![value],
        })
    }

    /// Where the chunk's fan-out loop runs (`None` for a segment without
    /// the idiom). It runs only where every point and item it takes is
    /// inside the arrays gathered by `k / n` and `k % n` and `k` fits a
    /// u32, so that its gathers need no check.
    fn fan_plan(&mut self, invariants: &Invariants, n: Value, first: Value) -> Option<FanPlan> {
        let fan = self.fan_out.as_ref()?;
        let Val::Prim { components } = &invariants.fills[fan.fill].0 else {
            return None;
        };
        let b = &mut self.b;
        let items = b.ins().uextend(types::I64, components[0]);
        let zero = b.ins().iconst(types::I64, 0);
        let one = b.ins().iconst(types::I64, 1);
        let no_items = b.ins().icmp_imm_u(IntCC::Equal, items, 0);
        let divisor = b.ins().select(no_items, one, items);
        let end = b.ins().iadd(first, n);
        let rounded_up = b.ins().iadd(first, divisor);
        let rounded_up = b.ins().iadd_imm_s(rounded_up, -1);
        let first_point = b.ins().udiv(rounded_up, divisor);
        let last_point = b.ins().udiv(end, divisor);
        let some = b
            .ins()
            .icmp(IntCC::UnsignedGreaterThan, last_point, first_point);
        let span = b.ins().isub(last_point, first_point);
        let span = b.ins().select(some, span, zero);
        let points = b.ins().band_imm_s(span, -i64::from(BLOCK));
        let points_end = b.ins().iadd(first_point, points);
        let mut ok = b.ins().icmp_imm_u(IntCC::NotEqual, points, 0);
        let fits = b
            .ins()
            .icmp_imm_u(IntCC::UnsignedLessThanOrEqual, end, 1 << 32);
        ok = b.ins().band(ok, fits);
        let bounds = fan
            .quotients
            .iter()
            .map(|q| (q, points_end))
            .chain(fan.remainders.iter().map(|r| (r, items)));
        for (var, needed) in bounds {
            if let Some(limit) = invariants.limits.get(var) {
                let inside = b
                    .ins()
                    .icmp(IntCC::UnsignedLessThanOrEqual, needed, limit.len);
                ok = b.ins().band(ok, inside);
            }
        }
        let head_end = b.ins().imul(first_point, items);
        let head_end = b.ins().isub(head_end, first);
        let rest_start = b.ins().imul(points_end, items);
        let rest_start = b.ins().isub(rest_start, first);
        Some(FanPlan {
            head_end: b.ins().select(ok, head_end, zero),
            first_point,
            points_end: b.ins().select(ok, points_end, first_point),
            rest_start: b.ins().select(ok, rest_start, zero),
            items,
        })
    }

    /// The fan-out loop: for each [`BLOCK`] of points from `plan.first_point`,
    /// the steps of the points alone, then each item's; then the rest of the
    /// chunk's range at `block_head`.
    #[allow(clippy::too_many_arguments)]
    fn fan_loop(
        &mut self,
        segment: &Segment,
        invariants: &Invariants,
        plan: &FanPlan,
        fan_head: Block,
        block_head: Block,
        n: Value,
        first: Value,
    ) -> Result<(), String> {
        let point_steps = match &self.fan_out {
            Some(fan) => fan.point_steps.clone(),
            None => return Err("a fan-out loop without the idiom".into()),
        };
        let b = &mut self.b;
        let (points_body, item_head, item_body) =
            (b.create_block(), b.create_block(), b.create_block());
        b.append_block_param(fan_head, types::I64);
        b.switch_to_block(fan_head);
        let point = b.block_params(fan_head)[0];
        let more = b
            .ins()
            .icmp(IntCC::UnsignedLessThan, point, plan.points_end);
        let after_fan = b.ins().iconst(types::I64, 1);
        b.ins().brif(
            more,
            points_body,
            &[],
            block_head,
            &[plan.rest_start.into(), n.into(), after_fan.into()],
        );

        // The points' own steps, once for all their items.
        self.b.switch_to_block(points_body);
        self.width = BLOCK;
        let point_u32 = self.b.ins().ireduce(types::I32, point);
        let points = self.widen(point_u32);
        let lanes = self.lane_numbers();
        let quotient = self.b.ins().iadd(points, lanes);
        let pairs_start = self.b.ins().imul(point, plan.items);
        self.position = self.b.ins().isub(pairs_start, first);
        self.fan_lanes = Some(FanLanes {
            quotient,
            item: None,
        });
        self.values.clear();
        self.places_by_index.clear();
        if let Some(fan) = &self.fan_out {
            // Inside the arrays (checked once for the whole loop: `fan_plan`).
            for quotient in &fan.quotients {
                self.places_by_index.insert(*quotient, Places::From(point));
            }
        }
        self.steps(segment, invariants, |k| point_steps[k])?;
        self.check();
        let zero = self.b.ins().iconst(types::I64, 0);
        self.b.ins().jump(item_head, &[zero.into()]);

        // Each item's pairs with the points.
        let b = &mut self.b;
        b.append_block_param(item_head, types::I64);
        b.switch_to_block(item_head);
        let item = b.block_params(item_head)[0];
        let more = b.ins().icmp(IntCC::UnsignedLessThan, item, plan.items);
        let next_point = b.ins().iadd_imm_s(point, i64::from(BLOCK));
        b.ins()
            .brif(more, item_body, &[], fan_head, &[next_point.into()]);
        self.b.switch_to_block(item_body);
        let item_lanes = self.item_lanes(plan, quotient, pairs_start, item, first);
        self.position = item_lanes.positions[0];
        if let Some(fan) = &self.fan_out {
            for remainder in &fan.remainders {
                self.places_by_index.insert(*remainder, Places::Same(item));
            }
        }
        if let Some(lanes) = &mut self.fan_lanes {
            lanes.item = Some(item_lanes);
        }
        self.load_elementwise(segment, invariants);
        self.steps(segment, invariants, |k| !point_steps[k])?;
        self.finish(segment, invariants)?;
        self.fan_lanes = None;
        let next_item = self.b.ins().iadd_imm_s(item, 1);
        self.b.ins().jump(item_head, &[next_item.into()]);
        Ok(())
    }

    /// The idiom's values for the pairs of the points whose `k / n` is
    /// `quotient` with `item`, and their positions in the chunk (the first
    /// point's pairs begin at `pairs_start`).
    fn item_lanes(
        &mut self,
        plan: &FanPlan,
        quotient: Value,
        pairs_start: Value,
        item: Value,
        first: Value,
    ) -> ItemLanes {
        let item_u32 = self.b.ins().ireduce(types::I32, item);
        let items_u32 = self.b.ins().ireduce(types::I32, plan.items);
        let remainder = self.widen(item_u32);
        let items_wide = self.widen(items_u32);
        let scaled = self.b.ins().imul(quotient, items_wide);
        let iota = self.b.ins().iadd(scaled, remainder);
        let start = self.b.ins().iadd(pairs_start, item);
        let mut position = self.b.ins().isub(start, first);
        let mut positions = vec![position];
        for _ in 1..BLOCK {
            position = self.b.ins().iadd(position, plan.items);
            positions.push(position);
        }
        ItemLanes {
            iota,
            remainder,
            positions,
        }
    }

    /// The iteration's elements' indices in the whole array (u32, wrapping).
    fn iota(&mut self, first: Value) -> Value {
        let start = self.b.ins().iadd(first, self.position);
        let start = self.b.ins().ireduce(types::I32, start);
        if self.width == 1 {
            return start;
        }
        let starts = self.widen(start);
        let offsets = self.lane_numbers();
        self.b.ins().iadd(starts, offsets)
    }

    /// Each lane's number, 0 to [`BLOCK`] - 1 (i32x4).
    fn lane_numbers(&mut self) -> Value {
        let numbers: Vec<u8> = (0..BLOCK).flat_map(u32::to_le_bytes).collect();
        let numbers = self
            .b
            .func
            .dfg
            .constants
            .insert(ConstantData::from(numbers));
        self.b.ins().vconst(types::I32X4, numbers)
    }

    /// The positions of a gather's `index` (u32 per element). One out of
    /// range makes the iteration fail; its position is replaced by 0, so
    /// that every load stays inside the array (the kernel's entry made sure
    /// that none it gathers from is empty).
    fn gathered_places(&mut self, index: Value, limit: &IndexLimit) -> Places {
        if self.width == 1 {
            let position = self.b.ins().uextend(types::I64, index);
            let inside = self
                .b
                .ins()
                .icmp(IntCC::UnsignedLessThan, position, limit.len);
            self.require(inside);
            let zero = self.b.ins().iconst(types::I64, 0);
            return Places::Each(vec![self.b.ins().select(inside, position, zero)]);
        }
        let bound = self.widen(limit.len_u32);
        let inside = self.b.ins().icmp(IntCC::UnsignedLessThan, index, bound);
        let all_inside = self.b.ins().vall_true(inside);
        self.require(all_inside);
        let zero = self.i32(0);
        let clamped = self.choose(inside, index, zero);
        let positions = self
            .elements(clamped)
            .into_iter()
            .map(|index| self.b.ins().uextend(types::I64, index))
            .collect();
        Places::Each(positions)
    }

    /// The elements at `places` of the column(s) `leaves` of type `ty`:
    /// loaded now for a primitive, left to its fields' reads for a record.
    fn at(&mut self, ty: ElemType, leaves: &[Value], places: Places) -> Val {
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
                places,
            },
            primitive => Val::Prim {
                components: self.load(primitive, leaves[0], &places),
            },
        }
    }

    fn address(&mut self, ty: ElemType, base: Value, position: Value) -> Value {
        let offset = self
            .b
            .ins()
            .imul_imm_s(position, ty.bytes(self.records) as i64);
        self.b.ins().iadd(base, offset)
    }

    /// Each element's position.
    fn positions(&mut self, places: &Places) -> Vec<Value> {
        match places {
            Places::From(first) => (0..self.width)
                .map(|e| match e {
                    0 => *first,
                    _ => self.b.ins().iadd_imm_s(*first, i64::from(e)),
                })
                .collect(),
            Places::Each(positions) => positions.clone(),
            Places::Same(position) => vec![*position; self.width as usize],
        }
    }

    /// Whether a block's elements of `ty` move as one vector: consecutive
    /// scalars (bools are bytes, vectors' components interleaved).
    fn moves_whole(&self, ty: ElemType, places: &Places) -> Option<Value> {
        match places {
            Places::From(first)
                if self.width > 1 && components(ty) == 1 && ty != ElemType::Bool =>
            {
                Some(*first)
            }
            _ => None,
        }
    }

    fn load(&mut self, ty: ElemType, base: Value, places: &Places) -> Vec<Value> {
        if let Some(first) = self.moves_whole(ty, places) {
            let address = self.address(ty, base, first);
            let vector = self.value_type(ty);
            return vec![self.b.ins().load(vector, input_flags(true), address, 0)];
        }
        if let (Places::Same(position), true) = (places, self.width > 1) {
            // One element for the whole block.
            let width = self.width;
            self.width = 1;
            let one = self.load(ty, base, &Places::Each(vec![*position]));
            self.width = width;
            return self.broadcast(ty, &one);
        }
        let addresses: Vec<Value> = self
            .positions(places)
            .into_iter()
            .map(|position| self.address(ty, base, position))
            .collect();
        let flags = input_flags(false);
        (0..components(ty))
            .map(|c| {
                let offset = 4 * c as i32;
                let scalars = addresses
                    .iter()
                    .map(|&address| match (ty, self.width) {
                        (ElemType::Bool, 1) => self.b.ins().load(types::I8, flags, address, 0),
                        (ElemType::Bool, _) => {
                            let byte = self.b.ins().uload8(types::I32, flags, address, 0);
                            self.b.ins().ineg(byte)
                        }
                        _ => self.b.ins().load(scalar_type(ty), flags, address, offset),
                    })
                    .collect();
                self.assemble(scalars)
            })
            .collect()
    }

    fn store(
        &mut self,
        ty: ElemType,
        val: Val,
        pointers: &[Value],
        places: &Places,
    ) -> Result<(), String> {
        match val {
            Val::Prim { components } => {
                if let Some(first) = self.moves_whole(ty, places) {
                    let address = self.address(ty, pointers[0], first);
                    self.b
                        .ins()
                        .store(vector_flags(), components[0], address, 0);
                    return Ok(());
                }
                let addresses: Vec<Value> = self
                    .positions(places)
                    .into_iter()
                    .map(|position| self.address(ty, pointers[0], position))
                    .collect();
                for (c, component) in components.into_iter().enumerate() {
                    for (address, element) in addresses.iter().zip(self.elements(component)) {
                        // A block's bool lane is a mask: stored as the byte 0 or 1.
                        let element = match ty == ElemType::Bool && self.width > 1 {
                            true => {
                                let bit = self.b.ins().band_imm_s(element, 1);
                                self.b.ins().ireduce(types::I8, bit)
                            }
                            false => element,
                        };
                        self.b.ins().store(
                            MemFlagsData::trusted(),
                            element,
                            *address,
                            4 * c as i32,
                        );
                    }
                }
            }
            Val::Record {
                fields,
                places: loaded_from,
            } => {
                for ((field_ty, base), pointer) in fields.into_iter().zip(pointers) {
                    let components = self.load(field_ty, base, &loaded_from);
                    self.store(field_ty, Val::Prim { components }, &[*pointer], places)?;
                }
            }
        }
        Ok(())
    }

    /// Makes the iteration fail, at its end, unless `holds` (an i8 truth
    /// value) is true: one branch per iteration, not one per check, keeps
    /// the body one block of straight-line code.
    fn require(&mut self, holds: Value) {
        self.valid = Some(match self.valid {
            Some(valid) => self.b.ins().band(valid, holds),
            None => holds,
        });
    }

    fn prim(&self, var: u32) -> Result<Vec<Value>, String> {
        match self.values.get(&var) {
            Some(Val::Prim { components }) => Ok(components.clone()),
            _ => Err(format!("value {var} is not a primitive of the segment")),
        }
    }

    fn field(&mut self, record: u32, field: usize) -> Result<Val, String> {
        let Some(Val::Record { fields, places }) = self.values.get(&record).cloned() else {
            return Err(format!("value {record} is not a record of the segment"));
        };
        let (ty, base) = fields[field];
        Ok(Val::Prim {
            components: self.load(ty, base, &places),
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
        let components = self.operation(functor, ty, &args, named)?;
        if components.len() != self::components(output) {
            return Err(format!(
                "`{functor}` gave {} components for {output:?}",
                components.len()
            ));
        }
        Ok(Val::Prim { components })
    }

    /// The type of one component of `ty` for the iteration's elements.
    fn value_type(&self, ty: ElemType) -> Type {
        match (ty, self.width) {
            (_, 1) => scalar_type(ty),
            (ElemType::Bool, _) => types::I32X4,
            _ => scalar_type(ty).by(self.width).unwrap_or(types::INVALID),
        }
    }

    /// One element's components (a bool as an `i8`) for every element of
    /// the iteration (a bool as a mask).
    fn broadcast(&mut self, ty: ElemType, one: &[Value]) -> Vec<Value> {
        one.iter()
            .map(|&scalar| match ty {
                ElemType::Bool if self.width > 1 => {
                    let wide = self.b.ins().uextend(types::I32, scalar);
                    let mask = self.b.ins().ineg(wide);
                    self.widen(mask)
                }
                _ => self.widen(scalar),
            })
            .collect()
    }

    /// `scalar` for every element of the iteration.
    fn widen(&mut self, scalar: Value) -> Value {
        if self.width == 1 {
            return scalar;
        }
        let ty = self.b.func.dfg.value_type(scalar);
        let vector = ty.by(self.width).unwrap_or(types::INVALID);
        self.b.ins().splat(vector, scalar)
    }

    /// A component's value for each element: itself, or a block's lanes.
    fn elements(&mut self, value: Value) -> Vec<Value> {
        if self.width == 1 {
            return vec![value];
        }
        (0..self.width)
            .map(|e| self.b.ins().extractlane(value, e as u8))
            .collect()
    }

    /// The value whose elements are `scalars` (the inverse of [`Self::elements`]).
    fn assemble(&mut self, scalars: Vec<Value>) -> Value {
        if self.width == 1 {
            return scalars[0];
        }
        let ty = self.b.func.dfg.value_type(scalars[0]);
        let vector = ty.by(self.width).unwrap_or(types::INVALID);
        // A splat is one instruction; a vector from a scalar clears the rest first.
        let mut value = self.b.ins().splat(vector, scalars[0]);
        for (e, scalar) in scalars.into_iter().enumerate().skip(1) {
            value = self.b.ins().insertlane(value, scalar, e as u8);
        }
        value
    }

    /// `op` of one element's scalars, for each element of the iteration:
    /// for what has no vector instruction.
    fn each_element(
        &mut self,
        args: &[Value],
        mut op: impl FnMut(&mut Self, &[Value]) -> Value,
    ) -> Value {
        if self.width == 1 {
            return op(self, args);
        }
        let per_arg: Vec<Vec<Value>> = args.iter().map(|&a| self.elements(a)).collect();
        let width = self.width;
        self.width = 1;
        let mut results = Vec::new();
        for e in 0..width as usize {
            let scalars: Vec<Value> = per_arg.iter().map(|lanes| lanes[e]).collect();
            results.push(op(self, &scalars));
        }
        self.width = width;
        self.assemble(results)
    }

    /// `op` applied to each component of `args` (all of `ty`'s shape).
    fn per_component(
        &mut self,
        args: &[Vec<Value>],
        mut op: impl FnMut(&mut Self, &[Value]) -> Value,
    ) -> Vec<Value> {
        (0..args[0].len())
            .map(|c| {
                let component_args: Vec<Value> = args.iter().map(|a| a[c]).collect();
                op(self, &component_args)
            })
            .collect()
    }

    fn f32(&mut self, value: f32) -> Value {
        let scalar = self.b.ins().f32const(value);
        self.widen(scalar)
    }

    fn i32(&mut self, value: i32) -> Value {
        let scalar = self.b.ins().iconst(types::I32, i64::from(value));
        self.widen(scalar)
    }

    /// `a` where `condition` (a bool) holds, else `b`.
    fn choose(&mut self, condition: Value, a: Value, b: Value) -> Value {
        if self.width == 1 {
            return self.b.ins().select(condition, a, b);
        }
        let ty = self.b.func.dfg.value_type(a);
        let mask = match ty == types::I32X4 {
            true => condition,
            false => self.bitcast(ty, condition),
        };
        self.b.ins().bitselect(mask, a, b)
    }

    /// A bool as the integer 0 or 1.
    fn bool_to_int(&mut self, x: Value) -> Value {
        if self.width == 1 {
            return self.b.ins().uextend(types::I32, x);
        }
        let one = self.i32(1);
        self.b.ins().band(x, one)
    }

    /// The libm function `name` of `args` (f32 values, one per argument).
    fn call(&mut self, name: &str, args: &[Value]) -> Value {
        let (element, block) = self.calls[name];
        if self.width == 1 {
            let call = self.b.ins().call(element, args);
            return self.b.inst_results(call)[0];
        }
        // The block's function reads its arguments from the stack slot's
        // first vectors and writes its result into the next one.
        let flags = MemFlagsData::trusted();
        let mut pointers = Vec::new();
        for (k, arg) in args.iter().enumerate() {
            let pointer = self.b.ins().stack_addr(
                types::I64,
                self.call_slot,
                (LANES_BYTES as usize * k) as i32,
            );
            self.b.ins().store(flags, *arg, pointer, 0);
            pointers.push(pointer);
        }
        let wanted = match self.wanted {
            Some(mask) => mask,
            None => self.i32(-1),
        };
        let slot = |k: usize| (LANES_BYTES as usize * k) as i32;
        let wanted_at = self
            .b
            .ins()
            .stack_addr(types::I64, self.call_slot, slot(args.len()));
        self.b.ins().store(flags, wanted, wanted_at, 0);
        pointers.push(wanted_at);
        let result = self
            .b
            .ins()
            .stack_addr(types::I64, self.call_slot, slot(args.len() + 1));
        pointers.push(result);
        self.b.ins().call(block, &pointers);
        self.b.ins().load(types::F32X4, flags, result, 0)
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
        let chosen = self.choose(b_better, b, a);
        let a_nan = self.b.ins().fcmp(FloatCC::Unordered, a, a);
        self.choose(a_nan, b, chosen)
    }

    fn sum_of_products(&mut self, a: &[Value], b: &[Value]) -> Value {
        let mut sum = self.b.ins().fmul(a[0], b[0]);
        for c in 1..a.len() {
            let product = self.b.ins().fmul(a[c], b[c]);
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
            "add" if float => self.per_component(args, |s, x| s.b.ins().fadd(x[0], x[1])),
            "sub" if float => self.per_component(args, |s, x| s.b.ins().fsub(x[0], x[1])),
            "mul" if float => self.per_component(args, |s, x| s.b.ins().fmul(x[0], x[1])),
            "div" if float => self.per_component(args, |s, x| s.b.ins().fdiv(x[0], x[1])),
            "add" => self.per_component(args, |s, x| s.b.ins().iadd(x[0], x[1])),
            "sub" => self.per_component(args, |s, x| s.b.ins().isub(x[0], x[1])),
            "mul" => self.per_component(args, |s, x| s.b.ins().imul(x[0], x[1])),
            "rem" if ty == F32 => vec![self.float_remainder(args[0][0], args[1][0])],
            "div" | "rem" if ty == U32 && self.width > 1 => {
                vec![self.unsigned_division_block(functor == "rem", args[0][0], args[1][0])]
            }
            "div" | "rem" if !float => {
                let operands = [args[0][0], args[1][0]];
                vec![self.each_element(&operands, |s, x| {
                    s.integer_division(functor, ty, x[0], x[1])
                })]
            }
            "min" | "max" if float => {
                let smaller = functor == "min";
                self.per_component(args, |s, x| s.nan_ignoring(x[0], x[1], smaller))
            }
            "min" if ty == U32 => vec![self.b.ins().umin(args[0][0], args[1][0])],
            "max" if ty == U32 => vec![self.b.ins().umax(args[0][0], args[1][0])],
            "min" => vec![self.b.ins().smin(args[0][0], args[1][0])],
            "max" => vec![self.b.ins().smax(args[0][0], args[1][0])],
            "and" => vec![self.b.ins().band(args[0][0], args[1][0])],
            "or" => vec![self.b.ins().bor(args[0][0], args[1][0])],
            "not" if self.width == 1 => vec![self.b.ins().bxor_imm_u(args[0][0], 1)],
            "not" => vec![self.b.ins().bnot(args[0][0])],
            "neg" if float => self.per_component(args, |s, x| s.b.ins().fneg(x[0])),
            "neg" => vec![self.b.ins().ineg(args[0][0])],
            "abs" => self.per_component(args, |s, x| s.b.ins().fabs(x[0])),
            "floor" => self.per_component(args, |s, x| s.b.ins().floor(x[0])),
            "ceil" => self.per_component(args, |s, x| s.b.ins().ceil(x[0])),
            "sqrt" => self.per_component(args, |s, x| s.b.ins().sqrt(x[0])),
            "fract" => self.per_component(args, |s, x| {
                let floor = s.b.ins().floor(x[0]);
                s.b.ins().fsub(x[0], floor)
            }),
            "rsqrt" => self.per_component(args, |s, x| {
                let one = s.f32(1.0);
                let root = s.b.ins().sqrt(x[0]);
                s.b.ins().fdiv(one, root)
            }),
            "exp" | "log" | "sin" | "cos" => {
                let name = UNARY_CALLS
                    .iter()
                    .find(|(n, _, _)| *n == functor)
                    .map(|(n, _, _)| *n)
                    .ok_or("an unknown call")?;
                self.per_component(args, |s, x| s.call(name, &[x[0]]))
            }
            "pow" => self.per_component(args, |s, x| s.call("pow", &[x[0], x[1]])),
            // `x.max(lo).min(hi)`.
            "clamp" => self.per_component(args, |s, x| {
                let low = s.nan_ignoring(x[0], x[1], false);
                s.nan_ignoring(low, x[2], true)
            }),
            // `a * (1.0 - t) + b * t`.
            "mix" => self.per_component(args, |s, x| {
                let one = s.f32(1.0);
                let rest = s.b.ins().fsub(one, x[2]);
                let left = s.b.ins().fmul(x[0], rest);
                let right = s.b.ins().fmul(x[1], x[2]);
                s.b.ins().fadd(left, right)
            }),
            "step" => self.per_component(args, |s, x| {
                let reached = s.b.ins().fcmp(FloatCC::LessThanOrEqual, x[0], x[1]);
                let (one, zero) = (s.f32(1.0), s.f32(0.0));
                s.choose(reached, one, zero)
            }),
            // `t = ((x - lo) / (hi - lo)).max(0.0).min(1.0); t * t * (3.0 - 2.0 * t)`.
            "smoothstep" => self.per_component(args, |s, x| {
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
                let d = self.per_component(args, |s, x| s.b.ins().fsub(x[0], x[1]));
                let squared = self.sum_of_products(&d, &d);
                vec![self.b.ins().sqrt(squared)]
            }
            "normalize" => {
                let squared = self.sum_of_products(&args[0], &args[0]);
                let length = self.b.ins().sqrt(squared);
                let zero = self.f32(0.0);
                let vanishes = self.b.ins().fcmp(FloatCC::Equal, length, zero);
                self.per_component(args, |s, x| {
                    let scaled = s.b.ins().fdiv(x[0], length);
                    s.choose(vanishes, zero, scaled)
                })
            }
            // `i - (2.0 * dot(n, i)) * n`.
            "reflect" => {
                let dot = self.sum_of_products(&args[1], &args[0]);
                let two = self.f32(2.0);
                let twice = self.b.ins().fmul(two, dot);
                self.per_component(args, |s, x| {
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
                    _ => self.i32(0),
                };
                let relation = if functor == "isZero" { "eq" } else { "ne" };
                vec![self.compare(relation, ty, args[0][0], zero)?]
            }
            "toF32" | "toU32" | "toI32" => vec![self.convert(functor, ty, args[0][0])?],
            "select" => {
                let condition = args[0][0];
                (0..args[1].len())
                    .map(|c| self.choose(condition, args[1][c], args[2][c]))
                    .collect()
            }
            "identity" => args[0].clone(),
            other => return Err(format!("`{other}` does not compile")),
        })
    }

    /// `rem` of floats: `a - b * trunc(a / b)`.
    fn float_remainder(&mut self, a: Value, b: Value) -> Value {
        let quotient = self.b.ins().fdiv(a, b);
        let truncated = self.b.ins().trunc(quotient);
        let product = self.b.ins().fmul(b, truncated);
        self.b.ins().fsub(a, product)
    }

    /// `div` and `rem` of a block of u32s without the hardware's division,
    /// which takes tens of cycles a lane (and the pair idiom's `k / lights`
    /// and `k % lights` cost two per pair): each quotient is the truncated
    /// f64 quotient, exact for 32-bit operands (its rounding error, below
    /// 2^-21 / b, never reaches the next integer, at least 1 / b away), and
    /// `rem` is `a - q * b`. A zero divisor makes the iteration fail.
    fn unsigned_division_block(&mut self, rem: bool, a: Value, b: Value) -> Value {
        let zero = self.i32(0);
        let nonzero = self.b.ins().icmp(IntCC::NotEqual, b, zero);
        let all_nonzero = self.b.ins().vall_true(nonzero);
        self.require(all_nonzero);
        // 2^52: added to an integer below 2^32, its low 32 bits are the integer's.
        let magic = self.b.ins().f64const(4_503_599_627_370_496.0);
        let magic = self.b.ins().splat(types::F64X2, magic);
        let mut quotient_bits = Vec::new();
        for high in [false, true] {
            let [a, b] = [a, b].map(|v| {
                let half = match high {
                    true => self.shuffle_lanes(v, v, [2, 3, 0, 1]),
                    false => v,
                };
                let wide = self.b.ins().uwiden_low(half);
                self.b.ins().fcvt_from_uint(types::F64X2, wide)
            });
            let quotient = self.b.ins().fdiv(a, b);
            let quotient = self.b.ins().trunc(quotient);
            let shifted = self.b.ins().fadd(quotient, magic);
            quotient_bits.push(self.bitcast(types::I32X4, shifted));
        }
        let quotient = self.shuffle_lanes(quotient_bits[0], quotient_bits[1], [0, 2, 4, 6]);
        if !rem {
            return quotient;
        }
        let product = self.b.ins().imul(quotient, b);
        self.b.ins().isub(a, product)
    }

    /// Lanes of two 32-bit-lane vectors: `lanes[i]` picks lane `l` of `x`
    /// for `l < 4`, else lane `l - 4` of `y`.
    fn shuffle_lanes(&mut self, x: Value, y: Value, lanes: [u8; 4]) -> Value {
        let ty = self.b.func.dfg.value_type(x);
        let bytes: Vec<u8> = lanes
            .iter()
            .flat_map(|lane| (0..4).map(move |byte| 4 * lane + byte))
            .collect();
        let mask = self.b.func.dfg.immediates.push(ConstantData::from(bytes));
        let [x, y] = [x, y].map(|v| self.bitcast(types::I8X16, v));
        let shuffled = self.b.ins().shuffle(x, y, mask);
        self.bitcast(ty, shuffled)
    }

    fn bitcast(&mut self, ty: Type, value: Value) -> Value {
        let little = MemFlagsData::new().with_endianness(Endianness::Little);
        self.b.ins().bitcast(ty, little, value)
    }

    /// `div` and `rem` of integers of one element: wrapping; a zero divisor
    /// makes the iteration fail (and is replaced by 1, as division by zero
    /// traps in hardware).
    fn integer_division(&mut self, functor: &str, ty: ElemType, a: Value, b: Value) -> Value {
        let rem = functor == "rem";
        let nonzero = self.b.ins().icmp_imm_u(IntCC::NotEqual, b, 0);
        self.require(nonzero);
        let one = self.b.ins().iconst(types::I32, 1);
        match ty {
            ElemType::U32 => {
                let divisor = self.b.ins().select(nonzero, b, one);
                match rem {
                    true => self.b.ins().urem(a, divisor),
                    false => self.b.ins().udiv(a, divisor),
                }
            }
            _ => {
                // `i32::MIN / -1` traps in hardware too: divide by 1 instead,
                // which gives `wrapping_rem`'s 0, and negate for `wrapping_div`.
                let minus_one = self.b.ins().icmp_imm_s(IntCC::Equal, b, -1);
                let zero = self.b.ins().icmp_imm_u(IntCC::Equal, b, 0);
                let unusable = self.b.ins().bor(minus_one, zero);
                let divisor = self.b.ins().select(unusable, one, b);
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
        let (float, integer) = (self.value_type(F32), self.value_type(U32));
        Ok(match (from, to) {
            (Bool, "toF32") => {
                let bit = self.bool_to_int(x);
                self.b.ins().fcvt_from_sint(float, bit)
            }
            (Bool, _) => self.bool_to_int(x),
            (U32, "toF32") => self.b.ins().fcvt_from_uint(float, x),
            (I32, "toF32") => self.b.ins().fcvt_from_sint(float, x),
            (U32, "toI32") => {
                let most = self.i32(i32::MAX);
                self.b.ins().umin(x, most)
            }
            (I32, "toU32") => {
                let zero = self.i32(0);
                self.b.ins().smax(x, zero)
            }
            (F32, "toU32") => self.b.ins().fcvt_to_uint_sat(integer, x),
            (F32, "toI32") => self.b.ins().fcvt_to_sint_sat(integer, x),
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
