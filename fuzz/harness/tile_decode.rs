//! The tile decoders (raw, Rice, sparse, Context, SparseContext) on
//! arbitrary payloads and geometries, into 8- and 16-bit frames: an error
//! or samples, never a panic; what decodes as 8-bit decodes to the same
//! levels as 16-bit.
//!
//! Run by the fuzz target of the same name (`fuzz/fuzz_targets`) and, over
//! the committed corpus, by `tests/tests/fuzz_corpora.rs`.

use spiv_core::wire::codec::{decode_tile, tile_scratch};
use spiv_core::wire::Encoding;

/// One input: returns, or panics on a finding.
pub fn run(input: &[u8]) {
    if input.len() < 4 {
        return;
    }
    let Some(enc) = Encoding::from_u8(input[0] % 7) else {
        return;
    };
    // Up to 256 × 32 samples: the codecs' loops, not the memory, are tested.
    let width = u16::from(input[1]) + 1;
    let rows = u16::from(input[2] % 32) + 1;
    let payload = &input[4..];
    let n = usize::from(width) * usize::from(rows);
    let mut scratch = vec![0u16; tile_scratch(enc, width, rows, 2)];
    let mut out8 = vec![0u8; n];
    let r8 = decode_tile(enc, payload, width, rows, &mut scratch, &mut out8);
    let mut out16 = vec![0u16; n];
    let r16 = decode_tile(enc, payload, width, rows, &mut scratch, &mut out16);
    if r8.is_ok() {
        // What decodes as 8-bit decodes the same as 16-bit.
        assert!(r16.is_ok());
        assert!(out8.iter().zip(&out16).all(|(&a, &b)| u16::from(a) == b));
    }
    // A short output buffer is an error, not a panic.
    let mut short = vec![0u8; n - 1];
    assert!(decode_tile(enc, payload, width, rows, &mut scratch, &mut short).is_err());
}
