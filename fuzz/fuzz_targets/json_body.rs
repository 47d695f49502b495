#![no_main]
//! `cargo fuzz run json_body`: see `json_body` in `fuzz/harness.rs` for what it feeds and checks.

use libfuzzer_sys::fuzz_target;

#[path = "../harness.rs"]
mod harness;

fuzz_target!(|data: &[u8]| harness::json_body(data));
