//! The closed loop on virtual-rig records: every library effect is named when (and only when)
//! the record carries it, the error drops and the wear moves toward the truth; an effect outside
//! the library is reported as unexplained, not misattributed; a clean record claims nothing.
//! The effects are configured here only; `calibrate` sees nothing but the record.

use gearwear_core::closed_loop::virtual_rig::{RigEffects, RigSpec, generate};
use gearwear_core::closed_loop::{CalibrateOptions, CalibrationReport, calibrate};
use gearwear_core::signature::SignatureTable;
use gearwear_core::signature::table::default_table_path;

const EA: f64 = 0.3;

fn run(effects: RigEffects, seed: u64, gain: f64) -> CalibrationReport {
    run_with(effects, seed, gain, None)
}

/// `run` with the input-shaft rate given (Ω1 = 1 is 30 Hz on the paper's rig).
fn run_with(effects: RigEffects, seed: u64, gain: f64, shaft_hz: Option<f64>) -> CalibrationReport {
    let table = SignatureTable::load(&default_table_path()).unwrap();
    let rec = rig_record(&table, effects, seed, gain, 20.0);
    let mut opts = CalibrateOptions::default();
    opts.diagnose.shaft_hz = shaft_hz;
    calibrate(&rec, &table, &opts).unwrap()
}

/// A virtual-rig record at wear [`EA`], Ω1 = 1, 16 kHz, 0.6 s.
fn rig_record(
    table: &SignatureTable,
    effects: RigEffects,
    seed: u64,
    gain: f64,
    snr_db: f64,
) -> gearwear_core::record::Record {
    let spec = RigSpec {
        ea: EA,
        omega1: 1.0,
        sample_rate: 16000.0,
        duration: 0.6,
        gain,
        snr_db,
        seed,
        effects,
    };
    generate(table.gearbox(), &spec).unwrap()
}

fn names(r: &CalibrationReport) -> Vec<&str> {
    r.effects.iter().map(|e| e.name.as_str()).collect()
}

#[test]
fn clean_record_claims_no_effect() {
    let r = run(RigEffects::default(), 2000, 0.03);
    assert!(r.effects.is_empty(), "claimed {:?}", names(&r));
    assert!(
        r.unexplained_in_time.is_empty(),
        "{:?}",
        r.unexplained_in_time
    );
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

/// The two experimental scores (`candidate_seeds`: each candidate's best of the seven initial
/// states; `mean_seeds`: every candidate and "no effect" on its mean spectrum over them) keep
/// the plain answers on the clean and the eccentric record: nothing, and exactly the input
/// shaft's modulation with the error cut.
#[test]
fn the_seeded_scores_keep_the_clean_and_eccentric_answers() {
    let table = SignatureTable::load(&default_table_path()).unwrap();
    let clean = rig_record(&table, RigEffects::default(), 2000, 0.03, 20.0);
    let eccentric = rig_record(
        &table,
        RigEffects {
            eccentricity: Some(0.1),
            ..Default::default()
        },
        2001,
        40.0,
        20.0,
    );
    for (candidate_seeds, mean_seeds) in [(true, false), (false, true)] {
        let opts = CalibrateOptions {
            candidate_seeds,
            mean_seeds,
            ..Default::default()
        };
        let what = format!("candidate_seeds {candidate_seeds}, mean_seeds {mean_seeds}");
        let r = calibrate(&clean, &table, &opts).unwrap();
        assert!(r.effects.is_empty(), "{what}: claimed {:?}", names(&r));
        let r = calibrate(&eccentric, &table, &opts).unwrap();
        assert_eq!(
            names(&r),
            vec!["shaft-modulation"],
            "{what}: {:?}",
            r.candidates
        );
        assert!(
            r.error_after < 0.7 * r.error_before,
            "{what}: {} → {}",
            r.error_before,
            r.error_after
        );
    }
}

/// A low-pass mode at 1.6 f1 is named **at its frequency** (checking the name only would pass
/// with the mode fitted at 0.85 f1). Measured over seeds 2000–2011 of this case, with either grid
/// interpolation alike: the mode is named at 1.6 f1 on 1 of 12 seeds (2010, where the table's
/// wear is right, 0.305). On the others the table reads ea ≈ 0.10 for 0.30, and the
/// record's period-3 lines (0.33, 0.67 f1), which the plain model from its own initial state
/// does not make, are fitted by a peaking mode near 0.86 f1 (named on 5 of 12 seeds with the new
/// interpolation, 4 with the old) or by nothing. Searching the band at every wear of the
/// profile instead of at the best one was tried and changed no answer on those 12 seeds.
#[test]
#[ignore = "not met: a low-pass mode at 1.6 f1 is fitted near 0.86 f1 or not at all on 11 of \
            12 seeds, where the table's wear is wrong and the record sits on an attractor the \
            model's initial state does not reach (docs/closed-loop.md, Session 12)"]
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
    let rho = r.effects[0].parameters["frequency_ratio"];
    assert!((rho / 1.6 - 1.0).abs() < 0.2, "fitted at {rho:.3} f1");
    assert!(
        r.error_after < 0.85 * r.error_before,
        "{} → {}",
        r.error_before,
        r.error_after
    );
    assert!((r.wear_after.ea - EA).abs() < (r.wear_before.ea - EA).abs());
    // A path stage alone: the wear is the table's posterior on the de-coloured record, a
    // continuous estimate with a real interval (its coverage is the benchmark's business: on
    // this record 0.356 [0.309, 0.442] for 0.3, against the coloured record's 0.103 [0.1, 0.852]).
    assert_eq!(r.wear_after.method, "table-posterior-decoloured");
    assert!(
        r.wear_after.ea_lower < r.wear_after.ea
            && r.wear_after.ea < r.wear_after.ea_upper
            && r.wear_after.ea_upper - r.wear_after.ea_lower > 0.02,
        "{:?}",
        r.wear_after
    );
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

#[test]
fn refit_wear_is_continuous_with_a_real_interval() {
    // The eccentricity record of the test above: an element effect is claimed, so the wear is
    // refitted by the profile likelihood.
    let r = run(
        RigEffects {
            eccentricity: Some(0.1),
            ..Default::default()
        },
        2001,
        40.0,
    );
    // The refit (the table's posterior with the effect held fixed), the profile beside it,
    // and the wear after: each continuous with a real interval around the truth.
    let refit = r.wear_refit.expect("an effect is claimed: a refit");
    assert_eq!(refit.method, "table-posterior-effects-held");
    let profile = r.wear_profile.expect("an effect is claimed: a profile");
    assert_eq!(profile.method, "profile-likelihood");
    for w in [&r.wear_after, &refit, &profile] {
        assert!(
            w.ea_lower <= w.ea && w.ea <= w.ea_upper,
            "interval [{}, {}] around {}",
            w.ea_lower,
            w.ea_upper,
            w.ea
        );
        assert!(w.ea_upper - w.ea_lower > 0.005, "{w:?}");
        assert!(w.ea_lower <= EA + 0.02 && EA - 0.02 <= w.ea_upper, "{w:?}");
    }
    // The wear after follows the rule: the refit when it leaves the table's interval, else the
    // table's estimate, confirmed.
    let b = &r.wear_before;
    if (b.ea_lower..=b.ea_upper).contains(&refit.ea) {
        assert_eq!(r.wear_after.method, "table-posterior-confirmed");
        assert_eq!(r.wear_after.ea, b.ea);
    } else {
        assert_eq!(r.wear_after.method, refit.method);
        assert_eq!(r.wear_after.ea, refit.ea);
    }
}

#[test]
#[ignore = "not met by the final selection: the mode is found (fitted at 0.453 f1, ΔBIC -70 in \
            session 14) but moves only 1 of the plain model's lines by more than 3 dB, fewer \
            than MIN_COLOURED_LINES = 2 (docs/closed-loop.md, Weak or missing)"]
fn a_resonance_below_the_mesh_is_named_at_its_frequency() {
    // A peaking mode at 0.45 f1 (Q 10, peak gain 6): far from the old single starting guess.
    // The shaft rate is given: without it the tacho-less f1 search of the diagnosis picked
    // f1/2 on this record (the mode lifts the sub-mesh lines), which is not what this tests.
    let r = run_with(
        RigEffects {
            path_peak: Some((0.45, 0.05, 6.0)),
            ..Default::default()
        },
        2005,
        3.0,
        Some(30.0),
    );
    assert_eq!(names(&r), vec!["path-resonance"], "{:?}", r.candidates);
    let p = &r.effects[0].parameters;
    assert!(
        (p["frequency_ratio"] / 0.45 - 1.0).abs() < 0.05,
        "fitted {p:?}"
    );
    assert!(r.error_after < r.error_before);
}

/// A strong, narrow peaking mode between the lines (the benchmark's seed 32, record 23: 2.16 f1,
/// ζ 0.023, peak gain 8.2, at Ω1 1.3 and 28 dB SNR) lifts the chaotic continuum around it more
/// than any line: most of its improvement lies off the plain model's lines. Its own half-power
/// band holds it (`BandEvidence`), so it is named there. (At Ω1 = 1 the same mode sits on
/// lines and the old rule named it too: this record is the one the band is for.)
#[test]
fn a_mode_between_the_lines_is_named_on_its_band() {
    let table = SignatureTable::load(&default_table_path()).unwrap();
    let spec = RigSpec {
        ea: EA,
        omega1: 1.3,
        sample_rate: 16000.0,
        duration: 0.6,
        gain: 0.035,
        snr_db: 28.0,
        seed: 2011,
        effects: RigEffects {
            path_peak: Some((2.16, 0.023, 8.2)),
            ..Default::default()
        },
    };
    let rec = generate(table.gearbox(), &spec).unwrap();
    let r = calibrate(&rec, &table, &CalibrateOptions::default()).unwrap();
    assert_eq!(names(&r), vec!["path-resonance"], "{:?}", r.candidates);
    let p = &r.effects[0].parameters;
    assert!(
        (p["frequency_ratio"] / 2.16 - 1.0).abs() < 0.03,
        "fitted {p:?}"
    );
    let c = r
        .candidates
        .iter()
        .find(|c| c.name == "path-resonance")
        .unwrap();
    let band = c.band.expect("a resonance candidate carries its band");
    // The plain model's lines alone would not carry it (share 0.03 when this was written).
    assert!(
        c.fingerprint_share < gearwear_core::closed_loop::SUPPORT_SHARE,
        "{c:?}"
    );
    assert!(band.holds(), "{band:?}");
    assert!(c.eligible && c.refused.is_empty(), "{c:?}");
    assert!(
        r.error_after < 0.7 * r.error_before,
        "{} → {}",
        r.error_before,
        r.error_after
    );
}

/// What the loop does with a damaged tooth today (docs/closed-loop.md: tooth damage is rarely
/// named exactly; shaft modulation at the damaged gear's shaft is the usual answer): an element
/// effect at the damaged gear's shaft is claimed and the error drops.
#[test]
fn a_damaged_tooth_is_claimed_at_its_shaft() {
    let table = SignatureTable::load(&default_table_path()).unwrap();
    let gears = gearwear_core::closed_loop::effects::reference_gears(table.gearbox());
    let pinion = &gears[0];
    let r = run(
        RigEffects {
            tooth: Some((pinion.shaft_ratio, 0.6)),
            ..Default::default()
        },
        2006,
        2.0,
    );
    // Named as what it is, on its gear, with a stiffness loss of the right size (the loss is
    // scored over a grid, not read off the comb's lines).
    let tooth = r
        .effects
        .iter()
        .find(|e| e.kind == "element" && e.name == "tooth-damage")
        .unwrap_or_else(|| panic!("no tooth damage in {:?}", r.candidates));
    assert_eq!(tooth.labels.get("shaft"), Some(&pinion.shaft), "{tooth:?}");
    // Its impacts, if the level trace sees them, are the model's now: not unexplained.
    assert!(
        !r.unexplained_in_time.iter().any(|f| f.kind == "impacts"),
        "{:?}",
        r.unexplained_in_time
    );
    let loss = tooth.parameters["stiffness_loss"];
    assert!((0.3..=0.9).contains(&loss), "stiffness loss {loss} for 0.6");
    assert!(r.error_after < r.error_before);
    assert!(
        ["table-posterior-effects-held", "table-posterior-confirmed"]
            .contains(&r.wear_after.method),
        "{:?}",
        r.wear_after
    );
}

/// Noise bursts only raise the spectrum's floor: the level over time reports them (the
/// spectral residual has nothing to say), and no library effect takes them.
#[test]
fn noise_bursts_are_reported_in_time_and_not_claimed() {
    let r = run(
        RigEffects {
            bursts: Some((4, 6.0)),
            ..Default::default()
        },
        2010,
        1.0,
    );
    assert!(r.effects.is_empty(), "misattributed to {:?}", names(&r));
    let b = r
        .unexplained_in_time
        .iter()
        .find(|f| f.kind == "bursts")
        .unwrap_or_else(|| panic!("no bursts in {:?}", r.unexplained_in_time));
    // Four 10 ms bursts 6 dB over the signal: 7 dB in a window inside one, up to 9.5 dB where
    // two overlap (they are placed at random and may touch: then one run).
    assert!((1..=4).contains(&b.times_s.len()), "{b:?}");
    assert!(b.times_s.iter().all(|t| (0.0..=0.6).contains(t)), "{b:?}");
    assert!((4.0..=10.5).contains(&b.size_db), "{b:?}");
}

/// A sensor gain rising by 40 % over the record: a level drift of 20 log10(1.2/0.8) = 3.5 dB
/// (less the half window at each end), unexplained, not claimed.
#[test]
fn a_gain_drift_is_reported_as_a_level_drift() {
    let r = run(
        RigEffects {
            gain_drift: Some(0.4),
            ..Default::default()
        },
        2011,
        1.0,
    );
    assert!(r.effects.is_empty(), "misattributed to {:?}", names(&r));
    let d = r
        .unexplained_in_time
        .iter()
        .find(|f| f.kind == "level-drift")
        .unwrap_or_else(|| panic!("no drift in {:?}", r.unexplained_in_time));
    assert!((d.size_db - 3.5).abs() < 0.7, "{d:?}");
}

#[test]
fn mains_hum_is_unexplained_and_called_electrical_pickup() {
    let r = run(
        RigEffects {
            mains: Some((50.0, -15.0)),
            ..Default::default()
        },
        2007,
        0.5,
    );
    assert!(r.effects.is_empty(), "misattributed to {:?}", names(&r));
    assert!(
        r.unexplained
            .iter()
            .filter(|u| u.guess.contains("mains"))
            .count()
            >= 2,
        "{:?}",
        r.unexplained
    );
}

/// The held-fixed posterior's arithmetic ([`diagnose_shifted`]): no shift and no extra variance
/// is the plain diagnosis bit for bit; a shift of (table mean at 0.3 − table mean at 0.8) makes
/// a clean 0.3 record read like the table's 0.8 (the features are *reduced* by the shift — a
/// sign error would push the estimate the other way, to the grid's low end); a huge extra
/// variance on every feature leaves a wide posterior.
#[test]
fn a_feature_shift_moves_the_table_posterior_the_right_way() {
    use gearwear_core::diagnosis::{DiagnoseOptions, Matcher, diagnose, diagnose_shifted};
    let table = SignatureTable::load(&default_table_path()).unwrap();
    let rec = rig_record(&table, RigEffects::default(), 2010, 1.0, 30.0);
    let opts = DiagnoseOptions::default();
    let plain = diagnose(&rec, &table, &opts).unwrap();
    let nf = table.features.lines.len();
    let zero = vec![0.0; nf];
    let same = diagnose_shifted(&rec, &table, &opts, &zero, &zero).unwrap();
    assert_eq!(same.wear_degree.estimate, plain.wear_degree.estimate);
    assert_eq!(same.wear_degree.lower, plain.wear_degree.lower);
    assert_eq!(same.wear_degree.upper, plain.wear_degree.upper);

    let m = Matcher::new(&table, &opts).unwrap();
    let om = plain.omega1;
    let shift: Vec<f64> = (0..nf)
        .map(|d| m.stats_at(d, EA, om).0 - m.stats_at(d, 0.8, om).0)
        .collect();
    let moved = diagnose_shifted(&rec, &table, &opts, &shift, &zero).unwrap();
    assert!(
        (moved.wear_degree.estimate - 0.8).abs() < 0.1,
        "shifted estimate {} (plain {})",
        moved.wear_degree.estimate,
        plain.wear_degree.estimate
    );

    let vague = diagnose_shifted(&rec, &table, &opts, &zero, &vec![100.0; nf]).unwrap();
    let width = |d: &gearwear_core::diagnosis::Diagnosis| d.wear_degree.upper - d.wear_degree.lower;
    assert!(
        width(&vague) > 2.0 * width(&plain),
        "{} vs {}",
        width(&vague),
        width(&plain)
    );
    // A shift of the wrong length is refused, not truncated.
    assert!(diagnose_shifted(&rec, &table, &opts, &zero[1..], &zero).is_err());
}

/// Speed wander at 0.024 f1 puts frequency-modulation sidebands around the mesh lines one grid
/// step from where the input shaft's (1/29 ≈ 0.0345 f1) would be. At the record's own
/// resolution (0.0018 f1 for 0.6 s) they are found where they are, the effects of that shaft
/// are not claimed, and the extra lines are reported as a speed or load fluctuation.
#[test]
fn speed_wander_is_not_claimed_as_the_input_shafts_modulation() {
    let r = run(
        RigEffects {
            speed_wander: Some((0.013, 0.024)),
            ..Default::default()
        },
        2011,
        1.0,
    );
    let input = r
        .sideband_checks
        .iter()
        .find(|c| (c.shaft_ratio - 1.0 / 29.0).abs() < 1e-9)
        .unwrap_or_else(|| panic!("no check of the input shaft: {:?}", r.sideband_checks));
    assert!(input.off_rate, "{input:?}");
    assert!(
        (input.spacing_ratio - 0.024).abs() < input.resolution_ratio,
        "{input:?}"
    );
    assert!(
        !r.effects
            .iter()
            .any(|e| e.labels.get("shaft") == Some(&input.shaft)),
        "claimed at the input shaft: {:?}",
        r.effects
    );
    // The candidates say why: modulation at the input shaft is refused by the sidebands.
    let at_input: Vec<_> = r
        .candidates
        .iter()
        .filter(|c| {
            c.effects.iter().any(|e| {
                e.name == "shaft-modulation" && e.labels.get("shaft") == Some(&input.shaft)
            })
        })
        .collect();
    assert!(!at_input.is_empty(), "{:?}", r.candidates);
    for c in at_input {
        assert!(
            !c.eligible
                && c.refused
                    .iter()
                    .any(|m| m.contains("not at the shaft's rate")),
            "{c:?}"
        );
    }
    assert!(
        r.unexplained.iter().any(|u| u.guess.contains("fluctuates")),
        "{:?}",
        r.unexplained
    );
}

/// Modulation at the stage-1 gear's shaft (f1/100: its sidebands 1.3 grid steps from the
/// carrier, inside its main lobe on the grid) is named at that shaft, with its amplitude scored
/// over a grid rather than read off lines the grid cannot separate.
#[test]
fn a_slow_shafts_modulation_is_named_at_its_shaft() {
    let table = SignatureTable::load(&default_table_path()).unwrap();
    let gears = gearwear_core::closed_loop::effects::reference_gears(table.gearbox());
    let gear = &gears[1];
    assert!((gear.shaft_ratio - 0.01).abs() < 1e-9);
    let r = run(
        RigEffects {
            eccentricity: Some(0.15),
            eccentricity_shaft: Some(gear.shaft_ratio),
            ..Default::default()
        },
        2012,
        3.0,
    );
    let m = r
        .effects
        .iter()
        .find(|e| e.name == "shaft-modulation")
        .unwrap_or_else(|| panic!("not named: {:?}", r.candidates));
    assert_eq!(m.labels.get("shaft"), Some(&gear.shaft), "{m:?}");
    let a = m.parameters["sideband_amplitude_b"];
    assert!((0.06..=0.4).contains(&a), "amplitude {a} for 0.15");
    assert!(r.error_after < r.error_before);
}

/// A pair whose resonance (0.39 f1, Q ≈ 9.5, peak gain 5.8) a search on the plain model does not
/// find — there it fits the modulation's sidebands instead — is found by the search run again
/// on top of the modulation's spectrum, and both members are named (the benchmark's record 5
/// of seed 7; before, only the modulation was named and the error went 5.7 → 3.2 dB).
#[test]
fn a_pairs_resonance_is_searched_beside_its_element() {
    let table = SignatureTable::load(&default_table_path()).unwrap();
    let spec = RigSpec {
        ea: 0.9766941446745643,
        omega1: 1.5764878589060372,
        sample_rate: 16000.0,
        duration: 0.6,
        gain: 1.248527120145213,
        snr_db: 27.0991501975534,
        seed: 4765784394135412812,
        effects: RigEffects {
            eccentricity: Some(0.16085544260648924),
            eccentricity_shaft: Some(0.034482758620689655),
            path_peak: Some((
                0.38856302059208825,
                0.052851078667080505,
                5.8014959605400955,
            )),
            ..Default::default()
        },
    };
    let rec = generate(table.gearbox(), &spec).unwrap();
    let r = calibrate(&rec, &table, &CalibrateOptions::default()).unwrap();
    let mut n = names(&r);
    n.sort();
    assert_eq!(
        n,
        vec!["path-resonance", "shaft-modulation"],
        "{:?}",
        r.candidates
    );
    let res = r
        .effects
        .iter()
        .find(|e| e.name == "path-resonance")
        .unwrap();
    let rho = res.parameters["frequency_ratio"];
    assert!(
        (rho / 0.3886 - 1.0).abs() < 0.2,
        "resonance at {rho} f1 for 0.389"
    );
    assert!(
        r.error_after < 0.5 * r.error_before,
        "{} → {}",
        r.error_before,
        r.error_after
    );
}
