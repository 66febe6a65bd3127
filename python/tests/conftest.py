"""Fixtures: the `spiv` command line the module is held to, and one
simulated recording written by it."""

import os
import pathlib
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def cli():
    """The `spiv` binary: $SPIV_BIN, else built here (release)."""
    exe = os.environ.get("SPIV_BIN")
    if not exe:
        subprocess.run(
            ["cargo", "build", "--release", "-q", "-p", "spiv-host", "--bin", "spiv"],
            cwd=ROOT,
            check=True,
        )
        target = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
        exe = str(target / "release" / "spiv")

    def run(*args, check=True):
        return subprocess.run(
            [exe, *map(str, args)], capture_output=True, text=True, check=check
        )

    return run


@pytest.fixture(scope="session")
def recording(cli, tmp_path_factory):
    """`spiv simulate` of a small uniform scene: 2.0 px right, 1.0 px down."""
    d = tmp_path_factory.mktemp("uniform")
    cli("simulate", "--scene", "uniform", "--shift", "2.0,1.0", "--width", "128",
        "--height", "128", "--seed", "3", "--out", d)
    return d


@pytest.fixture(scope="session")
def messages(tmp_path_factory):
    """A file of wire messages from `spiv-firmware-sim` (uniform scene, 3
    pairs): $SPIV_FIRMWARE_SIM_BIN, else built here (release)."""
    exe = os.environ.get("SPIV_FIRMWARE_SIM_BIN")
    if not exe:
        subprocess.run(
            ["cargo", "build", "--release", "-q", "-p", "spiv-firmware-sim"],
            cwd=ROOT,
            check=True,
        )
        target = pathlib.Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
        exe = str(target / "release" / "spiv-firmware-sim")
    path = tmp_path_factory.mktemp("link") / "messages.bin"
    subprocess.run([exe, "--scene", "uniform", "--pairs", "3", "--out", str(path)],
                   capture_output=True, check=True)
    return path
