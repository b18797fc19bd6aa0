"""Re-choose the default ``sparse_norm`` of the geometric saliency on a tuning split of the maps.

The only reference maps are the four of ``saliency/`` (block, cad, casting, fandisk), which are
also the whole evaluation of ``spectrageo evaluate saliency``. Split, fixed by a rule before any
result of this script was looked at: the models in alphabetical order, the first two are the
tuning split and the last two the validation split (:data:`TUNING`, :data:`VALIDATION`).

Candidates: ``sparse_norm`` in {``"patch"`` (row norm of ``S``), ``"center"`` (first 3-vector,
Eq. 6.9)}. Everything else at its default (``k = 25``, guided normals, group shrinkage, internal
solver, ``tol = 1e-4``).

Objective (fixed before the run): the mean, over the tuning models and the two maps that read
``sparse_norm`` by default (``method="geometric"`` and ``method="combined"``, per face), of the
Pearson correlation with the reference per-face map. A difference below ``TIE`` = 0.005 is a tie,
which keeps the current default. The ``fast`` variant's Pearson and Spearman correlations are
reported, not scored.

    python benchmarks/retune_saliency.py                        # tuning: table and choice
    python benchmarks/retune_saliency.py --validation           # validation, installed default

Outputs in ``benchmarks/_out/retune_saliency/``: ``tuning.{md,csv}`` and, with ``--validation``,
``validation_<default>.{md,csv}`` (one row per model, method and ``sparse_norm``).
"""

from __future__ import annotations

import argparse
import csv
import inspect
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import OUT, machine_line  # noqa: E402

OUT_DIR = OUT / "retune_saliency"
MODELS = ("block", "cad", "casting", "fandisk")
_ORDER = sorted(MODELS)
TUNING = tuple(_ORDER[:2])
VALIDATION = tuple(_ORDER[2:])
CANDIDATES = ("patch", "center")
SCORED = ("geometric", "combined")
REPORTED = ("fast",)
TIE = 0.005
COLS = ("split", "model", "method", "sparse_norm", "n_faces", "pearson", "spearman", "time_s")


def installed_default() -> str:
    from spectrageo.saliency import geometric_saliency

    return inspect.signature(geometric_saliency).parameters["sparse_norm"].default


def measure(folder: Path, split: str, models, norms) -> list[dict]:
    from scipy.stats import pearsonr, spearmanr

    from spectrageo import io
    from spectrageo.saliency import SaliencyOptions, saliency

    rows = []
    for name in models:
        mesh = io.read_mesh(folder / f"{name}.obj")
        V, F = mesh.vertices, mesh.faces
        gt = np.loadtxt(folder / f"{name}_saliencyValues_of_centroids.csv").ravel()
        for norm in norms:
            for method in SCORED + REPORTED:
                fast = method == "fast"
                opts = SaliencyOptions(fast=fast, sparse_norm=norm)
                t0 = time.perf_counter()
                s = saliency(V, F, opts, per="face", method="combined" if fast else method)
                dt = time.perf_counter() - t0
                rows.append(
                    {
                        "split": split,
                        "model": name,
                        "method": method,
                        "sparse_norm": norm,
                        "n_faces": int(F.shape[0]),
                        "pearson": float(pearsonr(s, gt)[0]),
                        "spearman": float(spearmanr(s, gt)[0]),
                        "time_s": dt,
                    }
                )
                print(
                    f"{split} {name} {method} {norm}: Pearson {rows[-1]['pearson']:.4f}",
                    flush=True,
                )
    return rows


def objective(rows: list[dict], norm: str) -> float:
    return float(
        np.mean([r["pearson"] for r in rows if r["sparse_norm"] == norm and r["method"] in SCORED])
    )


def table(rows: list[dict]) -> list[str]:
    lines = [
        "| split | model | method | sparse_norm | faces | Pearson | Spearman | time (s) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['split']} | {r['model']} | {r['method']} | {r['sparse_norm']} | "
            f"{r['n_faces']:,} | {r['pearson']:.4f} | {r['spearman']:.4f} | {r['time_s']:.2f} |"
        )
    return lines


def write(name: str, md: str, rows: list[dict]) -> None:
    OUT_DIR.mkdir(parents=True, exist_ok=True)
    for ext, text in (("md", md), ("csv", None)):
        path = OUT_DIR / f"{name}.{ext}"
        tmp = path.with_suffix(f".{ext}.tmp")
        if text is None:
            with tmp.open("w", newline="") as fh:
                w = csv.DictWriter(fh, COLS)
                w.writeheader()
                w.writerows(rows)
        else:
            tmp.write_text(text)
        os.replace(tmp, path)


def tune(folder: Path) -> None:
    current = installed_default()
    rows = measure(folder, "tuning", TUNING, CANDIDATES)
    scores = {n: objective(rows, n) for n in CANDIDATES}
    best = max(scores, key=scores.get)
    chosen = current if scores[best] - scores[current] < TIE else best
    md = "\n".join(
        [
            "## Saliency `sparse_norm` chosen on the tuning maps",
            "",
            f"Machine: {machine_line()}. Command: `python benchmarks/retune_saliency.py`.",
            "",
            f"Split (alphabetical rule, fixed before the run): tuning {', '.join(TUNING)}; "
            f"validation {', '.join(VALIDATION)}. Objective: mean Pearson (per face, against "
            f"the reference map) over the tuning models x methods {', '.join(SCORED)}; "
            f"differences below {TIE} keep the current default ({current!r}).",
            "",
            "Objective: " + "; ".join(f"{n} {s:.4f}" for n, s in scores.items()) + ".",
            f"Chosen: {chosen!r} (current {current!r}).",
            "",
            *table(rows),
        ]
    )
    write("tuning", md + "\n", rows)
    print(md)


def validate(folder: Path) -> None:
    norm = installed_default()
    rows = measure(folder, "validation", VALIDATION, (norm,))
    md = "\n".join(
        [
            f"## Saliency on the validation maps, installed default sparse_norm={norm!r}",
            "",
            f"Machine: {machine_line()}. Command: "
            "`python benchmarks/retune_saliency.py --validation` (measured once, after the "
            "choice on the tuning maps).",
            "",
            f"Mean Pearson over {', '.join(VALIDATION)} x {', '.join(SCORED)}: "
            f"{objective(rows, norm):.4f}.",
            "",
            *table(rows),
        ]
    )
    write(f"validation_{norm}", md + "\n", rows)
    print(md)


def main() -> None:
    from spectrageo.datasets import data_dir

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--validation", action="store_true", help="measure the validation maps once")
    a = ap.parse_args()
    folder = Path(data_dir(required=True)) / "saliency"
    if a.validation:
        validate(folder)
    else:
        tune(folder)


if __name__ == "__main__":
    main()
