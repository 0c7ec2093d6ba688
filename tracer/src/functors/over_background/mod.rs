//! `overBackground(color: vec3, alpha: f32) -> (rgb: vec3)`: a colour
//! accumulated front to back with opacity `alpha`, over the shading's
//! background: `color + (1 - alpha) * background` (linear RGB).

use crate::functors::wgsl::{request_resources, twin, TwinParts};
use crate::scene::TraceResources;
use dpp_runtime::wgsl::{WgslRequest, WgslTwin};
use dpp_runtime::{CallContext, Column, ColumnView, ElemType, Functor, FunctorError, Signature};

pub struct OverBackground {
    signature: Signature,
}

impl OverBackground {
    pub fn new() -> OverBackground {
        OverBackground {
            signature: Signature::map("overBackground")
                .input("color", ElemType::Vec3)
                .input("alpha", ElemType::F32)
                .output("rgb", ElemType::Vec3)
                .doc(
                    "a premultiplied colour over the background: color + (1 - alpha) * background",
                ),
        }
    }
}

impl Default for OverBackground {
    fn default() -> Self {
        OverBackground::new()
    }
}

impl Functor for OverBackground {
    fn signature(&self) -> &Signature {
        &self.signature
    }

    /// `twin.wgsl`, reading the background from the shading constants.
    fn wgsl(&self, request: &WgslRequest<'_>) -> Result<WgslTwin, FunctorError> {
        let shading =
            request_resources::<TraceResources>(request, "overBackground")?.shading_gpu_buffers();
        let parts = TwinParts {
            buffers: vec![shading.constants],
            ..TwinParts::default()
        };
        twin(&self.signature, request, include_str!("twin.wgsl"), parts)
    }

    fn run_cpu(
        &self,
        ctx: &CallContext<'_>,
        inputs: &[ColumnView<'_>],
        outputs: &mut [Column],
    ) -> Result<(), FunctorError> {
        let background = ctx.resources::<TraceResources>()?.shading.background();
        let (colors, alphas) = (inputs[0].as_vec3(), inputs[1].as_f32());
        let out = outputs[0].as_vec3_mut();
        out.extend(
            (colors.iter().zip(alphas)).map(|(&color, &alpha)| color + background * (1.0 - alpha)),
        );
        Ok(())
    }
}
