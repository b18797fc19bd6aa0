"""Do-no-harm on clean coarse meshes (issue 53): low-poly models, CAD exports, multi-part files
and triangle soups denoised with default settings through the API the CLI uses
(:func:`spectrageo.io.read_with_report`, then :func:`spectrageo.denoise.denoise` with welding on).

    python benchmarks/lowpoly/clean_coarse.py [--split tuning|validation|both]
                                              [--methods default,gnf,taubin] [--data DIR]
                                              [--out DIR] [--tag NAME]

Files: ``benchmarks/lowpoly/manifest.csv`` (repository, path, commit, licence, sha256, split).
The fetched files live in ``--data`` (default ``/work/lowpoly_data`` or ``$SPECTRAGEO_LOWPOLY``);
rows whose ``name`` starts with ``cad/`` are read from the shared data (``$SPECTRAGEO_DATA``) and
keep the split the registry gives them (``denoise-gate``). The other files were split before any
result was seen: sorted by name, even positions (0-based) tuning, odd validation.

Per file and method: relative area change (%), largest vertex move (% of the bounding-box
diagonal), mean face-normal change (degrees, :func:`spectrageo.metrics.theta_deg`) and the
status (``unchanged`` when the output equals the input bit for bit, ``error: ...`` when the
method refused). Targets of issue 53: |area| <= 1 %, move <= 0.5 %, normals <= 2 degrees.
Writes ``clean_coarse[_TAG].md`` and ``.csv`` under ``benchmarks/_out/lowpoly/``.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import os
import time
import warnings
from pathlib import Path

import numpy as np

from spectrageo import denoise, io
from spectrageo.geometry import face_areas
from spectrageo.metrics import theta_deg

HERE = Path(__file__).resolve().parent
METHODS = {"default": None, "gnf": "gnf", "taubin": "taubin"}
TARGET_AREA, TARGET_MOVE, TARGET_DEG = 1.0, 0.5, 2.0


def rows_of_manifest(split: str):
    with open(HERE / "manifest.csv", newline="") as f:
        for r in csv.DictReader(f):
            if split in ("both", r["split"]):
                yield r


def path_of(row, data: Path, shared: Path) -> Path:
    return shared / row["path"] if row["name"].startswith("cad/") else data / row["name"]


def measure(V, F, X) -> dict:
    a0 = float(face_areas(V, F).sum())
    a1 = float(face_areas(X, F).sum())
    diag = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    move = float(np.linalg.norm(X - V, axis=1).max()) if V.shape[0] else 0.0
    try:
        th = float(theta_deg(X, V, F))
    except Exception:  # noqa: BLE001 - every face degenerate
        th = float("nan")
    return {
        "area_pct": 100.0 * (a1 / a0 - 1.0) if a0 > 0 else float("nan"),
        "move_pct": 100.0 * move / diag if diag > 0 else 0.0,
        "theta_deg": th,
        "status": "unchanged" if np.array_equal(X, V) else "changed",
    }


def run(split: str, methods: list[str], data: Path, shared: Path) -> list[dict]:
    out = []
    for row in rows_of_manifest(split):
        p = path_of(row, data, shared)
        if not p.is_file():
            print(f"skip {row['name']}: not found at {p}")
            continue
        digest = hashlib.sha256(p.read_bytes()).hexdigest()
        if digest != row["sha256"]:
            print(f"skip {row['name']}: sha256 differs from the manifest")
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            mesh, _rep = io.read_with_report(p)
        V, F = mesh.vertices, mesh.faces
        for m in methods:
            kw = {} if METHODS[m] is None else {"method": METHODS[m]}
            t0 = time.perf_counter()
            try:
                X = denoise.denoise(V, F, weld=True, **kw)
                res = measure(V, F, X)
            except Exception as exc:  # noqa: BLE001 - reported in the table
                res = {"area_pct": float("nan"), "move_pct": float("nan"),
                       "theta_deg": float("nan"), "status": f"error: {exc}"}  # fmt: skip
            res.update(
                name=row["name"], split=row["split"], method=m, n=V.shape[0], m=F.shape[0],
                seconds=time.perf_counter() - t0,
            )  # fmt: skip
            ok = (
                res["status"].startswith("error")
                or res["status"] == "unchanged"
                or (
                    abs(res["area_pct"]) <= TARGET_AREA
                    and res["move_pct"] <= TARGET_MOVE
                    and res["theta_deg"] <= TARGET_DEG
                )
            )
            res["ok"] = bool(ok)
            out.append(res)
            print(
                f"{row['split'][:3]} {row['name']:40s} {m:8s} area {res['area_pct']:8.2f} % "
                f"move {res['move_pct']:7.2f} % theta {res['theta_deg']:6.2f} {res['status']}",
                flush=True,
            )
    return out


COLS = ["split", "name", "n", "m", "method", "area_pct", "move_pct", "theta_deg", "status", "ok",
        "seconds"]  # fmt: skip


def write(rows: list[dict], out: Path, tag: str) -> None:
    out.mkdir(parents=True, exist_ok=True)
    stem = "clean_coarse" + (f"_{tag}" if tag else "")
    with open(out / f"{stem}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLS, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    lines = [
        f"## Clean coarse meshes: do no harm ({tag or 'all'})",
        "",
        "`python benchmarks/lowpoly/clean_coarse.py`: area change (%), largest vertex move (% of "
        "the diagonal), mean normal change (degrees); target |area| <= 1 %, move <= 0.5 %, "
        "normals <= 2 degrees. `ok`: within the target (or unchanged, or refused).",
        "",
        "| split | file | vertices | method | area % | move % | normals deg | status | ok |",
        "|---|---|---:|---|---:|---:|---:|---|---|",
    ]
    for r in rows:
        st = r["status"] if len(r["status"]) < 60 else r["status"][:57] + "..."
        lines.append(
            f"| {r['split']} | {r['name']} | {r['n']} | {r['method']} | {r['area_pct']:.2f} | "
            f"{r['move_pct']:.2f} | {r['theta_deg']:.2f} | {st} | {'yes' if r['ok'] else 'NO'} |"
        )
    lines.append("")
    for sp in ("tuning", "validation"):
        for m in dict.fromkeys(r["method"] for r in rows):
            sel = [r for r in rows if r["split"] == sp and r["method"] == m]
            if sel:
                bad = sum(not r["ok"] for r in sel)
                lines.append(f"- {sp}, {m}: {len(sel) - bad}/{len(sel)} files within the target")
    (out / f"{stem}.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {out / stem}.md/.csv")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--split", default="tuning", choices=["tuning", "validation", "both"])
    ap.add_argument("--methods", default="default,gnf,taubin")
    ap.add_argument(
        "--data", default=os.environ.get("SPECTRAGEO_LOWPOLY", "/work/lowpoly_data"), type=Path
    )
    ap.add_argument("--out", default=HERE.parent / "_out" / "lowpoly", type=Path)
    ap.add_argument("--tag", default="")
    a = ap.parse_args()
    shared = Path(os.environ.get("SPECTRAGEO_DATA", HERE.parents[2] / "shared" / "data"))
    methods = [m for m in a.methods.split(",") if m]
    for m in methods:
        if m not in METHODS:
            ap.error(f"--methods: unknown {m!r}; choose from {', '.join(METHODS)}")
    rows = run(a.split, methods, a.data, shared)
    write(rows, a.out, a.tag or a.split)


if __name__ == "__main__":
    main()
