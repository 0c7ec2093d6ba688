//! One stage as one compute shader: each op of the stage becomes WGSL
//! statements in plan order, values live in locals, whole arrays are read
//! through generated accessors, and what the stage materialises is stored at
//! the end. Each sink (scatter, reduce, scan, sort; a stage may end in several
//! scatters) either completes in the kernel (combining scatter, through
//! atomics) or leaves its inputs in arrays for the sink kernels that follow
//! (see `exec.rs`).

use crate::array::{allocate_array, copy_array, GpuArray};
use crate::backend::GpuBackend;
use crate::monoid;
use crate::shader::{Access, ShaderBuilder};
use dpp_runtime::compile::ir::*;
use dpp_runtime::interpret::{elementwise_materialised, RunError, Slots, StageCall};
use dpp_runtime::signature::FunctorKind;
use dpp_runtime::types::ElemType;
use dpp_runtime::wgsl::{collect_dependencies, elem_type_wgsl, WgslRequest};
use std::collections::HashMap;
use std::fmt::Write;

/// A value inside the stage.
#[derive(Clone)]
enum Value {
    /// A WGSL local.
    Local(String),
    /// A whole array, read at the stage's own index.
    Whole(GpuArray),
}

/// What the stage kernel leaves for the sink kernels (a combining scatter
/// leaves nothing: it completes in the stage kernel).
pub enum SinkWork {
    /// A plain scatter: `winner[t]` holds 1 + the last position writing slot `t`.
    Scatter {
        indices: GpuArray,
        values: GpuArray,
        mask: Option<GpuArray>,
        winner: GpuArray,
        target: GpuArray,
    },
    Reduce {
        op: dpp_runtime::monoid::MonoidOp,
        values: GpuArray,
    },
    Scan {
        op: dpp_runtime::monoid::MonoidOp,
        exclusive: bool,
        values: GpuArray,
        flags: Option<GpuArray>,
    },
    /// `sort` and `sortByKey`: the keys, and the values with the variable
    /// that gets them sorted.
    Sort {
        keys: GpuArray,
        values: Option<(GpuArray, VarId)>,
    },
}

pub struct StageKernel<'r> {
    pub builder: ShaderBuilder<'r>,
    /// One per sink of the stage, in stage order, with the sink's result.
    pub sinks: Vec<(VarId, SinkWork)>,
}

/// Generates the stage's kernel; allocates (and records in `slots`) the
/// arrays it materialises. Copies for `scatter(…, into: dst)` go to `encoder`.
pub fn build_stage_kernel<'r>(
    backend: &GpuBackend<'_>,
    call: &StageCall<'r>,
    slots: &mut Slots<GpuArray>,
    builder: ShaderBuilder<'r>,
    encoder: &mut wgpu::CommandEncoder,
) -> Result<StageKernel<'r>, RunError> {
    let mut generator = Generator {
        backend,
        call,
        builder,
        locals: HashMap::new(),
        twins: Vec::new(),
    };
    let sinks = generator.ops(slots, encoder)?;
    generator.materialise(slots)?;
    generator.emit_twins()?;
    Ok(StageKernel {
        builder: generator.builder,
        sinks,
    })
}

struct Generator<'b, 'c, 'r> {
    backend: &'b GpuBackend<'c>,
    call: &'b StageCall<'r>,
    builder: ShaderBuilder<'r>,
    locals: HashMap<VarId, Value>,
    twins: Vec<dpp_runtime::wgsl::WgslTwin>,
}

impl Generator<'_, '_, '_> {
    fn lookup(&self, slots: &Slots<GpuArray>, var: VarId) -> Result<Value, RunError> {
        match self.locals.get(&var) {
            Some(v) => Ok(v.clone()),
            None => Ok(Value::Whole(slots.array(self.call.plan, var)?.clone())),
        }
    }

    /// The value as a WGSL expression at the stage's index.
    fn expression(&mut self, value: &Value) -> String {
        match value {
            Value::Local(name) => name.clone(),
            Value::Whole(array) => {
                let loader = self.builder.array_loader(array);
                format!("{loader}(i)")
            }
        }
    }

    fn bind(&mut self, var: VarId, expression: String) {
        let name = self.builder.local();
        let _ = writeln!(self.builder.body, "    let {name} = {expression};");
        self.locals.insert(var, Value::Local(name));
    }

    fn ops(
        &mut self,
        slots: &mut Slots<GpuArray>,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<Vec<(VarId, SinkWork)>, RunError> {
        let call = self.call;
        let mut sinks = Vec::new();
        // A nested stage's inner ops become the body of the function its
        // closing group gather reads them through, at the inner index (its
        // `i`); the kernel's own body waits here meanwhile.
        let inner_ops = call.stage.inner_ops();
        let mut kernel_body = None;
        for (position, (op, values)) in call.stage.ops.iter().zip(&call.host_values).enumerate() {
            if position == 0 && inner_ops > 0 {
                kernel_body = Some(std::mem::take(&mut self.builder.body));
            }
            match &op.kind {
                OpKind::Iota { .. } => self.bind(op.outputs[0], "i".into()),
                OpKind::Fill { .. } => {
                    let value = values.fill.expect("fill value");
                    let expression = self
                        .builder
                        .param_element(value)
                        .map_err(RunError::internal)?;
                    self.bind(op.outputs[0], expression);
                }
                OpKind::Field { field } => {
                    let source = self.lookup(slots, op.inputs[0])?;
                    let ElemType::Record(record) = call.elem_type(op.inputs[0]) else {
                        return Err(RunError::internal("field of a non-record array"));
                    };
                    let index = call
                        .records
                        .get(record)
                        .field_index(field)
                        .expect("type-checked field");
                    let value = match source {
                        Value::Local(name) => Value::Local(format!("{name}.{field}")),
                        Value::Whole(array) => Value::Whole(GpuArray {
                            ty: array.fields[index].ty,
                            len: array.len,
                            fields: vec![array.fields[index].clone()],
                        }),
                    };
                    self.locals.insert(op.outputs[0], value);
                }
                OpKind::Map => {
                    let (function, kind) = self.twin(position, op, slots)?;
                    let inputs: Vec<Value> = op
                        .inputs
                        .iter()
                        .map(|v| self.lookup(slots, *v))
                        .collect::<Result<_, _>>()?;
                    let mut arguments: Vec<String> = Vec::new();
                    if kind == FunctorKind::Map {
                        arguments.push("i".into());
                    }
                    for input in &inputs {
                        arguments.push(self.expression(input));
                    }
                    self.named_arguments(op, values, &mut arguments)?;
                    self.bind(
                        op.outputs[0],
                        format!("{function}({})", arguments.join(", ")),
                    );
                }
                OpKind::Gather => {
                    let index = self.lookup(slots, op.inputs[0])?;
                    let index = self.expression(&index);
                    let source = slots.array(call.plan, op.inputs[1])?.clone();
                    let loader = self.builder.array_loader(&source);
                    let len = self.builder.param_u32(source.len as u32);
                    let code = self.backend.failure(
                        "gather index {a} (at position {b}) is out of range for its source array",
                    );
                    let name = self.builder.local();
                    let _ = writeln!(
                        self.builder.body,
                        "    let {name}_index = {index};\n    if ({name}_index >= {len}) {{ dpp_fail({code}u, {name}_index, i); }}"
                    );
                    self.bind(op.outputs[0], format!("{loader}({name}_index)"));
                }
                OpKind::GroupGather { .. } => {
                    let (function, _) = self.twin(position, op, slots)?;
                    let ty = elem_type_wgsl(call.elem_type(op.inputs[0]), call.records);
                    match self.lookup(slots, op.inputs[0])? {
                        Value::Local(value) if position == inner_ops && inner_ops > 0 => {
                            let kernel_body = kernel_body.take().unwrap_or_default();
                            let inner_body = std::mem::replace(&mut self.builder.body, kernel_body);
                            let _ = writeln!(
                                self.builder.functions,
                                "fn {function}_src(i: u32) -> {ty} {{\n{inner_body}    return {value};\n}}"
                            );
                            for output in call.stage.ops[..inner_ops]
                                .iter()
                                .flat_map(|op| &op.outputs)
                            {
                                self.locals.remove(output);
                            }
                        }
                        Value::Whole(source) => {
                            let loader = self.builder.array_loader(&source);
                            let _ = writeln!(
                                self.builder.functions,
                                "fn {function}_src(i: u32) -> {ty} {{ return {loader}(i); }}"
                            );
                        }
                        // A gather of groups of one after other ops of its stage
                        // (`fuse::is_elementwise_group`) reads the element's own
                        // value, which the twin's reader finds in a private variable.
                        Value::Local(value) => {
                            let _ = writeln!(
                                self.builder.functions,
                                "var<private> {function}_value: {ty};\nfn {function}_src(i: u32) -> {ty} {{ return {function}_value; }}"
                            );
                            let _ = writeln!(self.builder.body, "    {function}_value = {value};");
                        }
                    }
                    let k = self.builder.param_u32(values.group as u32);
                    let mut arguments = vec![format!("i * {k}"), k];
                    self.named_arguments(op, values, &mut arguments)?;
                    self.bind(
                        op.outputs[0],
                        format!("{function}({})", arguments.join(", ")),
                    );
                }
                OpKind::Expand { .. } => {
                    let (function, _) = self.twin(position, op, slots)?;
                    let source = slots.array(call.plan, op.inputs[0])?.clone();
                    let loader = self.builder.array_loader(&source);
                    let k = self.builder.param_u32(values.group as u32);
                    let name = self.builder.local();
                    let _ = writeln!(
                        self.builder.body,
                        "    let {name}_source = i / {k};\n    let {name}_lane = i - {name}_source * {k};"
                    );
                    let mut arguments = vec![
                        format!("{name}_source"),
                        format!("{loader}({name}_source)"),
                        format!("{name}_lane"),
                        k,
                    ];
                    self.named_arguments(op, values, &mut arguments)?;
                    self.bind(
                        op.outputs[0],
                        format!("{function}({})", arguments.join(", ")),
                    );
                }
                OpKind::Scatter {
                    target,
                    mask,
                    combine,
                } => {
                    let ty = call.elem_type(op.outputs[0]);
                    let target = match target {
                        ScatterTarget::Len(_) => allocate_array(
                            self.backend.gpu,
                            ty,
                            values.scatter_len.unwrap_or_default(),
                            call.records,
                            &self.backend.buffers,
                        )
                        .map_err(RunError::from)?,
                        ScatterTarget::Into(dst) => copy_array(
                            self.backend.gpu,
                            encoder,
                            slots.array(call.plan, *dst)?,
                            &self.backend.buffers,
                        )
                        .map_err(RunError::from)?,
                    };
                    let index = self.lookup(slots, op.inputs[0])?;
                    let index = self.expression(&index);
                    let value = self.lookup(slots, op.inputs[1])?;
                    let mask_value = match mask {
                        Some(m) => Some(self.lookup(slots, *m)?),
                        None => None,
                    };
                    let condition = match &mask_value {
                        Some(m) => self.expression(m),
                        None => "true".into(),
                    };
                    let len = self.builder.param_u32(target.len as u32);
                    let code = self.backend.failure(
                        "scatter index {a} (at position {b}) is out of range for its target array",
                    );
                    let name = self.builder.local();
                    let _ = writeln!(
                        self.builder.body,
                        "    let {name}_index = {index};\n    let {name}_used = {condition};\n    if ({name}_used && {name}_index >= {len}) {{ dpp_fail({code}u, {name}_index, i); }}\n    let {name}_write = {name}_used && {name}_index < {len};"
                    );
                    match combine {
                        Some(monoid_op) => {
                            let value = self.expression(&value);
                            let field = self.builder.field(&target.fields[0], Access::Atomic);
                            let update = monoid::atomic_update(
                                *monoid_op,
                                ty,
                                &field,
                                &mut self.builder.functions,
                            )
                            .map_err(RunError::internal)?;
                            let components: Vec<String> = match ty {
                                ElemType::Vec2 | ElemType::Vec3 | ElemType::Vec4 => {
                                    ["x", "y", "z", "w"][..crate::array::words_of(ty)]
                                        .iter()
                                        .map(|c| format!("{name}_value.{c}"))
                                        .collect()
                                }
                                _ => vec![format!("{name}_value")],
                            };
                            let _ = writeln!(
                                self.builder.body,
                                "    if ({name}_write) {{\n        let {name}_value = {value};"
                            );
                            for (j, component) in components.iter().enumerate() {
                                let _ = writeln!(
                                    self.builder.body,
                                    "        {update}({name}_index, {j}u, {component});"
                                );
                            }
                            self.builder.body.push_str("    }\n");
                            slots.set_array(op.outputs[0], target);
                        }
                        None => {
                            let winner = allocate_array(
                                self.backend.gpu,
                                ElemType::U32,
                                target.len,
                                call.records,
                                &self.backend.buffers,
                            )
                            .map_err(RunError::from)?;
                            let field = self.builder.field(&winner.fields[0], Access::Atomic);
                            let update = monoid::atomic_update(
                                dpp_runtime::monoid::MonoidOp::Max,
                                ElemType::U32,
                                &field,
                                &mut self.builder.functions,
                            )
                            .map_err(RunError::internal)?;
                            let _ = writeln!(
                                self.builder.body,
                                "    if ({name}_write) {{ {update}({name}_index, 0u, i + 1u); }}"
                            );
                            let indices = self.keep(op.inputs[0], slots)?;
                            let values = self.keep(op.inputs[1], slots)?;
                            let mask = match mask {
                                Some(m) => Some(self.keep(*m, slots)?),
                                None => None,
                            };
                            sinks.push((
                                op.outputs[0],
                                SinkWork::Scatter {
                                    indices,
                                    values,
                                    mask,
                                    winner,
                                    target,
                                },
                            ));
                        }
                    }
                }
                OpKind::Reduce { op: monoid_op } => {
                    let values = self.keep(op.inputs[0], slots)?;
                    sinks.push((
                        op.outputs[0],
                        SinkWork::Reduce {
                            op: *monoid_op,
                            values,
                        },
                    ));
                }
                OpKind::Scan {
                    op: monoid_op,
                    exclusive,
                    segments,
                } => {
                    let values = self.keep(op.inputs[0], slots)?;
                    let flags = match segments {
                        Some(f) => Some(self.keep(*f, slots)?),
                        None => None,
                    };
                    sinks.push((
                        op.outputs[0],
                        SinkWork::Scan {
                            op: *monoid_op,
                            exclusive: *exclusive,
                            values,
                            flags,
                        },
                    ));
                }
                OpKind::Sort { .. } => {
                    let keys = self.keep(op.inputs[0], slots)?;
                    let values = match op.inputs.get(1) {
                        Some(&v) => Some((self.keep(v, slots)?, op.outputs[1])),
                        None => None,
                    };
                    sinks.push((op.outputs[0], SinkWork::Sort { keys, values }));
                }
                OpKind::Elementwise { .. } => {
                    return Err(RunError::internal(format!(
                        "`{}` reached the GPU backend before the compiler made it a map",
                        op.label()
                    )))
                }
            }
        }
        Ok(sinks)
    }

    /// The op's named arguments as parameter words, in signature order.
    fn named_arguments(
        &mut self,
        op: &Op,
        values: &dpp_runtime::interpret::OpHostValues,
        arguments: &mut Vec<String>,
    ) -> Result<(), RunError> {
        for ((name, _), value) in op.named.iter().zip(&values.named) {
            let expression = self.builder.param_host(*value).map_err(|e| {
                RunError::bad_input(format!("`{}` argument `{name}`: {e}", op.label()))
            })?;
            arguments.push(expression);
        }
        Ok(())
    }

    /// `var` as an array of the stage's length, for a sink kernel: the array
    /// itself when the stage reads it whole, else stored by the stage kernel.
    fn keep(&mut self, var: VarId, slots: &Slots<GpuArray>) -> Result<GpuArray, RunError> {
        match self.lookup(slots, var)? {
            Value::Whole(array) => Ok(array),
            Value::Local(name) => self.store_in_new_array(var, &name),
        }
    }

    /// Stores what the stage materialises (besides a sink's result).
    fn materialise(&mut self, slots: &mut Slots<GpuArray>) -> Result<(), RunError> {
        for var in elementwise_materialised(self.call.stage) {
            let array = self.keep(var, slots)?;
            slots.set_array(var, array);
        }
        Ok(())
    }

    /// A new array of `var`'s type and the stage's length, which the kernel
    /// fills with local `name` at every index.
    fn store_in_new_array(&mut self, var: VarId, name: &str) -> Result<GpuArray, RunError> {
        let array = allocate_array(
            self.backend.gpu,
            self.call.elem_type(var),
            self.call.len,
            self.call.records,
            &self.backend.buffers,
        )
        .map_err(RunError::from)?;
        let store = self.builder.array_store(&array, "i", name);
        self.builder.body.push_str("    ");
        self.builder.body.push_str(&store);
        Ok(array)
    }

    /// Asks the op's functor for its twin and adds it; returns its function
    /// name and the functor's kind (which decides how it is called).
    fn twin(
        &mut self,
        position: usize,
        op: &Op,
        slots: &Slots<GpuArray>,
    ) -> Result<(String, FunctorKind), RunError> {
        let call = self.call;
        let name = op.functor.as_deref().unwrap_or_default();
        let functor = self.backend.library.get(name).ok_or_else(|| {
            RunError::internal(format!("functor `{name}` is not in this run's library"))
        })?;
        let inputs: Vec<ElemType> = op
            .inputs
            .iter()
            .map(|v| match self.locals.get(v) {
                Some(_) => Ok(call.elem_type(*v)),
                None => slots.array(call.plan, *v).map(|a| a.ty),
            })
            .collect::<Result<_, _>>()?;
        let outputs: Vec<ElemType> = op.outputs.iter().map(|v| call.elem_type(*v)).collect();
        if outputs.len() != 1 {
            return Err(RunError::bad_input(format!(
                "`{}` has {} outputs; GPU twins have one",
                op.label(),
                outputs.len()
            )));
        }
        let function = format!("op{position}_{name}");
        let twin = functor
            .wgsl(&WgslRequest {
                function: &function,
                inputs: &inputs,
                outputs: &outputs,
                records: call.records,
                resources: self.backend.resources,
            })
            .map_err(RunError::from)?;
        // The twin's failures, numbered by the backend. Twins do not know the
        // element index, so the failure reports only the code.
        let mut fail = format!("fn {function}_fail(code: u32) {{\n    switch code {{\n");
        for (local, message) in twin.failures.iter().enumerate() {
            let code = self.backend.failure(&format!("{}: {message}", op.label()));
            let _ = writeln!(
                fail,
                "        case {local}u: {{ dpp_fail({code}u, 0u, 0u); }}"
            );
        }
        let unknown = self
            .backend
            .failure(&format!("{}: failure {{a}} without a message", op.label()));
        let _ = writeln!(
            fail,
            "        default: {{ dpp_fail({unknown}u, code, 0u); }}\n    }}\n}}"
        );
        self.builder.functions.push_str(&fail);
        self.twins.push(twin);
        Ok((function, functor.signature().kind))
    }

    /// Adds the twins' shared modules and scene buffers, then the twins themselves.
    fn emit_twins(&mut self) -> Result<(), RunError> {
        let mut modules = Vec::new();
        let mut buffers = Vec::new();
        for twin in &self.twins {
            collect_dependencies(twin, &mut modules, &mut buffers);
        }
        for buffer in &buffers {
            let device_buffer = self.backend.scene_buffer(buffer)?;
            self.builder
                .bind_named(buffer.name, buffer.wgsl_type, device_buffer);
        }
        let mut text = String::new();
        for module in &modules {
            text.push_str(&module.source);
            text.push('\n');
        }
        for twin in &self.twins {
            text.push_str(&twin.source);
            text.push('\n');
        }
        self.builder.functions.push_str(&text);
        Ok(())
    }
}
