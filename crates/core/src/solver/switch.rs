//! Location of the first switch in a step, shared by the integrators.

/// The earliest root, as a fraction θ ∈ (0, 1] of a step, of the switching functions whose
/// values at θ = 0, ½, 1 are `g0`, `gm`, `g1`. A function is bracketed in the first half if it
/// changes sign there, else in the second half (the midpoint catches an in-and-out crossing),
/// and refined with the Illinois method on `eval(i, θ)` (the `i`-th switching function on the
/// step's dense output) until the bracket, times the step `h`, is narrower than `time_tol`. The returned θ is the
/// bracket's far end, just past the root, so a step shortened to it ends on the new side.
/// Roots at or before `theta_min` are ignored.
pub(crate) fn first_root(
    g0: &[f64],
    gm: &[f64],
    g1: &[f64],
    theta_min: f64,
    h: f64,
    time_tol: f64,
    mut eval: impl FnMut(usize, f64) -> f64,
) -> Option<f64> {
    let mut best: Option<f64> = None;
    for i in 0..g0.len() {
        let (g0, gm, g1) = (g0[i], gm[i], g1[i]);
        let bracket = if g0 != 0.0 && (g0 > 0.0) != (gm > 0.0) {
            Some((0.0, g0, 0.5, gm))
        } else if gm != 0.0 && g1 != 0.0 && (gm > 0.0) != (g1 > 0.0) {
            Some((0.5, gm, 1.0, g1))
        } else {
            None
        };
        let Some((mut a, mut ga, mut b, mut gb)) = bracket else {
            continue;
        };
        if best.is_some_and(|bst| a >= bst) {
            continue;
        }
        let mut side = 0i8;
        for _ in 0..60 {
            let c = (a * gb - b * ga) / (gb - ga);
            let c = if c.is_finite() && c > a && c < b {
                c
            } else {
                0.5 * (a + b)
            };
            let gc = eval(i, c);
            if (gc > 0.0) == (gb > 0.0) {
                b = c;
                gb = gc;
                if side == 1 {
                    ga *= 0.5;
                }
                side = 1;
            } else {
                a = c;
                ga = gc;
                if side == -1 {
                    gb *= 0.5;
                }
                side = -1;
            }
            if (b - a) * h < time_tol {
                break;
            }
        }
        if b > theta_min && best.is_none_or(|bst| b < bst) {
            best = Some(b);
        }
    }
    best
}
