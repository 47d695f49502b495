//! Checks of the model and the solvers against references that do not share their code:
//! closed-form piecewise-linear solutions, a hand-written physical-coordinate model, the static
//! solution from a free-body balance, the linear frequency response, and RK4 at a tiny step.

use std::f64::consts::TAU;

use gearwear_core::analysis::simulate::{RunSpec, Transient, run, run_system};
use gearwear_core::gearbox::{Gearbox, GearboxDescription};
use gearwear_core::model::{Load, LoadSchedule, Wear};
use gearwear_core::solver::{
    Dopri5, Dopri5Options, Integrator, OdeSystem, Rk4, advance_to, sample_uniform,
};
use nalgebra::{DMatrix, DVector};
use num_complex::Complex64;

// ---------------------------------------------------------------------------------------------
// 1. A single mesh with backlash: exact piecewise closed-form reference (`tests/support/one_mesh.rs`).
// ---------------------------------------------------------------------------------------------

#[path = "support/one_mesh.rs"]
mod one_mesh;
use one_mesh::{OneMesh, one_mesh_assembly};

#[test]
fn single_mesh_with_backlash_matches_piecewise_closed_form() {
    // Impacting regime: forcing large enough to cross both clearance edges.
    let p = OneMesh {
        c: 0.1,
        k: 1.0,
        b: 1.0,
        f: 0.1,
        a: 0.8,
        w: 0.9,
        phi: 0.3,
    };
    let model = one_mesh_assembly(&p).resolve().unwrap();
    let sys = model.system(p.w).unwrap();
    let grid: Vec<f64> = (0..=3000).map(|i| i as f64 * 0.02).collect();
    let reference = p.reference(0.0, 0.0, &grid);
    // The reference must really switch regions many times for the test to mean anything.
    let switches = reference
        .windows(2)
        .filter(|w| p.region(w[0]) != p.region(w[1]))
        .count();
    assert!(switches >= 20, "reference crosses only {switches} times");

    let opts = Dopri5Options {
        rtol: 1e-10,
        atol: 1e-12,
        ..Default::default()
    };
    let mut integ = Dopri5::new(&sys, 0.0, &[0.0, 0.0], opts).unwrap();
    let mut max_err: f64 = 0.0;
    sample_uniform(&mut integ, 0.0, 0.02, 60.0, |k, _, y| {
        max_err = max_err.max((y[0] - reference[k]).abs());
    })
    .unwrap();
    assert!(
        max_err < 1e-7,
        "DOPRI5 with switch location: max error {max_err:e}"
    );
    assert!(integ.stats().switches > 0);

    // Without switch location at the same tolerance the error is larger: the kinks cost
    // accuracy (or steps). This is what locating them buys.
    let opts_nl = Dopri5Options {
        locate_switches: false,
        ..opts
    };
    let mut plain = Dopri5::new(&sys, 0.0, &[0.0, 0.0], opts_nl).unwrap();
    let mut err_plain: f64 = 0.0;
    sample_uniform(&mut plain, 0.0, 0.02, 60.0, |k, _, y| {
        err_plain = err_plain.max((y[0] - reference[k]).abs());
    })
    .unwrap();
    let cost_located = integ.stats().rhs_evals as f64 * max_err;
    let cost_plain = plain.stats().rhs_evals as f64 * err_plain;
    assert!(
        cost_located < cost_plain,
        "located: {} evals, err {max_err:e}; plain: {} evals, err {err_plain:e}",
        integ.stats().rhs_evals,
        plain.stats().rhs_evals
    );
}

#[test]
fn rk4_converges_at_fourth_order_on_a_smooth_piece() {
    // No backlash: smooth, so RK4's global error falls 16× per halving of the step.
    let p = OneMesh {
        c: 0.1,
        k: 1.0,
        b: 0.0,
        f: 0.1,
        a: 0.3,
        w: 0.7,
        phi: 0.0,
    };
    let model = one_mesh_assembly(&p).resolve().unwrap();
    let sys = model.system(p.w).unwrap();
    let exact = p.solve(1, 0.0, 0.0, 0.0, 20.0).0;
    let err = |h: f64| {
        let mut r = Rk4::new(&sys, 0.0, &[0.0, 0.0], h).unwrap();
        advance_to(&mut r, 20.0).unwrap();
        (r.y()[0] - exact).abs()
    };
    let (e1, e2, e3) = (err(0.1), err(0.05), err(0.025));
    for (a, b) in [(e1, e2), (e2, e3)] {
        let order = (a / b).log2();
        assert!(
            (3.6..4.6).contains(&order),
            "observed order {order} ({a:e} → {b:e})"
        );
    }
}

#[test]
fn dopri5_error_falls_with_tolerance() {
    let p = OneMesh {
        c: 0.1,
        k: 1.0,
        b: 1.0,
        f: 0.1,
        a: 0.8,
        w: 0.9,
        phi: 0.3,
    };
    let model = one_mesh_assembly(&p).resolve().unwrap();
    let sys = model.system(p.w).unwrap();
    let grid: Vec<f64> = (0..=1500).map(|i| i as f64 * 0.02).collect();
    let reference = p.reference(0.0, 0.0, &grid);
    let err_at = |rtol: f64| {
        let opts = Dopri5Options {
            rtol,
            atol: rtol * 1e-2,
            ..Default::default()
        };
        let mut integ = Dopri5::new(&sys, 0.0, &[0.0, 0.0], opts).unwrap();
        let mut e: f64 = 0.0;
        sample_uniform(&mut integ, 0.0, 0.02, 30.0, |k, _, y| {
            e = e.max((y[0] - reference[k]).abs())
        })
        .unwrap();
        e
    };
    let (e6, e9) = (err_at(1e-6), err_at(1e-9));
    assert!(e6 < 1e-4, "rtol 1e-6: {e6:e}");
    assert!(
        e9 < e6 / 100.0,
        "tightening the tolerance 1000× gained only {e6:e} → {e9:e}"
    );
}

// ---------------------------------------------------------------------------------------------
// 2. Model A against an independent physical-coordinate model written from model.md.
// ---------------------------------------------------------------------------------------------

/// Model A in physical coordinates q = [θ1, θB, θC, θp1..4, θc], written by hand from the
/// table in model.md (not through the assembly): M q̈ = −Gᵀ F + T.
struct PhysicalModelA {
    r: [f64; 7], // r1 r2 r3 r4 rs rp rc
    j: [f64; 8],
    k: [f64; 10],
    c: [f64; 10],
    eps: f64,
    b: f64,
    w: [f64; 10],
    ea: [f64; 10],
    t_in: f64,
    t_out: f64,
}

impl PhysicalModelA {
    fn deflections(&self, t: f64, q: &[f64], qd: &[f64]) -> ([f64; 10], [f64; 10]) {
        let [r1, r2, r3, r4, rs, rp, rc] = self.r;
        let mut x = [0.0; 10];
        let mut v = [0.0; 10];
        x[0] = r1 * q[0] - r2 * q[1];
        v[0] = r1 * qd[0] - r2 * qd[1];
        x[1] = r3 * q[1] - r4 * q[2];
        v[1] = r3 * qd[1] - r4 * qd[2];
        for n in 0..4 {
            x[2 + n] = rs * q[2] - rp * q[3 + n] - rc * q[7];
            v[2 + n] = rs * qd[2] - rp * qd[3 + n] - rc * qd[7];
            x[6 + n] = rp * q[3 + n] - rc * q[7];
            v[6 + n] = rp * qd[3 + n] - rc * qd[7];
        }
        for m in 0..10 {
            x[m] -= self.ea[m] * (self.w[m] * t).sin();
            v[m] -= self.ea[m] * self.w[m] * (self.w[m] * t).cos();
        }
        (x, v)
    }
}

impl OdeSystem for PhysicalModelA {
    fn dim(&self) -> usize {
        16
    }
    fn rhs(&self, t: f64, y: &[f64], dy: &mut [f64]) {
        let (q, qd) = y.split_at(8);
        let (x, v) = self.deflections(t, q, qd);
        let mut f = [0.0; 10];
        for m in 0..10 {
            let kt = self.k[m] * (1.0 + self.eps * (self.w[m] * t).cos());
            let fb = if x[m] > self.b {
                x[m] - self.b
            } else if x[m] < -self.b {
                x[m] + self.b
            } else {
                0.0
            };
            f[m] = kt * fb + self.c[m] * v[m];
        }
        let [r1, r2, r3, r4, rs, rp, rc] = self.r;
        // Generalised forces −Gᵀ F + T, from the same table read column by column.
        let mut g = [0.0; 8];
        g[0] = -r1 * f[0] + self.t_in;
        g[1] = r2 * f[0] - r3 * f[1];
        g[2] = r4 * f[1];
        for n in 0..4 {
            g[2] -= rs * f[2 + n];
            g[3 + n] = rp * f[2 + n] - rp * f[6 + n];
            g[7] += rc * f[2 + n] + rc * f[6 + n];
        }
        g[7] -= self.t_out;
        for i in 0..8 {
            dy[i] = qd[i];
            dy[8 + i] = g[i] / self.j[i];
        }
    }
}

#[test]
fn relative_form_matches_an_independent_physical_model() {
    let ea = 0.6;
    let model = Gearbox::paper_rig()
        .assembly(Wear::fixed_axis(ea))
        .unwrap()
        .resolve()
        .unwrap();
    let omega1 = 0.9;
    // Physical parameters typed in here from the paper's Table 1 and the rig description's
    // assumed values (configs/gearboxes/wang2019.toml), independent of any parsing code.
    let mm = 1e-3;
    let r = [
        20.4 * mm,
        70.5 * mm,
        25.3 * mm,
        63.4 * mm,
        13.0 * mm,
        17.0 * mm,
        30.0 * mm,
    ];
    let jp = 0.01e-3;
    let jc = 0.76e-3 + 4.0 * 0.35 * r[6] * r[6];
    let j = [
        0.05e-3,
        6.0e-3 + 0.14e-3,
        4.0e-3 + 0.007e-3,
        jp,
        jp,
        jp,
        jp,
        jc,
    ];
    struct Assumed {
        stiffness_ratio_sun_planet: f64,
        stiffness_ratio_stage2: f64,
        stiffness_ratio_ring_planet: f64,
        planetary_error: f64,
        static_load: f64,
        fluctuation: f64,
    }
    let a = &Assumed {
        stiffness_ratio_sun_planet: 0.667,
        stiffness_ratio_stage2: 0.667,
        stiffness_ratio_ring_planet: 0.75,
        planetary_error: 0.1,
        static_load: 0.15,
        fluctuation: 0.2,
    };
    let (damping_ratio, length_ref_um, half_clearance) = (0.07, 5.0, 1.0);
    // Table 2 from the tooth counts by hand: f2 = 36·(29/100)/29, f3 = 28·(nC − nc)/29.
    let n_c_sun = (29.0 / 100.0) * (36.0 / 90.0) / 29.0;
    let f2 = 36.0 * (29.0 / 100.0) / 29.0;
    let f3 = 28.0 * (n_c_sun - n_c_sun * 28.0 / 128.0);
    let wh = model.omega_h;
    let a11 = r[0] * r[0] / j[0] + r[1] * r[1] / j[1];
    assert!((wh - TAU * 870.0).abs() < 1e-6 * wh);
    let k1 = wh * wh / a11;
    let mut k = [k1 * a.stiffness_ratio_sun_planet; 10];
    k[0] = k1;
    k[1] = k1 * a.stiffness_ratio_stage2;
    for kk in k.iter_mut().skip(6) {
        *kk = k1 * a.stiffness_ratio_ring_planet;
    }
    // Equivalent masses from model.md: 1/me = A_jj, written out by hand.
    let inv_me = |m: usize| -> f64 {
        let [r1, r2, r3, r4, rs, rp, rc] = r;
        match m {
            0 => r1 * r1 / j[0] + r2 * r2 / j[1],
            1 => r3 * r3 / j[1] + r4 * r4 / j[2],
            2..=5 => rs * rs / j[2] + rp * rp / jp + rc * rc / jc,
            _ => rp * rp / jp + rc * rc / jc,
        }
    };
    let c: Vec<f64> = (0..10)
        .map(|m| 2.0 * damping_ratio * (k[m] / inv_me(m)).sqrt())
        .collect();
    let b_ref = length_ref_um * 1e-6;
    let wmesh = omega1 * wh; // rad/s
    let mut w = [wmesh * f3; 10];
    w[0] = wmesh;
    w[1] = wmesh * f2;
    let mut ea_v = [a.planetary_error * b_ref; 10];
    ea_v[0] = ea * b_ref;
    ea_v[1] = ea * b_ref;
    let t_in = a.static_load * k1 * b_ref * r[0];
    let t_out = t_in * (r[1] / r[0]) * (r[3] / r[2]) * (2.0 * r[6] / r[4]);
    let phys = PhysicalModelA {
        r,
        j,
        k,
        c: c.try_into().unwrap(),
        eps: a.fluctuation,
        b: half_clearance * b_ref,
        w,
        ea: ea_v,
        t_in,
        t_out,
    };
    // Same start: the physical model at rest (q = 0, q̇ = 0) has x = −e(0) = 0 and
    // ẋ = −ė(0), so the relative model starts at x̄ = 0, x̄' = −ē Ω.
    let mut y0 = [0.0; 20];
    for m in 0..10 {
        y0[10 + m] = -ea_v[m] / b_ref * w[m] / wh;
    }
    let t_end_tau = 60.0;
    let opts = Dopri5Options {
        rtol: 1e-10,
        atol: 1e-13,
        ..Default::default()
    };
    let sys = model.system(omega1).unwrap();
    let mut rel = Dopri5::new(
        &sys,
        0.0,
        &y0,
        Dopri5Options {
            atol: 1e-10,
            ..opts
        },
    )
    .unwrap();
    let mut rel_samples = Vec::new();
    sample_uniform(&mut rel, 0.0, 0.5, t_end_tau, |_, _, y| {
        rel_samples.push(y[..10].to_vec())
    })
    .unwrap();
    let mut ph = Dopri5::new(
        &phys,
        0.0,
        &[0.0; 16],
        Dopri5Options {
            atol: 1e-16,
            ..opts
        },
    )
    .unwrap();
    let mut max_err: f64 = 0.0;
    let mut max_amp: f64 = 0.0;
    sample_uniform(&mut ph, 0.0, 0.5 / wh, t_end_tau / wh, |kk, t, y| {
        let (x, _) = phys.deflections(t, &y[..8], &y[8..]);
        for m in 0..10 {
            let xd = x[m] / b_ref;
            max_err = max_err.max((xd - rel_samples[kk][m]).abs());
            max_amp = max_amp.max(xd.abs());
        }
    })
    .unwrap();
    assert!(
        max_amp > 0.5,
        "the comparison must exercise real motion (max |x̄| = {max_amp})"
    );
    assert!(
        max_err < 1e-5 * max_amp.max(1.0),
        "relative vs physical form: max |Δx̄| = {max_err:e}"
    );
}

#[test]
fn model_a_a_matrix_entries_match_model_md() {
    let asm = Gearbox::paper_rig()
        .assembly(Wear::fixed_axis(0.1))
        .unwrap();
    let m = asm.resolve().unwrap();
    let mm = 1e-3;
    // Table 1: base radii of gears 1–3, inertias of gear 1 and body B (gears 2 + 3).
    let (r1, r2, r3) = (20.4 * mm, 70.5 * mm, 25.3 * mm);
    let jb = 6.0e-3 + 0.14e-3;
    let a11 = r1 * r1 / 0.05e-3 + r2 * r2 / jb;
    // Row 1 of the paper's equation: A11 = 1/me1, A12 = −r2 r3 / JB.
    assert!((m.a_ref - a11).abs() < 1e-12 * a11);
    assert!((m.a[(0, 1)] - (-r2 * r3 / jb) / a11).abs() < 1e-12);
    assert!((m.a[(0, 0)] - 1.0).abs() < 1e-15);
    // Symmetric, rank 7 (10 meshes, 8 coordinates, one rigid-body mode).
    assert!((&m.a - m.a.transpose()).abs().max() < 1e-12);
    let rank =
        m.a.clone()
            .svd(false, false)
            .singular_values
            .iter()
            .filter(|s| **s > 1e-9)
            .count();
    assert_eq!(rank, 7);
    // Three constraint combinations: xsp_n + xrp_n − (xsp_1 + xrp_1) is in A's left null space.
    for n in 1..4 {
        let mut w = DVector::zeros(10);
        w[2] = 1.0;
        w[6] = 1.0;
        w[2 + n] = -1.0;
        w[6 + n] = -1.0;
        assert!((w.transpose() * &m.a).abs().max() < 1e-12);
    }
}

// ---------------------------------------------------------------------------------------------
// 3. Static deflection and the linear limit.
// ---------------------------------------------------------------------------------------------

/// The paper's rig with its description edited.
fn rig_with(edit: impl FnOnce(&mut GearboxDescription)) -> Gearbox {
    let mut d = Gearbox::paper_rig().description;
    edit(&mut d);
    Gearbox::new(d).unwrap()
}

fn linear_config() -> Gearbox {
    rig_with(|d| {
        d.mesh.half_clearance_um = Some(0.0);
        d.mesh.fluctuation = Some(0.0);
    })
}

#[test]
fn static_deflection_matches_the_free_body_balance() {
    // No error, constant stiffness, backlash: the response settles to the static deflection
    // `x = b + F_mesh / k`, with mesh forces from torque balance body by body (not from A).
    let cfg = rig_with(|d| d.mesh.fluctuation = Some(0.0));
    let mut w = Wear::fixed_axis(0.0);
    w.planetary = Some(0.0);
    let model = cfg.assembly(w).unwrap().resolve().unwrap();
    let mut spec = RunSpec::paper(0.5);
    spec.periods = 2;
    spec.transient = Transient {
        tau: 1500.0,
        periods: 0.0,
    };
    let traj = run(&model, &spec).unwrap();
    let mm = 1e-3;
    // Table 1 base radii of gears 2, 3, 4 and the sun; the description's assumed values.
    let (r2, r3, r4, rs) = (70.5 * mm, 25.3 * mm, 63.4 * mm, 13.0 * mm);
    struct Assumed {
        static_load: f64,
        stiffness_ratio_stage2: f64,
        stiffness_ratio_sun_planet: f64,
        stiffness_ratio_ring_planet: f64,
    }
    let a = &Assumed {
        static_load: 0.15,
        stiffness_ratio_stage2: 0.667,
        stiffness_ratio_sun_planet: 0.667,
        stiffness_ratio_ring_planet: 0.75,
    };
    let f1 = a.static_load; // F1 / (k1 b_ref)
    let f2 = f1 * r2 / r3; // body B: r2 F1 = r3 F2
    let fsp = f2 * r4 / (4.0 * rs); // body C: r4 F2 = 4 rs Fsp
    let frp = fsp; // planet: rp Fsp = rp Frp
    let expected = [
        1.0 + f1,
        1.0 + f2 / a.stiffness_ratio_stage2,
        1.0 + fsp / a.stiffness_ratio_sun_planet,
        1.0 + frp / a.stiffness_ratio_ring_planet,
    ];
    let last = traj.len() - 1;
    let x = |j: usize| traj.states[last * traj.dim + j];
    for (j, e) in [
        (0, expected[0]),
        (1, expected[1]),
        (2, expected[2]),
        (9, expected[3]),
    ] {
        assert!(
            (x(j) - e).abs() < 1e-5,
            "mesh {j}: {} vs free-body {e}",
            x(j)
        );
    }
}

#[test]
fn linear_limit_matches_the_complex_frequency_response() {
    // No backlash, constant stiffness: x'' + Ā(K x + C x') = F̄ + Σ ē Ω² sin(Ω τ + φ) has the
    // steady state x_s + Σ Im(X e^{i(Ωτ+φ)}) with (−Ω² I + iΩ Ā C + Ā K) X = ē Ω².
    let cfg = linear_config();
    let ea = 0.5;
    let model = cfg
        .assembly(Wear::fixed_axis(ea))
        .unwrap()
        .resolve()
        .unwrap();
    let omega1 = 0.7;
    let n = model.n();
    let kd = DMatrix::from_diagonal(&DVector::from_vec(model.k_ratio.clone()));
    let cd = DMatrix::from_diagonal(&DVector::from_vec(model.c.clone()));
    // Static part: Ā K x = F̄ with the constraint directions (null space of Ā) set to zero.
    let ak = &model.a * &kd;
    let svd = model.a.clone().svd(true, false);
    let u = svd.u.unwrap();
    let null: Vec<usize> = (0..n).filter(|&i| svd.singular_values[i] < 1e-9).collect();
    assert_eq!(null.len(), 3);
    let mut big = DMatrix::zeros(n + 3, n);
    let mut rhs = DVector::zeros(n + 3);
    big.view_mut((0, 0), (n, n)).copy_from(&ak);
    for i in 0..n {
        rhs[i] = model.f[i];
    }
    for (r, &c) in null.iter().enumerate() {
        for j in 0..n {
            big[(n + r, j)] = u[(j, c)];
        }
    }
    let xs = big.clone().svd(true, true).solve(&rhs, 1e-12).unwrap();
    // Harmonic parts, one per distinct forcing frequency.
    let mut parts: Vec<(f64, Vec<Complex64>)> = Vec::new();
    for (j, hs) in model.error.iter().enumerate() {
        for h in hs {
            let w = h.freq_ratio * omega1;
            let mut f = vec![Complex64::new(0.0, 0.0); n];
            f[j] = Complex64::from_polar(h.amplitude * w * w, h.phase);
            parts.push((w, f));
        }
    }
    let response = |w: f64, f: &[Complex64]| -> Vec<Complex64> {
        let m = DMatrix::from_fn(n, n, |i, k| {
            let id = if i == k { -w * w } else { 0.0 };
            Complex64::new(id + ak[(i, k)], w * (&model.a * &cd)[(i, k)])
        });
        let rhs = DVector::from_vec(f.to_vec());
        m.lu().solve(&rhs).unwrap().iter().cloned().collect()
    };
    let xs_parts: Vec<(f64, Vec<Complex64>)> =
        parts.iter().map(|(w, f)| (*w, response(*w, f))).collect();
    let analytic = |tau: f64, j: usize| -> f64 {
        xs[j]
            + xs_parts
                .iter()
                .map(|(w, x)| (x[j] * Complex64::from_polar(1.0, w * tau)).im)
                .sum::<f64>()
    };
    let mut spec = RunSpec::paper(omega1);
    spec.periods = 10;
    spec.samples_per_period = 32;
    spec.transient = Transient {
        tau: 1500.0,
        periods: 0.0,
    };
    spec.solver = Dopri5Options {
        rtol: 1e-9,
        atol: 1e-11,
        ..Default::default()
    };
    let traj = run(&model, &spec).unwrap();
    let mut max_err: f64 = 0.0;
    let mut amp: f64 = 0.0;
    for (k, &tau) in traj.tau.iter().enumerate() {
        for j in 0..n {
            let a = analytic(tau, j);
            max_err = max_err.max((traj.states[k * traj.dim + j] - a).abs());
            amp = amp.max((a - xs[j]).abs());
        }
    }
    assert!(
        amp > 0.05,
        "the forced response must be visible (amplitude {amp})"
    );
    assert!(
        max_err < 1e-5,
        "linear limit: max error {max_err:e} (dynamic amplitude {amp})"
    );
}

// ---------------------------------------------------------------------------------------------
// 4. DOPRI5 against RK4 at a tiny step on the full nonlinear Model A.
// ---------------------------------------------------------------------------------------------

#[test]
fn dopri5_agrees_with_tiny_step_rk4_on_model_a() {
    let model = Gearbox::paper_rig()
        .assembly(Wear::fixed_axis(0.4))
        .unwrap()
        .resolve()
        .unwrap();
    let sys = model.system(1.0).unwrap();
    let t_end = 40.0; // short enough that chaos has not amplified differences
    let mut rk = Rk4::new(&sys, 0.0, &[0.0; 20], 2e-4).unwrap();
    let mut rk_s = Vec::new();
    sample_uniform(&mut rk, 0.0, 0.1, t_end, |_, _, y| rk_s.push(y[0])).unwrap();
    let opts = Dopri5Options {
        rtol: 1e-9,
        atol: 1e-11,
        ..Default::default()
    };
    let mut dp = Dopri5::new(&sys, 0.0, &[0.0; 20], opts).unwrap();
    let mut max_err: f64 = 0.0;
    sample_uniform(&mut dp, 0.0, 0.1, t_end, |k, _, y| {
        max_err = max_err.max((y[0] - rk_s[k]).abs())
    })
    .unwrap();
    assert!(dp.stats().switches > 0, "the run must cross the clearance");
    assert!(max_err < 1e-6, "DOPRI5 vs RK4(h = 2e-4): {max_err:e}");
}

// ---------------------------------------------------------------------------------------------
// 5. Sampling lands exactly on the grid.
// ---------------------------------------------------------------------------------------------

#[test]
fn samples_land_on_the_requested_grid() {
    let model = Gearbox::paper_rig()
        .assembly(Wear::fixed_axis(0.3))
        .unwrap()
        .resolve()
        .unwrap();
    let mut spec = RunSpec::paper(1.3);
    spec.periods = 3;
    let traj = run(&model, &spec).unwrap();
    assert_eq!(traj.len(), 3 * 256);
    let dt = TAU / 1.3 / 256.0;
    let t0 = spec.transient.length(1.3);
    for (k, t) in traj.tau.iter().enumerate() {
        assert!((t - (t0 + k as f64 * dt)).abs() < 1e-9, "sample {k} at {t}");
    }
    // run_system on the same system gives the same samples.
    let sys = model.system(1.3).unwrap();
    let traj2 = run_system(&sys, &spec).unwrap();
    assert!(traj.states == traj2.states, "run and run_system differ");
}

// ---------------------------------------------------------------------------------------------
// 6. Motion-state classification on known cases, through the solver and the Lyapunov twin.
// ---------------------------------------------------------------------------------------------

/// Ueda's oscillator x'' + 0.05 x' + x³ = 7.5 cos τ: a textbook chaotic attractor.
struct Ueda;

impl OdeSystem for Ueda {
    fn dim(&self) -> usize {
        2
    }
    fn rhs(&self, t: f64, y: &[f64], dy: &mut [f64]) {
        dy[0] = y[1];
        dy[1] = -0.05 * y[1] - y[0].powi(3) + 7.5 * t.cos();
    }
}

fn classify_run<S: OdeSystem>(
    sys: &S,
    periods: usize,
) -> gearwear_core::analysis::motion::Classification {
    use gearwear_core::analysis::motion::{ClassifyOptions, classify_forced};
    let spec = RunSpec {
        omega1: 1.0,
        periods,
        samples_per_period: 64,
        transient: Transient {
            tau: 300.0,
            periods: 0.0,
        },
        initial: vec![],
        solver: Dopri5Options::default(),
        lyapunov: true,
    };
    let traj = run_system(sys, &spec).unwrap();
    let x = traj.series(0);
    let v = traj.series(1);
    let span = |s: &[f64]| {
        s.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
            - s.iter().cloned().fold(f64::INFINITY, f64::min)
    };
    let lyap = traj.lyapunov_per_period.unwrap();
    classify_forced(
        &traj.poincare(0),
        (span(&x), span(&v)),
        lyap,
        &[],
        &ClassifyOptions::default(),
    )
    .unwrap()
}

#[test]
fn known_motion_states_are_classified() {
    use gearwear_core::analysis::motion::MotionState;
    // A damped linear oscillator under harmonic forcing: period-1, negative exponent.
    let p = OneMesh {
        c: 0.1,
        k: 1.0,
        b: 0.0,
        f: 0.1,
        a: 0.3,
        w: 1.0,
        phi: 0.0,
    };
    let model = one_mesh_assembly(&p).resolve().unwrap();
    let sys = model.system(1.0).unwrap();
    let c = classify_run(&sys, 80);
    assert_eq!(c.state, MotionState::Periodic { period: 1 }, "{c:?}");
    // Its exponent is the decay rate over one period: −(c/2)·2π = −0.314.
    let l = c.lyapunov_per_period.unwrap();
    assert!(
        (l + 0.05 * std::f64::consts::TAU).abs() < 0.05,
        "linear oscillator exponent {l}"
    );
    // Ueda's attractor: chaotic.
    let c = classify_run(&Ueda, 150);
    assert_eq!(c.state, MotionState::Chaotic, "{c:?}");
}

// ---------------------------------------------------------------------------------------------
// 7. A load step: both solvers land on it and match the closed form across it.
// ---------------------------------------------------------------------------------------------

#[test]
fn load_step_is_integrated_exactly_by_both_solvers() {
    use gearwear_core::solver::{Rodas4, Rodas4Options};
    // x'' + c x' + x = F(τ), F = 0.1 before τ = 7.3 and 0.6 after; no backlash, no forcing.
    let before = OneMesh {
        c: 0.1,
        k: 1.0,
        b: 0.0,
        f: 0.1,
        a: 0.0,
        w: 1.0,
        phi: 0.0,
    };
    let after = OneMesh { f: 0.6, ..before };
    let tau_s = 7.3;
    let mut asm = one_mesh_assembly(&before);
    asm.loads = vec![Load {
        dof: "q".into(),
        schedule: LoadSchedule::Step {
            before: 0.1,
            after: 0.6,
            at: tau_s,
        },
    }];
    let model = asm.resolve().unwrap();
    let sys = model.system(1.0).unwrap();
    assert_eq!(sys.breakpoints(), vec![tau_s]);
    let (xs, vs) = before.solve(1, 0.0, 0.0, 0.0, tau_s);
    let exact = |t: f64| {
        if t <= tau_s {
            before.solve(1, 0.0, 0.0, 0.0, t).0
        } else {
            after.solve(1, tau_s, xs, vs, t - tau_s).0
        }
    };
    let dp_opts = Dopri5Options {
        rtol: 1e-11,
        atol: 1e-13,
        ..Default::default()
    };
    let mut dp = Dopri5::new(&sys, 0.0, &[0.0, 0.0], dp_opts).unwrap();
    let mut err_dp: f64 = 0.0;
    sample_uniform(&mut dp, 0.0, 0.05, 20.0, |_, t, y| {
        err_dp = err_dp.max((y[0] - exact(t)).abs())
    })
    .unwrap();
    assert!(err_dp < 1e-9, "DOPRI5 across the load step: {err_dp:e}");
    // Landing on the jump with the left limit costs no rejections; seeing the new load in the
    // last stages of the step that ends on it costs dozens (measured: 1 vs 28).
    assert!(
        dp.stats().rejected <= 5,
        "DOPRI5 rejections around the load step: {:?}",
        dp.stats()
    );
    let ro_opts = Rodas4Options {
        rtol: 1e-9,
        atol: 1e-11,
        ..Default::default()
    };
    let mut ro = Rodas4::new(&sys, 0.0, &[0.0, 0.0], ro_opts).unwrap();
    let mut err_ro: f64 = 0.0;
    sample_uniform(&mut ro, 0.0, 0.05, 20.0, |_, t, y| {
        err_ro = err_ro.max((y[0] - exact(t)).abs())
    })
    .unwrap();
    assert!(err_ro < 1e-6, "RODAS4 across the load step: {err_ro:e}");
    assert!(
        ro.stats().rejected <= 5,
        "RODAS4 rejections around the load step: {:?}",
        ro.stats()
    );
}
