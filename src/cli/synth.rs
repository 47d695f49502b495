//! The `synth` command: a virtual accelerometer record written to a file.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::Args;

use super::common::{RigArgs, wear};
use crate::closed_loop::virtual_rig::{RigEffects, RigSpec, generate};

#[derive(Debug, Args)]
pub struct SynthArgs {
    /// Wear degree ea of the virtual gearbox.
    #[arg(long)]
    pub ea: f64,
    /// Operating point Ω1 (1 = motor at 30 Hz on the paper's rig; default: 1, or the
    /// gearbox's nominal_input_hz).
    #[arg(long, conflicts_with = "input_hz")]
    pub omega1: Option<f64>,
    /// Input-shaft rate in Hz, instead of --omega1.
    #[arg(long)]
    pub input_hz: Option<f64>,
    /// Sample rate, Hz.
    #[arg(long, default_value_t = 25600.0)]
    pub sample_rate: f64,
    /// Duration, s.
    #[arg(long, default_value_t = 1.0)]
    pub duration: f64,
    /// Overall sensor gain.
    #[arg(long, default_value_t = 1.0)]
    pub gain: f64,
    /// Signal-to-noise ratio of the added white noise, dB.
    #[arg(long, default_value_t = 20.0)]
    pub snr_db: f64,
    /// Random seed (initial state, noise).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Shaft-rate modulation (eccentricity) sideband amplitude on mesh x1, units of b.
    #[arg(long)]
    pub eccentricity: Option<f64>,
    /// Planetary composite-error amplitude, units of b (default: the baseline 0.1).
    #[arg(long)]
    pub planetary: Option<f64>,
    /// Output file: `.wav` (32-bit float), `.f32` (raw little-endian) or `.csv` (one column).
    #[arg(long)]
    pub output: PathBuf,
    #[command(flatten)]
    pub rig: RigArgs,
}

/// `gearwear synth`.
pub fn synth_cmd(a: SynthArgs) -> Result<()> {
    let gb = a.rig.load()?;
    wear(&a.rig, a.ea)?;
    let f_ref = gb.reference_frequency_hz();
    let omega1 = match (a.omega1, a.input_hz.or(gb.description.nominal_input_hz)) {
        (Some(o), _) => o,
        (None, Some(hz)) => {
            if !(hz.is_finite() && hz > 0.0) {
                bail!("--input-hz must be a positive rate in Hz, got {hz}");
            }
            gb.f1_hz(hz) / f_ref
        }
        (None, None) => 1.0,
    };
    let spec = RigSpec {
        ea: a.ea,
        omega1,
        sample_rate: a.sample_rate,
        duration: a.duration,
        gain: a.gain,
        snr_db: a.snr_db,
        seed: a.seed,
        effects: RigEffects {
            eccentricity: a.eccentricity,
            planetary: a.planetary,
            ..Default::default()
        },
    };
    let rec = generate(&gb, &spec)?;
    let ext = a
        .output
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let bytes: Vec<u8> = match ext.as_str() {
        "wav" => {
            let fs = rec.sample_rate.round();
            if (fs - rec.sample_rate).abs() > 1e-9 || fs > u32::MAX as f64 {
                bail!(
                    "a WAV file needs a whole sample rate in Hz, got {}",
                    rec.sample_rate
                );
            }
            crate::record::encode_wav(&rec.samples, fs as u32, true)
        }
        "f32" | "raw" | "bin" => rec
            .samples
            .iter()
            .flat_map(|v| (*v as f32).to_le_bytes())
            .collect(),
        "csv" => rec
            .samples
            .iter()
            .map(|v| format!("{v:.9e}\n"))
            .collect::<String>()
            .into_bytes(),
        _ => bail!(
            "--output must end in .wav, .f32 or .csv, got {}",
            a.output.display()
        ),
    };
    if let Some(dir) = a.output.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    std::fs::write(&a.output, bytes).with_context(|| format!("writing {}", a.output.display()))?;
    eprintln!(
        "wrote {} ({} samples at {} Hz; shaft {:.3} Hz, f1 {:.1} Hz)",
        a.output.display(),
        rec.samples.len(),
        rec.sample_rate,
        omega1 * f_ref * gb.input_shaft_ratio(),
        omega1 * f_ref
    );
    Ok(())
}
