//! Window functions (periodic, "DFT-even" form).

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use serde::{Deserialize, Serialize};

/// Window shapes for spectral analysis.
///
/// All windows are generated in the *periodic* (DFT-even) form: `w[n]` for `n = 0..N` is the
/// first `N` samples of a symmetric window of length `N + 1`. This is the right form for FFT
/// analysis (the window's DFT has exactly the textbook main-lobe shape on the bin grid).
///
/// Amplitude calibration is done by the spectrum functions (they divide by `sum(w)`), so the
/// window values themselves are not normalised to any particular gain.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Window {
    /// All ones. Exact on-bin amplitudes, worst leakage; up to 36 % scalloping loss between bins.
    Rectangular,
    /// Hann (raised cosine) `0.5 − 0.5 cos(2πn/N)`. Good general purpose window;
    /// up to 15 % scalloping loss between bins, sidelobes fall as 1/f³.
    Hann,
    /// Heinzel's HFT90D flat-top window (Heinzel, Rüdiger & Schilling 2002,
    /// "Spectrum and spectral density estimation by the DFT"):
    /// `1 − 1.942604 cos z + 1.340318 cos 2z − 0.440811 cos 3z + 0.043097 cos 4z`, `z = 2πn/N`.
    /// Amplitude flatness better than 0.05 % anywhere between bins (so a sine reads its
    /// amplitude at the nearest bin whatever its frequency), at the cost of a wide main lobe
    /// (±5 bins).
    FlatTop,
}

/// HFT90D cosine-sum coefficients `c_k` (signs alternate: `w = Σ (−1)^k c_k cos(k z)`).
const HFT90D: [f64; 5] = [1.0, 1.942604, 1.340318, 0.440811, 0.043097];

/// The `n` samples of a window of shape `kind`, periodic (DFT-even) form.
///
/// `n = 0` gives an empty vector; `n = 1` gives `[1.0]` for every shape (a one-point window
/// must not be zero, or the amplitude normalisation `sum(w)` would vanish).
pub fn window(kind: Window, n: usize) -> Vec<f64> {
    if n == 1 {
        return vec![1.0];
    }
    let nf = n as f64;
    match kind {
        Window::Rectangular => vec![1.0; n],
        Window::Hann => (0..n)
            .map(|i| {
                let z = std::f64::consts::TAU * i as f64 / nf;
                0.5 - 0.5 * z.cos()
            })
            .collect(),
        Window::FlatTop => (0..n)
            .map(|i| {
                let z = std::f64::consts::TAU * i as f64 / nf;
                HFT90D
                    .iter()
                    .enumerate()
                    .map(|(k, &c)| {
                        let s = if k % 2 == 0 { 1.0 } else { -1.0 };
                        s * c * (k as f64 * z).cos()
                    })
                    .sum()
            })
            .collect(),
    }
}

/// Most windows [`shared_window`] keeps (the cache is emptied when it would grow past this, so
/// a stream of records of ever-new lengths cannot grow it without bound).
const SHARED_WINDOWS: usize = 32;

/// [`window`] from a small process-wide cache: the same values, computed once per
/// `(kind, n)`. A record-length Hann window costs one `cos` per sample, which is a noticeable
/// share of a diagnosis when it is recomputed for every record.
pub fn shared_window(kind: Window, n: usize) -> Arc<[f64]> {
    type Cache = Mutex<HashMap<(Window, usize), Arc<[f64]>>>;
    static CACHE: OnceLock<Cache> = OnceLock::new();
    let cache = CACHE.get_or_init(Default::default);
    if let Some(w) = cache
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .get(&(kind, n))
    {
        return Arc::clone(w);
    }
    // Computed outside the lock; two threads may both compute it, with identical values.
    let w: Arc<[f64]> = window(kind, n).into();
    let mut g = cache.lock().unwrap_or_else(|e| e.into_inner());
    if g.len() >= SHARED_WINDOWS {
        g.clear();
    }
    g.insert((kind, n), Arc::clone(&w));
    w
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lengths_and_degenerate_sizes() {
        for kind in [Window::Rectangular, Window::Hann, Window::FlatTop] {
            assert!(window(kind, 0).is_empty());
            assert_eq!(window(kind, 1), vec![1.0]);
            assert_eq!(window(kind, 17).len(), 17);
        }
    }

    #[test]
    fn shared_window_equals_window() {
        for kind in [Window::Rectangular, Window::Hann, Window::FlatTop] {
            for n in [1usize, 2, 17, 1000] {
                let a = shared_window(kind, n);
                assert_eq!(&a[..], &window(kind, n)[..]);
                assert!(Arc::ptr_eq(&a, &shared_window(kind, n)));
            }
        }
    }

    #[test]
    fn hann_is_periodic_form() {
        // Periodic Hann of length 8: starts at 0, peak 1 at n = 4, symmetric about n = 4
        // (i.e. w[n] == w[N - n]), and sums to N/2.
        let w = window(Window::Hann, 8);
        assert_eq!(w[0], 0.0);
        assert!((w[4] - 1.0).abs() < 1e-15);
        for i in 1..8 {
            assert!((w[i] - w[8 - i]).abs() < 1e-15);
        }
        assert!((w.iter().sum::<f64>() - 4.0).abs() < 1e-12);
    }

    #[test]
    fn flat_top_sum_and_peak() {
        // Coherent gain of a cosine-sum window on the periodic grid is c0 (= 1 for HFT90D),
        // peak value at the centre is Σ c_k.
        let n = 64;
        let w = window(Window::FlatTop, n);
        assert!((w.iter().sum::<f64>() / n as f64 - 1.0).abs() < 1e-12);
        let peak: f64 = HFT90D.iter().sum();
        assert!((w[n / 2] - peak).abs() < 1e-12);
    }

    #[test]
    fn serde_names_are_kebab_case() {
        // serde_json is a normal dependency of the crate.
        let s = serde_json::to_string(&Window::FlatTop).unwrap();
        assert_eq!(s, "\"flat-top\"");
        let w: Window = serde_json::from_str("\"hann\"").unwrap();
        assert_eq!(w, Window::Hann);
    }
}
