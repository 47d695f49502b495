//! The documented steps of docs/gearbox.md for each committed description besides the paper's
//! rig: describe, kinematics, precompute a small table, synthesise a record, diagnose it, close
//! the loop on it (`calibrate --gearbox`).

use std::process::Command;

fn gearwear(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_gearwear"))
        .args(args)
        .output()
        .expect("binary runs");
    assert!(
        out.status.success(),
        "gearwear {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn config(name: &str) -> String {
    format!(
        "{}/configs/gearboxes/{name}.toml",
        env!("CARGO_MANIFEST_DIR")
    )
}

/// A small table (4 wear degrees × 2 speeds × 1 seed, 128 periods), a record at ea = 0.7 and
/// 25 Hz, and its diagnosis with the speed given.
fn round_trip(name: &str) {
    let dir = std::env::temp_dir().join(format!("gearwear-gb-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let g = config(name);
    let table = dir.join("table.json");
    let rec = dir.join("rec.wav");
    let show: serde_json::Value =
        serde_json::from_str(&gearwear(&["gearbox", "show", "--gearbox", &g])).unwrap();
    assert_eq!(show["name"], name);
    let kin: serde_json::Value = serde_json::from_str(&gearwear(&[
        "gearbox",
        "kinematics",
        "--gearbox",
        &g,
        "--input-hz",
        "25",
    ]))
    .unwrap();
    let f1 = kin["meshes"][0]["hz"].as_f64().unwrap();
    gearwear(&[
        "precompute",
        "--gearbox",
        &g,
        "--ea",
        "0.1:1:0.3",
        "--input-hz",
        "24:26:2",
        "--seeds",
        "1",
        "--periods",
        "128",
        "--fresh",
        "--output",
        table.to_str().unwrap(),
    ]);
    gearwear(&[
        "synth",
        "--gearbox",
        &g,
        "--ea",
        "0.7",
        "--input-hz",
        "25",
        "--output",
        rec.to_str().unwrap(),
    ]);
    let d: serde_json::Value = serde_json::from_str(&gearwear(&[
        "diagnose",
        "--gearbox",
        &g,
        "--table",
        table.to_str().unwrap(),
        "--input",
        rec.to_str().unwrap(),
        "--shaft-hz",
        "25",
    ]))
    .unwrap();
    let est = d["wear_degree"]["estimate"].as_f64().unwrap();
    assert!((0.1..=1.0).contains(&est), "{name}: {d}");
    let got_f1 = d["f1_hz"].as_f64().unwrap();
    assert!(
        (got_f1 / f1 - 1.0).abs() < 0.005,
        "{name}: f1 {got_f1} vs {f1}"
    );
    // The closed loop runs on this gearbox: the model error does not grow and the refitted
    // wear is a number with an interval around it.
    let c: serde_json::Value = serde_json::from_str(&gearwear(&[
        "calibrate",
        "--gearbox",
        &g,
        "--table",
        table.to_str().unwrap(),
        "--input",
        rec.to_str().unwrap(),
        "--shaft-hz",
        "25",
    ]))
    .unwrap();
    let (before, after) = (
        c["error_before"].as_f64().unwrap(),
        c["error_after"].as_f64().unwrap(),
    );
    assert!(after <= before + 1e-9, "{name}: error {before} → {after}");
    let w = &c["wear_after"];
    let (ea, lo, hi) = (
        w["ea"].as_f64().unwrap(),
        w["ea_lower"].as_f64().unwrap(),
        w["ea_upper"].as_f64().unwrap(),
    );
    assert!(
        lo <= ea && ea <= hi && (0.1..=1.0).contains(&ea),
        "{name}: {w}"
    );
    // The table of another gearbox is refused as stale.
    let other = if name == "spur-pair" {
        "two-stage-parallel"
    } else {
        "spur-pair"
    };
    let out = Command::new(env!("CARGO_BIN_EXE_gearwear"))
        .args([
            "diagnose",
            "--gearbox",
            &config(other),
            "--table",
            table.to_str().unwrap(),
            "--input",
            rec.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("stale"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn spur_pair_end_to_end() {
    round_trip("spur-pair");
}

#[test]
fn two_stage_parallel_end_to_end() {
    round_trip("two-stage-parallel");
}

#[test]
fn planetary_sun_in_end_to_end() {
    round_trip("planetary-sun-in");
}
