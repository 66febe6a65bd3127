//! The Cortex-M4 firmware's input through the native firmware loop: the
//! parity line `spiv-firmware-sim --checksum` prints must be the one
//! committed in `cortex-m4/expected.txt`, which the firmware under QEMU must
//! print too (`firmware-sim/cost.sh`, run by `.ci/run`). A change of the
//! core's output shows here first; a platform difference shows there.

use std::process::Command;

#[test]
fn native_loop_prints_the_committed_parity_line() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("cortex-m4");
    let out = Command::new(env!("CARGO_BIN_EXE_spiv-firmware-sim"))
        .args(["--pairs", "1", "--checksum", "--input"])
        .arg(dir.join("data/strip.dat"))
        .output()
        .expect("run spiv-firmware-sim");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let want = std::fs::read_to_string(dir.join("expected.txt")).expect("expected.txt");
    assert_eq!(String::from_utf8_lossy(&out.stdout).trim(), want.trim());
}
