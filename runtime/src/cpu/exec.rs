//! The CPU backend: runs a plan's stages with rayon over fixed-size chunks
//! (fixed, not per thread, so results do not depend on the thread count).
//! Inside a stage each chunk runs the ops in plan order; values that the stage
//! does not materialise live only as chunk-sized columns.

use super::kernels::{self, Element, ScanTotal};
use crate::column::{Column, ColumnView};
use crate::compile::ir::*;
use crate::functor::{CallContext, FunctorLibrary};
use crate::host::Uniforms;
use crate::interpret::{
    elementwise_materialised, error, interpret, is_sink, Backend, OpHostValues, Slots, StageCall,
};
use crate::types::ElemType;
use std::any::Any;
use std::ops::Range;
use std::sync::Arc;
use std::time::Duration;

pub struct RunContext<'a> {
    pub library: &'a FunctorLibrary,
    pub uniforms: &'a Uniforms,
    /// Scene data for the functors (see [`CallContext::resources`]).
    pub resources: &'a (dyn Any + Send + Sync),
    /// Elements per chunk; [`kernels::DEFAULT_CHUNK`] unless a test wants smaller.
    pub chunk: usize,
}

pub use crate::interpret::{
    OutputValue, RunError, RunResult, StageTiming, MAX_ELEMENTS, MAX_WHILE_ITERATIONS,
};

/// Runs `plan` on the CPU.
pub fn run_plan(plan: &Plan, context: &RunContext<'_>) -> Result<RunResult, RunError> {
    let mut backend = CpuBackend { context };
    interpret(
        plan,
        &mut backend,
        context.uniforms,
        &context.library.records,
    )
}

struct CpuBackend<'a> {
    context: &'a RunContext<'a>,
}

impl Backend for CpuBackend<'_> {
    type Array = Arc<Column>;

    fn len(array: &Arc<Column>) -> usize {
        array.len()
    }

    fn field(&self, array: &Arc<Column>, index: usize) -> Option<Arc<Column>> {
        array.field(index)
    }

    fn run_stage(
        &mut self,
        call: &StageCall<'_>,
        slots: &mut Slots<Arc<Column>>,
    ) -> Result<Option<Duration>, RunError> {
        StageRun {
            call,
            context: self.context,
            slots,
        }
        .run()?;
        Ok(None)
    }

    fn to_column(&mut self, array: &Arc<Column>) -> Result<Arc<Column>, RunError> {
        Ok(array.clone())
    }
}

/// A value inside a running stage: a chunk-sized column, or a whole array to
/// be read at the chunk's own range.
#[derive(Clone)]
enum ChunkValue {
    Chunk(Arc<Column>),
    Whole(Arc<Column>),
}

impl ChunkValue {
    fn view(&self, range: &Range<usize>) -> ColumnView<'_> {
        match self {
            ChunkValue::Chunk(c) => c.view(),
            ChunkValue::Whole(c) => c.slice(range.clone()),
        }
    }
}

/// What one chunk hands back to the stage.
struct ChunkResult {
    range: Range<usize>,
    /// One column per [`chunk_materialised`] variable.
    materialised: Vec<Arc<Column>>,
    sink: SinkPart,
}

enum SinkPart {
    None,
    Scatter {
        indices: ChunkValue,
        values: ChunkValue,
        mask: Option<ChunkValue>,
    },
    Reduce(Element),
    Scan {
        values: ChunkValue,
        flags: Option<ChunkValue>,
        total: ScanTotal,
    },
}

/// One stage running on the CPU.
struct StageRun<'s, 'a> {
    call: &'s StageCall<'s>,
    context: &'a RunContext<'a>,
    slots: &'s mut Slots<Arc<Column>>,
}

impl StageRun<'_, '_> {
    fn array(&self, var: VarId) -> Result<&Arc<Column>, RunError> {
        self.slots.array(self.call.plan, var)
    }

    fn elem_type(&self, var: VarId) -> ElemType {
        self.call.elem_type(var)
    }

    fn run(&mut self) -> Result<(), RunError> {
        let stage = self.call.stage;
        let head = &stage.ops[0];
        let host_values = &self.call.host_values;
        let len = self.call.len;
        let k = host_values[0].group;
        // Chunks hold whole groups of a fan-out so each source element is in one chunk.
        let chunk = match head.kind {
            OpKind::Expand { .. } => (self.context.chunk / k).max(1) * k,
            OpKind::GroupGather { .. } => (self.context.chunk / k).max(1),
            _ => self.context.chunk,
        };

        let results = kernels::run_chunked(len, chunk, |range| {
            self.run_chunk(stage, host_values, range)
        })
        .into_iter()
        .collect::<Result<Vec<_>, RunError>>()?;

        // Materialised values: the chunks joined in order, variables in parallel.
        let call = self.call;
        let records = &self.context.library.records;
        let variables = elementwise_materialised(stage);
        let joined: Vec<Column> = {
            use rayon::prelude::*;
            variables
                .par_iter()
                .enumerate()
                .map(|(position, var)| {
                    let parts: Vec<ColumnView<'_>> = results
                        .iter()
                        .map(|r| r.materialised[position].view())
                        .collect();
                    Column::concat_views(call.elem_type(*var), &parts, records)
                })
                .collect()
        };
        for (var, column) in variables.into_iter().zip(joined) {
            self.slots.set_array(var, Arc::new(column));
        }
        if let Some(op) = stage.ops.last().filter(|op| is_sink(op)) {
            let sink_values = &host_values[stage.ops.len() - 1];
            self.finish_sink(op, sink_values, results)?;
        }
        Ok(())
    }

    fn finish_sink(
        &mut self,
        op: &Op,
        values: &OpHostValues,
        results: Vec<ChunkResult>,
    ) -> Result<(), RunError> {
        let records = &self.context.library.records;
        let kernel_error = |e: kernels::KernelError| error(e.to_string());
        match &op.kind {
            OpKind::Scatter {
                target, combine, ..
            } => {
                let ty = self.elem_type(op.outputs[0]);
                let mut dst = match target {
                    ScatterTarget::Len(_) => {
                        Column::zeroed(ty, values.scatter_len.unwrap_or_default(), records)
                    }
                    ScatterTarget::Into(dst) => Arc::unwrap_or_clone(self.array(*dst)?.clone()),
                };
                for result in &results {
                    let SinkPart::Scatter {
                        indices,
                        values,
                        mask,
                    } = &result.sink
                    else {
                        unreachable!()
                    };
                    let range = result.range.clone();
                    let indices = indices.view(&range);
                    let values = values.view(&range);
                    let mask = mask.as_ref().map(|m| m.view(&range));
                    let mask = mask.as_ref().map(|m| m.as_bool());
                    match combine {
                        Some(op) => {
                            kernels::scatter_combine(*op, indices.as_u32(), &values, mask, &mut dst)
                        }
                        None => kernels::scatter(indices.as_u32(), &values, mask, &mut dst),
                    }
                    .map_err(kernel_error)?;
                }
                self.slots.set_array(op.outputs[0], Arc::new(dst));
            }
            OpKind::Reduce { op: monoid } => {
                let partials: Vec<Element> = results
                    .iter()
                    .map(|r| match r.sink {
                        SinkPart::Reduce(e) => e,
                        _ => unreachable!(),
                    })
                    .collect();
                let ty = self.elem_type(op.inputs[0]);
                let value =
                    kernels::reduce_to_host(*monoid, ty, &partials).map_err(kernel_error)?;
                self.slots.set_host(op.outputs[0], value);
            }
            OpKind::Scan {
                op: monoid,
                exclusive,
                ..
            } => {
                let ty = self.elem_type(op.inputs[0]);
                let totals: Vec<ScanTotal> = results
                    .iter()
                    .map(|r| match &r.sink {
                        SinkPart::Scan { total, .. } => *total,
                        _ => unreachable!(),
                    })
                    .collect();
                let carries = kernels::scan_carries(*monoid, ty, &totals).map_err(kernel_error)?;
                use rayon::prelude::*;
                let parts = results
                    .par_iter()
                    .zip(carries)
                    .map(|(result, carry)| {
                        let SinkPart::Scan { values, flags, .. } = &result.sink else {
                            unreachable!()
                        };
                        let range = result.range.clone();
                        let flags = flags.as_ref().map(|f| f.view(&range));
                        kernels::scan_chunk(
                            *monoid,
                            &values.view(&range),
                            !exclusive,
                            carry,
                            flags.as_ref().map(|f| f.as_bool()),
                        )
                    })
                    .collect::<Result<Vec<Column>, _>>()
                    .map_err(kernel_error)?;
                self.slots
                    .set_array(op.outputs[0], Arc::new(Column::concat(ty, &parts, records)));
            }
            _ => unreachable!("only scatter, reduce and scan are sinks"),
        }
        Ok(())
    }

    /// Runs every op of `stage` over one chunk of its index space.
    fn run_chunk(
        &self,
        stage: &Stage,
        host_values: &[OpHostValues],
        range: Range<usize>,
    ) -> Result<ChunkResult, RunError> {
        let records = &self.context.library.records;
        let mut locals: Vec<(VarId, ChunkValue)> = Vec::new();
        // A value written earlier in the stage shadows the array of the same slot.
        let lookup =
            |locals: &Vec<(VarId, ChunkValue)>, var: VarId| -> Result<ChunkValue, RunError> {
                match locals.iter().rev().find(|(v, _)| *v == var) {
                    Some((_, value)) => Ok(value.clone()),
                    None => Ok(ChunkValue::Whole(self.array(var)?.clone())),
                }
            };
        let mut sink = SinkPart::None;
        for (op, values) in stage.ops.iter().zip(host_values) {
            let functor_context = |first_index: usize| CallContext {
                named: &values.named,
                uniforms: self.context.uniforms,
                resources: self.context.resources,
                first_index,
                group: values.group,
                records,
            };
            let new_outputs = |len: usize| -> Vec<Column> {
                op.outputs
                    .iter()
                    .map(|o| Column::with_capacity(self.elem_type(*o), len, records))
                    .collect()
            };
            let mut produced: Vec<Column> = Vec::new();
            match &op.kind {
                OpKind::Iota { .. } => produced.push(Column::U32(
                    (range.start as u32..range.end as u32).collect(),
                )),
                OpKind::Fill { .. } => produced.push(
                    Column::filled(values.fill.expect("fill value"), range.len()).map_err(error)?,
                ),
                OpKind::Field { field } => {
                    let src = lookup(&locals, op.inputs[0])?;
                    let (ChunkValue::Chunk(column) | ChunkValue::Whole(column)) = &src;
                    let Column::Record { ty, .. } = column.as_ref() else {
                        return Err(error("field of a non-record array"));
                    };
                    let index = records
                        .get(*ty)
                        .field_index(field)
                        .expect("type-checked field");
                    let field_column = column.field(index).expect("record field");
                    let value = match src {
                        ChunkValue::Chunk(_) => ChunkValue::Chunk(field_column),
                        ChunkValue::Whole(_) => ChunkValue::Whole(field_column),
                    };
                    locals.push((op.outputs[0], value));
                    continue;
                }
                OpKind::Map => {
                    let inputs: Vec<ChunkValue> = op
                        .inputs
                        .iter()
                        .map(|v| lookup(&locals, *v))
                        .collect::<Result<_, _>>()?;
                    let views: Vec<ColumnView> = inputs.iter().map(|c| c.view(&range)).collect();
                    let functor = self.functor(op)?;
                    let mut outputs = new_outputs(range.len());
                    functor
                        .run_cpu(&functor_context(range.start), &views, &mut outputs)
                        .map_err(|e| error(e.0))?;
                    produced = outputs;
                }
                OpKind::Gather => {
                    let indices = lookup(&locals, op.inputs[0])?;
                    let src = self.array(op.inputs[1])?;
                    let gathered = kernels::gather(indices.view(&range).as_u32(), &src.view())
                        .map_err(|e| error(e.to_string()))?;
                    produced.push(gathered);
                }
                OpKind::GroupGather { .. } | OpKind::Expand { .. } => {
                    let k = values.group;
                    let source_range = match op.kind {
                        OpKind::GroupGather { .. } => range.start * k..range.end * k,
                        _ => range.start / k..range.end / k,
                    };
                    let src = self.array(op.inputs[0])?;
                    let functor = self.functor(op)?;
                    let mut outputs = new_outputs(range.len());
                    functor
                        .run_cpu(
                            &functor_context(source_range.start),
                            &[src.slice(source_range)],
                            &mut outputs,
                        )
                        .map_err(|e| error(e.0))?;
                    produced = outputs;
                }
                OpKind::Scatter { mask, .. } => {
                    sink = SinkPart::Scatter {
                        indices: lookup(&locals, op.inputs[0])?,
                        values: lookup(&locals, op.inputs[1])?,
                        mask: mask.map(|m| lookup(&locals, m)).transpose()?,
                    };
                }
                OpKind::Reduce { op: monoid } => {
                    let input = lookup(&locals, op.inputs[0])?;
                    let partial = kernels::reduce_partial(*monoid, &input.view(&range))
                        .map_err(|e| error(e.to_string()))?;
                    sink = SinkPart::Reduce(partial);
                }
                OpKind::Scan {
                    op: monoid,
                    segments,
                    ..
                } => {
                    let input = lookup(&locals, op.inputs[0])?;
                    let flags = segments.map(|f| lookup(&locals, f)).transpose()?;
                    let flag_view = flags.as_ref().map(|f| f.view(&range));
                    let total = kernels::scan_total(
                        *monoid,
                        &input.view(&range),
                        flag_view.as_ref().map(|f| f.as_bool()),
                    )
                    .map_err(|e| error(e.to_string()))?;
                    sink = SinkPart::Scan {
                        values: input,
                        flags,
                        total,
                    };
                }
            }
            for (output, column) in op.outputs.iter().zip(produced) {
                if column.elem_type() != self.elem_type(*output) {
                    return Err(error(format!(
                        "`{}` produced {} elements where its signature says {} (a functor bug)",
                        op.label(),
                        column.elem_type().name(records),
                        self.elem_type(*output).name(records)
                    )));
                }
                if column.len() != range.len() {
                    return Err(error(format!(
                        "`{}` produced {} elements for a chunk of {} (a functor bug)",
                        op.label(),
                        column.len(),
                        range.len()
                    )));
                }
                locals.push((*output, ChunkValue::Chunk(Arc::new(column))));
            }
        }
        let mut materialised = Vec::new();
        for var in elementwise_materialised(stage) {
            let value = lookup(&locals, var)?;
            materialised.push(match value {
                ChunkValue::Chunk(c) => c,
                ChunkValue::Whole(c) => Arc::new(c.slice(range.clone()).to_column()),
            });
        }
        Ok(ChunkResult {
            range,
            materialised,
            sink,
        })
    }

    fn functor(&self, op: &Op) -> Result<&Arc<dyn crate::functor::Functor>, RunError> {
        let name = op.functor.as_deref().unwrap_or_default();
        self.context
            .library
            .get(name)
            .ok_or_else(|| error(format!("functor `{name}` is not in this run's library")))
    }
}
