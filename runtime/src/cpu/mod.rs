pub mod exec;
pub mod kernels;
mod shared_scatter;
