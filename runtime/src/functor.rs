//! Functors: named, typed per-element kernels, and the library that holds them.
//!
//! The runtime knows functors only through [`Functor`]: a [`Signature`] for the
//! plan compiler (see [`crate::signature`]) and a chunk-wise CPU implementation
//! for the CPU backend.

use crate::column::{Column, ColumnView};
use crate::elem::KernelError;
use crate::error::ErrorKind;
use crate::host::{HostValue, UniformSchema, Uniforms};
use crate::signature::Signature;
use crate::types::RecordRegistry;
use crate::wgsl::{WgslRequest, WgslTwin};
use std::any::Any;
use std::collections::BTreeMap;
use std::fmt;
use std::sync::Arc;

/// Everything a functor's CPU implementation may read besides its array inputs.
pub struct CallContext<'a> {
    /// The values of the functor's named parameters, defaults filled in, in signature order.
    pub named: &'a [HostValue],
    pub uniforms: &'a Uniforms,
    /// Scene data (BVH, triangles, materials) the functor library put there; see
    /// [`FunctorLibrary::resources`].
    pub resources: &'a (dyn Any + Send + Sync),
    /// Index, in the functor's input index space, of the first element of this chunk.
    pub first_index: usize,
    /// `k` for `Group` and `Expand` functors; 1 otherwise.
    pub group: usize,
    pub records: &'a RecordRegistry,
}

impl CallContext<'_> {
    /// The named parameter at `index` of the signature (already type-checked).
    pub fn named(&self, index: usize) -> HostValue {
        self.named[index]
    }

    pub fn resources<T: Any>(&self) -> Result<&T, FunctorError> {
        self.resources.downcast_ref::<T>().ok_or_else(|| {
            FunctorError::bad_input(format!(
                "this functor needs {} but the run has none (no scene loaded?)",
                std::any::type_name::<T>()
            ))
        })
    }
}

/// A run-time failure inside a functor (a missing scene, an index out of range),
/// with the kind that decides the exit status.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FunctorError {
    pub kind: ErrorKind,
    pub message: String,
}

impl FunctorError {
    pub fn new(kind: ErrorKind, message: impl Into<String>) -> FunctorError {
        FunctorError {
            kind,
            message: message.into(),
        }
    }

    /// The input the functor was given is wrong: the common case.
    pub fn bad_input(message: impl Into<String>) -> FunctorError {
        FunctorError::new(ErrorKind::BadInput, message)
    }

    pub fn internal(message: impl Into<String>) -> FunctorError {
        FunctorError::new(ErrorKind::Internal, message)
    }
}

impl fmt::Display for FunctorError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for FunctorError {}

// Functors call kernels for their per-chunk work and report kernel errors as their own.
impl From<KernelError> for FunctorError {
    fn from(error: KernelError) -> FunctorError {
        FunctorError::new(error.kind(), error.to_string())
    }
}

/// The error a functor without a twin gives the GPU backend.
pub fn no_twin(name: &str) -> FunctorError {
    FunctorError::bad_input(format!(
        "functor `{name}` has no WGSL twin, so it cannot run on the GPU backend"
    ))
}

pub trait Functor: Send + Sync {
    fn signature(&self) -> &Signature;

    /// Runs the functor over one chunk. `inputs` follow the signature (types already
    /// checked and type variables bound); `outputs` are empty columns of the output
    /// types that the implementation must fill to the chunk's output length:
    /// `n` for `Map` and `Monoid`, `n / k` for `Group`, `n * k` for `Expand`
    /// (output `i*k + j` from input `i`, lane `j`).
    fn run_cpu(
        &self,
        ctx: &CallContext<'_>,
        inputs: &[ColumnView<'_>],
        outputs: &mut [Column],
    ) -> Result<(), FunctorError>;

    /// The functor's WGSL twin for the GPU backend (conventions in [`crate::wgsl`]).
    fn wgsl(&self, request: &WgslRequest<'_>) -> Result<WgslTwin, FunctorError> {
        let _ = request;
        Err(no_twin(self.signature().name))
    }
}

/// [`Functor::run_cpu`] as a closure.
pub type CpuBody = dyn Fn(&CallContext<'_>, &[ColumnView<'_>], &mut [Column]) -> Result<(), FunctorError>
    + Send
    + Sync;

/// [`Functor::wgsl`] as a closure, handed the functor's signature.
pub type TwinBody =
    dyn Fn(&Signature, &WgslRequest<'_>) -> Result<WgslTwin, FunctorError> + Send + Sync;

/// A functor made of its parts: a signature, a CPU body and (for the GPU
/// backend) a twin. The generic functors and the tracer's are all this, each
/// family with its own helper that turns what is particular to a functor into
/// the two bodies, so that no functor writes the [`Functor`] impl itself.
pub struct ClosureFunctor {
    signature: Signature,
    cpu: Box<CpuBody>,
    twin: Option<Box<TwinBody>>,
}

impl ClosureFunctor {
    /// A functor without a twin (it runs on the CPU backend only).
    pub fn new(
        signature: Signature,
        cpu: impl Fn(&CallContext<'_>, &[ColumnView<'_>], &mut [Column]) -> Result<(), FunctorError>
            + Send
            + Sync
            + 'static,
    ) -> ClosureFunctor {
        ClosureFunctor {
            signature,
            cpu: Box::new(cpu),
            twin: None,
        }
    }

    pub fn with_twin(
        mut self,
        twin: impl Fn(&Signature, &WgslRequest<'_>) -> Result<WgslTwin, FunctorError>
            + Send
            + Sync
            + 'static,
    ) -> ClosureFunctor {
        self.twin = Some(Box::new(twin));
        self
    }
}

impl Functor for ClosureFunctor {
    fn signature(&self) -> &Signature {
        &self.signature
    }

    fn run_cpu(
        &self,
        ctx: &CallContext<'_>,
        inputs: &[ColumnView<'_>],
        outputs: &mut [Column],
    ) -> Result<(), FunctorError> {
        (self.cpu)(ctx, inputs, outputs)
    }

    fn wgsl(&self, request: &WgslRequest<'_>) -> Result<WgslTwin, FunctorError> {
        match &self.twin {
            Some(twin) => twin(&self.signature, request),
            None => Err(no_twin(self.signature.name)),
        }
    }
}

/// Every functor, record type and uniform a pipeline may name.
#[derive(Clone, Default)]
pub struct FunctorLibrary {
    functors: BTreeMap<&'static str, Arc<dyn Functor>>,
    pub records: RecordRegistry,
    pub uniforms: UniformSchema,
}

impl FunctorLibrary {
    pub fn register(&mut self, functor: Arc<dyn Functor>) {
        let name = functor.signature().name;
        let previous = self.functors.insert(name, functor);
        assert!(previous.is_none(), "functor `{name}` registered twice");
    }

    pub fn get(&self, name: &str) -> Option<&Arc<dyn Functor>> {
        self.functors.get(name)
    }

    pub fn names(&self) -> impl Iterator<Item = &'static str> + '_ {
        self.functors.keys().copied()
    }

    pub fn iter(&self) -> impl Iterator<Item = &Arc<dyn Functor>> {
        self.functors.values()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::ElemType;

    /// `doubled(x: u32) -> (y: u32)`, with a twin that names its signature.
    fn doubled(with_twin: bool) -> ClosureFunctor {
        let signature = Signature::map("doubled")
            .input("x", ElemType::U32)
            .output("y", ElemType::U32);
        let functor = ClosureFunctor::new(signature, |_, inputs, outputs| {
            *outputs[0].as_u32_mut() = inputs[0].as_u32().iter().map(|x| 2 * x).collect();
            Ok(())
        });
        if !with_twin {
            return functor;
        }
        functor.with_twin(|signature, request| {
            Ok(WgslTwin {
                source: format!("// {} as {}", signature.name, request.function),
                ..WgslTwin::default()
            })
        })
    }

    #[test]
    fn a_closure_functor_runs_its_closures() {
        let records = RecordRegistry::default();
        let ctx = CallContext {
            named: &[],
            uniforms: &Uniforms::default(),
            resources: &(),
            first_index: 0,
            group: 1,
            records: &records,
        };
        let input = Column::U32(vec![1, 5]);
        let mut outputs = [Column::U32(Vec::new())];
        let functor = doubled(true);
        functor
            .run_cpu(&ctx, &[input.view()], &mut outputs)
            .unwrap();
        assert_eq!(outputs[0], Column::U32(vec![2, 10]));
        assert_eq!(functor.signature().name, "doubled");
        let request = WgslRequest {
            function: "stage0_doubled",
            inputs: &[ElemType::U32],
            outputs: &[ElemType::U32],
            records: &records,
            resources: &(),
        };
        let twin = functor.wgsl(&request).unwrap();
        assert_eq!(twin.source, "// doubled as stage0_doubled");
        assert_eq!(doubled(false).wgsl(&request), Err(no_twin("doubled")));
    }
}
