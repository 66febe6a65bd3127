//! End-to-end tests live in `tests/`; this library holds what they share:
//! finding the workspace's binaries and running them.

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, ChildStderr, Command, Output, Stdio};

/// The path of a workspace binary (`spiv`, `spiv-firmware-sim`) built by the
/// same `cargo test` run: it sits in the profile directory two levels above
/// the test executable (`target/<profile>/deps/<test>`). `cargo test
/// --workspace` builds it, because its own package has integration tests.
///
/// # Panics
/// When the binary is not there, with the command that builds it.
pub fn binary(name: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("the test executable's path");
    let dir = exe
        .parent()
        .and_then(|deps| deps.parent())
        .expect("target/<profile>/deps/<test>");
    let path = dir.join(format!("{name}{}", std::env::consts::EXE_SUFFIX));
    assert!(
        path.is_file(),
        "{} is missing: run `cargo test --workspace` (or `cargo build --bins`) first",
        path.display()
    );
    path
}

/// A command for a workspace binary.
pub fn command(name: &str) -> Command {
    Command::new(binary(name))
}

/// Starts `spiv-firmware-sim` with `args` (which include `--tcp HOST:0`)
/// and waits for its listening line: the child, the rest of its stderr,
/// and the address the OS gave it.
///
/// # Panics
/// When it does not start or prints no listening line.
pub fn listening_sidecar(args: &[String]) -> (Child, BufReader<ChildStderr>, String) {
    let mut sim = command("spiv-firmware-sim")
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn spiv-firmware-sim");
    let mut err = BufReader::new(sim.stderr.take().expect("stderr"));
    let mut line = String::new();
    err.read_line(&mut line).expect("read listening line");
    let addr = line
        .trim()
        .strip_prefix("spiv-firmware-sim: listening on ")
        .unwrap_or_else(|| panic!("no listening line: {line}"))
        .to_string();
    (sim, err, addr)
}

/// Runs `name args` to its end and returns its output.
pub fn run(name: &str, args: &[&str]) -> Output {
    command(name)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("spawn {name}: {e}"))
}
