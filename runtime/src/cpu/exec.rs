//! The CPU backend: runs a plan's stages with rayon over fixed-size chunks
//! (fixed, not per thread, so results do not depend on the thread count).
//! Inside a stage each chunk runs the ops in plan order; values that the stage
//! does not materialise live only as chunk-sized columns. Each chunk times
//! its ops, so a fused stage's profile still says where its time went.

use super::column_pool::{ColumnPool, Contents};
use super::compiled::{self, Elementwise, PreparedSegment};
use super::kernels::{self, ScanTotal};
use super::shared_scatter::{Claimed, Owners, ScatterClaims, SharedTarget};
use super::sort::SortedOrder;
use crate::column::{Column, ColumnView};
use crate::compile::ir::*;
use crate::elem::Element;
use crate::functor::{CallContext, FunctorLibrary};
use crate::host::Uniforms;
use crate::interpret::{
    elementwise_materialised, interpret_observed, Backend, OpHostValues, RunError, RunHooks,
    RunResult, Slots, StageCall, StageMeasurement,
};
use crate::types::ElemType;
use std::any::Any;
use std::ops::Range;
use std::sync::Arc;
use std::time::{Duration, Instant};

pub struct RunContext<'a> {
    pub library: &'a FunctorLibrary,
    pub uniforms: &'a Uniforms,
    /// Scene data for the functors (see [`CallContext::resources`]).
    pub resources: &'a (dyn Any + Send + Sync),
    /// Elements per chunk; [`kernels::DEFAULT_CHUNK`] unless a test wants smaller.
    pub chunk: usize,
    /// Where the run's large arrays come from and go back to; a caller that
    /// runs many frames keeps one pool for all of them.
    pub column_pool: &'a ColumnPool,
    /// Whether runs of element-wise ops are compiled into one loop each.
    pub elementwise: Elementwise,
}

/// Runs `plan` on the CPU.
pub fn run_plan(plan: &Plan, context: &RunContext<'_>) -> Result<RunResult, RunError> {
    run_plan_observed(plan, context, RunHooks::default())
}

/// [`run_plan`] with the run's hooks (a stage observer, the other ranks).
pub fn run_plan_observed(
    plan: &Plan,
    context: &RunContext<'_>,
    hooks: RunHooks<'_>,
) -> Result<RunResult, RunError> {
    let mut backend = CpuBackend { context };
    interpret_observed(
        plan,
        &mut backend,
        context.uniforms,
        &context.library.records,
        Vec::new(),
        hooks,
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
    ) -> Result<StageMeasurement, RunError> {
        let (op_thread_times, compiled) = StageRun {
            call,
            context: self.context,
            slots,
        }
        .run()?;
        Ok(StageMeasurement {
            device_time: None,
            op_thread_times,
            compiled,
        })
    }

    fn to_column(&mut self, array: &Arc<Column>) -> Result<Arc<Column>, RunError> {
        Ok(array.clone())
    }

    fn upload(&mut self, column: Arc<Column>) -> Result<Arc<Column>, RunError> {
        Ok(column)
    }

    fn release(&mut self, array: Arc<Column>) {
        self.context.column_pool.give(array);
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
    /// One part per sink of the stage, in stage order.
    sinks: Vec<SinkPart>,
    /// The chunk's claims, by claims group of [`DirectScatters`].
    claims: Vec<Option<Claimed>>,
    /// The time the chunk spent in each op of the stage.
    op_times: Vec<Duration>,
}

enum SinkPart {
    /// A plain scatter wrote its chunk into the shared target; where slots
    /// of its claims' `aside` positions are owned by other chunks, its indices
    /// and values are kept to write them after the stage.
    Written(Option<(ChunkValue, ChunkValue)>),
    /// A combining scatter: its chunk, to combine into the target in order.
    Scatter {
        indices: SinkInput,
        values: SinkInput,
        mask: Option<SinkInput>,
    },
    Reduce(Element),
    Scan {
        values: SinkInput,
        flags: Option<SinkInput>,
        total: ScanTotal,
    },
    /// A sort's keys and values: sorted, all chunks together, after the stage.
    Sort(Vec<SinkInput>),
}

/// What a sink that finishes after its stage keeps of one input: the value
/// as the chunk had it (an array made before the stage), or, for a value the
/// stage makes, the name of a stage-wide array the chunk copied its range
/// into. The chunk's own columns then go back to the allocator as the chunk
/// ends, and the next chunk's reuse them: kept to the end of the stage, each
/// chunk's could be fresh pages (in a process rendering the bunny alone,
/// WORKLOAD3's `map<shader>` took twice its time faulting in the colours
/// `scatter<add>` kept; docs/benchmarks.md, "A seventh day").
#[derive(Clone)]
enum SinkInput {
    Value(ChunkValue),
    Stored(VarId),
}

/// The stage-wide arrays its chunks copy their ranges of values into: the
/// values it materialises, and those its sinks keep ([`SinkInput`]).
#[derive(Clone, Copy)]
struct StageArrays<'t> {
    materialised: &'t [(VarId, SharedTarget)],
    kept: &'t [(VarId, SharedTarget)],
}

/// The targets of a stage's plain scatters, which its chunks write directly.
struct DirectScatters {
    /// By sink number: the claims group and the target of each plain scatter.
    targets: Vec<Option<(usize, SharedTarget)>>,
    /// Claims shared by the scatters with the same indices, mask and target length.
    groups: Vec<ScatterClaims>,
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

    /// Runs the stage; returns the time its chunks spent in each op, summed
    /// over the threads, and the runs of ops it ran compiled.
    fn run(&mut self) -> Result<(Vec<Duration>, Vec<Range<usize>>), RunError> {
        let stage = self.call.stage;
        let head = &stage.ops[0];
        let host_values = &self.call.host_values;
        let len = self.call.len;
        let k = host_values[0].group;
        // Chunks hold whole groups of a fan-out so each source element is in
        // one chunk; a nested stage's chunk holds a chunk of inner elements.
        let chunk = match (self.call.inner_level(), &head.kind) {
            (Some((_, group)), _) => (self.context.chunk / group).max(1),
            (None, OpKind::GroupGather { .. }) => (self.context.chunk / k).max(1),
            (None, OpKind::Expand { .. }) => (self.context.chunk / k).max(1) * k,
            (None, _) => self.context.chunk,
        };

        self.release_rebound_outputs();
        let mut direct = self.direct_scatters(stage, host_values)?;
        // Materialised values: each chunk copies its range into them, so no
        // chunk keeps its columns to the end of the stage and nothing is
        // joined after it. The same for the values sinks keep.
        let materialised = self.stage_wide_arrays(elementwise_materialised(stage));
        let kept = self.stage_wide_arrays(self.sink_kept_values(&materialised));
        let segments = match self.context.elementwise {
            Elementwise::Compiled => compiled::prepare(self.call),
            Elementwise::Columns => Vec::new(),
        };
        let stage_arrays = StageArrays {
            materialised: &materialised,
            kept: &kept,
        };
        let results = kernels::run_chunked(len, chunk, |range| {
            self.run_chunk(stage, host_values, &segments, &direct, &stage_arrays, range)
        })
        .into_iter()
        .collect::<Result<Vec<_>, RunError>>()?;
        // One entry per op, and one for storing the materialised values.
        let timed = stage.ops.len() + usize::from(!materialised.is_empty());
        let mut op_times = vec![Duration::ZERO; timed];
        for result in &results {
            for (total, time) in op_times.iter_mut().zip(&result.op_times) {
                *total += *time;
            }
        }

        for (var, target) in materialised {
            self.store(var, target.into_column());
        }
        let kept: Vec<(VarId, Arc<Column>)> = kept
            .into_iter()
            .map(|(var, target)| (var, Arc::new(target.into_column())))
            .collect();
        let sinks = stage
            .ops
            .iter()
            .zip(host_values)
            .filter(|(op, _)| op.is_sink());
        for (number, (op, sink_values)) in sinks.enumerate() {
            match direct.targets[number].take() {
                Some((group, target)) => self.finish_direct_scatter(
                    op,
                    target,
                    &direct.groups[group],
                    group,
                    &results,
                    number,
                )?,
                None => self.finish_sink(op, sink_values, &results, number, &kept)?,
            }
        }
        for (_, array) in kept {
            self.context.column_pool.give(array);
        }
        let compiled = segments
            .iter()
            .flatten()
            .map(|prepared| prepared.segment.ops.clone())
            .collect();
        Ok((op_times, compiled))
    }

    /// An array of the stage's length for each of `vars`, which its chunks
    /// write their ranges of.
    fn stage_wide_arrays(&self, vars: Vec<VarId>) -> Vec<(VarId, SharedTarget)> {
        let records = &self.context.library.records;
        vars.into_iter()
            .map(|var| {
                let array = self.context.column_pool.take(
                    self.elem_type(var),
                    self.call.len,
                    Contents::Overwritten,
                    records,
                );
                (var, SharedTarget::new(array))
            })
            .collect()
    }

    /// The values made in the stage that its sinks finishing after it read
    /// (combining scatters, scans and sorts), but for the materialised ones:
    /// each gets a stage-wide array (see [`SinkInput`]).
    fn sink_kept_values(&self, materialised: &[(VarId, SharedTarget)]) -> Vec<VarId> {
        let stage = self.call.stage;
        let outer_ops = &stage.ops[self.call.inner_level().map_or(0, |(ops, _)| ops)..];
        // Made by the chunks: a field of an array made before the stage is
        // read where it is.
        let made = |mut var: VarId| loop {
            match outer_ops.iter().find(|op| op.outputs.contains(&var)) {
                None => return false,
                Some(op) if matches!(op.kind, OpKind::Field { .. }) => var = op.inputs[0],
                Some(_) => return true,
            }
        };
        let mut kept = Vec::new();
        let sinks = stage.ops.iter().filter(|op| op.is_sink());
        for op in sinks {
            // (A plain scatter writes from inside its chunks.)
            let inputs: Vec<VarId> = match &op.kind {
                OpKind::Scatter {
                    mask,
                    combine: Some(_),
                    ..
                } => op.inputs[..2].iter().copied().chain(*mask).collect(),
                OpKind::Scan { segments, .. } => {
                    op.inputs[..1].iter().copied().chain(*segments).collect()
                }
                OpKind::Sort { .. } => op.inputs.clone(),
                _ => Vec::new(),
            };
            for var in inputs {
                if made(var) && !kept.contains(&var) && !materialised.iter().any(|(v, _)| *v == var)
                {
                    kept.push(var);
                }
            }
        }
        kept
    }

    /// A sink's input at the end of its stage (`kept`: the stage-wide arrays
    /// of [`StageRun::sink_kept_values`]).
    fn sink_input(
        &self,
        input: &SinkInput,
        kept: &[(VarId, Arc<Column>)],
    ) -> Result<ChunkValue, RunError> {
        Ok(match input {
            SinkInput::Value(value) => value.clone(),
            SinkInput::Stored(var) => {
                ChunkValue::Whole(match kept.iter().find(|(v, _)| v == var) {
                    Some((_, array)) => array.clone(),
                    None => self.array(*var)?.clone(),
                })
            }
        })
    }

    /// Binds `var` to `column`, giving the array it held back to the pool.
    fn store(&mut self, var: VarId, column: Column) {
        if let Some(old) = self.slots.replace_array(var, Arc::new(column)) {
            self.context.column_pool.give(old);
        }
    }

    /// Gives back, before the stage allocates, the arrays its outputs still
    /// hold from an earlier run of the same code (a loop's previous round),
    /// where no op of the stage reads them: the new values can use them.
    fn release_rebound_outputs(&mut self) {
        let stage = self.call.stage;
        for &output in stage.ops.iter().flat_map(|op| &op.outputs) {
            if self.read_in_stage(output, None) {
                continue;
            }
            if let Some(old) = self.slots.take_array(output) {
                self.context.column_pool.give(old);
            }
        }
    }

    /// Whether an op of the stage, other than `besides`, reads `var`'s array.
    fn read_in_stage(&self, var: VarId, besides: Option<&Op>) -> bool {
        self.call.stage.ops.iter().any(|op| {
            !besides.is_some_and(|besides| std::ptr::eq(op, besides))
                && op.array_reads().contains(&var)
        })
    }

    /// The targets of the stage's plain scatters, made before its chunks run.
    fn direct_scatters(
        &mut self,
        stage: &Stage,
        host_values: &[OpHostValues],
    ) -> Result<DirectScatters, RunError> {
        let mut direct = DirectScatters {
            targets: Vec::new(),
            groups: Vec::new(),
        };
        let mut group_keys = Vec::new();
        let sinks = stage
            .ops
            .iter()
            .zip(host_values)
            .filter(|(op, _)| op.is_sink());
        for (op, values) in sinks {
            let OpKind::Scatter {
                mask,
                combine: None,
                ..
            } = &op.kind
            else {
                direct.targets.push(None);
                continue;
            };
            // A `len:` target's unclaimed slots are cleared after the stage.
            let target = self.scatter_target(op, values, Contents::Overwritten)?;
            let key = (op.inputs[0], *mask, target.len());
            let group = match group_keys.iter().position(|k| *k == key) {
                Some(group) => group,
                None => {
                    group_keys.push(key);
                    direct.groups.push(ScatterClaims::new(target.len()));
                    group_keys.len() - 1
                }
            };
            direct
                .targets
                .push(Some((group, SharedTarget::new(target))));
        }
        Ok(direct)
    }

    /// What a scatter writes into: zeros (or, asked for `Overwritten`, an
    /// array whose every slot the caller writes), or a copy of its `into:` array. A
    /// scatter that rebinds its own target (`c = scatter(…, into: c)`) takes
    /// the array out of the slot it replaces, where no other op of the stage
    /// reads it, so the copy is only made if something else still holds it.
    fn scatter_target(
        &mut self,
        op: &Op,
        values: &OpHostValues,
        len_target: Contents,
    ) -> Result<Column, RunError> {
        let OpKind::Scatter { target, .. } = &op.kind else {
            unreachable!("a scatter")
        };
        Ok(match target {
            ScatterTarget::Len(_) => self.context.column_pool.take(
                self.elem_type(op.outputs[0]),
                values.scatter_len.unwrap_or_default(),
                len_target,
                &self.context.library.records,
            ),
            ScatterTarget::Into(dst) => {
                let array = self.array(*dst)?.clone();
                let last_read = *dst == op.outputs[0] || self.call.last_reads.contains(dst);
                if last_read && !self.read_in_stage(*dst, Some(op)) {
                    // The slot is about to be overwritten, or never read
                    // again: it lets go of the array.
                    self.slots.take_array(*dst);
                }
                Arc::unwrap_or_clone(array)
            }
        })
    }

    /// A plain scatter's target, once the writes kept aside are applied in
    /// chunk order where they come after the slot's owner.
    fn finish_direct_scatter(
        &mut self,
        op: &Op,
        target: SharedTarget,
        claims: &ScatterClaims,
        group: usize,
        results: &[ChunkResult],
        number: usize,
    ) -> Result<(), RunError> {
        let mut dst = target.into_column();
        if let OpKind::Scatter {
            target: ScatterTarget::Len(_),
            ..
        } = &op.kind
        {
            claims.zero_unclaimed(&mut dst);
        }
        fn kept_aside(result: &ChunkResult, number: usize) -> Option<&(ChunkValue, ChunkValue)> {
            match &result.sinks[number] {
                SinkPart::Written(kept) => kept.as_ref(),
                _ => None,
            }
        }
        if results
            .iter()
            .any(|result| kept_aside(result, number).is_some())
        {
            let claims = results
                .iter()
                .filter_map(|r| Some((r.range.start, r.claims[group].as_ref()?)));
            let owners = Owners::new(dst.len(), claims);
            for result in results {
                let (Some((indices, values)), Some(claimed)) =
                    (kept_aside(result, number), &result.claims[group])
                else {
                    continue;
                };
                let range = result.range.clone();
                owners
                    .apply_aside(
                        range.start,
                        claimed,
                        indices.view(&range).as_u32(),
                        &values.view(&range),
                        &mut dst,
                    )
                    .map_err(RunError::from)?;
            }
        }
        self.store(op.outputs[0], dst);
        Ok(())
    }

    /// Assembles the result of the stage's sink `number` (counted in stage
    /// order) from every chunk's part: a combining scatter, a reduce, a scan or a sort.
    fn finish_sink(
        &mut self,
        op: &Op,
        values: &OpHostValues,
        results: &[ChunkResult],
        number: usize,
        kept: &[(VarId, Arc<Column>)],
    ) -> Result<(), RunError> {
        let records = &self.context.library.records;
        let input = |input: &SinkInput| self.sink_input(input, kept);
        match &op.kind {
            OpKind::Scatter {
                combine: Some(combine),
                ..
            } => {
                let inputs = results
                    .iter()
                    .map(|result| {
                        let SinkPart::Scatter {
                            indices,
                            values,
                            mask,
                        } = &result.sinks[number]
                        else {
                            unreachable!()
                        };
                        Ok((
                            input(indices)?,
                            input(values)?,
                            mask.as_ref().map(input).transpose()?,
                        ))
                    })
                    .collect::<Result<Vec<_>, RunError>>()?;
                let parts: Vec<_> = inputs
                    .iter()
                    .zip(results)
                    .map(|((indices, values, mask), result)| {
                        let range = &result.range;
                        (
                            indices.view(range),
                            values.view(range),
                            mask.as_ref().map(|m| m.view(range)),
                        )
                    })
                    .collect();
                let parts: Vec<_> = parts
                    .iter()
                    .map(|(indices, src, mask)| kernels::ScatterPart {
                        indices: indices.as_u32(),
                        src: src.clone(),
                        mask: mask.as_ref().map(|m| m.as_bool()),
                    })
                    .collect();
                let mut dst = self.scatter_target(op, values, Contents::Zeroed)?;
                kernels::scatter_combine_parts(*combine, &parts, &mut dst)
                    .map_err(RunError::from)?;
                self.store(op.outputs[0], dst);
            }
            OpKind::Reduce { op: monoid } => {
                let partials: Vec<Element> = results
                    .iter()
                    .map(|r| match r.sinks[number] {
                        SinkPart::Reduce(e) => e,
                        _ => unreachable!(),
                    })
                    .collect();
                let ty = self.elem_type(op.inputs[0]);
                let value =
                    kernels::reduce_to_host(*monoid, ty, &partials).map_err(RunError::from)?;
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
                    .map(|r| match &r.sinks[number] {
                        SinkPart::Scan { total, .. } => *total,
                        _ => unreachable!(),
                    })
                    .collect();
                let carries =
                    kernels::scan_carries(*monoid, ty, &totals).map_err(RunError::from)?;
                use rayon::prelude::*;
                // Each chunk's scanned values go straight to their range of the result.
                let len = self.call.len;
                let target = SharedTarget::new(self.context.column_pool.take(
                    ty,
                    len,
                    Contents::Overwritten,
                    records,
                ));
                let inputs = results
                    .iter()
                    .map(|result| {
                        let SinkPart::Scan { values, flags, .. } = &result.sinks[number] else {
                            unreachable!()
                        };
                        Ok((input(values)?, flags.as_ref().map(input).transpose()?))
                    })
                    .collect::<Result<Vec<_>, RunError>>()?;
                results
                    .par_iter()
                    .zip(carries)
                    .zip(&inputs)
                    .try_for_each(|((result, carry), (values, flags))| {
                        let range = result.range.clone();
                        let flags = flags.as_ref().map(|f| f.view(&range));
                        let part = kernels::scan_chunk(
                            *monoid,
                            &values.view(&range),
                            !exclusive,
                            carry,
                            flags.as_ref().map(|f| f.as_bool()),
                        )?;
                        target.write_range(range.start, &part.view())
                    })
                    .map_err(RunError::from)?;
                self.store(op.outputs[0], target.into_column());
            }
            OpKind::Sort { .. } => {
                let inputs = results
                    .iter()
                    .map(|result| match &result.sinks[number] {
                        SinkPart::Sort(inputs) => inputs.iter().map(input).collect(),
                        _ => unreachable!(),
                    })
                    .collect::<Result<Vec<Vec<ChunkValue>>, RunError>>()?;
                // Each input as the chunks' views of it, in chunk order.
                let parts = |number: usize| -> Vec<ColumnView<'_>> {
                    inputs
                        .iter()
                        .zip(results)
                        .map(|(inputs, result)| inputs[number].view(&result.range))
                        .collect()
                };
                let key_type = self.elem_type(op.inputs[0]);
                let order = SortedOrder::new(key_type, &parts(0)).map_err(RunError::from)?;
                let len = order.len();
                let pool = self.context.column_pool;
                let keys = pool.take(key_type, len, Contents::Overwritten, records);
                let keys = order.keys_into(keys).map_err(RunError::from)?;
                let sorted_values = match op.inputs.get(1) {
                    Some(&values) => {
                        let ty = self.elem_type(values);
                        // Values made before the stage, or stored whole by its
                        // chunks, are read where they are.
                        let whole = inputs.first().and_then(|inputs| match &inputs[1] {
                            ChunkValue::Whole(array) => Some(array.clone()),
                            ChunkValue::Chunk(_) => None,
                        });
                        let joined = whole.unwrap_or_else(|| {
                            Arc::new(Column::concat_views(ty, &parts(1), records))
                        });
                        let target = pool.take(ty, len, Contents::Overwritten, records);
                        Some(
                            order
                                .values_into(&joined.view(), target)
                                .map_err(RunError::from)?,
                        )
                    }
                    None => None,
                };
                self.store(op.outputs[0], keys);
                if let Some(sorted_values) = sorted_values {
                    self.store(op.outputs[1], sorted_values);
                }
            }
            _ => unreachable!("plain scatters finish in `finish_direct_scatter`"),
        }
        Ok(())
    }

    /// Runs every op of `stage` over one chunk of its index space.
    fn run_chunk(
        &self,
        stage: &Stage,
        host_values: &[OpHostValues],
        segments: &[Option<PreparedSegment>],
        direct: &DirectScatters,
        arrays: &StageArrays<'_>,
        range: Range<usize>,
    ) -> Result<ChunkResult, RunError> {
        let StageArrays { materialised, kept } = *arrays;
        let records = &self.context.library.records;
        // A nested stage's inner ops run over the chunk's groups' elements.
        let (inner_ops, inner_range) = match self.call.inner_level() {
            Some((ops, k)) => (ops, range.start * k..range.end * k),
            None => (0, range.clone()),
        };
        let stage_range = range;
        let mut locals: Vec<(VarId, ChunkValue)> = Vec::new();
        // A value written earlier in the stage shadows the array of the same slot.
        let lookup =
            |locals: &Vec<(VarId, ChunkValue)>, var: VarId| -> Result<ChunkValue, RunError> {
                match locals.iter().rev().find(|(v, _)| *v == var) {
                    Some((_, value)) => Ok(value.clone()),
                    None => Ok(ChunkValue::Whole(self.array(var)?.clone())),
                }
            };
        // Which of the `kept` values this chunk has copied its range of.
        let mut kept_written = vec![false; kept.len()];
        // A sink's input: a materialised value is stored after the ops, a
        // kept one now (once), both to stage-wide arrays.
        let sink_input = |locals: &Vec<(VarId, ChunkValue)>,
                          kept_written: &mut Vec<bool>,
                          var: VarId|
         -> Result<SinkInput, RunError> {
            if materialised.iter().any(|(v, _)| *v == var) {
                return Ok(SinkInput::Stored(var));
            }
            let value = lookup(locals, var)?;
            let Some(place) = kept.iter().position(|(v, _)| *v == var) else {
                return Ok(SinkInput::Value(value));
            };
            if let ChunkValue::Whole(_) = value {
                return Ok(SinkInput::Value(value));
            }
            if !kept_written[place] {
                kept[place]
                    .1
                    .write_range(stage_range.start, &value.view(&stage_range))
                    .map_err(RunError::from)?;
                kept_written[place] = true;
            }
            Ok(SinkInput::Stored(var))
        };
        let mut sinks = Vec::new();
        // By claims group: this chunk's claims, made by the group's first scatter.
        let mut claims: Vec<Option<Claimed>> = direct.groups.iter().map(|_| None).collect();
        // One clock reading per op: op `i`'s time runs from its start to the
        // start of op `i + 1` (or the end of the loop), whichever way it ends.
        let mut op_times = vec![Duration::ZERO; stage.ops.len()];
        let mut op_start = Instant::now();
        // Ops before this one were computed by a compiled segment (whose
        // time is its first op's).
        let mut computed_until = 0;
        for (number, (op, values)) in stage.ops.iter().zip(host_values).enumerate() {
            if number > 0 {
                let now = Instant::now();
                op_times[number - 1] = now - op_start;
                op_start = now;
            }
            if number < computed_until {
                continue;
            }
            let range = if number < inner_ops {
                inner_range.clone()
            } else {
                stage_range.clone()
            };
            if let Some(Some(prepared)) = segments.get(number) {
                let segment = &prepared.segment;
                let inputs: Vec<ChunkValue> = segment
                    .elementwise_inputs()
                    .map(|v| lookup(&locals, v))
                    .collect::<Result<_, _>>()?;
                let views: Vec<ColumnView> = inputs.iter().map(|c| c.view(&range)).collect();
                let gathered: Vec<&Arc<Column>> = segment
                    .gathered_inputs()
                    .map(|v| self.array(v))
                    .collect::<Result<_, _>>()?;
                let gathered: Vec<ColumnView> = gathered.iter().map(|c| c.view()).collect();
                // `None`: an element failed; the ops below run one by one and say why.
                if let Some(outputs) =
                    prepared.run(&views, &gathered, range.start, range.len(), records)
                {
                    for ((var, _), column) in segment.outputs.iter().zip(outputs) {
                        locals.push((*var, ChunkValue::Chunk(Arc::new(column))));
                    }
                    computed_until = segment.ops.end;
                    continue;
                }
            }
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
                    Column::filled(values.fill.expect("fill value"), range.len())
                        .map_err(RunError::internal)?,
                ),
                OpKind::Field { field } => {
                    let src = lookup(&locals, op.inputs[0])?;
                    let (ChunkValue::Chunk(column) | ChunkValue::Whole(column)) = &src;
                    let Column::Record { ty, .. } = column.as_ref() else {
                        return Err(RunError::internal("field of a non-record array"));
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
                        .map_err(RunError::from)?;
                    produced = outputs;
                }
                OpKind::Gather => {
                    let indices = lookup(&locals, op.inputs[0])?;
                    let src = self.array(op.inputs[1])?;
                    let gathered = kernels::gather(indices.view(&range).as_u32(), &src.view())
                        .map_err(RunError::from)?;
                    produced.push(gathered);
                }
                OpKind::GroupGather { .. } | OpKind::Expand { .. } => {
                    let k = values.group;
                    let source_range = match op.kind {
                        OpKind::GroupGather { .. } => range.start * k..range.end * k,
                        _ => range.start / k..range.end / k,
                    };
                    // Only a gather of groups of one (`fuse::is_elementwise_group`)
                    // or the gather that closes an inner level runs after other
                    // ops of its stage: its input may then be the chunk's own
                    // values, element for element or the chunk's groups' elements.
                    let src = lookup(&locals, op.inputs[0])?;
                    let functor = self.functor(op)?;
                    let mut outputs = new_outputs(range.len());
                    functor
                        .run_cpu(
                            &functor_context(source_range.start),
                            &[src.view(&source_range)],
                            &mut outputs,
                        )
                        .map_err(RunError::from)?;
                    produced = outputs;
                }
                OpKind::Scatter { mask, .. } => {
                    if let Some((group, target)) = &direct.targets[sinks.len()] {
                        let indices = lookup(&locals, op.inputs[0])?;
                        let values = lookup(&locals, op.inputs[1])?;
                        let mask = mask.map(|m| lookup(&locals, m)).transpose()?;
                        let index_view = indices.view(&range);
                        let mask_view = mask.as_ref().map(|m| m.view(&range));
                        let mask_view = mask_view.as_ref().map(|m| m.as_bool());
                        let claimed = match &mut claims[*group] {
                            Some(claimed) => claimed,
                            slot => slot.insert(
                                direct.groups[*group]
                                    .claim(index_view.as_u32(), mask_view)
                                    .map_err(RunError::from)?,
                            ),
                        };
                        target
                            .write(
                                claimed,
                                index_view.as_u32(),
                                mask_view,
                                &values.view(&range),
                            )
                            .map_err(RunError::from)?;
                        let kept = claimed.kept_aside();
                        sinks.push(SinkPart::Written(kept.then(|| (indices.clone(), values))));
                        continue;
                    }
                    sinks.push(SinkPart::Scatter {
                        indices: sink_input(&locals, &mut kept_written, op.inputs[0])?,
                        values: sink_input(&locals, &mut kept_written, op.inputs[1])?,
                        mask: mask
                            .map(|m| sink_input(&locals, &mut kept_written, m))
                            .transpose()?,
                    });
                }
                OpKind::Reduce { op: monoid } => {
                    let input = lookup(&locals, op.inputs[0])?;
                    let partial = kernels::reduce_partial(*monoid, &input.view(&range))
                        .map_err(RunError::from)?;
                    sinks.push(SinkPart::Reduce(partial));
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
                    .map_err(RunError::from)?;
                    sinks.push(SinkPart::Scan {
                        values: sink_input(&locals, &mut kept_written, op.inputs[0])?,
                        flags: segments
                            .map(|f| sink_input(&locals, &mut kept_written, f))
                            .transpose()?,
                        total,
                    });
                }
                OpKind::Sort { .. } => {
                    let inputs = op
                        .inputs
                        .iter()
                        .map(|v| sink_input(&locals, &mut kept_written, *v));
                    sinks.push(SinkPart::Sort(inputs.collect::<Result<_, _>>()?));
                }
                OpKind::Elementwise { .. } => {
                    return Err(RunError::internal(format!(
                        "`{}` reached the CPU backend before the compiler made it a map",
                        op.label()
                    )))
                }
            }
            for (output, column) in op.outputs.iter().zip(produced) {
                if column.elem_type() != self.elem_type(*output) {
                    return Err(RunError::internal(format!(
                        "`{}` produced {} elements where its signature says {} (a functor bug)",
                        op.label(),
                        column.elem_type().name(records),
                        self.elem_type(*output).name(records)
                    )));
                }
                if column.len() != range.len() {
                    return Err(RunError::internal(format!(
                        "`{}` produced {} elements for a chunk of {} (a functor bug)",
                        op.label(),
                        column.len(),
                        range.len()
                    )));
                }
                locals.push((*output, ChunkValue::Chunk(Arc::new(column))));
            }
        }
        if let Some(last) = op_times.last_mut() {
            *last = op_start.elapsed();
        }
        let range = stage_range;
        if !materialised.is_empty() {
            let store_start = Instant::now();
            for (var, target) in materialised {
                target
                    .write_range(range.start, &lookup(&locals, *var)?.view(&range))
                    .map_err(RunError::from)?;
            }
            op_times.push(store_start.elapsed());
        }
        Ok(ChunkResult {
            range,
            sinks,
            claims,
            op_times,
        })
    }

    fn functor(&self, op: &Op) -> Result<&Arc<dyn crate::functor::Functor>, RunError> {
        let name = op.functor.as_deref().unwrap_or_default();
        self.context.library.get(name).ok_or_else(|| {
            RunError::internal(format!("functor `{name}` is not in this run's library"))
        })
    }
}
