//! The `.npz` capture reader on arbitrary bytes (zip container, `.npy`
//! header, data): an error or a consistent capture, never a panic, never
//! an allocation from a declared size that was not checked.
//!
//! Run by the fuzz target of the same name (`fuzz/fuzz_targets`) and, over
//! the committed corpus, by `tests/tests/fuzz_corpora.rs`.

use std::io::Cursor;
use std::path::Path;

use spiv_formats::npz::read_npz_spikes_from;

/// One input: returns, or panics on a finding.
pub fn run(input: &[u8]) {
    if let Ok(s) = read_npz_spikes_from(Cursor::new(input), Path::new("fuzz.npz")) {
        let pb = usize::from(s.packed_width) * usize::from(s.height) / 8;
        assert_eq!(s.planes.len(), pb * s.ticks);
        assert!(s.packed_width >= s.width);
    }
}
