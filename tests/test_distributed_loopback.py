"""Issue 21 (b): the CLI runs unchanged against a real ``distributed`` scheduler.

A module fixture starts ``dask scheduler`` and two ``dask worker`` processes (one thread each) on
127.0.0.1 from the venv's own ``dask`` command; the tests run ``spectrageo outliers IN OUT --tile N
--scheduler ADDRESS`` and ``spectrageo batch outliers ... --scheduler ADDRESS`` as subprocesses and
compare with the same commands on a local cluster (``--workers``) and with the untiled run. The
processes are always stopped (terminate, then kill after a timeout) by the fixture's finalizer.
Skipped when dask/distributed or the ``dask`` command is missing.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("dask")
distributed = pytest.importorskip("distributed")

from spectrageo import io, outliers  # noqa: E402
from spectrageo.geometry import PointCloud  # noqa: E402

from conftest import outlier_recall_precision, skip_or_fail  # noqa: E402

BIN = Path(sys.executable).parent
START_TIMEOUT = 40.0  # s, scheduler file + both workers registered
RUN_TIMEOUT = 120  # s, one CLI call


def _exe(name: str) -> str | None:
    p = BIN / name
    return str(p) if p.exists() else shutil.which(name)


def _stop(procs: list[subprocess.Popen]) -> None:
    """SIGTERM every process we started (workers first), SIGKILL what is left after 5 s."""
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGTERM)
    deadline = time.monotonic() + 5.0
    for p in procs:
        try:
            p.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait(timeout=5)


@pytest.fixture(scope="module")
def scheduler(tmp_path_factory, request):
    """Address of a loopback ``dask scheduler`` with two single-threaded ``dask worker``s."""
    dask_cli = _exe("dask")
    if dask_cli is None:
        skip_or_fail("the `dask` command (distributed) is not on PATH")
    root = tmp_path_factory.mktemp("loopback")
    sfile = root / "scheduler.json"
    env = {**os.environ, "DASK_DISTRIBUTED__WORKER__DAEMON": "False"}
    logs: list = []
    procs: list[subprocess.Popen] = []

    def spawn(args, name):
        log = open(root / f"{name}.log", "wb")  # noqa: SIM115 - closed by the finalizer
        logs.append(log)
        procs.append(
            subprocess.Popen(
                [dask_cli, *args], stdout=log, stderr=subprocess.STDOUT, cwd=root, env=env
            )
        )

    def finalize():
        _stop(procs[::-1])
        for log in logs:
            log.close()

    request.addfinalizer(finalize)
    spawn(
        ["scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
         "--scheduler-file", str(sfile)],
        "scheduler",
    )  # fmt: skip
    deadline = time.monotonic() + START_TIMEOUT
    while not sfile.exists() or not sfile.read_text().strip():
        if procs[0].poll() is not None or time.monotonic() > deadline:
            pytest.fail("dask scheduler did not start:\n" + (root / "scheduler.log").read_text())
        time.sleep(0.2)
    time.sleep(0.2)  # the file is written in one go, but give the writer a moment
    address = json.loads(sfile.read_text())["address"]
    assert address.startswith("tcp://127.0.0.1:")
    for i in range(2):
        spawn(
            ["worker", address, "--nthreads", "1", "--no-nanny", "--no-dashboard",
             "--host", "127.0.0.1", "--local-directory", str(root / f"w{i}"),
             "--death-timeout", "60"],
            f"worker{i}",
        )  # fmt: skip
    with distributed.Client(address, timeout="20s") as c:
        try:
            c.wait_for_workers(2, timeout=max(1.0, deadline - time.monotonic()))
        except (TimeoutError, OSError) as exc:
            logs_text = "\n".join(
                (root / f"{n}.log").read_text(errors="replace") for n in ("worker0", "worker1")
            )
            pytest.fail(f"dask workers did not register: {exc}\n{logs_text}")
    return address


def _cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    r = subprocess.run(
        [sys.executable, "-m", "spectrageo.cli.main", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=RUN_TIMEOUT,
    )
    assert r.returncode == 0, f"spectrageo {' '.join(args)} failed:\n{r.stdout}\n{r.stderr}"
    return r


def _cloud(n=6000, n_out=120, seed=0):
    rng = np.random.default_rng(seed)
    u = rng.uniform(0, 1, (n, 2))
    P = np.c_[u, 0.05 * np.sin(6 * u[:, 0]) + 0.002 * rng.standard_normal(n)]
    O = rng.uniform([0, 0, -0.3], [1, 1, 0.3], (n_out, 3))
    return np.r_[P, O]


def _labels(X, n_out):
    """Injected outliers (the last ``n_out`` rows of :func:`_cloud`) and those of them farther
    than 0.02 (10 sigma of the surface noise) from the surface; the others (about 7 %) lie on
    it and no filter can tell them apart."""
    injected = np.zeros(len(X), dtype=bool)
    injected[len(X) - n_out :] = True
    off = np.abs(X[:, 2] - 0.05 * np.sin(6 * X[:, 0]))
    return injected, injected & (off > 0.02)


def test_cli_module_entry_point():
    """``python -m spectrageo.cli.main`` is the ``spectrageo`` command (what the tests run)."""
    r = subprocess.run(
        [sys.executable, "-m", "spectrageo.cli.main", "outliers", "--help"],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert r.returncode == 0 and "--scheduler" in r.stdout


@pytest.mark.parametrize("method", ["sor", "rpca"])
def test_outliers_tile_against_loopback_scheduler(scheduler, tmp_path, method):
    P = _cloud()
    src = tmp_path / "cloud.ply"
    io.write(src, PointCloud(P))
    # untiled and local-cluster references, then the same command with --scheduler
    _cli("outliers", str(src), str(tmp_path / "ref.ply"), "--method", method,
         "--mask", str(tmp_path / "ref.npy"), cwd=tmp_path)  # fmt: skip
    if method == "rpca":  # sor is exact: the untiled run is the reference (no second cluster)
        _cli("outliers", str(src), str(tmp_path / "loc.ply"), "--method", method, "--tile",
             "1600", "--workers", "2", "--mask", str(tmp_path / "loc.npy"), cwd=tmp_path)  # fmt: skip
    r = _cli("outliers", str(src), str(tmp_path / "rem.ply"), "--method", method, "--tile",
             "1600", "--scheduler", scheduler, "--mask", str(tmp_path / "rem.npy"),
             cwd=tmp_path)  # fmt: skip
    assert "2 workers" in r.stderr and "4 tiles" in r.stderr, r.stderr
    ref, rem = np.load(tmp_path / "ref.npy"), np.load(tmp_path / "rem.npy")
    assert rem.shape == (len(P),) and rem.dtype == bool
    np.testing.assert_array_equal(io.read(tmp_path / "rem.ply").points, P[rem])
    if method == "sor":  # exact across tiles (docs/scaling.md): the untiled keep mask and file
        np.testing.assert_array_equal(rem, ref)
        assert not rem.all()
        assert (tmp_path / "rem.ply").read_bytes() == (tmp_path / "ref.ply").read_bytes()
    else:  # rpca: the scheduler does not change the tiled result (same mask and file as a
        # local cluster); several tiles approximate the untiled run
        np.testing.assert_array_equal(rem, np.load(tmp_path / "loc.npy"))
        assert (tmp_path / "rem.ply").read_bytes() == (tmp_path / "loc.ply").read_bytes()
        # both find the outliers: measured on _cloud(seed=0..19) with 4 tiles of 1600 points,
        # recall 0.96-1.0 of the detectable outliers (tiled and untiled), precision 0.97-1.0;
        # 0-3 of the 6120 masks' entries differ, against about 120 if one run kept the outliers
        injected, detectable = _labels(P, 120)
        for keep in (ref, rem):
            recall, precision = outlier_recall_precision(keep, injected, detectable)
            assert recall >= 0.95 and precision >= 0.9, (recall, precision)
        assert np.count_nonzero(rem != ref) <= 0.15 * 120
    assert not any(".tiles-" in p.name for p in tmp_path.iterdir())  # scratch removed


def test_batch_against_loopback_scheduler(scheduler, tmp_path):
    d = tmp_path / "in"
    d.mkdir()
    for i in range(2):
        np.save(d / f"c{i}.npy", _cloud(n=3000, n_out=60, seed=i))
    _cli("batch", "outliers", str(d), "--out", str(tmp_path / "rem"), "--scheduler", scheduler,
         "--method", "sor", cwd=tmp_path)  # fmt: skip
    summary = json.loads((tmp_path / "rem" / "batch-summary.json").read_text())
    assert summary["scheduler"] == scheduler and summary["workers"] == 2
    assert summary["n_ok"] == 2 and len(summary["files"]) == 2
    for i in range(2):  # what `spectrageo outliers c{i}.npy ... --method sor` keeps
        X = np.load(d / f"c{i}.npy")
        ref = outliers.remove_outliers(X, method="sor", k=10)
        np.testing.assert_array_equal(np.load(tmp_path / "rem" / f"c{i}.npy"), X[ref.keep])
        assert 0 < ref.keep.sum() < len(X)


def test_rpca_tiles_equal_untiled_against_loopback_scheduler(scheduler, tmp_path):
    """Python API on the real scheduler: RPCA tiles at ``block_size`` equal the untiled run."""
    from spectrageo import distributed as sgd

    P = _cloud()
    np.save(tmp_path / "c.npy", P)
    opts = outliers.RPCAOptions(block_size=1600)
    ref = outliers.remove_outliers(P, options=opts)
    r = sgd.remove_outliers_tiled(
        tmp_path / "c.npy", None, sgd.TileOptions(1600, scheduler=scheduler), options=opts
    )
    assert r.n_tiles == 4 and r.info["n_workers"] == 2
    np.testing.assert_array_equal(r.scores, ref.scores)
    np.testing.assert_array_equal(r.keep, ref.keep)
    recall, precision = outlier_recall_precision(r.keep, *_labels(P, 120))  # not vacuous
    assert recall >= 0.95 and precision >= 0.9, (recall, precision)
