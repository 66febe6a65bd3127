//! The gray image loader (PNG, TIFF, BMP by content) on arbitrary bytes:
//! an error or an image within the size limit, never a panic.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use spiv_firmware_sim::formats::image::read_gray_bytes;
use spiv_firmware_sim::formats::MAX_FRAME_PIXELS;

fuzz_target!(|input: &[u8]| {
    if let Ok(g) = read_gray_bytes(input, Path::new("fuzz.img")) {
        assert!(u64::from(g.width) * u64::from(g.height) <= MAX_FRAME_PIXELS);
        assert_eq!(
            g.data.len() as u64,
            u64::from(g.width) * u64::from(g.height)
        );
        assert!(g.bits == 8 || g.bits == 16);
    }
});
