pub mod column_pool;
pub mod exec;
pub mod kernels;
mod shared_scatter;
pub mod sort;
