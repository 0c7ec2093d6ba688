//! `colormap(scalar: f32) -> (rgb: vec3)`: the scene's colour map in linear
//! RGB at `(scalar - min) * (1 / (max - min))` over the scene's scalar range,
//! clamped to its ends (NaN reads as `min`): the table lookup of the `shader`
//! functor's `base`, computed as it computes it.

use crate::functors::tracer_functor;
use crate::functors::wgsl::{colormap_module, request_resources, vector_module, TwinParts};
use crate::scene::TraceResources;
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{CallContext, Column, ColumnView, ElemType, Functor, FunctorError, Signature};
use std::sync::Arc;

pub fn functor() -> Arc<dyn Functor> {
    let signature = Signature::map("colormap")
        .input("scalar", ElemType::F32)
        .output("rgb", ElemType::Vec3)
        .doc("the scene's colour map (linear RGB) at the scalar over the scene's scalar range");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

fn twin_parts(request: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    let shading = request_resources::<TraceResources>(request, "colormap")?.shading_gpu_buffers();
    Ok(TwinParts {
        modules: vec![vector_module(), colormap_module(&shading)],
        buffers: vec![shading.constants],
        ..TwinParts::default()
    })
}

fn run_cpu(
    ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let shading = &ctx.resources::<TraceResources>()?.shading;
    let colormap = shading.colormap();
    let [low, high] = shading.scalar_range();
    let inverse_range = 1.0 / (high - low);
    outputs[0].as_vec3_mut().extend(
        inputs[0]
            .as_f32()
            .iter()
            .map(|&s| colormap.linear_at((s - low) * inverse_range)),
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use crate::functors::test_support::Fixture;
    use dpp_runtime::Column;

    #[test]
    fn the_range_maps_onto_the_table_and_clamps() {
        let fixture = Fixture::new();
        let shading = &fixture.resources.shading;
        let [low, high] = shading.scalar_range();
        let map = shading.colormap();
        let scalars = Column::F32(vec![low, high, low - 1.0, high + 1.0, f32::NAN]);
        let out = fixture.run("colormap", &[], 0, &[scalars.view()]).unwrap();
        let (first, last) = (map.linear_at(0.0), map.linear_at(1.0));
        assert_eq!(out[0].view().as_vec3(), &[first, last, first, last, first]);
    }
}
