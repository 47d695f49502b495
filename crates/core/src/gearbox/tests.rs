use super::*;
use crate::model::DimensionlessModel;

fn parse(text: &str) -> Result<Gearbox, GearboxError> {
    Gearbox::parse(text, "test")
}

fn close(a: f64, b: f64, rel: f64) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()).max(1e-300)
}

const HEADER: &str = "format = \"gearwear-gearbox\"\nversion = 1\nname = \"t\"\n";

#[test]
fn paper_rig_table_2() {
    let gb = Gearbox::paper_rig();
    let k = gb.kinematics(30.0);
    assert_eq!(k.meshes.len(), 3);
    assert!(close(k.meshes[0].hz, 870.0, 1e-14));
    // Table 2: f2/f1 = 0.3599 (0.36 exact), f3/f1 = 0.0877 (0.0875 exact).
    assert!(close(k.meshes[1].hz / k.meshes[0].hz, 0.36, 1e-12));
    assert!(close(k.meshes[2].hz / k.meshes[0].hz, 0.0875, 1e-12));
    assert!(close(gb.mesh_ratios[1], 0.36, 1e-14) && close(gb.mesh_ratios[2], 0.0875, 1e-14));
    // Shafts: B = 30·29/100, C = B·36/90, carrier = C·28/128.
    assert!(close(k.shafts["B"], 8.7, 1e-14));
    assert!(close(k.shafts["C"], 3.48, 1e-14));
    assert!(close(k.shafts["output"], 3.48 * 28.0 / 128.0, 1e-14));
    assert_eq!(k.shaft_directions["B"], -1);
    assert_eq!(k.shaft_directions["C"], 1);
    let p = &k.planetary[0];
    assert!(close(p.planet_spin_hz, k.meshes[2].hz / 36.0, 1e-14));
    assert!(close(p.planet_pass_hz, 4.0 * p.carrier_hz, 1e-14));
    assert!(close(
        k.reduction,
        (100.0 / 29.0) * (90.0 / 36.0) * (128.0 / 28.0),
        1e-12
    ));
}

#[test]
fn three_stage_parallel_box_by_hand() {
    let text = format!(
        "{HEADER}input_shaft = \"in\"\n\
         [[stage]]\nkind = \"parallel\"\npinion = {{ shaft = \"in\", teeth = 20 }}\ngear = {{ shaft = \"a\", teeth = 60 }}\n\
         [[stage]]\nkind = \"parallel\"\npinion = {{ shaft = \"a\", teeth = 15 }}\ngear = {{ shaft = \"b\", teeth = 45 }}\n\
         [[stage]]\nkind = \"parallel\"\npinion = {{ shaft = \"b\", teeth = 12 }}\ngear = {{ shaft = \"out\", teeth = 48 }}\n"
    );
    let gb = parse(&text).unwrap();
    let k = gb.kinematics(50.0);
    // in 50 Hz → a 50·20/60 = 16.667 → b 16.667·15/45 = 5.556 → out 5.556·12/48 = 1.389.
    assert!(close(k.shafts["a"], 50.0 / 3.0, 1e-14));
    assert!(close(k.shafts["b"], 50.0 / 9.0, 1e-14));
    assert!(close(k.shafts["out"], 50.0 / 36.0, 1e-14));
    assert!(close(k.meshes[0].hz, 1000.0, 1e-14));
    assert!(close(k.meshes[1].hz, 250.0, 1e-14));
    assert!(close(k.meshes[2].hz, 200.0 / 3.0, 1e-14));
    assert_eq!(k.shaft_directions["out"], -1);
    // Hunting tooth: 1000·gcd(20,60)/(20·60) = 1000/60.
    assert!(close(
        k.meshes[0].hunting_tooth_hz.unwrap(),
        1000.0 / 60.0,
        1e-14
    ));
    assert_eq!(k.output_shaft, "out");
    assert!(close(k.reduction, 36.0, 1e-12));
    assert!(gb.dynamics_estimated());
    assert!(gb.assumed.iter().any(|a| a.what == "stage 1 pinion module"));
}

fn planetary(fixed: &str, sun: &str, ring: &str, carrier: &str, input: &str) -> String {
    format!(
        "{HEADER}input_shaft = \"{input}\"\n\
         [[stage]]\nkind = \"planetary\"\nsun = {{ {sun}teeth = 24 }}\nplanets = {{ count = 3, teeth = 18 }}\n\
         ring = {{ {ring}teeth = 60 }}\ncarrier = {{ {carrier} }}\nfixed = \"{fixed}\"\n"
    )
}

#[test]
fn planetary_fixed_ring_by_hand() {
    let gb = parse(&planetary(
        "ring",
        "shaft = \"s\", ",
        "",
        "shaft = \"c\"",
        "s",
    ))
    .unwrap();
    let k = gb.kinematics(42.0);
    // n_c = 42·24/84 = 12; f_m = 24·(42 − 12) = 720 = 60·|0 − 12|.
    assert!(close(k.shafts["c"], 12.0, 1e-14));
    assert!(close(k.meshes[0].hz, 720.0, 1e-14));
    let p = &k.planetary[0];
    assert!(close(p.planet_spin_hz, 40.0, 1e-14));
    assert!(close(p.planet_pass_hz, 36.0, 1e-14));
    assert!(close(p.sun_tooth_defect_hz, 3.0 * 720.0 / 24.0, 1e-14));
    assert!(close(p.ring_tooth_defect_hz, 3.0 * 720.0 / 60.0, 1e-14));
    assert!(close(k.reduction, 3.5, 1e-14));
    assert_eq!(k.shaft_directions["c"], 1);
    // A planetary-only box wears on its own stage (no parallel stage).
    assert_eq!(gb.wear_stages(), vec![1]);
}

#[test]
fn star_stage_fixed_carrier_by_hand() {
    let gb = parse(&planetary(
        "carrier",
        "shaft = \"s\", ",
        "shaft = \"r\", ",
        "",
        "s",
    ))
    .unwrap();
    let k = gb.kinematics(30.0);
    // n_r = −30·24/60 = −12; f_m = 24·30 = 720.
    assert!(close(k.shafts["r"], 12.0, 1e-14));
    assert_eq!(k.shaft_directions["r"], -1);
    assert!(close(k.meshes[0].hz, 720.0, 1e-14));
    assert!(close(k.planetary[0].planet_pass_hz, 3.0 * 12.0, 1e-14));
}

#[test]
fn sun_fixed_and_carrier_input() {
    let gb = parse(&planetary(
        "sun",
        "",
        "shaft = \"r\", ",
        "shaft = \"c\"",
        "c",
    ))
    .unwrap();
    let k = gb.kinematics(10.0);
    // n_r = n_c (zs + zr)/zr = 10·84/60 = 14; f_m = 60·|14 − 10| = 240 = 24·10.
    assert!(close(k.shafts["r"], 14.0, 1e-14));
    assert!(close(k.meshes[0].hz, 240.0, 1e-14));
}

/// The rigid-body mode of the assembled model is the kinematic motion: each coordinate's rate
/// over the input's equals the kinematics' (Willis for the planetary cases).
#[test]
fn rigid_body_mode_follows_the_kinematics() {
    let cases = [
        planetary("ring", "shaft = \"s\", ", "", "shaft = \"c\"", "s"),
        planetary("carrier", "shaft = \"s\", ", "shaft = \"r\", ", "", "s"),
        planetary("sun", "", "shaft = \"r\", ", "shaft = \"c\"", "c"),
        PAPER_RIG.to_string(),
    ];
    for text in cases {
        // The paper's Table 1 base radii are not exactly proportional to the tooth counts
        // (20.4 / 70.5 = 0.2894 against 29 / 100; sun 13 mm against 28 · 1 · cos 20° / 2 =
        // 13.16 mm): its rigid mode follows the radii, up to 1.4 % off the tooth ratios.
        let tol = if text == PAPER_RIG { 2e-2 } else { 1e-9 };
        let gb = parse(&text).unwrap();
        let asm = gb.assembly(Wear::fixed_axis(0.3)).unwrap();
        let modes = asm.rigid_modes().unwrap();
        assert_eq!(modes.ncols(), 1, "{text}");
        let rates = gb.topology.signed_rates(1.0);
        let input = asm
            .dof_index(&format!("theta_{}", gb.topology.input_shaft))
            .unwrap();
        for shaft in &gb.topology.shafts {
            let i = asm.dof_index(&format!("theta_{shaft}")).unwrap();
            let ratio = modes[(i, 0)] / modes[(input, 0)];
            // Coordinates are measured in each member's own mesh sense: magnitudes agree.
            assert!(
                close(ratio.abs(), rates[shaft].abs(), tol),
                "{shaft}: mode {ratio} vs kinematics {}",
                rates[shaft]
            );
        }
    }
}

#[test]
fn json_and_toml_give_the_same_gearbox() {
    let toml_gb = Gearbox::paper_rig();
    let json = serde_json::to_string_pretty(&toml_gb.description).unwrap();
    let json_gb = parse(&json).unwrap();
    assert_eq!(json_gb.hash, toml_gb.hash);
    assert_eq!(json_gb.physics, toml_gb.physics);
}

#[test]
fn a_flexible_shaft_adds_a_coordinate_and_a_shaft_element() {
    let text = PAPER_RIG.to_string() + "\n[shafts.B]\ntorsional_stiffness_nm_per_rad = 2.0e4\n";
    let gb = parse(&text).unwrap();
    assert_eq!(
        gb.physics.dofs.len(),
        Gearbox::paper_rig().physics.dofs.len() + 1
    );
    assert_eq!(gb.physics.shafts.len(), 1);
    let m = gb
        .assembly(Wear::fixed_axis(0.5))
        .unwrap()
        .resolve()
        .unwrap();
    assert_eq!(m.n(), 11);
}

fn err(text: &str) -> GearboxError {
    parse(text).expect_err("must be refused")
}

/// One parallel stage with the given pinion and gear tables.
fn par(p: &str, g: &str) -> String {
    format!(
        "{HEADER}input_shaft = \"in\"\n[[stage]]\nkind = \"parallel\"\npinion = {{ {p} }}\ngear = {{ {g} }}\n"
    )
}

#[test]
fn bad_stages_get_specific_errors() {
    // zero and negative teeth
    assert!(matches!(
        err(&par(
            "shaft = \"in\", teeth = 0",
            "shaft = \"o\", teeth = 40"
        )),
        GearboxError::Teeth { teeth: 0, .. }
    ));
    assert!(matches!(
        err(&par(
            "shaft = \"in\", teeth = 20",
            "shaft = \"o\", teeth = -3"
        )),
        GearboxError::Teeth { teeth: -3, .. }
    ));
    // a gear on no shaft
    assert!(matches!(
        err(&par("shaft = \"in\", teeth = 20", "teeth = 40")),
        GearboxError::NoShaft { .. }
    ));
    // both gears on one shaft
    assert!(matches!(
        err(&par(
            "shaft = \"in\", teeth = 20",
            "shaft = \"in\", teeth = 40"
        )),
        GearboxError::SameShaft { .. }
    ));
    // input shaft on no stage
    let t = par("shaft = \"a\", teeth = 20", "shaft = \"o\", teeth = 40");
    assert!(matches!(err(&t), GearboxError::UnknownInput { .. }));
    // not coaxial
    let t = planetary("ring", "shaft = \"s\", ", "", "shaft = \"c\"", "s")
        .replace("teeth = 60", "teeth = 61");
    let e = err(&t);
    assert!(
        matches!(e, GearboxError::Coaxial { expected: 60, .. }),
        "{e}"
    );
    assert!(e.to_string().contains("profile_shifted"));
    // ... unless declared profile-shifted
    assert!(
        parse(&t.replace(
            "fixed = \"ring\"",
            "fixed = \"ring\"\nprofile_shifted = true"
        ))
        .is_ok()
    );
    // no member fixed / an unknown one
    let t = planetary("ring", "shaft = \"s\", ", "", "shaft = \"c\"", "s")
        .replace("fixed = \"ring\"\n", "");
    assert!(matches!(err(&t), GearboxError::Fixed { .. }));
    let t = planetary("housing", "shaft = \"s\", ", "", "shaft = \"c\"", "s");
    assert!(matches!(err(&t), GearboxError::Fixed { .. }));
    // two members fixed: the ring is fixed but also turns a shaft
    let t = planetary(
        "ring",
        "shaft = \"s\", ",
        "shaft = \"r\", ",
        "shaft = \"c\"",
        "s",
    );
    assert!(matches!(
        err(&t),
        GearboxError::FixedOnShaft { member: "ring", .. }
    ));
    // a stage not connected to the input
    let t = format!(
        "{HEADER}input_shaft = \"in\"\n\
         [[stage]]\nkind = \"parallel\"\npinion = {{ shaft = \"in\", teeth = 20 }}\ngear = {{ shaft = \"a\", teeth = 60 }}\n\
         [[stage]]\nkind = \"parallel\"\npinion = {{ shaft = \"x\", teeth = 15 }}\ngear = {{ shaft = \"y\", teeth = 45 }}\n"
    );
    assert!(matches!(
        err(&t),
        GearboxError::Disconnected { stage: 2, .. }
    ));
    // a shaft two stages disagree on (a locked loop)
    let t = format!(
        "{HEADER}input_shaft = \"in\"\n\
         [[stage]]\nkind = \"parallel\"\npinion = {{ shaft = \"in\", teeth = 20 }}\ngear = {{ shaft = \"a\", teeth = 60 }}\n\
         [[stage]]\nkind = \"parallel\"\npinion = {{ shaft = \"in\", teeth = 30 }}\ngear = {{ shaft = \"a\", teeth = 60 }}\n"
    );
    assert!(matches!(err(&t), GearboxError::ShaftConflict { .. }));
    // an unknown kind, a member of the other kind, a missing member
    assert!(matches!(
        err(
            &par("shaft = \"in\", teeth = 20", "shaft = \"o\", teeth = 40")
                .replace("parallel", "bevel")
        ),
        GearboxError::UnknownKind { .. }
    ));
    let t = par("shaft = \"in\", teeth = 20", "shaft = \"o\", teeth = 40")
        + "sun = { shaft = \"in\", teeth = 3 }\n";
    assert!(matches!(
        err(&t),
        GearboxError::ForeignMember { member: "sun", .. }
    ));
    let t = format!(
        "{HEADER}input_shaft = \"in\"\n[[stage]]\nkind = \"parallel\"\npinion = {{ shaft = \"in\", teeth = 20 }}\n"
    );
    assert!(matches!(
        err(&t),
        GearboxError::MissingMember { member: "gear", .. }
    ));
}

#[test]
fn bad_values_and_headers_get_specific_errors() {
    // values out of range
    let t = par(
        "shaft = \"in\", teeth = 20, face_width_mm = -5",
        "shaft = \"o\", teeth = 40",
    );
    assert!(matches!(err(&t), GearboxError::Value { .. }));
    let t = par("shaft = \"in\", teeth = 20", "shaft = \"o\", teeth = 40")
        + "mesh = { fluctuation = 1.5 }\n";
    assert!(matches!(err(&t), GearboxError::Value { .. }));
    // syntax, unknown field, format, version, name, no stage
    assert!(matches!(
        err("this is not toml ["),
        GearboxError::Syntax { .. }
    ));
    let t = par(
        "shaft = \"in\", teeth = 20, colour = \"red\"",
        "shaft = \"o\", teeth = 40",
    );
    let e = err(&t);
    assert!(
        matches!(e, GearboxError::Syntax { .. }) && e.to_string().contains("colour"),
        "{e}"
    );
    assert!(matches!(
        err(
            &par("shaft = \"in\", teeth = 20", "shaft = \"o\", teeth = 40")
                .replace("gearwear-gearbox", "other")
        ),
        GearboxError::Format { .. }
    ));
    assert!(matches!(
        err(
            &par("shaft = \"in\", teeth = 20", "shaft = \"o\", teeth = 40")
                .replace("version = 1", "version = 2")
        ),
        GearboxError::Version { found: 2 }
    ));
    assert!(matches!(
        err(
            &par("shaft = \"in\", teeth = 20", "shaft = \"o\", teeth = 40")
                .replace("name = \"t\"", "name = \"a b/c\"")
        ),
        GearboxError::Name { .. }
    ));
    assert!(matches!(
        err(&format!("{HEADER}input_shaft = \"in\"\nstage = []\n")),
        GearboxError::StageCount { .. }
    ));
    // sensor and wear stages out of range
    let t = par("shaft = \"in\", teeth = 20", "shaft = \"o\", teeth = 40").replace(
        "input_shaft = \"in\"",
        "input_shaft = \"in\"\nwear_stages = [2]",
    );
    assert!(matches!(err(&t), GearboxError::StageIndex { .. }));
}

/// A bearing on a shaft no gear sits on, with only part of its geometry or only some of its
/// orders, or with a ball wider than its pitch circle: each refused, naming the bearing. A
/// complete one resolves to the textbook orders (n = 8, d/D = 7.94/33.5: BPFO = 4 (1 − d/D)).
#[test]
fn bearings_are_checked_and_resolve_to_their_defect_orders() {
    let base = par("shaft = \"in\", teeth = 20", "shaft = \"o\", teeth = 40");
    let with = |b: &str| format!("{base}[[bearing]]\nname = \"b1\"\n{b}");
    for (b, says) in [
        (
            "shaft = \"x\"\nbpfo = 3.0\nbpfi = 5.0\nbsf = 2.0\nftf = 0.4\n",
            "carries no gear",
        ),
        ("shaft = \"o\"\nrolling_elements = 8\n", "pitch_diameter_mm"),
        ("shaft = \"o\"\nbpfo = 3.0\n", "all four"),
        (
            "shaft = \"o\"\nrolling_elements = 8\nball_diameter_mm = 40\npitch_diameter_mm = 33.5\n",
            "ball diameter",
        ),
    ] {
        let e = err(&with(b));
        assert!(
            matches!(&e, GearboxError::Bearing { name, .. } if name == "b1")
                && e.to_string().contains(says),
            "{b}: {e}"
        );
    }
    let gb = parse(&with(
        "shaft = \"o\"\nrolling_elements = 8\nball_diameter_mm = 7.94\npitch_diameter_mm = 33.5\n",
    ))
    .unwrap();
    let o = gb.description.bearings[0].defect_orders().unwrap();
    let r = 7.94 / 33.5;
    assert!((o.bpfo - 4.0 * (1.0 - r)).abs() < 1e-12 && (o.bpfi - 4.0 * (1.0 + r)).abs() < 1e-12);
    assert!((o.ftf - 0.5 * (1.0 - r)).abs() < 1e-12);
    assert!((o.bsf - 33.5 / (2.0 * 7.94) * (1.0 - r * r)).abs() < 1e-12);
}

#[test]
fn unequal_planet_spacing_is_a_warning_not_an_error() {
    // (24 + 60) / 3 = 28: equal spacing possible; 4 planets: 84/4 = 21 also. 5 planets: no.
    let t = planetary("ring", "shaft = \"s\", ", "", "shaft = \"c\"", "s")
        .replace("count = 3", "count = 5");
    let gb = parse(&t).unwrap();
    assert_eq!(gb.warnings.len(), 1, "{:?}", gb.warnings);
}

#[test]
fn committed_descriptions_resolve() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/gearboxes");
    let mut n = 0;
    for entry in std::fs::read_dir(dir).unwrap() {
        let p = entry.unwrap().path();
        if p.extension().is_some_and(|e| e == "toml" || e == "json") {
            let gb = Gearbox::from_file(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            let m = gb
                .assembly(Wear::fixed_axis(0.5))
                .unwrap()
                .resolve()
                .unwrap();
            assert!(m.omega_h.is_finite() && m.omega_h > 0.0);
            n += 1;
        }
    }
    assert!(
        n >= 4,
        "the paper rig and three more descriptions are committed"
    );
}

#[test]
fn the_sensor_stage_picks_the_simulated_element() {
    let two = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../configs/gearboxes/two-stage-parallel.toml"),
    )
    .unwrap();
    let m = parse(&two)
        .unwrap()
        .assembly(Wear::fixed_axis(0.5))
        .unwrap()
        .resolve()
        .unwrap();
    assert_eq!(m.sensor, 0);
    let at2 = two.replace(
        "input_shaft = \"input\"",
        "input_shaft = \"input\"\nsensor = { stage = 2 }",
    );
    let gb = parse(&at2).unwrap();
    let m = gb
        .assembly(Wear::fixed_axis(0.5))
        .unwrap()
        .resolve()
        .unwrap();
    assert_eq!(m.names[m.sensor], "x2");
    // The simulated record then follows mesh 2: its mean is that mesh's static deflection,
    // just past its own half-clearance (stage 2: module 2 mm → 100 µm = 20 b_ref; stage 1:
    // module 1.5 mm → 15 b_ref).
    use crate::signature::precompute::{SimOptions, simulate_sensor};
    let omega1 = 0.3;
    let spp = 32usize;
    let period = std::f64::consts::TAU / omega1;
    let mean = |m: &crate::model::DimensionlessModel| {
        let rec = simulate_sensor(
            m,
            &vec![0.0; 2 * m.n()],
            &SimOptions {
                omega1,
                transient_tau: 600.0,
                dt_tau: period / spp as f64,
                samples: 32 * spp,
                sensor: crate::signature::SensorQuantity::X1,
                poincare_every: 0,
                solver: Default::default(),
            },
        )
        .unwrap();
        rec.series.iter().sum::<f64>() / rec.series.len() as f64
    };
    let (b1, b2) = (m.backlash[0], m.backlash[1]);
    assert!(
        (b1 - 15.0).abs() < 1e-9 && (b2 - 20.0).abs() < 1e-9,
        "{b1} {b2}"
    );
    let mut at1 = m.clone();
    at1.sensor = 0;
    let (x1, x2) = (mean(&at1), mean(&m));
    assert!(
        (x1 - b1).abs() < 2.0,
        "sensor at stage 1: mean {x1}, clearance {b1}"
    );
    assert!(
        (x2 - b2).abs() < 2.0,
        "sensor at stage 2: mean {x2}, clearance {b2}"
    );
}

#[test]
fn unit_physics_factors_change_nothing_and_the_description_hashes_as_before() {
    let gb = Gearbox::paper_rig();
    let same = gb.with_factors(&PhysicsFactors::default()).unwrap();
    assert_eq!(same.hash, gb.hash, "identity factors are not written");
    let ones = PhysicsFactors {
        stages: vec![StageFactors::default(); 3],
        ..Default::default()
    };
    let mut d = gb.description.clone();
    d.physics_factors = Some(ones);
    let written = Gearbox::new(d).unwrap();
    assert_ne!(
        written.hash, gb.hash,
        "the block is part of the description"
    );
    assert_eq!(written.physics, gb.physics, "factors of 1 change no value");
    let (a, b) = (
        gb.assembly(Wear::fixed_axis(0.4))
            .unwrap()
            .resolve()
            .unwrap(),
        written
            .assembly(Wear::fixed_axis(0.4))
            .unwrap()
            .resolve()
            .unwrap(),
    );
    assert_eq!(a.a, b.a);
    assert_eq!(
        (a.k_ratio.clone(), a.c.clone(), a.f.clone()),
        (b.k_ratio, b.c, b.f)
    );
    assert_eq!(a.omega_h, b.omega_h);
}

#[test]
fn physics_factors_scale_what_they_name() {
    let gb = Gearbox::paper_rig();
    let f = PhysicsFactors {
        stages: vec![
            StageFactors {
                stiffness: 1.44,
                damping: 2.0,
                fluctuation: 1.5,
                error: 0.5,
            },
            StageFactors {
                error: 2.0,
                ..Default::default()
            },
        ],
        load: 1.3,
        clearance: 0.8,
    };
    let fitted = gb.with_factors(&f).unwrap();
    // ω_h = √(k_1 A_11): a 1.44 × stiffer reference mesh moves it by 1.2.
    assert!(close(
        fitted.reference_frequency_hz(),
        1.2 * gb.reference_frequency_hz(),
        1e-12
    ));
    let (m0, m1) = (&fitted.physics.meshes[0], &gb.physics.meshes[0]);
    assert!(close(
        m0.stiffness_n_per_m,
        1.44 * m1.stiffness_n_per_m,
        1e-12
    ));
    assert!(close(m0.damping_ratio, 2.0 * m1.damping_ratio, 1e-12));
    assert!(close(m0.half_clearance_m, 0.8 * m1.half_clearance_m, 1e-12));
    assert!(close(
        fitted.physics.input_torque_nm,
        1.3 * gb.physics.input_torque_nm,
        1e-12
    ));
    let model = fitted
        .assembly(Wear::fixed_axis(0.4))
        .unwrap()
        .resolve()
        .unwrap();
    let plain = gb
        .assembly(Wear::fixed_axis(0.4))
        .unwrap()
        .resolve()
        .unwrap();
    // The wear mesh of stage 1 carries 0.5 × ea, stage 2's 2 × ea; the planetary meshes keep
    // theirs; the fluctuation is 1.5 × 0.2.
    let amp = |m: &DimensionlessModel, i: usize| m.error[i][0].amplitude;
    assert!(close(amp(&model, 0), 0.5 * amp(&plain, 0), 1e-12));
    assert!(close(amp(&model, 1), 2.0 * amp(&plain, 1), 1e-12));
    assert!(close(amp(&model, 2), amp(&plain, 2), 1e-12));
    match model.shape[0] {
        crate::model::StiffnessShape::FirstHarmonic { eps } => assert!(close(eps, 0.3, 1e-12)),
        ref s => panic!("{s:?}"),
    }
    // The stage-1 stiffness is the reference: every other mesh's ratio to it falls by 1.44.
    assert!(close(model.k_ratio[1], plain.k_ratio[1] / 1.44, 1e-12));
}

#[test]
fn physics_factors_out_of_range_are_refused_by_name() {
    let gb = Gearbox::paper_rig();
    let f = PhysicsFactors {
        stages: vec![StageFactors {
            fluctuation: 6.0,
            ..Default::default()
        }],
        ..Default::default()
    };
    let e = gb.with_factors(&f).unwrap_err().to_string();
    assert!(e.contains("fluctuation"), "{e}");
    let f = PhysicsFactors {
        load: 0.0,
        ..Default::default()
    };
    let e = gb.with_factors(&f).unwrap_err().to_string();
    assert!(e.contains("physics_factors.load"), "{e}");
    let f = PhysicsFactors {
        stages: vec![
            StageFactors {
                damping: 2.0,
                ..Default::default()
            };
            4
        ],
        ..Default::default()
    };
    assert!(gb.with_factors(&f).is_err(), "the rig has three stages");
}
