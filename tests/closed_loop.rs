//! The closed loop on virtual-rig records: every library effect is named when (and only when)
//! the record carries it, the error drops and the wear moves toward the truth; an effect outside
//! the library is reported as unexplained, not misattributed; a clean record claims nothing.
//! The effects are configured here only; `calibrate` sees nothing but the record.

use gearwear::closed_loop::virtual_rig::{RigEffects, RigSpec, generate};
use gearwear::closed_loop::{CalibrateOptions, CalibrationReport, calibrate};
use gearwear::signature::SignatureTable;
use gearwear::signature::table::DEFAULT_TABLE_PATH;

const EA: f64 = 0.3;

fn run(effects: RigEffects, seed: u64, gain: f64) -> CalibrationReport {
    let table = SignatureTable::load(std::path::Path::new(DEFAULT_TABLE_PATH)).unwrap();
    let spec = RigSpec {
        ea: EA,
        omega1: 1.0,
        sample_rate: 16000.0,
        duration: 0.6,
        gain,
        snr_db: 20.0,
        seed,
        effects,
    };
    let rec = generate(table.gearbox(), &spec).unwrap();
    calibrate(&rec, &table, &CalibrateOptions::default()).unwrap()
}

fn names(r: &CalibrationReport) -> Vec<&str> {
    r.effects.iter().map(|e| e.name.as_str()).collect()
}

#[test]
fn clean_record_claims_no_effect() {
    let r = run(RigEffects::default(), 2000, 0.03);
    assert!(r.effects.is_empty(), "claimed {:?}", names(&r));
    assert!(
        (r.wear_after.ea - EA).abs() < 0.05,
        "ea {}",
        r.wear_after.ea
    );
}

#[test]
fn eccentricity_is_named_and_fixes_the_wear() {
    let r = run(
        RigEffects {
            eccentricity: Some(0.1),
            ..Default::default()
        },
        2001,
        40.0,
    );
    assert_eq!(names(&r), vec!["shaft-modulation"], "{:?}", r.candidates);
    assert!(
        r.error_after < 0.7 * r.error_before,
        "{} → {}",
        r.error_before,
        r.error_after
    );
    assert!((r.wear_after.ea - EA).abs() <= (r.wear_before.ea - EA).abs() + 0.02);
}

#[test]
fn path_resonance_is_named() {
    let r = run(
        RigEffects {
            resonance: Some((1.6, 0.05)),
            ..Default::default()
        },
        2002,
        1.0,
    );
    assert_eq!(names(&r), vec!["path-resonance"], "{:?}", r.candidates);
    assert!(
        r.error_after < 0.85 * r.error_before,
        "{} → {}",
        r.error_before,
        r.error_after
    );
    assert!((r.wear_after.ea - EA).abs() < (r.wear_before.ea - EA).abs());
}

#[test]
fn planetary_wear_is_named_and_its_clearance_moves_up() {
    let r = run(
        RigEffects {
            planetary: Some(3.0),
            ..Default::default()
        },
        2003,
        5.0,
    );
    assert_eq!(names(&r), vec!["planetary-wear"], "{:?}", r.candidates);
    assert!(
        r.error_after < 0.85 * r.error_before,
        "{} → {}",
        r.error_before,
        r.error_after
    );
    assert!(
        r.wear_after.planetary > 1.0,
        "planetary {}",
        r.wear_after.planetary
    );
    assert!((r.wear_after.ea - EA).abs() < 0.05);
}

#[test]
fn a_tone_outside_the_library_is_unexplained() {
    let r = run(
        RigEffects {
            tone: Some((1.27, -20.0)),
            ..Default::default()
        },
        2004,
        0.2,
    );
    assert!(r.effects.is_empty(), "misattributed to {:?}", names(&r));
    assert!(
        r.unexplained.iter().any(|u| u.kind == "extra"
            && (u.frequency_ratio - 1.27).abs() < 0.02
            && u.size_db > 10.0),
        "{:?}",
        r.unexplained
    );
}
