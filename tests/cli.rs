//! The built binary, run as a user would.

use std::process::Command;

fn gearwear(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_gearwear"))
        .args(args)
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
