//! Every committed fuzz corpus input (`fuzz/corpus/<target>`) through its
//! target's own harness (`fuzz/harness/<target>.rs`, the code libFuzzer
//! runs): the minimised inputs that reach every branch the fuzzer found,
//! replayed on every test run without the fuzzer's instrumented build. Debug and overflow assertions are on in
//! the test profile, as in the fuzz build.

use std::path::PathBuf;

#[path = "../../fuzz/harness/dat_reader.rs"]
mod dat_reader;
#[path = "../../fuzz/harness/dense_reader.rs"]
mod dense_reader;
#[path = "../../fuzz/harness/downlink.rs"]
mod downlink;
#[path = "../../fuzz/harness/image_loader.rs"]
mod image_loader;
#[path = "../../fuzz/harness/live_wire.rs"]
mod live_wire;
#[path = "../../fuzz/harness/npz_reader.rs"]
mod npz_reader;
#[path = "../../fuzz/harness/tile_decode.rs"]
mod tile_decode;
#[path = "../../fuzz/harness/wire_stream.rs"]
mod wire_stream;

/// A target's name and its harness.
type Target = (&'static str, fn(&[u8]));

/// Runs `run` on every file of `fuzz/corpus/<target>`, naming the file
/// that panics; returns how many inputs ran.
fn replay(target: &str, run: fn(&[u8])) -> usize {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../fuzz/corpus")
        .join(target);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.expect("a corpus entry").path())
        .collect();
    files.sort();
    for f in &files {
        let input = std::fs::read(f).expect("a corpus file");
        if std::panic::catch_unwind(|| run(&input)).is_err() {
            panic!("{target}: {} fails", f.display());
        }
    }
    files.len()
}

#[test]
fn every_corpus_input_passes_its_harness() {
    let targets: [Target; 8] = [
        ("wire_stream", wire_stream::run),
        ("tile_decode", tile_decode::run),
        ("downlink", downlink::run),
        ("live_wire", live_wire::run),
        ("dat_reader", dat_reader::run),
        ("npz_reader", npz_reader::run),
        ("image_loader", image_loader::run),
        ("dense_reader", dense_reader::run),
    ];
    for (target, run) in targets {
        let n = replay(target, run);
        // A corpus emptied or moved would make this test pass on nothing.
        assert!(n >= 50, "{target}: only {n} corpus inputs");
        eprintln!("{target}: {n} inputs");
    }
}
