//! The dense-field readers (`.flo` and `.npy`) on arbitrary bytes: an
//! error or a consistent field, never a panic, never an allocation from a
//! declared size that was not checked.
//!
//! Run by the fuzz target of the same name (`fuzz/fuzz_targets`) and, over
//! the committed corpus, by `tests/tests/fuzz_corpora.rs`.

use std::path::Path;

use spiv_formats::dense::read_dense_from;

/// One input: returns, or panics on a finding.
pub fn run(input: &[u8]) {
    let Some((&which, bytes)) = input.split_first() else {
        return;
    };
    let npy = which & 1 == 1;
    if let Ok(f) = read_dense_from(bytes, Path::new("fuzz"), npy) {
        assert_eq!(f.u.len(), f.width * f.height);
        assert_eq!(f.v.len(), f.u.len());
    }
}
