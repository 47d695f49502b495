//! Spectral signatures of the simulated gearbox: the features shared by the offline table
//! ([`precompute`]) and the diagnosis of a measured record ([`crate::diagnosis`]).
//!
//! # The feature definition (read this first)
//!
//! A record `x[n]` sampled at `fs` with a known stage-1 mesh frequency `f1` (same time unit) is
//! cut into segments of `L = round(SEGMENT_PERIODS · fs / f1)` samples (so every segment spans
//! the same number of mesh periods whatever the speed or sample rate: the frequency resolution
//! is `f1 / SEGMENT_PERIODS` for every record and every table entry), hopping by `L/2`. Each
//! segment has its mean removed and is multiplied by a periodic Hann window `w`. For every line
//! `ℓ` of [`line_set`] at normalised frequency `r_ℓ` (multiple of f1) the segment's Hann DTFT at
//! exactly `r_ℓ f1` gives a peak amplitude `A_{ℓ,s} = 2 |Σ w[n] x[n] e^{−2πi r_ℓ f1 n / fs}| / Σ w`;
//! segments are averaged in power, `A_ℓ = sqrt(mean_s A_{ℓ,s}²)` (unit of `x`).
//!
//! Features used for matching are **invariant to the sensor's overall gain** (a measured record
//! is housing acceleration in unknown units):
//!
//! * `ln(A_ℓ / A_f1)` for every line `ℓ ≠ f1` (natural log of the amplitude ratio to the
//!   stage-1 mesh line; divide by `ln 10 / 20` for dB). The diagnosis clips these from below at
//!   a noise floor before comparing ([`crate::diagnosis::DiagnoseOptions::floor_db`]);
//! * `f1_power_fraction = ln((A_f1² / 2) / P_band)`: the share of the band power `P_band` (of
//!   `[BAND_LO, BAND_HI] · f1`, Welch segments as above, Parseval on the Hann-windowed FFT) that
//!   the f1 line carries. Near 0 for a clean periodic mesh, strongly negative for a broadband
//!   (chaotic) response.
//!
//! The sensor quantity of the simulation is configurable ([`SensorQuantity`]); the default is the
//! stage-1 relative acceleration `ẍ̄1`.

pub mod line_set;
pub mod precompute;
pub mod table;

use std::f64::consts::TAU;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::model::Frequencies;
use crate::signal::{PlanCache, Window, shared_window};

pub use table::{SignatureTable, model_hash};

/// Segment length of the line estimator, in stage-1 mesh periods (resolution `f1 / 64`).
pub const SEGMENT_PERIODS: f64 = 64.0;
/// Lower edge of the band whose power normalises `f1_power_fraction`, in units of f1.
pub const BAND_LO: f64 = 0.05;
/// Upper edge of that band, in units of f1.
pub const BAND_HI: f64 = 2.5;

/// What the simulated "sensor" measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum SensorQuantity {
    /// Stage-1 relative displacement `x̄1` (the paper's figures).
    X1,
    /// Stage-1 relative acceleration `x̄1''` (closest to a housing accelerometer; default).
    #[default]
    Accel,
    /// Stage-1 dynamic mesh force `k̄1(τ) f(x̄1) + c̄1 x̄1'`.
    MeshForce,
}

impl SensorQuantity {
    /// Label used in files and the CLI.
    pub fn label(&self) -> &'static str {
        match self {
            SensorQuantity::X1 => "x1",
            SensorQuantity::Accel => "accel",
            SensorQuantity::MeshForce => "mesh-force",
        }
    }
}

/// One spectral line of the model, at `ratio × f1`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LineDef {
    /// Name, e.g. `f2`, `2f2`, `f1-f2`.
    pub name: String,
    /// Frequency over the stage-1 mesh frequency f1.
    pub ratio: f64,
    /// True for lines of the planetary stage (f3 and its sidebands): they are kept out of the
    /// wear likelihood and drive the planetary-clearance flag instead.
    pub planetary: bool,
}

/// The lines the model produces that the estimator measures, in ascending frequency: the mesh
/// frequencies, their harmonics and combination tones, and the subharmonics of period-2 motion.
/// Lines closer than 4 resolution bins (`4 / SEGMENT_PERIODS` f1) to another are left out (e.g.
/// `3f2 = 1.08` next to `f1 + f3 = 1.0875`; `f2 + f3 = 0.4475` next to `f1/2`).
pub fn line_set(fr: &Frequencies) -> Vec<LineDef> {
    let (f2, f3) = (fr.f2, fr.f3);
    let l = |name: &str, ratio: f64, planetary: bool| LineDef {
        name: name.into(),
        ratio,
        planetary,
    };
    let mut v = vec![
        l("f3", f3, true),
        l("2f3", 2.0 * f3, true),
        l("f1-2f2", 1.0 - 2.0 * f2, false),
        l("f2", f2, false),
        l("f1/2", 0.5, false),
        l("f1-f2", 1.0 - f2, false),
        l("2f2", 2.0 * f2, false),
        l("f1-f3", 1.0 - f3, true),
        l("f1", 1.0, false),
        l("f1+f3", 1.0 + f3, true),
        l("f1+f2", 1.0 + f2, false),
        l("3f1/2", 1.5, false),
        l("2f1-f2", 2.0 - f2, false),
        l("2f1", 2.0, false),
    ];
    v.sort_by(|a, b| a.ratio.total_cmp(&b.ratio));
    v
}

/// Highest line ratio of a line set (sets the sample-rate requirement `fs > 2 · max · f1`).
pub fn highest_ratio(lines: &[LineDef]) -> f64 {
    lines.iter().map(|l| l.ratio).fold(BAND_HI, f64::max)
}

/// Line amplitudes and band power of a record, as defined in the [module docs](self).
#[derive(Debug, Clone, Serialize)]
pub struct LineMeasurement {
    /// Peak amplitude of each line (unit of the record), in the order of the line set.
    pub amplitudes: Vec<f64>,
    /// Power (mean square, unit²) in `[BAND_LO, BAND_HI] · f1`.
    pub band_power: f64,
    /// Number of Welch segments averaged.
    pub segments: usize,
    /// Segment length in samples.
    pub segment_len: usize,
}

impl LineMeasurement {
    /// Index of a line by name in `lines`.
    pub fn index(lines: &[LineDef], name: &str) -> Option<usize> {
        lines.iter().position(|l| l.name == name)
    }

    /// The gain-invariant feature vector: `ln(A_ℓ/A_f1)` for every line except f1 (line-set
    /// order), then `f1_power_fraction`. Unclipped; non-finite values (a zero line) become a very
    /// negative number (−50, i.e. −434 dB) so that clipping handles them.
    pub fn features(&self, lines: &[LineDef]) -> Vec<f64> {
        let i1 = Self::index(lines, "f1").unwrap_or(0);
        let a1 = self.amplitudes[i1];
        let mut out = Vec::with_capacity(lines.len());
        for (i, a) in self.amplitudes.iter().enumerate() {
            if i == i1 {
                continue;
            }
            out.push(finite_or((a / a1).ln(), -50.0));
        }
        out.push(finite_or((0.5 * a1 * a1 / self.band_power).ln(), -50.0).min(0.0));
        out
    }
}

fn finite_or(v: f64, alt: f64) -> f64 {
    if v.is_finite() { v.max(alt) } else { alt }
}

/// Names of the features returned by [`LineMeasurement::features`].
pub fn feature_names(lines: &[LineDef]) -> Vec<String> {
    let mut v: Vec<String> = lines
        .iter()
        .filter(|l| l.name != "f1")
        .map(|l| format!("ln({}/f1)", l.name))
        .collect();
    v.push("f1_power_fraction".into());
    v
}

/// Samples per segment for a record at `fs` with mesh frequency `f1` (same time unit).
pub fn segment_len(fs: f64, f1: f64) -> usize {
    (SEGMENT_PERIODS * fs / f1).round().max(0.0) as usize
}

/// Measure the lines of `x` (sample rate `fs`, stage-1 mesh frequency `f1`, same time unit).
///
/// Errors: a non-finite sample, a record shorter than one segment, `f1` or `fs` not positive,
/// a line at or above Nyquist.
pub fn measure_lines(x: &[f64], fs: f64, f1: f64, lines: &[LineDef]) -> Result<LineMeasurement> {
    if !(fs.is_finite() && fs > 0.0 && f1.is_finite() && f1 > 0.0) {
        return Err(Error::param(
            "f1 / sample rate",
            f1 / fs,
            "both must be finite and positive",
        ));
    }
    if let Some((index, &value)) = x.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(Error::NonFiniteSample { index, value });
    }
    let highest = highest_ratio(lines) * f1;
    if 2.0 * highest >= fs {
        return Err(Error::SampleRateTooLow {
            sample_rate: fs,
            highest_line_hz: highest,
            needed: 2.0 * highest,
        });
    }
    let l = segment_len(fs, f1);
    if l < 16 || x.len() < l {
        return Err(Error::RecordTooShort {
            samples: x.len(),
            periods: x.len() as f64 * f1 / fs,
            f1_hz: f1,
            needed_periods: SEGMENT_PERIODS as usize,
            needed_samples: l.max(16),
        });
    }
    let hop = (l / 2).max(1);
    let nseg = 1 + (x.len() - l) / hop;
    let w = shared_window(Window::Hann, l);
    let wsum: f64 = w.iter().sum();
    let w2sum: f64 = w.iter().map(|v| v * v).sum();
    // Window × complex exponential, per line, and its sum (for the mean removal). Stored
    // sample-major (`[n][line]`) so that one pass over a segment updates every line's sums:
    // the lines' accumulations are independent chains the CPU overlaps (and vectorises), each
    // still summed in sample order, so the values are those of one line at a time.
    let nl = lines.len();
    let mut kre = vec![0.0; l * nl];
    let mut kim = vec![0.0; l * nl];
    let mut ksum: Vec<(f64, f64)> = Vec::with_capacity(nl);
    let (mut pc, mut ps) = (vec![0.0; l], vec![0.0; l]);
    for (q, ln) in lines.iter().enumerate() {
        let c = ln.ratio * f1 / fs;
        crate::signal::unit_phasors(c, &mut pc, &mut ps);
        let (mut sr, mut si) = (0.0, 0.0);
        for (n, wv) in w.iter().enumerate() {
            let (s, co) = (ps[n], pc[n]);
            let (re, im) = (wv * co, -wv * s);
            kre[n * nl + q] = re;
            kim[n * nl + q] = im;
            sr += re;
            si += im;
        }
        ksum.push((sr, si));
    }
    let mut sum_re = vec![0.0; nl];
    let mut sum_im = vec![0.0; nl];
    let mut power = vec![0.0; lines.len()];
    let plan = PlanCache::global().forward(l);
    let mut input = plan.make_input_vec();
    let mut spectrum = plan.make_output_vec();
    let mut scratch = plan.make_scratch_vec();
    let (k_lo, k_hi) = (
        (BAND_LO * f1 * l as f64 / fs).ceil() as usize,
        ((BAND_HI * f1 * l as f64 / fs).floor() as usize).min(l / 2),
    );
    let mut band = 0.0;
    for s in 0..nseg {
        let seg = &x[s * hop..s * hop + l];
        let mean = seg.iter().sum::<f64>() / l as f64;
        line_sums(seg, &kre, &kim, &mut sum_re, &mut sum_im);
        for (((p, &(sr, si)), &a), &b) in power.iter_mut().zip(&ksum).zip(&sum_re).zip(&sum_im) {
            let (mut a, mut b) = (a, b);
            a -= mean * sr;
            b -= mean * si;
            let amp = 2.0 * a.hypot(b) / wsum;
            *p += amp * amp;
        }
        for ((o, xv), wv) in input.iter_mut().zip(seg).zip(w.iter()) {
            *o = (xv - mean) * wv;
        }
        plan.process_with_scratch(&mut input, &mut spectrum, &mut scratch)
            .map_err(|e| Error::Signal(format!("FFT failed: {e}")))?;
        let e: f64 = spectrum[k_lo..=k_hi.max(k_lo)]
            .iter()
            .map(|c| c.norm_sqr())
            .sum();
        band += 2.0 * e / (l as f64 * w2sum);
    }
    let inv = 1.0 / nseg as f64;
    Ok(LineMeasurement {
        amplitudes: power.iter().map(|p| (p * inv).sqrt()).collect(),
        band_power: band * inv,
        segments: nseg,
        segment_len: l,
    })
}

/// `sum_re[q] = Σ_n seg[n] kre[n][q]` and likewise `sum_im`, kernels sample-major with
/// `sum_re.len()` lines; each line summed in sample order.
#[inline(always)]
fn line_sums_impl(seg: &[f64], kre: &[f64], kim: &[f64], sum_re: &mut [f64], sum_im: &mut [f64]) {
    let nl = sum_re.len();
    sum_re.fill(0.0);
    sum_im.fill(0.0);
    for ((xv, kr), ki) in seg
        .iter()
        .zip(kre.chunks_exact(nl))
        .zip(kim.chunks_exact(nl))
    {
        for (a, k) in sum_re.iter_mut().zip(kr) {
            *a += xv * k;
        }
        for (b, k) in sum_im.iter_mut().zip(ki) {
            *b += xv * k;
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn line_sums_avx2(
    seg: &[f64],
    kre: &[f64],
    kim: &[f64],
    sum_re: &mut [f64],
    sum_im: &mut [f64],
) {
    line_sums_impl(seg, kre, kim, sum_re, sum_im)
}

/// [`line_sums_impl`] with 256-bit vectors when the CPU has AVX2 (same operations per line,
/// no FMA contraction: identical results).
fn line_sums(seg: &[f64], kre: &[f64], kim: &[f64], sum_re: &mut [f64], sum_im: &mut [f64]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (checked just above).
        return unsafe { line_sums_avx2(seg, kre, kim, sum_re, sum_im) };
    }
    line_sums_impl(seg, kre, kim, sum_re, sum_im)
}

/// SplitMix64: a tiny, well-mixed deterministic generator for seeds and initial states (no
/// external dependency; not for cryptography).
#[derive(Debug, Clone)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// A generator from a seed.
    pub fn new(seed: u64) -> Self {
        SplitMix64(seed)
    }
    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in `[0, 1)`.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Uniform in `[lo, hi)`.
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }
    /// Standard normal (Box–Muller).
    pub fn normal(&mut self) -> f64 {
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (TAU * u2).cos()
    }
}

/// Mix several integers into one seed.
pub fn mix_seed(parts: &[u64]) -> u64 {
    let mut g = SplitMix64::new(0x6765_6172_7765_6172);
    let mut s = 0u64;
    for &p in parts {
        g.0 ^= p.wrapping_mul(0x9E37_79B9_7F4A_7C15);
        s = g.next_u64();
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::ModelAConfig;

    #[test]
    fn measures_known_lines_gain_invariantly() {
        let fr = ModelAConfig::default_rig().tooth_counts().frequencies();
        let lines = line_set(&fr);
        let (fs, f1) = (25_600.0, 870.0);
        let n = 25_600;
        let sig = |gain: f64| -> Vec<f64> {
            (0..n)
                .map(|i| {
                    let t = i as f64 / fs;
                    gain * (2.0 * (TAU * f1 * t).sin()
                        + 0.5 * (TAU * fr.f2 * f1 * t + 0.3).sin()
                        + 0.1 * (TAU * 2.0 * f1 * t).cos()
                        + 7.0)
                })
                .collect()
        };
        let m = measure_lines(&sig(1.0), fs, f1, &lines).unwrap();
        let a = |name: &str| m.amplitudes[LineMeasurement::index(&lines, name).unwrap()];
        assert!((a("f1") - 2.0).abs() < 1e-3, "{}", a("f1"));
        assert!((a("f2") - 0.5).abs() < 1e-3);
        assert!((a("2f1") - 0.1).abs() < 1e-3);
        assert!(a("f1/2") < 1e-3);
        // Band power: (2² + 0.5² + 0.1²)/2.
        assert!((m.band_power - (4.0 + 0.25 + 0.01) / 2.0).abs() < 0.01 * m.band_power);
        let f = m.features(&lines);
        let g = measure_lines(&sig(37.0), fs, f1, &lines)
            .unwrap()
            .features(&lines);
        for (x, y) in f.iter().zip(&g) {
            assert!((x - y).abs() < 1e-9);
        }
        assert_eq!(f.len(), feature_names(&lines).len());
    }

    #[test]
    fn refuses_short_records_and_low_rates() {
        let lines = line_set(&ModelAConfig::default_rig().tooth_counts().frequencies());
        let x = vec![0.0; 100];
        assert!(matches!(
            measure_lines(&x, 25_600.0, 870.0, &lines),
            Err(Error::RecordTooShort { .. })
        ));
        assert!(matches!(
            measure_lines(&x, 3000.0, 870.0, &lines),
            Err(Error::SampleRateTooLow { .. })
        ));
    }
}
