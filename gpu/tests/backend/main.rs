//! The GPU backend's tests, one binary: every primitive form on both backends
//! against a sequential reference, every generic functor's twin against its
//! CPU code, and every twin validated by naga.

#[path = "../../../runtime/tests/common/mod.rs"]
mod common;
mod data;
mod gpu_functors;
mod primitives;
mod wgsl_twins;

/// The test process's GPU (see [`dpp_gpu::gpu_for_tests`]).
fn gpu() -> Option<&'static dpp_gpu::GpuContext> {
    dpp_gpu::gpu_for_tests()
}
