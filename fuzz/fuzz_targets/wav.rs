#![no_main]
//! `cargo fuzz run wav`: see `gearwear::fuzzing::wav` for what it feeds and checks.

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| gearwear::fuzzing::wav(data));
