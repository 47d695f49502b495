#![no_main]
//! `cargo fuzz run csv`: see `csv` in `fuzz/harness.rs` for what it feeds and checks.

use libfuzzer_sys::fuzz_target;

#[path = "../harness.rs"]
mod harness;

fuzz_target!(|data: &[u8]| harness::csv(data));
