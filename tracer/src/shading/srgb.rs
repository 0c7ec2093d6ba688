//! The sRGB transfer function, both ways.
//!
//! Encoding runs on every component of every pixel of every frame (`antiAlias`),
//! where three `powf` calls per pixel were an eighth of a WORKLOAD2 frame. So
//! [`encode_component`] computes `x^(1/2.4)` as `2^(log2(x) · 5/12)` from two
//! short series, without branches or calls: a slice of components
//! ([`encode_in_place`]) compiles to SIMD, and on x86-64 runs in AVX-512 or AVX2
//! where the CPU has them. The series run in f64 and use only `+ - * /`, no
//! fused multiply-add, so every instruction set gives the same bits, and the
//! result, rounded to f32 once, is within one unit in the last place of the
//! exact value (tested over the whole range): as close as `powf` gets.

use glam::Vec3;

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

/// Every component of `values` encoded as [`encode_component`] does.
pub fn encode_in_place(values: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    {
        if std::is_x86_feature_detected!("avx512f") {
            // SAFETY: the CPU has the feature.
            return unsafe { encode_in_place_avx512(values) };
        }
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has the feature.
            return unsafe { encode_in_place_avx2(values) };
        }
    }
    encode_in_place_portable(values)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn encode_in_place_avx512(values: &mut [f32]) {
    encode_in_place_portable(values)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn encode_in_place_avx2(values: &mut [f32]) {
    encode_in_place_portable(values)
}

/// Components go in blocks of 48 (16 RGB pixels). A block the same as the one
/// before (bit for bit: runs of background) copies its encoding.
const BLOCK: usize = 48;

#[inline(always)]
fn encode_in_place_portable(values: &mut [f32]) {
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
    let curve = (1.055 * pow_five_twelfths(x) - 0.055) as f32;
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

/// `x^(5/12)` for normal `x` in (0, 1] (1/2.4 = 5/12), in f64 to about 1e-11,
/// so that the f32 it is rounded to is almost always the nearest one. Other
/// inputs give some number, which `encode_component` does not use.
#[inline(always)]
fn pow_five_twelfths(x: f32) -> f64 {
    // x = m · 2^e with m in [√½, √2), both exact.
    let bits = x.to_bits();
    let mantissa = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000);
    let large = mantissa > std::f32::consts::SQRT_2;
    let m = f64::from(if large { 0.5 * mantissa } else { mantissa });
    let e = ((bits >> 23) & 0xff) as i32 - 127 + i32::from(large);
    // ln m = 2 atanh(t) = 2 (t + t³/3 + t⁵/5 + …), t = (m-1)/(m+1), |t| < 0.172:
    // the first omitted term (t¹⁵/15) is below 2e-13.
    let t = (m - 1.0) / (m + 1.0);
    let t2 = t * t;
    let series = 1.0
        + t2 * (1.0 / 3.0
            + t2 * (1.0 / 5.0
                + t2 * (1.0 / 7.0 + t2 * (1.0 / 9.0 + t2 * (1.0 / 11.0 + t2 * (1.0 / 13.0))))));
    let ln_m = 2.0 * t * series;
    // (5/12) log2 x = 5e/12 + (5/12) ln m / ln 2. The integer part of 5e/12 is
    // split off exactly (with 5e shifted by 12 · 53, as e ≥ -127, the division
    // is of a number ≥ 0), which leaves a small argument for the series below.
    let five_e = (5 * e + 12 * 53) as u32;
    let whole = (five_e / 12) as i32 - 53;
    let remainder = f64::from(five_e % 12) / 12.0;
    let fraction = remainder + ln_m * (5.0 / 12.0 * std::f64::consts::LOG2_E);
    // 2^fraction for fraction in (-0.15, 1.07): round it to the nearest integer
    // `k` (0 or 1) and sum e^z, z = (fraction - k) ln 2, |z| ≤ 0.35, to the
    // term of degree 9 (the first omitted one is below 1e-11).
    let k = if fraction > 0.5 { 1 } else { 0 };
    let z = (fraction - f64::from(k)) * std::f64::consts::LN_2;
    let mut exp = 1.0 / 362_880.0;
    for factorial in [40_320.0, 5040.0, 720.0, 120.0, 24.0, 6.0, 2.0, 1.0, 1.0] {
        exp = exp * z + 1.0 / factorial;
    }
    let scale = f64::from_bits(((whole + k + 1023).clamp(1, 2046) as u64) << 52);
    exp * scale
}

#[cfg(test)]
mod tests {
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
            let exact = exact(x);
            let ulp = f64::from(f32::EPSILON) * f64::from(2f32.powi(exact.log2().floor() as i32));
            let error = (f64::from(encode_component(x)) - exact).abs() / ulp;
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
    fn a_slice_encodes_as_its_components_do_on_every_instruction_set() {
        // Whole blocks, repeated blocks and a remainder.
        let mut values: Vec<f32> = (0..1000).map(|i| i as f32 / 997.0 - 0.001).collect();
        values.extend([0.25; 2 * BLOCK + 5]);
        let mut encoded = values.clone();
        encode_in_place(&mut encoded);
        let mut portable = values.clone();
        encode_in_place_portable(&mut portable);
        for ((x, fast), slow) in values.iter().zip(&encoded).zip(&portable) {
            assert_eq!(fast.to_bits(), encode_component(*x).to_bits(), "{x}");
            assert_eq!(slow.to_bits(), fast.to_bits(), "{x}");
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
