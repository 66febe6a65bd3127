//! libFuzzer's entry to `fuzz/harness/tile_decode.rs` (what it checks is there).
#![no_main]

#[path = "../harness/tile_decode.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|input: &[u8]| harness::run(input));
