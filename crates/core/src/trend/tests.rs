use super::*;
use crate::signature::SplitMix64;

/// `n` points, 4 a day, on the line `level0 + slope·t` plus Gaussian noise of `sigma`.
fn line(n: usize, level0: f64, slope: f64, sigma: f64, seed: u64) -> Vec<Sample> {
    let mut rng = SplitMix64::new(seed);
    (0..n)
        .map(|i| {
            let t = i as f64 / 4.0;
            Sample {
                t_days: t,
                value: level0 + slope * t + sigma * rng.normal(),
            }
        })
        .collect()
}

#[test]
fn an_exact_line_gives_its_slope_level_and_crossing() {
    let pts = line(40, 0.2, 0.01, 0.0, 1);
    let t = fit(&pts, &TrendOptions::default()).unwrap();
    assert!((t.fit.slope_per_day - 0.01).abs() < 1e-12);
    // Latest point at t = 9.75 days: 0.2 + 0.0975.
    assert!((t.fit.level - 0.2975).abs() < 1e-12);
    assert!(t.fit.significant && t.fit.p_value < 1e-6);
    // Alarm at 0.8: (0.8 − 0.2975) / 0.01 = 50.25 days.
    let c = t.crossing(0.8).unwrap();
    assert!((c.days - 50.25).abs() < 1e-9, "{c:?}");
    assert!((c.interval_90[0].unwrap() - 50.25).abs() < 1e-9);
    assert!((c.interval_90[1].unwrap() - 50.25).abs() < 1e-9);
}

#[test]
fn the_slope_is_recovered_from_noise_within_its_interval() {
    let mut covered = 0;
    for seed in 100..140 {
        let pts = line(40, 0.2, 0.01, 0.02, seed);
        let t = fit(&pts, &TrendOptions::default()).unwrap();
        let [lo, hi] = t.fit.slope_interval_90;
        assert!((t.fit.slope_per_day - 0.01).abs() < 0.004, "{:?}", t.fit);
        covered += usize::from(lo <= 0.01 && 0.01 <= hi);
        assert!(t.fit.significant);
    }
    // A 90 % interval: about 36 of 40; a wrong one would cover far fewer.
    assert!(covered >= 30, "covered {covered} of 40");
}

#[test]
fn outliers_do_not_move_the_slope() {
    let mut pts = line(40, 0.2, 0.01, 0.005, 7);
    // A fifth of the points wild (a record the model misread): least squares would tilt.
    for i in (0..40).step_by(5) {
        pts[i].value = if i < 20 { 3.0 } else { -2.0 };
    }
    let t = fit(&pts, &TrendOptions::default()).unwrap();
    assert!(
        (t.fit.slope_per_day - 0.01).abs() < 0.002,
        "slope {}",
        t.fit.slope_per_day
    );
    assert!((t.fit.level - 0.2975).abs() < 0.02, "level {}", t.fit.level);
}

#[test]
fn flat_noise_is_no_significant_trend() {
    let mut trends = 0;
    for seed in 0..100 {
        let pts = line(40, 0.3, 0.0, 0.02, 1000 + seed);
        let t = fit(&pts, &TrendOptions::default()).unwrap();
        if t.fit.significant {
            trends += 1;
        } else {
            assert!(t.crossing(0.8).is_none());
            assert_eq!(verdict(Some(&t), &[("alarm", 0.8)]), "no significant trend");
        }
    }
    // α = 5 %: about 5 of 100.
    assert!(trends <= 12, "{trends} of 100 flat series called a trend");
}

#[test]
fn a_crossed_threshold_is_zero_days_and_a_falling_line_never_crosses() {
    let up = fit(&line(20, 0.9, 0.01, 0.0, 1), &TrendOptions::default()).unwrap();
    assert_eq!(up.crossing(0.8).unwrap().days, 0.0);
    assert_eq!(
        verdict(Some(&up), &[("warning", 0.5), ("alarm", 0.8)]),
        "above alarm"
    );
    let down = fit(&line(20, 0.4, -0.01, 0.0, 1), &TrendOptions::default()).unwrap();
    assert!(down.fit.significant && down.crossing(0.8).is_none());
    assert_eq!(
        verdict(Some(&down), &[("alarm", 0.8)]),
        "falling 0.010 per day"
    );
}

#[test]
fn the_order_of_the_points_does_not_matter_and_the_fit_is_deterministic() {
    let pts = line(40, 0.2, 0.01, 0.02, 3);
    let mut shuffled = pts.clone();
    shuffled.reverse();
    shuffled.swap(3, 17);
    let (a, b) = (
        fit(&pts, &TrendOptions::default()).unwrap(),
        fit(&shuffled, &TrendOptions::default()).unwrap(),
    );
    assert_eq!(a.fit, b.fit);
    assert_eq!(a.crossing(0.8), b.crossing(0.8));
}

#[test]
fn the_verdict_names_both_thresholds() {
    let t = fit(&line(40, 0.2, 0.01, 0.0, 1), &TrendOptions::default()).unwrap();
    assert_eq!(
        verdict(Some(&t), &[("warning", 0.5), ("alarm", 0.8)]),
        "warning in 20 days (90 % interval 20–20); alarm in 50 days (90 % interval 50–50)"
    );
    assert_eq!(verdict(None, &[("alarm", 0.8)]), "no significant trend");
}

#[test]
fn erfc_matches_known_values() {
    assert!((erfc(0.0) - 1.0).abs() < 1e-6);
    assert!((erfc(1.0) - 0.157_299_207).abs() < 1e-6);
    // p = 0.05 two-sided at z = 1.959964.
    assert!((erfc(1.959_964 / std::f64::consts::SQRT_2) - 0.05).abs() < 1e-6);
}

#[test]
fn a_long_series_resamples_random_pairs_and_still_covers_its_slope() {
    // 200 points (19 900 pairs): the bootstrap uses random pairs.
    let pts = line(200, 0.2, 0.004, 0.02, 11);
    let t = fit(&pts, &TrendOptions::default()).unwrap();
    let [lo, hi] = t.fit.slope_interval_90;
    assert!(lo < 0.004 && 0.004 < hi, "{:?}", t.fit);
    assert!(hi - lo < 0.002, "{:?}", t.fit);
    assert!(t.fit.significant);
}
