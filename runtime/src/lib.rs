//! The dpp runtime: the plan compiler, the backend-neutral semantics and
//! interpreter, and the CPU backend.

pub mod column;
pub mod elem;
pub mod error;
pub mod functor;
pub mod host;
pub mod monoid;
pub mod random;
pub mod signature;
pub mod types;

pub use column::{Column, ColumnView};
pub use error::ErrorKind;
pub use functor::{CallContext, ClosureFunctor, Functor, FunctorError, FunctorLibrary};
pub use host::{HostValue, UniformSchema, Uniforms};
pub use monoid::MonoidOp;
pub use signature::{ArrayParam, FunctorKind, NamedParam, Signature, TypeConstraint, TypePattern};
pub use types::{ElemType, HostType, RecordId, RecordRegistry, RecordType};

pub mod compile;
pub mod cpu;
pub mod generic;
pub mod interpret;
pub mod wgsl;

pub use compile::ir::Plan;
pub use compile::{compile_file, compile_text, CompileFailure, CompileOptions};
