//! `light(index: u32) -> (l: Light)`: point light `index` of the scene
//! (`0 ≤ index < scene.lights`): `position`, `intensity` and linear `color`.
//! An index past the lights is an error.
//!
//! `iota(scene.lights) → map<light>` makes the lights an array, which a
//! pipeline gathers for every pair of a shading point and a light (the
//! fan-out `shader` does inside one functor).

use crate::functors::record_fields_mut;
use crate::functors::tracer_functor;
use crate::functors::wgsl::{request_resources, TwinParts};
use crate::scene::TraceResources;
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{
    CallContext, Column, ColumnView, ElemType, Functor, FunctorError, RecordId, Signature,
};
use std::sync::Arc;

pub fn functor(light: RecordId) -> Arc<dyn Functor> {
    let signature = Signature::map("light")
        .input("index", ElemType::U32)
        .output("l", ElemType::Record(light))
        .doc("point light index of the scene (below scene.lights): position, intensity, colour");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

fn twin_parts(request: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    let shading = request_resources::<TraceResources>(request, "light")?.shading_gpu_buffers();
    Ok(TwinParts {
        buffers: vec![shading.lights],
        failures: vec!["light: an index past the scene's lights".into()],
        ..TwinParts::default()
    })
}

fn run_cpu(
    ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let lights = ctx.resources::<TraceResources>()?.shading.lights();
    let indices = inputs[0].as_u32();
    if let Some(&index) = indices.iter().find(|&&i| i as usize >= lights.len()) {
        return Err(FunctorError::bad_input(format!(
            "light: index {index}, but the scene has {} lights",
            lights.len()
        )));
    }
    let picked = || indices.iter().map(|&i| &lights[i as usize]);
    let [position, intensity, color] = record_fields_mut(&mut outputs[0])?;
    *position = Column::Vec3(picked().map(|l| l.position).collect());
    *intensity = Column::F32(picked().map(|l| l.intensity).collect());
    *color = Column::Vec3(picked().map(|l| l.color).collect());
    Ok(())
}

#[cfg(test)]
mod tests {
    use crate::functors::test_support::Fixture;
    use dpp_runtime::Column;

    #[test]
    fn the_scene_lights_in_order_or_an_error() {
        let fixture = Fixture::new();
        let lights = fixture.resources.shading.lights().to_vec();
        let indices = Column::U32((0..lights.len() as u32).rev().collect());
        let out = fixture.run("light", &[], 0, &[indices.view()]).unwrap();
        let positions = out[0].field(0).unwrap();
        let expected: Vec<_> = lights.iter().rev().map(|l| l.position).collect();
        assert_eq!(positions.view().as_vec3(), &expected[..]);
        let past = Column::U32(vec![lights.len() as u32]);
        let error = fixture.run("light", &[], 0, &[past.view()]).unwrap_err();
        assert!(error.to_string().contains("light"), "{error}");
    }
}
