//! Lane-parallel f32 arithmetic for the wide traversal, behind two traits: [`Lanes`]
//! (any width, for triangle tests) and [`Lanes8`] (eight lanes, for box tests).
//! Implementations: AVX-512 (eight lanes with compares into mask registers, and
//! sixteen lanes for triangles), AVX2 (eight lanes, and sixteen as two halves),
//! and a portable one (plain lane loops).
//! Each does exactly the IEEE operations the scalar code does (no fused
//! multiply-add, the same NaN rules), so all compute bit-identical results.
//!
//! The x86 implementations are zero-sized tokens that can only be made where the
//! CPU has the instructions (checked at run time), which keeps their methods safe.
//! Their methods are `#[inline(always)]`: the traversal is instantiated inside a
//! `#[target_feature]` function (see `wide.rs`), where the intrinsics inline.

/// Rows in memory are 16 floats; an implementation handles `N` (8 or 16) at a
/// time, from `offset`. Compares produce a bit mask: bit `i` for lane `i`.
pub(super) trait Lanes: Copy {
    const N: usize;
    type F: Copy;
    fn splat(self, x: f32) -> Self::F;
    fn load_at(self, row: &[f32; 16], offset: usize) -> Self::F;
    /// Lane `i` is `value(i)`, assembled in registers: a row of scalars just
    /// stored and loaded back as one vector would wait for the stores.
    fn lanes_of(self, value: impl Fn(usize) -> f32) -> Self::F;
    fn store_at(self, x: Self::F, row: &mut [f32; 16], offset: usize);
    fn add(self, a: Self::F, b: Self::F) -> Self::F;
    fn sub(self, a: Self::F, b: Self::F) -> Self::F;
    fn mul(self, a: Self::F, b: Self::F) -> Self::F;
    fn div(self, a: Self::F, b: Self::F) -> Self::F;
    /// `if a > b { a } else { b }` per lane: `b` when either is NaN.
    fn max_or_second(self, a: Self::F, b: Self::F) -> Self::F;
    /// `if a < b { a } else { b }` per lane: `b` when either is NaN.
    fn min_or_second(self, a: Self::F, b: Self::F) -> Self::F;
    /// Lanes of `a` where `mask` has a bit, else of `b`.
    fn select(self, mask: u32, a: Self::F, b: Self::F) -> Self::F;
    /// `a < b` (false for NaN), and so on.
    fn lt(self, a: Self::F, b: Self::F) -> u32;
    fn le(self, a: Self::F, b: Self::F) -> u32;
    fn gt(self, a: Self::F, b: Self::F) -> u32;
    fn eq(self, a: Self::F, b: Self::F) -> u32;
    /// `px·qy - py·qx` in f64 (where the products are exact), rounded to f32:
    /// the watertight test's re-evaluation of an edge function that came out
    /// exactly zero in f32.
    fn edge_in_f64(self, px: Self::F, py: Self::F, qx: Self::F, qy: Self::F) -> Self::F;
    /// The least and the greatest lane (for lanes without NaN).
    fn least(self, x: Self::F) -> f32;
    fn greatest(self, x: Self::F) -> f32;
}

/// Helpers built on [`Lanes`]. No closures: a closure is a function of its own,
/// compiled without the caller's target features, where intrinsics do not inline.
pub(super) trait LanesExt: Lanes {
    #[inline(always)]
    fn splat3(self, x: [f32; 3]) -> [Self::F; 3] {
        [self.splat(x[0]), self.splat(x[1]), self.splat(x[2])]
    }
    #[inline(always)]
    fn load_row(self, row: &[f32; 16]) -> Self::F {
        self.load_at(row, 0)
    }
    #[inline(always)]
    fn store_row(self, x: Self::F) -> [f32; 16] {
        let mut row = [0.0; 16];
        self.store_at(x, &mut row, 0);
        row
    }
}

impl<L: Lanes> LanesExt for L {}

/// Eight lanes, with rows of eight.
pub(super) trait Lanes8: Lanes {
    fn load(self, x: &[f32; 8]) -> Self::F;
    fn store(self, x: Self::F) -> [f32; 8];
}

/// Plain Rust, lane by lane: the reference the SIMD implementations must match.
#[derive(Clone, Copy, Debug)]
pub(super) struct Portable;

#[inline(always)]
fn lanes_map(a: [f32; 8], b: [f32; 8], f: impl Fn(f32, f32) -> f32) -> [f32; 8] {
    std::array::from_fn(|i| f(a[i], b[i]))
}

#[inline(always)]
fn lanes_mask(a: [f32; 8], b: [f32; 8], f: impl Fn(f32, f32) -> bool) -> u32 {
    (0..8).fold(0, |mask, i| mask | (u32::from(f(a[i], b[i])) << i))
}

impl Lanes for Portable {
    const N: usize = 8;
    type F = [f32; 8];
    #[inline(always)]
    fn splat(self, x: f32) -> [f32; 8] {
        [x; 8]
    }
    #[inline(always)]
    fn load_at(self, row: &[f32; 16], offset: usize) -> [f32; 8] {
        std::array::from_fn(|i| row[offset + i])
    }
    #[inline(always)]
    fn lanes_of(self, value: impl Fn(usize) -> f32) -> [f32; 8] {
        std::array::from_fn(value)
    }
    #[inline(always)]
    fn store_at(self, x: [f32; 8], row: &mut [f32; 16], offset: usize) {
        row[offset..offset + 8].copy_from_slice(&x);
    }
    #[inline(always)]
    fn add(self, a: [f32; 8], b: [f32; 8]) -> [f32; 8] {
        lanes_map(a, b, |a, b| a + b)
    }
    #[inline(always)]
    fn sub(self, a: [f32; 8], b: [f32; 8]) -> [f32; 8] {
        lanes_map(a, b, |a, b| a - b)
    }
    #[inline(always)]
    fn mul(self, a: [f32; 8], b: [f32; 8]) -> [f32; 8] {
        lanes_map(a, b, |a, b| a * b)
    }
    #[inline(always)]
    fn div(self, a: [f32; 8], b: [f32; 8]) -> [f32; 8] {
        lanes_map(a, b, |a, b| a / b)
    }
    #[inline(always)]
    fn max_or_second(self, a: [f32; 8], b: [f32; 8]) -> [f32; 8] {
        lanes_map(a, b, |a, b| if a > b { a } else { b })
    }
    #[inline(always)]
    fn min_or_second(self, a: [f32; 8], b: [f32; 8]) -> [f32; 8] {
        lanes_map(a, b, |a, b| if a < b { a } else { b })
    }
    #[inline(always)]
    fn select(self, mask: u32, a: [f32; 8], b: [f32; 8]) -> [f32; 8] {
        std::array::from_fn(|i| if mask >> i & 1 == 1 { a[i] } else { b[i] })
    }
    #[inline(always)]
    fn lt(self, a: [f32; 8], b: [f32; 8]) -> u32 {
        lanes_mask(a, b, |a, b| a < b)
    }
    #[inline(always)]
    fn le(self, a: [f32; 8], b: [f32; 8]) -> u32 {
        lanes_mask(a, b, |a, b| a <= b)
    }
    #[inline(always)]
    fn gt(self, a: [f32; 8], b: [f32; 8]) -> u32 {
        lanes_mask(a, b, |a, b| a > b)
    }
    #[inline(always)]
    fn eq(self, a: [f32; 8], b: [f32; 8]) -> u32 {
        lanes_mask(a, b, |a, b| a == b)
    }
    #[inline(always)]
    fn edge_in_f64(self, px: [f32; 8], py: [f32; 8], qx: [f32; 8], qy: [f32; 8]) -> [f32; 8] {
        std::array::from_fn(|i| {
            (f64::from(px[i]) * f64::from(qy[i]) - f64::from(py[i]) * f64::from(qx[i])) as f32
        })
    }
    #[inline(always)]
    fn least(self, x: [f32; 8]) -> f32 {
        x.into_iter().fold(f32::INFINITY, f32::min)
    }
    #[inline(always)]
    fn greatest(self, x: [f32; 8]) -> f32 {
        x.into_iter().fold(f32::NEG_INFINITY, f32::max)
    }
}

impl Lanes8 for Portable {
    #[inline(always)]
    fn load(self, x: &[f32; 8]) -> [f32; 8] {
        *x
    }
    #[inline(always)]
    fn store(self, x: [f32; 8]) -> [f32; 8] {
        x
    }
}

#[cfg(target_arch = "x86_64")]
pub(super) use x86::{Avx2, Avx512};

#[cfg(target_arch = "x86_64")]
mod x86 {
    use super::{Lanes, Lanes8};
    use std::arch::x86_64::*;

    /// Proof that the CPU runs AVX2 (made only by [`Avx2::detect`]).
    #[derive(Clone, Copy, Debug)]
    pub(in crate::bvh) struct Avx2(());

    impl Avx2 {
        pub(in crate::bvh) fn detect() -> Option<Avx2> {
            is_x86_feature_detected!("avx2").then_some(Avx2(()))
        }
    }

    impl Avx2 {
        /// Sixteen lanes in pairs of 256-bit registers.
        pub(in crate::bvh) fn x16(self) -> Avx2x16 {
            Avx2x16(self)
        }
    }

    /// Sixteen lanes as two halves of [`Avx2`] (made only from an [`Avx2`]
    /// token): packets of sixteen rays where the CPU has no AVX-512. Each op
    /// is its eight-lane op on each half; a mask's bits 8-15 are the high half's.
    #[derive(Clone, Copy, Debug)]
    pub(in crate::bvh) struct Avx2x16(Avx2);

    /// Proof that the CPU runs AVX-512 F and VL (made only by [`Avx512::detect`]):
    /// eight lanes in 256-bit registers, compares into mask registers.
    #[derive(Clone, Copy, Debug)]
    pub(in crate::bvh) struct Avx512(());

    impl Avx512 {
        pub(in crate::bvh) fn detect() -> Option<Avx512> {
            (is_x86_feature_detected!("avx2")
                && is_x86_feature_detected!("avx512f")
                && is_x86_feature_detected!("avx512vl"))
            .then_some(Avx512(()))
        }

        /// Sixteen lanes in 512-bit registers.
        pub(in crate::bvh) fn x16(self) -> Avx512x16 {
            Avx512x16(())
        }
    }

    /// Sixteen lanes of AVX-512 (made only from an [`Avx512`] token).
    #[derive(Clone, Copy, Debug)]
    pub(in crate::bvh) struct Avx512x16(());

    // SAFETY (every `unsafe` block below): the token proves the features exist,
    // and `offset + N <= 16` for every row access (the callers' loop bounds).
    macro_rules! ops_256 {
        () => {
            const N: usize = 8;
            type F = __m256;
            #[inline(always)]
            fn splat(self, x: f32) -> __m256 {
                unsafe { _mm256_set1_ps(x) }
            }
            #[inline(always)]
            fn load_at(self, row: &[f32; 16], offset: usize) -> __m256 {
                assert!(offset <= 8);
                unsafe { _mm256_loadu_ps(row.as_ptr().add(offset)) }
            }
            #[inline(always)]
            fn lanes_of(self, value: impl Fn(usize) -> f32) -> __m256 {
                unsafe {
                    _mm256_setr_ps(
                        value(0),
                        value(1),
                        value(2),
                        value(3),
                        value(4),
                        value(5),
                        value(6),
                        value(7),
                    )
                }
            }
            #[inline(always)]
            fn store_at(self, x: __m256, row: &mut [f32; 16], offset: usize) {
                assert!(offset <= 8);
                unsafe { _mm256_storeu_ps(row.as_mut_ptr().add(offset), x) }
            }
            #[inline(always)]
            fn add(self, a: __m256, b: __m256) -> __m256 {
                unsafe { _mm256_add_ps(a, b) }
            }
            #[inline(always)]
            fn sub(self, a: __m256, b: __m256) -> __m256 {
                unsafe { _mm256_sub_ps(a, b) }
            }
            #[inline(always)]
            fn mul(self, a: __m256, b: __m256) -> __m256 {
                unsafe { _mm256_mul_ps(a, b) }
            }
            #[inline(always)]
            fn div(self, a: __m256, b: __m256) -> __m256 {
                unsafe { _mm256_div_ps(a, b) }
            }
            // vmaxps/vminps return the second operand when either is NaN.
            #[inline(always)]
            fn max_or_second(self, a: __m256, b: __m256) -> __m256 {
                unsafe { _mm256_max_ps(a, b) }
            }
            #[inline(always)]
            fn min_or_second(self, a: __m256, b: __m256) -> __m256 {
                unsafe { _mm256_min_ps(a, b) }
            }
            // Four lanes at a time in f64: vmulpd is exact for f32 inputs, and
            // vsubpd and vcvtpd2ps round as the scalar code does.
            #[inline(always)]
            fn edge_in_f64(self, px: __m256, py: __m256, qx: __m256, qy: __m256) -> __m256 {
                unsafe {
                    let low = _mm256_cvtpd_ps(_mm256_sub_pd(
                        _mm256_mul_pd(
                            _mm256_cvtps_pd(_mm256_castps256_ps128(px)),
                            _mm256_cvtps_pd(_mm256_castps256_ps128(qy)),
                        ),
                        _mm256_mul_pd(
                            _mm256_cvtps_pd(_mm256_castps256_ps128(py)),
                            _mm256_cvtps_pd(_mm256_castps256_ps128(qx)),
                        ),
                    ));
                    let high = _mm256_cvtpd_ps(_mm256_sub_pd(
                        _mm256_mul_pd(
                            _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(px)),
                            _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(qy)),
                        ),
                        _mm256_mul_pd(
                            _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(py)),
                            _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(qx)),
                        ),
                    ));
                    _mm256_set_m128(high, low)
                }
            }
            #[inline(always)]
            fn least(self, x: __m256) -> f32 {
                unsafe { least_of_8(x) }
            }
            #[inline(always)]
            fn greatest(self, x: __m256) -> f32 {
                unsafe { greatest_of_8(x) }
            }
        };
    }

    // SAFETY: callers hold a token for AVX (AVX2 or AVX-512).
    #[inline(always)]
    unsafe fn least_of_8(x: __m256) -> f32 {
        unsafe {
            let m = _mm_min_ps(_mm256_castps256_ps128(x), _mm256_extractf128_ps::<1>(x));
            let m = _mm_min_ps(m, _mm_movehl_ps(m, m));
            _mm_cvtss_f32(_mm_min_ss(m, _mm_shuffle_ps::<1>(m, m)))
        }
    }

    #[inline(always)]
    unsafe fn greatest_of_8(x: __m256) -> f32 {
        unsafe {
            let m = _mm_max_ps(_mm256_castps256_ps128(x), _mm256_extractf128_ps::<1>(x));
            let m = _mm_max_ps(m, _mm_movehl_ps(m, m));
            _mm_cvtss_f32(_mm_max_ss(m, _mm_shuffle_ps::<1>(m, m)))
        }
    }

    macro_rules! lanes8_256 {
        ($token:ty) => {
            impl Lanes8 for $token {
                #[inline(always)]
                fn load(self, x: &[f32; 8]) -> __m256 {
                    unsafe { _mm256_loadu_ps(x.as_ptr()) }
                }
                #[inline(always)]
                fn store(self, x: __m256) -> [f32; 8] {
                    let mut out = [0.0; 8];
                    unsafe { _mm256_storeu_ps(out.as_mut_ptr(), x) };
                    out
                }
            }
        };
    }

    impl Lanes for Avx2 {
        ops_256!();
        #[inline(always)]
        fn select(self, mask: u32, a: __m256, b: __m256) -> __m256 {
            unsafe {
                let bits = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
                let chosen = _mm256_and_si256(_mm256_set1_epi32(mask as i32), bits);
                let chosen = _mm256_castsi256_ps(_mm256_cmpeq_epi32(chosen, bits));
                _mm256_blendv_ps(b, a, chosen)
            }
        }
        #[inline(always)]
        fn lt(self, a: __m256, b: __m256) -> u32 {
            unsafe { _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LT_OQ>(a, b)) as u32 }
        }
        #[inline(always)]
        fn le(self, a: __m256, b: __m256) -> u32 {
            unsafe { _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(a, b)) as u32 }
        }
        #[inline(always)]
        fn gt(self, a: __m256, b: __m256) -> u32 {
            unsafe { _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(a, b)) as u32 }
        }
        #[inline(always)]
        fn eq(self, a: __m256, b: __m256) -> u32 {
            unsafe { _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_EQ_OQ>(a, b)) as u32 }
        }
    }
    lanes8_256!(Avx2);

    impl Lanes for Avx512 {
        ops_256!();
        #[inline(always)]
        fn select(self, mask: u32, a: __m256, b: __m256) -> __m256 {
            unsafe { _mm256_mask_blend_ps(mask as __mmask8, b, a) }
        }
        #[inline(always)]
        fn lt(self, a: __m256, b: __m256) -> u32 {
            u32::from(unsafe { _mm256_cmp_ps_mask::<_CMP_LT_OQ>(a, b) })
        }
        #[inline(always)]
        fn le(self, a: __m256, b: __m256) -> u32 {
            u32::from(unsafe { _mm256_cmp_ps_mask::<_CMP_LE_OQ>(a, b) })
        }
        #[inline(always)]
        fn gt(self, a: __m256, b: __m256) -> u32 {
            u32::from(unsafe { _mm256_cmp_ps_mask::<_CMP_GT_OQ>(a, b) })
        }
        #[inline(always)]
        fn eq(self, a: __m256, b: __m256) -> u32 {
            u32::from(unsafe { _mm256_cmp_ps_mask::<_CMP_EQ_OQ>(a, b) })
        }
    }
    lanes8_256!(Avx512);

    impl Lanes for Avx512x16 {
        const N: usize = 16;
        type F = __m512;
        #[inline(always)]
        fn splat(self, x: f32) -> __m512 {
            unsafe { _mm512_set1_ps(x) }
        }
        #[inline(always)]
        fn load_at(self, row: &[f32; 16], offset: usize) -> __m512 {
            assert!(offset == 0);
            unsafe { _mm512_loadu_ps(row.as_ptr()) }
        }
        #[inline(always)]
        fn lanes_of(self, value: impl Fn(usize) -> f32) -> __m512 {
            unsafe {
                _mm512_setr_ps(
                    value(0),
                    value(1),
                    value(2),
                    value(3),
                    value(4),
                    value(5),
                    value(6),
                    value(7),
                    value(8),
                    value(9),
                    value(10),
                    value(11),
                    value(12),
                    value(13),
                    value(14),
                    value(15),
                )
            }
        }
        #[inline(always)]
        fn store_at(self, x: __m512, row: &mut [f32; 16], offset: usize) {
            assert!(offset == 0);
            unsafe { _mm512_storeu_ps(row.as_mut_ptr(), x) }
        }
        #[inline(always)]
        fn add(self, a: __m512, b: __m512) -> __m512 {
            unsafe { _mm512_add_ps(a, b) }
        }
        #[inline(always)]
        fn sub(self, a: __m512, b: __m512) -> __m512 {
            unsafe { _mm512_sub_ps(a, b) }
        }
        #[inline(always)]
        fn mul(self, a: __m512, b: __m512) -> __m512 {
            unsafe { _mm512_mul_ps(a, b) }
        }
        #[inline(always)]
        fn div(self, a: __m512, b: __m512) -> __m512 {
            unsafe { _mm512_div_ps(a, b) }
        }
        #[inline(always)]
        fn max_or_second(self, a: __m512, b: __m512) -> __m512 {
            unsafe { _mm512_max_ps(a, b) }
        }
        #[inline(always)]
        fn min_or_second(self, a: __m512, b: __m512) -> __m512 {
            unsafe { _mm512_min_ps(a, b) }
        }
        #[inline(always)]
        fn select(self, mask: u32, a: __m512, b: __m512) -> __m512 {
            unsafe { _mm512_mask_blend_ps(mask as __mmask16, b, a) }
        }
        #[inline(always)]
        fn lt(self, a: __m512, b: __m512) -> u32 {
            u32::from(unsafe { _mm512_cmp_ps_mask::<_CMP_LT_OQ>(a, b) })
        }
        #[inline(always)]
        fn le(self, a: __m512, b: __m512) -> u32 {
            u32::from(unsafe { _mm512_cmp_ps_mask::<_CMP_LE_OQ>(a, b) })
        }
        #[inline(always)]
        fn gt(self, a: __m512, b: __m512) -> u32 {
            u32::from(unsafe { _mm512_cmp_ps_mask::<_CMP_GT_OQ>(a, b) })
        }
        #[inline(always)]
        fn eq(self, a: __m512, b: __m512) -> u32 {
            u32::from(unsafe { _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(a, b) })
        }
        // Eight lanes at a time in f64, as in `ops_256`. (No closures: see `LanesExt`.)
        #[inline(always)]
        fn edge_in_f64(self, px: __m512, py: __m512, qx: __m512, qy: __m512) -> __m512 {
            unsafe {
                let low = _mm512_cvtpd_ps(_mm512_sub_pd(
                    _mm512_mul_pd(
                        _mm512_cvtps_pd(_mm512_castps512_ps256(px)),
                        _mm512_cvtps_pd(_mm512_castps512_ps256(qy)),
                    ),
                    _mm512_mul_pd(
                        _mm512_cvtps_pd(_mm512_castps512_ps256(py)),
                        _mm512_cvtps_pd(_mm512_castps512_ps256(qx)),
                    ),
                ));
                let high = _mm512_cvtpd_ps(_mm512_sub_pd(
                    _mm512_mul_pd(
                        _mm512_cvtps_pd(_mm256_castpd_ps(_mm512_extractf64x4_pd::<1>(
                            _mm512_castps_pd(px),
                        ))),
                        _mm512_cvtps_pd(_mm256_castpd_ps(_mm512_extractf64x4_pd::<1>(
                            _mm512_castps_pd(qy),
                        ))),
                    ),
                    _mm512_mul_pd(
                        _mm512_cvtps_pd(_mm256_castpd_ps(_mm512_extractf64x4_pd::<1>(
                            _mm512_castps_pd(py),
                        ))),
                        _mm512_cvtps_pd(_mm256_castpd_ps(_mm512_extractf64x4_pd::<1>(
                            _mm512_castps_pd(qx),
                        ))),
                    ),
                ));
                let low = _mm512_castps_pd(_mm512_castps256_ps512(low));
                _mm512_castpd_ps(_mm512_insertf64x4::<1>(low, _mm256_castps_pd(high)))
            }
        }
        #[inline(always)]
        fn least(self, x: __m512) -> f32 {
            unsafe { _mm512_reduce_min_ps(x) }
        }
        #[inline(always)]
        fn greatest(self, x: __m512) -> f32 {
            unsafe { _mm512_reduce_max_ps(x) }
        }
    }

    impl Lanes for Avx2x16 {
        const N: usize = 16;
        type F = [__m256; 2];
        #[inline(always)]
        fn splat(self, x: f32) -> [__m256; 2] {
            let half = self.0.splat(x);
            [half, half]
        }
        #[inline(always)]
        fn load_at(self, row: &[f32; 16], offset: usize) -> [__m256; 2] {
            assert!(offset == 0);
            [self.0.load_at(row, 0), self.0.load_at(row, 8)]
        }
        #[inline(always)]
        fn lanes_of(self, value: impl Fn(usize) -> f32) -> [__m256; 2] {
            [
                self.0.lanes_of(&value),
                self.0.lanes_of(|lane| value(8 + lane)),
            ]
        }
        #[inline(always)]
        fn store_at(self, x: [__m256; 2], row: &mut [f32; 16], offset: usize) {
            assert!(offset == 0);
            self.0.store_at(x[0], row, 0);
            self.0.store_at(x[1], row, 8);
        }
        #[inline(always)]
        fn add(self, a: [__m256; 2], b: [__m256; 2]) -> [__m256; 2] {
            [self.0.add(a[0], b[0]), self.0.add(a[1], b[1])]
        }
        #[inline(always)]
        fn sub(self, a: [__m256; 2], b: [__m256; 2]) -> [__m256; 2] {
            [self.0.sub(a[0], b[0]), self.0.sub(a[1], b[1])]
        }
        #[inline(always)]
        fn mul(self, a: [__m256; 2], b: [__m256; 2]) -> [__m256; 2] {
            [self.0.mul(a[0], b[0]), self.0.mul(a[1], b[1])]
        }
        #[inline(always)]
        fn div(self, a: [__m256; 2], b: [__m256; 2]) -> [__m256; 2] {
            [self.0.div(a[0], b[0]), self.0.div(a[1], b[1])]
        }
        #[inline(always)]
        fn max_or_second(self, a: [__m256; 2], b: [__m256; 2]) -> [__m256; 2] {
            [
                self.0.max_or_second(a[0], b[0]),
                self.0.max_or_second(a[1], b[1]),
            ]
        }
        #[inline(always)]
        fn min_or_second(self, a: [__m256; 2], b: [__m256; 2]) -> [__m256; 2] {
            [
                self.0.min_or_second(a[0], b[0]),
                self.0.min_or_second(a[1], b[1]),
            ]
        }
        #[inline(always)]
        fn select(self, mask: u32, a: [__m256; 2], b: [__m256; 2]) -> [__m256; 2] {
            [
                self.0.select(mask & 0xff, a[0], b[0]),
                self.0.select(mask >> 8, a[1], b[1]),
            ]
        }
        #[inline(always)]
        fn lt(self, a: [__m256; 2], b: [__m256; 2]) -> u32 {
            self.0.lt(a[0], b[0]) | self.0.lt(a[1], b[1]) << 8
        }
        #[inline(always)]
        fn le(self, a: [__m256; 2], b: [__m256; 2]) -> u32 {
            self.0.le(a[0], b[0]) | self.0.le(a[1], b[1]) << 8
        }
        #[inline(always)]
        fn gt(self, a: [__m256; 2], b: [__m256; 2]) -> u32 {
            self.0.gt(a[0], b[0]) | self.0.gt(a[1], b[1]) << 8
        }
        #[inline(always)]
        fn eq(self, a: [__m256; 2], b: [__m256; 2]) -> u32 {
            self.0.eq(a[0], b[0]) | self.0.eq(a[1], b[1]) << 8
        }
        #[inline(always)]
        fn edge_in_f64(
            self,
            px: [__m256; 2],
            py: [__m256; 2],
            qx: [__m256; 2],
            qy: [__m256; 2],
        ) -> [__m256; 2] {
            [
                self.0.edge_in_f64(px[0], py[0], qx[0], qy[0]),
                self.0.edge_in_f64(px[1], py[1], qx[1], qy[1]),
            ]
        }
        #[inline(always)]
        fn least(self, x: [__m256; 2]) -> f32 {
            self.0.least(self.0.min_or_second(x[0], x[1]))
        }
        #[inline(always)]
        fn greatest(self, x: [__m256; 2]) -> f32 {
            self.0.greatest(self.0.max_or_second(x[0], x[1]))
        }
    }
}
