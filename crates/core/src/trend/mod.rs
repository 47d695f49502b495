//! Trends and time to threshold: a machine's series over measurement time —
//! its wear degree, novelty score or a finding's strength — fitted with a straight line robust
//! to outliers, and the time until the line crosses the warning and alarm thresholds.
//!
//! # The estimate
//! * **Slope**: the Theil–Sen estimator, the median of the pairwise slopes
//!   `(y_j − y_i) / (t_j − t_i)` over all pairs with `t_i ≠ t_j` (Sen 1968). Up to 29 % of the
//!   points can be arbitrary outliers before it breaks down; on Gaussian noise its efficiency is
//!   about 91 % of least squares.
//! * **Level**: the line's value at the latest point, `median(y_i − b·(t_i − t_end))`.
//! * **Significance**: the Mann–Kendall test of `S = Σ_{i<j} sign(y_j − y_i)` (points in time
//!   order) against no monotonic trend, `Var S = n(n−1)(2n+5)/18`, normal approximation with a
//!   continuity correction; the slope is *significant* when the two-sided p-value is below
//!   [`TrendOptions::alpha`] (5 %) and there are at least [`TrendOptions::min_points`] points.
//!   A flat history is thus called a trend in about 5 % of cases when its residuals are
//!   independent.
//! * **Intervals**: a pairs bootstrap — [`TrendOptions::resamples`] resamples of the points with
//!   replacement, each refitted (slope and level) — seeded ([`TrendOptions::seed`]), so the same
//!   series gives the same answer. The slope's 90 % interval is the 5th and 95th percentiles of
//!   the resampled slopes; a crossing time's 90 % interval is those percentiles of the crossing
//!   times `(threshold − level_b) / slope_b` of the resamples (a resample whose line does not
//!   rise towards the threshold never crosses: an upper end of `None`, "not bounded").
//!
//! Times are in days (any origin: [`Sample::t_days`]); a crossing is counted in days from the
//! latest point. Values are in the series' own unit (the wear degree in reference lengths, the
//! novelty score, a finding's strength).

use serde::Serialize;

use crate::signature::SplitMix64;

#[cfg(test)]
mod tests;

/// One point of a series.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Measurement time, days (any origin).
    pub t_days: f64,
    /// The series' value.
    pub value: f64,
}

/// How a trend is estimated.
#[derive(Debug, Clone, Copy)]
pub struct TrendOptions {
    /// Bootstrap resamples for the intervals.
    pub resamples: usize,
    /// Seed of the bootstrap's generator.
    pub seed: u64,
    /// Two-sided significance level of the Mann–Kendall test.
    pub alpha: f64,
    /// Fewer points than this: never significant.
    pub min_points: usize,
}

impl Default for TrendOptions {
    fn default() -> Self {
        TrendOptions {
            resamples: 400,
            seed: 0x74_7265_6e64,
            alpha: 0.05,
            min_points: 6,
        }
    }
}

/// The fitted line.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Fit {
    /// Theil–Sen slope, series unit per day.
    pub slope_per_day: f64,
    /// 90 % bootstrap interval of the slope.
    pub slope_interval_90: [f64; 2],
    /// The line's value at the latest point.
    pub level: f64,
    /// Mann–Kendall two-sided p-value of "no monotonic trend".
    pub p_value: f64,
    /// Is the trend significant (p below the level, enough points)?
    pub significant: bool,
    /// Points fitted.
    pub points: usize,
    /// Time from the first to the latest point, days.
    pub span_days: f64,
}

/// When the line reaches a threshold, counted from the latest point.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Crossing {
    /// Days from the latest point; 0 when the level is already at or above the threshold.
    pub days: f64,
    /// 90 % interval of `days`; an upper end of `None` is unbounded (some resampled lines do
    /// not rise towards the threshold).
    pub interval_90: [Option<f64>; 2],
}

/// A fitted series: its line and the bootstrap's resampled lines, for projections.
#[derive(Debug, Clone)]
pub struct Trend {
    pub fit: Fit,
    /// Resampled `(slope, level)` pairs.
    resampled: Vec<(f64, f64)>,
}

/// Fit a series (any order; points with a non-finite time or value are skipped). `None` with
/// fewer than 2 points at distinct times.
pub fn fit(samples: &[Sample], opts: &TrendOptions) -> Option<Trend> {
    let mut pts: Vec<Sample> = samples
        .iter()
        .copied()
        .filter(|s| s.t_days.is_finite() && s.value.is_finite())
        .collect();
    pts.sort_by(|a, b| a.t_days.total_cmp(&b.t_days));
    let (first, last) = (pts.first()?.t_days, pts.last()?.t_days);
    if last <= first {
        return None;
    }
    let (slope, level) = theil_sen(&pts, last)?;
    let mut rng = SplitMix64::new(opts.seed);
    let mut resampled = Vec::with_capacity(opts.resamples);
    let mut draw = Vec::with_capacity(pts.len());
    for _ in 0..opts.resamples {
        draw.clear();
        for _ in 0..pts.len() {
            draw.push(pts[(rng.uniform() * pts.len() as f64) as usize % pts.len()]);
        }
        if let Some(line) = theil_sen_sampled(&draw, last, &mut rng) {
            resampled.push(line);
        }
    }
    let mut slopes: Vec<f64> = resampled.iter().map(|r| r.0).collect();
    slopes.sort_by(f64::total_cmp);
    let p_value = mann_kendall_p(&pts);
    let fit = Fit {
        slope_per_day: slope,
        slope_interval_90: [
            percentile(&slopes, 0.05).unwrap_or(slope),
            percentile(&slopes, 0.95).unwrap_or(slope),
        ],
        level,
        p_value,
        significant: pts.len() >= opts.min_points && p_value < opts.alpha,
        points: pts.len(),
        span_days: last - first,
    };
    Some(Trend { fit, resampled })
}

impl Trend {
    /// When the line reaches `threshold` (rising towards it), counted from the latest point:
    /// `days` 0 when the level is already there; `None` when the trend is not significant or
    /// the line falls away from the threshold.
    pub fn crossing(&self, threshold: f64) -> Option<Crossing> {
        let f = &self.fit;
        if !f.significant {
            return None;
        }
        if f.level >= threshold {
            return Some(Crossing {
                days: 0.0,
                interval_90: [Some(0.0), Some(0.0)],
            });
        }
        if f.slope_per_day <= 0.0 {
            return None;
        }
        let mut days: Vec<f64> = self
            .resampled
            .iter()
            .map(|&(b, level)| days_to(threshold, level, b))
            .collect();
        days.sort_by(f64::total_cmp);
        let bound = |q| percentile(&days, q).filter(|d: &f64| d.is_finite());
        Some(Crossing {
            days: days_to(threshold, f.level, f.slope_per_day),
            interval_90: [bound(0.05), bound(0.95)],
        })
    }
}

/// Days until a line at `level` rising at `slope` per day reaches `threshold` (0 when there,
/// infinite when it does not rise).
fn days_to(threshold: f64, level: f64, slope: f64) -> f64 {
    if level >= threshold {
        0.0
    } else if slope > 0.0 {
        (threshold - level) / slope
    } else {
        f64::INFINITY
    }
}

/// Pairs a bootstrap resample's slope is the median of, at most: beyond 64 points (2 016
/// pairs) a resample uses this many random pairs (the randomized Theil–Sen estimator), so a
/// fit of 200 points costs milliseconds, not tens of them. The fit itself uses every pair.
const MAX_RESAMPLE_PAIRS: usize = 2_016;

/// [`theil_sen`] over at most [`MAX_RESAMPLE_PAIRS`] pairs drawn at random (all of them when
/// there are no more).
fn theil_sen_sampled(pts: &[Sample], t_end: f64, rng: &mut SplitMix64) -> Option<(f64, f64)> {
    let n = pts.len();
    if n * n.saturating_sub(1) / 2 <= MAX_RESAMPLE_PAIRS {
        return theil_sen(pts, t_end);
    }
    let mut slopes = Vec::with_capacity(MAX_RESAMPLE_PAIRS);
    for _ in 0..MAX_RESAMPLE_PAIRS {
        let i = (rng.uniform() * n as f64) as usize % n;
        let j = (rng.uniform() * n as f64) as usize % n;
        let dt = pts[j].t_days - pts[i].t_days;
        if dt != 0.0 {
            slopes.push((pts[j].value - pts[i].value) / dt);
        }
    }
    let slope = median_select(&mut slopes)?;
    Some((slope, level_at(pts, slope, t_end)?))
}

/// `median(y_i − slope·(t_i − t_end))`: the level at `t_end` of a line of that slope.
fn level_at(pts: &[Sample], slope: f64, t_end: f64) -> Option<f64> {
    let mut offsets: Vec<f64> = pts
        .iter()
        .map(|p| p.value - slope * (p.t_days - t_end))
        .collect();
    median_select(&mut offsets)
}

/// Theil–Sen `(slope, level at t_end)` of points; `None` without two distinct times.
fn theil_sen(pts: &[Sample], t_end: f64) -> Option<(f64, f64)> {
    let mut slopes = Vec::with_capacity(pts.len() * (pts.len().saturating_sub(1)) / 2);
    for (i, a) in pts.iter().enumerate() {
        for b in &pts[i + 1..] {
            let dt = b.t_days - a.t_days;
            if dt != 0.0 {
                slopes.push((b.value - a.value) / dt);
            }
        }
    }
    let slope = median_select(&mut slopes)?;
    Some((slope, level_at(pts, slope, t_end)?))
}

/// The median by selection (O(n), reorders `v`); the mean of the two middle values for an
/// even count; `None` for none.
fn median_select(v: &mut [f64]) -> Option<f64> {
    let n = v.len();
    if n == 0 {
        return None;
    }
    let (_, hi, _) = v.select_nth_unstable_by(n / 2, f64::total_cmp);
    let hi = *hi;
    if n % 2 == 1 {
        return Some(hi);
    }
    let lo = v[..n / 2].iter().copied().fold(f64::NEG_INFINITY, f64::max);
    Some(0.5 * (lo + hi))
}

/// The `q` quantile of sorted values (linear interpolation); `None` for none.
fn percentile(sorted: &[f64], q: f64) -> Option<f64> {
    let n = sorted.len();
    if n == 0 {
        return None;
    }
    let x = q.clamp(0.0, 1.0) * (n - 1) as f64;
    let (i, frac) = (x.floor() as usize, x - x.floor());
    let a = sorted[i];
    if frac == 0.0 || i + 1 >= n {
        return Some(a);
    }
    let b = sorted[i + 1];
    if a.is_infinite() || b.is_infinite() {
        return Some(if frac < 0.5 { a } else { b });
    }
    Some(a + frac * (b - a))
}

/// Two-sided p-value of the Mann–Kendall test on points in time order: `S = Σ_{i<j}
/// sign(y_j − y_i)` over pairs at distinct times, `Var S = n(n−1)(2n+5)/18`,
/// `z = (S − sign S)/√Var S`, `p = erfc(|z|/√2)`.
fn mann_kendall_p(pts: &[Sample]) -> f64 {
    let n = pts.len() as f64;
    if pts.len() < 3 {
        return 1.0;
    }
    let mut s = 0.0;
    for (i, a) in pts.iter().enumerate() {
        for b in &pts[i + 1..] {
            if b.t_days > a.t_days {
                s += (b.value - a.value).signum() * f64::from(b.value != a.value);
            }
        }
    }
    let var = n * (n - 1.0) * (2.0 * n + 5.0) / 18.0;
    let z = (s - s.signum()) / var.sqrt();
    erfc(z.abs() / std::f64::consts::SQRT_2)
}

/// The complementary error function, `erfc(x) = 1 − erf(x)`, for `x ≥ 0`, from the Chebyshev
/// fit of Numerical Recipes (`erfcc`, fractional error below 1.2e-7 everywhere).
fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let poly = -z * z - 1.265_512_23
        + t * (1.000_023_68
            + t * (0.374_091_96
                + t * (0.096_784_18
                    + t * (-0.186_288_06
                        + t * (0.278_868_07
                            + t * (-1.135_203_98
                                + t * (1.488_515_87 + t * (-0.822_152_23 + t * 0.170_872_77))))))));
    let r = t * poly.exp();
    if x >= 0.0 { r } else { 2.0 - r }
}

/// A sentence for a planner: "alarm in 41 days (90 % interval 28–70)", "above alarm",
/// "no significant trend", … — `thresholds` are `(name, value)` in increasing order.
pub fn verdict(trend: Option<&Trend>, thresholds: &[(&str, f64)]) -> String {
    let Some(t) = trend.filter(|t| t.fit.significant) else {
        return "no significant trend".into();
    };
    let f = &t.fit;
    let mut parts = Vec::new();
    for &(name, value) in thresholds {
        match t.crossing(value) {
            Some(c) if c.days == 0.0 => parts = vec![format!("above {name}")],
            Some(c) => parts.push(format!(
                "{name} in {} days (90 % interval {}–{})",
                days_text(c.days),
                c.interval_90[0].map_or("?".into(), days_text),
                c.interval_90[1].map_or("unbounded".into(), days_text)
            )),
            None => {}
        }
    }
    if parts.is_empty() || thresholds.is_empty() {
        let dir = if f.slope_per_day > 0.0 {
            "rising"
        } else {
            "falling"
        };
        parts.push(format!("{dir} {:.3} per day", f.slope_per_day.abs()));
    }
    parts.join("; ")
}

fn days_text(d: f64) -> String {
    if d < 10.0 {
        format!("{d:.1}")
    } else {
        format!("{d:.0}")
    }
}
