"""Helpers shared by the benchmark scripts: isolated runs with time and peak memory, markdown output."""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import textwrap
from pathlib import Path

OUT = Path(__file__).resolve().parent / "_out"


def run_isolated(code: str, *, timeout: float = 3600) -> dict:
    """Run ``code`` in a fresh Python process; it must print one JSON dict as its last line.

    Returns that dict plus ``peak_rss_mb`` (the child's maximum resident set size), so each measurement's
    peak memory is not polluted by earlier work in this process.
    """
    wrapper = textwrap.dedent(
        """
        import json, resource, sys
        ns = {}
        exec(compile(sys.stdin.read(), "<bench>", "exec"), ns)
        out = ns["RESULT"]
        out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
        print(json.dumps(out))
        """
    )
    proc = subprocess.run(
        [sys.executable, "-c", wrapper],
        input=textwrap.dedent(code),
        capture_output=True,
        text=True,
        timeout=timeout,
        env={**os.environ, "SPECTRAGEO_PROGRESS": "0"},
    )
    if proc.returncode != 0:
        raise RuntimeError(f"benchmark child failed:\n{proc.stderr[-4000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def machine_line() -> str:
    try:
        import psutil

        mem = f"{psutil.virtual_memory().total / 2**30:.0f} GiB RAM"
    except ImportError:
        mem = "RAM unknown"
    return f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, {mem}, Python {platform.python_version()}"


def write_section(name: str, markdown: str) -> Path:
    OUT.mkdir(parents=True, exist_ok=True)
    path = OUT / f"{name}.md"
    tmp = path.with_suffix(".md.tmp")
    tmp.write_text(markdown.rstrip() + "\n")
    os.replace(tmp, path)
    print(markdown)
    return path


def data_out_args():
    """``--data DIR`` (default ``$SPECTRAGEO_DATA`` or ``../shared/data``) and ``--out FILE.md``
    of the tuning-data scripts, parsed, with warnings silenced (their tables are the output)."""
    import argparse
    import warnings

    warnings.filterwarnings("ignore")
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default=os.environ.get("SPECTRAGEO_DATA", "../shared/data"))
    ap.add_argument("--out", default=None)
    return ap.parse_args()


#: kinds of registration pairs: the real scans, and every kind of the evaluation
REAL_PAIRS = ("bunny", "open3d")
ALL_PAIRS = ("bunny", "open3d", "generated", "fragment-crops")


def register_tuning_pairs(kinds: tuple[str, ...] = REAL_PAIRS):
    """``(ev, pairs, seed)``: the registration evaluation module, its tuning pairs of ``kinds``
    (``spectrageo.evaluate.register.pairs_for`` on the shared data) and the tuning seed."""
    from spectrageo.datasets import data_dir
    from spectrageo.evaluate import register as ev

    pairs = ev.pairs_for(Path(data_dir(required=True)), ev.TUNING, kinds)
    return ev, pairs, ev.TUNING["reg_seed"]
