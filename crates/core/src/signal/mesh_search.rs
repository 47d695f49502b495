//! Locating the stage-1 mesh line (f1) of a gearbox in a record's spectrum.
//!
//! With a speed hint (`f1 = z1 × shaft_hz`), the line is refined to the maximum of the record's
//! Hann DTFT within ±0.3 %. Without one (tacho-less), every prominent peak (≥ 10 dB over the
//! local floor) inside the admissible band is scored by its own prominence plus the prominence
//! of its kinematic partners (the caller's `(name, ratio)` list: the other stages' mesh lines,
//! their combination tones, `2 f1`, …); the best candidate wins (or its half-frequency
//! neighbour, see `locate_f1`) and is refined the same way. The diagnosis
//! ([`crate::diagnosis`]) uses it.

use serde::Serialize;

use super::{Spectrum, Window, amplitude_spectrum, welch};
use crate::error::{Error, Result};

/// How f1 was found.
#[derive(Debug, Clone, Serialize)]
pub struct F1Detection {
    /// `shaft-speed` or `spectrum` (tacho-less).
    pub method: &'static str,
    /// Starting value before refinement (Hz).
    pub initial_hz: f64,
    /// Prominence of the f1 peak over the local spectral floor (dB).
    pub prominence_db: f64,
    /// Kinematic partner lines seen at ≥ 6 dB over the floor, by name.
    pub partners_found: Vec<String>,
    /// Score of the chosen candidate (tacho-less) and of the runner-up.
    pub score: f64,
    pub runner_up_hz: Option<f64>,
    pub runner_up_score: Option<f64>,
    /// Best candidates `(Hz, score, partners found)` of the tacho-less search.
    pub candidates: Vec<(f64, f64, Vec<String>)>,
}

/// Local spectral floor: running median of `amp` over ±`half` bins, evaluated every `stride`
/// bins and interpolated. The medians are computed on first use: the f1 search reads the floor
/// only around the speed band and the partner lines, a fraction of the spectrum.
struct LocalFloor {
    half: usize,
    stride: usize,
    /// Median at centre `i · stride`, once computed.
    medians: Vec<std::cell::OnceCell<f64>>,
}

impl LocalFloor {
    fn new(n: usize, half: usize, stride: usize) -> Self {
        LocalFloor {
            half,
            stride,
            medians: (0..n.div_ceil(stride))
                .map(|_| std::cell::OnceCell::new())
                .collect(),
        }
    }

    fn median(&self, amp: &[f64], i: usize) -> f64 {
        *self.medians[i].get_or_init(|| {
            let c = i * self.stride;
            let lo = c.saturating_sub(self.half);
            let hi = (c + self.half + 1).min(amp.len());
            let mut buf = amp[lo..hi].to_vec();
            let mid = buf.len() / 2;
            buf.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
            buf[mid].max(1e-300)
        })
    }

    /// The floor at bin `k` of `amp` (the spectrum this floor was made for).
    fn at(&self, amp: &[f64], k: usize) -> f64 {
        let last = self.medians.len() - 1;
        let i = (k / self.stride).min(last);
        let i1 = (i + 1).min(last);
        let t = if i1 > i {
            (k - i * self.stride) as f64 / ((i1 - i) * self.stride) as f64
        } else {
            0.0
        };
        self.median(amp, i) * (1.0 - t) + self.median(amp, i1) * t
    }
}

/// [`LocalFloor`] at every bin (reference for the tests).
#[cfg(test)]
fn local_floor(amp: &[f64], half: usize, stride: usize) -> Vec<f64> {
    let f = LocalFloor::new(amp.len(), half, stride);
    (0..amp.len()).map(|k| f.at(amp, k)).collect()
}

/// Hann-windowed DTFT magnitude of the whole record at `f` (Hz): a smooth peak to refine on.
/// `xw` is the record times the window.
fn dtft_mag(xw: &[f64], fs: f64, f: f64) -> f64 {
    let (re, im) = crate::signal::dtft_sums(xw, f / fs);
    re.hypot(im)
}

/// Golden-section maximisation of the DTFT magnitude on `[a, b]`.
fn refine_peak(x: &[f64], fs: f64, a: f64, b: f64, w: &[f64]) -> f64 {
    // The windowed record does not depend on the frequency: form it once.
    let xw: Vec<f64> = x.iter().zip(w).map(|(x, w)| x * w).collect();
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let (mut a, mut b) = (a, b);
    let mut c = b - g * (b - a);
    let mut d = a + g * (b - a);
    let (mut fc, mut fd) = (dtft_mag(&xw, fs, c), dtft_mag(&xw, fs, d));
    for _ in 0..40 {
        if fc > fd {
            b = d;
            d = c;
            fd = fc;
            c = b - g * (b - a);
            fc = dtft_mag(&xw, fs, c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + g * (b - a);
            fd = dtft_mag(&xw, fs, d);
        }
        if (b - a) < 1e-7 * b.abs().max(1.0) {
            break;
        }
    }
    0.5 * (a + b)
}

/// Refine a peak near `f0` (Hz) to the maximum of the whole-record Hann DTFT within ±`half`.
pub(crate) fn refine_near(x: &[f64], fs: f64, f0: f64, half: f64) -> f64 {
    let w = crate::signal::shared_window(Window::Hann, x.len());
    refine_peak(x, fs, (f0 - half).max(1e-9), f0 + half, &w)
}

/// Spectrum used for the f1 search: Hann, whole record up to 2^17 samples, Welch above.
pub(crate) struct SearchSpectrum {
    freq_step: f64,
    amp: Vec<f64>,
    freq: Vec<f64>,
    /// `amp` is the whole record's [`amplitude_spectrum`] (not Welch).
    whole: bool,
    floor: LocalFloor,
}

impl SearchSpectrum {
    pub(crate) fn new(x: &[f64], fs: f64) -> Result<Self> {
        const MAX: usize = 1 << 17;
        let whole = x.len() <= MAX;
        let s = if whole {
            amplitude_spectrum(x, fs, Window::Hann)?
        } else {
            welch(x, fs, MAX, 0.5, Window::Hann)?
        };
        let floor = LocalFloor::new(s.amplitude.len(), 100, 10);
        Ok(SearchSpectrum {
            freq_step: s.resolution(),
            amp: s.amplitude,
            freq: s.freq,
            whole,
            floor,
        })
    }

    /// The whole record's Hann amplitude spectrum, if that is what the search used.
    pub(crate) fn into_whole(self) -> Option<Spectrum> {
        self.whole.then_some(Spectrum {
            freq: self.freq,
            amplitude: self.amp,
        })
    }
    /// Peak prominence (dB over the local floor) of the largest bin within ±tol Hz of f.
    fn prominence(&self, f: f64, tol: f64) -> f64 {
        let lo = ((f - tol) / self.freq_step).floor().max(0.0) as usize;
        let hi = (((f + tol) / self.freq_step).ceil() as usize).min(self.amp.len() - 1);
        if lo > hi {
            return 0.0;
        }
        (lo..=hi)
            .map(|k| 20.0 * (self.amp[k] / self.floor.at(&self.amp, k)).log10())
            .fold(f64::NEG_INFINITY, f64::max)
    }
}

/// Find f1 (Hz). `band` is the admissible f1 range (Hz); `parts` the kinematic partners
/// `(name, ratio to f1)` that support a candidate.
pub(crate) fn locate_f1(
    x: &[f64],
    fs: f64,
    spec: &SearchSpectrum,
    parts: &[(String, f64)],
    band: (f64, f64),
    nominal: Option<f64>,
) -> Result<(f64, F1Detection)> {
    let df = spec.freq_step;
    let tol = |f: f64| (2.0 * df).max(0.002 * f);
    let w = crate::signal::shared_window(Window::Hann, x.len());
    let evidence = |f: f64| -> (f64, Vec<String>) {
        let mut score = spec.prominence(f, tol(f)).clamp(0.0, 60.0);
        let mut found = Vec::new();
        for (name, r) in parts {
            let fp = r * f;
            if fp >= 0.5 * fs {
                continue;
            }
            let p = spec.prominence(fp, tol(fp));
            score += p.clamp(0.0, 30.0);
            if p >= 6.0 {
                found.push(name.to_string());
            }
        }
        (score, found)
    };
    if let Some(f0) = nominal {
        let half = (0.003 * f0).max(2.0 * df);
        let f = refine_peak(x, fs, f0 - half, f0 + half, &w);
        let prom = spec.prominence(f, tol(f));
        let (score, found) = evidence(f);
        return Ok((
            f,
            F1Detection {
                method: "shaft-speed",
                initial_hz: f0,
                prominence_db: prom,
                partners_found: found,
                score,
                runner_up_hz: None,
                runner_up_score: None,
                candidates: Vec::new(),
            },
        ));
    }
    let klo = (band.0 / df).ceil().max(1.0) as usize;
    let khi = ((band.1 / df).floor() as usize).min(spec.amp.len().saturating_sub(3));
    let mut cands: Vec<(usize, f64)> = Vec::new();
    for k in klo.max(2)..=khi {
        let a = spec.amp[k];
        if a >= spec.amp[k - 1]
            && a > spec.amp[k + 1]
            && a >= spec.amp[k - 2]
            && a > spec.amp[k + 2]
        {
            let p = 20.0 * (a / spec.floor.at(&spec.amp, k)).log10();
            if p >= 10.0 {
                cands.push((k, p));
            }
        }
    }
    if cands.is_empty() {
        return Err(Error::NoMeshLine {
            lo_hz: band.0,
            hi_hz: band.1,
            reason: "no spectral peak stands 10 dB above the local floor in the band; give the \
                     input-shaft rate or check the sample rate"
                .into(),
        });
    }
    cands.sort_by(|a, b| b.1.total_cmp(&a.1));
    cands.truncate(40);
    let mut scored: Vec<(f64, f64, Vec<String>, f64)> = cands
        .iter()
        .map(|&(k, p)| {
            let f = k as f64 * df;
            let (s, found) = evidence(f);
            (f, s, found, p)
        })
        .collect();
    scored.sort_by(|a, b| b.1.total_cmp(&a.1));
    // Harmonic ambiguity: with a rich nonlinear spectrum, 2·f1 finds "partners" too (the
    // combination tones 2·f2, 2·(f1 − f2), …). Prefer the half-frequency candidate when it is
    // nearly as well supported and carries most of the first-order partners.
    let mut pick = 0;
    for (k, c) in scored.iter().enumerate().skip(1) {
        let best = &scored[0];
        if (c.0 - 0.5 * best.0).abs() <= tol(c.0) && c.1 >= best.1 - 15.0 && c.2.len() >= 4 {
            pick = k;
            break;
        }
    }
    let (f0, score, found, prom) = scored[pick].clone();
    let f = refine_peak(x, fs, f0 - 1.5 * df, f0 + 1.5 * df, &w);
    Ok((
        f,
        F1Detection {
            method: "spectrum",
            initial_hz: f0,
            prominence_db: prom,
            partners_found: found,
            score,
            runner_up_hz: scored.get(1).map(|s| s.0),
            runner_up_score: scored.get(1).map(|s| s.1),
            candidates: scored
                .iter()
                .take(4)
                .map(|s| (s.0, s.1, s.2.clone()))
                .collect(),
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The running median equals a fresh median of every window.
    #[test]
    fn local_floor_matches_per_window_median() {
        let mut s = 12345u64;
        let amp: Vec<f64> = (0..3001)
            .map(|i| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                // Repeated values too (ties).
                if i % 7 == 0 {
                    0.5
                } else {
                    (s >> 11) as f64 / (1u64 << 53) as f64
                }
            })
            .collect();
        for (half, stride) in [(100, 10), (3, 10), (50, 1)] {
            let got = local_floor(&amp, half, stride);
            let n = amp.len();
            let mut c = 0;
            while c < n {
                let mut w = amp[c.saturating_sub(half)..(c + half + 1).min(n)].to_vec();
                let mid = w.len() / 2;
                w.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
                assert_eq!(got[c], w[mid], "half {half} stride {stride} centre {c}");
                c += stride;
            }
        }
    }
}
