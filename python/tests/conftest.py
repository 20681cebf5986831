"""Shared fixtures: the repository root, the CLI binary when built."""

import os
import shutil
import subprocess

import pytest

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))


def model_path(name: str) -> str:
    return os.path.join(ROOT, "models", name)


def data_dir(name: str) -> str:
    return os.path.join(ROOT, "data", name)


@pytest.fixture(scope="session")
def plantc_bin():
    """The `plantc` command line built from this tree (PLANTC_BIN, else
    target/release or target/debug), or skip: tests that compare Python with
    the CLI as a separate process need it."""
    cands = [os.environ.get("PLANTC_BIN")] + [
        os.path.join(ROOT, "target", p, "plantc") for p in ("release", "debug")
    ]
    for c in cands:
        if c and os.path.isfile(c) and os.access(c, os.X_OK):
            return c
    found = shutil.which("plantc")
    if found:
        return found
    pytest.skip("no plantc binary (build it with `cargo build -p plantc` or set PLANTC_BIN)")


def run_cli(binary, *args, cwd=None):
    r = subprocess.run([binary, *args], capture_output=True, text=True, cwd=cwd)
    assert r.returncode == 0, r.stderr
    return r.stdout
