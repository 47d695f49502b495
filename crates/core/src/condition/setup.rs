//! Does a record's set-up agree with itself? The input-shaft rate the sender declares (the
//! record's `shaft_hz`, else the machine's configured rate), the rate the record measures (its
//! tachometer, or the lines every shaft makes) and where the gearbox's lines sit.
//!
//! A sample rate declared wrong by a factor (the true rate is `T`, the declared `D`) shows
//! every frequency, the tachometer's included, at `D/T` times its true value; a tachometer
//! declared with `n` pulses per revolution that gives `N` measures `N/n` times the true rate
//! while the gearbox's lines stay where they are. So:
//!
//! - **With a tachometer**, `r` = measured / declared. Within [`SLIP_LIMIT`] the set-up agrees
//!   (motor slip, a setting a little off): nothing is reported, and the lines are not
//!   consulted (a record whose tachometer agrees with its declared rate gets no rate finding).
//!   Beyond it, the lines decide the cause: when the grid of every shaft's lines is more
//!   prominent near the declared rate than at the tachometer's ([`MARGIN`]), the pulses per
//!   revolution are wrong (likely `n · r'`, `r'` = tachometer / lines' rate, when that is near a
//!   whole number); otherwise the sample rate (likely `D / r`) — or the declared speed itself.
//!   A tachometer counting twice the pulses puts the rate on every other line of the true grid,
//!   which scores as well: there the shaft sidebands near the meshes that only the slower grid
//!   makes decide.
//! - **Without one**, the measured rate was searched near the declared one, so it cannot
//!   disagree; instead each factor `c` of [`FACTORS`] is tried: the rate within [`SLIP`] of
//!   `c ×` declared at which every shaft's lines line up, and the weighted mean prominence of
//!   the grid there. A factor other than 1 wins when it beats 1 by [`MARGIN`]. Doubling is
//!   ambiguous from the mesh lines alone (a grid at twice the rate is every other line of the
//!   grid at the rate, and the coarser grid of the strongest lines scores as well), so of the
//!   winner and its partner at half or twice its factor the slower wins when the lines only it
//!   makes near the meshes (the shaft sidebands) stand [`MARGIN`] over the midpoints between
//!   its lines — and, for a grid other than the declared one, its own mesh harmonics too: the
//!   burden of proof lies on a finding. Halving is not tried (see [`FACTORS`]).
//!
//! The constants were fixed before the rule was run on a record; the pairing of halves and
//! doubles, the mesh harmonics' part in it, the tachometer's k-fold count and dropping halving
//! without a tachometer came after the first runs on the real records (`docs/real-data.md`,
//! "Set-up").

use serde::Serialize;

use super::lines::LineMap;
use super::synchronous::{LineProminence, grid_orders};

/// Largest relative difference between the declared and the measured input-shaft rate that is
/// normal (slip, a setting a little off).
pub const SLIP_LIMIT: f64 = 0.06;
/// Relative half-width of the search around each factor's rate.
pub const SLIP: f64 = 0.03;
/// Factors tried besides 1 without a tachometer (where the lines sit, as a multiple of where
/// the declared rate puts them): double, 0.9 and 1.1. Not half: the grid at half the rate holds
/// every line of the right one, and a gear's nonlinear response (subharmonics, the model's own
/// period-2 motion) and lines the description does not explain fill the rest.
pub const FACTORS: [f64; 3] = [2.0, 0.9, 1.1];
/// How much (mean prominence, ln units: ≈ 2.6 dB) one explanation must beat another.
pub const MARGIN: f64 = 0.3;

/// What the check concludes about the set-up.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "cause", rename_all = "kebab-case")]
pub enum Cause {
    /// The sample rate is probably `likely_hz`, not the declared one.
    SampleRate { declared_hz: f64, likely_hz: f64 },
    /// The tachometer probably gives `likely` pulses per revolution, not `declared`.
    PulsesPerRevolution { declared: usize, likely: usize },
    /// The measured rate disagrees with the declared one and neither cause above fits: the
    /// declared speed may be wrong.
    Speed,
}

/// The set-up check's verdict.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SetupCheck {
    /// The input-shaft rate the sender declared, Hz (in the answer's `setup` object already).
    #[serde(skip)]
    pub declared_shaft_hz: f64,
    /// Where the gearbox's lines put the input-shaft rate, Hz (`None`: not read).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lines_shaft_hz: Option<f64>,
    /// Where the lines sit, as a multiple of where the declared rate puts them.
    pub ratio: f64,
    /// The disagreement's likely cause (`cause` and its figures, flat); `None` when the set-up
    /// agrees.
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    pub cause: Option<Cause>,
}

impl SetupCheck {
    /// The sentence a person reads, when the set-up disagrees.
    pub fn message(&self) -> Option<String> {
        let lead = format!(
            "the record's lines put the input shaft at {:.3} × the declared {:.2} Hz",
            self.ratio, self.declared_shaft_hz
        );
        Some(match self.cause.as_ref()? {
            Cause::SampleRate {
                declared_hz,
                likely_hz,
            } => format!(
                "{lead}: is the sample rate {likely_hz:.0} Hz, not {declared_hz:.0}? Send the \
                 record with its true sample rate (or correct the declared shaft rate)"
            ),
            Cause::PulsesPerRevolution { declared, likely } => format!(
                "{lead} by the tachometer, but the gearbox's lines sit at {:.2} Hz: does the \
                 tachometer give {likely} pulses per revolution, not {declared}? Correct \
                 `tacho_ppr`",
                self.lines_shaft_hz.unwrap_or(self.declared_shaft_hz)
            ),
            Cause::Speed => format!(
                "{lead}, and no mis-declared sample rate or pulse count explains it: check the \
                 declared shaft rate and the sample rate"
            ),
        })
    }
}

/// A record with a tachometer: `measured_hz` counted from it with `ppr` pulses per revolution,
/// `x` (rate `fs`, Hz) the channel whose lines are read; see the [module docs](self).
pub fn check_tachometer(
    x: &[f64],
    fs: f64,
    map: &LineMap,
    declared_hz: f64,
    measured_hz: f64,
    ppr: usize,
) -> SetupCheck {
    let r = measured_hz / declared_hz;
    let mut check = SetupCheck {
        declared_shaft_hz: declared_hz,
        lines_shaft_hz: None,
        ratio: r,
        cause: None,
    };
    if (r - 1.0).abs() <= SLIP_LIMIT {
        return check;
    }
    let lines = LineProminence::of(x, fs).ok();
    let orders = grid_orders(map, 3.0);
    let fit = |centre: f64, search: f64| -> Option<(f64, f64)> {
        let (lines, orders) = (lines.as_ref()?, orders.as_ref()?);
        let rate = lines.rate(map, centre, search).ok()?;
        Some((rate, lines.grid_mean(orders, rate)?))
    };
    let at_tacho = fit(measured_hz, 0.005);
    let near_declared = fit(declared_hz, SLIP_LIMIT);
    // A tachometer counting k times the pulses puts the rate on every k-th line of the true
    // grid, which scores as well: then the lines only the slower grid makes decide.
    let doubled = |d: f64| {
        let k = (measured_hz / d).round();
        k >= 2.0
            && (measured_hz / (k * d) - 1.0).abs() < 0.01
            && match (&lines, &orders) {
                (Some(l), Some(o)) => in_between_stand_out(l, o, map, d, false, k),
                _ => false,
            }
    };
    let lines_win = match (at_tacho, near_declared) {
        (Some((_, t)), Some((d_hz, d))) => d >= t + MARGIN || doubled(d_hz),
        (None, Some(_)) => true,
        _ => false,
    };
    check.cause = Some(match near_declared.filter(|_| lines_win) {
        Some((lines_hz, _)) => {
            check.lines_shaft_hz = Some(lines_hz);
            check.ratio = lines_hz / declared_hz;
            let pulses = ppr as f64 * measured_hz / lines_hz;
            let likely = pulses.round();
            if likely >= 1.0 && (pulses / likely - 1.0).abs() <= 0.02 && likely as usize != ppr {
                Cause::PulsesPerRevolution {
                    declared: ppr,
                    likely: likely as usize,
                }
            } else {
                Cause::Speed
            }
        }
        None => {
            check.lines_shaft_hz = at_tacho.map(|t| t.0);
            Cause::SampleRate {
                declared_hz: fs,
                likely_hz: fs / r,
            }
        }
    });
    check
}

/// A record without a tachometer (`x`, rate `fs`, Hz); see the [module docs](self). `None`
/// when the lines cannot be read (rates not commensurate, no line under 0.45 × `fs`).
pub fn check_tacho_less(x: &[f64], fs: f64, map: &LineMap, declared_hz: f64) -> Option<SetupCheck> {
    let lines = LineProminence::of(x, fs).ok()?;
    let orders = grid_orders(map, 3.0)?;
    let fit = |c: f64| -> Option<(f64, f64)> {
        let search = if c == 1.0 { SLIP_LIMIT } else { SLIP };
        let rate = lines.rate(map, c * declared_hz, search).ok()?;
        Some((rate, lines.grid_mean(&orders, rate)?))
    };
    let (rate_1, score_1) = fit(1.0)?;
    let mut fits: Vec<(f64, f64, f64)> = vec![(1.0, rate_1, score_1)];
    fits.extend(
        FACTORS
            .iter()
            .filter_map(|&c| fit(c).map(|(rate, s)| (c, rate, s))),
    );
    // The best factor by the grid's mean prominence (another than 1 by [`MARGIN`]).
    let best = fits
        .iter()
        .copied()
        .filter(|f| f.0 == 1.0 || f.2 >= score_1 + MARGIN)
        .max_by(|a, b| a.2.total_cmp(&b.2))?;
    // Halving and doubling: a grid at twice the rate is every other line of the grid at the
    // rate, so the coarser grid of the strongest lines scores as well. Of the winner and its
    // partner at half or twice its factor, the slower wins when the lines only it makes near
    // the meshes stand out — the sidebands alone for the declared rate's grid, its own mesh
    // harmonics too for another (the burden of proof lies on a finding).
    let at = |c: f64| fits.iter().copied().find(|f| (f.0 - c).abs() < 1e-9);
    let best = match (at(best.0 / 2.0), at(best.0 * 2.0)) {
        (Some(slow), _)
            if in_between_stand_out(&lines, &orders, map, slow.1, slow.0 != 1.0, 2.0) =>
        {
            slow
        }
        (_, Some(fast))
            if fast.2 >= best.2
                && !in_between_stand_out(&lines, &orders, map, best.1, best.0 != 1.0, 2.0) =>
        {
            fast
        }
        _ => best,
    };
    let mut check = SetupCheck {
        declared_shaft_hz: declared_hz,
        lines_shaft_hz: Some(best.1),
        ratio: best.1 / declared_hz,
        cause: None,
    };
    if best.0 != 1.0 {
        check.cause = Some(Cause::SampleRate {
            declared_hz: fs,
            likely_hz: fs / best.0,
        });
    }
    Some(check)
}

/// Whether the grid at `rate_hz` is the record's rather than the grid at `multiple` (2: twice)
/// the rate (which holds every `multiple`-th of its lines): near the meshes (within 3 × the slowest shaft's order of a
/// mesh harmonic), the lines it adds stand [`MARGIN`] over the midpoints between its lines,
/// and so do its own mesh harmonics that the doubled grid lacks (a grid whose every mesh
/// harmonic is also a line of the doubled one is not told from it: `false`).
fn in_between_stand_out(
    lines: &LineProminence,
    orders: &[(f64, f64)],
    map: &LineMap,
    rate_hz: f64,
    meshes: bool,
    multiple: f64,
) -> bool {
    let slowest = map.shafts.iter().fold(1.0f64, |a, s| a.min(s.rate));
    let near_mesh = |o: f64| {
        map.meshes.iter().any(|&m| {
            let k = (o / m).round().max(1.0);
            (o - k * m).abs() <= 3.0 * slowest + 1e-9
        })
    };
    let freqs: Vec<f64> = orders
        .iter()
        .filter(|(o, _)| near_mesh(*o))
        .map(|(o, _)| o * rate_hz)
        .filter(|f| *f < lines.top_hz())
        .collect();
    let on_double = |f: f64| {
        orders
            .iter()
            .any(|(o, _)| (o * multiple * rate_hz - f).abs() < 0.5 * lines.resolution())
    };
    let mean = |v: &[f64]| (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64);
    let extra: Vec<f64> = freqs
        .iter()
        .filter(|f| !on_double(**f))
        .map(|&f| lines.at(f))
        .collect();
    let background: Vec<f64> = freqs
        .windows(2)
        .map(|w| lines.at(0.5 * (w[0] + w[1])))
        .collect();
    let own_meshes: Vec<f64> = mesh_harmonics(map, rate_hz, lines.top_hz(), 3)
        .filter(|f| !on_double(*f))
        .map(|f| lines.at(f))
        .collect();
    let (Some(e), Some(b)) = (mean(&extra), mean(&background)) else {
        return false;
    };
    e >= b + MARGIN && (!meshes || mean(&own_meshes).is_some_and(|m| m >= b + MARGIN))
}

/// The first `harmonics` harmonics of every mesh at the input-shaft rate `rate_hz`, under
/// `top_hz`.
fn mesh_harmonics(
    map: &LineMap,
    rate_hz: f64,
    top_hz: f64,
    harmonics: usize,
) -> impl Iterator<Item = f64> + '_ {
    map.meshes
        .iter()
        .flat_map(move |&m| (1..=harmonics).map(move |k| k as f64 * m * rate_hz))
        .filter(move |f| *f < top_hz)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::condition::test_util::spur;
    use crate::signal::test_util::lcg;
    use std::f64::consts::TAU;

    /// A spur train (32T→96T, 48T→80T: shafts 1, 1/3, 1/5) at 29.9 Hz: mesh lines with
    /// sidebands at every shaft's rate, shaft lines, noise.
    fn record(fs: f64, f: f64) -> (Vec<f64>, LineMap) {
        let n = (4.0 * fs) as usize;
        let noise = lcg(n, 11);
        let x = (0..n)
            .map(|i| {
                let th = TAU * f * i as f64 / fs;
                let mut v = (32.0 * th).sin() + 0.7 * (16.0 * th).sin() + 0.3 * (48.0 * th).sin();
                for j in 1..6 {
                    let j = j as f64;
                    for m in [16.0, 32.0] {
                        v += 0.05 / j * ((m + j / 3.0) * th).sin();
                        v += 0.04 / j * ((m - j / 5.0) * th).sin();
                    }
                    v += 0.03 / j * ((j / 3.0) * th).sin() + 0.03 / j * (j * th).sin();
                }
                v + 0.15 * noise[i]
            })
            .collect();
        (x, LineMap::of(&spur()))
    }

    #[test]
    fn a_tachometer_that_agrees_within_slip_raises_nothing() {
        let (x, map) = record(20_000.0, 29.9);
        let c = check_tachometer(&x, 20_000.0, &map, 30.0, 29.9, 10);
        assert_eq!(c.cause, None);
    }

    #[test]
    fn a_wrong_sample_rate_and_a_wrong_pulse_count_are_told_apart() {
        // Recorded at 20 kHz, declared 15 kHz: every line, the tachometer's rate too, at 3/4.
        let (x, map) = record(20_000.0, 29.9);
        let c = check_tachometer(&x, 15_000.0, &map, 30.0, 29.9 * 0.75, 10);
        match c.cause {
            Some(Cause::SampleRate { likely_hz, .. }) => {
                assert!((likely_hz / 20_000.0 - 1.0).abs() < 0.01, "{likely_hz}")
            }
            other => panic!("{other:?}"),
        }
        assert!(c.message().unwrap().contains("is the sample rate 200"));
        // A 10-pulse tachometer declared with 1 pulse: ten times the rate, lines where they were.
        let c = check_tachometer(&x, 20_000.0, &map, 30.0, 299.0, 1);
        assert_eq!(
            c.cause,
            Some(Cause::PulsesPerRevolution {
                declared: 1,
                likely: 10
            })
        );
    }

    #[test]
    fn without_a_tachometer_a_doubled_sample_rate_is_named_and_a_right_one_is_not() {
        let (x, map) = record(20_000.0, 29.9);
        let right = check_tacho_less(&x, 20_000.0, &map, 30.0).unwrap();
        assert_eq!(right.cause, None, "{right:?}");
        let (x, _) = record(10_000.0, 29.9);
        let doubled = check_tacho_less(&x, 20_000.0, &map, 30.0).unwrap();
        assert_eq!(
            doubled.cause,
            Some(Cause::SampleRate {
                declared_hz: 20_000.0,
                likely_hz: 10_000.0
            }),
            "{doubled:?}"
        );
    }
}
