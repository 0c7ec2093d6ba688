//! Vector arithmetic that holds over f32's whole range, for the places that
//! see world-space sizes (scenes may be 1e15 or 1e-14 across): a triangle's
//! normal is a cross product of two edges, and its squared length (the fourth
//! power of the edges) overflows f32 for edges above about 4e9 and underflows
//! below about 1e-10. The WGSL twin is `tracer_unit_or_zero` in
//! `functors/wgsl/vector.wgsl`.

use glam::Vec3;

/// `v.normalize_or_zero()`, except that a nonzero vector whose squared length
/// overflows or underflows is first multiplied by the power of two that
/// brings its largest component into `1 .. 2` (an exact scaling). Ordinary
/// vectors get glam's bits.
#[inline]
pub fn unit_or_zero(v: Vec3) -> Vec3 {
    let unit = v.normalize_or_zero();
    if unit != Vec3::ZERO || v == Vec3::ZERO || !v.is_finite() {
        return unit;
    }
    (v * power_of_two_scale(v.abs().max_element())).normalize_or_zero()
}

/// The power of two `2^-e` for `x = m · 2^e` with `1 <= m < 2`, clamped to the
/// normal f32 range (`2^127` for subnormal `x`).
fn power_of_two_scale(x: f32) -> f32 {
    let biased_exponent = (x.to_bits() >> 23) & 0xff;
    f32::from_bits(254u32.saturating_sub(biased_exponent).clamp(1, 254) << 23)
}

#[cfg(test)]
mod tests {
    use super::unit_or_zero;
    use glam::Vec3;

    #[test]
    fn units_of_vectors_too_long_or_too_short_to_square() {
        for scale in [1.0, 1e30, 1e-30, 5e37, 1e-40] {
            let v = Vec3::new(3.0, 0.0, -4.0) * scale;
            let unit = unit_or_zero(v);
            assert!(
                (unit - Vec3::new(0.6, 0.0, -0.8)).length() < 1e-4,
                "{scale}: {unit}"
            );
        }
        // Ordinary vectors: glam's bits.
        let v = Vec3::new(0.3, -1.7, 2.9);
        assert_eq!(unit_or_zero(v), v.normalize_or_zero());
        assert_eq!(unit_or_zero(Vec3::ZERO), Vec3::ZERO);
        assert_eq!(unit_or_zero(Vec3::new(f32::INFINITY, 0.0, 0.0)), Vec3::ZERO);
    }
}
