"""Locally sparse points of ``remove_outliers(method="rpca")``
(``_local_density.LOCAL_FACTOR``, ``LOCAL_REFERENCE``, ``LOCAL_FLOOR``), tuning split only.

Per tuning case of ``--task`` (``outliers-scantypes``: clean, 10 / 30 % injected far + near,
the 1-3 / 3-5 / 5-15 spacing bands; ``outliers``: the pattern split), ``rpca`` at its defaults
with each ``factor:reference`` of ``--configs`` (``off``: the stage off), in the same process;
F1 with the clean points removed (%) in brackets, bands: recall per band. ``--robot``: the
horse-gallop robot pipeline (halo 10 %, 12 frames; F1 and theta) per configuration.

    python benchmarks/outliers5_local.py --data /work/shared/data [--task outliers] [--robot]
See docs/decisions.md#outliers5-local-density.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import spectrageo.outliers._local_density as ld
from outliers3_harm import _cell, _f1, _pattern_cases, _scan_type_cases
from spectrageo.outliers import detect_outliers


def _configs(text: str) -> list:
    out = []
    for c in text.split(","):
        if c == "off":
            out.append(("off", None, ld.LOCAL_REFERENCE))
        else:
            f, m = (c.split(":") + [str(ld.LOCAL_REFERENCE)])[:2]
            out.append((c, float(f), int(m)))
    return out


def _with(cfg, fn):
    f0, m0 = ld.LOCAL_FACTOR, ld.LOCAL_REFERENCE
    ld.LOCAL_FACTOR, ld.LOCAL_REFERENCE = cfg[1], cfg[2]
    try:
        return fn()
    finally:
        ld.LOCAL_FACTOR, ld.LOCAL_REFERENCE = f0, m0


def cases_table(data: Path, task: str, configs: list, names) -> None:
    cases = _pattern_cases(data) if task == "outliers" else _scan_type_cases(data, names)
    print("| case | " + " | ".join(c[0] for c in configs) + " |")
    print("|---" * (len(configs) + 1) + "|")
    f1s: dict = {c[0]: [] for c in configs}
    times: dict = {c[0]: 0.0 for c in configs}
    for label, Q, lab, band, opts in cases:
        cells = []
        for c in configs:
            t0 = time.perf_counter()
            r = _with(c, lambda Q=Q, opts=opts: detect_outliers(Q, options=opts))
            times[c[0]] += time.perf_counter() - t0
            if lab.any() and band is None:
                f1s[c[0]].append(_f1(~r.keep, lab))
            cells.append(_cell(~r.keep, lab, band))
        print(f"| {label} | " + " | ".join(cells) + " |", flush=True)
    print("\nmean F1 of the contaminated cases: "
          + ", ".join(f"{k} {np.mean(v):.4f}" for k, v in f1s.items()))  # fmt: skip
    print("seconds: " + ", ".join(f"{k} {v:.1f}" for k, v in times.items()))


def robot(data: Path, configs: list) -> None:
    from spectrageo.evaluate.outliers import evaluate_sequence_patterns

    ds = (("horse-gallop", "animations/horse-gallop.npz", 1),)
    for c in configs:
        rows = _with(c, lambda: evaluate_sequence_patterns(
            data, patterns=("halo",), fractions=(0.1,), datasets=ds, max_frames=12))  # fmt: skip
        rr = [r for r in rows if r["method"] == "robot"][0]
        print(f"robot horse-gallop halo 10 % ({c[0]}): F1 {rr['f1']:.4f}, "
              f"theta {rr['theta_deg']:.2f}", flush=True)  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default="/work/shared/data")
    ap.add_argument(
        "--task", default="outliers-scantypes", choices=("outliers", "outliers-scantypes")
    )
    ap.add_argument("--configs", default="off,2.25", help="factor[:reference] or off, comma list")
    ap.add_argument("--cases", default="", help="comma-separated scan-type case names")
    ap.add_argument("--robot", action="store_true")
    a = ap.parse_args()
    data, configs = Path(a.data), _configs(a.configs)
    if a.robot:
        robot(data, configs)
    else:
        cases_table(data, a.task, configs, set(a.cases.split(",")) if a.cases else None)


if __name__ == "__main__":
    main()
