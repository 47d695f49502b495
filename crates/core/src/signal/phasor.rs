//! Sums of a record against a complex exponential `e^{i 2π c n}` (one DTFT bin at an arbitrary
//! frequency, sinusoid fitting), computed with [`LANES`] interleaved phasor recurrences.
//!
//! One recurrence `z ← z · e^{i 2π c}` is a chain of dependent multiplications: the CPU waits
//! for each step before starting the next (≈ 8 cycles a sample). Running `LANES` recurrences,
//! lane `r` covering samples `n ≡ r (mod LANES)` and stepping by `e^{i 2π c LANES}`, makes the
//! steps independent (and vectorisable); the phases are re-anchored exactly (`sin_cos` of the
//! phase reduced to one cycle, times the exact lane offsets) every [`RESYNC`] samples, so the
//! rounding drift stays at the 1e-14 level whatever the record length. On x86-64 CPUs with AVX2
//! the same code runs with 256-bit vectors (runtime detection; identical results). Results agree with a single recurrence to
//! rounding, not bit for bit (the sums are accumulated per lane, then added).

use std::f64::consts::TAU;

/// Number of interleaved recurrences.
pub(crate) const LANES: usize = 16;
/// Samples between exact re-anchorings of the phases (a multiple of [`LANES`]).
pub(crate) const RESYNC: usize = 1024;

/// Per-frequency constants: the lane step `e^{i 2π c LANES}` and the lane offsets
/// `e^{i 2π c r}`, `r < LANES`.
struct Steps {
    cyc: f64,
    rc: f64,
    rs: f64,
    oc: [f64; LANES],
    os: [f64; LANES],
}

impl Steps {
    #[inline(always)]
    fn new(cyc: f64) -> Self {
        let (rs, rc) = (TAU * cyc * LANES as f64).sin_cos();
        let mut oc = [0.0; LANES];
        let mut os = [0.0; LANES];
        for r in 0..LANES {
            let (s, c) = ((cyc * r as f64).fract() * TAU).sin_cos();
            oc[r] = c;
            os[r] = s;
        }
        Steps {
            cyc,
            rc,
            rs,
            oc,
            os,
        }
    }

    /// The phasors `e^{i 2π c (n0 + r)}`, `r < LANES`, as (cos, sin) lanes: one exact
    /// `sin_cos` of the block phase (reduced to one cycle) times the lane offsets.
    #[inline(always)]
    fn anchor(&self, n0: usize) -> ([f64; LANES], [f64; LANES]) {
        let (s, c) = ((self.cyc * n0 as f64).fract() * TAU).sin_cos();
        let mut zc = [0.0; LANES];
        let mut zs = [0.0; LANES];
        for r in 0..LANES {
            zc[r] = c * self.oc[r] - s * self.os[r];
            zs[r] = c * self.os[r] + s * self.oc[r];
        }
        (zc, zs)
    }
}

/// Run `$body` with AVX2 enabled when the CPU has it (the same lane arithmetic, twice as wide
/// per instruction; no FMA contraction, so the results are identical to the plain path).
macro_rules! dispatch {
    ($name:ident, $avx:ident, ($($arg:ident: $ty:ty),*) -> $ret:ty) => {
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2")]
        unsafe fn $avx($($arg: $ty),*) -> $ret {
            $name($($arg),*)
        }
    };
}

/// `(Σ v[n] cos(2π c n), Σ v[n] sin(2π c n))`.
#[inline(always)]
fn dtft_sums_impl(v: &[f64], cyc: f64) -> (f64, f64) {
    let st = Steps::new(cyc);
    let (rs, rc) = (st.rs, st.rc);
    let mut re = [0.0; LANES];
    let mut im = [0.0; LANES];
    for (b, block) in v.chunks(RESYNC).enumerate() {
        let (mut zc, mut zs) = st.anchor(b * RESYNC);
        let mut it = block.chunks_exact(LANES);
        for q in &mut it {
            for r in 0..LANES {
                re[r] += q[r] * zc[r];
                im[r] += q[r] * zs[r];
                let c = zc[r] * rc - zs[r] * rs;
                zs[r] = zc[r] * rs + zs[r] * rc;
                zc[r] = c;
            }
        }
        for (r, &x) in it.remainder().iter().enumerate() {
            re[r] += x * zc[r];
            im[r] += x * zs[r];
        }
    }
    (re.iter().sum(), im.iter().sum())
}

dispatch!(dtft_sums_impl, dtft_sums_avx2, (v: &[f64], cyc: f64) -> (f64, f64));

#[doc = concat!("See [`", stringify!(dtft_sums_impl), "`]; AVX2 when available.")]
pub(crate) fn dtft_sums(v: &[f64], cyc: f64) -> (f64, f64) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (checked just above).
        return unsafe { dtft_sums_avx2(v, cyc) };
    }
    dtft_sums_impl(v, cyc)
}

/// The unit phasors `e^{i 2π c n}`, `n < cos.len()`, written as `(cos, sin)`: the interleaved
/// recurrences of this module, re-anchored exactly every [`RESYNC`] samples — the same values as
/// one `sin_cos` a sample to ≈ 1e-14, at a fraction of the cost (one `sin_cos` per block).
#[inline(always)]
fn unit_phasors_impl(cyc: f64, cos: &mut [f64], sin: &mut [f64]) {
    debug_assert_eq!(cos.len(), sin.len());
    let st = Steps::new(cyc);
    let (rs, rc) = (st.rs, st.rc);
    for (b, (cb, sb)) in cos
        .chunks_mut(RESYNC)
        .zip(sin.chunks_mut(RESYNC))
        .enumerate()
    {
        let (mut zc, mut zs) = st.anchor(b * RESYNC);
        let mut it = cb.chunks_exact_mut(LANES).zip(sb.chunks_exact_mut(LANES));
        for (qc, qs) in &mut it {
            for r in 0..LANES {
                qc[r] = zc[r];
                qs[r] = zs[r];
                let c = zc[r] * rc - zs[r] * rs;
                zs[r] = zc[r] * rs + zs[r] * rc;
                zc[r] = c;
            }
        }
        let done = cb.len() / LANES * LANES;
        let rest = cb.len() - done;
        cb[done..].copy_from_slice(&zc[..rest]);
        sb[done..].copy_from_slice(&zs[..rest]);
    }
}

dispatch!(unit_phasors_impl, unit_phasors_avx2, (cyc: f64, cos: &mut [f64], sin: &mut [f64]) -> ());

#[doc = concat!("See [`", stringify!(unit_phasors_impl), "`]; AVX2 when available.")]
pub(crate) fn unit_phasors(cyc: f64, cos: &mut [f64], sin: &mut [f64]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (checked just above).
        return unsafe { unit_phasors_avx2(cyc, cos, sin) };
    }
    unit_phasors_impl(cyc, cos, sin)
}

/// Least-squares fit of `a cos(2π c n) + b sin(2π c n)` to `x`: returns the five sums
/// `(Σ x cos, Σ x sin, Σ cos², Σ sin², Σ cos sin)`.
#[inline(always)]
fn fit_sums_impl(x: &[f64], cyc: f64) -> [f64; 5] {
    let st = Steps::new(cyc);
    let (rs, rc) = (st.rs, st.rc);
    let mut acc = [[0.0; LANES]; 5];
    let add = |acc: &mut [[f64; LANES]; 5], r: usize, v: f64, c: f64, s: f64| {
        acc[0][r] += v * c;
        acc[1][r] += v * s;
        acc[2][r] += c * c;
        acc[3][r] += s * s;
        acc[4][r] += c * s;
    };
    for (b, block) in x.chunks(RESYNC).enumerate() {
        let (mut zc, mut zs) = st.anchor(b * RESYNC);
        let mut it = block.chunks_exact(LANES);
        for q in &mut it {
            for r in 0..LANES {
                add(&mut acc, r, q[r], zc[r], zs[r]);
                let c = zc[r] * rc - zs[r] * rs;
                zs[r] = zc[r] * rs + zs[r] * rc;
                zc[r] = c;
            }
        }
        for (r, &v) in it.remainder().iter().enumerate() {
            add(&mut acc, r, v, zc[r], zs[r]);
        }
    }
    acc.map(|a| a.iter().sum())
}

dispatch!(fit_sums_impl, fit_sums_avx2, (x: &[f64], cyc: f64) -> [f64; 5]);

/// The five sums of [`fit_sums_impl`]. The three that do not depend on the data have a closed
/// form: with `φ = 4π c` and `D = Σ_{n<N} e^{iφn} = e^{iφ(N−1)/2} sin(Nφ/2) / sin(φ/2)`,
/// `Σ cos² = N/2 + Re D / 2`, `Σ sin² = N/2 − Re D / 2`, `Σ cos sin = Im D / 2`; so only
/// `Σ x cos` and `Σ x sin` are summed ([`dtft_sums`], two accumulators instead of five). Near
/// `c ≡ 0` or `½` (where `sin(φ/2) → 0`) all five are summed.
pub(crate) fn fit_sums(x: &[f64], cyc: f64) -> [f64; 5] {
    if let Some([cc, ss, cs]) = gram_sums(x.len(), cyc) {
        let (c, s) = dtft_sums(x, cyc);
        return [c, s, cc, ss, cs];
    }
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (checked just above).
        return unsafe { fit_sums_avx2(x, cyc) };
    }
    fit_sums_impl(x, cyc)
}

/// `(Σ cos², Σ sin², Σ cos sin)` of `2π c n`, `n < len`, in closed form (see [`fit_sums`]);
/// `None` where `|sin 2πc| < 1e-3`. Phases are reduced to one cycle before `sin`/`cos`, so the
/// error stays at the rounding of `c·len` (≈ 1e-12 cycles for a 25 600-sample record).
fn gram_sums(len: usize, cyc: f64) -> Option<[f64; 3]> {
    let den = (TAU * cyc.fract()).sin();
    if !(den.abs() >= 1e-3) {
        return None;
    }
    let n = len as f64;
    let d = (TAU * (cyc * n).fract()).sin() / den;
    let (sb, cb) = (TAU * (cyc * (n - 1.0)).fract()).sin_cos();
    let (re, im) = (d * cb, d * sb);
    Some([0.5 * (n + re), 0.5 * (n - re), 0.5 * im])
}

/// `x[n] -= a cos(2π c n) + b sin(2π c n)`.
#[inline(always)]
fn subtract_sinusoid_impl(x: &mut [f64], cyc: f64, a: f64, b: f64) {
    let st = Steps::new(cyc);
    let (rs, rc) = (st.rs, st.rc);
    for (blk, block) in x.chunks_mut(RESYNC).enumerate() {
        let (mut zc, mut zs) = st.anchor(blk * RESYNC);
        let mut it = block.chunks_exact_mut(LANES);
        for q in &mut it {
            for r in 0..LANES {
                q[r] -= a * zc[r] + b * zs[r];
                let c = zc[r] * rc - zs[r] * rs;
                zs[r] = zc[r] * rs + zs[r] * rc;
                zc[r] = c;
            }
        }
        for (r, v) in it.into_remainder().iter_mut().enumerate() {
            *v -= a * zc[r] + b * zs[r];
        }
    }
}

dispatch!(subtract_sinusoid_impl, subtract_sinusoid_avx2, (x: &mut [f64], cyc: f64, a: f64, b: f64) -> ());

#[doc = concat!("See [`", stringify!(subtract_sinusoid_impl), "`]; AVX2 when available.")]
pub(crate) fn subtract_sinusoid(x: &mut [f64], cyc: f64, a: f64, b: f64) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (checked just above).
        return unsafe { subtract_sinusoid_avx2(x, cyc, a, b) };
    }
    subtract_sinusoid_impl(x, cyc, a, b)
}

#[cfg(test)]
mod tests {
    use super::super::test_util::lcg;
    use super::*;

    #[test]
    fn sums_match_direct_evaluation() {
        for (n, cyc) in [
            (25_600usize, 0.0339843),
            (1883, 0.4),
            (13, 0.01),
            (3001, 0.2501),
        ] {
            let x = lcg(n, n as u64);
            let (mut c, mut s, mut cc, mut ss, mut cs) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for (i, v) in x.iter().enumerate() {
                let ph = (cyc * i as f64).fract() * TAU;
                let (sn, cn) = ph.sin_cos();
                c += v * cn;
                s += v * sn;
                cc += cn * cn;
                ss += sn * sn;
                cs += cn * sn;
            }
            let tol = 1e-11 * n as f64;
            let (re, im) = dtft_sums(&x, cyc);
            assert!((re - c).abs() < tol && (im - s).abs() < tol, "{n} {cyc}");
            let f = fit_sums(&x, cyc);
            for (got, want) in f.iter().zip([c, s, cc, ss, cs]) {
                assert!((got - want).abs() < tol, "{n} {cyc}: {got} vs {want}");
            }
            // The dispatched (AVX2 when available) and the plain path agree bit for bit.
            assert_eq!(dtft_sums_impl(&x, cyc), (re, im));
            // The closed-form Gram sums agree with the summed ones.
            for (got, want) in f.iter().zip(fit_sums_impl(&x, cyc)) {
                assert!(
                    (got - want).abs() < tol,
                    "{n} {cyc}: {got} vs summed {want}"
                );
            }
            let (mut pc, mut ps) = (vec![0.0; n], vec![0.0; n]);
            unit_phasors(cyc, &mut pc, &mut ps);
            let (mut qc, mut qs) = (vec![0.0; n], vec![0.0; n]);
            unit_phasors_impl(cyc, &mut qc, &mut qs);
            assert_eq!((&pc, &ps), (&qc, &qs));
            for i in 0..n {
                let (sn, cn) = ((cyc * i as f64).fract() * TAU).sin_cos();
                // Tolerance set by the reference's own phase, `fract(c·i)·2π` (≈ c·i·1e-15).
                assert!(
                    (pc[i] - cn).abs() < 1e-12 && (ps[i] - sn).abs() < 1e-12,
                    "{n} {cyc} phasor {i}: {} {}",
                    pc[i] - cn,
                    ps[i] - sn
                );
            }
            let mut y = x.clone();
            subtract_sinusoid(&mut y, cyc, 0.7, -1.3);
            let mut z = x.clone();
            subtract_sinusoid_impl(&mut z, cyc, 0.7, -1.3);
            assert_eq!(y, z);
            for (i, (a, b)) in y.iter().zip(&x).enumerate() {
                let ph = (cyc * i as f64).fract() * TAU;
                let (sn, cn) = ph.sin_cos();
                // The reference's own phase, `fract(c·i)·2π`, is only good to ≈ c·i·1e-16.
                let e = (a - (b - 0.7 * cn + 1.3 * sn)).abs();
                assert!(e < 1e-11, "{n} {cyc} sample {i}: error {e}");
            }
        }
    }

    /// [`fit_sums`] with closed-form Gram sums against all five summed, across frequencies
    /// from near DC to near Nyquist, both sides of the 1e-3 switch to summing.
    #[test]
    fn closed_form_gram_sums_match_summed() {
        for n in [17usize, 1883, 25_600, 100_003] {
            let x = lcg(n, 3);
            for cyc in [
                1e-9, 1e-5, 1.6e-4, 1.59e-4, 0.0339843, 0.1, 0.25, 0.3333, 0.4, 0.4998, 0.49984,
                0.4999, 0.4999999, 0.5,
            ] {
                let a = fit_sums(&x, cyc);
                let b = fit_sums_impl(&x, cyc);
                if gram_sums(n, cyc).is_none() {
                    // Summed: the dispatched (AVX2 when available) path, bit for bit.
                    assert_eq!(a, b, "n {n} c {cyc}");
                }
                for (k, (got, want)) in a.iter().zip(b).enumerate() {
                    let tol = 1e-11 * n as f64;
                    assert!(
                        (got - want).abs() < tol,
                        "n {n} c {cyc} sum {k}: {got} vs {want}"
                    );
                }
            }
        }
    }
}
