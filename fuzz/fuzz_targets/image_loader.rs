//! The gray image loader (PNG, TIFF, BMP by content) on arbitrary bytes:
//! an error or an image within the size limit, never a panic. The limit is
//! 2^20 px here (8192 × 8192 in the binaries): the same checks, but an
//! input declaring a huge image costs the fuzzer milliseconds, not seconds.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use spiv_formats::image::read_gray_bytes_within;

const LIMIT: u64 = 1 << 20;

fuzz_target!(|input: &[u8]| {
    if let Ok(g) = read_gray_bytes_within(input, Path::new("fuzz.img"), LIMIT) {
        assert!(u64::from(g.width) * u64::from(g.height) <= LIMIT);
        assert_eq!(
            g.data.len() as u64,
            u64::from(g.width) * u64::from(g.height)
        );
        assert!(g.bits == 8 || g.bits == 16);
    }
});
