#![no_main]
//! `cargo fuzz run model_config`: see `gearwear::fuzzing::model_config` for what it feeds and checks.

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| gearwear::fuzzing::model_config(data));
