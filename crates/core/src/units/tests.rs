//! Units, their conversion, the vibration figures in each unit, the ISO 20816-3 zones.

use std::collections::BTreeMap;
use std::f64::consts::{SQRT_2, TAU};

use super::*;
use crate::gearbox::Gearbox;

const FS: f64 = 25_600.0;

/// A physical sine of amplitude `amp` (SI: m/s² or m/s) as a sensor in `spec` records it, 1 s
/// at 25.6 kHz, with the acceleration's crests on samples (100, and every period after: the
/// sampled peak is the sine's).
fn recorded(spec: &UnitSpec, f: f64, amp: f64) -> Vec<f64> {
    let unit = spec.resolve().unwrap();
    // An acceleration peaks where its phase is π/2; a velocity's derivative where it is 0.
    let phase = match unit.quantity {
        Kinematic::Acceleration => std::f64::consts::FRAC_PI_2,
        Kinematic::Velocity => 0.0,
    };
    (0..25_600)
        .map(|i| amp * (TAU * f * (i as f64 - 100.0) / FS + phase).sin())
        .map(|x| x / unit.to_si)
        .collect()
}

/// Every unit a channel may declare, with what its samples measure.
fn every_unit() -> Vec<(UnitSpec, Kinematic)> {
    vec![
        (UnitSpec::plain("g"), Kinematic::Acceleration),
        (UnitSpec::plain("m/s²"), Kinematic::Acceleration),
        (UnitSpec::plain("m/s^2"), Kinematic::Acceleration),
        (UnitSpec::plain("mm/s"), Kinematic::Velocity),
        (UnitSpec::volts(100.0, Per::G), Kinematic::Acceleration),
        (
            UnitSpec::volts(10.2, Per::MetrePerSecondSquared),
            Kinematic::Acceleration,
        ),
        (
            UnitSpec::volts(20.0, Per::MillimetrePerSecond),
            Kinematic::Velocity,
        ),
    ]
}

#[test]
fn each_unit_converts_to_si_by_its_factor() {
    let si = |s: UnitSpec| s.resolve().unwrap();
    assert_eq!(si(UnitSpec::plain("g")).to_si, 9.806_65);
    assert_eq!(si(UnitSpec::plain("m/s2")).to_si, 1.0);
    assert_eq!(si(UnitSpec::plain("mm/s")).to_si, 1e-3);
    // 100 mV/g: 1 V is 10 g.
    assert!((si(UnitSpec::volts(100.0, Per::G)).to_si - 98.0665).abs() < 1e-12);
    // 10.2 mV/(m/s²): 1 V is 98.04 m/s².
    let c = si(UnitSpec::volts(10.2, Per::MetrePerSecondSquared));
    assert!((c.to_si - 1000.0 / 10.2).abs() < 1e-12);
    // 20 mV/(mm/s): 1 V is 50 mm/s = 0.05 m/s.
    let c = si(UnitSpec::volts(20.0, Per::MillimetrePerSecond));
    assert!((c.to_si - 0.05).abs() < 1e-15 && c.quantity == Kinematic::Velocity);
}

/// The target in every unit: the velocity RMS of a sine recorded in that unit
/// within 2 % of the analytic value at 10, 100 and 1000 Hz (0.01 % at 100 and 1000 Hz), and
/// the acceleration's RMS and peak in m/s² and in g.
#[test]
fn a_sine_in_every_unit_gives_its_analytic_figures() {
    let class = IsoClass::new(2, "rigid").unwrap();
    for (spec, q) in every_unit() {
        for f in [10.0, 100.0, 1000.0] {
            // A velocity of 2.5 mm/s RMS (zone B for group 2 rigid), as an acceleration or a
            // velocity.
            let v_rms = 2.5e-3;
            let (amp, a_amp) = match q {
                Kinematic::Acceleration => (v_rms * SQRT_2 * TAU * f, v_rms * SQRT_2 * TAU * f),
                Kinematic::Velocity => (v_rms * SQRT_2, v_rms * SQRT_2 * TAU * f),
            };
            let x = recorded(&spec, f, amp);
            let unit = spec.resolve().unwrap();
            let vib = vibration(&x, FS, &spec, &unit, Some(class)).unwrap();
            let v = vib.velocity_rms_mm_s.unwrap();
            let e = v / 2.5 - 1.0;
            println!(
                "{:?} at {f} Hz: velocity {v:.5} mm/s ({:+.4} %)",
                spec,
                100.0 * e
            );
            let bound = if f == 10.0 { 0.02 } else { 1e-4 };
            assert!(e.abs() < bound, "{spec:?} {f} Hz: {e}");
            let tol = if q == Kinematic::Velocity { 2e-3 } else { 1e-9 };
            assert!((vib.acceleration_rms_m_s2 / (a_amp / SQRT_2) - 1.0).abs() < tol);
            assert!((vib.acceleration_peak_m_s2 / a_amp - 1.0).abs() < tol);
            assert!(
                (vib.acceleration_rms_g * STANDARD_GRAVITY / vib.acceleration_rms_m_s2 - 1.0).abs()
                    < 1e-12
            );
            let zone = vib.iso_20816_3.unwrap();
            assert_eq!((zone.zone, zone.group), (Zone::B, 2));
            assert_eq!(vib.velocity_band_hz, [10.0, 1000.0]);
        }
    }
}

#[test]
fn the_vibration_object_says_why_a_record_has_no_velocity() {
    let spec = UnitSpec::plain("g");
    let unit = spec.resolve().unwrap();
    let short = vec![0.1, -0.2, 0.3, 0.0, 0.5, -0.1];
    let vib = vibration(&short, FS, &spec, &unit, IsoClass::new(1, "flexible").ok()).unwrap();
    assert_eq!(vib.velocity_rms_mm_s, None);
    assert!(vib.iso_20816_3.is_none());
    assert!(
        vib.velocity_note
            .as_deref()
            .unwrap()
            .contains("needs at least 0.500 s"),
        "{vib:?}"
    );
    let json = serde_json::to_value(&vib).unwrap();
    assert_eq!(json["unit"], "g");
    assert!(json["velocity_rms_mm_s"].is_null() && json.get("iso_20816_3").is_none());
    assert!(json.get("sensitivity_mv_per_g").is_none());
}

#[test]
fn units_that_cannot_be_converted_are_refused_with_what_to_write() {
    let refuse = |s: UnitSpec| s.resolve().unwrap_err();
    assert_eq!(
        refuse(UnitSpec::plain("in/s")),
        UnitError::Unknown {
            unit: "in/s".into()
        }
    );
    for d in ["µm", "um", "mm", "mil"] {
        let e = refuse(UnitSpec::plain(d));
        assert_eq!(e, UnitError::Displacement { unit: d.into() });
        assert!(e.to_string().contains("proximity probe"), "{e}");
    }
    assert_eq!(refuse(UnitSpec::plain("V")), UnitError::NoSensitivity);
    let e = refuse(UnitSpec {
        unit: "g".into(),
        ..UnitSpec::volts(100.0, Per::G)
    });
    assert_eq!(
        e,
        UnitError::SensitivityWithoutVolts {
            unit: "g".into(),
            value: 100.0,
            per: "g"
        }
    );
    assert!(e.to_string().contains("100 mV/g"), "{e}");
    let two = UnitSpec {
        sensitivity_mv_per_mm_s: Some(5.0),
        ..UnitSpec::volts(100.0, Per::G)
    };
    assert_eq!(
        refuse(two),
        UnitError::TwoSensitivities {
            first: "g",
            second: "(mm/s)"
        }
    );
    for bad in [0.0, -10.0, f64::NAN, f64::INFINITY, 2e6] {
        match refuse(UnitSpec::volts(bad, Per::G)) {
            UnitError::BadSensitivity { per: "g", .. } => {}
            other => panic!("{bad}: {other:?}"),
        }
    }
}

#[test]
fn sensitivities_are_read_as_written_on_a_sensor_sheet() {
    assert_eq!(parse_sensitivity("100mV/g"), Ok((100.0, Per::G)));
    assert_eq!(
        parse_sensitivity("10.2 mV/(m/s²)"),
        Ok((10.2, Per::MetrePerSecondSquared))
    );
    assert_eq!(
        parse_sensitivity("10.2mV/m/s^2"),
        Ok((10.2, Per::MetrePerSecondSquared))
    );
    assert_eq!(
        parse_sensitivity("20mV/(mm/s)"),
        Ok((20.0, Per::MillimetrePerSecond))
    );
    for bad in ["100", "100 V/g", "mV/g", "1e2mV/kg", ""] {
        assert!(parse_sensitivity(bad).is_err(), "{bad}");
    }
}

#[test]
fn a_channel_takes_its_own_unit_else_every_channel_s() {
    let mut specs = BTreeMap::new();
    specs.insert("a1".to_string(), UnitSpec::volts(100.0, Per::G));
    specs.insert(ANY_CHANNEL.to_string(), UnitSpec::plain("g"));
    let units = ChannelUnits::new(specs.clone()).unwrap();
    assert_eq!(units.of("a1").unwrap().0, UnitSpec::volts(100.0, Per::G));
    assert_eq!(units.of("a2").unwrap().0, UnitSpec::plain("g"));
    assert_eq!(units.specs(), specs);
    specs.remove(ANY_CHANNEL);
    let only = ChannelUnits::new(specs.clone()).unwrap();
    assert!(only.of("a2").is_none());
    specs.insert("b".into(), UnitSpec::plain("furlong"));
    assert_eq!(
        ChannelUnits::new(specs).unwrap_err(),
        (
            "b".to_string(),
            UnitError::Unknown {
                unit: "furlong".into()
            }
        )
    );
}

/// Every boundary of ISO 20816-3's Tables A.1 and A.2: just below it is the lower zone, on it
/// the higher.
#[test]
fn iso_zones_follow_the_standard_s_boundaries() {
    let table = [
        (1, "rigid", [2.3, 4.5, 7.1]),
        (1, "flexible", [3.5, 7.1, 11.0]),
        (2, "rigid", [1.4, 2.8, 4.5]),
        (2, "flexible", [2.3, 4.5, 7.1]),
    ];
    for (group, support, bounds) in table {
        let c = IsoClass::new(group, support).unwrap();
        let b = c.boundaries();
        assert_eq!([b.a_b, b.b_c, b.c_d], bounds);
        let zones = [Zone::A, Zone::B, Zone::C, Zone::D];
        assert_eq!(c.zone(0.0).zone, Zone::A);
        for (i, v) in bounds.iter().enumerate() {
            assert_eq!(c.zone(v - 1e-9).zone, zones[i], "{group} {support} {v}");
            assert_eq!(c.zone(*v).zone, zones[i + 1], "{group} {support} {v}");
        }
        assert_eq!(c.zone(1e3).zone, Zone::D);
    }
    let z = IsoClass::new(2, "rigid").unwrap().zone(3.0);
    let json = serde_json::to_value(&z).unwrap();
    assert_eq!(json["zone"], "C");
    assert_eq!(json["support"], "rigid");
    assert_eq!(json["boundaries_mm_s"]["c_d"], 4.5);
    assert!(json["meaning"].as_str().unwrap().contains("limited period"));
    assert_eq!(
        IsoClass::new(3, "rigid"),
        Err(UnitError::IsoGroup { group: 3 })
    );
    assert_eq!(
        IsoClass::new(1, "soft"),
        Err(UnitError::IsoSupport {
            support: "soft".into()
        })
    );
}

/// The wear degree in µm is in each gearbox's own reference length.
#[test]
fn the_wear_in_um_uses_the_gearbox_s_reference_length() {
    let wear = crate::diagnosis::WearDegree {
        estimate: 0.6,
        lower: 0.5,
        upper: 0.7,
        level: 0.9,
        mode: 0.6,
        withheld: None,
    };
    let paper = Gearbox::paper_rig();
    let um = WearUm::of(&wear, &paper).unwrap();
    assert_eq!(um.reference_length_um, 5.0);
    assert!((um.estimate - 3.0).abs() < 1e-12 && (um.upper - 3.5).abs() < 1e-12);
    // A description without reference_length_um is in 5 µm; one with it, in its own.
    let spur = include_str!("../../../../configs/gearboxes/spur-pair.toml");
    assert!(!spur.contains("reference_length_um"));
    let plain = Gearbox::parse(spur, "spur").unwrap();
    assert_eq!(WearUm::of(&wear, &plain).unwrap().reference_length_um, 5.0);
    let eight = Gearbox::parse(
        &spur.replacen("[[stage]]", "reference_length_um = 8.0\n\n[[stage]]", 1),
        "spur",
    )
    .unwrap();
    let um = WearUm::of(&wear, &eight).unwrap();
    assert_eq!(um.reference_length_um, 8.0);
    assert!((um.lower - 4.0).abs() < 1e-12);
    assert_eq!(eight.physics.length_ref_m, 8e-6);
    let withheld = crate::diagnosis::WearDegree {
        withheld: Some(crate::diagnosis::Withheld {
            reason: crate::diagnosis::WithheldReason::PoorFit,
            note: "no fit".into(),
        }),
        ..wear
    };
    assert!(WearUm::of(&withheld, &paper).is_none());
}
