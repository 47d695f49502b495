#![no_main]
//! `cargo fuzz run csv_gz`: see `gearwear::fuzzing::csv_gz` for what it feeds and checks.

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| gearwear::fuzzing::csv_gz(data));
