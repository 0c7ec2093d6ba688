//! One run on the device: the context, the functors and the run's uniform
//! and status buffers, failure messages and arrays, which the stage kernels
//! (`stage`) and the executor (`exec`) share. `exec` adds the running.

use crate::array::RunBuffers;
use crate::device::GpuContext;
use dpp_runtime::functor::FunctorLibrary;
use dpp_runtime::interpret::RunError;
use dpp_runtime::wgsl::GpuBuffer;
use std::any::Any;
use std::sync::{Arc, Mutex};
use wgpu::util::DeviceExt;

pub struct GpuBackend<'a> {
    pub gpu: &'a GpuContext,
    pub library: &'a FunctorLibrary,
    pub resources: &'a (dyn Any + Send + Sync),
    pub(crate) profile: bool,
    /// Record structs and uniform accessors: the start of every shader.
    pub(crate) prelude: String,
    pub(crate) uniforms: wgpu::Buffer,
    pub(crate) status: wgpu::Buffer,
    /// Failure messages; code `n` is entry `n - 1`. `{a}`, `{b}` are filled
    /// from the status words.
    pub(crate) failures: Mutex<Vec<String>>,
    /// Where the run's arrays leave their buffers for later runs.
    pub(crate) buffers: Arc<RunBuffers>,
}

impl GpuBackend<'_> {
    /// The code of a failure message (the same message, the same code, so a
    /// stage's shader text does not change between runs).
    pub fn failure(&self, message: &str) -> u32 {
        let mut failures = self.failures.lock().expect("failure table");
        let index = match failures.iter().position(|m| m == message) {
            Some(index) => index,
            None => {
                failures.push(message.to_string());
                failures.len() - 1
            }
        };
        index as u32 + 1
    }

    /// The device copy of a scene buffer, uploaded once per context.
    pub fn scene_buffer(&self, buffer: &GpuBuffer) -> Result<wgpu::Buffer, RunError> {
        let bytes = (buffer.data.len() * 4) as u64;
        if bytes > self.gpu.limits.device_max_binding_bytes {
            return Err(RunError::resource_limit(format!(
                "scene buffer `{}` has {bytes} bytes, above the adapter `{}`'s largest storage binding ({} bytes)",
                buffer.name,
                self.gpu.adapter_name(),
                self.gpu.limits.device_max_binding_bytes
            )));
        }
        let key = (
            buffer.name,
            Arc::as_ptr(&buffer.data) as *const u32 as usize,
        );
        let mut cache = self.gpu.scene_buffers.lock().expect("scene buffer cache");
        if let Some((data, device_buffer)) = cache.get(&key) {
            if Arc::ptr_eq(data, &buffer.data) {
                return Ok(device_buffer.clone());
            }
        }
        let mut contents: &[u32] = &buffer.data;
        let placeholder = [0u32];
        if contents.is_empty() {
            contents = &placeholder;
        }
        let device_buffer = self
            .gpu
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(buffer.name),
                contents: bytemuck::cast_slice(contents),
                usage: wgpu::BufferUsages::STORAGE,
            });
        cache.insert(key, (buffer.data.clone(), device_buffer.clone()));
        Ok(device_buffer)
    }
}
