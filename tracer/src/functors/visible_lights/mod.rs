//! `visibleLights(blocked: bool) -> (mask: u32)`, a group functor used as
//! `gather<visibleLights>(blocked, group: scene.lights)` after
//! `scatter<shadowRay>(surf, fanout: scene.lights) → map<occluded>`: bit `j` of
//! the mask is set when light `j` is *not* blocked. At most 32 lights (the scene
//! set-up refuses more).

use crate::functors::tracer_functor;
use crate::functors::wgsl::TwinParts;
use crate::shading::MAX_LIGHTS;
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{CallContext, Column, ColumnView, ElemType, Functor, FunctorError, Signature};
use std::sync::Arc;

pub fn functor() -> Arc<dyn Functor> {
    let signature = Signature::group("visibleLights")
        .input("blocked", ElemType::Bool)
        .output("mask", ElemType::U32)
        .doc(
            "bit j set when light j of the group is not blocked (group: scene.lights, at most 32)",
        );
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

/// `twin.wgsl`: one bit per unblocked light of the group.
fn twin_parts(_: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    Ok(TwinParts {
        constants: vec![("MAX_LIGHTS", format!("{MAX_LIGHTS}u"))],
        failures: vec![format!(
            "visibleLights: the group must be 1 to {MAX_LIGHTS} lights (a mask holds {MAX_LIGHTS})"
        )],
        ..TwinParts::default()
    })
}

fn run_cpu(
    ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let lights = ctx.group;
    if lights == 0 || lights > MAX_LIGHTS {
        return Err(FunctorError::bad_input(format!(
            "visibleLights: group {lights}; a mask holds 1 to {MAX_LIGHTS} lights"
        )));
    }
    let blocked = inputs[0].as_bool();
    let masks = outputs[0].as_u32_mut();
    masks.extend(blocked.chunks_exact(lights).map(|group| {
        group
            .iter()
            .enumerate()
            .filter(|(_, &blocked)| !blocked)
            .fold(0u32, |mask, (light, _)| mask | (1 << light))
    }));
    Ok(())
}

#[cfg(test)]
mod tests {
    use crate::functors::test_support::Fixture;
    use dpp_runtime::Column;

    #[test]
    fn bit_j_means_light_j_is_visible() {
        let fixture = Fixture::new();
        let blocked = Column::Bool(vec![
            false, true, false, true, true, true, false, false, false,
        ]);
        let out = fixture
            .run_grouped("visibleLights", &[], 3, 0, &[blocked.view()])
            .unwrap();
        assert_eq!(out[0].view().as_u32(), &[0b101, 0b000, 0b111]);
        let out = fixture
            .run_grouped("visibleLights", &[], 1, 0, &[blocked.view()])
            .unwrap();
        assert_eq!(out[0].view().as_u32(), &[1, 0, 1, 0, 0, 0, 1, 1, 1]);
        let all: Vec<bool> = (0..32).map(|j| j == 31).collect();
        let out = fixture
            .run_grouped("visibleLights", &[], 32, 0, &[Column::Bool(all).view()])
            .unwrap();
        assert_eq!(out[0].view().as_u32(), &[u32::MAX >> 1]);
    }

    #[test]
    fn more_than_32_lights_is_an_error() {
        let fixture = Fixture::new();
        let blocked = Column::Bool(vec![false; 33]);
        let error = fixture
            .run_grouped("visibleLights", &[], 33, 0, &[blocked.view()])
            .unwrap_err();
        assert!(error.message.contains("32"), "{error}");
    }
}
