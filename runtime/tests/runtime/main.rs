//! The runtime's integration tests, one binary (no GPU code is linked):
//! each compiler pass, the plan validator, diagnostics, the CPU kernels and
//! the generic functors.

#[path = "../common/mod.rs"]
mod common;
mod compiled;
mod composite;
mod diagnostics;
mod generic_functors;
mod kernels;
mod last_reads;
mod pass_cse;
mod pass_desugar;
mod pass_fuse;
mod pass_lower;
mod pass_narrow;
mod pass_resolve;
mod pass_typecheck;
mod pass_validate;
