"""Where ``spectral`` beats ``predictive``: the gate of ``compress.encode(method="auto")``.

    python benchmarks/codec_auto.py --split tuning     # writes _out/codec_auto_tuning.md

Per mesh of the split registry's ``compress`` task, order kept and ``--reorder``: both methods at
the same ``max_error`` requests (:data:`spectrageo.evaluate.compress.MAX_ERRORS`) and the same
RMS ``error`` requests (:data:`ERRORS`); each row gives the ``predictive`` file's geometry bits per
vertex (file minus connectivity) and the size ratio ``spectral / predictive``. ``auto`` tries
``spectral`` only where the ``predictive`` geometry is at most ``AUTO_SPECTRAL_BPV``; the
largest geometry rate at which ``spectral`` is smaller is the figure that gate must cover.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _util import machine_line, write_section  # noqa: E402
from spectrageo import compress, io  # noqa: E402
from spectrageo._errors import InvalidInputError  # noqa: E402
from spectrageo.datasets import data_dir  # noqa: E402
from spectrageo.evaluate import compress as ev  # noqa: E402

#: RMS ``error`` requests (fraction of the diagonal)
ERRORS = (3e-3, 1e-3, 3e-4, 1e-4, 3e-5, 1e-5)


def _size(V, F, method: str, reorder: bool, **target) -> int | None:
    try:
        return len(compress.encode(V, F, method=method, reorder=reorder, **target))
    except InvalidInputError:
        return None


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--split", default="tuning", choices=sorted(ev.SPLITS))
    args = ap.parse_args()
    root = data_dir(required=True)
    lines = [
        f"## Where spectral beats predictive ({args.split} split)",
        "",
        machine_line(),
        "",
        f"`python benchmarks/codec_auto.py --split {args.split}`: both methods at the same request; "
        "cells: predictive geometry bpv : spectral size / predictive size (bold where spectral is "
        "smaller).",
        "",
        "| model | order | request | cells |",
        "|---|---|---|---|",
    ]
    wins = []
    for rel in ev.SPLITS[args.split]:
        path = root / rel
        if not path.exists():
            continue
        mesh = io.read_mesh(path)
        V, F = mesh.vertices, mesh.faces
        n = V.shape[0]
        for reorder in (True, False):
            conn = compress.info(compress.encode(V, F, method="predictive", reorder=reorder))[
                "connectivity_bpv"
            ]
            for kind, values in (("max_error", ev.MAX_ERRORS), ("error", ERRORS)):
                cells = []
                for v in values:
                    p = _size(V, F, "predictive", reorder, **{kind: v})
                    s = _size(V, F, "spectral", reorder, **{kind: v})
                    if p is None:
                        continue
                    g = 8.0 * p / n - conn
                    if s is None:
                        cells.append(f"{g:.1f}:-")
                        continue
                    r = s / p
                    cells.append(f"**{g:.1f}:{r:.2f}**" if r < 1 else f"{g:.1f}:{r:.2f}")
                    if r < 1:
                        wins.append((g, Path(rel).stem, reorder, kind, v, r))
                order = "reorder" if reorder else "kept"
                lines.append(f"| {Path(rel).stem} | {order} | {kind} | {' '.join(cells)} |")
    lines.append("")
    if wins:
        g, model, reorder, kind, v, r = max(wins)
        lines.append(
            f"Largest predictive geometry rate at which spectral is smaller: {g:.2f} bpv "
            f"({model}, {'reorder' if reorder else 'order kept'}, {kind}={v:g}, ratio {r:.3f}); "
            f"{len(wins)} such points."
        )
    else:
        lines.append("Spectral is smaller at no point.")
    text = "\n".join(lines) + "\n"
    write_section(f"codec_auto_{args.split}", text)


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
