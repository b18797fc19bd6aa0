"""What may skip where: a missing prerequisite (the shared data, a file in it, a peer) skips a
test on a user's machine and fails it under ``CI=true`` (``conftest.skip_or_fail``), and the
peers the differential tests compare against are installed in CI."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from conftest import PEERS, require_module

TESTS = Path(__file__).resolve().parent

PROBE = """
from conftest import require_module


def test_needs_data(shared_data):
    assert shared_data.is_dir()


def test_needs_a_peer():
    require_module("spectrageo_no_such_peer")
"""


def _run_probe(tmp_path: Path, *, ci: bool) -> subprocess.CompletedProcess:
    """pytest in a subprocess on two tests that need what is missing: the shared data (an empty
    ``SPECTRAGEO_DATA`` folder) and a peer that does not exist."""
    probe = tmp_path / "test_probe.py"
    probe.write_text(textwrap.dedent(PROBE))
    empty = tmp_path / "empty_data"
    empty.mkdir(exist_ok=True)
    env = {k: v for k, v in os.environ.items() if k not in ("CI", "PYTHONPATH")}
    env.update(SPECTRAGEO_DATA=str(empty), PYTHONPATH=str(TESTS))
    if ci:
        env["CI"] = "true"
    return subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-rs", "-p", "no:cacheprovider", "-p", "no:dash",
         "-p", "conftest", str(probe)],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300,
    )  # fmt: skip


def test_missing_data_and_peer_fail_under_ci(tmp_path):
    r = _run_probe(tmp_path, ci=True)
    out = r.stdout + r.stderr
    assert r.returncode == 1, out  # 1: tests failed (not 0, nor a usage or collection error)
    # the data fixture's failure is reported as an error of the test that uses it
    assert "1 failed" in out and "1 error" in out and "skipped" not in out, out
    assert "shared data not found" in out and "spectrageo_no_such_peer" in out, out
    assert "CI=true: fails instead of skipping" in out, out


def test_missing_data_and_peer_skip_elsewhere(tmp_path):
    r = _run_probe(tmp_path, ci=False)
    out = r.stdout + r.stderr
    assert r.returncode == 0, out
    assert "2 skipped" in out and "failed" not in out, out
    assert "shared data not found" in out and "spectrageo_no_such_peer" in out, out


@pytest.mark.parametrize("name", PEERS)
def test_peer_is_installed(name):
    """Open3D, PyMeshLab and DracoPy import (CI installs them with the ``test`` extra, and
    Debian's libusb-1.0-0 for Open3D): otherwise the evaluations that run a peer only when it is
    installed would leave it out silently."""
    require_module(name)
