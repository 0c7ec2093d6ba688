//! `antiAlias(color: vec3) -> (pixel: vec3)`, a group functor used as
//! `gather<antiAlias>(color, group: spp)`: the mean of a pixel's `k` samples
//! (linear RGB), clamped to [0, 1] and encoded with the sRGB transfer function
//! (`crate::shading::linear_to_srgb`).
//!
//! This is where display encoding happens: the PNG writer writes the values it
//! gets as they are (scaled to 8 bits), so a pipeline whose colours are linear
//! (the shader's) ends with `antiAlias`, with `group: 1` when it takes one
//! sample per pixel. NaN components become 0.

use crate::functors::tracer_functor;
use crate::functors::wgsl::{f32_literal, vector_module, TwinParts};
use crate::shading::encode_srgb_in_place;
use dpp_runtime::wgsl::WgslRequest;
use dpp_runtime::{CallContext, Column, ColumnView, ElemType, Functor, FunctorError, Signature};
use glam::Vec3;
use std::sync::Arc;

pub fn functor() -> Arc<dyn Functor> {
    let signature = Signature::group("antiAlias")
        .input("color", ElemType::Vec3)
        .output("pixel", ElemType::Vec3)
        .doc("mean of each group of k linear colours (group: spp, 1 allowed), clamped to [0, 1] and sRGB-encoded for display");
    tracer_functor(signature, run_cpu, include_str!("twin.wgsl"), twin_parts)
}

/// `twin.wgsl`: the mean, clamped and sRGB-encoded with the CPU's constants.
fn twin_parts(_: &WgslRequest<'_>) -> Result<TwinParts<'static>, FunctorError> {
    Ok(TwinParts {
        constants: vec![
            ("SRGB_LINEAR_LIMIT", f32_literal(0.003_130_8)),
            ("SRGB_EXPONENT", f32_literal(1.0 / 2.4)),
        ],
        modules: vec![vector_module()],
        failures: vec!["antiAlias: group must be at least 1".into()],
        ..TwinParts::default()
    })
}

fn run_cpu(
    ctx: &CallContext<'_>,
    inputs: &[ColumnView<'_>],
    outputs: &mut [Column],
) -> Result<(), FunctorError> {
    let samples = ctx.group;
    if samples == 0 {
        return Err(FunctorError::bad_input(
            "antiAlias: group must be at least 1",
        ));
    }
    let colors = inputs[0].as_vec3();
    let scale = 1.0 / samples as f32;
    let out = outputs[0].as_vec3_mut();
    let first = out.len();
    // `max` first: it maps NaN to 0.
    let clamp = |mean: Vec3| mean.max(Vec3::ZERO).min(Vec3::ONE);
    if samples == 1 {
        // The sum of one sample, as `Sum` folds it (from zero).
        out.extend(colors.iter().map(|&c| clamp((Vec3::ZERO + c) * scale)));
    } else {
        out.extend(
            colors
                .chunks_exact(samples)
                .map(|group| clamp(group.iter().copied().sum::<Vec3>() * scale)),
        );
    }
    // The means' components in one run, for the SIMD encoder.
    encode_srgb_in_place(bytemuck::cast_slice_mut(&mut out[first..]));
    Ok(())
}

#[cfg(test)]
mod tests {
    use crate::functors::test_support::Fixture;
    use dpp_runtime::Column;
    use glam::Vec3;

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).abs().max_element() < 1e-5
    }

    #[test]
    fn mean_of_the_samples_then_srgb() {
        let fixture = Fixture::new();
        let colors = Column::Vec3(vec![
            Vec3::new(0.0, 0.2, 1.0),
            Vec3::new(0.4, 0.2, 1.0),
            Vec3::new(0.2, 0.2, 1.0),
            Vec3::new(0.2, 0.2, 1.0),
            // Out of range: clamped.
            Vec3::new(-1.0, 3.0, 0.0),
            Vec3::new(-1.0, 3.0, 0.0),
            Vec3::new(-1.0, 3.0, 0.0),
            Vec3::new(-1.0, 3.0, f32::NAN),
        ]);
        let out = fixture
            .run_grouped("antiAlias", &[], 4, 0, &[colors.view()])
            .unwrap();
        let pixels = out[0].view().as_vec3();
        assert_eq!(pixels.len(), 2);
        // linear 0.2 is sRGB 0.4845; 1 stays 1.
        assert!(
            close(pixels[0], Vec3::new(0.484_529, 0.484_529, 1.0)),
            "{}",
            pixels[0]
        );
        assert_eq!(pixels[1], Vec3::new(0.0, 1.0, 0.0));
        // Group 1: the encoding alone; linear 0.5 is sRGB 0.7354, 0.001 is 0.01292.
        let colors = Column::Vec3(vec![Vec3::new(0.5, 0.001, 0.0)]);
        let out = fixture
            .run_grouped("antiAlias", &[], 1, 0, &[colors.view()])
            .unwrap();
        assert!(
            close(
                out[0].view().as_vec3()[0],
                Vec3::new(0.735_357, 0.012_92, 0.0)
            ),
            "{}",
            out[0].view().as_vec3()[0]
        );
    }
}
