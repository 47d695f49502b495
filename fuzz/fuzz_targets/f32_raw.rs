#![no_main]
//! `cargo fuzz run f32_raw`: see `gearwear::fuzzing::f32_raw` for what it feeds and checks.

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| gearwear::fuzzing::f32_raw(data));
