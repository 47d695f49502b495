//! Order tracking: the shaft angle from a record, and the record resampled to a fixed number of
//! samples per revolution of a shaft (computed order tracking).
//!
//! # Tacho-less tracking from the phase of a mesh line ([`track_mesh_phase`])
//!
//! A gear mesh makes a line at `z · f_shaft` whose phase advances by `2π z` per revolution of
//! the shaft carrying the `z`-tooth gear. Its instantaneous phase, divided by `z`, is that
//! shaft's angle. Two passes:
//!
//! 1. **Ridge.** In the whole-record Hann spectrum, the strongest bin within `±search`
//!    (relative) of each of the hint's first three harmonics proposes a fundamental; the
//!    proposal whose multiples carry the most amplitude wins, and its strongest multiple `h` is
//!    the tracked line (on a housing the fundamental is often not the strongest mesh line); its
//!    phase advances `h z` cycles per revolution. Short-time spectra (Hann segments of 8 nominal
//!    revolutions, no overlap, zero-padded to a power of two ≥ 2×, parabolic interpolation of
//!    the log magnitude)
//!    follow it; a polynomial of degree ≤ 3 in time, fitted by least squares with one round of
//!    outlier rejection (> 0.25 shaft orders off), is the coarse mesh frequency `f_A(t)`, and
//!    its integral the coarse phase `φ_A(t)` (cycles).
//! 2. **Demodulation.** `y(t) = x(t) e^{−i 2π φ_A(t)}` moves the mesh line to 0 Hz whatever the
//!    speed variation; an FFT low-pass of `±0.4 f_shaft` keeps it and rejects its shaft-order
//!    sidebands (at `±f_shaft`) and everything else; the unwrapped phase `ψ(t)` of the result
//!    (the analytic-signal phase of the band-passed mesh line, relative to `φ_A`) corrects it:
//!    `Φ(t) = φ_A(t) + ψ(t) / 2π`, and the shaft angle is `Φ(t) / z` revolutions.
//!
//! The low-pass is circular (FFT), so the first and last [`EDGE_REVS`] revolutions carry a
//! wrap-around transient; [`angular_resample`] leaves them out.
//!
//! # Tachometer ([`track_tachometer`])
//!
//! Rising crossings of the mid level between the tachometer's 1st and 99th percentiles,
//! interpolated linearly between samples; the angle is linear in time between pulses and
//! extrapolated with the first/last interval's rate.
//!
//! # Angular resampling ([`angular_resample`])
//!
//! Any shaft whose rate is a fixed multiple `ratio` of the tracked shaft's (from the gearbox
//! kinematics) has angle `ratio · θ(t)`. The record is interpolated at the instants where that
//! angle crosses `k / P` (`P` samples per revolution) with the Keys cubic-convolution kernel
//! (`a = −½`), over a whole number of revolutions. The caller should pick `P ≥ fs / f_shaft` so
//! that the resampled signal keeps every order the record holds (no aliasing); the cubic
//! kernel attenuates content close to the original Nyquist frequency a little.

use rustfft::num_complex::Complex64;
use serde::{Deserialize, Serialize};

use super::window::{Window, shared_window};
use super::{PlanCache, Spectrum, amplitude_spectrum, check_rate, check_samples};
use crate::error::SpeedProblem;
use crate::{Error, Result};

/// Revolutions of the tracked shaft left out at each end of a mesh-phase track (the circular
/// low-pass's wrap-around transient lasts about `1 / (0.4 f_shaft)` ≈ 2.5 revolutions).
pub const EDGE_REVS: f64 = 3.0;
/// Half-width of the demodulated low-pass, in shaft orders (excludes the ±1 sidebands).
pub const LOWPASS_ORDERS: f64 = 0.4;

/// The smallest `2^a 3^b 5^c ≥ n` (an FFT length RustFFT handles fast).
pub(crate) fn fast_len(n: usize) -> usize {
    let mut best = n.next_power_of_two();
    let mut p5 = 1;
    while p5 < best {
        let mut p35 = p5;
        while p35 < best {
            let mut m = p35;
            while m < n {
                m *= 2;
            }
            best = best.min(m);
            p35 *= 3;
        }
        p5 *= 5;
    }
    best
}

/// How a shaft angle was obtained.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TrackMethod {
    /// Tacho-less: the phase of a mesh line divided by its tooth count.
    MeshPhase,
    /// A tachometer channel's pulses.
    Tachometer,
    /// A constant rate found in the spectrum (the phase of no line could be followed).
    ConstantRate,
}

/// The angle of the tracked shaft at every sample of a record.
#[derive(Debug, Clone, PartialEq)]
pub struct ShaftAngle {
    /// Angle in revolutions at sample `n` (unwrapped, 0 at the first sample).
    pub revs: Vec<f64>,
    /// Sample rate of the record (Hz).
    pub sample_rate: f64,
    /// First and last usable sample (the ends of a mesh-phase track carry a filter transient).
    pub usable: (usize, usize),
    pub summary: TrackSummary,
}

/// What a track found, for people and for the features.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrackSummary {
    pub method: TrackMethod,
    /// Mean shaft rate over the usable part (Hz).
    pub mean_hz: f64,
    /// (max − min) / mean of the per-revolution rate.
    pub speed_variation: f64,
    /// Standard deviation / mean of the per-revolution rate.
    pub speed_std: f64,
    /// Revolutions in the usable part.
    pub revolutions: f64,
    /// Mean frequency of the tracked mesh line (Hz); `None` with a tachometer.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mesh_hz: Option<f64>,
    /// Mesh order on the tracked shaft (its gear's tooth count); `None` with a tachometer.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mesh_order: Option<f64>,
    /// Which mesh harmonic's phase was tracked (the strongest); `None` with a tachometer.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub harmonic: Option<usize>,
}

/// Tuning of [`track_mesh_phase`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshTrackOptions {
    /// The mesh line is searched within `hint · (1 ± search)`.
    pub search: f64,
    /// Degree of the ridge polynomial (≤ 3).
    pub degree: usize,
    /// The strongest of the mesh harmonics `1 ..= harmonics` (under Nyquist) is tracked: on a
    /// real housing the fundamental is often not the strongest mesh line.
    pub harmonics: usize,
    /// Half-width of the demodulated low-pass, in orders of the tracked shaft: below the
    /// slowest sideband spacing of the train (a shaft turning at 0.2 × the tracked one puts
    /// sidebands 0.2 orders from the mesh line), so that no sideband pulls the phase.
    pub lowpass_orders: f64,
}

impl Default for MeshTrackOptions {
    fn default() -> Self {
        MeshTrackOptions {
            search: 0.08,
            degree: 3,
            harmonics: 3,
            lowpass_orders: LOWPASS_ORDERS,
        }
    }
}

/// Per-revolution rates from an angle track between samples `lo..=hi`: `(mean, variation, std)`.
fn speed_stats(revs: &[f64], fs: f64, lo: usize, hi: usize) -> (f64, f64, f64, f64) {
    let span = revs[hi] - revs[lo];
    let mean = span * fs / (hi - lo).max(1) as f64;
    // Instants (in samples) at which the angle crosses whole revolutions.
    let mut crossings = Vec::new();
    let mut next = revs[lo].floor() + 1.0;
    for n in lo..hi {
        while revs[n + 1] >= next && revs[n] < next {
            let f = (next - revs[n]) / (revs[n + 1] - revs[n]);
            crossings.push(n as f64 + f);
            next += 1.0;
        }
    }
    let rates: Vec<f64> = crossings.windows(2).map(|w| fs / (w[1] - w[0])).collect();
    if rates.len() < 2 || !(mean > 0.0) {
        return (mean, 0.0, 0.0, span);
    }
    let m = rates.iter().sum::<f64>() / rates.len() as f64;
    let (mn, mx) = rates
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &r| {
            (a.min(r), b.max(r))
        });
    let sd = (rates.iter().map(|r| (r - m).powi(2)).sum::<f64>() / rates.len() as f64).sqrt();
    (mean, (mx - mn) / m, sd / m, span)
}

/// Least-squares polynomial `Σ a_k τ^k` (degree `d`) through `(τ_i, y_i)`; `None` if singular.
fn polyfit(t: &[f64], y: &[f64], d: usize) -> Option<Vec<f64>> {
    let m = d + 1;
    let mut a = vec![vec![0.0; m + 1]; m];
    for (&ti, &yi) in t.iter().zip(y) {
        let mut p = vec![1.0; 2 * m];
        for k in 1..2 * m {
            p[k] = p[k - 1] * ti;
        }
        for r in 0..m {
            for c in 0..m {
                a[r][c] += p[r + c];
            }
            a[r][m] += p[r] * yi;
        }
    }
    // Gaussian elimination with partial pivoting.
    for c in 0..m {
        let piv = (c..m).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))?;
        if !(a[piv][c].abs() > 1e-12) {
            return None;
        }
        a.swap(c, piv);
        for r in 0..m {
            if r != c {
                let f = a[r][c] / a[c][c];
                for k in c..=m {
                    a[r][k] -= f * a[c][k];
                }
            }
        }
    }
    Some((0..m).map(|r| a[r][m] / a[r][r]).collect())
}

/// Peak frequency (Hz) of the Hann spectrum of `seg` zero-padded to `nfft`, within `[lo, hi]`
/// Hz, refined by a parabola through the log magnitudes; `None` without a bin in the band.
fn segment_peak(seg: &[f64], w: &[f64], fs: f64, nfft: usize, lo: f64, hi: f64) -> Option<f64> {
    let plan = PlanCache::global().forward(nfft);
    let mut input = plan.make_input_vec();
    for (i, (s, wv)) in seg.iter().zip(w).enumerate() {
        input[i] = s * wv;
    }
    let mut out = plan.make_output_vec();
    plan.process(&mut input, &mut out).ok()?;
    let df = fs / nfft as f64;
    let k0 = ((lo / df).ceil() as usize).max(1);
    let k1 = ((hi / df).floor() as usize).min(out.len() - 2);
    if k0 > k1 {
        return None;
    }
    let mag = |k: usize| out[k].norm_sqr().max(1e-300).ln();
    let k = (k0..=k1).max_by(|&a, &b| out[a].norm_sqr().total_cmp(&out[b].norm_sqr()))?;
    let (a, b, c) = (mag(k - 1), mag(k), mag(k + 1));
    let den = a - 2.0 * b + c;
    let delta = if den < 0.0 {
        (0.5 * (a - c) / den).clamp(-0.5, 0.5)
    } else {
        0.0
    };
    Some((k as f64 + delta) * df)
}

/// Tacho-less shaft angle from the phase of the mesh line near `mesh_hz_hint` (Hz) of a gear
/// with `mesh_order` teeth on the tracked shaft (see the [module docs](self)).
///
/// Errors: bad samples or rate; a hint or order that is not a positive finite number, or a
/// hint above Nyquist; a record shorter than 16 nominal revolutions; a mesh line that the
/// demodulated low-pass loses (its magnitude under a tenth of its median on more than 1 % of
/// the samples: too weak to track).
pub fn track_mesh_phase(
    x: &[f64],
    fs: f64,
    mesh_hz_hint: f64,
    mesh_order: f64,
    opts: &MeshTrackOptions,
) -> Result<ShaftAngle> {
    track_mesh_phase_with(x, fs, mesh_hz_hint, mesh_order, opts, None)
}

/// [`track_mesh_phase`] with the record's whole-record Hann [`amplitude_spectrum`] already at
/// hand (the diagnosis computes it for its f1 search); `None`: computed here. A spectrum of
/// another length than the record's is ignored.
pub fn track_mesh_phase_with(
    x: &[f64],
    fs: f64,
    mesh_hz_hint: f64,
    mesh_order: f64,
    opts: &MeshTrackOptions,
    spectrum: Option<&Spectrum>,
) -> Result<ShaftAngle> {
    check_track_inputs(x, fs, mesh_hz_hint, mesh_order, opts)?;
    let n = x.len();
    let fund_order = mesh_order;
    let mean = x.iter().sum::<f64>() / n as f64;
    let xc: Vec<f64> = x.iter().map(|v| v - mean).collect();

    // Pass 1: the strongest mesh harmonic in the whole record, then its ridge.
    let own;
    let spec = match spectrum.filter(|s| s.amplitude.len() == n / 2 + 1) {
        Some(s) => s,
        None => {
            own = amplitude_spectrum(&xc, fs, Window::Hann)?;
            &own
        }
    };
    let (fm0, harmonic) = strongest_mesh_harmonic(spec, fs, mesh_hz_hint, opts)?;
    let mesh_order = harmonic * fund_order;
    let shaft_a = fm0 / mesh_order;
    let coef = coarse_mesh_frequency(&xc, fs, fm0, shaft_a, opts);

    // Pass 2: demodulate, low-pass, unwrap.
    let lowpass = opts.lowpass_orders.clamp(1e-3, LOWPASS_ORDERS);
    let (phi_a, psi, step) = demodulated_phase(&xc, fs, &coef, fm0, shaft_a, lowpass)?;
    let mut revs: Vec<f64> = (0..n)
        .map(|i| (phi_a[i] + cubic_at(&psi, i as f64 / step)) / mesh_order)
        .collect();
    let r0 = revs[0];
    for r in &mut revs {
        *r -= r0;
    }
    if revs.windows(2).any(|w| !(w[1] > w[0])) {
        return Err(Error::SpeedNotMeasured(SpeedProblem::IrregularTrack {
            mesh_hz: fm0,
        }));
    }
    // The low-pass's transient lasts about 1 / (lowpass · f_shaft).
    let edge = (EDGE_REVS.max(1.2 / lowpass) * fs / shaft_a).round() as usize;
    let usable = (edge.min(n / 4), (n - 1).saturating_sub(edge).max(3 * n / 4));
    let (mean_hz, var, sd, span) = speed_stats(&revs, fs, usable.0, usable.1);
    let mesh_hz = mean_hz * fund_order;
    Ok(ShaftAngle {
        revs,
        sample_rate: fs,
        usable,
        summary: TrackSummary {
            method: TrackMethod::MeshPhase,
            mean_hz,
            speed_variation: var,
            speed_std: sd,
            revolutions: span,
            mesh_hz: Some(mesh_hz),
            mesh_order: Some(fund_order),
            harmonic: Some(harmonic as usize),
        },
    })
}

/// The refusals of [`track_mesh_phase_with`]: bad samples or rate, a hint or order that is not
/// a positive finite number, a search band above Nyquist, fewer than 16 nominal revolutions.
fn check_track_inputs(
    x: &[f64],
    fs: f64,
    mesh_hz_hint: f64,
    mesh_order: f64,
    opts: &MeshTrackOptions,
) -> Result<()> {
    check_rate(fs)?;
    check_samples(x)?;
    if !(mesh_order.is_finite() && mesh_order > 0.0) {
        return Err(Error::param(
            "mesh_order",
            mesh_order,
            "the tracked gear's tooth count must be a positive number",
        ));
    }
    if !(mesh_hz_hint.is_finite()
        && mesh_hz_hint > 0.0
        && mesh_hz_hint * (1.0 + opts.search) < 0.5 * fs)
    {
        return Err(Error::param(
            "mesh_hz_hint",
            mesh_hz_hint,
            format!(
                "the mesh frequency hint must be positive and its search band under the Nyquist \
                 frequency {} Hz",
                0.5 * fs
            ),
        ));
    }
    let n = x.len();
    let shaft0 = mesh_hz_hint / mesh_order;
    let min_len = (16.0 * fs / shaft0).ceil() as usize;
    if n < min_len {
        return Err(Error::TooFewSamples {
            analysis: "order tracking (16 input-shaft revolutions)",
            needed: min_len,
            samples: n,
        });
    }
    Ok(())
}

/// Pass 1, the line to track: `(frequency in Hz, harmonic of the fundamental)`.
///
/// Each harmonic band's strongest bin proposes a fundamental; the proposal whose multiples
/// carry the most amplitude wins (a shaft-order sideband stronger than its mesh harmonic
/// proposes a fundamental whose other multiples miss the mesh harmonics). Then the strongest
/// multiple of that fundamental is tracked.
fn strongest_mesh_harmonic(
    spec: &Spectrum,
    fs: f64,
    mesh_hz_hint: f64,
    opts: &MeshTrackOptions,
) -> Result<(f64, f64)> {
    let df = spec.resolution();
    let nyq = 0.5 * fs;
    let hmax = (1..=opts.harmonics.max(1))
        .take_while(|&h| h as f64 * mesh_hz_hint * (1.0 + opts.search) < nyq)
        .last()
        .unwrap_or(0);
    let amp_at = |f: f64| spec.peak_near(f, 1.5 * df);
    let mut best: Option<(f64, f64)> = None; // (harmonic-sum, fundamental)
    for h in 1..=hmax {
        let c = h as f64 * mesh_hz_hint;
        let (f, _) = spec.peak_near(c, c * opts.search);
        if !f.is_finite() {
            continue;
        }
        let fund = f / h as f64;
        let sum: f64 = (1..=hmax)
            .map(|k| amp_at(k as f64 * fund).1)
            .filter(|a| a.is_finite())
            .sum();
        if best.is_none_or(|b| sum > b.0) {
            best = Some((sum, fund));
        }
    }
    let Some((_, fund)) = best else {
        return Err(Error::SpeedNotMeasured(SpeedProblem::NoBinNearMesh {
            mesh_hz: mesh_hz_hint,
            search_percent: 100.0 * opts.search,
        }));
    };
    let (mut fm0, mut harmonic, mut top) = (fund, 1.0, f64::NEG_INFINITY);
    for k in 1..=hmax {
        let (f, a) = amp_at(k as f64 * fund);
        if f.is_finite() && a > top {
            (fm0, harmonic, top) = (f, k as f64, a);
        }
    }
    Ok((fm0, harmonic))
}

/// Pass 1, the ridge: the tracked line's peak in short-time spectra of `xc` (the mean-free
/// record) within `±search` of `fm0`, and the coefficients of the polynomial in normalised time
/// `τ ∈ [−1, 1]` fitted to them (the coarse mesh frequency `f_A`, Hz; see the
/// [module docs](self)). `shaft_a`: the tracked shaft's rate at `fm0` (Hz).
fn coarse_mesh_frequency(
    xc: &[f64],
    fs: f64,
    fm0: f64,
    shaft_a: f64,
    opts: &MeshTrackOptions,
) -> Vec<f64> {
    let n = xc.len();
    let lo = fm0 * (1.0 - opts.search);
    let hi = fm0 * (1.0 + opts.search);
    let seg = ((8.0 * fs / shaft_a).round() as usize).clamp(64, n);
    let hop = seg;
    // A power of two: a segment of 8 revolutions is any length (often a prime), whose FFT
    // would cost many times more.
    let nfft = (2 * seg).next_power_of_two();
    let w = shared_window(Window::Hann, seg);
    let half = 0.5 * n as f64 / fs;
    let (mut ts, mut fs_) = (Vec::new(), Vec::new());
    let mut s0 = 0;
    while s0 + seg <= n {
        if let Some(f) = segment_peak(&xc[s0..s0 + seg], &w, fs, nfft, lo, hi) {
            ts.push(((s0 as f64 + 0.5 * seg as f64) / fs - half) / half);
            fs_.push(f);
        }
        s0 += hop;
    }
    let mut coef = vec![fm0];
    if ts.len() >= 2 {
        let d = opts.degree.min(3).min(ts.len() - 1);
        if let Some(c) = polyfit(&ts, &fs_, d) {
            // One round of outlier rejection (a sideband or a noise peak won a segment).
            let eval = |c: &[f64], t: f64| c.iter().rev().fold(0.0, |a, &k| a * t + k);
            let keep: Vec<usize> = (0..ts.len())
                .filter(|&i| (fs_[i] - eval(&c, ts[i])).abs() <= 0.25 * shaft_a)
                .collect();
            coef = c;
            if keep.len() > d && keep.len() < ts.len() {
                let t2: Vec<f64> = keep.iter().map(|&i| ts[i]).collect();
                let f2: Vec<f64> = keep.iter().map(|&i| fs_[i]).collect();
                if let Some(c2) = polyfit(&t2, &f2, d) {
                    coef = c2;
                }
            }
        }
    }
    coef
}

/// The coarse phase `φ_A(τ)` in cycles: `∫ f_A dt` with `t = half (τ + 1)`, so `dt = half dτ`
/// (`coef`: [`coarse_mesh_frequency`]'s polynomial, `half`: half the record's duration).
fn coarse_phase(coef: &[f64], half: f64, tau: f64) -> f64 {
    let mut acc = 0.0;
    for (k, &a) in coef.iter().enumerate() {
        let p = (k + 1) as i32;
        acc += a * (tau.powi(p) - (-1.0f64).powi(p)) / (k + 1) as f64;
    }
    half * acc
}

/// Pass 2: `xc` (the mean-free record) demodulated by the coarse phase, low-passed to
/// `±lowpass` orders of `shaft_a` and unwrapped. Returns the coarse phase used at every
/// sample (`φ_A`, cycles), the unwrapped residual phase `ψ / 2π` (cycles) on a decimated grid,
/// and that grid's step in samples.
///
/// The FFT runs on a fast length (2^a 3^b 5^c ≥ n, zero-padded): the padding's transient falls
/// in the discarded end revolutions. Errors: a line too weak to track (see
/// [`track_mesh_phase`]).
fn demodulated_phase(
    xc: &[f64],
    fs: f64,
    coef: &[f64],
    fm0: f64,
    shaft_a: f64,
    lowpass: f64,
) -> Result<(Vec<f64>, Vec<f64>, f64)> {
    let n = xc.len();
    let half = 0.5 * n as f64 / fs;
    let m = fast_len(n);
    let (mut buf, phi_a) = demodulate(xc, fs, coef, half, m);
    PlanCache::global().complex(m, false).process(&mut buf);
    let bw = ((lowpass * shaft_a) * m as f64 / fs).floor() as usize;
    for (k, c) in buf.iter_mut().enumerate() {
        if k > bw && k < m - bw {
            *c = Complex64::new(0.0, 0.0);
        }
    }
    // The low-passed signal is band-limited to ±bw bins: its inverse transform at a short
    // length `l` (≥ 16 bw) samples it densely enough to interpolate its unwrapped phase back to
    // every sample (Keys cubic), at a fraction of a record-length inverse FFT.
    let l = fast_len((16 * bw).max(64)).min(m);
    let mut small = vec![Complex64::new(0.0, 0.0); l];
    for k in 0..=bw.min(l / 2) {
        small[k] = buf[k];
        if k > 0 {
            small[l - k] = buf[m - k];
        }
    }
    PlanCache::global().complex(l, true).process(&mut small);
    // Decimated samples that fall inside the record.
    let step = m as f64 / l as f64;
    let nd = (((n - 1) as f64 / step).floor() as usize + 2).min(l);
    let mags: Vec<f64> = small[..nd].iter().map(|c| c.norm()).collect();
    let mut sorted = mags.clone();
    let mid = sorted.len() / 2;
    sorted.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
    let med = sorted[mid];
    let weak = mags.iter().filter(|&&v| v < 0.1 * med).count();
    if !(med > 0.0) || weak * 100 > nd {
        return Err(Error::SpeedNotMeasured(SpeedProblem::MeshLineTooWeak {
            mesh_hz: fm0,
            weak,
            samples: nd,
        }));
    }
    let tau = std::f64::consts::TAU;
    let mut psi = Vec::with_capacity(nd);
    let mut prev = small[0].arg();
    let mut unwrapped = 0.0;
    for (j, c) in small[..nd].iter().enumerate() {
        let a = c.arg();
        if j > 0 {
            let mut d = a - prev;
            d -= tau * (d / tau).round();
            unwrapped += d;
        }
        prev = a;
        psi.push(unwrapped / tau);
    }
    Ok((phi_a, psi, step))
}

/// `xc[i] e^{−i 2π φ_A(t_i)}` zero-padded to `m` points, and the `φ_A` used at every sample
/// (cycles).
///
/// `φ_A` is evaluated exactly every `BLOCK` samples and linearly in between (the phase actually
/// used, kept in `phi_a`, so that `φ_A + ψ` stays exact); the phasor steps by a constant
/// rotation inside a block: two `sin_cos` a block instead of one a sample.
fn demodulate(
    xc: &[f64],
    fs: f64,
    coef: &[f64],
    half: f64,
    m: usize,
) -> (Vec<Complex64>, Vec<f64>) {
    let n = xc.len();
    let mut buf: Vec<Complex64> = Vec::with_capacity(m);
    const BLOCK: usize = 32;
    let mut phi_a = Vec::with_capacity(n);
    let tau_at = |i: usize| (i as f64 / fs - half) / half;
    let mut b0 = 0;
    while b0 < n {
        let b1 = (b0 + BLOCK).min(n);
        let (p0, p1) = (
            coarse_phase(coef, half, tau_at(b0)),
            coarse_phase(coef, half, tau_at(b1)),
        );
        let dphi = (p1 - p0) / (b1 - b0) as f64;
        let (s0, c0) = (-p0.fract() * std::f64::consts::TAU).sin_cos();
        let (ds, dc) = (-dphi * std::f64::consts::TAU).sin_cos();
        let (mut zc, mut zs) = (c0, s0);
        for i in b0..b1 {
            let v = xc[i];
            buf.push(Complex64::new(v * zc, v * zs));
            phi_a.push(p0 + dphi * (i - b0) as f64);
            let c = zc * dc - zs * ds;
            zs = zc * ds + zs * dc;
            zc = c;
        }
        b0 = b1;
    }
    buf.resize(m, Complex64::new(0.0, 0.0));
    (buf, phi_a)
}

/// Shaft angle from a tachometer channel with `pulses_per_rev` pulses per revolution (see the
/// [module docs](self)).
///
/// Errors: bad samples or rate, `pulses_per_rev` = 0, fewer than 3 pulses.
pub fn track_tachometer(tacho: &[f64], fs: f64, pulses_per_rev: usize) -> Result<ShaftAngle> {
    check_rate(fs)?;
    check_samples(tacho)?;
    if pulses_per_rev == 0 {
        return Err(Error::param(
            "pulses_per_rev",
            0.0,
            "a tachometer gives at least one pulse per revolution",
        ));
    }
    let n = tacho.len();
    let mut s = tacho.to_vec();
    s.sort_by(f64::total_cmp);
    let lo = s[n / 100];
    let hi = s[(n - 1) - n / 100];
    let mid = 0.5 * (lo + hi);
    let hyst = 0.1 * (hi - lo);
    let mut pulses = Vec::new();
    let mut armed = tacho[0] < mid;
    for i in 1..n {
        if !armed && tacho[i] < mid - hyst {
            armed = true;
        }
        if armed && tacho[i - 1] < mid && tacho[i] >= mid {
            let f = (mid - tacho[i - 1]) / (tacho[i] - tacho[i - 1]);
            pulses.push((i - 1) as f64 + f);
            armed = false;
        }
    }
    if pulses.len() < 3 {
        return Err(Error::TooFewPulses {
            pulses: pulses.len(),
            needed: 3,
        });
    }
    let step = 1.0 / pulses_per_rev as f64;
    let mut revs = Vec::with_capacity(n);
    let mut k = 0;
    for i in 0..n {
        let t = i as f64;
        while k + 2 < pulses.len() && t > pulses[k + 1] {
            k += 1;
        }
        let (a, b) = (pulses[k], pulses[k + 1]);
        revs.push((k as f64 + (t - a) / (b - a)) * step);
    }
    let r0 = revs[0];
    for r in &mut revs {
        *r -= r0;
    }
    let usable = (0, n - 1);
    let (mean_hz, var, sd, span) = speed_stats(&revs, fs, usable.0, usable.1);
    Ok(ShaftAngle {
        revs,
        sample_rate: fs,
        usable,
        summary: TrackSummary {
            method: TrackMethod::Tachometer,
            mean_hz,
            speed_variation: var,
            speed_std: sd,
            revolutions: span,
            mesh_hz: None,
            mesh_order: None,
            harmonic: None,
        },
    })
}

/// The angle of a shaft turning at a constant `rate_hz` over `n` samples at `fs`: the fallback
/// when no line's phase can be followed (a steady machine, whose speed varies by a fraction of
/// a per cent over a record).
pub fn constant_rate_angle(n: usize, fs: f64, rate_hz: f64) -> ShaftAngle {
    let revs: Vec<f64> = (0..n).map(|i| i as f64 * rate_hz / fs).collect();
    ShaftAngle {
        revs,
        sample_rate: fs,
        usable: (0, n.saturating_sub(1)),
        summary: TrackSummary {
            method: TrackMethod::ConstantRate,
            mean_hz: rate_hz,
            speed_variation: 0.0,
            speed_std: 0.0,
            revolutions: n.saturating_sub(1) as f64 * rate_hz / fs,
            mesh_hz: None,
            mesh_order: None,
            harmonic: None,
        },
    }
}

/// A record resampled in the angle domain of one shaft.
#[derive(Debug, Clone, PartialEq)]
pub struct AngularRecord {
    /// `revolutions × samples_per_rev` samples, uniform in the shaft's angle.
    pub samples: Vec<f64>,
    pub samples_per_rev: usize,
    pub revolutions: usize,
}

/// Keys cubic convolution (`a = −½`) of `x` at fractional index `u`.
#[inline]
fn cubic_at(x: &[f64], u: f64) -> f64 {
    let n = x.len() as isize;
    let i = u.floor() as isize;
    let t = u - i as f64;
    let at = |k: isize| x[k.clamp(0, n - 1) as usize];
    let (p0, p1, p2, p3) = (at(i - 1), at(i), at(i + 1), at(i + 2));
    p1 + 0.5
        * t
        * (p2 - p0 + t * (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3 + t * (3.0 * (p1 - p2) + p3 - p0)))
}

/// Resample `x` to `samples_per_rev` samples per revolution of a shaft turning `ratio` times
/// as fast as the tracked one (see the [module docs](self)), over the whole revolutions that fit
/// in the track's usable part.
///
/// Errors: `x` and the track of different lengths, `ratio` not positive, `samples_per_rev`
/// < 8, less than one whole revolution.
pub fn angular_resample(
    x: &[f64],
    angle: &ShaftAngle,
    ratio: f64,
    samples_per_rev: usize,
) -> Result<AngularRecord> {
    if x.len() != angle.revs.len() {
        return Err(Error::LengthMismatch {
            what: "the angle track of the record's samples",
            expected: x.len(),
            found: angle.revs.len(),
        });
    }
    if !(ratio.is_finite() && ratio > 0.0) {
        return Err(Error::param(
            "ratio",
            ratio,
            "a shaft's rate over the tracked shaft's must be positive",
        ));
    }
    if samples_per_rev < 8 {
        return Err(Error::param(
            "samples_per_rev",
            samples_per_rev as f64,
            "at least 8 samples per revolution",
        ));
    }
    let (lo, hi) = angle.usable;
    let th = |i: usize| angle.revs[i] * ratio;
    let start = th(lo);
    let revolutions = (th(hi) - start).floor().max(0.0) as usize;
    if revolutions < 1 {
        return Err(Error::TooFewRevolutions {
            revolutions: th(hi) - start,
            needed: 1.0,
        });
    }
    let p = samples_per_rev;
    let mut out = Vec::with_capacity(revolutions * p);
    let mut i = lo;
    for m in 0..revolutions * p {
        let target = start + m as f64 / p as f64;
        while i + 1 < hi && th(i + 1) < target {
            i += 1;
        }
        let (a, b) = (th(i), th(i + 1));
        let u = i as f64 + ((target - a) / (b - a)).clamp(0.0, 1.0);
        out.push(cubic_at(x, u));
    }
    Ok(AngularRecord {
        samples: out,
        samples_per_rev: p,
        revolutions,
    })
}

/// The smallest power of two ≥ `fs / shaft_hz` (at least 64): samples per revolution that keep
/// every order a record sampled at `fs` holds.
pub fn samples_per_rev_for(fs: f64, shaft_hz: f64) -> usize {
    let need = (fs / shaft_hz).ceil();
    if !(need.is_finite() && need > 0.0) {
        return 64;
    }
    (need as usize).next_power_of_two().max(64)
}

#[cfg(test)]
mod tests {
    use super::super::test_util::lcg;
    use super::*;
    use std::f64::consts::TAU;

    /// A gear record with a known angle: shaft rate `f(t) = f0 (1 + ramp (2t/T − 1))`,
    /// mesh tone of order `z` (amplitude 1), its second harmonic (0.4), first-order sidebands
    /// (0.2 each), a shaft-order line (0.3) and white noise (±0.3 uniform).
    fn ramp_record(fs: f64, secs: f64, f0: f64, ramp: f64, z: f64) -> (Vec<f64>, Vec<f64>) {
        let n = (fs * secs) as usize;
        let noise = lcg(n, 7);
        let mut theta = Vec::with_capacity(n);
        let mut x = Vec::with_capacity(n);
        for i in 0..n {
            let t = i as f64 / fs;
            // θ(t) = ∫ f0 (1 + ramp (2t/T − 1)) dt.
            let th = f0 * (t + ramp * (t * t / secs - t));
            theta.push(th);
            let v = (TAU * z * th).sin()
                + 0.4 * (TAU * 2.0 * z * th + 0.3).sin()
                + 0.2 * (TAU * (z - 1.0) * th).sin()
                + 0.2 * (TAU * (z + 1.0) * th).sin()
                + 0.3 * (TAU * th + 1.0).sin()
                + 0.3 * noise[i];
            x.push(v);
        }
        (x, theta)
    }

    /// A ±5 % linear speed ramp is recovered: the tracked angle stays within 0.01 revolution of
    /// the true one over the usable part (after removing the constant offset), and the
    /// per-revolution rates give the ramp's (max − min)/mean = 10 % within 1 point.
    #[test]
    fn speed_ramp_is_recovered() {
        let (fs, secs, f0, z) = (12_800.0, 4.0, 30.0, 32.0);
        let (x, theta) = ramp_record(fs, secs, f0, 0.05, z);
        // The hint is off by 2 %: the ridge finds the line.
        let a = track_mesh_phase(&x, fs, 0.98 * f0 * z, z, &MeshTrackOptions::default()).unwrap();
        let (lo, hi) = a.usable;
        let off = a.revs[lo] - theta[lo];
        let worst = (lo..=hi)
            .map(|i| (a.revs[i] - theta[i] - off).abs())
            .fold(0.0, f64::max);
        assert!(worst < 0.01, "angle error {worst} rev");
        let s = &a.summary;
        assert!((s.mean_hz - f0).abs() < 0.01 * f0, "{s:?}");
        // True per-revolution variation over the usable part: the ramp's span there.
        let t_lo = lo as f64 / fs;
        let t_hi = hi as f64 / fs;
        let rate = |t: f64| f0 * (1.0 + 0.05 * (2.0 * t / secs - 1.0));
        let want = (rate(t_hi) - rate(t_lo)) / f0;
        assert!(
            (s.speed_variation - want).abs() < 0.01,
            "variation {} vs {want}",
            s.speed_variation
        );
        assert_eq!(s.method, TrackMethod::MeshPhase);
    }

    /// Constant speed, tachometer and mesh phase agree; resampling a pure order-z tone puts
    /// exactly z cycles in every revolution.
    #[test]
    fn tachometer_and_resampling() {
        let (fs, f0, z) = (10_000.0, 25.0, 20.0);
        let n = 40_000;
        let tacho: Vec<f64> = (0..n)
            .map(|i| {
                let ph = (f0 * i as f64 / fs).fract();
                if ph < 0.1 { 5.0 } else { 0.0 }
            })
            .collect();
        let a = track_tachometer(&tacho, fs, 1).unwrap();
        assert!((a.summary.mean_hz - f0).abs() < 1e-3, "{:?}", a.summary);
        assert!(a.summary.speed_std < 1e-3);
        let x: Vec<f64> = (0..n)
            .map(|i| (TAU * z * f0 * i as f64 / fs).cos())
            .collect();
        let r = angular_resample(&x, &a, 1.0, 64).unwrap();
        assert_eq!(r.samples.len(), r.revolutions * 64);
        assert!(r.revolutions >= 95, "{}", r.revolutions);
        // Order spectrum: all of the power at order z.
        let s = amplitude_spectrum(&r.samples, 64.0, Window::Hann).unwrap();
        let (fpk, apk) = s.peak_near(20.0, 2.0);
        assert!(
            (fpk - z).abs() < 1e-9 && (apk - 1.0).abs() < 0.02,
            "{fpk} {apk}"
        );
        // Tacho-less on the same tone gives the same rate.
        let m = track_mesh_phase(&x, fs, z * f0, z, &MeshTrackOptions::default()).unwrap();
        assert!((m.summary.mean_hz - f0).abs() < 1e-3, "{:?}", m.summary);
    }

    #[test]
    fn refuses_bad_input() {
        let x = lcg(1000, 1);
        assert!(track_mesh_phase(&x, 1000.0, 100.0, 10.0, &MeshTrackOptions::default()).is_err());
        assert!(track_mesh_phase(&x, 1000.0, -1.0, 10.0, &MeshTrackOptions::default()).is_err());
        assert!(track_tachometer(&[0.0; 100], 1000.0, 1).is_err());
        assert_eq!(samples_per_rev_for(12_900.0, 30.0), 512);
        assert_eq!(fast_len(25_600), 25_600);
        assert_eq!(fast_len(88_832), 90_000);
        assert_eq!(fast_len(1), 1);
        assert_eq!(fast_len(7), 8);
    }
}
