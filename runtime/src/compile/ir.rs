//! The plan: a typed dataflow program of primitive applications inside
//! structured control flow. Lowering produces it with one [`Node::Op`] per
//! primitive; fusion groups ops into [`Node::Stage`]s, which is all a backend runs.
//!
//! Variables are slots: a name bound outside a loop or branch and rebound inside
//! it is the same slot (that is how loop-carried state is written); other
//! bindings get fresh slots, so most variables have a single definition.

use crate::host::HostValue;
use crate::monoid::MonoidOp;
use crate::types::{ElemType, HostType};
use dpp_dsl::ast::{BinaryOp, UnaryOp};
use dpp_dsl::Span;
use serde::Serialize;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
pub struct VarId(pub u32);

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum VarType {
    /// Not yet inferred (before type checking) or unreachable.
    Unknown,
    Array(ElemType),
    Host(HostType),
}

#[derive(Clone, Debug, Serialize)]
pub struct VarInfo {
    /// The source name (`rays`), or `%N` for a compiler temporary.
    pub name: String,
    #[serde(skip)]
    pub span: Span,
    pub ty: VarType,
    /// The symbolic length of an array variable, when type checking knows one.
    pub len: Option<HostExpr>,
}

/// A host scalar expression: evaluated on the host, never per element.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub enum HostExpr {
    Const(HostValue),
    /// A host variable: a param, a loop counter, a binding or a `reduce` result.
    Var(VarId),
    Uniform {
        record: String,
        field: String,
    },
    /// `len(a)` of an array variable.
    Len(VarId),
    Unary(
        #[serde(serialize_with = "serialize_debug")] UnaryOp,
        Box<HostExpr>,
    ),
    Binary(
        #[serde(serialize_with = "serialize_debug")] BinaryOp,
        Box<HostExpr>,
        Box<HostExpr>,
    ),
    Call(HostFunction, Vec<HostExpr>),
}

fn serialize_debug<T: std::fmt::Debug, S: serde::Serializer>(
    value: &T,
    serializer: S,
) -> Result<S::Ok, S::Error> {
    serializer.serialize_str(&format!("{value:?}"))
}

/// Built-in host functions.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum HostFunction {
    Vec2,
    Vec3,
    Vec4,
    Min,
    Max,
    Abs,
    Floor,
    Ceil,
    Sqrt,
    Float,
}

impl HostFunction {
    pub const ALL: [(&'static str, HostFunction); 10] = [
        ("vec2", HostFunction::Vec2),
        ("vec3", HostFunction::Vec3),
        ("vec4", HostFunction::Vec4),
        ("min", HostFunction::Min),
        ("max", HostFunction::Max),
        ("abs", HostFunction::Abs),
        ("floor", HostFunction::Floor),
        ("ceil", HostFunction::Ceil),
        ("sqrt", HostFunction::Sqrt),
        ("float", HostFunction::Float),
    ];

    pub fn name(self) -> &'static str {
        HostFunction::ALL
            .iter()
            .find(|(_, f)| *f == self)
            .map(|(n, _)| *n)
            .unwrap_or("?")
    }
}

/// The primitives: the callees that take a functor in angle brackets, and
/// `gather`, `scatter`, `sort` and `sortByKey`, which may take none.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum Primitive {
    Map,
    Gather,
    Scatter,
    Reduce,
    Scan,
    ExclusiveScan,
    Sort,
    SortByKey,
}

impl Primitive {
    pub const ALL: [Primitive; 8] = [
        Primitive::Map,
        Primitive::Gather,
        Primitive::Scatter,
        Primitive::Reduce,
        Primitive::Scan,
        Primitive::ExclusiveScan,
        Primitive::Sort,
        Primitive::SortByKey,
    ];

    /// The name as written in a pipeline.
    pub fn name(self) -> &'static str {
        match self {
            Primitive::Map => "map",
            Primitive::Gather => "gather",
            Primitive::Scatter => "scatter",
            Primitive::Reduce => "reduce",
            Primitive::Scan => "scan",
            Primitive::ExclusiveScan => "exclusiveScan",
            Primitive::Sort => "sort",
            Primitive::SortByKey => "sortByKey",
        }
    }

    pub fn from_name(name: &str) -> Option<Primitive> {
        Primitive::ALL.into_iter().find(|p| p.name() == name)
    }
}

impl std::fmt::Display for Primitive {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The built-in callees that take no functor and make or measure arrays.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum Generator {
    /// `iota(n)`: `0, 1, …, n-1`.
    Iota,
    /// `fill(n, value)`.
    Fill,
    /// `len(a)`: a host scalar.
    Len,
}

impl Generator {
    pub const ALL: [Generator; 3] = [Generator::Iota, Generator::Fill, Generator::Len];

    pub fn name(self) -> &'static str {
        match self {
            Generator::Iota => "iota",
            Generator::Fill => "fill",
            Generator::Len => "len",
        }
    }

    pub fn from_name(name: &str) -> Option<Generator> {
        Generator::ALL.into_iter().find(|g| g.name() == name)
    }
}

/// Where a plain `scatter` writes.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub enum ScatterTarget {
    /// `len: m`: a new zeroed array of length `m`.
    Len(HostExpr),
    /// `into: dst`: a copy of `dst`.
    Into(VarId),
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub enum OpKind {
    /// `a.field`: a view of one field of a record array (no copy outside a stage).
    Field { field: String },
    /// `iota(n)`: `out[i] = i`.
    Iota { count: HostExpr },
    /// `fill(n, value)`.
    Fill { count: HostExpr, value: HostExpr },
    /// `map<f>(inputs…)`.
    Map,
    /// An element-wise expression before desugaring (`a + 1.0`, `sqrt(x)`):
    /// the functor applied to arrays and host scalars, which the `desugar`
    /// pass turns into a `map` after broadcasting host scalars (`fill`) and
    /// `f32` arrays against vectors (`splat`). `inputs` holds the array
    /// operands, in order; never seen after type checking.
    Elementwise {
        operands: Vec<Operand>,
        /// The operator it was written with (`+`, `!`), for its errors; `None` for a call.
        operator: Option<&'static str>,
    },
    /// `gather(idx, src)`: inputs `[idx, src]`.
    Gather,
    /// `gather<f>(src, group: k)`: inputs `[src]`.
    GroupGather { group: HostExpr },
    /// `scatter<f>(src, fanout: k)`: inputs `[src]`.
    Expand { fanout: HostExpr },
    /// `scatter(idx, src, …)` and `scatter<f>(idx, src, into: dst)`: inputs `[idx, src]`.
    Scatter {
        target: ScatterTarget,
        mask: Option<VarId>,
        combine: Option<MonoidOp>,
    },
    /// `reduce<f>(a)`: the output is a host variable.
    Reduce { op: MonoidOp },
    /// `scan<f>(a)` / `exclusiveScan<f>(a)`.
    Scan {
        op: MonoidOp,
        exclusive: bool,
        segments: Option<VarId>,
    },
    /// `sort(keys)`: inputs `[keys]`, outputs `[sorted]`; `sortByKey(keys,
    /// values)`: inputs `[keys, values]`, outputs `[sortedKeys, sortedValues]`.
    /// Stable and ascending, f32 keys in the total order of their bits
    /// (docs/language.md §3, sort).
    Sort { by_key: bool },
}

/// An operand of an [`OpKind::Elementwise`] op.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub enum Operand {
    Array(VarId),
    Host(HostExpr),
}

/// One primitive application.
#[derive(Clone, Debug, Serialize)]
pub struct Op {
    pub kind: OpKind,
    /// The functor between angle brackets, if any.
    pub functor: Option<String>,
    pub inputs: Vec<VarId>,
    pub outputs: Vec<VarId>,
    /// The functor's named arguments in signature order, defaults filled in.
    pub named: Vec<(String, HostExpr)>,
    #[serde(skip)]
    pub span: Span,
}

/// The host expressions of an op, shared or mutable: one list of where they are.
macro_rules! op_host_exprs {
    ($op:expr, $iter:ident, $($reference:tt)+) => {{
        let mut exprs: Vec<$($reference)+ HostExpr> = $op.named.$iter().map(|(_, e)| e).collect();
        match $($reference)+ $op.kind {
            OpKind::Iota { count } => exprs.push(count),
            OpKind::Fill { count, value } => {
                exprs.push(count);
                exprs.push(value);
            }
            OpKind::GroupGather { group } => exprs.push(group),
            OpKind::Expand { fanout } => exprs.push(fanout),
            OpKind::Scatter {
                target: ScatterTarget::Len(len),
                ..
            } => exprs.push(len),
            OpKind::Elementwise { operands, .. } => {
                for operand in operands {
                    if let Operand::Host(expr) = operand {
                        exprs.push(expr);
                    }
                }
            }
            _ => {}
        }
        exprs
    }};
}

impl Op {
    /// The primitive the op applies; `None` for a field view, `iota` and `fill`.
    pub fn primitive(&self) -> Option<Primitive> {
        self.callee().ok()
    }

    /// The primitive the op applies, or else the name of the built-in it is.
    fn callee(&self) -> Result<Primitive, &'static str> {
        Ok(match self.kind {
            OpKind::Field { .. } => return Err("field"),
            OpKind::Iota { .. } => return Err(Generator::Iota.name()),
            OpKind::Fill { .. } => return Err(Generator::Fill.name()),
            OpKind::Map | OpKind::Elementwise { .. } => Primitive::Map,
            OpKind::Gather | OpKind::GroupGather { .. } => Primitive::Gather,
            OpKind::Expand { .. } | OpKind::Scatter { .. } => Primitive::Scatter,
            OpKind::Reduce { .. } => Primitive::Reduce,
            OpKind::Scan {
                exclusive: false, ..
            } => Primitive::Scan,
            OpKind::Scan {
                exclusive: true, ..
            } => Primitive::ExclusiveScan,
            OpKind::Sort { by_key: false } => Primitive::Sort,
            OpKind::Sort { by_key: true } => Primitive::SortByKey,
        })
    }

    /// `map<intersect>`, `gather`, `iota`, `.normal`.
    pub fn label(&self) -> String {
        if let OpKind::Field { field } = &self.kind {
            return format!(".{field}");
        }
        let name = self
            .callee()
            .map_or_else(|builtin| builtin, Primitive::name);
        match &self.functor {
            Some(f) => format!("{name}<{f}>"),
            None => name.to_string(),
        }
    }

    /// Every array variable the op reads, named arguments included.
    pub fn array_reads(&self) -> Vec<VarId> {
        let mut reads = self.inputs.clone();
        match &self.kind {
            OpKind::Scatter { target, mask, .. } => {
                if let ScatterTarget::Into(dst) = target {
                    reads.push(*dst);
                }
                reads.extend(mask);
            }
            OpKind::Scan { segments, .. } => reads.extend(segments),
            _ => {}
        }
        reads
    }

    /// Whether the op combines its stage's elements into a result that is
    /// complete only when the stage ends (scatter, reduce, scan, sort).
    pub fn is_sink(&self) -> bool {
        matches!(
            self.kind,
            OpKind::Scatter { .. }
                | OpKind::Reduce { .. }
                | OpKind::Scan { .. }
                | OpKind::Sort { .. }
        )
    }

    /// Every variable the op reads: its arrays and those its host expressions name.
    pub fn reads(&self) -> Vec<VarId> {
        let mut reads = self.array_reads();
        for expr in self.host_exprs() {
            expr.visit_vars(&mut |v| reads.push(v));
        }
        reads
    }

    /// Every host expression the op evaluates.
    pub fn host_exprs(&self) -> Vec<&HostExpr> {
        op_host_exprs!(self, iter, &)
    }

    /// [`Op::host_exprs`], to rewrite them (fusion replaces `len(v)` of a value
    /// its stage makes by `v`'s symbolic length).
    pub fn host_exprs_mut(&mut self) -> Vec<&mut HostExpr> {
        op_host_exprs!(self, iter_mut, &mut)
    }
}

/// Why a stage ends.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum Barrier {
    /// Fusion is off.
    Unfused,
    /// A scan needs every element before its result exists.
    Scan,
    /// A sort needs every key before any element's place is known.
    Sort,
    /// The host reads a reduce result.
    Reduce,
    /// A scatter writes through an index: its result is complete only at the end.
    Scatter,
    /// The next op runs over another number of elements (compaction, fan-out, group gather).
    LengthChange,
    /// The next op reads a value of this stage through an index (gather, group, fan-out source).
    IndexedRead,
    /// A loop, branch, host statement or the end of the block follows.
    ControlFlow,
}

impl Barrier {
    pub fn describe(self) -> &'static str {
        match self {
            Barrier::Unfused => "unfused",
            Barrier::Scan => "scan",
            Barrier::Sort => "sort",
            Barrier::Reduce => "reduce result read by the host",
            Barrier::Scatter => "scatter",
            Barrier::LengthChange => "length change",
            Barrier::IndexedRead => "indexed read of a value made here",
            Barrier::ControlFlow => "control flow",
        }
    }
}

/// One parallel pass: one kernel launch on the GPU, one parallel loop on the CPU.
#[derive(Clone, Debug, Serialize)]
pub struct Stage {
    pub ops: Vec<Op>,
    /// The number of elements the stage runs over, symbolically.
    pub index_space: Option<HostExpr>,
    /// Arrays read element by element at the stage's own index.
    pub reads_direct: Vec<VarId>,
    /// Arrays read through an index (gather sources, group and fan-out sources).
    pub reads_indexed: Vec<VarId>,
    /// Host variables and uniforms the stage's host expressions read.
    pub reads_uniform: Vec<String>,
    /// Variables the stage writes in full; every other output stays inside the stage.
    pub materialises: Vec<VarId>,
    pub barrier: Barrier,
    /// The stage's first ops when they run over groups of its elements
    /// (docs/language.md §6, rule 5): `None` for a stage of one level.
    pub inner: Option<InnerLevel>,
}

/// The inner level of a nested stage: its first `ops` ops run over
/// `index_space` elements, `k` for each of the stage's own, and the group
/// gather that follows them (its input the last of them) closes the level,
/// giving one value per element of the stage. No value of the inner level is
/// materialised or read by any node but the stage's own inner ops and that
/// group gather, so a backend may compute a group's inner values one element
/// of the stage at a time.
#[derive(Clone, Debug, Serialize)]
pub struct InnerLevel {
    pub ops: usize,
    pub index_space: Option<HostExpr>,
    /// Arrays the inner ops read element by element, at the inner index.
    pub reads_direct: Vec<VarId>,
}

impl Stage {
    /// The group gather that closes the inner level, if the stage has one.
    pub fn closing_group_gather(&self) -> Option<&Op> {
        self.inner.as_ref().map(|inner| &self.ops[inner.ops])
    }

    /// The number of ops at the inner level (0 for a stage of one level).
    pub fn inner_ops(&self) -> usize {
        self.inner.as_ref().map_or(0, |inner| inner.ops)
    }

    /// The stage's ops in order: `iota → map<cameraRay> → map<intersect>`.
    pub fn label(&self) -> String {
        self.ops
            .iter()
            .map(Op::label)
            .collect::<Vec<_>>()
            .join(" → ")
    }
}

#[derive(Clone, Debug, Serialize)]
pub enum Node {
    /// A primitive before fusion (lowering's output).
    Op(Op),
    Stage(Stage),
    /// A host scalar binding.
    Host {
        dst: VarId,
        expr: HostExpr,
        #[serde(skip)]
        span: Span,
    },
    /// `dst = src.field`: a view of one field of a record array; copies nothing.
    View {
        dst: VarId,
        src: VarId,
        field: String,
    },
    /// Rebinding an array name to another array (no copy: arrays are immutable).
    Alias {
        dst: VarId,
        src: VarId,
    },
    For {
        var: VarId,
        start: HostExpr,
        end: HostExpr,
        body: Vec<Node>,
        #[serde(skip)]
        span: Span,
    },
    While {
        cond: HostExpr,
        body: Vec<Node>,
        #[serde(skip)]
        span: Span,
    },
    If {
        #[serde(skip)]
        span: Span,
        cond: HostExpr,
        then_body: Vec<Node>,
        else_body: Vec<Node>,
    },
    Break,
    /// `composite<blend>(a, b, …)`: sort-last compositing across ranks.
    Composite(Box<Composite>),
    /// `out name = …`: the value of `var` when this runs becomes output `name`.
    Output {
        name: String,
        var: VarId,
    },
}

/// The callee of [`Composite`]: a reserved name like the primitives'.
pub const COMPOSITE: &str = "composite";

/// `(a#1, b#1) = composite<blend>(a, b)`: this rank's per-pixel arrays
/// `inputs` and every other rank's, composited into `outputs` — the whole
/// image, which only rank 0 goes on with: the run of every other rank ends
/// here. The schedule that moves the pieces is the run's (docs/language.md
/// §3, composite); how two pieces combine is `blend`, the nodes of the fn
/// `blend_fn` inlined with its parameters bound to `front` (the piece nearer
/// the front of the order) and `back`, leaving the blended arrays in
/// `blended`. With one rank `outputs` are `inputs` and `blend` never runs.
#[derive(Clone, Debug, Serialize)]
pub struct Composite {
    pub blend_fn: String,
    pub inputs: Vec<VarId>,
    pub outputs: Vec<VarId>,
    pub front: Vec<VarId>,
    pub back: Vec<VarId>,
    pub blend: Vec<Node>,
    pub blended: Vec<VarId>,
    /// Whether pieces go front to back in visibility order (translucent
    /// images) rather than rank order (nearest depth, ties to the lower rank).
    pub visibility: HostExpr,
    #[serde(skip)]
    pub span: Span,
}

#[derive(Clone, Debug, Serialize)]
pub struct ParamInfo {
    pub name: String,
    pub var: VarId,
    pub ty: HostType,
    pub value: HostValue,
    /// Whether `--set` overrode the file's value.
    pub overridden: bool,
}

#[derive(Clone, Debug, Serialize)]
pub struct Plan {
    pub pipeline: String,
    pub fused: bool,
    pub params: Vec<ParamInfo>,
    pub vars: Vec<VarInfo>,
    pub body: Vec<Node>,
    /// Output names in declaration order.
    pub outputs: Vec<String>,
}

impl Plan {
    pub fn var(&self, id: VarId) -> &VarInfo {
        &self.vars[id.0 as usize]
    }

    pub fn var_mut(&mut self, id: VarId) -> &mut VarInfo {
        &mut self.vars[id.0 as usize]
    }

    /// Every stage in execution order of the text (loops and branches flattened).
    pub fn stages(&self) -> Vec<&Stage> {
        fn walk<'a>(nodes: &'a [Node], out: &mut Vec<&'a Stage>) {
            for node in nodes {
                match node {
                    Node::Stage(s) => out.push(s),
                    Node::For { body, .. } | Node::While { body, .. } => walk(body, out),
                    Node::Composite(composite) => walk(&composite.blend, out),
                    Node::If {
                        then_body,
                        else_body,
                        ..
                    } => {
                        walk(then_body, out);
                        walk(else_body, out);
                    }
                    _ => {}
                }
            }
        }
        let mut out = Vec::new();
        walk(&self.body, &mut out);
        out
    }

    /// Every uniform the plan reads, `(record, field)`, sorted and once each:
    /// what a run's scene must provide (`dpp run` checks it before running).
    pub fn uniforms_read(&self) -> Vec<(String, String)> {
        let mut exprs: Vec<&HostExpr> = Vec::new();
        walk_nodes(&self.body, &mut |node| match node {
            Node::Op(op) => exprs.extend(op.host_exprs()),
            Node::Stage(stage) => {
                exprs.extend(&stage.index_space);
                exprs.extend(stage.ops.iter().flat_map(Op::host_exprs));
            }
            Node::Host { expr, .. } => exprs.push(expr),
            Node::For { start, end, .. } => exprs.extend([start, end]),
            Node::While { cond, .. } | Node::If { cond, .. } => exprs.push(cond),
            Node::Composite(composite) => exprs.push(&composite.visibility),
            Node::View { .. } | Node::Alias { .. } | Node::Break | Node::Output { .. } => {}
        });
        let mut uniforms = Vec::new();
        for expr in exprs {
            expr.visit_uniforms(&mut |record, field| {
                uniforms.push((record.to_string(), field.to_string()))
            });
        }
        uniforms.sort();
        uniforms.dedup();
        uniforms
    }
}

/// Visits every node of a body, depth first, in order.
pub fn walk_nodes<'a>(nodes: &'a [Node], visit: &mut impl FnMut(&'a Node)) {
    for node in nodes {
        visit(node);
        match node {
            Node::For { body, .. } | Node::While { body, .. } => walk_nodes(body, visit),
            Node::Composite(composite) => walk_nodes(&composite.blend, visit),
            Node::If {
                then_body,
                else_body,
                ..
            } => {
                walk_nodes(then_body, visit);
                walk_nodes(else_body, visit);
            }
            _ => {}
        }
    }
}

impl HostExpr {
    /// Every uniform the expression reads, as record and field.
    pub fn visit_uniforms(&self, visit: &mut impl FnMut(&str, &str)) {
        match self {
            HostExpr::Uniform { record, field } => visit(record, field),
            HostExpr::Const(_) | HostExpr::Var(_) | HostExpr::Len(_) => {}
            HostExpr::Unary(_, e) => e.visit_uniforms(visit),
            HostExpr::Binary(_, a, b) => {
                a.visit_uniforms(visit);
                b.visit_uniforms(visit);
            }
            HostExpr::Call(_, args) => args.iter().for_each(|a| a.visit_uniforms(visit)),
        }
    }

    /// Every host variable and array (through `len`) the expression reads.
    pub fn visit_vars(&self, visit: &mut impl FnMut(VarId)) {
        match self {
            HostExpr::Const(_) | HostExpr::Uniform { .. } => {}
            HostExpr::Var(v) | HostExpr::Len(v) => visit(*v),
            HostExpr::Unary(_, e) => e.visit_vars(visit),
            HostExpr::Binary(_, a, b) => {
                a.visit_vars(visit);
                b.visit_vars(visit);
            }
            HostExpr::Call(_, args) => args.iter().for_each(|a| a.visit_vars(visit)),
        }
    }
}

/// Every variable a node reads directly (not those of nested bodies).
pub fn node_reads(node: &Node) -> Vec<VarId> {
    let mut reads = Vec::new();
    let host = |e: &HostExpr, reads: &mut Vec<VarId>| e.visit_vars(&mut |v| reads.push(v));
    match node {
        Node::Op(op) => reads.extend(op.reads()),
        Node::Stage(stage) => reads.extend(stage.ops.iter().flat_map(Op::reads)),
        Node::Host { expr, .. } => host(expr, &mut reads),
        Node::Alias { src, .. } | Node::View { src, .. } => reads.push(*src),
        Node::For { start, end, .. } => {
            host(start, &mut reads);
            host(end, &mut reads);
        }
        Node::While { cond, .. } | Node::If { cond, .. } => host(cond, &mut reads),
        Node::Composite(composite) => {
            reads.extend(&composite.inputs);
            host(&composite.visibility, &mut reads);
        }
        Node::Break => {}
        Node::Output { var, .. } => reads.push(*var),
    }
    reads
}

/// Every variable a node writes (not those of nested bodies).
pub fn node_writes(node: &Node) -> Vec<VarId> {
    match node {
        Node::Op(op) => op.outputs.clone(),
        Node::Stage(stage) => stage.ops.iter().flat_map(|op| op.outputs.clone()).collect(),
        Node::Host { dst, .. } | Node::Alias { dst, .. } | Node::View { dst, .. } => vec![*dst],
        Node::For { var, .. } => vec![*var],
        // `front` and `back` are bound before each run of the blend, like a loop's counter.
        Node::Composite(composite) => (composite.outputs.iter())
            .chain(&composite.front)
            .chain(&composite.back)
            .copied()
            .collect(),
        _ => Vec::new(),
    }
}
