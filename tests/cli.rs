//! The built binary, run as a user would.

use std::process::Command;

fn gearwear(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_gearwear"))
        .args(args)
        // The table and model cache: this test run's own, not the user's.
        .env(
            "GEARWEAR_CACHE_DIR",
            std::env::temp_dir().join(format!("gearwear-cli-cache-{}", std::process::id())),
        )
        .output()
        .expect("binary runs");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn tmpdir(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("gearwear-cli-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn simulate_prints_lines_and_motion_state_and_writes_plots() {
    let dir = tmpdir("sim");
    let (ok, out, err) = gearwear(&[
        "simulate",
        "--omega1",
        "1",
        "--ea",
        "0.8",
        "--periods",
        "40",
        "--plot",
        dir.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    for k in ["f1", "f2", "2f2", "f3", "f1/2", "f1-f2"] {
        let a = v["lines"][k]
            .as_f64()
            .unwrap_or_else(|| panic!("line {k} missing"));
        assert!(a.is_finite() && a >= 0.0);
    }
    assert!(v["lines"]["f1"].as_f64().unwrap() > v["lines"]["f3"].as_f64().unwrap());
    let state = v["motion_state"].as_str().unwrap();
    assert!(state.starts_with("period-") || state == "quasi-periodic" || state == "chaotic");
    assert!((v["f1_hz"].as_f64().unwrap() - 870.0).abs() < 1e-6);
    for f in [
        "time.png",
        "phase.png",
        "poincare.png",
        "spectrum.png",
        "overview.png",
    ] {
        let bytes = std::fs::read(dir.join(f)).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    }
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn model_export_is_complete_and_consistent() {
    let (ok, out, err) = gearwear(&["model", "--export", "json"]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let a = v["A"].as_array().unwrap();
    assert_eq!(a.len(), 10);
    for (i, row) in a.iter().enumerate() {
        let row = row.as_array().unwrap();
        assert_eq!(row.len(), 10);
        for (j, x) in row.iter().enumerate() {
            let y = a[j][i].as_f64().unwrap();
            assert!(
                (x.as_f64().unwrap() - y).abs() < 1e-12,
                "A not symmetric at {i},{j}"
            );
        }
    }
    assert!((a[0][0].as_f64().unwrap() - 1.0).abs() < 1e-12);
    for k in [
        "k_ratio",
        "eps",
        "c",
        "F",
        "omega_ratio",
        "phase",
        "backlash",
        "error_amplitude",
    ] {
        assert_eq!(
            v[k].as_array()
                .unwrap_or_else(|| panic!("{k} missing"))
                .len(),
            10,
            "{k}"
        );
    }
    let order: Vec<&str> = v["order"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s.as_str().unwrap())
        .collect();
    assert_eq!(
        order,
        [
            "x1", "x2", "xsp1", "xsp2", "xsp3", "xsp4", "xrp1", "xrp2", "xrp3", "xrp4"
        ]
    );
    let w: Vec<f64> = v["omega_ratio"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    assert!(
        (w[0] - 1.0).abs() < 1e-12 && (w[1] - 0.36).abs() < 1e-12 && (w[9] - 0.0875).abs() < 1e-12
    );
}

#[test]
fn frequencies_reproduce_table_2() {
    let (ok, out, err) = gearwear(&["frequencies", "--shaft-hz", "30"]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert!((v["hz"]["f1"].as_f64().unwrap() - 870.0).abs() < 1e-9);
    assert!((v["ratio_to_f1"]["f2"].as_f64().unwrap() - 0.3599).abs() < 5e-4);
    assert!((v["ratio_to_f1"]["f3"].as_f64().unwrap() - 0.0877).abs() < 5e-4);
}

#[test]
fn bifurcation_writes_csv_and_plots() {
    let dir = tmpdir("bif");
    let csv = dir.join("b.csv");
    let png = dir.join("b.png");
    let (ok, _out, err) = gearwear(&[
        "bifurcation",
        "--ea",
        "0.8",
        "--omega1",
        "0.2:1.2:0.25",
        "--periods",
        "20",
        "--output",
        csv.to_str().unwrap(),
        "--plot",
        png.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next().unwrap(),
        "omega1,state,lyapunov_per_period,x1,x1_velocity,xrp1,xrp1_velocity"
    );
    assert_eq!(lines.count(), 5 * 20);
    assert!(png.exists() && dir.join("b_xrp1.png").exists());
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn bad_arguments_get_clear_errors() {
    let (ok, _, err) = gearwear(&["bifurcation", "--ea", "0.8", "--omega1", "1:0.5:0.1"]);
    assert!(!ok && err.contains("START"), "{err}");
    let (ok, _, err) = gearwear(&["simulate", "--omega1=-1", "--ea", "0.5"]);
    assert!(!ok && err.contains("Ω1"), "{err}");
    let (ok, _, err) = gearwear(&["simulate", "--omega1", "1", "--ea", "NaN"]);
    assert!(!ok && err.contains("--ea"), "{err}");
    let (ok, _, err) = gearwear(&[
        "simulate",
        "--omega1",
        "1",
        "--ea",
        "0.5",
        "--element",
        "x99",
    ]);
    assert!(!ok && err.contains("x99"), "{err}");
    let (ok, _, err) = gearwear(&["model", "--gearbox", "/nonexistent/rig.toml"]);
    assert!(!ok && err.contains("/nonexistent/rig.toml"), "{err}");
}

fn config(name: &str) -> String {
    format!("{}/configs/gearboxes/{name}", env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn gearbox_kinematics_by_hand() {
    // 32:80 then 24:72 at 30 Hz: intermediate 12 Hz, output 4 Hz, meshes 960 and 288 Hz.
    let (ok, out, err) = gearwear(&[
        "gearbox",
        "kinematics",
        "--gearbox",
        &config("two-stage-parallel.toml"),
        "--input-hz",
        "30",
    ]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let close = |a: &serde_json::Value, b: f64| (a.as_f64().unwrap() - b).abs() < 1e-9 * b;
    assert!(close(&v["shafts"]["intermediate"], 12.0), "{v}");
    assert!(close(&v["shafts"]["output"], 4.0), "{v}");
    assert_eq!(v["meshes"][0]["stage"], 1);
    assert!(close(&v["meshes"][0]["hz"], 960.0), "{v}");
    assert!(close(&v["meshes"][1]["hz"], 288.0), "{v}");
}

#[test]
fn paper_rig_description_exports_the_default_model() {
    let (ok, default, err) = gearwear(&["model", "--export", "json"]);
    assert!(ok, "{err}");
    let (ok, described, err) = gearwear(&[
        "model",
        "--export",
        "json",
        "--gearbox",
        &config("wang2019.toml"),
    ]);
    assert!(ok, "{err}");
    assert_eq!(default, described);
    let v: serde_json::Value = serde_json::from_str(&described).unwrap();
    assert_eq!(v["A"].as_array().unwrap().len(), 10);
    assert_eq!(v["dynamics_estimated"], false);
    // A tooth-count-only description says its dynamics are estimated and what it assumed.
    let (ok, out, err) = gearwear(&["gearbox", "show", "--gearbox", &config("spur-pair.toml")]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["dynamics_estimated"], true);
    assert!(v["assumed"].as_array().unwrap().len() >= 5, "{v}");
}

#[test]
fn bad_gearbox_descriptions_get_specific_errors() {
    let dir = tmpdir("gearbox");
    let bad = dir.join("bad.toml");
    std::fs::write(
        &bad,
        "format = \"gearwear-gearbox\"\nversion = 1\nname = \"p\"\ninput_shaft = \"s\"\n\
         [[stage]]\nkind = \"planetary\"\nsun = { shaft = \"s\", teeth = 20 }\n\
         planets = { count = 3, teeth = 30 }\nring = { teeth = 79 }\ncarrier = { shaft = \"c\" }\n\
         fixed = \"ring\"\n",
    )
    .unwrap();
    let (ok, _, err) = gearwear(&["gearbox", "show", "--gearbox", bad.to_str().unwrap()]);
    assert!(
        !ok,
        "a ring of 79 teeth with sun 20 and planets 30 must be refused"
    );
    assert!(err.contains("coaxial") && err.contains("80"), "{err}");
    let (ok, _, err) = gearwear(&[
        "simulate",
        "--omega1",
        "1",
        "--ea",
        "0.5",
        "--gearbox",
        bad.to_str().unwrap(),
    ]);
    assert!(!ok && err.contains("profile_shifted"), "{err}");
}

#[test]
fn synth_then_diagnose_round_trip_through_files() {
    let dir = tmpdir("synth");
    let wav = dir.join("rec.wav");
    let (ok, _, err) = gearwear(&[
        "synth",
        "--ea",
        "0.7",
        "--seed",
        "7",
        "--gain",
        "3.5",
        "--output",
        wav.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    for args in [vec!["--shaft-hz", "30"], vec![]] {
        let mut a = vec!["diagnose", "--input", wav.to_str().unwrap()];
        a.extend(args.iter());
        let (ok, out, err) = gearwear(&a);
        assert!(ok, "{err}");
        let v: serde_json::Value = serde_json::from_str(&out).unwrap();
        let w = &v["wear_degree"];
        let (est, lo, hi) = (
            w["estimate"].as_f64().unwrap(),
            w["lower"].as_f64().unwrap(),
            w["upper"].as_f64().unwrap(),
        );
        assert!(lo <= est && est <= hi);
        assert!(
            (est - 0.7).abs() < 0.1,
            "estimate {est} [{lo}, {hi}] for ea 0.7 ({args:?})"
        );
        assert!((v["f1_hz"].as_f64().unwrap() - 870.0).abs() < 2.0);
    }
    // The same samples as CSV give the same answer.
    let csv = dir.join("rec.csv");
    let (ok, _, err) = gearwear(&[
        "synth",
        "--ea",
        "0.7",
        "--seed",
        "7",
        "--gain",
        "3.5",
        "--output",
        csv.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let (ok, out, err) = gearwear(&[
        "diagnose",
        "--input",
        csv.to_str().unwrap(),
        "--sample-rate",
        "25600",
        "--shaft-hz",
        "30",
    ]);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert!((v["wear_degree"]["estimate"].as_f64().unwrap() - 0.7).abs() < 0.1);
    let (ok, _, err) = gearwear(&[
        "synth",
        "--ea",
        "0.7",
        "--output",
        dir.join("rec.mp3").to_str().unwrap(),
    ]);
    assert!(!ok && err.contains(".wav"), "{err}");
    std::fs::remove_dir_all(dir).ok();
}

/// `diagnose --baseline`: three healthy records give a `novelty` object with a calibrated
/// threshold; two give a clear error; the diagnosis carries the order tracking of the record.
#[test]
fn diagnose_with_a_baseline_scores_novelty() {
    let dir = tmpdir("baseline");
    let synth = |name: &str, ea: &str, seed: &str| {
        let p = dir.join(name);
        let (ok, _, err) = gearwear(&[
            "synth",
            "--ea",
            ea,
            "--seed",
            seed,
            "--output",
            p.to_str().unwrap(),
        ]);
        assert!(ok, "{err}");
        p.to_str().unwrap().to_string()
    };
    let base: Vec<String> = (1..=3)
        .map(|k| synth(&format!("h{k}.wav"), "0.3", &k.to_string()))
        .collect();
    let rec = synth("t.wav", "0.3", "9");
    let gearbox = config("wang2019.toml");
    let mut args = vec![
        "diagnose",
        "--input",
        &rec,
        "--shaft-hz",
        "30",
        "--gearbox",
        &gearbox,
    ];
    for b in &base {
        args.extend(["--baseline", b.as_str()]);
    }
    let (ok, out, err) = gearwear(&args);
    assert!(ok, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let n = &v["novelty"];
    assert_eq!(n["baseline_records"], 3, "{n}");
    let (score, thr) = (
        n["score"].as_f64().unwrap(),
        n["threshold"].as_f64().unwrap(),
    );
    assert!(score.is_finite() && score >= 0.0 && thr >= 3.0, "{n}");
    assert_eq!(n["anomalous"].as_bool().unwrap(), score > thr);
    assert!(!n["top_features"].as_array().unwrap().is_empty(), "{n}");
    assert!(n["features_used"].as_u64().unwrap() > 20, "{n}");
    // Order tracking of the input shaft from the f1 line: 30 Hz, a TSA of it.
    let o = &v["order"];
    let hz = o["tracking"]["mean_hz"].as_f64().unwrap();
    assert!((hz - 30.0).abs() < 0.1, "{o}");
    assert_eq!(o["tracked_shaft"], "motor", "{o}");
    assert!(o["shafts"][0]["metrics"]["fm4"].as_f64().is_some(), "{o}");
    // The existing fields are still there.
    assert!(v["wear_degree"]["estimate"].as_f64().is_some());

    let (ok, _, err) = gearwear(&[
        "diagnose",
        "--input",
        &rec,
        "--baseline",
        &base[0],
        "--baseline",
        &base[1],
    ]);
    assert!(!ok);
    assert!(err.contains("at least 3"), "{err}");
}

/// A synthetic record of the helical gearbox (`configs/gearboxes/phm09-helical.toml`: 16:48
/// then 24:40) as a 3-column CSV `input,output,tach` at 20 kHz, 2 s: mesh tones at 16× and 8×
/// the input rate `f` (with harmonics), a 10-pulse tachometer, seeded noise; `impacts`: a
/// decaying 3 kHz burst once per idler revolution (a broken tooth on the idler).
fn helical_csv(path: &std::path::Path, f: f64, seed: u64, impacts: f64) {
    let fs = 20_000.0;
    let n = 40_000;
    let mut s = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    let mut noise = move || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((s >> 11) as f64 / (1u64 << 53) as f64) - 0.5
    };
    let tau = std::f64::consts::TAU;
    let mut out = String::from("input,output,tach\n");
    for i in 0..n {
        let t = i as f64 / fs;
        let th = f * t; // input revolutions
        let mesh = (tau * 16.0 * th).sin()
            + 0.6 * (tau * 8.0 * th + 0.3).sin()
            + 0.3 * (tau * 32.0 * th).sin()
            + 0.2 * (tau * 24.0 * th).sin();
        let idler = th / 3.0;
        let since = idler.fract() * 3.0 / f; // seconds since the last idler revolution
        let burst = impacts * (-since * 400.0).exp() * (tau * 3000.0 * since).sin();
        let tach = if (th * 10.0).fract() < 0.25 { 5.0 } else { 0.0 };
        let a = mesh + burst + 0.3 * noise();
        let b = 0.7 * mesh + 0.5 * burst + 0.3 * noise();
        out.push_str(&format!("{a:.5},{b:.5},{tach}\n"));
    }
    std::fs::write(path, out).unwrap();
}

/// `diagnose --baseline-manifest` with a tachometer: the speed is counted from the pulses,
/// the record is judged against healthy records at its speed and load, a healthy one is not
/// anomalous, one with impacts once per idler revolution gets findings led by a gear on the idler, and
/// one at a speed the baseline lacks is `unknown`, naming the missing state. Without a
/// signature table for the gearbox (`--cached-only`: nothing is computed) the answer has no
/// wear figure and says why.
#[test]
fn diagnose_judges_each_record_at_its_operating_state() {
    let dir = tmpdir("states");
    let mut manifest = String::from("file,shaft_hz,load\n");
    for (k, (f, load)) in [
        (30.0, "High"),
        (40.0, "High"),
        (50.0, "High"),
        (30.0, "Low"),
        (40.0, "Low"),
        (50.0, "Low"),
    ]
    .iter()
    .enumerate()
    {
        let slip = if *load == "High" { 0.985 } else { 0.995 };
        let name = format!("b{k}.csv");
        helical_csv(&dir.join(&name), f * slip, k as u64, 0.0);
        manifest += &format!("{name},{f},{load}\n");
    }
    let m = dir.join("baseline.csv");
    std::fs::write(&m, manifest).unwrap();
    // The helical description under a name no committed table has: no wear figure.
    let text = std::fs::read_to_string(config("phm09-helical.toml")).unwrap();
    let gb = dir.join("untabled.toml");
    std::fs::write(
        &gb,
        text.replace("name = \"phm09-helical\"", "name = \"untabled-helical\""),
    )
    .unwrap();
    let gearbox = gb.to_str().unwrap().to_string();
    let run = |rec: &std::path::Path, hz: &str, load: &str| {
        let (ok, out, err) = gearwear(&[
            "diagnose",
            "--gearbox",
            &gearbox,
            "--input",
            rec.to_str().unwrap(),
            "--sample-rate",
            "20000",
            "--shaft-hz",
            hz,
            "--tacho-column",
            "tach",
            "--tacho-ppr",
            "10",
            "--load",
            load,
            "--baseline-manifest",
            m.to_str().unwrap(),
            "--cached-only",
        ]);
        assert!(ok, "{err}");
        serde_json::from_str::<serde_json::Value>(&out).unwrap()
    };
    let healthy = dir.join("healthy.csv");
    helical_csv(&healthy, 40.0 * 0.985, 77, 0.0);
    let v = run(&healthy, "40", "High");
    let st = &v["operating_state"];
    assert_eq!(st["source"], "tachometer", "{st}");
    assert!(
        (st["shaft_hz"].as_f64().unwrap() / (40.0 * 0.985) - 1.0).abs() < 0.005,
        "{st}"
    );
    assert_eq!(st["load"], "High");
    assert_eq!(v["state_reference"]["reference"], "same-state", "{v}");
    assert_eq!(v["novelty"]["anomalous"], false, "{}", v["novelty"]);
    assert_eq!(v["findings"].as_array().unwrap().len(), 0);
    assert!(v["wear_degree"].is_null());
    assert!(
        v["warnings"]
            .to_string()
            .contains("covers the records' speeds"),
        "{}",
        v["warnings"]
    );

    let broken = dir.join("broken.csv");
    helical_csv(&broken, 40.0 * 0.985, 78, 4.0);
    let v = run(&broken, "40", "High");
    assert!(
        ["warning", "alarm"].contains(&v["alert"]["level"].as_str().unwrap()),
        "{}",
        v["alert"]
    );
    let f = v["findings"].as_array().unwrap();
    assert!(!f.is_empty(), "{v}");
    // Impacts once per idler revolution: a gear on the idler, with local damage, first.
    assert_eq!(f[0]["kind"], "gear-local-damage", "{v}");
    assert_eq!(f[0]["shaft"], "idler", "{v}");
    for x in f {
        assert!(
            x["kind"].is_string() && x["strength"].as_f64().unwrap() >= 3.0,
            "{x}"
        );
        let share = x["share"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&share), "{x}");
        assert!(!x["evidence"].as_array().unwrap().is_empty(), "{x}");
    }

    let fast = dir.join("fast.csv");
    helical_csv(&fast, 70.0, 79, 0.0);
    let v = run(&fast, "70", "High");
    assert_eq!(v["alert"]["level"], "unknown", "{}", v["alert"]);
    let reason = v["alert"]["reason"].as_str().unwrap();
    assert!(
        reason.contains("load High") && reason.contains("Hz"),
        "{reason}"
    );
    std::fs::remove_dir_all(dir).ok();
}

/// `serve --dashboard-without-key` says what it does; the old `--open-dashboard` still parses
/// (a hidden alias), and an unknown flag does not.
#[test]
fn serve_dashboard_flag_keeps_its_old_name() {
    let (ok, out, _) = gearwear(&["serve", "--help"]);
    assert!(ok && out.contains("--dashboard-without-key"), "{out}");
    assert!(!out.contains("\n      --open-dashboard"), "{out}");
    assert!(gearwear(&["serve", "--open-dashboard", "--help"]).0);
    assert!(!gearwear(&["serve", "--no-such-flag", "--help"]).0);
}

/// `diagnose --gearbox F` without `--table`: a description with no nominal rate gets its table
/// computed over the speed the record ran at, from the cache on the next run, and extended
/// (not recomputed) when a record runs outside it.
#[test]
fn diagnose_computes_the_table_over_the_records_speeds_and_reuses_it() {
    let dir = tmpdir("table-cache");
    let text = std::fs::read_to_string(config("spur-pair.toml")).unwrap();
    let gb = dir.join("cached-pair.toml");
    std::fs::write(
        &gb,
        text.replace("name = \"spur-pair\"", "name = \"cached-pair\"")
            .lines()
            .filter(|l| !l.starts_with("nominal_input_hz"))
            .collect::<Vec<_>>()
            .join("\n"),
    )
    .unwrap();
    let gb = gb.to_str().unwrap().to_string();
    let synth = |hz: &str, name: &str| {
        let out = dir.join(name);
        let (ok, _, err) = gearwear(&[
            "synth",
            "--gearbox",
            &gb,
            "--ea",
            "0.5",
            "--input-hz",
            hz,
            "--output",
            out.to_str().unwrap(),
        ]);
        assert!(ok, "{err}");
        out
    };
    let diagnose = |rec: &std::path::Path, hz: &str| {
        let (ok, out, err) = gearwear(&[
            "diagnose",
            "--gearbox",
            &gb,
            "--input",
            rec.to_str().unwrap(),
            "--shaft-hz",
            hz,
        ]);
        assert!(ok, "{err}");
        (
            serde_json::from_str::<serde_json::Value>(&out).unwrap(),
            err,
        )
    };
    let r20 = synth("20", "r20.wav");
    let (v, err) = diagnose(&r20, "20");
    assert!(err.contains("simulations"), "computed: {err}");
    assert!(v["wear_degree"].is_object(), "{v}");
    assert_eq!(v["gearbox"]["table_status"], "ready", "{v}");
    let (again, err) = diagnose(&r20, "20");
    assert!(!err.contains("simulations"), "reused: {err}");
    assert_eq!(again["wear_degree"], v["wear_degree"]);
    let r27 = synth("27", "r27.wav");
    let (v, err) = diagnose(&r27, "27");
    assert!(err.contains("extending the table"), "{err}");
    assert!(v["wear_degree"].is_object(), "{v}");
}

/// The paper's rig by default is the same machine as its description: no `--gearbox` and
/// `--gearbox configs/gearboxes/wang2019.toml` give the same answer.
#[test]
fn the_paper_rig_by_default_is_its_own_description() {
    let dir = tmpdir("rig-default");
    let rec = dir.join("rig.wav");
    let (ok, _, err) = gearwear(&["synth", "--ea", "0.6", "--output", rec.to_str().unwrap()]);
    assert!(ok, "{err}");
    let run = |extra: &[&str]| {
        let mut args = vec![
            "diagnose",
            "--input",
            rec.to_str().unwrap(),
            "--shaft-hz",
            "30",
        ];
        args.extend_from_slice(extra);
        let (ok, out, err) = gearwear(&args);
        assert!(ok, "{err}");
        serde_json::from_str::<serde_json::Value>(&out).unwrap()
    };
    let plain = run(&[]);
    let described = run(&["--gearbox", &config("wang2019.toml")]);
    assert!(plain["wear_degree"].is_object(), "{plain}");
    assert_eq!(plain, described);
}
