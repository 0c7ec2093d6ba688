//! The sRGB transfer function, both ways.
//!
//! Encoding runs on every component of every pixel of every frame (`antiAlias`),
//! where three `powf` calls per pixel were an eighth of a WORKLOAD2 frame. So
//! [`encode_component`] computes `x^(1/2.4)` as `2^(log2(x) · 5/12)` from the
//! f64 series of `super::series`, without branches or calls: a slice of
//! components ([`encode_in_place`]) compiles to SIMD, and on x86-64 runs in
//! AVX-512 or AVX2 where the CPU has them (`multiversion` picks at run time),
//! with the same bits everywhere. The
//! result, rounded to f32 once, is within half a unit in the last place of the
//! exact curve (tested over the whole range), so 8-bit pixels come out as they
//! did with `powf`.

use super::series::{exp2, log2};
use glam::Vec3;
use multiversion::multiversion;

/// At or below this, the curve is the straight line `12.92 x`.
const LINEAR_LIMIT: f32 = 0.003_130_8;

/// The sRGB transfer function, inverted (display value to linear light).
#[inline]
pub fn srgb_to_linear(c: Vec3) -> Vec3 {
    let f = |x: f32| {
        if x <= 0.04045 {
            x / 12.92
        } else {
            ((x + 0.055) / 1.055).powf(2.4)
        }
    };
    Vec3::new(f(c.x), f(c.y), f(c.z))
}

/// The sRGB transfer function (linear light in [0, 1] to display value; 1 and
/// above give exactly 1), per component as [`encode_component`].
#[inline]
pub fn linear_to_srgb(c: Vec3) -> Vec3 {
    Vec3::new(
        encode_component(c.x),
        encode_component(c.y),
        encode_component(c.z),
    )
}

/// Components go in blocks of 48 (16 RGB pixels). A block the same as the one
/// before (bit for bit: runs of background) copies its encoding.
const BLOCK: usize = 48;

/// Every component of `values` encoded as [`encode_component`] does.
#[multiversion(targets("x86_64+avx512f+avx512vl+avx2", "x86_64+avx2"))]
pub fn encode_in_place(values: &mut [f32]) {
    let mut last: Option<([u32; BLOCK], [f32; BLOCK])> = None;
    let mut blocks = values.chunks_exact_mut(BLOCK);
    for block in &mut blocks {
        let block: &mut [f32; BLOCK] = block.try_into().expect("a whole block");
        let bits = block.map(f32::to_bits);
        match &last {
            Some((last_bits, encoded)) if *last_bits == bits => *block = *encoded,
            _ => {
                for value in block.iter_mut() {
                    *value = encode_component(*value);
                }
                last = Some((bits, *block));
            }
        }
    }
    for value in blocks.into_remainder() {
        *value = encode_component(*value);
    }
}

/// One component: `12.92 x` up to 0.0031308, `1.055 x^(1/2.4) - 0.055` above,
/// exactly 1 from 1 up (where the formula rounds to 0.99999994); NaN stays NaN.
#[inline(always)]
pub fn encode_component(x: f32) -> f32 {
    // 1/2.4 = 5/12.
    let curve = (1.055 * exp2(log2(x) * (5.0 / 12.0)) - 0.055) as f32;
    if x <= LINEAR_LIMIT {
        x * 12.92
    } else if x < 1.0 {
        curve
    } else if x >= 1.0 {
        1.0
    } else {
        x
    }
}

#[cfg(test)]
mod tests {
    use super::super::series::ulps;
    use super::*;

    /// The curve in f64 (the line with the f32 slope the code uses).
    fn exact(x: f32) -> f64 {
        let x = f64::from(x);
        if x <= f64::from(LINEAR_LIMIT) {
            x * f64::from(12.92f32)
        } else if x >= 1.0 {
            1.0
        } else {
            1.055 * x.powf(1.0 / 2.4) - 0.055
        }
    }

    #[test]
    fn encoding_is_within_an_ulp_of_the_exact_curve_over_its_whole_range() {
        // Every 7th normal float up to 1 (about 1.2 million per octave).
        // Errors in units of the last place of the exact value.
        let (mut worst, mut worst_at) = (0.0f64, 0.0f32);
        let one = 1.0f32.to_bits();
        for bits in (f32::MIN_POSITIVE.to_bits()..=one).step_by(7).chain([one]) {
            let x = f32::from_bits(bits);
            let error = ulps(encode_component(x), exact(x));
            if error > worst {
                (worst, worst_at) = (error, x);
            }
        }
        assert!(
            worst <= 0.51,
            "{worst} units in the last place at {worst_at:e}"
        );
    }

    #[test]
    fn edges_and_non_finite_components() {
        assert_eq!(encode_component(0.0), 0.0);
        assert_eq!(encode_component(LINEAR_LIMIT), LINEAR_LIMIT * 12.92);
        assert_eq!(encode_component(-0.5), -0.5 * 12.92);
        assert_eq!(encode_component(1.0), 1.0);
        assert_eq!(encode_component(7.0), 1.0);
        assert_eq!(encode_component(f32::INFINITY), 1.0);
        assert!(encode_component(f32::NAN).is_nan());
        assert!((encode_component(0.5) - 0.735_357).abs() < 1e-6);
        // Continuous where the line meets the curve.
        let above = f32::from_bits(LINEAR_LIMIT.to_bits() + 1);
        assert!((encode_component(above) - encode_component(LINEAR_LIMIT)).abs() < 1e-6);
    }

    #[test]
    fn a_slice_encodes_as_its_components_do() {
        // Whole blocks, repeated blocks and a remainder.
        let mut values: Vec<f32> = (0..1000).map(|i| i as f32 / 997.0 - 0.001).collect();
        values.extend([0.25; 2 * BLOCK + 5]);
        let mut encoded = values.clone();
        encode_in_place(&mut encoded);
        for (x, fast) in values.iter().zip(&encoded) {
            assert_eq!(fast.to_bits(), encode_component(*x).to_bits(), "{x}");
        }
    }

    #[test]
    fn decoding_inverts_encoding() {
        for c in [0.0, 0.001, 0.02, 0.2, 0.5, 0.9, 1.0] {
            let v = Vec3::splat(c);
            let back = linear_to_srgb(srgb_to_linear(v));
            assert!((back - v).abs().max_element() < 1e-5, "{c}: {back}");
        }
    }
}
