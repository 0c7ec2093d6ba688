//! Compiled element-wise runs: the CPU's counterpart of the GPU's one
//! shader per stage.
//!
//! Column at a time, every op of a fused stage reads and writes a
//! chunk-sized column, which costs 1–4 ns per element per op whatever the
//! op computes: for a stage of fifty element-wise ops (the shading of
//! `pipelines/workload2_expressions.dpp`) that is most of its time. Here a
//! run of consecutive ops that are generic element-wise functors, fills,
//! iotas, field reads and gathers (a [`Segment`]) becomes one loop of
//! machine code (Cranelift) that computes them all per element in registers
//! and writes only the values read after the run. Ops that are not compiled
//! (the tracer's functors, sinks) run as before between segments; the
//! stage's op order is unchanged.
//!
//! Kernels are cached by the segment's shape (ops, types, and the values
//! that are constants in the code), so a plan's frames compile each segment
//! once per process; fill values are passed in, not compiled in.

mod codegen;
mod skipped_sides;

use crate::column::{Column, ColumnView};
use crate::compile::ir::{Op, OpKind, VarId};
use crate::host::HostValue;
use crate::interpret::{OpHostValues, StageCall};
use crate::types::{ElemType, RecordRegistry};
use codegen::{leaf_types, KernelEntry};
use std::collections::HashMap;
use std::ops::Range;
use std::sync::{Arc, Mutex, OnceLock};

/// How the CPU backend runs a fused stage's element-wise ops.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Elementwise {
    /// Runs of them compiled into one loop each (this module).
    #[default]
    Compiled,
    /// Each op over a whole chunk column, one after the other.
    Columns,
}

/// Consecutive ops of a stage compiled into one kernel.
pub(crate) struct Segment {
    /// The ops it replaces, by position in the stage.
    pub(crate) ops: Range<usize>,
    /// Arrays defined before the segment, read at the chunk's positions.
    elementwise: Vec<(VarId, ElemType)>,
    /// Whole arrays read through an index.
    gathered: Vec<(VarId, ElemType)>,
    /// Values of the segment read after it (or stored by the stage).
    pub(crate) outputs: Vec<(VarId, ElemType)>,
    /// The element type of each fill, in order: its value is a parameter.
    fills: Vec<ElemType>,
    steps: Vec<SegmentStep>,
}

enum SegmentStep {
    Iota {
        output: VarId,
    },
    Fill {
        fill: usize,
        output: VarId,
    },
    Field {
        record: u32,
        field: usize,
        output: VarId,
    },
    Gather {
        index: u32,
        gathered: usize,
        output: VarId,
    },
    Map {
        functor: String,
        inputs: Vec<(u32, ElemType)>,
        output_type: ElemType,
        named: Vec<HostValue>,
        output: VarId,
    },
}

impl SegmentStep {
    fn output(&self) -> VarId {
        match self {
            SegmentStep::Iota { output }
            | SegmentStep::Fill { output, .. }
            | SegmentStep::Field { output, .. }
            | SegmentStep::Gather { output, .. }
            | SegmentStep::Map { output, .. } => *output,
        }
    }

    /// The segment's values it reads (not the gathered arrays).
    fn reads(&self) -> Vec<u32> {
        match self {
            SegmentStep::Map { inputs, .. } => inputs.iter().map(|(v, _)| *v).collect(),
            SegmentStep::Gather { index, .. } => vec![*index],
            SegmentStep::Field { record, .. } => vec![*record],
            SegmentStep::Iota { .. } | SegmentStep::Fill { .. } => Vec::new(),
        }
    }
}

/// A segment with its kernel and the values of its fills for this run of the stage.
pub(crate) struct PreparedSegment {
    pub(crate) segment: Arc<Segment>,
    kernel: KernelEntry,
    params: Vec<[u32; 4]>,
}

/// The compiled segments of `call`'s stage, by first op (at most one per op).
pub(crate) fn prepare(call: &StageCall<'_>) -> Vec<Option<PreparedSegment>> {
    let stage = call.stage;
    let mut prepared: Vec<Option<PreparedSegment>> = stage.ops.iter().map(|_| None).collect();
    for range in candidate_runs(call) {
        let Some(segment) = build_segment(call, range.clone()) else {
            continue;
        };
        let Some(kernel) = cached_kernel(&segment, call.records) else {
            continue;
        };
        let params = range
            .clone()
            .filter(|&i| matches!(stage.ops[i].kind, OpKind::Fill { .. }))
            .map(|i| fill_param(&call.host_values[i]))
            .collect::<Option<Vec<_>>>();
        let Some(params) = params else { continue };
        prepared[range.start] = Some(PreparedSegment {
            segment,
            kernel,
            params,
        });
    }
    prepared
}

/// The maximal runs of compilable ops with at least two that compute or
/// fill (a fill alone is a column written and read; in a loop, a register).
fn candidate_runs(call: &StageCall<'_>) -> Vec<Range<usize>> {
    let ops = &call.stage.ops;
    let mut runs = Vec::new();
    let mut start = 0;
    for end in 0..=ops.len() {
        if end < ops.len() && compiles(call, &ops[end], end) {
            continue;
        }
        let computing = ops[start..end]
            .iter()
            .filter(|op| matches!(op.kind, OpKind::Map | OpKind::Gather | OpKind::Fill { .. }))
            .count();
        if computing >= 2 {
            runs.push(start..end);
        }
        start = end + 1;
    }
    runs
}

fn compiles(call: &StageCall<'_>, op: &Op, position: usize) -> bool {
    let primitive = |var: VarId| !matches!(call.elem_type(var), ElemType::Record(_));
    let all_primitive = |ty: ElemType| match ty {
        ElemType::Record(id) => call
            .records
            .get(id)
            .fields
            .iter()
            .all(|(_, t)| !matches!(t, ElemType::Record(_))),
        _ => true,
    };
    match &op.kind {
        OpKind::Iota { .. } => true,
        OpKind::Fill { .. } => {
            primitive(op.outputs[0]) && fill_param(&call.host_values[position]).is_some()
        }
        OpKind::Field { .. } => {
            primitive(op.outputs[0]) && all_primitive(call.elem_type(op.inputs[0]))
        }
        OpKind::Gather => {
            call.elem_type(op.inputs[0]) == ElemType::U32
                && all_primitive(call.elem_type(op.inputs[1]))
        }
        OpKind::Map => {
            let types: Vec<ElemType> = op.inputs.iter().map(|v| call.elem_type(*v)).collect();
            op.outputs.len() == 1
                && primitive(op.outputs[0])
                && op
                    .functor
                    .as_deref()
                    .is_some_and(|name| codegen::supports(name, &types))
        }
        _ => false,
    }
}

/// A fill's value as the kernel reads it: its element's bytes, in 16.
fn fill_param(values: &OpHostValues) -> Option<[u32; 4]> {
    let column = Column::filled(values.fill?, 1).ok()?;
    let mut param = [0u32; 4];
    match column.view() {
        ColumnView::Bool(v) => param[0] = u32::from(v[0]),
        ColumnView::U32(v) => param[0] = v[0],
        ColumnView::I32(v) => param[0] = v[0] as u32,
        ColumnView::F32(v) => param[0] = v[0].to_bits(),
        ColumnView::Vec2(v) => copy_floats(&mut param, &v[0].to_array()),
        ColumnView::Vec3(v) => copy_floats(&mut param, &v[0].to_array()),
        ColumnView::Vec4(v) => copy_floats(&mut param, &v[0].to_array()),
        ColumnView::Record { .. } => return None,
    }
    Some(param)
}

fn copy_floats(param: &mut [u32; 4], floats: &[f32]) {
    for (slot, f) in param.iter_mut().zip(floats) {
        *slot = f.to_bits();
    }
}

/// The segment of `range`'s ops, or `None` where it cannot be one (a gather
/// from an array the segment itself makes, a fill whose value's type is not
/// its output's).
fn build_segment(call: &StageCall<'_>, range: Range<usize>) -> Option<Arc<Segment>> {
    let stage = call.stage;
    let mut defined: Vec<VarId> = Vec::new();
    let mut elementwise: Vec<(VarId, ElemType)> = Vec::new();
    let mut gathered: Vec<(VarId, ElemType)> = Vec::new();
    let mut fills = Vec::new();
    let mut steps = Vec::new();
    let mut read = |var: VarId, defined: &Vec<VarId>| {
        if !defined.contains(&var) && !elementwise.iter().any(|(v, _)| *v == var) {
            elementwise.push((var, call.elem_type(var)));
        }
        var.0
    };
    for position in range.clone() {
        let op = &stage.ops[position];
        let output = op.outputs[0];
        let step = match &op.kind {
            OpKind::Iota { .. } => SegmentStep::Iota { output },
            OpKind::Fill { .. } => {
                let value = call.host_values[position].fill?;
                let filled_type = Column::filled(value, 0).ok()?.elem_type();
                if filled_type != call.elem_type(output) {
                    return None;
                }
                fills.push(filled_type);
                SegmentStep::Fill {
                    fill: fills.len() - 1,
                    output,
                }
            }
            OpKind::Field { field } => {
                let ElemType::Record(id) = call.elem_type(op.inputs[0]) else {
                    return None;
                };
                SegmentStep::Field {
                    record: read(op.inputs[0], &defined),
                    field: call.records.get(id).field_index(field)?,
                    output,
                }
            }
            OpKind::Gather => {
                let source = op.inputs[1];
                if defined.contains(&source) {
                    return None;
                }
                let index = read(op.inputs[0], &defined);
                let gathered_at = match gathered.iter().position(|(v, _)| *v == source) {
                    Some(k) => k,
                    None => {
                        gathered.push((source, call.elem_type(source)));
                        gathered.len() - 1
                    }
                };
                SegmentStep::Gather {
                    index,
                    gathered: gathered_at,
                    output,
                }
            }
            OpKind::Map => SegmentStep::Map {
                functor: op.functor.clone()?,
                inputs: op
                    .inputs
                    .iter()
                    .map(|v| (read(*v, &defined), call.elem_type(*v)))
                    .collect(),
                output_type: call.elem_type(output),
                named: call.host_values[position].named.clone(),
                output,
            },
            _ => return None,
        };
        steps.push(step);
        defined.push(output);
    }
    let materialised = crate::interpret::elementwise_materialised(stage);
    let read_later = |var: VarId| {
        materialised.contains(&var)
            || stage.ops[range.end..]
                .iter()
                .any(|op| op.array_reads().contains(&var))
    };
    let outputs = defined
        .iter()
        .filter(|v| read_later(**v))
        .map(|v| (*v, call.elem_type(*v)))
        .collect();
    Some(Arc::new(Segment {
        ops: range,
        elementwise,
        gathered,
        outputs,
        fills,
        steps,
    }))
}

/// The segment's kernel, compiled once per process for each shape.
fn cached_kernel(segment: &Segment, records: &RecordRegistry) -> Option<KernelEntry> {
    static KERNELS: OnceLock<Mutex<HashMap<String, Option<KernelEntry>>>> = OnceLock::new();
    let key = shape_key(segment, records);
    let mut kernels = KERNELS
        .get_or_init(Mutex::default)
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    *kernels
        .entry(key)
        .or_insert_with(|| codegen::compile(segment, records).ok())
}

/// What the machine code depends on, with the plan's variable numbers
/// replaced by their order of appearance (so equal segments of different
/// plans share a kernel) and record types by their fields.
fn shape_key(segment: &Segment, records: &RecordRegistry) -> String {
    let mut numbers: HashMap<u32, usize> = HashMap::new();
    let mut number = |var: u32| {
        let next = numbers.len();
        *numbers.entry(var).or_insert(next)
    };
    let spell = |ty: ElemType| format!("{:?}", leaf_types(ty, records));
    let mut key = String::new();
    for (var, ty) in &segment.elementwise {
        key += &format!("in{}:{};", number(var.0), spell(*ty));
    }
    for (_, ty) in &segment.gathered {
        key += &format!("gathered:{};", spell(*ty));
    }
    for ty in &segment.fills {
        key += &format!("fill:{ty:?};");
    }
    for step in &segment.steps {
        key += &match step {
            SegmentStep::Iota { output } => format!("{}=iota;", number(output.0)),
            SegmentStep::Fill { fill, output } => format!("{}=fill{fill};", number(output.0)),
            SegmentStep::Field {
                record,
                field,
                output,
            } => {
                let record = number(*record);
                format!("{}={record}.{field};", number(output.0))
            }
            SegmentStep::Gather {
                index,
                gathered,
                output,
            } => {
                let index = number(*index);
                format!("{}=gather({index},{gathered});", number(output.0))
            }
            SegmentStep::Map {
                functor,
                inputs,
                output_type,
                named,
                output,
            } => {
                let inputs: Vec<String> = inputs
                    .iter()
                    .map(|(v, ty)| format!("{}:{ty:?}", number(*v)))
                    .collect();
                format!(
                    "{}={functor}({}){output_type:?}{named:?};",
                    number(output.0),
                    inputs.join(",")
                )
            }
        };
    }
    for (var, ty) in &segment.outputs {
        key += &format!("out{}:{};", number(var.0), spell(*ty));
    }
    key
}

impl PreparedSegment {
    /// Runs the kernel over one chunk: `elementwise` are the chunk's views of
    /// the element-wise inputs (in the segment's order), `gathered` the whole
    /// gathered arrays. `None` where an element fails (the caller then runs
    /// the ops one by one, which report the failure) or the inputs do not
    /// have the chunk's length.
    pub(crate) fn run(
        &self,
        elementwise: &[ColumnView<'_>],
        gathered: &[ColumnView<'_>],
        first_index: usize,
        len: usize,
        records: &RecordRegistry,
    ) -> Option<Vec<Column>> {
        let segment = &self.segment;
        let mut input_pointers: Vec<*const u8> = Vec::new();
        for view in elementwise {
            if view.len() != len {
                return None;
            }
            leaf_pointers(view, &mut input_pointers);
        }
        let mut lengths: Vec<u64> = Vec::new();
        for view in gathered {
            leaf_pointers(view, &mut input_pointers);
            lengths.push(view.len() as u64);
        }
        let mut outputs: Vec<Column> = segment
            .outputs
            .iter()
            .map(|(_, ty)| Column::zeroed(*ty, len, records))
            .collect();
        let mut output_pointers: Vec<*mut u8> = Vec::new();
        for column in &mut outputs {
            leaf_pointers_mut(column, &mut output_pointers)?;
        }
        // SAFETY: every element-wise leaf holds `len` elements and every
        // output leaf was just made with `len`; gathered reads are checked
        // against `lengths` inside the kernel; the pointers' element types
        // are the segment's, which the kernel was compiled for.
        let status = unsafe {
            (self.kernel)(
                input_pointers.as_ptr(),
                lengths.as_ptr(),
                output_pointers.as_ptr(),
                self.params.as_ptr().cast(),
                len as u64,
                first_index as u64,
            )
        };
        (status == 0).then_some(outputs)
    }
}

impl Segment {
    pub(crate) fn elementwise_inputs(&self) -> impl Iterator<Item = VarId> + '_ {
        self.elementwise.iter().map(|(v, _)| *v)
    }

    pub(crate) fn gathered_inputs(&self) -> impl Iterator<Item = VarId> + '_ {
        self.gathered.iter().map(|(v, _)| *v)
    }
}

fn leaf_pointers(view: &ColumnView<'_>, out: &mut Vec<*const u8>) {
    crate::for_each_primitive!(ColumnView, view, v => out.push(v.as_ptr().cast()),
        ColumnView::Record { fields, .. } => fields.iter().for_each(|f| leaf_pointers(f, out)))
}

/// `None` if a record's field is shared (never, for a column just made).
fn leaf_pointers_mut(column: &mut Column, out: &mut Vec<*mut u8>) -> Option<()> {
    crate::for_each_primitive!(Column, column, v => out.push(v.as_mut_ptr().cast()),
    Column::Record { fields, .. } => {
        for field in fields {
            leaf_pointers_mut(Arc::get_mut(field)?, out)?;
        }
    });
    Some(())
}
