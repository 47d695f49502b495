//! Wear read through a machine's calibrated transfer path: the paper's rig seen through a
//! housing mode fixed in Hz and an unknown gain, healthy at five speeds, then worn. The
//! calibration sees only the healthy records' diagnoses; the path is configured here only.

use std::collections::BTreeMap;

use gearwear_core::assessment::{
    Baselines, Machine, RecordFacts, TableDiagnoser, TachoChannel, assess, baseline_features,
};
use gearwear_core::closed_loop::virtual_rig::{RigEffects, RigSpec, generate, tachometer};
use gearwear_core::diagnosis::machine_path::{LineRatios, PathCalibration};
use gearwear_core::diagnosis::{DiagnoseOptions, diagnose};
use gearwear_core::error::Error;
use gearwear_core::signature::SignatureTable;
use gearwear_core::signature::table::default_table_path;

/// A record at wear `ea` and speed `omega1` through a peaking mode at 1.3 × the reference
/// mesh frequency (ζ 0.05, peak gain `peak`), gain 37, 25 dB SNR, 16 kHz, 0.6 s.
fn record(
    table: &SignatureTable,
    ea: f64,
    omega1: f64,
    peak: f64,
    seed: u64,
) -> (gearwear_core::record::Record, DiagnoseOptions) {
    let gb = table.gearbox();
    let f_ref = gb.reference_frequency_hz();
    let spec = RigSpec {
        ea,
        omega1,
        sample_rate: 16_000.0,
        duration: 0.6,
        gain: 37.0,
        snr_db: 25.0,
        seed,
        effects: RigEffects {
            path_peak: Some((1.3 / omega1, 0.05, peak)),
            ..Default::default()
        },
    };
    let opts = DiagnoseOptions {
        shaft_hz: Some(omega1 * f_ref / gb.f1_per_input_hz),
        ..Default::default()
    };
    (generate(gb, &spec).unwrap(), opts)
}

fn calibration(table: &SignatureTable, peak: f64) -> Result<PathCalibration, Error> {
    let mut healthy = Vec::new();
    for (i, om) in [0.7, 0.85, 1.0, 1.15, 1.3].into_iter().enumerate() {
        for k in 0..2 {
            let (r, o) = record(table, 0.1, om, peak, 500 + (2 * i + k) as u64);
            healthy.push(LineRatios::of(&diagnose(&r, table, &o).unwrap()));
        }
    }
    PathCalibration::fit(table, &DiagnoseOptions::default(), &healthy)
}

/// Through a strong mode (+24 dB) the plain table misreads the wear; through the calibrated
/// path it gives a figure on at least five of six records, each within 0.1 and closer on
/// average, with the truth inside most intervals; the path's left-out residual is far below
/// the plain model's.
#[test]
fn wear_is_read_through_the_calibrated_path() {
    let table = SignatureTable::load(&default_table_path()).unwrap();
    let cal = calibration(&table, 15.0).unwrap();
    assert!(
        cal.residual_after_db < 0.5 * cal.residual_before_db,
        "{} vs {}",
        cal.residual_after_db,
        cal.residual_before_db
    );
    let (mut plain_err, mut cal_err, mut inside, mut given) = (0.0, 0.0, 0, 0);
    let cases = [
        (0.25, 0.8),
        (0.4, 1.2),
        (0.55, 0.95),
        (0.7, 1.1),
        (0.85, 0.9),
        (0.95, 1.05),
    ];
    for (i, (ea, om)) in cases.into_iter().enumerate() {
        let (r, o) = record(&table, ea, om, 15.0, 900 + i as u64);
        let p = diagnose(&r, &table, &o).unwrap().wear_degree;
        let c = cal.diagnose(&r, &table, &o).unwrap().wear_degree;
        if c.withheld.is_some() {
            continue;
        }
        given += 1;
        assert!((c.estimate - ea).abs() < 0.1, "ea {ea}: {c:?}");
        plain_err += (p.estimate - ea).abs();
        cal_err += (c.estimate - ea).abs();
        inside += (c.lower <= ea && ea <= c.upper) as usize;
    }
    assert!(given >= 5, "{given}/6");
    assert!(cal_err < plain_err, "{cal_err} vs {plain_err}");
    assert!(inside >= 4, "{inside}/{given}");
}

/// Healthy records at one speed cannot separate the path from the lines: refused.
#[test]
fn one_speed_is_refused() {
    let table = SignatureTable::load(&default_table_path()).unwrap();
    let healthy: Vec<_> = (0..4)
        .map(|k| {
            let (r, o) = record(&table, 0.1, 1.0, 5.0, 700 + k);
            LineRatios::of(&diagnose(&r, &table, &o).unwrap())
        })
        .collect();
    let e = PathCalibration::fit(&table, &DiagnoseOptions::default(), &healthy).unwrap_err();
    assert!(matches!(e, Error::BaselineTooSmall { .. }), "{e}");
}

/// The record's vibration channel and a 10-pulse tachometer at the rig's shaft rate, as a
/// machine sends them, with their facts.
fn channels(
    r: &gearwear_core::record::Record,
    o: &DiagnoseOptions,
    healthy: bool,
) -> (Vec<(String, Vec<f64>)>, RecordFacts) {
    let shaft_hz = o.shaft_hz.unwrap();
    let tach = tachometer(r.samples.len(), r.sample_rate, shaft_hz, 10);
    let facts = RecordFacts {
        sample_rate_hz: r.sample_rate,
        shaft_hz: Some(shaft_hz),
        declared_healthy: healthy,
        tacho: Some(TachoChannel {
            name: "tach".into(),
            pulses_per_rev: 10,
        }),
        ..Default::default()
    };
    (
        vec![("a1".into(), r.samples.clone()), ("tach".into(), tach)],
        facts,
    )
}

/// The product's door reads the same: a machine whose baseline is the healthy records (posted
/// with a tachometer) calibrates its channel's path, and its assessment of a worn record gives
/// the wear the library's calibrated reading gives.
#[test]
fn the_assessment_reads_the_wear_through_the_machines_path() {
    let table = SignatureTable::load(&default_table_path()).unwrap();
    let d = TableDiagnoser::new(table.clone(), DiagnoseOptions::default()).unwrap();
    let empty = Baselines::default();
    let m0 = Machine::described("rig", table.gearbox(), Some(&d), &empty);
    let mut feats = Vec::new();
    let mut healthy = Vec::new();
    for (i, om) in [0.7, 0.85, 1.0, 1.15, 1.3].into_iter().enumerate() {
        for k in 0..2 {
            let (r, o) = record(&table, 0.1, om, 15.0, 500 + (2 * i + k) as u64);
            healthy.push(LineRatios::of(&diagnose(&r, &table, &o).unwrap()));
            let (mut ch, facts) = channels(&r, &o, true);
            feats.push(
                baseline_features(&mut ch, &[0], &facts, &m0)
                    .unwrap()
                    .remove(0),
            );
        }
    }
    let cal = PathCalibration::fit(&table, &DiagnoseOptions::default(), &healthy).unwrap();
    let by_channel = BTreeMap::from([("a1".to_string(), feats)]);
    let b = Baselines::fit(&by_channel).with_paths(&by_channel, Some(&d));
    assert!(b.paths.contains_key("a1"), "{:?}", b.path_refusals);
    let m = Machine::described("rig", table.gearbox(), Some(&d), &b);
    for (i, (ea, om)) in [(0.4, 1.2), (0.7, 1.1)].into_iter().enumerate() {
        let (r, o) = record(&table, ea, om, 15.0, 900 + i as u64);
        let lib = cal.diagnose(&r, &table, &o).unwrap().wear_degree;
        let (mut ch, facts) = channels(&r, &o, false);
        let a = assess(&mut ch, &[0], &facts, &m, &mut |_| {}).unwrap();
        let w = a.wear().expect("a wear figure");
        assert!(
            (w.estimate - lib.estimate).abs() < 0.02,
            "ea {ea}: {w:?} vs {lib:?}"
        );
        assert!((w.estimate - ea).abs() < 0.1, "ea {ea}: {w:?}");
    }
}
