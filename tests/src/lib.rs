//! End-to-end tests live in `tests/`; this library holds what they share:
//! finding the workspace's binaries and running them.

use std::path::PathBuf;
use std::process::{Command, Output};

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

/// Runs `name args` to its end and returns its output.
pub fn run(name: &str, args: &[&str]) -> Output {
    command(name)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("spawn {name}: {e}"))
}
