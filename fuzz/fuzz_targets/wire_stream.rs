//! libFuzzer's entry to `fuzz/harness/wire_stream.rs` (what it checks is there).
#![no_main]

#[path = "../harness/wire_stream.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|input: &[u8]| harness::run(input));
