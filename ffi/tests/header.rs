//! The committed C header is exactly what cbindgen makes of the crate now
//! (`SPIV_BLESS=1` rewrites it).

use std::path::Path;

#[test]
fn committed_header_is_current() {
    let crate_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config =
        cbindgen::Config::from_file(crate_dir.join("cbindgen.toml")).expect("cbindgen.toml");
    let mut out = Vec::new();
    cbindgen::Builder::new()
        .with_crate(crate_dir)
        .with_config(config)
        .generate()
        .expect("cbindgen generates the header")
        .write(&mut out);
    let generated = String::from_utf8(out).expect("utf-8 header");
    let path = crate_dir.join("include/spiv_core.h");
    if std::env::var_os("SPIV_BLESS").is_some() {
        std::fs::write(&path, &generated).expect("write the header");
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        committed == generated,
        "ffi/include/spiv_core.h is stale: run SPIV_BLESS=1 cargo test -p spiv-ffi --test header"
    );
}
