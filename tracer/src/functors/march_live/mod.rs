//! `marchLive(march: March) -> (live: bool)`: `t <= tEnd` (false for NaN):
//! whether the march has samples left, the mask a pipeline compacts its
//! marches with.

use crate::functors::volume_render::MarchColumns;
use crate::functors::wgsl::{twin, TwinParts};
use dpp_runtime::wgsl::{WgslRequest, WgslTwin};
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, RecordId, Signature,
};

pub struct MarchLive {
    signature: Signature,
}

impl MarchLive {
    pub fn new(march: RecordId) -> MarchLive {
        MarchLive {
            signature: Signature::map("marchLive")
                .input("march", ElemType::Record(march))
                .output("live", ElemType::Bool)
                .doc("whether the march has samples left: t <= tEnd"),
        }
    }
}

impl Functor for MarchLive {
    fn signature(&self) -> &Signature {
        &self.signature
    }

    fn wgsl(&self, request: &WgslRequest<'_>) -> Result<WgslTwin, FunctorError> {
        twin(
            &self.signature,
            request,
            include_str!("twin.wgsl"),
            TwinParts::default(),
        )
    }

    fn run_cpu(
        &self,
        _ctx: &CallContext<'_>,
        inputs: &[ColumnView<'_>],
        outputs: &mut [Column],
    ) -> Result<(), FunctorError> {
        let marches = MarchColumns::new(&inputs[0]);
        let out = outputs[0].as_bool_mut();
        out.extend((0..marches.len()).map(|i| marches.get(i).live()));
        Ok(())
    }
}
