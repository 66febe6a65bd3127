//! The C example (`examples/c/parity.c`), built with the commands README
//! documents — the static library in release, `cc` — prints the parity
//! lines of the Cortex-M4 firmware and `spiv-firmware-sim --checksum` bit
//! for bit (`firmware-sim/cortex-m4/expected*.txt`, which
//! `firmware-sim/tests/m4_parity.rs` holds to the native loop).

use std::path::{Path, PathBuf};
use std::process::Command;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

#[test]
fn c_example_prints_the_rust_parity_lines() {
    let root = repo();
    let target = Path::new(env!("CARGO_TARGET_TMPDIR")).join("ffi-c");
    // Its own target folder: the outer cargo may still hold the build lock.
    let built = Command::new(env!("CARGO"))
        .args(["build", "-p", "spiv-ffi", "--release", "--target-dir"])
        .arg(&target)
        .current_dir(&root)
        .env_remove("CARGO_TARGET_DIR")
        .status()
        .expect("cargo runs");
    assert!(built.success(), "cargo build -p spiv-ffi --release failed");
    let exe = target.join("parity");
    let cc = Command::new(std::env::var("CC").unwrap_or_else(|_| "cc".into()))
        .args([
            "-O2",
            "-std=c11",
            "-Wall",
            "-Wextra",
            "-pedantic",
            "-Werror",
        ])
        .arg("-I")
        .arg(root.join("ffi/include"))
        .arg(root.join("examples/c/parity.c"))
        .arg(target.join("release/libspiv_ffi.a"))
        .args(["-lpthread", "-ldl", "-lm", "-o"])
        .arg(&exe)
        .status()
        .expect("a C compiler (cc) runs");
    assert!(cc.success(), "cc failed on examples/c/parity.c");
    let m4 = root.join("firmware-sim/cortex-m4");
    let out = Command::new(&exe)
        .arg(m4.join("data/strip.dat"))
        .arg(m4.join("data/control.bin"))
        .output()
        .expect("the example runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let expected = format!(
        "{}mc {}",
        std::fs::read_to_string(m4.join("expected.txt")).unwrap(),
        std::fs::read_to_string(m4.join("expected-mc.txt")).unwrap()
    );
    assert_eq!(String::from_utf8_lossy(&out.stdout), expected);

    // Bad input: one clear line on stderr, a non-zero exit.
    let bad = Command::new(&exe)
        .arg(root.join("no/such/strip.dat"))
        .output()
        .expect("the example runs");
    assert!(!bad.status.success());
    assert_eq!(String::from_utf8_lossy(&bad.stderr).lines().count(), 1);
}
