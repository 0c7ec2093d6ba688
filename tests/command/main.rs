//! The `dpp` command's tests, one binary: every pipeline on both backends,
//! plans, golden images, the CLI and `dpp bench`.

mod backends;
mod bench;
mod cli;
mod cli_citizen;
#[path = "../common/mod.rs"]
mod common;
#[cfg(feature = "mpi")]
mod distributed;
mod expressions;
mod images;
mod plans;
mod volume_surface;
mod vtk;
