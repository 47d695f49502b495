//! Record quality: the defects data acquisition puts into a record that the basic checks
//! ([`super::check_signal`]: finite, not flat, not clipped at the extremes) let through —
//! spikes, absurd values, dropouts and DC steps — each found with the samples it spans, and
//! the policy for each: refused ([`Error::RecordQuality`]) or repaired ([`inspect`] then
//! [`Inspection::repair`]).
//!
//! The spread everything is measured against is robust, so a defect does not hide itself:
//! σ_r = 1.4826 · MAD (the median absolute deviation from the median; σ for Gaussian noise).
//! On the real records in `shared/data` (SpectraQuest GFD, PHM 2009 helical; every vibration
//! channel) the largest sample sits at 6–15 σ_r, the longest run of one exact value is 7
//! samples and the largest DC step statistic is 0.03 σ_r (`docs/diagnosis.md`, "Record
//! quality"); the thresholds below leave a wide margin over that.
//!
//! | defect | rule | policy |
//! | --- | --- | --- |
//! | absurd value | \|x\| > [`ABSURD_MAGNITUDE`], or beyond the declared unit's plausible range ([`plausible_limit`]) | repaired when inside an isolated spike, else refused |
//! | spike | a cluster of samples beyond [`SPIKE_SIGMAS`] σ_r of the median, at most [`MAX_SPIKE_WIDTH`] wide | up to [`MAX_REPAIRABLE_SPIKES`] repaired (linear interpolation between the neighbours); more: refused when any holds an absurd value, else kept as signal (`impulses`, warned: tooth impacts) |
//! | dropout | a run of at least [`DROPOUT_MIN_RUN`] samples of one exact value | refused |
//! | DC step | the means before and after one sample differ by more than [`DC_STEP_SIGMAS`] σ_r and [`DC_STEP_NOISE`] standard errors (both sides at least 10 % of the record) | refused |

use crate::error::{Error, Result};
pub use crate::quality_finding::QualityFinding;
use crate::signal::velocity::Kinematic;

/// A sample beyond this many robust σ from the median is an outlier (real records: ≤ 15).
pub const SPIKE_SIGMAS: f64 = 25.0;
/// Widest cluster of outliers that is a spike (a glitch, not a mechanical event: an impact
/// rings for many samples).
pub const MAX_SPIKE_WIDTH: usize = 4;
/// Most spikes a record may have and still be repaired.
pub const MAX_REPAIRABLE_SPIKES: usize = 8;
/// Shortest run of one exact value that is a dropout (real records: ≤ 7).
pub const DROPOUT_MIN_RUN: usize = 32;
/// A step of the mean by more than this many robust σ is a DC step (real records: ≤ 0.03).
pub const DC_STEP_SIGMAS: f64 = 0.5;
/// A DC step must also exceed this many standard errors of the shorter side's mean
/// (σ_r / √m for m samples): a short record's segment means wander.
pub const DC_STEP_NOISE: f64 = 6.0;
/// A magnitude no vibration measurement reaches in any unit (its square still fits an `f64`
/// summed over any record).
pub const ABSURD_MAGNITUDE: f64 = 1e12;
/// Largest plausible acceleration, m/s² (≈ 10 000 g: beyond any machine-vibration
/// accelerometer's range).
pub const MAX_ACCELERATION_SI: f64 = 1e5;
/// Largest plausible velocity, m/s (10 000 mm/s).
pub const MAX_VELOCITY_SI: f64 = 10.0;
/// Repaired samples, as a fraction of the record, up to which the alert stands (the repair
/// changes the record's energy by at most this fraction of the local level).
pub const REPAIR_KEEPS_ALERT_FRACTION: f64 = 1e-4;

/// What [`inspect`] found in one channel: the repairable findings and the spans to repair.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Inspection {
    pub findings: Vec<QualityFinding>,
    /// Inclusive sample spans to replace by interpolation.
    pub spans: Vec<(usize, usize)>,
}

impl Inspection {
    /// Samples the repair replaces.
    pub fn repaired_samples(&self) -> usize {
        self.spans.iter().map(|(a, b)| b - a + 1).sum()
    }

    /// Replace each span by the straight line between its neighbours (a span at an end takes
    /// its one neighbour's value).
    pub fn repair(&self, x: &mut [f64]) {
        for &(a, b) in &self.spans {
            let left = a.checked_sub(1).map(|i| x[i]);
            let right = x.get(b + 1).copied();
            let (l, r) = match (left, right) {
                (Some(l), Some(r)) => (l, r),
                (Some(l), None) => (l, l),
                (None, Some(r)) => (r, r),
                (None, None) => (0.0, 0.0),
            };
            let width = (b - a + 2) as f64;
            for (k, v) in x[a..=b].iter_mut().enumerate() {
                let t = (k + 1) as f64 / width;
                *v = l + (r - l) * t;
            }
        }
    }
}

/// The largest plausible magnitude of a sample of a channel measuring `quantity` whose unit is
/// `to_si` SI units (in the channel's own unit): [`MAX_ACCELERATION_SI`] or
/// [`MAX_VELOCITY_SI`] over `to_si`.
pub fn plausible_limit(quantity: Kinematic, to_si: f64) -> f64 {
    let si = match quantity {
        Kinematic::Acceleration => MAX_ACCELERATION_SI,
        Kinematic::Velocity => MAX_VELOCITY_SI,
    };
    (si / to_si).min(ABSURD_MAGNITUDE)
}

/// Where a finding is: `samples a–b (t0–t1 s)`.
fn place(first: usize, last: usize, fs: f64) -> String {
    if first == last {
        format!("sample {first} ({:.4} s)", first as f64 / fs)
    } else {
        format!(
            "samples {first}–{last} ({:.4}–{:.4} s)",
            first as f64 / fs,
            (last + 1) as f64 / fs
        )
    }
}

fn finding(
    defect: &'static str,
    (first, last): (usize, usize),
    fs: f64,
    action: &'static str,
    message: String,
) -> QualityFinding {
    QualityFinding {
        defect,
        channel: None,
        first_sample: first,
        last_sample: last,
        start_s: first as f64 / fs,
        end_s: (last + 1) as f64 / fs,
        action,
        message,
    }
}

fn refuse(f: QualityFinding) -> Error {
    Error::RecordQuality(Box::new(f))
}

/// Median and robust σ (1.4826 · MAD) of `x`, from at most 2¹⁶ evenly spread samples.
fn robust_spread(x: &[f64]) -> (f64, f64) {
    let step = (x.len() / 65_536).max(1);
    let mut s: Vec<f64> = x.iter().step_by(step).copied().collect();
    let mid = s.len() / 2;
    let med = *s.select_nth_unstable_by(mid, f64::total_cmp).1;
    for v in s.iter_mut() {
        *v = (*v - med).abs();
    }
    let mad = *s.select_nth_unstable_by(mid, f64::total_cmp).1;
    (med, 1.4826 * mad)
}

/// Inspect one channel's samples (`fs` in Hz; `limit`: the declared unit's plausible
/// magnitude, [`plausible_limit`]) for the defects of the [module docs](self). A defect that
/// is refused comes back as [`Error::RecordQuality`]; the repairable ones as the
/// [`Inspection`]. The samples must have passed [`super::check_signal`] (finite, not flat).
pub fn inspect(x: &[f64], fs: f64, limit: Option<f64>) -> Result<Inspection> {
    let n = x.len();
    if n < 16 {
        return Ok(Inspection::default());
    }
    find_dropout(x, fs)?;
    let (med, sigma) = robust_spread(x);
    let limit = limit.unwrap_or(ABSURD_MAGNITUDE).min(ABSURD_MAGNITUDE);
    let absurd = |v: f64| v.abs() > limit;
    let outlier = |v: f64| absurd(v) || (sigma > 0.0 && (v - med).abs() > SPIKE_SIGMAS * sigma);
    let clusters = outlier_clusters(x, outlier);
    let mut ins = Inspection::default();
    let spikes: Vec<_> = clusters
        .iter()
        .filter(|(a, b)| b - a < MAX_SPIKE_WIDTH)
        .collect();
    for &(a, b) in &clusters {
        if b - a >= MAX_SPIKE_WIDTH && x[a..=b].iter().any(|&v| absurd(v)) {
            return Err(refuse(finding(
                "absurd-value",
                (a, b),
                fs,
                "refused",
                format!(
                    "{} hold values beyond {limit:e} in magnitude, beyond any vibration \
                     measurement{}: the record is corrupt (a broken sensor, a wrong unit or \
                     garbage bytes) — check the acquisition and send it again",
                    place(a, b, fs),
                    if limit < ABSURD_MAGNITUDE {
                        " in the channel's declared unit"
                    } else {
                        ""
                    }
                ),
            )));
        }
    }
    if spikes.len() > MAX_REPAIRABLE_SPIKES {
        return many_spikes(x, fs, &spikes, absurd, sigma);
    }
    for &&(a, b) in &spikes {
        let peak = x[a..=b].iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        let kind = if x[a..=b].iter().any(|&v| absurd(v)) {
            "absurd-value"
        } else {
            "spike"
        };
        ins.findings.push(finding(
            kind,
            (a, b),
            fs,
            "repaired",
            format!(
                "an isolated spike at {} (|x| up to {peak:.4e}, the record's robust σ is \
                 {sigma:.4e}): replaced by interpolation between its neighbours",
                place(a, b, fs)
            ),
        ));
        ins.spans.push((a, b));
    }
    let mut clean = x.to_vec();
    ins.repair(&mut clean);
    find_dc_step(&clean, fs, sigma)?;
    Ok(ins)
}

/// More than [`MAX_REPAIRABLE_SPIKES`] short outlier clusters. With an absurd value among them
/// the record is corrupt: refused. Otherwise they are kept as signal, with a `warned`
/// `impulses` finding and nothing repaired: many short, large excursions are what tooth
/// impacts (a chipped or broken tooth, backlash rattle) put into a record, and repairing them
/// would erase the very evidence of the fault (a simulated planetary rig's clearance impacts
/// reach beyond 25 σ_r; a sensor that glitches this often shows absurd values or dropouts too).
fn many_spikes(
    x: &[f64],
    fs: f64,
    spikes: &[&(usize, usize)],
    absurd: impl Fn(f64) -> bool,
    sigma: f64,
) -> Result<Inspection> {
    let &(a, b) = spikes[0];
    let &(_, z) = spikes[spikes.len() - 1];
    if spikes
        .iter()
        .any(|&&(p, q)| x[p..=q].iter().any(|&v| absurd(v)))
    {
        return Err(refuse(finding(
            "spike",
            (a, z),
            fs,
            "refused",
            format!(
                "{} isolated spikes (beyond {SPIKE_SIGMAS} robust σ, at most {MAX_SPIKE_WIDTH} \
                 samples wide), some with absurd values, between {} and {}: more than the \
                 {MAX_REPAIRABLE_SPIKES} that can be repaired — check the sensor's cable and \
                 grounding and record again",
                spikes.len(),
                place(a, b, fs),
                place(z, z, fs)
            ),
        )));
    }
    let peak = spikes
        .iter()
        .flat_map(|&&(p, q)| x[p..=q].iter())
        .fold(0.0_f64, |m, v| m.max(v.abs()));
    let mut ins = Inspection::default();
    ins.findings.push(finding(
        "impulses",
        (a, z),
        fs,
        "warned",
        format!(
            "{} short impulses beyond {SPIKE_SIGMAS} robust σ (|x| up to {peak:.4e}, σ_r = \
             {sigma:.4e}) between {} and {}: kept as signal — tooth impacts look like this; if \
             the sensor or its cable is suspect, check it",
            spikes.len(),
            place(a, b, fs),
            place(z, z, fs)
        ),
    ));
    Ok(ins)
}

/// Clusters of samples for which `outlier` holds: inclusive spans, neighbours up to 2 samples
/// apart joined.
fn outlier_clusters(x: &[f64], outlier: impl Fn(f64) -> bool) -> Vec<(usize, usize)> {
    let mut out: Vec<(usize, usize)> = Vec::new();
    for (i, &v) in x.iter().enumerate() {
        if !outlier(v) {
            continue;
        }
        match out.last_mut() {
            Some((_, b)) if i - *b <= 2 => *b = i,
            _ => out.push((i, i)),
        }
    }
    out
}

/// Refuse the first run of at least [`DROPOUT_MIN_RUN`] samples of one exact value.
fn find_dropout(x: &[f64], fs: f64) -> Result<()> {
    let mut start = 0;
    for i in 1..=x.len() {
        if i < x.len() && x[i] == x[start] {
            continue;
        }
        if i - start >= DROPOUT_MIN_RUN {
            let (a, b) = (start, i - 1);
            return Err(refuse(finding(
                "dropout",
                (a, b),
                fs,
                "refused",
                format!(
                    "{} all hold exactly {}: a dropout of {} samples (a lost connection, a \
                     stalled converter or a gap filled with a constant); a spectrum across it is \
                     not the machine's — send the record without the gap",
                    place(a, b, fs),
                    x[a],
                    b - a + 1
                ),
            )));
        }
        start = i;
    }
    Ok(())
}

/// Refuse a DC step: the split point `k` (both sides at least a tenth of the record) where
/// the means of `x[..k]` and `x[k..]` differ most relative to what is needed — more than
/// [`DC_STEP_SIGMAS`] σ_r and more than [`DC_STEP_NOISE`] σ_r / √min(k, n − k).
///
/// For a zero-mean vibration the two means differ by O(σ/√(n/10)); a step of the offset by d
/// at k moves them apart by d.
fn find_dc_step(x: &[f64], fs: f64, sigma: f64) -> Result<()> {
    let n = x.len();
    if sigma <= 0.0 || n < 100 {
        return Ok(());
    }
    let total: f64 = x.iter().sum();
    let (lo, hi) = (n / 10, n - n / 10);
    let mut left = 0.0;
    let (mut best, mut at, mut excess) = (0.0_f64, 0usize, 0.0_f64);
    for (k, &v) in x.iter().enumerate().take(hi) {
        if k >= lo {
            let d = (left / k as f64 - (total - left) / (n - k) as f64).abs();
            // Above the floor and above the noise of the shorter side's mean.
            let need =
                (DC_STEP_SIGMAS * sigma).max(DC_STEP_NOISE * sigma / (k.min(n - k) as f64).sqrt());
            if d / need > excess {
                excess = d / need;
                best = d;
                at = k;
            }
        }
        left += v;
    }
    if excess > 1.0 {
        return Err(refuse(finding(
            "dc-step",
            (at, at),
            fs,
            "refused",
            format!(
                "the record's mean steps by {best:.4e} ({:.1} robust σ) at {}: a DC step (a \
                 sensor's bias shifting, a cable or range change mid-record); the vibration \
                 on either side is not one measurement — send the two parts as separate records",
                best / sigma,
                place(at, at, fs)
            ),
        )));
    }
    Ok(())
}
