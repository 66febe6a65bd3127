//! The dense-field readers (`.flo` and `.npy`) on arbitrary bytes: an
//! error or a consistent field, never a panic, never an allocation from a
//! declared size that was not checked.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;
use spiv_formats::dense::read_dense_from;

fuzz_target!(|input: &[u8]| {
    let Some((&which, bytes)) = input.split_first() else {
        return;
    };
    let npy = which & 1 == 1;
    if let Ok(f) = read_dense_from(bytes, Path::new("fuzz"), npy) {
        assert_eq!(f.u.len(), f.width * f.height);
        assert_eq!(f.v.len(), f.u.len());
    }
});
