#![no_main]
//! `cargo fuzz run json_body`: see `gearwear::fuzzing::json_body` for what it feeds and checks.

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| gearwear::fuzzing::json_body(data));
