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
    the newer of target/release and target/debug), or skip: tests that compare Python with
    the CLI as a separate process need it."""
    env = os.environ.get("PLANTC_BIN")
    if env:
        return env
    # the newer of the two builds (an older one may predate this tree)
    built = [
        c
        for c in (os.path.join(ROOT, "target", p, "plantc") for p in ("release", "debug"))
        if os.path.isfile(c) and os.access(c, os.X_OK)
    ]
    if built:
        return max(built, key=os.path.getmtime)
    found = shutil.which("plantc")
    if found:
        return found
    pytest.skip("no plantc binary (build it with `cargo build -p plantc` or set PLANTC_BIN)")


def run_cli(binary, *args, cwd=None):
    r = subprocess.run([binary, *args], capture_output=True, text=True, cwd=cwd)
    assert r.returncode == 0, r.stderr
    return r.stdout
