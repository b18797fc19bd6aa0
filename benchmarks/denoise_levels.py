"""The denoising generality protocol's validation split at the two other levels (0.1 and 0.5),
with the 100k-vertex dragon: the main protocol section reports level 0.3 up to 30k vertices.

    python benchmarks/denoise_levels.py [--levels 0.1,0.5] [--max-vertices 110000] [--out FILE.md]

Runs :func:`spectrageo.evaluate.denoise.evaluate_generality` on the validation split with the
peers at their frozen fixed settings (:data:`~spectrageo.evaluate.denoise.PEER_FIXED`, chosen on
the 68 tuning cases at the three levels) and their per-case oracles, one in-process timing per
case (no CLI timing; the time targets are measured in the main section), and summarises it per
level and for the meshes of more than 30k vertices. The full rows are written next to the
output (``<out stem>_rows.csv``).
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numpy as np

from spectrageo.evaluate._tables import rows_to_csv
from spectrageo.evaluate.denoise import PROTOCOL_COLUMNS, evaluate_generality, generality_summary

HERE = Path(__file__).resolve().parent

PEERS = ("pymeshlab-twostep", "pymeshlab-taubin", "open3d-taubin")


def _f(v) -> str:
    return "-" if v is None or not np.isfinite(v) else f"{v:.2f}"


def _pct(v) -> str:
    return "-" if v is None else f"{v:+.1f} %"


def summary_table(groups: dict[str, list[dict]]) -> list[str]:
    names = list(groups)
    summ = {g: generality_summary(rs).get("validation", {}) for g, rs in groups.items()}
    lines = ["| | " + " | ".join(names) + " |", "|---|" + "---:|" * len(names)]

    def row(label, fn):
        lines.append(
            f"| {label} | " + " | ".join(fn(summ[g]) if summ[g] else "-" for g in names) + " |"
        )

    row("cases", lambda s: str(s["cases"]))
    row("mean theta: noisy input", lambda s: _f(s["input_theta"]))
    methods = ["tsgsp", "gnf"] + [f"{p}:{k}" for k in ("fixed", "oracle") for p in PEERS]
    for m in methods:
        row(f"mean theta: {m}", lambda s, m=m: _f(s["mean_theta"].get(m)))
    row(
        "cases where tsgsp beats gnf",
        lambda s: f"{s.get('tsgsp_beats_gnf_pct', float('nan')):.0f} %",
    )
    row(
        "cases where tsgsp and gnf return the same mesh",
        lambda s: str(s.get("tsgsp_ties_gnf", "-")),
    )
    row("tsgsp vs best peer fixed setting", lambda s: _pct(s.get("tsgsp_vs_best_fixed_pct")))
    row("(best peer fixed setting)", lambda s: str(s.get("best_peer_fixed", "-")))
    row("tsgsp vs best peer oracle", lambda s: _pct(s.get("tsgsp_vs_best_oracle_pct")))
    row("(best peer oracle)", lambda s: str(s.get("best_peer_oracle", "-")))
    row("mean of the per-case best peer oracle", lambda s: _f(s.get("any_peer_oracle_mean")))
    row(
        "tsgsp / gnf time, median where both filters ran",
        lambda s: _f(s.get("time_ratio_median_denoised")),
    )
    for m in ("tsgsp", "gnf", "open3d-taubin:fixed"):
        row(
            f"cases above the noisy input: {m}",
            lambda s, m=m: str(len(s["above_input"].get(m, []))),
        )
    return lines


def failure_lines(rows: list[dict]) -> list[str]:
    """One line per method that failed on some cases (its rows then count the noisy input)."""
    out = []
    for m in sorted({r["method"] for r in rows if r.get("error")}):
        bad = [r for r in rows if r["method"] == m and r.get("error")]
        models = sorted({r["model"] for r in bad})
        first = str(bad[0]["error"]).splitlines()[0][:120]
        out.append(
            f"- {m} failed on {len(bad)} case(s) ({', '.join(models)}; first error: {first}); "
            "those rows count the noisy input"
        )
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", default=os.environ.get("SPECTRAGEO_DATA", "../shared/data"))
    ap.add_argument("--levels", default="0.1,0.5")
    ap.add_argument("--max-vertices", type=int, default=110_000)
    ap.add_argument("--out", default=str(HERE / "_out" / "denoise_levels.md"))
    a = ap.parse_args()
    levels = [float(x) for x in a.levels.split(",")]
    t0 = time.perf_counter()
    res = evaluate_generality(
        a.data, split="validation", levels=levels, max_vertices=a.max_vertices, repeat=1
    )
    wall = time.perf_counter() - t0
    rows = [r for r in res.rows if r.get("method")]
    groups = {f"level {lv:g}": [r for r in rows if r["level"] == lv] for lv in levels}
    big = [r for r in rows if r["n_vertices"] > 30_000]
    if big:
        groups["meshes > 30k vertices (all levels)"] = big
    out = Path(a.out)
    csv_path = out.with_name(out.stem + "_rows.csv")
    csv_path.write_text(rows_to_csv(rows, PROTOCOL_COLUMNS))
    above = {
        lv: sorted(
            r["case"]
            for r in rows
            if r["level"] == lv and r["method"] == "tsgsp" and r["above_input"]
        )
        for lv in levels
    }
    lv_text = " and ".join(f"{lv:g}" for lv in levels)
    n_max = {}
    for r in rows:
        n_max[r["model"]] = r["n_vertices"]
    largest = max(n_max.values()) if n_max else 0
    models = sorted({r["model"] for r in rows})
    lines = [
        f"## Denoising generality protocol at levels {lv_text} (validation split)",
        "",
        f"`python benchmarks/denoise_levels.py` ({platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}; {wall / 60:.0f} min). The section above reports the "
        "protocol at level 0.3 up to 30k vertices; this one runs the same validation split "
        f"at levels {lv_text} with every model up to {a.max_vertices:,} vertices "
        f"({len(models)} models, the largest of {largest:,} vertices), "
        "the same five corruption kinds and generator, the package's methods with default "
        "settings and the peers at the fixed settings frozen from the three-level tuning run "
        f"({res.fixed_source}) and at their per-case oracles. Nothing was chosen on these rows. "
        "Times are single in-process runs on a machine also running other work: the time "
        "targets are measured in the section above. theta = mean face-normal angle to the clean "
        f"mesh (degrees); every row is in `benchmarks/_out/{csv_path.name}`.",
        "",
        *summary_table(groups),
        "",
    ]
    for lv in levels:
        lines.append(
            f"- level {lv:g}, tsgsp above the noisy input on: " + (", ".join(above[lv]) or "none")
        )
    lines += failure_lines(rows)
    text = "\n".join(lines) + "\n"
    out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
