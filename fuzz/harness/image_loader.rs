//! The gray image loader (PNG, TIFF, BMP by content) on arbitrary bytes:
//! an error or an image within the size limit, never a panic. The limit is
//! 2^20 px here (8192 × 8192 in the binaries): the same checks, but an
//! input declaring a huge image costs the fuzzer milliseconds, not seconds.
//!
//! Run by the fuzz target of the same name (`fuzz/fuzz_targets`) and, over
//! the committed corpus, by `tests/tests/fuzz_corpora.rs`.

use std::path::Path;

use spiv_formats::image::read_gray_bytes_within;

const LIMIT: u64 = 1 << 20;

/// One input: returns, or panics on a finding.
pub fn run(input: &[u8]) {
    if let Ok(g) = read_gray_bytes_within(input, Path::new("fuzz.img"), LIMIT) {
        assert!(u64::from(g.width) * u64::from(g.height) <= LIMIT);
        assert_eq!(
            g.data.len() as u64,
            u64::from(g.width) * u64::from(g.height)
        );
        assert!(g.bits == 8 || g.bits == 16);
    }
}
