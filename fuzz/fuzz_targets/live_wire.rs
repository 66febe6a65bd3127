//! libFuzzer's entry to `fuzz/harness/live_wire.rs` (what it checks is there).
#![no_main]

#[path = "../harness/live_wire.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|input: &[u8]| harness::run(input));
