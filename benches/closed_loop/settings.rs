//! The benchmark's settings from the environment (the `CL_*` variables of the module docs),
//! the kinds of record it draws, and where its rows go.

/// The environment variable `k` parsed, or `d`.
pub fn env<T: std::str::FromStr>(k: &str, d: T) -> T {
    std::env::var(k)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(d)
}

/// Whether the environment variable `k` is set (to anything).
pub fn flag(k: &str) -> bool {
    std::env::var(k).is_ok()
}

pub const KINDS: [&str; 11] = [
    "clean",
    "path-resonance",
    "shaft-modulation",
    "planetary-wear",
    "tooth-damage",
    "pair",
    "speed-wander",
    "tone",
    "mains-hum",
    "noise-bursts",
    "gain-drift",
];

/// Whether the library holds the effect of a kind of record.
pub fn library(kind: &str) -> bool {
    matches!(
        kind,
        "path-resonance" | "shaft-modulation" | "planetary-wear" | "tooth-damage" | "pair"
    )
}

/// What a run draws and measures.
pub struct Settings {
    /// Records a base seed (`CL_N`).
    pub n: usize,
    /// Base seeds (`CL_SEEDS`, else `CL_SEED`).
    pub seeds: Vec<u64>,
    /// Every drawn effect scaled by this (`CL_EFFECT_SCALE`), and the same in dB.
    pub scale: f64,
    pub db_scale: f64,
    /// K of the K-draw visibility measure (`CL_VIS_DRAWS`, at least 2).
    pub k_draws: usize,
    /// The kinds drawn, cycled in this order (`CL_KINDS`).
    pub kinds: Vec<&'static str>,
    /// Only these records of each set (`CL_INDICES`; empty: all).
    pub indices: Vec<usize>,
}

impl Settings {
    pub fn from_env() -> Settings {
        let n: usize = env("CL_N", 110);
        // `CL_SEEDS=18,19`: several base seeds in one run (n records each, one report, rows
        // tagged with their seed); otherwise `CL_SEED` alone.
        let seeds: Vec<u64> = std::env::var("CL_SEEDS")
            .ok()
            .map(|v| v.split(',').filter_map(|s| s.trim().parse().ok()).collect())
            .filter(|v: &Vec<u64>| !v.is_empty())
            .unwrap_or_else(|| vec![env("CL_SEED", 2)]);
        // `CL_EFFECT_SCALE` (every drawn effect scaled) and `CL_VIS_DRAWS` (K): module docs.
        let scale: f64 = env("CL_EFFECT_SCALE", 1.0);
        let db_scale = 20.0 * scale.log10();
        let k_draws: usize = env("CL_VIS_DRAWS", 4usize).max(2);
        let only: String = env("CL_KINDS", String::new());
        let kinds: Vec<&str> = KINDS
            .iter()
            .copied()
            .filter(|k| only.is_empty() || only.split(',').any(|o| o == *k))
            .collect();
        // `CL_INDICES=3,17`: only these records of the set (for looking at single records).
        let indices: Vec<usize> = env("CL_INDICES", String::new())
            .split(',')
            .filter_map(|v| v.trim().parse().ok())
            .collect();
        Settings {
            n,
            seeds,
            scale,
            db_scale,
            k_draws,
            kinds,
            indices,
        }
    }

    /// Every record of the run: (base seed, index).
    pub fn records(&self) -> Vec<(u64, usize)> {
        self.seeds
            .iter()
            .flat_map(|&base| {
                (0..self.n)
                    .filter(|i| self.indices.is_empty() || self.indices.contains(i))
                    .map(move |i| (base, i))
            })
            .collect()
    }
}
