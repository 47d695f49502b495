#![no_main]
//! `cargo fuzz run f32_raw`: see `f32_raw` in `fuzz/harness.rs` for what it feeds and checks.

use libfuzzer_sys::fuzz_target;

#[path = "../harness.rs"]
mod harness;

fuzz_target!(|data: &[u8]| harness::f32_raw(data));
