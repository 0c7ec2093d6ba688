//! Running plans on the device: the [`Backend`] the shared interpreter drives.
//! Each stage is encoded as one command buffer: buffer copies, then one
//! compute pass with the stage kernel and its sink kernels. The host waits
//! only where it must read: a `reduce` result the plan's control flow uses,
//! the outputs, and (when profiling) the end of every stage.

use crate::array::{allocate_array, download, download_words, wait, GpuArray, RunBuffers};
use crate::backend::GpuBackend;
use crate::device::{GpuContext, GpuError};
use crate::monoid;
use crate::shader::{Access, Binding, ShaderBuilder, WORKGROUP};
use crate::stage::{build_stage_kernel, SinkWork};
use dpp_runtime::column::Column;
use dpp_runtime::functor::FunctorLibrary;
use dpp_runtime::host::{HostValue, Uniforms};
use dpp_runtime::interpret::{
    interpret_observed, Backend, RunError, RunHooks, RunResult, Slots, StageCall, StageMeasurement,
};
use dpp_runtime::monoid::MonoidOp;
use dpp_runtime::types::ElemType;
use dpp_runtime::wgsl::{host_type_wgsl, record_structs};
use std::any::Any;
use std::fmt::Write;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use wgpu::util::DeviceExt;

mod radix_sort;

pub struct GpuRunContext<'a> {
    pub gpu: &'a GpuContext,
    pub library: &'a FunctorLibrary,
    pub uniforms: &'a Uniforms,
    /// Scene data for the functors' twins (see [`dpp_runtime::CallContext::resources`]).
    pub resources: &'a (dyn Any + Send + Sync),
    /// Wait for every stage and time it on the device (timestamp queries where
    /// the adapter has them, else host time around the wait).
    pub profile: bool,
}

/// Runs `plan` on the GPU.
pub fn run_plan_gpu(
    plan: &dpp_runtime::Plan,
    context: &GpuRunContext<'_>,
) -> Result<RunResult, RunError> {
    run_plan_gpu_with_inputs(plan, context, Vec::new(), RunHooks::default())
}

/// [`run_plan_gpu`] with the run's hooks: an observer told of every stage
/// before it is issued (the device may still be working on earlier stages),
/// the other ranks.
pub fn run_plan_gpu_observed(
    plan: &dpp_runtime::Plan,
    context: &GpuRunContext<'_>,
    hooks: RunHooks<'_>,
) -> Result<RunResult, RunError> {
    run_plan_gpu_with_inputs(plan, context, Vec::new(), hooks)
}

/// Runs `plan` with some array variables already on the device.
pub(crate) fn run_plan_gpu_with_inputs(
    plan: &dpp_runtime::Plan,
    context: &GpuRunContext<'_>,
    inputs: Vec<(dpp_runtime::compile::ir::VarId, GpuArray)>,
    hooks: RunHooks<'_>,
) -> Result<RunResult, RunError> {
    let gpu = context.gpu;
    let records = &context.library.records;
    let (uniform_words, uniform_accessors) = uniform_layout(context);
    let uniforms = gpu
        .device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("dpp uniforms"),
            contents: bytemuck::cast_slice(&uniform_words),
            usage: wgpu::BufferUsages::STORAGE,
        });
    let status = gpu
        .device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("dpp status"),
            contents: bytemuck::cast_slice(&[0u32; 4]),
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
        });
    let mut backend = GpuBackend {
        gpu,
        library: context.library,
        resources: context.resources,
        profile: context.profile,
        prelude: format!("{}{uniform_accessors}", record_structs(records)),
        uniforms,
        status,
        failures: Mutex::new(Vec::new()),
        buffers: RunBuffers::new(gpu),
    };
    let result = interpret_observed(plan, &mut backend, context.uniforms, records, inputs, hooks)?;
    backend.check_status()?;
    Ok(result)
}

/// The run's uniforms as words, and `fn uniform_{record}_{field}()` for each.
fn uniform_layout(context: &GpuRunContext<'_>) -> (Vec<u32>, String) {
    let mut words = Vec::new();
    let mut accessors = String::new();
    for (record, fields) in &context.library.uniforms.records {
        for (field, ty) in fields {
            let offset = words.len();
            let value = context.uniforms.get(record, field);
            let wgsl = host_type_wgsl(*ty);
            let float = |x: f32| x.to_bits();
            let (value_words, expression): (Vec<u32>, String) = match ty {
                dpp_runtime::HostType::Bool => (
                    vec![u32::from(value.and_then(|v| v.as_bool()).unwrap_or(false))],
                    format!("uniforms[{offset}] != 0u"),
                ),
                dpp_runtime::HostType::Int => (
                    vec![value.and_then(|v| v.as_int()).unwrap_or(0) as i32 as u32],
                    format!("bitcast<i32>(uniforms[{offset}])"),
                ),
                dpp_runtime::HostType::Float => (
                    vec![float(value.and_then(|v| v.as_f32()).unwrap_or(0.0))],
                    format!("bitcast<f32>(uniforms[{offset}])"),
                ),
                vector => {
                    let components: Vec<f32> = match (vector, value) {
                        (dpp_runtime::HostType::Vec2, v) => v
                            .and_then(|v| v.as_vec2())
                            .unwrap_or_default()
                            .to_array()
                            .to_vec(),
                        (dpp_runtime::HostType::Vec3, v) => v
                            .and_then(|v| v.as_vec3())
                            .unwrap_or_default()
                            .to_array()
                            .to_vec(),
                        (_, v) => v
                            .and_then(|v| v.as_vec4())
                            .unwrap_or_default()
                            .to_array()
                            .to_vec(),
                    };
                    let parts: Vec<String> = (0..components.len())
                        .map(|j| format!("bitcast<f32>(uniforms[{}])", offset + j))
                        .collect();
                    (
                        components.into_iter().map(float).collect(),
                        format!("{wgsl}({})", parts.join(", ")),
                    )
                }
            };
            words.extend(value_words);
            let _ = writeln!(
                accessors,
                "fn uniform_{record}_{field}() -> {wgsl} {{ return {expression}; }}"
            );
        }
    }
    if words.is_empty() {
        words.push(0);
    }
    (words, accessors)
}

/// A kernel ready to dispatch over `threads` invocations.
struct Dispatch {
    source: String,
    bindings: Vec<Binding>,
    params: Vec<u32>,
    threads: usize,
}

impl GpuBackend<'_> {
    fn builder(&self) -> ShaderBuilder<'_> {
        ShaderBuilder::new(&self.library.records, &self.status, &self.uniforms)
    }

    fn dispatch_of(&self, builder: ShaderBuilder<'_>, threads: usize) -> Dispatch {
        let mut source = self.prelude.clone();
        source.push_str(&builder.finish());
        Dispatch {
            source,
            bindings: builder.bindings,
            params: builder.params,
            threads,
        }
    }

    /// Encodes and submits `dispatches` after the copies already in `encoder`;
    /// returns the device time when profiling.
    fn submit(
        &self,
        mut encoder: wgpu::CommandEncoder,
        dispatches: Vec<Dispatch>,
    ) -> Result<Option<Duration>, RunError> {
        let gpu = self.gpu;
        let max_x = gpu.limits.max_workgroups_per_dimension.max(1) as usize;
        let mut prepared = Vec::new();
        for dispatch in dispatches {
            if dispatch.threads == 0 {
                continue;
            }
            if dispatch.bindings.len() > gpu.limits.max_storage_buffers_per_stage as usize {
                return Err(RunError::resource_limit(format!(
                    "a stage needs {} storage buffers, above the adapter `{}`'s max_storage_buffers_per_shader_stage of {}",
                    dispatch.bindings.len(),
                    gpu.adapter_name(),
                    gpu.limits.max_storage_buffers_per_stage
                )));
            }
            let groups = dispatch.threads.div_ceil(WORKGROUP as usize);
            let groups_x = groups.min(max_x);
            let groups_y = groups.div_ceil(groups_x);
            if groups_y > max_x {
                return Err(RunError::resource_limit(format!(
                    "{} invocations are more than the adapter `{}` can dispatch",
                    dispatch.threads,
                    gpu.adapter_name()
                )));
            }
            let mut params = dispatch.params.clone();
            params[0] = groups_x as u32;
            params[1] = dispatch.threads as u32;
            let pipeline = self.pipeline(&dispatch.source, &dispatch.bindings)?;
            let params_buffer = gpu
                .device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("dpp params"),
                    contents: bytemuck::cast_slice(&params),
                    usage: wgpu::BufferUsages::STORAGE,
                });
            let entries: Vec<wgpu::BindGroupEntry> = dispatch
                .bindings
                .iter()
                .enumerate()
                .map(|(n, binding)| wgpu::BindGroupEntry {
                    binding: n as u32,
                    resource: binding
                        .buffer
                        .as_ref()
                        .unwrap_or(&params_buffer)
                        .as_entire_binding(),
                })
                .collect();
            let bind_group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: None,
                layout: &pipeline.1,
                entries: &entries,
            });
            prepared.push((pipeline, bind_group, groups_x as u32, groups_y as u32));
        }
        let timestamps = (self.profile && gpu.timestamps).then(|| {
            let set = gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: None,
                ty: wgpu::QueryType::Timestamp,
                count: 2,
            });
            let resolve = gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: None,
                size: 16,
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            let read = gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: None,
                size: 16,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            (set, resolve, read)
        });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: None,
                timestamp_writes: timestamps.as_ref().map(|(set, _, _)| {
                    wgpu::ComputePassTimestampWrites {
                        query_set: set,
                        beginning_of_pass_write_index: Some(0),
                        end_of_pass_write_index: Some(1),
                    }
                }),
            });
            for (pipeline, bind_group, x, y) in &prepared {
                pass.set_pipeline(&pipeline.0);
                pass.set_bind_group(0, bind_group, &[]);
                pass.dispatch_workgroups(*x, *y, 1);
            }
        }
        if let Some((set, resolve, read)) = &timestamps {
            encoder.resolve_query_set(set, 0..2, resolve, 0);
            encoder.copy_buffer_to_buffer(resolve, 0, read, 0, 16);
        }
        let start = std::time::Instant::now();
        gpu.queue.submit([encoder.finish()]);
        if !self.profile {
            return Ok(None);
        }
        if let Some((_, _, read)) = &timestamps {
            read.slice(..).map_async(wgpu::MapMode::Read, |_| {});
        }
        wait(gpu).map_err(RunError::from)?;
        let host_time = start.elapsed();
        let Some((_, _, read)) = &timestamps else {
            return Ok(Some(host_time));
        };
        let view = read
            .slice(..)
            .get_mapped_range()
            .map_err(|e| RunError::device(format!("reading GPU timestamps failed: {e}")))?;
        let ticks: &[u64] = bytemuck::cast_slice(&view);
        let nanoseconds =
            ticks[1].saturating_sub(ticks[0]) as f64 * f64::from(gpu.queue.get_timestamp_period());
        drop(view);
        read.unmap();
        // Some drivers report zero for passes they time coarsely; fall back to host time.
        Ok(Some(if nanoseconds > 0.0 {
            Duration::from_nanos(nanoseconds as u64)
        } else {
            host_time
        }))
    }

    /// The compiled pipeline of a kernel source (cached by source text).
    fn pipeline(
        &self,
        source: &str,
        bindings: &[Binding],
    ) -> Result<Arc<(wgpu::ComputePipeline, wgpu::BindGroupLayout)>, RunError> {
        let mut cache = self.gpu.pipelines.lock().expect("pipeline cache");
        if let Some(found) = cache.get(source) {
            return Ok(found.clone());
        }
        // Validate first so a bad twin is a clear error, not a device loss.
        crate::validate_wgsl(source).map_err(|e| {
            RunError::internal(format!(
                "internal error: a generated GPU kernel does not compile:\n{e}"
            ))
        })?;
        let device = &self.gpu.device;
        let entries: Vec<wgpu::BindGroupLayoutEntry> = bindings
            .iter()
            .enumerate()
            .map(|(n, b)| wgpu::BindGroupLayoutEntry {
                binding: n as u32,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage {
                        read_only: b.read_only,
                    },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            })
            .collect();
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: None,
            entries: &entries,
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: None,
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: None,
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: None,
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some("main"),
            compilation_options: Default::default(),
            cache: None,
        });
        let entry = Arc::new((pipeline, layout));
        cache.insert(source.to_string(), entry.clone());
        Ok(entry)
    }

    /// Fails the run if a kernel recorded a failure (waits for the device).
    fn check_status(&self) -> Result<(), RunError> {
        let words = read_buffer_words(self.gpu, &self.status, 3).map_err(RunError::from)?;
        if words[0] == 0 {
            return Ok(());
        }
        let failures = self.failures.lock().expect("failure table");
        let message = failures
            .get(words[0] as usize - 1)
            .cloned()
            .unwrap_or_else(|| format!("unknown GPU failure {}", words[0]));
        // A twin raises what its CPU code returns as a functor error: the input.
        Err(RunError::bad_input(
            message
                .replace("{a}", &words[1].to_string())
                .replace("{b}", &words[2].to_string()),
        ))
    }

    /// The reduce kernels: blocks of `BLOCK` elements per invocation, level by
    /// level, until one element is left.
    fn reduce(
        &self,
        op: MonoidOp,
        values: &GpuArray,
        dispatches: &mut Vec<Dispatch>,
    ) -> Result<GpuArray, RunError> {
        let records = &self.library.records;
        let mut level = values.clone();
        loop {
            let blocks = level.len.div_ceil(BLOCK).max(1);
            let out = allocate_array(self.gpu, level.ty, blocks, records, &self.buffers)
                .map_err(RunError::from)?;
            let mut builder = self.builder();
            let combine = monoid::combine_function(op, level.ty, &mut builder.functions)
                .map_err(RunError::internal)?;
            let identity = monoid::identity(op, level.ty).map_err(RunError::internal)?;
            let load = builder.array_loader(&level);
            let n = builder.param_u32(level.len as u32);
            let store = builder.array_store(&out, "i", "running");
            let _ = write!(
                builder.body,
                "    let start = i * {BLOCK}u;\n    let end = min(start + {BLOCK}u, {n});\n\
                 \x20   var running = {identity};\n\
                 \x20   for (var j = start; j < end; j++) {{ running = {combine}(running, {load}(j)); }}\n\
                 \x20   {store}"
            );
            dispatches.push(self.dispatch_of(builder, blocks));
            if blocks == 1 {
                return Ok(out);
            }
            level = out;
        }
    }

    /// The scan kernels (see `scan_levels`); returns the scanned array.
    fn scan(
        &self,
        op: MonoidOp,
        inclusive: bool,
        values: &GpuArray,
        flags: Option<&GpuArray>,
        dispatches: &mut Vec<Dispatch>,
    ) -> Result<GpuArray, RunError> {
        let records = &self.library.records;
        let n = values.len;
        let out = allocate_array(self.gpu, values.ty, n, records, &self.buffers)
            .map_err(RunError::from)?;
        if n == 0 {
            return Ok(out);
        }
        let blocks = n.div_ceil(BLOCK);
        // Pass 1: each block's (value since its last segment start, started) pair.
        let totals = allocate_array(self.gpu, values.ty, blocks, records, &self.buffers)
            .map_err(RunError::from)?;
        let starts = allocate_array(self.gpu, ElemType::Bool, blocks, records, &self.buffers)
            .map_err(RunError::from)?;
        let identity = monoid::identity(op, values.ty).map_err(RunError::internal)?;
        {
            let (mut builder, combine, load, flag) = self.scan_builder(op, values, flags)?;
            let count = builder.param_u32(n as u32);
            let store_total = builder.array_store(&totals, "i", "running");
            let store_start = builder.array_store(&starts, "i", "started");
            let _ = write!(
                builder.body,
                "    let start = i * {BLOCK}u;\n    let end = min(start + {BLOCK}u, {count});\n\
                 \x20   var running = {identity};\n    var started = false;\n\
                 \x20   for (var j = start; j < end; j++) {{\n\
                 \x20       if ({flag}) {{ running = {load}(j); started = true; }} else {{ running = {combine}(running, {load}(j)); }}\n\
                 \x20   }}\n    {store_total}    {store_start}"
            );
            dispatches.push(self.dispatch_of(builder, blocks));
        }
        // Pass 2: carries. Block t starts from the inclusive segmented scan of
        // the totals up to block t - 1.
        let carries = if blocks > 1 {
            Some(self.scan(op, true, &totals, Some(&starts), dispatches)?)
        } else {
            None
        };
        // Pass 3: each block rescanned from its carry, as the CPU's scan_chunk.
        let (mut builder, combine, load, flag) = self.scan_builder(op, values, flags)?;
        let carry = match &carries {
            Some(c) => format!(
                "select({identity}, {}(max(i, 1u) - 1u), i > 0u)",
                builder.array_loader(c)
            ),
            None => identity.clone(),
        };
        let count = builder.param_u32(n as u32);
        let result = if inclusive { "running" } else { "before" };
        let store = builder.array_store(&out, "j", result);
        let _ = write!(
            builder.body,
            "    let start = i * {BLOCK}u;\n    let end = min(start + {BLOCK}u, {count});\n\
             \x20   var running = {carry};\n\
             \x20   for (var j = start; j < end; j++) {{\n\
             \x20       let restarts = {flag};\n\
             \x20       let value = {load}(j);\n\
             \x20       let before = select(running, {identity}, restarts);\n\
             \x20       running = select({combine}(running, value), value, restarts);\n\
             \x20       {store}\
             \x20   }}\n"
        );
        dispatches.push(self.dispatch_of(builder, blocks));
        Ok(out)
    }

    /// A scan kernel's builder with the monoid, the value loader and the
    /// segment flag of element `j` (`false` unsegmented) it reads.
    fn scan_builder(
        &self,
        op: MonoidOp,
        values: &GpuArray,
        flags: Option<&GpuArray>,
    ) -> Result<(ShaderBuilder<'_>, String, String, String), RunError> {
        let mut builder = self.builder();
        let combine = monoid::combine_function(op, values.ty, &mut builder.functions)
            .map_err(RunError::internal)?;
        let load = builder.array_loader(values);
        let flag = match flags {
            Some(f) => format!("{}(j)", builder.array_loader(f)),
            None => "false".into(),
        };
        Ok((builder, combine, load, flag))
    }

    /// The second pass of a plain scatter: the last writer of each slot writes.
    fn scatter_write(
        &self,
        indices: &GpuArray,
        values: &GpuArray,
        mask: Option<&GpuArray>,
        winner: &GpuArray,
        target: &GpuArray,
    ) -> Dispatch {
        let mut builder = self.builder();
        let index = builder.array_loader(indices);
        let value = builder.array_loader(values);
        let winner_load = builder.field(&winner.fields[0], Access::Read);
        let used = match mask {
            Some(m) => format!("{}(i)", builder.array_loader(m)),
            None => "true".into(),
        };
        let len = builder.param_u32(target.len as u32);
        let store = builder.array_store(target, "slot", &format!("{value}(i)"));
        let _ = write!(
            builder.body,
            "    let slot = {index}(i);\n\
             \x20   if ({used} && slot < {len} && {winner_load}_load(slot) == i + 1u) {{\n        {store}    }}\n"
        );
        self.dispatch_of(builder, indices.len)
    }
}

/// Elements per invocation in the reduce and scan kernels.
const BLOCK: usize = 256;

fn read_buffer_words(
    gpu: &GpuContext,
    buffer: &wgpu::Buffer,
    words: usize,
) -> Result<Vec<u32>, GpuError> {
    let field = crate::array::Field {
        ty: ElemType::U32,
        len: words,
        segment: words,
        buffers: vec![buffer.clone()],
        pool: None,
    };
    download_words(gpu, &field)
}

impl Backend for GpuBackend<'_> {
    type Array = GpuArray;

    fn len(array: &GpuArray) -> usize {
        array.len
    }

    fn field(&self, array: &GpuArray, index: usize) -> Option<GpuArray> {
        let field = array.fields.get(index)?;
        matches!(array.ty, ElemType::Record(_)).then(|| GpuArray {
            ty: field.ty,
            len: array.len,
            fields: vec![field.clone()],
        })
    }

    fn run_stage(
        &mut self,
        call: &StageCall<'_>,
        slots: &mut Slots<GpuArray>,
    ) -> Result<StageMeasurement, RunError> {
        let mut encoder = self.gpu.device.create_command_encoder(&Default::default());
        let builder = self.builder();
        let kernel = build_stage_kernel(self, call, slots, builder, &mut encoder)?;
        let mut dispatches = vec![self.dispatch_of(kernel.builder, call.len)];
        let mut reduced = Vec::new();
        for (output, sink) in &kernel.sinks {
            match sink {
                SinkWork::Scatter {
                    indices,
                    values,
                    mask,
                    winner,
                    target,
                } => {
                    dispatches.push(self.scatter_write(
                        indices,
                        values,
                        mask.as_ref(),
                        winner,
                        target,
                    ));
                    slots.set_array(*output, target.clone());
                }
                SinkWork::Reduce { op, values } => {
                    reduced.push((*output, *op, self.reduce(*op, values, &mut dispatches)?));
                }
                SinkWork::Scan {
                    op,
                    exclusive,
                    values,
                    flags,
                } => {
                    let out =
                        self.scan(*op, !exclusive, values, flags.as_ref(), &mut dispatches)?;
                    slots.set_array(*output, out);
                }
                SinkWork::Sort { keys, values } => {
                    let values_array = values.as_ref().map(|(array, _)| array);
                    let (sorted_keys, sorted_values) =
                        self.sort(keys, values_array, &mut dispatches)?;
                    slots.set_array(*output, sorted_keys);
                    if let (Some((_, var)), Some(sorted)) = (values, sorted_values) {
                        slots.set_array(*var, sorted);
                    }
                }
            }
        }
        let time = self.submit(encoder, dispatches)?;
        if !reduced.is_empty() {
            // The host needs the values now: wait, and check for failures first.
            self.check_status()?;
        }
        for (output, op, result) in reduced {
            let value = if call.len == 0 {
                dpp_runtime::monoid::identity(op, result.ty)
                    .map_err(RunError::from)?
                    .to_host()
            } else {
                element_to_host(
                    &download(self.gpu, &result, &self.library.records).map_err(RunError::from)?,
                )
            };
            slots.set_host(output, value);
        }
        if self.profile {
            self.check_status()?;
        }
        // One kernel (and its sinks' passes) per stage: not split by op.
        Ok(StageMeasurement {
            device_time: time,
            op_thread_times: Vec::new(),
            compiled: Vec::new(),
        })
    }

    fn to_column(&mut self, array: &GpuArray) -> Result<Arc<Column>, RunError> {
        self.check_status()?;
        download(self.gpu, array, &self.library.records)
            .map(Arc::new)
            .map_err(RunError::from)
    }

    fn upload(&mut self, column: Arc<Column>) -> Result<GpuArray, RunError> {
        crate::array::upload(self.gpu, &column).map_err(RunError::from)
    }
}

/// The single element of a one-element column as a host value.
fn element_to_host(column: &Column) -> HostValue {
    match column {
        Column::Bool(v) => HostValue::Bool(v[0]),
        Column::U32(v) => HostValue::Int(i64::from(v[0])),
        Column::I32(v) => HostValue::Int(i64::from(v[0])),
        Column::F32(v) => HostValue::Float(f64::from(v[0])),
        Column::Vec2(v) => HostValue::Vec2(v[0].to_array()),
        Column::Vec3(v) => HostValue::Vec3(v[0].to_array()),
        Column::Vec4(v) => HostValue::Vec4(v[0].to_array()),
        Column::Record { .. } => unreachable!("reductions are over primitives"),
    }
}
