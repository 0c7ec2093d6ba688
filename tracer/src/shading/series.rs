//! `log2` and `exp2` from short series in f64, without branches or calls, for
//! per-pixel loops (the sRGB curve): in a loop they compile to SIMD, where
//! `f32::powf` is a call per element. They use only `+ - * /` and no fused
//! multiply-add, so every instruction set gives the same bits, and they are
//! accurate to about 1e-14: `exp2(y · log2(x))` rounded to f32 is within 0.51
//! units in the last place of `x^y`, as close as `f32::powf` gets (tested).
//!
//! (Tried for the shader's specular `max(n·h, 0)^Ns` too: in its light loop
//! the f64 series cost what the `powf` calls did, and so did a SIMD loop of
//! its own over a block's lanes, so that stays `powf`.)

/// `log2 x` for finite `x > 0`; other inputs give some number.
#[inline(always)]
pub(crate) fn log2(x: f32) -> f64 {
    // Subnormals are scaled into the normal range first.
    let subnormal = x < f32::MIN_POSITIVE;
    let x = if subnormal { x * 16_777_216.0 } else { x };
    // x = m · 2^e with m in [√½, √2), both exact.
    let bits = x.to_bits();
    let mantissa = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000);
    let large = mantissa > std::f32::consts::SQRT_2;
    let m = f64::from(if large { 0.5 * mantissa } else { mantissa });
    let e = ((bits >> 23) & 0xff) as i32 - 127 + i32::from(large) - 24 * i32::from(subnormal);
    // ln m = 2 atanh(t) = 2 (t + t³/3 + t⁵/5 + …), t = (m-1)/(m+1), |t| < 0.172:
    // the first omitted term (t¹⁵/15) is below 2e-13 (relative: 1e-12).
    let t = (m - 1.0) / (m + 1.0);
    let t2 = t * t;
    let mut series = 1.0 / 13.0;
    for odd in [11.0, 9.0, 7.0, 5.0, 3.0, 1.0] {
        series = series * t2 + 1.0 / odd;
    }
    f64::from(e) + 2.0 * t * series * std::f64::consts::LOG2_E
}

/// `2^y`; 0 below -1022 and the largest power of two (times up to √2) above 1023.
#[inline(always)]
pub(crate) fn exp2(y: f64) -> f64 {
    // y = n + f with n an integer and |f| ≤ 1/2 (1.5 · 2^52 rounds to an integer).
    const ROUND: f64 = 6_755_399_441_055_744.0;
    let y_clamped = y.clamp(-1100.0, 1100.0);
    let n = (y_clamped + ROUND) - ROUND;
    // e^z with z = f ln 2, |z| ≤ 0.35, to the term of degree 11 (the first
    // omitted one is below 1e-14).
    let z = (y_clamped - n) * std::f64::consts::LN_2;
    let mut exp = 1.0 / 39_916_800.0;
    for factorial in [
        3_628_800.0,
        362_880.0,
        40_320.0,
        5040.0,
        720.0,
        120.0,
        24.0,
        6.0,
        2.0,
        1.0,
        1.0,
    ] {
        exp = exp * z + 1.0 / factorial;
    }
    // 2^n from its exponent field, the biased exponent taken from the low bits
    // of `biased + 2^52` (exact: an integer below 2^11): unlike a float-to-int
    // conversion, this compiles to SIMD.
    let biased = (n + 1023.0).clamp(1.0, 2046.0);
    let scale = f64::from_bits((biased + 4_503_599_627_370_496.0).to_bits() << 52);
    if y < -1022.0 {
        0.0
    } else {
        exp * scale
    }
}

/// `|a - exact|` in units of the last place of `exact` as an f32.
#[cfg(test)]
pub(super) fn ulps(a: f32, exact: f64) -> f64 {
    if exact == 0.0 {
        return f64::from(a.abs()) / f64::from(f32::from_bits(1));
    }
    let exponent = exact.abs().log2().floor().max(-126.0) as i32;
    let ulp = f64::from(f32::EPSILON) * 2f64.powi(exponent);
    (f64::from(a) - exact).abs() / ulp
}

#[cfg(test)]
mod tests {
    use super::*;

    fn powf(x: f32, y: f32) -> f32 {
        exp2(f64::from(y) * log2(x)) as f32
    }

    #[test]
    fn powers_are_within_half_an_ulp_over_bases_and_exponents() {
        let mut worst = (0.0, 0.0f32, 0.0f32);
        // Bases over all of (0, 1] and a little above, subnormals included.
        let bases = (1..=1_000_000u32).map(|i| f32::from_bits(i * 1066)).chain([
            f32::from_bits(1),
            1e-30,
            0.5,
            0.999_999_9,
            1.5,
            3.0,
        ]);
        // Exponents of the sRGB curve and of a wider range.
        for x in bases {
            for y in [
                1.0 / 2.4,
                1.0,
                2.0,
                5.0,
                32.0,
                77.7,
                250.0,
                1000.0,
                0.5,
                -1.0,
            ] {
                let exact = f64::from(x).powf(f64::from(y));
                if exact > f64::from(f32::MAX) || exact < f64::from(f32::MIN_POSITIVE) {
                    continue;
                }
                let error = ulps(powf(x, y), exact);
                if error > worst.0 {
                    worst = (error, x, y);
                }
            }
        }
        assert!(
            worst.0 <= 0.51,
            "{} ulps at {:e}^{}",
            worst.0,
            worst.1,
            worst.2
        );
    }

    #[test]
    fn exact_cases_and_the_ends_of_the_range() {
        assert_eq!(log2(8.0), 3.0);
        assert_eq!(log2(1.0), 0.0);
        assert_eq!(log2(f32::from_bits(1)), -149.0);
        assert_eq!(exp2(10.0), 1024.0);
        assert_eq!(exp2(-1100.0), 0.0);
        assert_eq!(powf(0.25, 0.5), 0.5);
    }
}
