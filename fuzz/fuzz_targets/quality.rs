#![no_main]
//! `cargo fuzz run quality`: see `quality` in `fuzz/harness.rs` for what it feeds and checks.

use libfuzzer_sys::fuzz_target;

#[path = "../harness.rs"]
mod harness;

fuzz_target!(|data: &[u8]| harness::quality(data));
