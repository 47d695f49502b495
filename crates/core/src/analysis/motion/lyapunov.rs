//! The largest Lyapunov exponent by Benettin's two-trajectory method.

use crate::{Error, Result};

/// Largest Lyapunov exponent by Benettin's two-trajectory renormalisation method.
///
/// A reference trajectory starting at `x0` is first advanced by `transient_intervals`
/// intervals (to settle on the attractor). A companion trajectory is then started at distance
/// `d0` (Euclidean, along `(1, …, 1)/√dim`). Both are advanced by `interval`; the separation
/// `d_k` is measured, `ln(d_k/d0)` accumulated, and the companion is pulled back to distance
/// `d0` along the current separation. After `n_intervals` intervals
///
/// `λ ≈ Σ_k ln(d_k/d0) / (n_intervals · interval)`,
///
/// in units of 1/(independent variable). `d0` must be small enough for the linearisation
/// (e.g. `1e-8` relative to the state size) and `interval` short enough that `d0·e^{λ·interval}`
/// stays small.
///
/// `advance(state, duration)` integrates `state` in place by `duration`; its errors are
/// propagated.
///
/// Errors: empty or non-finite `x0`, non-positive or non-finite `d0`/`interval`,
/// `n_intervals == 0`, or a separation that becomes zero or non-finite ([`Error::NonFiniteValue`]).
pub fn largest_lyapunov<F>(
    x0: &[f64],
    d0: f64,
    interval: f64,
    n_intervals: usize,
    transient_intervals: usize,
    mut advance: F,
) -> Result<f64>
where
    F: FnMut(&mut [f64], f64) -> Result<()>,
{
    if x0.is_empty() {
        return Err(Error::TooFewSamples {
            analysis: "the Lyapunov exponent's state",
            needed: 1,
            samples: 0,
        });
    }
    if x0.iter().any(|v| !v.is_finite()) {
        return Err(Error::NonFiniteValue {
            analysis: "the Lyapunov exponent",
            what: "the initial state".into(),
        });
    }
    if !(d0.is_finite() && d0 > 0.0) {
        return Err(Error::param("d0", d0, "must be finite and > 0"));
    }
    if !(interval.is_finite() && interval > 0.0) {
        return Err(Error::param("interval", interval, "must be finite and > 0"));
    }
    if n_intervals == 0 {
        return Err(Error::param("n_intervals", 0.0, "must be at least 1"));
    }
    let dim = x0.len();
    let mut x = x0.to_vec();
    for _ in 0..transient_intervals {
        advance(&mut x, interval)?;
    }
    let offset = d0 / (dim as f64).sqrt();
    let mut y: Vec<f64> = x.iter().map(|v| v + offset).collect();
    let mut sum_log = 0.0;
    for k in 0..n_intervals {
        advance(&mut x, interval)?;
        advance(&mut y, interval)?;
        let dist = x
            .iter()
            .zip(&y)
            .map(|(a, b)| (b - a).powi(2))
            .sum::<f64>()
            .sqrt();
        if !dist.is_finite() || dist == 0.0 {
            return Err(Error::NonFiniteValue {
                analysis: "the Lyapunov exponent",
                what: format!("the separation in interval {k} ({dist})"),
            });
        }
        sum_log += (dist / d0).ln();
        let s = d0 / dist;
        for (yi, xi) in y.iter_mut().zip(&x) {
            *yi = xi + (*yi - xi) * s;
        }
    }
    Ok(sum_log / (n_intervals as f64 * interval))
}
