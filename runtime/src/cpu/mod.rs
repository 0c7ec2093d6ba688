pub mod column_pool;
pub mod compiled;
pub mod exec;
pub mod kernels;
mod shared_scatter;
pub mod sort;
