//! Where a bench writes its rows and dumps: the path in an environment variable, else
//! `target/bench/` (under `CARGO_TARGET_DIR` when it is set), never the source tree's `docs/`.
//! Included with `#[path]` by the benches that write files.

use std::path::PathBuf;

/// The path in the environment variable `var` (non-empty), else `<target>/bench/<name>`; the
/// parent directory is created.
pub fn out_path(var: &str, name: &str) -> PathBuf {
    let path = match std::env::var(var) {
        Ok(p) if !p.is_empty() => PathBuf::from(p),
        _ => {
            let target = std::env::var_os("CARGO_TARGET_DIR")
                .map(PathBuf::from)
                .unwrap_or_else(|| PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/target")));
            target.join("bench").join(name)
        }
    };
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).expect("the output directory can be created");
    }
    path
}
