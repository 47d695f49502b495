use std::f64::consts::PI;

use super::zero_one::oversampling_step;
use super::*;

const GOLDEN: f64 = 0.618_033_988_749_894_8; // (√5 − 1)/2

fn logistic_points(r: f64, n: usize) -> Vec<(f64, f64)> {
    let mut x = 0.123_456_7;
    for _ in 0..1000 {
        x = r * x * (1.0 - x);
    }
    let mut pts = Vec::with_capacity(n);
    for _ in 0..n {
        let next = r * x * (1.0 - x);
        pts.push((x, next));
        x = next;
    }
    pts
}

fn circle_points(alpha: f64, n: usize) -> Vec<(f64, f64)> {
    (0..n)
        .map(|k| {
            let a = 2.0 * PI * k as f64 * alpha;
            (a.cos(), a.sin())
        })
        .collect()
}

/// Fixed-step RK4 for the tests' `advance` closures.
fn rk4<const D: usize>(
    f: impl Fn(&[f64; D]) -> [f64; D],
    state: &mut [f64],
    duration: f64,
    h_max: f64,
) {
    let steps = (duration / h_max).ceil().max(1.0) as usize;
    let h = duration / steps as f64;
    let mut y = [0.0; D];
    y.copy_from_slice(state);
    let add = |a: &[f64; D], b: &[f64; D], s: f64| {
        let mut r = *a;
        r.iter_mut().zip(b).for_each(|(ri, bi)| *ri += s * bi);
        r
    };
    for _ in 0..steps {
        let k1 = f(&y);
        let k2 = f(&add(&y, &k1, 0.5 * h));
        let k3 = f(&add(&y, &k2, 0.5 * h));
        let k4 = f(&add(&y, &k3, h));
        for i in 0..D {
            y[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
    }
    state.copy_from_slice(&y);
}

#[test]
fn motion_labels_and_serde() {
    assert_eq!(MotionState::Periodic { period: 1 }.label(), "period-1");
    assert_eq!(MotionState::Periodic { period: 3 }.to_string(), "period-3");
    assert_eq!(MotionState::QuasiPeriodic.label(), "quasi-periodic");
    assert_eq!(MotionState::Chaotic.to_string(), "chaotic");
    let json = serde_json::to_string(&MotionState::Periodic { period: 2 }).unwrap();
    assert_eq!(json, r#"{"kind":"periodic","period":2}"#);
    let back: MotionState = serde_json::from_str(r#"{"kind":"quasi-periodic"}"#).unwrap();
    assert_eq!(back, MotionState::QuasiPeriodic);
    let o: ClassifyOptions = serde_json::from_str(r#"{"max_period": 4}"#).unwrap();
    assert_eq!((o.rel_tol, o.max_period, o.chaos_threshold), (0.02, 4, 0.5));
}

#[test]
fn motion_linear_oscillator_steady_state_is_period1() {
    // x'' + 2ζx' + x = F cos(ωt), steady state sampled once per forcing period, with a
    // little round-off-sized jitter.
    let (zeta, w, f) = (0.05, 1.3_f64, 1.0);
    let (a, b) = (1.0 - w * w, 2.0 * zeta * w);
    let amp = f / a.hypot(b);
    let phase = b.atan2(a);
    let period = 2.0 * PI / w;
    let t0 = 0.37;
    let pts: Vec<(f64, f64)> = (0..200)
        .map(|k| {
            let t = t0 + k as f64 * period;
            (
                amp * (w * t - phase).cos(),
                -amp * w * (w * t - phase).sin(),
            )
        })
        .collect();
    let scale = (2.0 * amp, 2.0 * amp * w);
    let c = classify(&pts, scale, &ClassifyOptions::default()).unwrap();
    assert_eq!(c.state, MotionState::Periodic { period: 1 });
    assert_eq!(c.clusters, 1);
    assert!(c.spread < 1e-9, "spread {}", c.spread);
}

#[test]
fn motion_period1_with_small_drift_stays_period1() {
    let n = 300;
    let pts: Vec<(f64, f64)> = (0..n)
        .map(|k| {
            let s = 0.005 * k as f64 / (n - 1) as f64;
            (0.3 + s, -0.2 + 0.5 * s)
        })
        .collect();
    let c = classify(&pts, (1.0, 1.0), &ClassifyOptions::default()).unwrap();
    assert_eq!(c.state, MotionState::Periodic { period: 1 });
    // …but a drift of 10 % of the scale is not a fixed point.
    let big: Vec<(f64, f64)> = pts.iter().map(|p| (p.0 * 20.0, p.1)).collect();
    let c = classify(&big, (1.0, 1.0), &ClassifyOptions::default()).unwrap();
    assert_ne!(c.state, MotionState::Periodic { period: 1 });
}

#[test]
fn motion_logistic_period_doubling_cascade() {
    let opts = ClassifyOptions::default();
    let scale = (1.0, 1.0);
    let c2 = classify(&logistic_points(3.2, 400), scale, &opts).unwrap();
    assert_eq!(c2.state, MotionState::Periodic { period: 2 });
    assert_eq!(c2.clusters, 2);
    let c4 = classify(&logistic_points(3.5, 400), scale, &opts).unwrap();
    assert_eq!(c4.state, MotionState::Periodic { period: 4 });
    assert_eq!(c4.clusters, 4);
    let cc = classify(&logistic_points(4.0, 1000), scale, &opts).unwrap();
    assert_eq!(cc.state, MotionState::Chaotic);
    assert!(cc.k_01.unwrap() > 0.8);
    assert_eq!(
        detect_period(&logistic_points(3.5, 400), scale, 0.02, 8),
        Some(4)
    );
    assert_eq!(
        detect_period(&logistic_points(3.5, 400), scale, 0.02, 3),
        None
    );
    assert_eq!(
        detect_period(&logistic_points(4.0, 400), scale, 0.02, 8),
        None
    );
}

#[test]
fn motion_circle_rotation_is_quasi_periodic() {
    let pts = circle_points(GOLDEN, 1000);
    let c = classify(&pts, (2.0, 2.0), &ClassifyOptions::default()).unwrap();
    assert_eq!(c.state, MotionState::QuasiPeriodic);
    assert!(c.k_01.unwrap().abs() < 0.2);
    assert!(c.clusters > 8);
    // A slow rotation: consecutive points are close (the pair criterion alone says
    // period-1), but the set does not return: not periodic.
    let slow = circle_points(0.002 * GOLDEN, 1000);
    assert_eq!(detect_period(&slow, (2.0, 2.0), 0.02, 8), Some(1));
    let c = classify(&slow, (2.0, 2.0), &ClassifyOptions::default()).unwrap();
    assert_eq!(c.state, MotionState::QuasiPeriodic);
}

#[test]
fn motion_geometric_fallback_for_short_sections() {
    let opts = ClassifyOptions::default();
    let c = classify(&logistic_points(4.0, 40), (1.0, 1.0), &opts).unwrap();
    assert_eq!(c.state, MotionState::Chaotic);
    assert!(c.k_01.is_none());
    let c = classify(&circle_points(GOLDEN, 40), (2.0, 2.0), &opts).unwrap();
    assert_eq!(c.state, MotionState::QuasiPeriodic);
    let c = classify(&logistic_points(4.0, 100), (1.0, 1.0), &opts).unwrap();
    assert_eq!(c.state, MotionState::Chaotic);
    // A quasi-periodic closed curve with harmonics, 150 points (delay-embedded): the 0–1
    // test alone says chaotic (resonances at ω, 2ω, 3ω), the geometric criterion vetoes.
    let f = |k: usize| {
        let t = 2.0 * PI * GOLDEN * k as f64;
        t.cos() + 0.4 * (2.0 * t).cos() + 0.2 * (3.0 * t).sin()
    };
    let curve: Vec<(f64, f64)> = (0..150).map(|k| (f(k), f(k + 1))).collect();
    let c = classify(&curve, (3.0, 3.0), &opts).unwrap();
    assert!(c.k_01.unwrap() > 0.5, "K = {:?}", c.k_01);
    assert_eq!(c.state, MotionState::QuasiPeriodic);
}

#[test]
fn motion_zero_one_test_reference_signals() {
    let chaotic: Vec<f64> = logistic_points(4.0, 2000).iter().map(|p| p.0).collect();
    let k = zero_one_test(&chaotic).unwrap();
    assert!(k > 0.8, "logistic r=4: K = {k}");

    let quasi: Vec<f64> = (0..2000)
        .map(|n| {
            let n = n as f64;
            (2.0 * PI * GOLDEN * n).cos() + 0.5 * (2.0_f64.sqrt() * n).sin()
        })
        .collect();
    let k = zero_one_test(&quasi).unwrap();
    assert!(k.abs() < 0.2, "quasi-periodic: K = {k}");

    let periodic: Vec<f64> = logistic_points(3.5, 2000).iter().map(|p| p.0).collect();
    let k = zero_one_test(&periodic).unwrap();
    assert!(k.abs() < 0.2, "period-4: K = {k}");

    assert_eq!(zero_one_test(&[1.5; 100]).unwrap(), 0.0);
    assert!(zero_one_test(&chaotic[..49]).is_err());
    let mut bad = chaotic.clone();
    bad[7] = f64::NAN;
    assert!(zero_one_test(&bad).is_err());
}

#[test]
fn motion_zero_one_test_oversampled_flow() {
    // Lorenz x(t) sampled every 0.01 (≈ 60 samples per oscillation): without the guard the
    // 0–1 test sees smooth, regular-looking data on the scale N/10.
    let lorenz = |s: &[f64; 3]| {
        [
            10.0 * (s[1] - s[0]),
            s[0] * (28.0 - s[2]) - s[1],
            s[0] * s[1] - 8.0 / 3.0 * s[2],
        ]
    };
    let mut s = [1.0, 1.0, 20.0];
    rk4(lorenz, &mut s, 20.0, 0.01);
    let xs: Vec<f64> = (0..40_000)
        .map(|_| {
            rk4(lorenz, &mut s, 0.01, 0.01);
            s[0]
        })
        .collect();
    assert!(oversampling_step(&xs) > 1);
    let k = zero_one_test(&xs).unwrap();
    assert!(k > 0.8, "oversampled Lorenz: K = {k}");
}

#[test]
fn motion_lyapunov_damped_oscillator() {
    // x'' + 2ζx' + x = 0: eigenvalues −ζ ± i√(1−ζ²), so λ = −ζ.
    let zeta = 0.1;
    let f = move |s: &[f64; 2]| [s[1], -2.0 * zeta * s[1] - s[0]];
    let lam = largest_lyapunov(&[1.0, 0.0], 1e-6, 1.0, 2000, 0, |s, dt| {
        rk4(f, s, dt, 0.01);
        Ok(())
    })
    .unwrap();
    assert!((lam + zeta).abs() < 0.005, "λ = {lam}");
}

#[test]
fn motion_lyapunov_lorenz() {
    let f = |s: &[f64; 3]| {
        [
            10.0 * (s[1] - s[0]),
            s[0] * (28.0 - s[2]) - s[1],
            s[0] * s[1] - 8.0 / 3.0 * s[2],
        ]
    };
    let lam = largest_lyapunov(&[1.0, 1.0, 20.0], 1e-8, 0.5, 2000, 40, |s, dt| {
        rk4(f, s, dt, 0.005);
        Ok(())
    })
    .unwrap();
    assert!((lam - 0.906).abs() < 0.15 * 0.906, "λ = {lam}");
}

#[test]
fn motion_degenerate_input_is_an_error() {
    let opts = ClassifyOptions::default();
    let pts = logistic_points(3.2, 100);
    assert!(classify(&[], (1.0, 1.0), &opts).is_err());
    assert!(classify(&pts[..1], (1.0, 1.0), &opts).is_err());
    assert!(classify(&pts, (0.0, 1.0), &opts).is_err());
    assert!(classify(&pts, (1.0, f64::NAN), &opts).is_err());
    let mut nan = pts.clone();
    nan[3].1 = f64::NAN;
    assert!(classify(&nan, (1.0, 1.0), &opts).is_err());
    let bad_opts = ClassifyOptions {
        rel_tol: -1.0,
        ..opts
    };
    assert!(classify(&pts, (1.0, 1.0), &bad_opts).is_err());
    assert_eq!(detect_period(&pts, (0.0, 1.0), 0.02, 8), None);
    assert_eq!(detect_period(&[], (1.0, 1.0), 0.02, 8), None);
    let ok = |_: &mut [f64], _: f64| Ok(());
    assert!(largest_lyapunov(&[], 1e-8, 1.0, 10, 0, ok).is_err());
    assert!(largest_lyapunov(&[1.0], 0.0, 1.0, 10, 0, ok).is_err());
    assert!(largest_lyapunov(&[1.0], 1e-8, 1.0, 0, 0, ok).is_err());
    // A map that collapses everything onto one point: separation becomes zero.
    let collapse = |s: &mut [f64], _: f64| {
        s.iter_mut().for_each(|v| *v = 0.0);
        Ok(())
    };
    assert!(largest_lyapunov(&[1.0, 2.0], 1e-8, 1.0, 10, 0, collapse).is_err());
    // Errors of the integrator propagate.
    let fail = |_: &mut [f64], t: f64| Err(Error::NonFinite { t });
    assert!(largest_lyapunov(&[1.0], 1e-8, 1.0, 10, 0, fail).is_err());
}

#[test]
fn forced_classifier_sees_modulated_period_1_and_period_2() {
    use std::f64::consts::TAU;
    let r = [0.36, 0.0875];
    let scale = (1.0, 1.0);
    // Period-1 locked to three forcings: a smooth function of the other phases.
    let p1: Vec<(f64, f64)> = (0..80)
        .map(|k| {
            let (a, b) = ((0.36 * k as f64).fract(), (0.0875 * k as f64).fract());
            let x = 1.0 + 0.1 * (TAU * a).sin() + 0.03 * (TAU * b).cos();
            (x, 0.2 * (TAU * a).cos())
        })
        .collect();
    let c = classify_forced(&p1, scale, -0.1, &r, &ClassifyOptions::default()).unwrap();
    assert_eq!(c.state, MotionState::Periodic { period: 1 });
    // The plain geometric test calls the same set non-periodic.
    assert_ne!(
        classify(&p1, scale, &ClassifyOptions::default())
            .unwrap()
            .state,
        MotionState::Periodic { period: 1 }
    );
    // Period-2: alternate branches.
    let p2: Vec<(f64, f64)> = p1
        .iter()
        .enumerate()
        .map(|(k, &(x, v))| {
            if k % 2 == 0 {
                (x + 0.5, v)
            } else {
                (x - 0.5, v)
            }
        })
        .collect();
    let c = classify_forced(&p2, scale, -0.1, &r, &ClassifyOptions::default()).unwrap();
    assert_eq!(c.state, MotionState::Periodic { period: 2 });
    // A frequency of its own (a torus): quasi-periodic.
    let alpha = (5f64.sqrt() - 1.0) / 2.0;
    let q: Vec<(f64, f64)> = (0..80)
        .map(|k| {
            (
                (TAU * alpha * k as f64).cos(),
                (TAU * alpha * k as f64).sin(),
            )
        })
        .collect();
    let c = classify_forced(&q, scale, -0.001, &r, &ClassifyOptions::default()).unwrap();
    assert_eq!(c.state, MotionState::QuasiPeriodic);
    // A positive exponent is chaos whatever the geometry.
    let c = classify_forced(&p1, scale, 0.5, &r, &ClassifyOptions::default()).unwrap();
    assert_eq!(c.state, MotionState::Chaotic);
}
