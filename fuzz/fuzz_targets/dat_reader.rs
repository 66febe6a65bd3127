//! libFuzzer's entry to `fuzz/harness/dat_reader.rs` (what it checks is there).
#![no_main]

#[path = "../harness/dat_reader.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|input: &[u8]| harness::run(input));
