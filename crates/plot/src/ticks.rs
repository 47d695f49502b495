//! Tick labels: decades on a log axis, the fewest exact decimals on a linear one.

/// Tick label for a log axis: `1e-3`, `0.01`, `10`, `1e4`.
pub(crate) fn log_tick(v: &f64) -> String {
    let v = *v;
    if v <= 0.0 || !v.is_finite() {
        return String::new();
    }
    let e = v.log10();
    if (e - e.round()).abs() > 1e-6 {
        return String::new(); // only label the decades
    }
    let e = e.round() as i32;
    if (-2..=3).contains(&e) {
        format!("{:.*}", (-e).max(0) as usize, 10f64.powi(e))
    } else {
        format!("1e{e}")
    }
}

/// Formatter for linear-axis ticks: the fewest decimals that represent every tick exactly
/// (`0`, `0.5`, `1.0`, … rather than `10.0`, `20.0`), scientific notation for very large or
/// very small magnitudes.
pub(crate) fn tick_formatter(ticks: &[f64]) -> impl Fn(&f64) -> String + use<> {
    let max_abs = ticks.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let sci = max_abs >= 1e5 || (max_abs > 0.0 && max_abs < 1e-3);
    let step = ticks
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .filter(|d| *d > 0.0)
        .fold(f64::INFINITY, f64::min);
    let tol = if step.is_finite() {
        step * 1e-6
    } else {
        max_abs.max(1e-300) * 1e-9
    };
    let decimals = (0..=10)
        .find(|&d| {
            ticks.iter().all(|v| {
                format!("{v:.d$}")
                    .parse::<f64>()
                    .is_ok_and(|p| (p - v).abs() <= tol)
            })
        })
        .unwrap_or(10);
    move |v: &f64| {
        let v = *v;
        let s = if sci {
            if v == 0.0 {
                "0".to_string()
            } else {
                // round away float noise, then shortest exponent form (2.5e-4, 1e6)
                let r: f64 = format!("{v:.6e}").parse().unwrap_or(v);
                format!("{r:e}")
            }
        } else {
            format!("{v:.decimals$}")
        };
        // "-0", "-0.00" → "0", "0.00"
        if s.starts_with('-') && s[1..].chars().all(|ch| ch == '0' || ch == '.') {
            s[1..].to_string()
        } else {
            s
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plot_tick_labels() {
        let f = tick_formatter(&[0.0, 10.0, 20.0, 30.0]);
        assert_eq!(f(&10.0), "10");
        let f = tick_formatter(&[0.0, 0.5, 1.0, 1.5]);
        assert_eq!(f(&1.0), "1.0");
        assert_eq!(f(&-0.0), "0.0");
        let f = tick_formatter(&[0.1, 0.2, 0.30000000000000004]);
        assert_eq!(f(&0.30000000000000004), "0.3");
        let f = tick_formatter(&[0.0, 2e-4, 4e-4]);
        assert_eq!(f(&2e-4), "2e-4");
        let f = tick_formatter(&[0.0, 5e5, 1e6]);
        assert_eq!(f(&1e6), "1e6");
        assert_eq!(log_tick(&1e-3), "1e-3");
        assert_eq!(log_tick(&0.01), "0.01");
        assert_eq!(log_tick(&100.0), "100");
        assert_eq!(log_tick(&2.0), "");
    }
}
