//! One record's draw (module docs' table): the wear, speed, gain, noise and the effect of its
//! kind, from the record's own seed.

use gearwear::closed_loop::effects::MeshGear;
use gearwear::closed_loop::virtual_rig::{RigEffects, RigSpec};
use gearwear::gearbox::Gearbox;
use gearwear::signature::{SplitMix64, mix_seed};

use super::row::Row;
use super::settings::Settings;

/// A drawn record.
pub struct Draw {
    /// The base seed and the index in its set.
    pub base: u64,
    pub i: usize,
    pub kind: &'static str,
    pub ea: f64,
    pub omega1: f64,
    pub snr_db: f64,
    /// The effects put in, and the library effects among them by name.
    pub e: RigEffects,
    pub truth: Vec<String>,
    /// The effect's size measure (NaN: none).
    pub size: f64,
    pub spec: RigSpec,
}

/// Draw record `i` of base seed `base`; `gears`: the reference mesh's gears, `(olo, ohi)`: the
/// table's band of Ω1.
pub fn draw(
    set: &Settings,
    gb: &Gearbox,
    gears: &[MeshGear],
    (olo, ohi): (f64, f64),
    base: u64,
    i: usize,
) -> Draw {
    let kinds = &set.kinds;
    let kind = kinds[i % kinds.len()];
    let mut rng = SplitMix64::new(mix_seed(&[base, i as u64, 0xC1_05ED]));
    let ea = rng.range(0.1, 1.0);
    let omega1 = rng.range(olo, ohi);
    let gain = 10f64.powf(rng.range(-2.0, 2.0));
    let snr_db = rng.range(20.0, 30.0);
    let mut d = Effects {
        rng,
        e: RigEffects::default(),
        truth: Vec::new(),
        scale: set.scale,
        db_scale: set.db_scale,
    };
    let size = d.kind(kind, i / kinds.len(), ea, gb, gears);
    let spec = RigSpec {
        ea,
        omega1,
        sample_rate: 16000.0,
        duration: 0.6,
        gain,
        snr_db,
        seed: mix_seed(&[base, i as u64, 1]),
        effects: d.e,
    };
    Draw {
        base,
        i,
        kind,
        ea,
        omega1,
        snr_db,
        e: d.e,
        truth: d.truth,
        size,
        spec,
    }
}

/// The effects of a record as they are drawn.
struct Effects {
    rng: SplitMix64,
    e: RigEffects,
    truth: Vec<String>,
    scale: f64,
    db_scale: f64,
}

impl Effects {
    /// Draw the effect of `kind` (`round`: how many times the kinds have cycled before this
    /// record); its size measure (NaN for a clean record).
    fn kind(&mut self, kind: &str, round: usize, ea: f64, gb: &Gearbox, gears: &[MeshGear]) -> f64 {
        let (scale, db_scale) = (self.scale, self.db_scale);
        let mut size = f64::NAN;
        match kind {
            "clean" => {}
            "path-resonance" => {
                size = self.resonance();
                self.truth.push("path-resonance".into());
            }
            "shaft-modulation" => {
                size = self.shaft(ea, gears);
                self.truth.push("shaft-modulation".into());
            }
            "planetary-wear" => {
                let p = 0.3 * (5.0f64 / 0.3).powf(self.rng.uniform());
                let base_p = gb.planetary_baseline().unwrap_or(0.0);
                let p = base_p + scale * (p - base_p);
                self.e.planetary = Some(p);
                size = p;
                self.truth.push("planetary-wear".into());
            }
            "tooth-damage" => {
                size = self.tooth(gears);
                self.truth.push("tooth-damage".into());
            }
            "pair" => {
                if round.is_multiple_of(2) {
                    size = self.shaft(ea, gears);
                    self.truth.push("shaft-modulation".into());
                } else {
                    size = self.tooth(gears);
                    self.truth.push("tooth-damage".into());
                }
                self.resonance();
                self.truth.push("path-resonance".into());
            }
            "speed-wander" => {
                let d = scale * self.rng.range(0.002, 0.02);
                self.e.speed_wander = Some((d, self.rng.range(0.003, 0.03)));
                size = d;
            }
            "tone" => {
                let lvl = self.rng.range(-30.0, -5.0) + db_scale;
                self.e.tone = Some((self.rng.range(0.1, 2.4), lvl));
                self.e.tone_harmonics = 1 + (self.rng.uniform() * 3.0) as u32;
                size = lvl;
            }
            "mains-hum" => {
                let hz = if self.rng.uniform() < 0.5 { 50.0 } else { 60.0 };
                let lvl = self.rng.range(-35.0, -10.0) + db_scale;
                self.e.mains = Some((hz, lvl));
                size = lvl;
            }
            "noise-bursts" => {
                let lvl = self.rng.range(0.0, 10.0) + db_scale;
                self.e.bursts = Some((2 + (self.rng.uniform() * 7.0) as u32, lvl));
                size = lvl;
            }
            "gain-drift" => {
                let d = scale * self.rng.range(0.1, 0.5);
                self.e.gain_drift = Some(d);
                size = d;
            }
            _ => unreachable!(),
        }
        size
    }

    /// A peaking path mode; its peak gain.
    fn resonance(&mut self) -> f64 {
        let rng = &mut self.rng;
        let rho = 0.2 * (3.0f64 / 0.2).powf(rng.uniform());
        let q = rng.range(2.0, 30.0);
        let g = self.scale * rng.range(1.0, 10.0);
        self.e.path_peak = Some((rho, 1.0 / (2.0 * q), g));
        g
    }

    /// A shaft modulation on either gear's shaft; its depth.
    fn shaft(&mut self, ea: f64, gears: &[MeshGear]) -> f64 {
        let rng = &mut self.rng;
        let m = self.scale * rng.range(0.05, 0.5);
        let gear = &gears[(rng.uniform() < 0.5) as usize];
        self.e.eccentricity = Some(m * ea / 2.0);
        self.e.eccentricity_shaft = Some(gear.shaft_ratio);
        m
    }

    /// A damaged tooth on either gear; its stiffness loss.
    fn tooth(&mut self, gears: &[MeshGear]) -> f64 {
        let rng = &mut self.rng;
        let d = self.scale * rng.range(0.1, 0.8);
        let gear = &gears[(rng.uniform() < 0.5) as usize];
        self.e.tooth = Some((gear.shaft_ratio, d));
        d
    }
}

impl Draw {
    /// The row of the draw alone, every measured figure NaN or empty (`err`: why the record
    /// failed).
    pub fn blank(&self, err: Option<String>) -> Row {
        let e = &self.e;
        Row {
            seed: self.base,
            index: self.i,
            kind: self.kind.into(),
            truth: self.truth.clone(),
            size: self.size,
            ea: self.ea,
            omega1: self.omega1,
            snr_db: self.snr_db,
            visible: false,
            v_effect: f64::NAN,
            v_noise: f64::NAN,
            visible_k: false,
            vis_d: f64::NAN,
            vis_s: f64::NAN,
            named: vec![],
            unexplained: 0,
            guesses: vec![],
            in_time: vec![],
            error_before: f64::NAN,
            error_after: f64::NAN,
            ea_before: f64::NAN,
            ea_after: f64::NAN,
            ea_lower: f64::NAN,
            ea_upper: f64::NAN,
            ea_before_lower: f64::NAN,
            ea_before_upper: f64::NAN,
            ea_profile: None,
            ea_refit: None,
            method: String::new(),
            rho_ratio: None,
            zeta_ratio: None,
            seconds: 0.0,
            error: err,
            null_spread: f64::NAN,
            claim_margin: f64::NAN,
            null_deviances: vec![],
            candidates: vec![],
            fm4: f64::NAN,
            kurtosis: f64::NAN,
            tsa_fm4: vec![],
            speed_std: f64::NAN,
            wander_rate: e.speed_wander.map(|w| w.1),
            truth_shaft: e.eccentricity_shaft.or(e.tooth.map(|t| t.0)),
            member_visible: vec![],
            member_visible_k: vec![],
            named_shaft: None,
            sidebands: vec![],
        }
    }
}
