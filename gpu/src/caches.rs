//! What a device context keeps from one run to the next: compiled kernels,
//! uploaded scene buffers and the buffers of dropped arrays. The lowest layer
//! of the crate beside `device`: it knows wgpu, nothing of arrays or runs.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

/// The caches a context keeps across runs.
pub type PipelineCache =
    Mutex<HashMap<String, Arc<(wgpu::ComputePipeline, wgpu::BindGroupLayout)>>>;
pub type SceneBufferCache = Mutex<HashMap<(&'static str, usize), (Arc<[u32]>, wgpu::Buffer)>>;

/// Buffers of the arrays of finished runs, by size, for the next arrays of
/// that size. Every run allocates its arrays anew, and new device memory is
/// slow to get (the driver clears it: on an H100 a frame that allocated
/// 80 MB took about 40 ms longer than one that allocated 16 MB); a reused
/// buffer is cleared on the device instead.
#[derive(Debug, Default)]
pub struct BufferPool {
    free: Mutex<PoolState>,
}

#[derive(Debug, Default)]
struct PoolState {
    by_size: HashMap<u64, Vec<wgpu::Buffer>>,
    bytes: u64,
}

/// The most memory the pool keeps; buffers beyond it are freed.
const POOL_MAX_BYTES: u64 = 1 << 30;

impl BufferPool {
    pub(crate) fn take(&self, size: u64) -> Option<wgpu::Buffer> {
        let mut state = self.free.lock().unwrap_or_else(|e| e.into_inner());
        let buffer = state.by_size.get_mut(&size)?.pop()?;
        state.bytes -= size;
        Some(buffer)
    }

    pub(crate) fn give(&self, buffers: Vec<wgpu::Buffer>) {
        let mut state = self.free.lock().unwrap_or_else(|e| e.into_inner());
        for buffer in buffers {
            if state.bytes + buffer.size() <= POOL_MAX_BYTES {
                state.bytes += buffer.size();
                state.by_size.entry(buffer.size()).or_default().push(buffer);
            }
        }
    }
}
