"""Shared fixtures: the repository root and the CLI binary built by cargo."""

import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def root() -> Path:
    return ROOT


@pytest.fixture(scope="session")
def cli() -> list[str]:
    """The `nanomotion` command: $NANOMOTION_CLI, else the test-profile build in
    target/ (CI builds it before pytest), else `cargo run --quiet --`."""
    if os.environ.get("NANOMOTION_CLI"):
        return [os.environ["NANOMOTION_CLI"]]
    target = Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
    exe = target / "debug" / "nanomotion"
    if exe.exists():
        return [str(exe)]
    cargo = shutil.which("cargo")
    assert cargo, "neither NANOMOTION_CLI, target/debug/nanomotion nor cargo is available"
    return [cargo, "run", "--quiet", "--manifest-path", str(ROOT / "Cargo.toml"), "--"]


def run_cli(cli: list[str], *args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run([*cli, *args], cwd=cwd, capture_output=True, text=True, timeout=600)
