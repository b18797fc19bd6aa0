"""Batch driver run in a child process: ``python driver.py LOG JOBS TIMEOUT``.

Each job of the JSON list ``JOBS`` runs :func:`spectrageo.cli.main.main` on its ``argv`` under a
SIGALRM timeout, with Python's and file descriptor 2's output captured; a successful ``convert``
is then checked (:func:`check_output`). One JSON line per job start and end goes to ``LOG``, so
the parent can name the job a dead batch was running.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import signal
import sys
import tempfile
import time

import numpy as np


class _Timeout(BaseException):
    pass


def _alarm(signum, frame):
    raise _Timeout()


def load_result(path: str) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (frames stacked for an animation) and faces of a ``convert`` output."""
    if path.endswith(".npz"):
        with np.load(path) as d:
            return np.asarray(d["vertices"], float), np.asarray(d["faces"])
    from spectrageo import io as sio

    obj = sio.read(path)
    V = obj.vertices if hasattr(obj, "vertices") else obj.points
    F = getattr(obj, "faces", None)
    return np.asarray(V, float), np.zeros((0, 3), int) if F is None else np.asarray(F)


def check_output(out: str, ref: tuple | None, expect: str) -> str | None:
    """None when the written result keeps the invariants, else what is wrong with it."""
    if expect == "error":
        return "accepted a file that must be refused"
    V, F = load_result(out)
    if not np.isfinite(V).all():
        return f"{int((~np.isfinite(V)).any(axis=-1).sum())} non-finite vertices"
    n = V.shape[-2] if V.ndim >= 2 else 0
    if F.size and (F.min() < 0 or F.max() >= n):
        return f"face index {int(F.max())} out of range for {n} vertices"
    if ref is not None and expect == "seed":
        RV, RF = ref
        if RV.shape != V.shape or RF.shape != F.shape or not np.array_equal(RF, F):
            return f"decoded {V.shape}/{F.shape} instead of the seed's {RV.shape}/{RF.shape}"
        diag = float(np.linalg.norm(np.ptp(RV.reshape(-1, 3), axis=0))) or 1.0
        err = float(np.abs(RV - V).max()) if V.size else 0.0
        if err > 1e-6 * diag:
            return f"decoded a different result than the seed (max difference {err:.3g})"
    return None


def check_self_metrics(stdout: str) -> str | None:
    """None when ``metrics F F`` found the file identical to itself, else what it reported."""
    d = json.loads(stdout)
    if "dmax" not in d:
        return "no vertex correspondence between a file and itself"
    if not (d["dmax"] == 0 and float(d.get("hd_max", 0)) <= 1e-9 * max(1.0, float(d["dmax"]))):
        return f"a file differs from itself (dmax {d['dmax']}, hd_max {d.get('hd_max')})"
    return None


def _call(main, argv, limit):
    out, err = io.StringIO(), io.StringIO()
    cap = tempfile.TemporaryFile()
    saved = os.dup(2)
    os.dup2(cap.fileno(), 2)  # native code writing to fd 2 counts as stderr too
    t0 = time.perf_counter()
    signal.alarm(limit)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = main(argv)
    except _Timeout:
        code = None
    except SystemExit as exc:
        code = exc.code
    except BaseException as exc:  # noqa: BLE001 - every escape is an outcome to report
        code = "raised " + type(exc).__name__ + ": " + str(exc)[:200]
    finally:
        signal.alarm(0)
        dt = time.perf_counter() - t0
        sys.stderr.flush()
        os.dup2(saved, 2)
        os.close(saved)
    cap.seek(0)
    native = cap.read().decode("utf-8", "replace")
    cap.close()
    lines = [ln for ln in (err.getvalue() + native).splitlines() if ln.strip()]
    return code, lines, out.getvalue(), dt


def run(log_path: str, jobs_path: str, limit: int) -> None:
    signal.signal(signal.SIGALRM, _alarm)
    from spectrageo.cli.main import main

    refs: dict[str, tuple | None] = {}
    with open(log_path, "a", buffering=1) as log:
        for job in json.loads(open(jobs_path).read()):
            log.write(json.dumps({"start": job["id"]}) + "\n")
            log.flush()
            code, lines, stdout, dt = _call(main, job["argv"], limit)
            wrong = None
            chk = job.get("check")
            if code == 0 and chk:
                try:
                    if chk.get("self_metrics"):
                        wrong = check_self_metrics(stdout)
                        chk = {}
                    ref = None
                    if chk.get("ref_seed"):
                        if chk["ref_seed"] not in refs:
                            r = chk["ref_out"]
                            ok = _call(main, ["convert", chk["ref_seed"], r], limit)[0] == 0
                            refs[chk["ref_seed"]] = load_result(r) if ok else None
                        ref = refs[chk["ref_seed"]]
                    if chk:
                        wrong = check_output(chk["out"], ref, chk.get("expect", ""))
                except Exception as exc:  # noqa: BLE001 - an unreadable output is wrong too
                    wrong = f"output unreadable: {type(exc).__name__}: {str(exc)[:160]}"
            rec = {"id": job["id"], "code": code, "lines": lines[:6], "n_lines": len(lines)}
            rec.update(stdout=stdout[:1_000_000] if code == 0 else "", seconds=dt, wrong=wrong)
            log.write(json.dumps(rec) + "\n")
            log.flush()


if __name__ == "__main__":
    run(sys.argv[1], sys.argv[2], int(sys.argv[3]))
