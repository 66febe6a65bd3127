//! libFuzzer's entry to `fuzz/harness/image_loader.rs` (what it checks is there).
#![no_main]

#[path = "../harness/image_loader.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|input: &[u8]| harness::run(input));
