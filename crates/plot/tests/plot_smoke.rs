//! Smoke tests of the plot module: every function writes a PNG and an SVG that decode to the
//! requested size / contain the title text; error cases are refused without panicking.

use std::f64::consts::PI;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use gearwear_core::Error;
use gearwear_plot::{self as plot, Panel, Series};

/// A fresh directory under the system temp dir (kept, so figures can be inspected).
fn out_dir(name: &str) -> PathBuf {
    static N: AtomicUsize = AtomicUsize::new(0);
    let d = std::env::temp_dir().join(format!(
        "gearwear_plot_smoke_{}_{}_{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed),
        name
    ));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// Width and height from the PNG IHDR chunk.
fn png_size(path: &Path) -> (u32, u32) {
    let b = std::fs::read(path).unwrap();
    assert!(b.len() > 33, "PNG too short");
    assert_eq!(&b[..8], b"\x89PNG\r\n\x1a\n", "PNG signature");
    assert_eq!(&b[12..16], b"IHDR");
    let w = u32::from_be_bytes(b[16..20].try_into().unwrap());
    let h = u32::from_be_bytes(b[20..24].try_into().unwrap());
    (w, h)
}

fn check_png(path: &Path, size: (u32, u32)) {
    assert!(path.exists(), "{} missing", path.display());
    assert_eq!(png_size(path), size, "{}", path.display());
}

fn check_svg(path: &Path, title: &str) {
    let s = std::fs::read_to_string(path).unwrap();
    assert!(s.contains("<svg"), "{} is not SVG", path.display());
    assert!(
        s.contains(title),
        "{} lacks the title {title:?}",
        path.display()
    );
}

/// Run `f` for a PNG and an SVG in a fresh (nested, not yet existing) directory.
fn both(name: &str, title: &str, size: (u32, u32), f: impl Fn(&Path) -> gearwear_core::Result<()>) {
    let d = out_dir(name).join("nested");
    let png = d.join(format!("{name}.png"));
    let svg = d.join(format!("{name}.svg"));
    f(&png).unwrap();
    f(&svg).unwrap();
    check_png(&png, size);
    check_svg(&svg, title);
    cleanup(&d);
}

/// Remove a test's output unless `GEARWEAR_KEEP_PLOTS` is set (to look at the figures).
fn cleanup(d: &Path) {
    if std::env::var_os("GEARWEAR_KEEP_PLOTS").is_none()
        && let Some(parent) = d.parent()
    {
        let _ = std::fs::remove_dir_all(parent);
    }
}

fn expect_plot_err(r: gearwear_core::Result<()>, needle: &str) {
    match r {
        Err(Error::Plot { reason, .. }) => {
            assert!(
                reason.contains(needle),
                "reason {reason:?} lacks {needle:?}"
            )
        }
        other => panic!("expected Error::Plot({needle}), got {other:?}"),
    }
}

fn signal(n: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let t: Vec<f64> = (0..n).map(|i| i as f64 * 0.01).collect();
    let x: Vec<f64> = t
        .iter()
        .map(|&t| (2.0 * PI * t).sin() + 0.3 * (2.0 * PI * 0.36 * t).sin())
        .collect();
    let v: Vec<f64> = t
        .iter()
        .map(|&t| {
            2.0 * PI * (2.0 * PI * t).cos() + 0.3 * 2.0 * PI * 0.36 * (2.0 * PI * 0.36 * t).cos()
        })
        .collect();
    (t, x, v)
}

const MARKERS: [(&str, f64); 6] = [
    ("f1", 1.0),
    ("f2", 0.36),
    ("2f2", 0.72),
    ("f3", 0.0875),
    ("f1/2", 0.5),
    ("f1-f2", 0.64),
];

fn spectrum_data() -> (Vec<f64>, Vec<f64>) {
    let f: Vec<f64> = (0..2000).map(|i| i as f64 * 0.0015).collect();
    let peak = |f: f64, c: f64, a: f64| a * (-((f - c) / 0.004).powi(2)).exp();
    let a: Vec<f64> = f
        .iter()
        .map(|&f| {
            1e-5 + peak(f, 1.0, 1.0)
                + peak(f, 0.36, 0.3)
                + peak(f, 0.72, 0.05)
                + peak(f, 0.64, 0.02)
                + peak(f, 2.0, 0.1)
        })
        .collect();
    (f, a)
}

#[test]
fn plot_lines() {
    let (t, x, v) = signal(3000);
    let mut x_nan = x.clone();
    x_nan[100] = f64::NAN;
    x_nan[200] = f64::INFINITY;
    both("lines", "Time history", plot::DEFAULT_SIZE, |p| {
        plot::lines(
            p,
            "Time history",
            "τ",
            "response",
            &[
                Series {
                    label: "x (with gaps)",
                    x: &t,
                    y: &x_nan,
                },
                Series {
                    label: "v / 2π",
                    x: &t,
                    y: &v.iter().map(|v| v / (2.0 * PI)).collect::<Vec<_>>(),
                },
            ],
        )
    });
    // a single constant series: zero range handled
    both("lines_const", "Constant", plot::DEFAULT_SIZE, |p| {
        plot::lines(
            p,
            "Constant",
            "t",
            "y",
            &[Series {
                label: "c",
                x: &t,
                y: &vec![3.0; t.len()],
            }],
        )
    });
    // a single point
    both("lines_point", "One point", plot::DEFAULT_SIZE, |p| {
        plot::lines(
            p,
            "One point",
            "t",
            "y",
            &[Series {
                label: "c",
                x: &[1.0],
                y: &[0.0],
            }],
        )
    });
}

#[test]
fn plot_phase_portrait() {
    let (_, x, v) = signal(5000);
    let px: Vec<f64> = x.iter().step_by(100).copied().collect();
    let pv: Vec<f64> = v.iter().step_by(100).copied().collect();
    both("phase", "Phase portrait", plot::DEFAULT_SIZE, |p| {
        plot::phase_portrait(p, "Phase portrait", &x, &v, Some((&px, &pv)))
    });
    both("phase_plain", "Phase only", plot::DEFAULT_SIZE, |p| {
        plot::phase_portrait(p, "Phase only", &x, &v, None)
    });
}

#[test]
fn plot_scatter() {
    let x: Vec<f64> = (0..300).map(|i| (i as f64 * 0.7).sin()).collect();
    let y: Vec<f64> = (0..300).map(|i| (i as f64 * 1.3).cos()).collect();
    both("scatter", "Poincare section", plot::DEFAULT_SIZE, |p| {
        plot::scatter(p, "Poincare section", "x", "v", &x, &y)
    });
}

#[test]
fn plot_spectrum() {
    let (f, a) = spectrum_data();
    both("spectrum_lin", "Spectrum", plot::DEFAULT_SIZE, |p| {
        plot::spectrum(p, "Spectrum", &f, &a, &MARKERS, 1.5, false)
    });
    both("spectrum_log", "Log spectrum", plot::DEFAULT_SIZE, |p| {
        plot::spectrum(p, "Log spectrum", &f, &a, &MARKERS, 2.5, true)
    });
    // zeros on a log axis must not panic
    let zeros = vec![0.0; f.len()];
    both("spectrum_zero", "Zero spectrum", plot::DEFAULT_SIZE, |p| {
        plot::spectrum(p, "Zero spectrum", &f, &zeros, &MARKERS, 2.0, true)
    });
    let d = out_dir("spectrum_bad");
    expect_plot_err(
        plot::spectrum(&d.join("s.png"), "S", &f, &a, &MARKERS, f64::NAN, false),
        "x_max",
    );
}

#[test]
fn plot_bifurcation() {
    // logistic map: 500 parameters × 80 samples
    let mut param = Vec::new();
    let mut value = Vec::new();
    for i in 0..500 {
        let r = 2.8 + 1.2 * i as f64 / 499.0;
        let mut x = 0.5;
        for _ in 0..300 {
            x = r * x * (1.0 - x);
        }
        for _ in 0..80 {
            x = r * x * (1.0 - x);
            param.push(r);
            value.push(x);
        }
    }
    assert_eq!(param.len(), 40_000);
    let t0 = std::time::Instant::now();
    both(
        "bifurcation",
        "Bifurcation diagram",
        plot::DEFAULT_SIZE,
        |p| {
            plot::bifurcation(
                p,
                "Bifurcation diagram",
                "Ω1",
                "x (Poincaré)",
                &param,
                &value,
            )
        },
    );
    assert!(
        t0.elapsed().as_secs_f64() < 20.0,
        "bifurcation too slow: {:?}",
        t0.elapsed()
    );
}

#[test]
fn plot_panels() {
    let (t, x, v) = signal(4000);
    let px: Vec<f64> = x.iter().step_by(100).copied().collect();
    let pv: Vec<f64> = v.iter().step_by(100).copied().collect();
    let (f, a) = spectrum_data();
    let make = || {
        vec![
            Panel {
                title: "Time history",
                x_label: "τ",
                y_label: "x",
                series: vec![Series {
                    label: "x",
                    x: &t,
                    y: &x,
                }],
                dots: false,
                log_y: false,
                markers: vec![],
            },
            Panel {
                title: "Phase portrait",
                x_label: "x",
                y_label: "ẋ",
                series: vec![Series {
                    label: "x",
                    x: &x,
                    y: &v,
                }],
                dots: false,
                log_y: false,
                markers: vec![],
            },
            Panel {
                title: "Poincaré section",
                x_label: "x",
                y_label: "ẋ",
                series: vec![Series {
                    label: "P",
                    x: &px,
                    y: &pv,
                }],
                dots: true,
                log_y: false,
                markers: vec![],
            },
            Panel {
                title: "Spectrum",
                x_label: "f / f1",
                y_label: "amplitude",
                series: vec![Series {
                    label: "A",
                    x: &f,
                    y: &a,
                }],
                dots: false,
                log_y: true,
                markers: MARKERS.to_vec(),
            },
        ]
    };
    let ps = make();
    both("panels", "Run overview", (1280, 890), |p| {
        plot::panels(p, "Run overview", 2, 2, &ps)
    });
    // fewer panels than cells is fine
    both("panels_partial", "Partial", (1920, 600), |p| {
        plot::panels(p, "Partial", 1, 3, &ps[..2])
    });
    let d = out_dir("panels_bad");
    expect_plot_err(plot::panels(&d.join("a.png"), "T", 1, 2, &ps), "do not fit");
    expect_plot_err(plot::panels(&d.join("a.png"), "T", 0, 2, &ps[..1]), "grid");
    expect_plot_err(plot::panels(&d.join("a.png"), "T", 1, 1, &[]), "no panels");
    let mut bad = make();
    bad[2].series[0].y = &[];
    expect_plot_err(
        plot::panels(&d.join("a.png"), "T", 2, 2, &bad),
        "no finite data",
    );
}

#[test]
fn plot_band() {
    let x: Vec<f64> = (0..60).map(|i| i as f64).collect();
    let mid: Vec<f64> = x.iter().map(|&x| 0.1 + 0.002 * x * x / 10.0).collect();
    let lower: Vec<f64> = mid
        .iter()
        .zip(&x)
        .map(|(m, x)| m - 0.02 - 0.001 * x)
        .collect();
    let upper: Vec<f64> = mid
        .iter()
        .zip(&x)
        .map(|(m, x)| m + 0.02 + 0.001 * x)
        .collect();
    let mut upper_gap = upper.clone();
    upper_gap[30] = f64::NAN;
    both("band", "Wear trend", plot::DEFAULT_SIZE, |p| {
        plot::band(
            p,
            "Wear trend",
            "operating hours / 100",
            "wear depth (mm)",
            &x,
            &mid,
            &lower,
            &upper_gap,
            &[("alert", 0.6), ("alarm", 0.8)],
        )
    });
}

#[test]
fn plot_errors() {
    let d = out_dir("errors");
    let x = [0.0, 1.0, 2.0];
    let y = [1.0, 2.0, 3.0];
    let nan = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY];
    let s = |y: &'static [f64]| {
        vec![Series {
            label: "s",
            x: &[0.0, 1.0, 2.0],
            y,
        }]
    };

    // unknown or missing extension
    for name in ["a.jpg", "a", "a.pdf"] {
        expect_plot_err(
            plot::scatter(&d.join(name), "T", "x", "y", &x, &y),
            "unsupported output format",
        );
    }
    // all-NaN and empty data, every function
    for ext in ["png", "svg"] {
        let p = d.join(format!("e.{ext}"));
        expect_plot_err(
            plot::lines(&p, "T", "x", "y", &s(&[f64::NAN; 3])),
            "no finite data",
        );
        expect_plot_err(plot::lines(&p, "T", "x", "y", &[]), "no finite data");
        expect_plot_err(plot::lines(&p, "T", "x", "y", &s(&[])), "no finite data");
        expect_plot_err(
            plot::phase_portrait(&p, "T", &nan, &y, None),
            "no finite data",
        );
        expect_plot_err(
            plot::phase_portrait(&p, "T", &[], &[], None),
            "no finite data",
        );
        expect_plot_err(plot::scatter(&p, "T", "x", "y", &x, &nan), "no finite data");
        expect_plot_err(plot::scatter(&p, "T", "x", "y", &[], &[]), "no finite data");
        expect_plot_err(
            plot::spectrum(&p, "T", &x, &nan, &MARKERS, 2.0, true),
            "no finite data",
        );
        expect_plot_err(
            plot::spectrum(&p, "T", &[], &[], &[], 2.0, false),
            "no finite data",
        );
        expect_plot_err(
            plot::bifurcation(&p, "T", "x", "y", &nan, &y),
            "no finite data",
        );
        expect_plot_err(
            plot::bifurcation(&p, "T", "x", "y", &[], &[]),
            "no finite data",
        );
        expect_plot_err(
            plot::band(&p, "T", "x", "y", &x, &nan, &nan, &nan, &[]),
            "no finite data",
        );
        expect_plot_err(
            plot::band(&p, "T", "x", "y", &[], &[], &[], &[], &[("a", 1.0)]),
            "no finite data",
        );
        assert!(!p.exists(), "no file is written on error");
    }
}
