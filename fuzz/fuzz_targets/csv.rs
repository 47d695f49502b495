#![no_main]
//! `cargo fuzz run csv`: see `gearwear::fuzzing::csv` for what it feeds and checks.

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| gearwear::fuzzing::csv(data));
