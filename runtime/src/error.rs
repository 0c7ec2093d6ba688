//! What kind of failure a run-time error is. Every error a run can end in
//! ([`RunError`](crate::interpret::RunError), [`FunctorError`](crate::FunctorError),
//! the GPU backend's errors) carries an [`ErrorKind`], so the command derives
//! its exit status from the error itself instead of from the call site that
//! happened to see it.

/// Why a run failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ErrorKind {
    /// The user's data, pipeline or arguments are wrong (an index out of
    /// range, a negative count, a length that does not match).
    BadInput,
    /// The work asks for more than a limit allows: the element cap, the
    /// `while` iteration cap, a device's memory or binding sizes.
    ResourceLimit,
    /// The GPU or its driver failed (no adapter, a lost device, a failed map).
    Device,
    /// A bug in dpp: a functor or backend broke its contract.
    Internal,
}

impl ErrorKind {
    /// The exit status of a command that ends in this kind of error:
    /// 2 for bad input (as for a malformed pipeline), 1 otherwise.
    pub fn exit_status(self) -> u8 {
        match self {
            ErrorKind::BadInput => 2,
            ErrorKind::ResourceLimit | ErrorKind::Device | ErrorKind::Internal => 1,
        }
    }
}
