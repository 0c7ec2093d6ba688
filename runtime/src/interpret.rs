//! What every backend shares: walking a plan's nodes in order (host bindings,
//! views, loops, branches, outputs), evaluating the host values a stage needs
//! and deciding how many elements it runs over. A backend supplies only its
//! array storage and how one stage runs ([`Backend`]), so the CPU and GPU
//! backends cannot disagree about control flow.

use crate::column::Column;
use crate::compile::host_eval::{eval_host, HostEnvironment};
use crate::compile::ir::*;
use crate::elem::KernelError;
use crate::error::ErrorKind;
use crate::functor::FunctorError;
use crate::host::{HostValue, Uniforms};
use crate::types::{ElemType, RecordRegistry};
use std::collections::{HashMap, HashSet};
use std::ops::Range;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Longest array a stage may make: keeps `u32` indices valid and memory sane.
pub const MAX_ELEMENTS: usize = 1 << 31;
/// A `while` loop that runs this often is taken to be stuck, and a `for` loop
/// with more iterations than this is refused before its first (a param set to
/// something absurd, `--set maxDepth=1000000000`, answers at once instead of
/// running for days).
pub const MAX_LOOP_ITERATIONS: u64 = 10_000_000;

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
    /// Wall time on the host (the CPU backend), or device time where the GPU
    /// backend measured it with timestamp queries.
    pub time: Duration,
    /// Where the stage's time went, op by op, where the backend can split it
    /// (the CPU backend: one entry per op of the stage, in stage order, then
    /// one for storing its element-wise values if it stores any); empty where
    /// it cannot (a GPU stage is one kernel).
    pub ops: Vec<OpTiming>,
    /// Runs of the stage's ops that ran as one compiled loop (the CPU
    /// backend's `cpu::compiled`), by position: the time of each is its
    /// first op's, and the other ops of the run are unlabelled.
    pub compiled: Vec<Range<usize>>,
}

/// Time the chunks of a stage spent in one of its ops, summed over the threads
/// that ran them (so the ops of a stage on 2 threads add up to about twice its
/// wall time, less what the stage does outside its chunks: finishing its
/// sinks).
#[derive(Clone, Debug)]
pub struct OpTiming {
    pub label: String,
    pub thread_time: Duration,
}

/// The ops of a stage's profile worth listing apart, each with its share of
/// the stage's op time: none for a stage of one op that stores nothing (or
/// one never timed), no field views (`.field`: they copy nothing) and none
/// of the ops a compiled run's first op stands for.
pub fn listed_op_shares(ops: &[OpTiming]) -> Vec<(&OpTiming, f64)> {
    let total: f64 = ops.iter().map(|op| op.thread_time.as_secs_f64()).sum();
    // Unlabelled: inside a compiled run, whose first op took the time.
    let listed: Vec<&OpTiming> = ops
        .iter()
        .filter(|op| !op.label.starts_with('.') && !op.label.is_empty())
        .collect();
    if listed.len() < 2 || total <= 0.0 {
        return Vec::new();
    }
    listed
        .into_iter()
        .map(|op| (op, op.thread_time.as_secs_f64() / total))
        .collect()
}

/// An op as a stage's profile names it: `name = map<f>` where its one output
/// has a name in the pipeline, else the op alone (`map<f>`, `.field`).
fn op_label(plan: &Plan, op: &Op) -> String {
    let label = op.label();
    match op.outputs.as_slice() {
        [output] if !plan.var(*output).name.starts_with('%') && !label.starts_with('.') => {
            format!("{} = {label}", plan.var(*output).name)
        }
        _ => label,
    }
}

/// The profile's name for a stage's copying of the element-wise values it
/// stores: `store` and the values' names (`store hits, surf`).
fn store_label(plan: &Plan, stage: &Stage) -> String {
    let names: Vec<&str> = elementwise_materialised(stage)
        .into_iter()
        .map(|var| plan.var(var).name.as_str())
        .filter(|name| !name.starts_with('%'))
        .collect();
    match names.as_slice() {
        [] => "store".to_string(),
        _ => format!("store {}", names.join(", ")),
    }
}

/// What a backend measured of one run of a stage.
#[derive(Clone, Debug, Default)]
pub struct StageMeasurement {
    /// Device time, when the backend measured one itself (GPU timestamps);
    /// otherwise the interpreter takes the host's wall time.
    pub device_time: Option<Duration>,
    /// Per op of the stage, in stage order, summed over threads, then, where
    /// the stage stores element-wise values, the time spent copying them into
    /// their arrays; empty where the backend cannot split a stage.
    pub op_thread_times: Vec<Duration>,
    /// Runs of ops that ran as one compiled loop, by position in the stage.
    pub compiled: Vec<Range<usize>>,
}

#[derive(Clone, Debug)]
pub struct RunResult {
    /// In the order of the pipeline's `out` declarations; none on a rank
    /// whose part of the image went to rank 0 at `composite`.
    pub outputs: Vec<(String, OutputValue)>,
    pub profile: Vec<StageTiming>,
    /// Whether this rank's run ended at `composite`, rank 0 holding the outputs.
    pub composited_elsewhere: bool,
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{message}")]
pub struct RunError {
    pub kind: ErrorKind,
    pub message: String,
}

impl RunError {
    pub fn new(kind: ErrorKind, message: impl Into<String>) -> RunError {
        RunError {
            kind,
            message: message.into(),
        }
    }

    pub fn bad_input(message: impl Into<String>) -> RunError {
        RunError::new(ErrorKind::BadInput, message)
    }

    pub fn resource_limit(message: impl Into<String>) -> RunError {
        RunError::new(ErrorKind::ResourceLimit, message)
    }

    pub fn device(message: impl Into<String>) -> RunError {
        RunError::new(ErrorKind::Device, message)
    }

    pub fn internal(message: impl Into<String>) -> RunError {
        RunError::new(ErrorKind::Internal, message)
    }

    /// The same error, its message behind `context: `.
    pub fn within(self, context: impl std::fmt::Display) -> RunError {
        RunError::new(self.kind, format!("{context}: {}", self.message))
    }
}

impl From<KernelError> for RunError {
    fn from(error: KernelError) -> RunError {
        RunError::new(error.kind(), error.to_string())
    }
}

impl From<FunctorError> for RunError {
    fn from(error: FunctorError) -> RunError {
        RunError::new(error.kind, error.message)
    }
}

/// Host values an op needs, evaluated once when its stage starts.
pub struct OpHostValues {
    /// Named arguments in signature order.
    pub named: Vec<HostValue>,
    /// `k` of a group gather or fan-out; 1 otherwise.
    pub group: usize,
    /// `fill`'s value.
    pub fill: Option<HostValue>,
    /// A scatter's `len:` target length.
    pub scatter_len: Option<usize>,
}

/// The variables of a running plan: arrays in the backend's storage, host scalars.
pub struct Slots<A> {
    pub arrays: Vec<Option<A>>,
    pub hosts: Vec<Option<HostValue>>,
}

impl<A> Slots<A> {
    pub fn array(&self, plan: &Plan, var: VarId) -> Result<&A, RunError> {
        self.arrays[var.0 as usize].as_ref().ok_or_else(|| {
            RunError::internal(format!(
                "`{}` is read before it has a value",
                plan.var(var).name
            ))
        })
    }

    pub fn set_array(&mut self, var: VarId, value: A) {
        self.arrays[var.0 as usize] = Some(value);
    }

    /// Binds `var` to `value`; the array it held, if any.
    pub fn replace_array(&mut self, var: VarId, value: A) -> Option<A> {
        self.arrays[var.0 as usize].replace(value)
    }

    /// Unbinds `var`; the array it held, if any.
    pub fn take_array(&mut self, var: VarId) -> Option<A> {
        self.arrays[var.0 as usize].take()
    }

    pub fn set_host(&mut self, var: VarId, value: HostValue) {
        self.hosts[var.0 as usize] = Some(value);
    }
}

impl StageCall<'_> {
    /// For a nested stage, the number of its inner ops and the size of the
    /// groups the gather after them closes (docs/language.md §6, rule 5).
    pub fn inner_level(&self) -> Option<(usize, usize)> {
        let inner = self.stage.inner.as_ref()?;
        Some((inner.ops, self.host_values[inner.ops].group))
    }
}

/// One stage, ready to run: its host values and length already known.
pub struct StageCall<'a> {
    pub plan: &'a Plan,
    pub stage: &'a Stage,
    /// One per op of the stage.
    pub host_values: Vec<OpHostValues>,
    /// The number of elements the stage runs over.
    pub len: usize,
    pub uniforms: &'a Uniforms,
    pub records: &'a RecordRegistry,
    /// Arrays nothing reads after this stage (see [`last_reads`]): a
    /// backend may reuse them, as a scatter `into:` one of them does.
    pub last_reads: &'a [VarId],
}

/// For each stage (in [`Plan::stages`] order), the variables whose last
/// read it is: read by nodes of the plan's top level only (never inside a
/// loop or branch, which may run again), the last of them this stage.
pub fn last_reads(plan: &Plan) -> Vec<Vec<VarId>> {
    let stages = plan.stages();
    let mut nested = HashSet::new();
    let mut last_reader: HashMap<VarId, Option<usize>> = HashMap::new();
    for node in &plan.body {
        // Whatever the node nests (a loop's or branch's body, a blend).
        walk_nodes(std::slice::from_ref(node), &mut |inner| {
            if !std::ptr::eq(inner, node) {
                nested.extend(node_reads(inner));
            }
        });
        let stage = match node {
            Node::Stage(stage) => stages.iter().position(|s| std::ptr::eq(*s, stage)),
            _ => None,
        };
        for var in node_reads(node) {
            if matches!(plan.var(var).ty, VarType::Array(_)) {
                last_reader.insert(var, stage);
            }
        }
    }
    let mut by_stage = vec![Vec::new(); stages.len()];
    for (var, stage) in last_reader {
        if let (Some(stage), false) = (stage, nested.contains(&var)) {
            by_stage[stage].push(var);
        }
    }
    by_stage
}

impl StageCall<'_> {
    pub fn elem_type(&self, var: VarId) -> ElemType {
        elem_type(self.plan, var)
    }
}

/// The array element type of `var` (type checking guarantees one).
pub fn elem_type(plan: &Plan, var: VarId) -> ElemType {
    match plan.var(var).ty {
        VarType::Array(t) => t,
        other => unreachable!("array variable of type {other:?} after type checking"),
    }
}

/// How a backend stores arrays and runs one stage.
pub trait Backend {
    type Array: Clone;

    fn len(array: &Self::Array) -> usize;

    /// A view of field `index` of a record array (no copy where the backend can help it).
    fn field(&self, array: &Self::Array, index: usize) -> Option<Self::Array>;

    /// Runs the stage, writing what it materialises (and a sink's result) into
    /// `slots`, and says what it measured of it.
    fn run_stage(
        &mut self,
        call: &StageCall<'_>,
        slots: &mut Slots<Self::Array>,
    ) -> Result<StageMeasurement, RunError>;

    /// The array as a host column, for the run's outputs.
    fn to_column(&mut self, array: &Self::Array) -> Result<Arc<Column>, RunError>;

    /// A host column as the backend's array: `composite` hands the pieces
    /// other ranks sent to the blend, and the whole image to the rest of the run.
    fn upload(&mut self, column: Arc<Column>) -> Result<Self::Array, RunError>;

    /// A slot lets go of `array` (it was rebound, or the run ended): a backend
    /// that reuses memory takes it back here; the others drop it.
    fn release(&mut self, array: Self::Array) {
        drop(array);
    }
}

/// A stage about to run, as a run reports it to an observer (`dpp run`'s
/// progress line on a terminal).
#[derive(Clone, Copy, Debug)]
pub struct StageStart<'a> {
    /// The stage's number in the plan, from 1.
    pub stage: usize,
    /// How many stages the plan has.
    pub stages: usize,
    /// `iota → map<cameraRay> → map<intersect>`.
    pub label: &'a str,
    /// Which run of the stage this is, from 1 (loops run stages again).
    pub run: u32,
}

/// Told of every stage before it runs; it must not block (it runs on the
/// thread that drives the run).
pub type StageObserver<'a> = &'a (dyn Fn(&StageStart<'_>) + Sync);

/// Combines two pieces of the image (each a range of the same pixels), the
/// one nearer the front first; the blended arrays in the order given.
pub type Blend<'b> =
    dyn FnMut(&[Arc<Column>], &[Arc<Column>]) -> Result<Vec<Arc<Column>>, RunError> + 'b;

/// Where a plan's `composite` meets the other ranks: the schedule that moves
/// the pieces between them (docs/language.md §3, composite). The per-pixel
/// blend is the plan's; the compositor calls it.
pub trait Compositor: Sync {
    /// Composites this rank's per-pixel arrays with every other rank's, in
    /// rank order or, with `visibility`, front to back in visibility order.
    /// The whole image on the rank that goes on with the run (rank 0), `None`
    /// on the others, whose run ends here.
    fn composite(
        &self,
        fragments: Vec<Arc<Column>>,
        visibility: bool,
        blend: &mut Blend<'_>,
    ) -> Result<Option<Vec<Arc<Column>>>, RunError>;
}

/// What a run tells, and whom it asks, besides its backend.
#[derive(Clone, Copy, Default)]
pub struct RunHooks<'a> {
    /// Told of every stage before it runs.
    pub observer: Option<StageObserver<'a>>,
    /// The other ranks, for `composite`; without one the run is the only rank.
    pub compositor: Option<&'a dyn Compositor>,
}

/// Runs `plan` on `backend`.
pub fn interpret<B: Backend>(
    plan: &Plan,
    backend: &mut B,
    uniforms: &Uniforms,
    records: &RecordRegistry,
) -> Result<RunResult, RunError> {
    interpret_with_inputs(plan, backend, uniforms, records, Vec::new())
}

/// Runs `plan` with some array variables already holding values (a plan
/// built in code to run one functor on given arrays).
pub fn interpret_with_inputs<B: Backend>(
    plan: &Plan,
    backend: &mut B,
    uniforms: &Uniforms,
    records: &RecordRegistry,
    inputs: Vec<(VarId, B::Array)>,
) -> Result<RunResult, RunError> {
    interpret_observed(
        plan,
        backend,
        uniforms,
        records,
        inputs,
        RunHooks::default(),
    )
}

/// [`interpret_with_inputs`] with the run's hooks: an observer told of every
/// stage before it runs, the other ranks.
pub fn interpret_observed<B: Backend>(
    plan: &Plan,
    backend: &mut B,
    uniforms: &Uniforms,
    records: &RecordRegistry,
    inputs: Vec<(VarId, B::Array)>,
    hooks: RunHooks<'_>,
) -> Result<RunResult, RunError> {
    let stages = plan.stages();
    let mut interpreter = Interpreter {
        plan,
        uniforms,
        records,
        backend,
        slots: Slots {
            arrays: vec![None; plan.vars.len()],
            hosts: vec![None; plan.vars.len()],
        },
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
                ops: Vec::new(),
                compiled: Vec::new(),
            })
            .collect(),
        stages,
        last_reads: last_reads(plan),
        observer: hooks.observer,
        compositor: hooks.compositor,
        composited_elsewhere: false,
    };
    for (var, array) in inputs {
        interpreter.slots.set_array(var, array);
    }
    interpreter.nodes(&plan.body)?;
    // The outputs hold their own handles: every array left is the backend's.
    for array in interpreter.slots.arrays.drain(..).flatten() {
        interpreter.backend.release(array);
    }
    let mut outputs = Vec::new();
    // This rank's part went to rank 0 at `composite`: the outputs are rank 0's.
    let written = if interpreter.composited_elsewhere {
        &[][..]
    } else {
        &plan.outputs[..]
    };
    for name in written {
        match interpreter.outputs.iter().rev().find(|(n, _)| n == name) {
            Some(found) => outputs.push(found.clone()),
            None => {
                return Err(RunError::bad_input(format!(
                    "output `{name}` was never written (its `out` did not run)"
                )))
            }
        }
    }
    Ok(RunResult {
        outputs,
        profile: interpreter.profile,
        composited_elsewhere: interpreter.composited_elsewhere,
    })
}

enum Flow {
    Continue,
    Break,
    /// This rank's part of the image went to rank 0: its run is over.
    Composited,
}

struct Interpreter<'a, B: Backend> {
    plan: &'a Plan,
    uniforms: &'a Uniforms,
    records: &'a RecordRegistry,
    backend: &'a mut B,
    slots: Slots<B::Array>,
    outputs: Vec<(String, OutputValue)>,
    profile: Vec<StageTiming>,
    stages: Vec<&'a Stage>,
    /// By stage: [`last_reads`].
    last_reads: Vec<Vec<VarId>>,
    observer: Option<StageObserver<'a>>,
    compositor: Option<&'a dyn Compositor>,
    /// Set once `composite` sent this rank's part to rank 0.
    composited_elsewhere: bool,
}

struct Environment<'a, A: Clone, B: Backend<Array = A>> {
    slots: &'a Slots<A>,
    uniforms: &'a Uniforms,
    backend: std::marker::PhantomData<B>,
}

impl<A: Clone, B: Backend<Array = A>> HostEnvironment for Environment<'_, A, B> {
    fn host_var(&self, var: VarId) -> Option<HostValue> {
        self.slots.hosts[var.0 as usize]
    }
    fn array_len(&self, var: VarId) -> Option<usize> {
        self.slots.arrays[var.0 as usize].as_ref().map(B::len)
    }
    fn uniforms(&self) -> &Uniforms {
        self.uniforms
    }
}

impl<'a, B: Backend> Interpreter<'a, B> {
    /// Binds `dst` to `value`, handing the array it held to the backend.
    fn store(&mut self, dst: VarId, value: B::Array) {
        if let Some(old) = self.slots.replace_array(dst, value) {
            self.backend.release(old);
        }
    }

    fn eval(&self, expr: &HostExpr) -> Result<HostValue, RunError> {
        let environment = Environment::<B::Array, B> {
            slots: &self.slots,
            uniforms: self.uniforms,
            backend: std::marker::PhantomData,
        };
        eval_host(expr, &environment).map_err(RunError::bad_input)
    }

    fn eval_count(&self, expr: &HostExpr, what: &str) -> Result<usize, RunError> {
        let value = self.eval(expr)?;
        match value.as_int() {
            Some(n) if n >= 0 && (n as u64) <= MAX_ELEMENTS as u64 => Ok(n as usize),
            Some(n) if n < 0 => Err(RunError::bad_input(format!("{what} is negative ({n})"))),
            Some(n) => Err(RunError::resource_limit(format!(
                "{what} is {n}, above the limit of {MAX_ELEMENTS} elements"
            ))),
            None => Err(RunError::bad_input(format!(
                "{what} must be an integer, found {value}"
            ))),
        }
    }

    fn array_len(&self, var: VarId) -> Result<usize, RunError> {
        Ok(B::len(self.slots.array(self.plan, var)?))
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
                    if let Some(observe) = self.observer {
                        observe(&StageStart {
                            stage: number + 1,
                            stages: self.stages.len(),
                            label: &self.profile[number].label,
                            run: self.profile[number].runs + 1,
                        });
                    }
                    let start = Instant::now();
                    let (elements, measured) = self.stage(stage, number).map_err(|e| {
                        e.within(format_args!(
                            "stage {} [{}]",
                            number + 1,
                            self.profile[number].label
                        ))
                    })?;
                    let timing = &mut self.profile[number];
                    timing.runs += 1;
                    timing.elements += elements as u64;
                    timing.time += measured.device_time.unwrap_or_else(|| start.elapsed());
                    if timing.ops.is_empty() && !measured.op_thread_times.is_empty() {
                        let mut labels: Vec<String> =
                            stage.ops.iter().map(|op| op_label(self.plan, op)).collect();
                        if measured.op_thread_times.len() > stage.ops.len() {
                            labels.push(store_label(self.plan, stage));
                        }
                        for run in &measured.compiled {
                            let (first, last) = (&labels[run.start], &labels[run.end - 1]);
                            labels[run.start] =
                                format!("compiled[{}]: {first} … {last}", run.len());
                            labels[run.start + 1..run.end].fill(String::new());
                        }
                        timing.compiled = measured.compiled.clone();
                        timing.ops = labels
                            .into_iter()
                            .map(|label| OpTiming {
                                label,
                                thread_time: Duration::ZERO,
                            })
                            .collect();
                    }
                    for (op, time) in timing.ops.iter_mut().zip(&measured.op_thread_times) {
                        op.thread_time += *time;
                    }
                }
                Node::Op(_) => unreachable!("plans hand backends stages, never bare ops"),
                Node::Host { dst, expr, .. } => {
                    let value = self.eval(expr)?;
                    self.slots.set_host(*dst, value);
                }
                Node::View { dst, src, field } => {
                    let array = self.slots.array(self.plan, *src)?;
                    let view = match elem_type(self.plan, *src) {
                        ElemType::Record(ty) => self
                            .records
                            .get(ty)
                            .field_index(field)
                            .and_then(|i| self.backend.field(array, i)),
                        _ => None,
                    };
                    let view = view.ok_or_else(|| {
                        RunError::internal(format!(
                            "`{}` has no field `{field}`",
                            self.plan.var(*src).name
                        ))
                    })?;
                    self.store(*dst, view);
                }
                Node::Alias { dst, src } => {
                    let value = self.slots.array(self.plan, *src)?.clone();
                    self.store(*dst, value);
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
                        return Err(RunError::bad_input("loop bounds must be integers"));
                    };
                    let iterations = i128::from(end) - i128::from(start);
                    if iterations > i128::from(MAX_LOOP_ITERATIONS) {
                        return Err(RunError::resource_limit(format!(
                            "`for {} in {start}..{end}` would run {iterations} times, more than the {MAX_LOOP_ITERATIONS} a loop may run",
                            self.plan.var(*var).name
                        )));
                    }
                    for i in start..end {
                        self.slots.set_host(*var, HostValue::Int(i));
                        match self.nodes(body)? {
                            Flow::Continue => {}
                            Flow::Break => break,
                            Flow::Composited => return Ok(Flow::Composited),
                        }
                    }
                }
                Node::While { cond, body, .. } => {
                    let mut iterations = 0u64;
                    while self.eval(cond)?.as_bool() == Some(true) {
                        iterations += 1;
                        if iterations > MAX_LOOP_ITERATIONS {
                            return Err(RunError::resource_limit(format!(
                                "a `while` loop ran {MAX_LOOP_ITERATIONS} times; stopping (is its condition ever false?)"
                            )));
                        }
                        match self.nodes(body)? {
                            Flow::Continue => {}
                            Flow::Break => break,
                            Flow::Composited => return Ok(Flow::Composited),
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
                    match self.nodes(branch)? {
                        Flow::Continue => {}
                        flow => return Ok(flow),
                    }
                }
                Node::Break => return Ok(Flow::Break),
                Node::Composite(composite) => {
                    if !self.composite(composite)? {
                        self.composited_elsewhere = true;
                        return Ok(Flow::Composited);
                    }
                }
                Node::Output { name, var } => {
                    let value = match self.plan.var(*var).ty {
                        VarType::Host(_) => {
                            OutputValue::Host(self.slots.hosts[var.0 as usize].ok_or_else(
                                || RunError::internal(format!("output `{name}` has no value")),
                            )?)
                        }
                        _ => {
                            let array = self.slots.array(self.plan, *var)?.clone();
                            OutputValue::Array(self.backend.to_column(&array)?)
                        }
                    };
                    self.outputs.push((name.clone(), value));
                }
            }
        }
        Ok(Flow::Continue)
    }

    /// Hands this rank's pieces to the compositor, which runs the blend as
    /// it needs it; binds the composited image and returns true on the rank
    /// that goes on, returns false on the others. Without a compositor the
    /// run is the only rank: the image is its own, and the blend never runs.
    fn composite(&mut self, composite: &'a Composite) -> Result<bool, RunError> {
        let Some(compositor) = self.compositor else {
            for (&input, &output) in composite.inputs.iter().zip(&composite.outputs) {
                let value = self.slots.array(self.plan, input)?.clone();
                self.store(output, value);
            }
            return Ok(true);
        };
        let visibility = self.eval(&composite.visibility)?.as_bool() == Some(true);
        let mut fragments = Vec::with_capacity(composite.inputs.len());
        for &input in &composite.inputs {
            let array = self.slots.array(self.plan, input)?.clone();
            fragments.push(self.backend.to_column(&array)?);
        }
        let mut blend =
            |front: &[Arc<Column>], back: &[Arc<Column>]| self.blend(composite, front, back);
        let whole = compositor
            .composite(fragments, visibility, &mut blend)
            .map_err(|e| e.within(format_args!("composite<{}>", composite.blend_fn)))?;
        let Some(whole) = whole else {
            return Ok(false);
        };
        for (&output, column) in composite.outputs.iter().zip(whole) {
            let array = self.backend.upload(column)?;
            self.store(output, array);
        }
        Ok(true)
    }

    /// One run of a composite's blend on two pieces.
    fn blend(
        &mut self,
        composite: &'a Composite,
        front: &[Arc<Column>],
        back: &[Arc<Column>],
    ) -> Result<Vec<Arc<Column>>, RunError> {
        for (vars, pieces) in [(&composite.front, front), (&composite.back, back)] {
            if pieces.len() != vars.len() {
                return Err(RunError::internal(format!(
                    "the blend takes {} arrays per piece, the compositor gave {}",
                    vars.len(),
                    pieces.len()
                )));
            }
            for (&var, piece) in vars.iter().zip(pieces) {
                let expected = elem_type(self.plan, var);
                if piece.elem_type() != expected {
                    return Err(RunError::internal(format!(
                        "the compositor gave `{}` {} elements where the blend takes {}",
                        self.plan.var(var).name,
                        piece.elem_type().name(self.records),
                        expected.name(self.records)
                    )));
                }
                let array = self.backend.upload(piece.clone())?;
                self.store(var, array);
            }
        }
        match self.nodes(&composite.blend)? {
            Flow::Continue => {}
            _ => return Err(RunError::internal("the blend left its body early")),
        }
        let mut blended = Vec::with_capacity(composite.blended.len());
        for &var in &composite.blended {
            let array = self.slots.array(self.plan, var)?.clone();
            blended.push(self.backend.to_column(&array)?);
        }
        Ok(blended)
    }

    /// Runs one stage; returns the number of elements it ran over and the
    /// backend's own measure of its time, if any.
    /// Runs `stage`, the plan's stage `number` (from 0).
    fn stage(
        &mut self,
        stage: &'a Stage,
        number: usize,
    ) -> Result<(usize, StageMeasurement), RunError> {
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
                        return Err(RunError::bad_input("a group or fan-out of 0 elements"));
                    }
                    k
                }
                _ => 1,
            };
            let fill = match &op.kind {
                OpKind::Fill { value, .. } => Some(self.eval(value)?),
                _ => None,
            };
            let scatter_len = match &op.kind {
                OpKind::Scatter {
                    target: ScatterTarget::Len(len),
                    ..
                } => Some(self.eval_count(len, "the scatter length")?),
                _ => None,
            };
            host_values.push(OpHostValues {
                named,
                group,
                fill,
                scatter_len,
            });
        }

        // The head op decides how many elements the stage (or its inner level) runs over.
        let k = host_values[0].group;
        let head_len = match &head.kind {
            OpKind::Iota { count } | OpKind::Fill { count, .. } => {
                self.eval_count(count, "the length")?
            }
            OpKind::GroupGather { .. } => groups_of(self.array_len(head.inputs[0])?, k)?,
            OpKind::Expand { .. } => {
                let n = self
                    .array_len(head.inputs[0])?
                    .checked_mul(k)
                    .filter(|n| *n <= MAX_ELEMENTS);
                n.ok_or_else(|| {
                    RunError::resource_limit(format!(
                        "fan-out by {k} makes more than {MAX_ELEMENTS} elements"
                    ))
                })?
            }
            _ => self.array_len(head.inputs[0])?,
        };
        // A nested stage runs over the groups its inner level's closing gather makes.
        let len = match &stage.inner {
            Some(inner) => groups_of(head_len, host_values[inner.ops].group)?,
            None => head_len,
        };
        let inner_reads = stage.inner.iter().flat_map(|inner| &inner.reads_direct);
        let level_reads =
            (stage.reads_direct.iter().map(|v| (v, len))).chain(inner_reads.map(|v| (v, head_len)));
        for (&v, level_len) in level_reads {
            let found = self.array_len(v)?;
            if found != level_len {
                return Err(RunError::bad_input(format!(
                    "length mismatch: `{}` has {found} elements, but the stage runs over {level_len}",
                    self.plan.var(v).name
                )));
            }
        }
        let call = StageCall {
            plan: self.plan,
            stage,
            host_values,
            len,
            uniforms: self.uniforms,
            records: self.records,
            last_reads: &self.last_reads[number],
        };
        let measured = self.backend.run_stage(&call, &mut self.slots)?;
        Ok((len, measured))
    }
}

/// The number of groups of `k` in `len` elements, which must be whole.
fn groups_of(len: usize, k: usize) -> Result<usize, RunError> {
    if !len.is_multiple_of(k) {
        return Err(RunError::bad_input(format!(
            "group gather of {len} elements in groups of {k}: {len} is not a multiple of {k}"
        )));
    }
    Ok(len / k)
}

/// The variables a stage writes element by element: everything it
/// materialises but its sinks' results, which each sink assembles itself.
pub fn elementwise_materialised(stage: &Stage) -> Vec<VarId> {
    let sink_outputs: Vec<VarId> = stage
        .ops
        .iter()
        .filter(|op| op.is_sink())
        .flat_map(|op| op.outputs.iter().copied())
        .collect();
    stage
        .materialises
        .iter()
        .copied()
        .filter(|v| !sink_outputs.contains(v))
        .collect()
}
