//! The CPU backend: runs a plan's stages with rayon over fixed-size chunks
//! (fixed, not per thread, so results do not depend on the thread count).
//! Inside a stage each chunk runs the ops in plan order; values that the stage
//! does not materialise live only as chunk-sized columns.

use super::kernels::{self, Element, ScanTotal};
use crate::column::{Column, ColumnView};
use crate::compile::ir::*;
use crate::functor::{CallContext, FunctorLibrary};
use crate::host::{HostValue, Uniforms};
use crate::host_eval::{eval_host, HostEnvironment};
use crate::types::ElemType;
use std::any::Any;
use std::ops::Range;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Longest array a stage may make: keeps `u32` indices valid and memory sane.
pub const MAX_ELEMENTS: usize = 1 << 31;
/// A `while` loop that runs this often is taken to be stuck.
pub const MAX_WHILE_ITERATIONS: u64 = 10_000_000;

pub struct RunContext<'a> {
    pub library: &'a FunctorLibrary,
    pub uniforms: &'a Uniforms,
    /// Scene data for the functors (see [`CallContext::resources`]).
    pub resources: &'a (dyn Any + Send + Sync),
    /// Elements per chunk; [`kernels::DEFAULT_CHUNK`] unless a test wants smaller.
    pub chunk: usize,
}

#[derive(Clone, Debug, PartialEq)]
pub enum OutputValue {
    Array(Arc<Column>),
    Host(HostValue),
}

/// Time spent in one stage of the plan over the whole run.
#[derive(Clone, Debug)]
pub struct StageTiming {
    /// 1-based, as numbered by `dpp plan`.
    pub stage: usize,
    pub label: String,
    pub runs: u32,
    pub elements: u64,
    pub time: Duration,
}

#[derive(Clone, Debug)]
pub struct RunResult {
    /// In the order of the pipeline's `out` declarations.
    pub outputs: Vec<(String, OutputValue)>,
    pub profile: Vec<StageTiming>,
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{message}")]
pub struct RunError {
    pub message: String,
}

fn error(message: impl Into<String>) -> RunError {
    RunError {
        message: message.into(),
    }
}

pub fn run_plan(plan: &Plan, context: &RunContext<'_>) -> Result<RunResult, RunError> {
    let stages = plan.stages();
    let mut executor = Executor {
        plan,
        context,
        arrays: vec![None; plan.vars.len()],
        hosts: vec![None; plan.vars.len()],
        outputs: Vec::new(),
        profile: stages
            .iter()
            .enumerate()
            .map(|(i, s)| StageTiming {
                stage: i + 1,
                label: s.label(),
                runs: 0,
                elements: 0,
                time: Duration::ZERO,
            })
            .collect(),
        stages,
    };
    executor.nodes(&plan.body)?;
    let mut outputs = Vec::new();
    for name in &plan.outputs {
        match executor.outputs.iter().rev().find(|(n, _)| n == name) {
            Some(found) => outputs.push(found.clone()),
            None => {
                return Err(error(format!(
                    "output `{name}` was never written (its `out` did not run)"
                )))
            }
        }
    }
    Ok(RunResult {
        outputs,
        profile: executor.profile,
    })
}

enum Flow {
    Continue,
    Break,
}

struct Executor<'a> {
    plan: &'a Plan,
    context: &'a RunContext<'a>,
    arrays: Vec<Option<Arc<Column>>>,
    hosts: Vec<Option<HostValue>>,
    outputs: Vec<(String, OutputValue)>,
    profile: Vec<StageTiming>,
    stages: Vec<&'a Stage>,
}

impl HostEnvironment for Executor<'_> {
    fn host_var(&self, var: VarId) -> Option<HostValue> {
        self.hosts[var.0 as usize]
    }
    fn array_len(&self, var: VarId) -> Option<usize> {
        self.arrays[var.0 as usize].as_ref().map(|a| a.len())
    }
    fn uniforms(&self) -> &Uniforms {
        self.context.uniforms
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

/// Host values an op needs, evaluated once when its stage starts.
struct OpHostValues {
    named: Vec<HostValue>,
    /// `k` of a group gather or fan-out.
    group: usize,
    /// `fill`'s value.
    fill: Option<HostValue>,
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

impl<'a> Executor<'a> {
    fn eval(&self, expr: &HostExpr) -> Result<HostValue, RunError> {
        eval_host(expr, self).map_err(error)
    }

    fn eval_count(&self, expr: &HostExpr, what: &str) -> Result<usize, RunError> {
        let value = self.eval(expr)?;
        match value.as_int() {
            Some(n) if n >= 0 && (n as u64) <= MAX_ELEMENTS as u64 => Ok(n as usize),
            Some(n) if n < 0 => Err(error(format!("{what} is negative ({n})"))),
            Some(n) => Err(error(format!(
                "{what} is {n}, above the limit of {MAX_ELEMENTS} elements"
            ))),
            None => Err(error(format!("{what} must be an integer, found {value}"))),
        }
    }

    fn array(&self, var: VarId) -> Result<&Arc<Column>, RunError> {
        self.arrays[var.0 as usize].as_ref().ok_or_else(|| {
            error(format!(
                "`{}` is read before it has a value",
                self.plan.var(var).name
            ))
        })
    }

    fn nodes(&mut self, nodes: &'a [Node]) -> Result<Flow, RunError> {
        for node in nodes {
            match node {
                Node::Stage(stage) => {
                    let number = self
                        .stages
                        .iter()
                        .position(|s| std::ptr::eq(*s, stage))
                        .expect("every stage is in the plan");
                    let start = Instant::now();
                    let elements = self.stage(stage).map_err(|e| {
                        error(format!(
                            "stage {} [{}]: {}",
                            number + 1,
                            self.profile[number].label,
                            e.message
                        ))
                    })?;
                    let timing = &mut self.profile[number];
                    timing.runs += 1;
                    timing.elements += elements as u64;
                    timing.time += start.elapsed();
                }
                Node::Op(_) => unreachable!("plans hand backends stages, never bare ops"),
                Node::Host { dst, expr, .. } => {
                    let value = self.eval(expr)?;
                    self.hosts[dst.0 as usize] = Some(value);
                }
                Node::View { dst, src, field } => {
                    let column = self.array(*src)?;
                    let view = match column.as_ref() {
                        Column::Record { ty, .. } => self
                            .context
                            .library
                            .records
                            .get(*ty)
                            .field_index(field)
                            .and_then(|i| column.field(i)),
                        _ => None,
                    };
                    let view = view.ok_or_else(|| {
                        error(format!(
                            "`{}` has no field `{field}`",
                            self.plan.var(*src).name
                        ))
                    })?;
                    self.arrays[dst.0 as usize] = Some(view);
                }
                Node::Alias { dst, src } => {
                    let value = self.array(*src)?.clone();
                    self.arrays[dst.0 as usize] = Some(value);
                }
                Node::For {
                    var,
                    start,
                    end,
                    body,
                    ..
                } => {
                    let (start, end) = (self.eval(start)?, self.eval(end)?);
                    let (Some(start), Some(end)) = (start.as_int(), end.as_int()) else {
                        return Err(error("loop bounds must be integers"));
                    };
                    for i in start..end {
                        self.hosts[var.0 as usize] = Some(HostValue::Int(i));
                        if let Flow::Break = self.nodes(body)? {
                            break;
                        }
                    }
                }
                Node::While { cond, body, .. } => {
                    let mut iterations = 0u64;
                    while self.eval(cond)?.as_bool() == Some(true) {
                        iterations += 1;
                        if iterations > MAX_WHILE_ITERATIONS {
                            return Err(error(format!(
                                "a `while` loop ran {MAX_WHILE_ITERATIONS} times; stopping (is its condition ever false?)"
                            )));
                        }
                        if let Flow::Break = self.nodes(body)? {
                            break;
                        }
                    }
                }
                Node::If {
                    cond,
                    then_body,
                    else_body,
                    ..
                } => {
                    let branch = if self.eval(cond)?.as_bool() == Some(true) {
                        then_body
                    } else {
                        else_body
                    };
                    if let Flow::Break = self.nodes(branch)? {
                        return Ok(Flow::Break);
                    }
                }
                Node::Break => return Ok(Flow::Break),
                Node::Output { name, var } => {
                    let value = match self.plan.var(*var).ty {
                        VarType::Host(_) => OutputValue::Host(
                            self.hosts[var.0 as usize]
                                .ok_or_else(|| error(format!("output `{name}` has no value")))?,
                        ),
                        _ => OutputValue::Array(self.array(*var)?.clone()),
                    };
                    self.outputs.push((name.clone(), value));
                }
            }
        }
        Ok(Flow::Continue)
    }

    fn elem_type(&self, var: VarId) -> ElemType {
        match self.plan.var(var).ty {
            VarType::Array(t) => t,
            other => unreachable!("array variable of type {other:?} after type checking"),
        }
    }

    /// Runs one stage; returns the number of elements it ran over.
    fn stage(&mut self, stage: &'a Stage) -> Result<usize, RunError> {
        let head = &stage.ops[0];
        let mut host_values = Vec::with_capacity(stage.ops.len());
        for op in &stage.ops {
            let named = op
                .named
                .iter()
                .map(|(_, e)| self.eval(e))
                .collect::<Result<Vec<_>, _>>()?;
            let group = match &op.kind {
                OpKind::GroupGather { group: k } | OpKind::Expand { fanout: k } => {
                    let k = self.eval_count(k, "the group size")?;
                    if k == 0 {
                        return Err(error("a group or fan-out of 0 elements"));
                    }
                    k
                }
                _ => 1,
            };
            let fill = match &op.kind {
                OpKind::Fill { value, .. } => Some(self.eval(value)?),
                _ => None,
            };
            host_values.push(OpHostValues { named, group, fill });
        }

        // The head op decides how many elements the stage runs over.
        let k = host_values[0].group;
        let len = match &head.kind {
            OpKind::Iota { count } | OpKind::Fill { count, .. } => {
                self.eval_count(count, "the length")?
            }
            OpKind::GroupGather { .. } => {
                let src = self.array(head.inputs[0])?.len();
                if src % k != 0 {
                    return Err(error(format!("group gather of {src} elements in groups of {k}: {src} is not a multiple of {k}")));
                }
                src / k
            }
            OpKind::Expand { .. } => {
                let n = self
                    .array(head.inputs[0])?
                    .len()
                    .checked_mul(k)
                    .filter(|n| *n <= MAX_ELEMENTS);
                n.ok_or_else(|| {
                    error(format!(
                        "fan-out by {k} makes more than {MAX_ELEMENTS} elements"
                    ))
                })?
            }
            _ => self.array(head.inputs[0])?.len(),
        };
        for &v in &stage.reads_direct {
            let found = self.array(v)?.len();
            if found != len {
                return Err(error(format!(
                    "length mismatch: `{}` has {found} elements, but the stage runs over {len}",
                    self.plan.var(v).name
                )));
            }
        }
        // Chunks hold whole groups of a fan-out so each source element is in one chunk.
        let chunk = match head.kind {
            OpKind::Expand { .. } => (self.context.chunk / k).max(1) * k,
            OpKind::GroupGather { .. } => (self.context.chunk / k).max(1),
            _ => self.context.chunk,
        };

        let results = kernels::run_chunked(len, chunk, |range| {
            self.run_chunk(stage, &host_values, range)
        })
        .into_iter()
        .collect::<Result<Vec<_>, RunError>>()?;

        // Materialised values: the chunks joined in order.
        for (position, var) in chunk_materialised(stage).into_iter().enumerate() {
            let parts: Vec<Column> = results
                .iter()
                .map(|r| Arc::unwrap_or_clone(r.materialised[position].clone()))
                .collect();
            let column = Column::concat(self.elem_type(var), &parts, &self.context.library.records);
            self.arrays[var.0 as usize] = Some(Arc::new(column));
        }
        if let Some(op) = stage.ops.last().filter(|op| is_sink(op)) {
            self.finish_sink(op, results)?;
        }
        Ok(len)
    }

    fn finish_sink(&mut self, op: &Op, results: Vec<ChunkResult>) -> Result<(), RunError> {
        let records = &self.context.library.records;
        let kernel_error = |e: kernels::KernelError| error(e.to_string());
        match &op.kind {
            OpKind::Scatter {
                target, combine, ..
            } => {
                let ty = self.elem_type(op.outputs[0]);
                let mut dst = match target {
                    ScatterTarget::Len(len) => {
                        Column::zeroed(ty, self.eval_count(len, "the scatter length")?, records)
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
                self.arrays[op.outputs[0].0 as usize] = Some(Arc::new(dst));
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
                self.hosts[op.outputs[0].0 as usize] = Some(value);
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
                self.arrays[op.outputs[0].0 as usize] =
                    Some(Arc::new(Column::concat(ty, &parts, records)));
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
        for var in chunk_materialised(stage) {
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

fn is_sink(op: &Op) -> bool {
    matches!(
        op.kind,
        OpKind::Scatter { .. } | OpKind::Reduce { .. } | OpKind::Scan { .. }
    )
}

/// The variables each chunk hands back: everything the stage materialises but
/// a sink's result, which the sink assembles itself.
fn chunk_materialised(stage: &Stage) -> Vec<VarId> {
    let sink_output = stage
        .ops
        .last()
        .filter(|op| is_sink(op))
        .map(|op| op.outputs[0]);
    stage
        .materialises
        .iter()
        .copied()
        .filter(|v| Some(*v) != sink_output)
        .collect()
}
