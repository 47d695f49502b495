//! The signature table: file format, loading, staleness check and derived statistics.
//!
//! The file is one JSON object (format `gearwear-signatures`, see `signatures/README.md`):
//! a header (format version, model hash, the full gearbox description, the sensor quantity,
//! the grid, the simulation settings, the feature definitions, the creating command) and one
//! entry per grid point `(ea, Ω1)` with the per-seed feature vectors and motion states.
//! Statistics (mean, standard deviation) are derived at load time, so the noise-floor clipping
//! used by the matcher can change without regenerating the table.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::{LineDef, SensorQuantity};
use crate::error::{Error, Result};
use crate::gearbox::{Gearbox, GearboxDescription};

/// File format identifier.
pub const FORMAT: &str = "gearwear-signatures";
/// Current format version. Bump when the meaning of a field or a feature changes.
/// Version 2: the header carries the gearbox description (`gearbox`) instead of the Model A
/// configuration; the paper rig's entries are unchanged (it resolves to the same model).
pub const VERSION: u32 = 2;

/// The committed default table (`signatures/model_a_accel.json`).
pub const DEFAULT_TABLE_PATH: &str = "signatures/model_a_accel.json";

/// Where the default table is: `signatures/model_a_accel.json` under the working directory when
/// it exists (a checkout, a container with the file copied), else the one in the source tree the
/// binary was built from.
pub fn default_table_path() -> std::path::PathBuf {
    let local = std::path::PathBuf::from(DEFAULT_TABLE_PATH);
    if local.exists() {
        local
    } else {
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../..")
            .join(DEFAULT_TABLE_PATH)
    }
}

/// SHA-256 (hex) of the gearbox description's canonical JSON (`serde_json` of
/// [`GearboxDescription`], fields in declaration order, no whitespace): [`Gearbox::hash`]. Any
/// change of a value in the description changes the hash.
pub fn model_hash(gb: &Gearbox) -> String {
    gb.hash.clone()
}

fn description_hash(d: &GearboxDescription) -> String {
    let digest = Sha256::digest(d.canonical_json().as_bytes());
    digest.iter().map(|b| format!("{b:02x}")).collect()
}

/// The simulation grid.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Grid {
    /// Wear degrees ea (units of b_ref = 5 µm), ascending.
    pub ea: Vec<f64>,
    /// Operating points Ω1 = f1 / f_ref, ascending.
    pub omega1: Vec<f64>,
    /// Random initial states (and transient lengths) per grid point.
    pub seeds: usize,
}

/// How each seed was simulated.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SimulationSettings {
    /// Retained stage-1 mesh periods per seed.
    pub periods: usize,
    /// Samples per stage-1 mesh period.
    pub samples_per_period: usize,
    /// Transient: `transient_tau + U(0, transient_jitter_tau)` in τ, at least
    /// `transient_periods` mesh periods.
    pub transient_tau: f64,
    pub transient_jitter_tau: f64,
    pub transient_periods: f64,
    /// Initial deflections `x̄_j ~ U(−a, a)`, velocities `x̄'_j ~ U(−a, a)·Ω1`, projected onto
    /// the kinematically consistent set.
    pub initial_amplitude: f64,
    /// Base seed of the random initial states.
    pub base_seed: u64,
    pub rtol: f64,
    pub atol: f64,
}

/// Feature definitions (see [`crate::signature`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FeatureDefs {
    /// Lines measured, ascending frequency (ratio to f1).
    pub lines: Vec<LineDef>,
    /// Names of the feature vector components, in order.
    pub names: Vec<String>,
    /// Welch segment length in f1 periods (Hann, 50 % overlap, power average).
    pub segment_periods: f64,
    /// Band of `f1_power_fraction`, in units of f1.
    pub band: (f64, f64),
    /// Human-readable definition.
    pub definition: String,
}

/// One grid point.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Entry {
    pub ea: f64,
    pub omega1: f64,
    /// Feature vectors, one per successful seed (natural-log units, unclipped).
    pub samples: Vec<Vec<f64>>,
    /// Motion state of x̄1 per seed (`period-1`, `chaotic`, …).
    pub motion: Vec<String>,
    /// Seeds whose simulation failed (not in `samples`).
    #[serde(default)]
    pub failed: usize,
}

impl Entry {
    /// The most frequent motion state (ties: the first in sorted order), `unknown` if none.
    pub fn majority_motion(&self) -> String {
        let mut c: BTreeMap<&str, usize> = BTreeMap::new();
        for m in &self.motion {
            *c.entry(m.as_str()).or_default() += 1;
        }
        c.iter()
            .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(a.0)))
            .map(|(k, _)| k.to_string())
            .unwrap_or_else(|| "unknown".into())
    }
}

/// A signature table.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SignatureTable {
    pub format: String,
    pub version: u32,
    /// [`model_hash`] of `gearbox`.
    pub model_hash: String,
    /// The gearbox the table was computed for.
    pub gearbox: GearboxDescription,
    /// `gearbox` resolved (set on loading and by the precompute job).
    #[serde(skip)]
    pub(crate) resolved: Option<Arc<Gearbox>>,
    pub sensor: SensorQuantity,
    pub grid: Grid,
    pub simulation: SimulationSettings,
    pub features: FeatureDefs,
    /// The command line that created the table.
    pub created_by: String,
    /// Wall-clock seconds the precompute took (the last run; a resumed run counts only itself).
    pub precompute_seconds: f64,
    /// Entries, `ea`-major: index `i_ea · omega1.len() + i_omega`.
    pub entries: Vec<Entry>,
}

impl SignatureTable {
    /// Parse a table from JSON text; `origin` names it in errors. Checks format, version and the
    /// grid's shape, not the model hash (see [`SignatureTable::check_model`]).
    pub fn from_json(text: &str, origin: &str) -> Result<Self> {
        let t: SignatureTable = serde_json::from_str(text).map_err(|e| Error::Parse {
            path: origin.into(),
            reason: format!("not a signature table: {e}"),
        })?;
        let bad = |reason: String| Error::Parse {
            path: origin.into(),
            reason,
        };
        if t.format != FORMAT {
            return Err(bad(format!("format `{}`, expected `{FORMAT}`", t.format)));
        }
        if t.version != VERSION {
            return Err(bad(format!(
                "format version {}, this program reads version {VERSION}; regenerate the table \
                 with `gearwear precompute`",
                t.version
            )));
        }
        let (ne, no) = (t.grid.ea.len(), t.grid.omega1.len());
        if ne < 2 || no < 1 || t.entries.len() != ne * no {
            return Err(bad(format!(
                "grid {ne} × {no} but {} entries (need ≥ 2 wear degrees and one entry per point)",
                t.entries.len()
            )));
        }
        let nf = t.features.names.len();
        for (k, e) in t.entries.iter().enumerate() {
            let (i, j) = (k / no, k % no);
            if (e.ea - t.grid.ea[i]).abs() > 1e-9 || (e.omega1 - t.grid.omega1[j]).abs() > 1e-9 {
                return Err(bad(format!(
                    "entry {k} is (ea {}, Ω1 {}), the grid says ({}, {})",
                    e.ea, e.omega1, t.grid.ea[i], t.grid.omega1[j]
                )));
            }
            if e.samples.is_empty() || e.samples.iter().any(|s| s.len() != nf) {
                return Err(bad(format!(
                    "entry {k} (ea {}, Ω1 {}) has no samples or a sample of the wrong length",
                    e.ea, e.omega1
                )));
            }
        }
        if !t.grid.ea.windows(2).all(|w| w[1] > w[0])
            || !t.grid.omega1.windows(2).all(|w| w[1] > w[0])
        {
            return Err(bad("grid axes must be strictly ascending".into()));
        }
        let mut t = t;
        let gb = Gearbox::new(t.gearbox.clone())
            .map_err(|e| bad(format!("its gearbox description does not resolve: {e}")))?;
        t.resolved = Some(Arc::new(gb));
        Ok(t)
    }

    /// The resolved gearbox of the table.
    pub fn gearbox(&self) -> &Gearbox {
        self.resolved
            .as_deref()
            .expect("a loaded or precomputed table has its gearbox resolved")
    }

    /// The resolved gearbox, shared.
    pub fn gearbox_arc(&self) -> Arc<Gearbox> {
        self.resolved
            .clone()
            .expect("a loaded or precomputed table has its gearbox resolved")
    }

    /// Read a table file.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
            path: path.display().to_string(),
            source,
        })?;
        Self::from_json(&text, &path.display().to_string())
    }

    /// Read a table and refuse it if it was computed for another gearbox description.
    pub fn load_checked(path: &Path, gb: &Gearbox) -> Result<Self> {
        let t = Self::load(path)?;
        t.check_model(gb)?;
        Ok(t)
    }

    /// [`Error::StaleTable`] unless the table's hash is the hash of `gb` (and of the
    /// description stored in the table itself).
    pub fn check_model(&self, gb: &Gearbox) -> Result<()> {
        let current = model_hash(gb);
        if self.model_hash != current {
            return Err(Error::StaleTable {
                table_hash: self.model_hash.clone(),
                model_hash: current,
            });
        }
        let stored = description_hash(&self.gearbox);
        if stored != self.model_hash {
            return Err(Error::StaleTable {
                table_hash: self.model_hash.clone(),
                model_hash: stored,
            });
        }
        Ok(())
    }

    /// Entry at grid indices.
    pub fn entry(&self, i_ea: usize, i_omega: usize) -> &Entry {
        &self.entries[i_ea * self.grid.omega1.len() + i_omega]
    }

    /// Ω1 band `[min, max]` of the table.
    pub fn omega_band(&self) -> (f64, f64) {
        let o = &self.grid.omega1;
        (o[0], o[o.len() - 1])
    }

    /// ea range `[min, max]`.
    pub fn ea_range(&self) -> (f64, f64) {
        let e = &self.grid.ea;
        (e[0], e[e.len() - 1])
    }

    /// Serialise compactly (one entry per line, so diffs stay readable).
    pub fn to_json(&self) -> Result<String> {
        let mut head = self.clone();
        head.entries.clear();
        let mut s = serde_json::to_string_pretty(&head).map_err(json_err)?;
        // Replace the empty entries array with one line per entry.
        let tail = "\"entries\": []\n}";
        if !s.ends_with(tail) {
            return Err(Error::InvalidConfig(
                "unexpected table serialisation layout".into(),
            ));
        }
        s.truncate(s.len() - tail.len());
        s.push_str("\"entries\": [\n");
        for (k, e) in self.entries.iter().enumerate() {
            s.push_str("    ");
            s.push_str(&serde_json::to_string(&rounded(e)).map_err(json_err)?);
            if k + 1 < self.entries.len() {
                s.push(',');
            }
            s.push('\n');
        }
        s.push_str("  ]\n}\n");
        Ok(s)
    }
}

fn json_err(e: serde_json::Error) -> Error {
    Error::InvalidConfig(format!("JSON serialisation failed: {e}"))
}

/// Round feature samples to 1e-4 (0.0009 dB): far below the seed-to-seed spread.
fn rounded(e: &Entry) -> Entry {
    let mut e = e.clone();
    for s in &mut e.samples {
        for v in s.iter_mut() {
            *v = (*v * 1e4).round() / 1e4;
        }
    }
    e
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hash_changes_with_the_description() {
        let gb = Gearbox::paper_rig();
        let h = model_hash(&gb);
        assert_eq!(h.len(), 64);
        assert_eq!(h, description_hash(&gb.description));
        let mut other = gb.description.clone();
        other.static_load = Some(0.15 * 1.01);
        let other = Gearbox::new(other).unwrap();
        assert_ne!(h, model_hash(&other));
        assert_eq!(h, model_hash(&Gearbox::paper_rig()));
    }
}
