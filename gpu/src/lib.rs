//! The GPU backend (wgpu): the same plans as the CPU backend, one compute
//! shader per stage made by composing the stage's functor twins in stage
//! order, plus multi-pass kernels for reduce, scan and plain scatter that do
//! not rely on forward progress between workgroups. The shared interpreter
//! (`dpp_runtime::interpret`) drives it, so control flow is the CPU's.

pub mod agreement;
pub mod array;
mod backend;
mod caches;
mod device;
mod exec;
mod functor_call;
mod monoid;
mod shader;
mod stage;
mod twin_check;

pub use array::GpuArray;
pub use device::{gpu_for_tests, quiet_headless_vulkan, GpuContext, GpuError, GpuLimits};
pub use exec::{run_plan_gpu, run_plan_gpu_observed, GpuRunContext};
pub use functor_call::run_functor_gpu;
pub use twin_check::{check_twin, validate_wgsl};
