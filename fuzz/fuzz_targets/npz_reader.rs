//! libFuzzer's entry to `fuzz/harness/npz_reader.rs` (what it checks is there).
#![no_main]

#[path = "../harness/npz_reader.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|input: &[u8]| harness::run(input));
