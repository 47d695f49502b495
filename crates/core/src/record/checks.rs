//! The checks every record passes: a plausible sample rate, finite samples, not flat, not
//! clipped (a tachometer's pulse train: not flat, see [`check_pulses`]).

use super::Channel;
use crate::error::{Error, Result};

/// Highest sample rate a record may claim: 10 MHz, far above any vibration ADC. A larger value
/// is a unit mistake (ns for s, a sample count for a rate), not a measurement.
pub const MAX_SAMPLE_RATE_HZ: f64 = 10e6;

/// Refuse a sample rate that is not a positive finite number of Hz up to
/// [`MAX_SAMPLE_RATE_HZ`], with [`Error::InvalidParameter`] (`"sample rate"`).
pub fn check_sample_rate(fs: f64) -> Result<()> {
    if !(fs.is_finite() && fs > 0.0) {
        return Err(Error::param(
            "sample rate",
            fs,
            "must be a positive number of samples per second",
        ));
    }
    if fs > MAX_SAMPLE_RATE_HZ {
        return Err(Error::param(
            "sample rate",
            fs,
            format!(
                "is above {MAX_SAMPLE_RATE_HZ:e} Hz, beyond any vibration ADC; give the rate in \
                 samples per second"
            ),
        ));
    }
    Ok(())
}

/// Smallest number of samples at one extreme that can count as clipping, as a fraction of the
/// record (0.1 %; at least [`CLIP_MIN_COUNT`]).
pub const CLIP_MIN_FRACTION: f64 = 1e-3;
/// Smallest number of samples at one extreme that can count as clipping.
pub const CLIP_MIN_COUNT: usize = 8;
/// Shortest run of consecutive samples at the extreme that counts as a saturated plateau.
pub const CLIP_MIN_RUN: usize = 3;
/// Fraction of the record at one extreme value that counts as clipping without a run of
/// [`CLIP_MIN_RUN`] (with the [`CLIP_PILE_UP`] rule).
pub const CLIP_PILE_UP_FRACTION: f64 = 0.01;
/// How many times more samples the extreme value must hold than the nearest value inside it.
pub const CLIP_PILE_UP: usize = 4;

/// Refuse a record whose samples cannot be a vibration measurement: empty
/// ([`Error::EmptyRecord`]), NaN or ±∞ ([`Error::NonFiniteSample`]), all one value
/// ([`Error::FlatRecord`]) or clipped ([`Error::ClippedRecord`]).
///
/// Clipping: a saturated sensor or ADC writes its limit value for as long as the signal stays
/// beyond it, so the record's maximum (or minimum) value is *exactly* repeated, in plateaus,
/// far more often than any value just inside it. The rule, per extreme: at least
/// max([`CLIP_MIN_COUNT`], [`CLIP_MIN_FRACTION`]·n) samples equal to it, a run of at least
/// [`CLIP_MIN_RUN`] consecutive ones (or [`CLIP_PILE_UP_FRACTION`] of the record), and at least [`CLIP_PILE_UP`] times as many as the
/// nearest value inside. An unclipped continuous record holds its extreme once; a quantised
/// unclipped sine holds its top ADC code at most ≈ 2.4 times as often as the next code (the
/// arcsine density near a peak), so neither trips the rule. Checked on the SpectraQuest
/// records (`shared/data`): every channel holds its extremes once.
pub fn check_signal(x: &[f64]) -> Result<()> {
    if x.is_empty() {
        return Err(Error::EmptyRecord);
    }
    // Branch-free passes (they vectorise): extremes with NaN/∞ folded in, then counts at the
    // extremes; the detailed look only when a count is large enough to matter.
    let (mut hi, mut lo, mut finite) = (f64::NEG_INFINITY, f64::INFINITY, true);
    for &v in x {
        hi = hi.max(v);
        lo = lo.min(v);
        finite &= v.is_finite();
    }
    if !finite {
        let (index, &value) = x
            .iter()
            .enumerate()
            .find(|(_, v)| !v.is_finite())
            .expect("a non-finite sample exists");
        return Err(Error::NonFiniteSample { index, value });
    }
    if x.len() < 2 {
        return Ok(());
    }
    if hi == lo {
        return Err(Error::FlatRecord {
            samples: x.len(),
            value: hi,
        });
    }
    let (n_hi, n_lo) = x.iter().fold((0usize, 0usize), |(h, l), &v| {
        (h + usize::from(v == hi), l + usize::from(v == lo))
    });
    let need = CLIP_MIN_COUNT.max((CLIP_MIN_FRACTION * x.len() as f64).ceil() as usize);
    for (side, level, count) in [("maximum", hi, n_hi), ("minimum", lo, n_lo)] {
        if count < need {
            continue;
        }
        let (mut run, mut longest, mut longest_at) = (0usize, 0usize, 0usize);
        // The nearest value inside the extreme and how often it occurs.
        let mut next = f64::NAN;
        let mut next_count = 0usize;
        for (i, &v) in x.iter().enumerate() {
            if v == level {
                run += 1;
                if run > longest {
                    longest = run;
                    longest_at = i + 1 - run;
                }
            } else {
                run = 0;
                let closer = next.is_nan() || if level == hi { v > next } else { v < next };
                if closer {
                    next = v;
                    next_count = 1;
                } else if v == next {
                    next_count += 1;
                }
            }
        }
        // A fast signal clipped at a low level crosses it in runs of one or two samples (real
        // SpectraQuest records clipped at 2 × RMS): a pile-up of 1 % of the record counts too.
        let piled = count as f64 >= CLIP_PILE_UP_FRACTION * x.len() as f64;
        if (longest >= CLIP_MIN_RUN || piled) && count >= CLIP_PILE_UP * next_count {
            return Err(Error::ClippedRecord {
                side,
                level,
                count,
                percent: 100.0 * count as f64 / x.len() as f64,
                longest_run: longest,
                longest_at,
            });
        }
    }
    Ok(())
}

/// The checks of a tachometer's pulse train: [`check_signal`] without the clipping rule. A
/// tachometer's pulses often sit exactly at a supply rail (an open collector pulled up to
/// 5 V) for many samples in a row while the other level is noisy: the clipping rule's
/// signature, yet a clean pulse train, not a saturated sensor. Empty, non-finite and flat
/// samples are still refused (a flat channel has no pulse to count).
pub fn check_pulses(x: &[f64]) -> Result<()> {
    match check_signal(x) {
        Err(Error::ClippedRecord { .. }) => Ok(()),
        r => r,
    }
}

/// [`check_signal`] on one channel, its error wrapped in [`Error::InChannel`] naming the
/// channel (for channels that did not come through [`parse_record_channels`], e.g. a JSON
/// body's).
pub fn check_channel(channel: &Channel) -> Result<()> {
    check_signal(&channel.samples).map_err(|e| e.in_channel(&channel.name))
}
