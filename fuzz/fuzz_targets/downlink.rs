//! libFuzzer's entry to `fuzz/harness/downlink.rs` (what it checks is there).
#![no_main]

#[path = "../harness/downlink.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|input: &[u8]| harness::run(input));
