"""Static ``--reorder`` size against Draco's default mode at equal exact symmetric Hausdorff.

    python benchmarks/codec_predictive.py --split tuning       # writes _out/codec_predictive_tuning.md
    python benchmarks/codec_predictive.py --split validation   # the held-out meshes, once
    python benchmarks/codec_predictive.py --split validation --methods auto-reorder
                                          # the default method alone: _out/codec_auto_reorder_*.md

Per mesh of the split registry's ``compress`` task: Draco (level 10) at 6-16 quantisation bits,
``predictive-reorder`` at the ``max_error`` points and ``spectral-reorder`` at its steps of
``spectrageo evaluate compress``, all in this run; the ratio is the best of ours interpolated at
each Draco point's Hausdorff distance (log-log) over Draco's size. ``conn`` is our connectivity
chunk (bits per vertex) at the first point.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _util import machine_line, write_section  # noqa: E402
from spectrageo.datasets import data_dir  # noqa: E402
from spectrageo.evaluate import compress as ev  # noqa: E402

DEFAULT_METHODS = "predictive-reorder,spectral-reorder"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--split", default="tuning", choices=sorted(ev.SPLITS))
    ap.add_argument("--methods", default=DEFAULT_METHODS)
    args = ap.parse_args()
    methods = args.methods.split(",") + ["draco"]
    rows = ev.evaluate(data_dir(required=True), methods, splits=(args.split,))
    flag = "" if args.methods == DEFAULT_METHODS else f" --methods {args.methods}"
    eq = [r for r in ev.equal_error_rows(rows) if r["peer"].startswith("draco q=")]
    lines = [
        "## Static --reorder against Draco at equal Hausdorff"
        + ("" if args.methods == DEFAULT_METHODS else f", {args.methods}")
        + f" ({args.split} split)",
        "",
        machine_line(),
        "",
        f"`python benchmarks/codec_predictive.py --split {args.split}{flag}`: "
        + ("the smaller of " if len(methods) > 2 else "")
        + f"{' and '.join(args.methods.split(','))} over Draco's default mode (DracoPy, compression "
        "level 10, which reorders) at each Draco point's exact symmetric Hausdorff distance, "
        "Draco in the same run; `conn bpv`: our connectivity share.",
        "",
        "| model | conn bpv | " + " | ".join(f"q={b}" for b in ev.DRACO_BITS) + " |",
        "|---|---|" + "---|" * len(ev.DRACO_BITS),
    ]
    ratios = []
    for model in dict.fromkeys(r["model"] for r in eq):
        conn = next(
            (r["conn_bpv"] for r in rows if r["model"] == model and r["method"] == methods[0]),
            float("nan"),
        )
        cells = []
        for b in ev.DRACO_BITS:
            r = next((r for r in eq if r["model"] == model and r["peer"] == f"draco q={b}"), None)
            if r is None or not np.isfinite(r["ratio"]):
                cells.append("-")
                continue
            ratios.append(r["ratio"])
            who = "" if r["ours"] == methods[0] else f" ({r['ours'].split('-')[0]})"
            cells.append(f"{r['ratio']:.3f} @ {r['peer_bpv']:.1f}{who}")
        lines.append(f"| {model} | {conn:.2f} | " + " | ".join(cells) + " |")
    if ratios:
        lines += [
            "",
            f"Geometric mean {np.exp(np.mean(np.log(ratios))):.3f}, largest {max(ratios):.3f} "
            "(cells: our size / Draco's at Draco's Hausdorff, @ Draco's bits per vertex).",
        ]
    name = "codec_predictive" if args.methods == DEFAULT_METHODS else "codec_" + methods[0]
    write_section(f"{name.replace('-', '_')}_{args.split}", "\n".join(lines))


if __name__ == "__main__":
    main()
