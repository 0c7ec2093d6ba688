//! Finding an adapter and opening a device with the adapter's own limits.

use dpp_runtime::interpret::RunError;
use dpp_runtime::ErrorKind;
use std::fmt;

/// Why the GPU backend cannot start or cannot go on: a device failure, or a
/// limit of the adapter the work does not fit.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{message}")]
pub struct GpuError {
    pub kind: ErrorKind,
    pub message: String,
}

impl GpuError {
    pub fn device(message: impl Into<String>) -> GpuError {
        GpuError {
            kind: ErrorKind::Device,
            message: message.into(),
        }
    }

    pub fn resource_limit(message: impl Into<String>) -> GpuError {
        GpuError {
            kind: ErrorKind::ResourceLimit,
            message: message.into(),
        }
    }

    pub fn internal(message: impl Into<String>) -> GpuError {
        GpuError {
            kind: ErrorKind::Internal,
            message: message.into(),
        }
    }
}

impl From<GpuError> for RunError {
    fn from(error: GpuError) -> RunError {
        RunError::new(error.kind, error.message)
    }
}

/// Keeps Mesa's Vulkan device-selection layer from probing a Wayland display
/// that cannot exist, which prints "error: XDG_RUNTIME_DIR is invalid or not
/// set in the environment." twice on every GPU run without `XDG_RUNTIME_DIR`
/// (ssh sessions, containers, CI) although nothing failed.
///
/// The message comes from libwayland-client, which Mesa's implicit layer
/// `VK_LAYER_MESA_device_select` calls from `vkEnumeratePhysicalDevices` to
/// put the GPU driving the display first, because wgpu enables
/// `VK_KHR_wayland_surface` on every instance (wgpu 30 has no option to leave
/// the window-system extensions out of a compute-only instance). Where no
/// Wayland connection is possible (no usable `XDG_RUNTIME_DIR`, no
/// `WAYLAND_SOCKET`, no absolute `WAYLAND_DISPLAY`) and no X display either,
/// the layer has no display to look for, so this sets its documented switch
/// `NODEVICE_SELECT=1`: the adapters come in the Vulkan loader's order and
/// wgpu chooses among them as always (`WGPU_ADAPTER_NAME` picks one). Nothing
/// changes where the user has set `NODEVICE_SELECT`, `MESA_VK_DEVICE_SELECT`
/// or `DRI_PRIME` (they steer that layer), or where a display can be reached.
///
/// It changes the process's environment, so call it first thing in `main`,
/// before any thread exists (`std::env::set_var` is unsound while another
/// thread reads the environment).
pub fn quiet_headless_vulkan() {
    let set = |name: &str| std::env::var_os(name).is_some();
    if set("NODEVICE_SELECT") || set("MESA_VK_DEVICE_SELECT") || set("DRI_PRIME") {
        return;
    }
    let runtime_dir = std::env::var_os("XDG_RUNTIME_DIR")
        .is_some_and(|dir| !dir.is_empty() && std::path::Path::new(&dir).is_dir());
    let wayland_display = std::env::var_os("WAYLAND_DISPLAY")
        .is_some_and(|display| std::path::Path::new(&display).is_absolute());
    if runtime_dir || wayland_display || set("WAYLAND_SOCKET") || set("DISPLAY") {
        return;
    }
    std::env::set_var("NODEVICE_SELECT", "1");
}

/// Limits the backend plans with: the adapter's, unless a test lowers them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GpuLimits {
    /// Largest storage-buffer binding in bytes; longer arrays are split into segments.
    pub max_binding_bytes: u64,
    /// The device's own binding limit (scene buffers are bound whole).
    pub device_max_binding_bytes: u64,
    pub max_buffer_bytes: u64,
    pub max_storage_buffers_per_stage: u32,
    pub max_workgroups_per_dimension: u32,
}

/// An open device and what the backend knows about it.
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
    pub limits: GpuLimits,
    /// Whether compute passes can write timestamps (per-stage device time).
    pub timestamps: bool,
    /// Compiled kernels by source text, kept across runs.
    pub(crate) pipelines: crate::caches::PipelineCache,
    /// Scene buffers by name and data, uploaded once.
    pub(crate) scene_buffers: crate::caches::SceneBufferCache,
    /// Buffers of dropped arrays, for the next arrays of the same size.
    pub(crate) buffer_pool: std::sync::Arc<crate::caches::BufferPool>,
}

impl fmt::Debug for GpuContext {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("GpuContext")
            .field("adapter", &self.adapter_name())
            .field("limits", &self.limits)
            .finish()
    }
}

impl GpuContext {
    /// Opens the first adapter wgpu offers (`WGPU_BACKEND`, `WGPU_ADAPTER_NAME`
    /// choose one), with the adapter's limits rather than wgpu's lower defaults.
    pub fn new() -> Result<GpuContext, GpuError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = pollster::block_on(wgpu::util::initialize_adapter_from_env_or_default(
            &instance, None,
        ))
        .map_err(|e| {
            GpuError::device(format!(
                "no GPU adapter found ({e}); on a machine without a GPU install Mesa's software Vulkan driver \
                 (Debian: mesa-vulkan-drivers libvulkan1) and set WGPU_BACKEND=vulkan"
            ))
        })?;
        let info = adapter.get_info();
        let adapter_limits = adapter.limits();
        let timestamps = adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        let mut required_features = wgpu::Features::empty();
        if timestamps {
            required_features |= wgpu::Features::TIMESTAMP_QUERY;
        }
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("dpp"),
            required_features,
            required_limits: adapter_limits.clone(),
            ..Default::default()
        }))
        .map_err(|e| GpuError::device(format!("adapter `{}` refused a device: {e}", info.name)))?;
        let limits = GpuLimits {
            max_binding_bytes: adapter_limits
                .max_storage_buffer_binding_size
                .min(adapter_limits.max_buffer_size),
            device_max_binding_bytes: adapter_limits
                .max_storage_buffer_binding_size
                .min(adapter_limits.max_buffer_size),
            max_buffer_bytes: adapter_limits.max_buffer_size,
            max_storage_buffers_per_stage: adapter_limits.max_storage_buffers_per_shader_stage,
            max_workgroups_per_dimension: adapter_limits.max_compute_workgroups_per_dimension,
        };
        Ok(GpuContext {
            device,
            queue,
            info,
            limits,
            timestamps,
            pipelines: Default::default(),
            scene_buffers: Default::default(),
            buffer_pool: Default::default(),
        })
    }

    /// `llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan, Cpu)`.
    pub fn adapter_name(&self) -> String {
        format!(
            "{} ({:?}, {:?})",
            self.info.name, self.info.backend, self.info.device_type
        )
    }

    /// The same device planned with other (lower) limits, so that tests can
    /// force the paths real sizes take: arrays split into many segments, 2-D
    /// dispatches.
    pub fn with_limits(&self, limits: GpuLimits) -> GpuContext {
        GpuContext {
            device: self.device.clone(),
            queue: self.queue.clone(),
            info: self.info.clone(),
            limits: GpuLimits {
                max_binding_bytes: limits.max_binding_bytes.max(16),
                device_max_binding_bytes: self.limits.device_max_binding_bytes,
                ..limits
            },
            timestamps: self.timestamps,
            pipelines: Default::default(),
            scene_buffers: Default::default(),
            buffer_pool: Default::default(),
        }
    }
}

/// The process's GPU for test suites, opened once. Without an adapter it
/// prints why and returns `None` (the caller skips), unless the environment
/// variable `DPP_REQUIRE_GPU` is set: CI sets it, so there a missing adapter
/// fails the tests instead of skipping them silently.
pub fn gpu_for_tests() -> Option<&'static GpuContext> {
    static GPU: std::sync::OnceLock<Option<GpuContext>> = std::sync::OnceLock::new();
    GPU.get_or_init(|| match GpuContext::new() {
        Ok(gpu) => Some(gpu),
        Err(e) if std::env::var_os("DPP_REQUIRE_GPU").is_some() => {
            panic!("DPP_REQUIRE_GPU is set but the GPU backend cannot start: {e}")
        }
        Err(e) => {
            eprintln!("skipping GPU checks: {e}");
            None
        }
    })
    .as_ref()
}
