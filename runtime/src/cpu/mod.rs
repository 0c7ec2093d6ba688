pub mod exec;
pub mod kernels;
