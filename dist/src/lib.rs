//! Distributed rendering's communication: where a process stands among the
//! ranks ([`Ranks`]), and sort-last compositing schedules that bring every
//! rank's per-pixel arrays together on rank 0 ([`composite`],
//! [`gather_pieces`]).
//!
//! **Invariant: the crate knows no pipelines. It moves and orders per-pixel
//! arrays; what a blend computes is the caller's (a callback), and the only
//! promise about it is the order of its arguments: the result on rank 0 is
//! the left fold of `blend(front, back)` over the ranks in the given order.**
//! Every decision of who sends what to whom is made by [`schedule::plan`]
//! from numbers every rank has, so ranks never negotiate a schedule.
//!
//! Without the `mpi` feature the crate is a single process of size 1, so the
//! same calls serve a build on a machine without MPI.

pub mod composite;
pub mod ranks;
pub mod schedule;
pub mod wire;

pub use composite::{composite, gather_pieces, CompositeStats, Composited, RoundStats};
pub use ranks::{DistError, Ranks};
pub use schedule::{cost, plan, CompositeSchedule, Cost, Plan};
