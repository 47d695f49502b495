//! The machine's own model (its physics fitted to its healthy records by simulating the
//! described gearbox, [`gearwear::diagnosis::machine_physics`]) on a PHM 2009 train, leave one
//! speed out (`cargo run --release --example real_data -- helical-physics`, or
//! `spur-physics`; several minutes a train).
//!
//! Chosen before any score was looked at: the baseline is case 1 run 1 at every state, both
//! accelerometers fitted at once (one physics, a path per channel) on the plain table's line
//! ratios at the tachometer's speed. Reported:
//! 1. the fit on every speed: its factors, the fit per speed and line family, its left-out
//!    error (each speed predicted by a fit of the others) against the empirical calibration's
//!    (the description's physics through a path alone) and the plain model's;
//! 2. each speed left out in turn — the physics fitted without it, its own table, and every
//!    record at that speed read against it: case 1 run 2 (healthy: is the healthy wear 0.1
//!    inside its 90 % interval?) and every other case's run 1 (is a figure withheld?).

use std::collections::BTreeMap;

use gearwear::assessment::TableDiagnoser;
use gearwear::assessment::condition::measure_record;
use gearwear::diagnosis::machine_path::LineRatios;
use gearwear::diagnosis::machine_physics::{MachinePhysics, PhysicsFitOptions};
use gearwear::diagnosis::{DiagnoseOptions, Diagnosis, diagnose};
use gearwear::gearbox::Gearbox;
use gearwear::record::Record;
use gearwear::signature::SignatureTable;
use gearwear::signature::precompute::precompute;
use rayon::prelude::*;

use super::phm::{self, File, Train};

const CHANNELS: [&str; 2] = ["input", "output"];

/// A record's plain diagnoses (per channel) at its tachometer's speed.
struct Plain<'a> {
    file: &'a File,
    diagnoses: Vec<Option<Diagnosis>>,
}

fn diagnosed<'a>(
    t: &Train,
    gb: &Gearbox,
    files: &'a [File],
    table: &SignatureTable,
) -> Vec<Plain<'a>> {
    let empty = Default::default();
    let m = phm::machine(t, gb, None, &empty);
    files
        .par_iter()
        .map(|f| {
            let (ch, facts) = phm::load(f, true, false);
            let shaft = measure_record(&ch, &phm::CHOSEN, &facts, &m)
                .ok()
                .and_then(|s| s.state)
                .map(|s| s.shaft_hz);
            let diagnoses = (0..CHANNELS.len())
                .map(|c| {
                    let rec = Record {
                        samples: ch[c].1.clone(),
                        sample_rate: phm::FS,
                    };
                    let o = DiagnoseOptions {
                        shaft_hz: shaft,
                        ..Default::default()
                    };
                    diagnose(&rec, table, &o).ok()
                })
                .collect();
            Plain { file: f, diagnoses }
        })
        .collect()
}

fn ratios(base: &[&Plain]) -> BTreeMap<String, Vec<LineRatios>> {
    CHANNELS
        .iter()
        .enumerate()
        .map(|(c, name)| {
            (
                name.to_string(),
                base.iter()
                    .filter_map(|p| p.diagnoses[c].as_ref().map(LineRatios::of))
                    .collect(),
            )
        })
        .collect()
}

fn print_fit(p: &MachinePhysics) {
    println!(
        "fitted in {:.0} s ({} simulations): a left-out speed's lines to {:.2} dB RMS, median \
         {:.2} dB (in sample {:.2} dB); the empirical path {} dB; the plain model {:.2} dB; λ {}\n",
        p.seconds,
        p.simulations,
        p.left_out_db,
        p.left_out_median_db,
        p.in_sample_db,
        p.yardstick_db.map_or("–".into(), |y| format!("{y:.2}")),
        p.plain_db,
        p.lambda
    );
    println!("| factor | value | 90 % interval | identified |\n| --- | --- | --- | --- |");
    for f in &p.parameters {
        println!(
            "| {} | {:.3} | {:.3}–{:.3} | {} |",
            f.name,
            f.value,
            f.lower,
            f.upper,
            if f.identified { "yes" } else { "prior" }
        );
    }
    println!(
        "\n| speed (f1 Hz) | family | lines | in sample dB | left out dB |\n| --- | --- | --- | --- | --- |"
    );
    for s in &p.states {
        for f in &s.families {
            println!(
                "| {:.0} | {} | {} | {:.2} | {:.2} |",
                s.f1_hz, f.family, f.lines, f.in_sample_db, f.left_out_db
            );
        }
    }
    println!();
}

/// One speed left out: what its records read against the own model fitted without it.
#[derive(Default)]
struct Tally {
    healthy: usize,
    healthy_figure: usize,
    healthy_inside: usize,
    faulted: usize,
    faulted_withheld: usize,
}

fn read_at(
    gb: &Gearbox,
    table: &SignatureTable,
    physics: &MachinePhysics,
    at: &[&Plain],
    tally: &mut Tally,
) {
    let Ok(spec) = physics.table_spec(gb, table) else {
        return;
    };
    let Ok(own) = precompute(&spec, None, &|| {}) else {
        return;
    };
    let Ok(d) = TableDiagnoser::new(own, DiagnoseOptions::default()) else {
        return;
    };
    let opts = DiagnoseOptions::default();
    for p in at {
        let healthy = p.file.case == 1;
        let (ch, _) = phm::load(p.file, true, false);
        // Both channels, as a user reads it: a figure when either gives one (the first).
        let mut reading: Option<(f64, f64)> = None;
        for c in 0..CHANNELS.len() {
            let Some(first) = &p.diagnoses[c] else {
                continue;
            };
            let rec = Record {
                samples: ch[c].1.clone(),
                sample_rate: phm::FS,
            };
            let Ok(Some(r)) = physics.reread(&rec, CHANNELS[c], d.table(), &opts, first) else {
                continue;
            };
            if r.wear_degree.withheld.is_none() && reading.is_none() {
                reading = Some((r.wear_degree.lower, r.wear_degree.upper));
            }
        }
        if healthy {
            tally.healthy += 1;
            if let Some((lo, hi)) = reading {
                tally.healthy_figure += 1;
                tally.healthy_inside +=
                    usize::from(lo <= physics.healthy_ea && physics.healthy_ea <= hi);
            }
        } else {
            tally.faulted += 1;
            tally.faulted_withheld += usize::from(reading.is_none());
        }
    }
}

pub fn run(t: &Train) {
    let dir = std::env::var(t.dir_env)
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|_| phm::manifest(t.default_dir));
    let all: Vec<File> = phm::files(t, &dir)
        .into_iter()
        .filter(|f| f.case == 1 || f.run == 1)
        .collect();
    let gb = Gearbox::from_file(&phm::manifest(t.config)).expect("description");
    let Ok(table) = SignatureTable::load(&phm::manifest(t.table)) else {
        eprintln!("no table {}", t.table);
        return;
    };
    let recs = diagnosed(t, &gb, &all, &table);
    let base: Vec<&Plain> = recs
        .iter()
        .filter(|r| r.file.case == 1 && r.file.run == 1)
        .collect();
    let fo = PhysicsFitOptions::default();
    let opts = DiagnoseOptions::default();
    println!("## The machine's own model, PHM 2009 {} train\n", t.name);
    match MachinePhysics::fit(&gb, &table, &opts, &ratios(&base), &fo) {
        Ok(p) => print_fit(&p),
        Err(e) => println!("refused: {e}\n"),
    }
    let mut speeds: Vec<u32> = base.iter().map(|r| r.file.speed).collect();
    speeds.sort();
    speeds.dedup();
    println!("### Leave one speed out: records read against the own model fitted without it\n");
    println!(
        "| left out | fit | healthy run 2: a figure | 0.1 inside | faulted: withheld |\n| --- | --- | --- | --- | --- |"
    );
    let mut total = Tally::default();
    for &x in &speeds {
        let train: Vec<&Plain> = base.iter().copied().filter(|r| r.file.speed != x).collect();
        let at: Vec<&Plain> = recs
            .iter()
            .filter(|r| r.file.speed == x && !(r.file.case == 1 && r.file.run == 1))
            .collect();
        let mut tally = Tally::default();
        let fit = match MachinePhysics::fit(&gb, &table, &opts, &ratios(&train), &fo) {
            Ok(p) => {
                read_at(&gb, &table, &p, &at, &mut tally);
                format!("{:.2} dB left out", p.left_out_db)
            }
            Err(e) => format!("refused: {e}"),
        };
        println!(
            "| {x} Hz | {fit} | {}/{} | {}/{} | {}/{} |",
            tally.healthy_figure,
            tally.healthy,
            tally.healthy_inside,
            tally.healthy_figure,
            tally.faulted_withheld,
            tally.faulted
        );
        total.healthy += tally.healthy;
        total.healthy_figure += tally.healthy_figure;
        total.healthy_inside += tally.healthy_inside;
        total.faulted += tally.faulted;
        total.faulted_withheld += tally.faulted_withheld;
    }
    println!(
        "| all | | {}/{} | {}/{} | {}/{} |\n",
        total.healthy_figure,
        total.healthy,
        total.healthy_inside,
        total.healthy_figure,
        total.faulted_withheld,
        total.faulted
    );
}
