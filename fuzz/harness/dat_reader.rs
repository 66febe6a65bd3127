//! The Vidar `.dat` reader on arbitrary bytes with sizes and options from
//! the input's head: every plane read, seeks anywhere, never a panic.
//!
//! Run by the fuzz target of the same name (`fuzz/fuzz_targets`) and, over
//! the committed corpus, by `tests/tests/fuzz_corpora.rs`.

use std::io::Cursor;
use std::path::Path;

use spiv_formats::dat::{DatOptions, DatReader};

/// One input: returns, or panics on a finding.
pub fn run(input: &[u8]) {
    if input.len() < 6 {
        return;
    }
    let width = u16::from_le_bytes([input[0], input[1]]);
    let height = u16::from_le_bytes([input[2], input[3]]);
    let opts = DatOptions {
        flip: input[4] & 1 == 1,
        allow_truncated: input[4] & 2 == 2,
        strip_head: u16::from(input[5]),
    };
    let Ok(mut r) = DatReader::from_reader(
        Cursor::new(&input[6..]),
        Path::new("fuzz.dat"),
        width,
        height,
        opts,
    ) else {
        return;
    };
    let mut plane = vec![0u8; r.out_plane_bytes()];
    let mut planes = 0u64;
    while r
        .read_plane(&mut plane)
        .expect("whole planes are in memory")
    {
        planes += 1;
    }
    assert_eq!(planes, r.planes());
    let got = r.read_range(u64::from(input[4]), 3).expect("a range");
    assert!(got.len() <= 3 * r.out_plane_bytes());
}
