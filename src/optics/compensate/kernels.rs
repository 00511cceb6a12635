//! The vector kernels of the set-up's pass over the field: Horner evaluation of the field
//! polynomial along a row, and the sum and extremes of a run of P values. Each has a
//! portable version (fixed-width lanes the compiler vectorizes) and an AVX2 version that
//! gives the same bits (the same operations in the same order, no fused multiply-add).
//! The AVX2 versions run only where the CPU has AVX2 (see [`super::field_pass`]).

/// The f64 sum of f32 values and their smallest and largest (plain comparisons, which
/// skip NaN), in four lanes. The sum is the same as adding them one by one only when every
/// sum of them is exact ([`sums_are_exact`](super::field_pass::sums_are_exact)); the extremes are the same except, possibly,
/// which of +0 and −0 is the smallest or largest.
#[inline(always)]
pub(super) fn sum_and_extremes(vals: &[f32]) -> (f64, f32, f32) {
    let mut acc = [0f64; 4];
    let (mut lo, mut hi) = ([f32::INFINITY; 4], [f32::NEG_INFINITY; 4]);
    let mut chunks = vals.chunks_exact(4);
    for c in &mut chunks {
        for k in 0..4 {
            let v = c[k];
            acc[k] += v as f64;
            lo[k] = if v < lo[k] { v } else { lo[k] };
            hi[k] = if v > hi[k] { v } else { hi[k] };
        }
    }
    combine_lanes(&acc, &lo, &hi, chunks.remainder())
}

/// [`sum_and_extremes`] with AVX2 (eight lanes, the last ones masked): the same sum when it is
/// exact, the same extremes (VMINPS/VMAXPS compare like the plain comparisons).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
pub(super) fn sum_and_extremes_avx2(vals: &[f32]) -> (f64, f32, f32) {
    use std::arch::x86_64::*;
    let (mut s0, mut s1) = (_mm256_setzero_pd(), _mm256_setzero_pd());
    let (inf, ninf) = (
        _mm256_set1_ps(f32::INFINITY),
        _mm256_set1_ps(f32::NEG_INFINITY),
    );
    let (mut lo, mut hi) = (inf, ninf);
    let mut chunks = vals.chunks_exact(8);
    for c in &mut chunks {
        // SAFETY: `c` holds eight f32.
        let v = unsafe { _mm256_loadu_ps(c.as_ptr()) };
        s0 = _mm256_add_pd(s0, _mm256_cvtps_pd(_mm256_castps256_ps128(v)));
        s1 = _mm256_add_pd(s1, _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(v)));
        // VMINPS a, b = a < b ? a : b.
        lo = _mm256_min_ps(v, lo);
        hi = _mm256_max_ps(v, hi);
    }
    let rest = chunks.remainder();
    if !rest.is_empty() {
        // The last 1 to 7 values: the other lanes load +0 (adding nothing to the sums)
        // and take ±∞ for the extremes.
        let mask = _mm256_cmpgt_epi32(
            _mm256_set1_epi32(rest.len() as i32),
            _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
        );
        // SAFETY: only the lanes of `mask` (the first `rest.len()`) are read.
        let v = unsafe { _mm256_maskload_ps(rest.as_ptr(), mask) };
        s0 = _mm256_add_pd(s0, _mm256_cvtps_pd(_mm256_castps256_ps128(v)));
        s1 = _mm256_add_pd(s1, _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(v)));
        let m = _mm256_castsi256_ps(mask);
        lo = _mm256_min_ps(_mm256_blendv_ps(inf, v, m), lo);
        hi = _mm256_max_ps(_mm256_blendv_ps(ninf, v, m), hi);
    }
    // Horizontal: lanes 0–3 with 4–7, then pairs, then the last two.
    let s = _mm256_add_pd(s0, s1);
    let s = _mm_add_pd(_mm256_castpd256_pd128(s), _mm256_extractf128_pd::<1>(s));
    let sum = _mm_cvtsd_f64(_mm_add_sd(s, _mm_unpackhi_pd(s, s)));
    let l = _mm_min_ps(_mm256_castps256_ps128(lo), _mm256_extractf128_ps::<1>(lo));
    let l = _mm_min_ps(l, _mm_movehl_ps(l, l));
    let l = _mm_cvtss_f32(_mm_min_ss(l, _mm_shuffle_ps::<1>(l, l)));
    let h = _mm_max_ps(_mm256_castps256_ps128(hi), _mm256_extractf128_ps::<1>(hi));
    let h = _mm_max_ps(h, _mm_movehl_ps(h, h));
    let h = _mm_cvtss_f32(_mm_max_ss(h, _mm_shuffle_ps::<1>(h, h)));
    (sum, l, h)
}

/// Combines the lanes of [`sum_and_extremes`] and adds the values left over.
#[inline(always)]
fn combine_lanes(acc: &[f64], lo: &[f32], hi: &[f32], rest: &[f32]) -> (f64, f32, f32) {
    let mut sum = acc.iter().fold(0.0, |s, &a| s + a);
    for &v in rest {
        sum += v as f64;
    }
    let (mut l, mut h) = min_max(rest);
    for (&a, &b) in lo.iter().zip(hi) {
        l = if a < l { a } else { l };
        h = if b > h { b } else { h };
    }
    (sum, l, h)
}

/// Smallest and largest of `vals` (plain comparisons, which skip NaN).
#[inline]
pub(super) fn min_max(vals: &[f32]) -> (f32, f32) {
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for &v in vals {
        lo = if v < lo { v } else { lo };
        hi = if v > hi { v } else { hi };
    }
    (lo, hi)
}

/// `out[i]` = the polynomial with coefficients `a` (constant first) at `us[i]` by Horner's
/// rule in f64 (from 0: 0·u + a_n, …), rounded to f32, times `scale` in f32 (1 is exact);
/// four lanes at a time.
#[inline(always)]
pub(super) fn horner_f32(out: &mut [f32], us: &[f64], a: &[f64], scale: f32) {
    #[inline(always)]
    fn lanes<const N: usize>(o: &mut [f32], u: &[f64], a: &[f64], scale: f32) {
        let mut acc = [0f64; N];
        for &k in a.iter().rev() {
            for l in 0..N {
                acc[l] = acc[l] * u[l] + k;
            }
        }
        for l in 0..N {
            o[l] = acc[l] as f32 * scale;
        }
    }
    let mut oc = out.chunks_exact_mut(4);
    let mut uc = us.chunks_exact(4);
    match <[f64; 4]>::try_from(a) {
        // A cubic (the common case): coefficients known to the unrolled loop.
        Ok(a4) => {
            for (o, u) in (&mut oc).zip(&mut uc) {
                lanes::<4>(o, u, &a4, scale);
            }
        }
        Err(_) => {
            for (o, u) in (&mut oc).zip(&mut uc) {
                lanes::<4>(o, u, a, scale);
            }
        }
    }
    for (o, u) in oc.into_remainder().iter_mut().zip(uc.remainder()) {
        lanes::<1>(std::slice::from_mut(o), std::slice::from_ref(u), a, scale);
    }
}

/// [`horner_f32`] with AVX2 (four f64 lanes; the same multiplications and additions, not
/// fused, and the same roundings to f32, so the same values). `from_top`: every u is
/// finite and the highest coefficient finite and nonzero, so Horner's first step
/// (0·u + a_n) gives a_n exactly and is left out.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
pub(super) fn horner_avx2(out: &mut [f32], us: &[f64], a: &[f64], scale: f32, from_top: bool) {
    use std::arch::x86_64::*;
    #[target_feature(enable = "avx2")]
    #[inline]
    fn run<const N: usize, const TOP: bool>(
        out: &mut [f32],
        us: &[f64],
        a: &[f64],
        scale: f32,
    ) -> usize {
        let mut k = [_mm256_setzero_pd(); crate::optics::field::MAX_DEGREE + 1];
        for (k, &c) in k.iter_mut().zip(a.iter().rev()) {
            *k = _mm256_set1_pd(c);
        }
        let k = &k[..if N > 0 { N } else { a.len() }];
        let sc = _mm_set1_ps(scale);
        let n = out.len().min(us.len()) / 4 * 4;
        for (o, u) in out[..n].chunks_exact_mut(4).zip(us.chunks_exact(4)) {
            // SAFETY: `u` holds four f64.
            let u = unsafe { _mm256_loadu_pd(u.as_ptr()) };
            let (mut acc, rest) = if TOP {
                (k[0], &k[1..])
            } else {
                (_mm256_setzero_pd(), k)
            };
            for &k in rest {
                acc = _mm256_add_pd(_mm256_mul_pd(acc, u), k);
            }
            let f = _mm_mul_ps(_mm256_cvtpd_ps(acc), sc);
            // SAFETY: `o` holds four f32.
            unsafe { _mm_storeu_ps(o.as_mut_ptr(), f) };
        }
        n
    }
    // A cubic's four coefficients as a fixed count (unrolled).
    let n = match (a.len() == 4, from_top && !a.is_empty()) {
        (true, true) => run::<4, true>(out, us, a, scale),
        (true, false) => run::<4, false>(out, us, a, scale),
        (false, true) => run::<0, true>(out, us, a, scale),
        (false, false) => run::<0, false>(out, us, a, scale),
    };
    horner_f32(&mut out[n..], &us[n..], a, scale);
}

#[cfg(test)]
mod tests {
    use super::super::test_support::rng;
    use super::*;

    #[test]
    fn horner_avx2_from_the_top_equals_horner_from_zero() {
        // Leaving out Horner's first step (0·u + a_n = a_n for finite u and a finite
        // nonzero a_n) changes no bit; with a zero top coefficient the full rule runs.
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            let mut rnd = rng(0x5851_f42d_4c95_7f2d);
            for case in 0..40 {
                let n = 1 + case % 7;
                let mut a: Vec<f64> = (0..n).map(|_| (rnd() - 0.5) * 3.0).collect();
                if case % 5 == 4 {
                    *a.last_mut().unwrap() = if case % 2 == 0 { 0.0 } else { -0.0 };
                }
                let us: Vec<f64> = (0..37).map(|_| (rnd() - 0.5) * 8.0).collect();
                let top = a.last().is_some_and(|&c| c.is_finite() && c != 0.0);
                let mut want = vec![0f32; us.len()];
                horner_f32(&mut want, &us, &a, 0.7);
                for from_top in [top, false] {
                    let mut got = vec![0f32; us.len()];
                    // SAFETY: the CPU has AVX2.
                    unsafe { horner_avx2(&mut got, &us, &a, 0.7, from_top) };
                    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                    assert_eq!(bits(&got), bits(&want), "case {case} from_top {from_top}");
                }
            }
        }
    }

    #[test]
    fn sum_and_extremes_with_and_without_avx2_agree_with_one_by_one() {
        let mut rnd = rng(7);
        for len in (0..40).chain([257, 1024]) {
            let vals: Vec<f32> = (0..len).map(|_| (1.0 + rnd() * 3.0) as f32).collect();
            let s = vals.iter().fold(0.0, |s, &v| s + v as f64);
            let (lo, hi) = min_max(&vals);
            assert_eq!(sum_and_extremes(&vals), (s, lo, hi), "len {len}");
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU has AVX2.
                assert_eq!(
                    unsafe { sum_and_extremes_avx2(&vals) },
                    (s, lo, hi),
                    "len {len}"
                );
            }
        }
    }
}
