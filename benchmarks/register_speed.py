"""Registration time per pair against Open3D RANSAC+FPFH+ICP in one process, and CLI overhead.

Pairs: the real scan pairs of a split of ``spectrageo evaluate register`` (bunny range scans and
the Open3D RGB-D fragment pair, the split's motions). Each pair runs ``spectrageo.register``
(defaults) and Open3D's global-registration tutorial pipeline (voxel = diagonal / 50, FPFH,
RANSAC 100000 / 0.999, point-to-plane ICP), alternating, after one warm-up of each. Reported:
time per pair, the ratio of the sums (ours / Open3D) and the median per-pair ratio; the time
per source when the target is prepared once (:func:`spectrageo.register.prepare_target`, the
bunny pairs sharing a target); and the overhead of ``spectrageo register`` on the fragment pair:
the command's wall time minus the in-process time of reading both files and registering them.

    python benchmarks/register_speed.py [--split validation|tuning]

Writes ``benchmarks/_out/register_speed.md``.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import machine_line, write_section  # noqa: E402


def _cli_overhead(data: Path, repeats: int = 3) -> tuple[float, float]:
    """(median CLI wall time, median in-process time of read + register) on the fragment pair."""
    from spectrageo import io
    from spectrageo.register import register

    a = data / "scans" / "registration" / "open3d" / "cloud_bin_0.pcd"
    b = data / "scans" / "registration" / "open3d" / "cloud_bin_1.pcd"
    exe = Path(sys.executable).parent / "spectrageo"
    cli, inproc = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(repeats):
            t0 = time.perf_counter()
            subprocess.run([str(exe), "register", str(a), str(b), "--out", f"{tmp}/t.json"],
                           check=True, capture_output=True)  # fmt: skip
            cli.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            register(io.read_point_cloud(a), io.read_point_cloud(b))
            inproc.append(time.perf_counter() - t0)
    return float(np.median(cli)), float(np.median(inproc))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--split", choices=("validation", "tuning"), default="validation")
    args = ap.parse_args()
    from spectrageo.datasets import data_dir
    from spectrageo.evaluate import register as ev
    from spectrageo.register import prepare_target, register

    warnings.simplefilter("ignore")
    data = Path(data_dir(required=True))
    cfg = ev.VALIDATION if args.split == "validation" else ev.TUNING
    pairs = ev.pairs_for(data, cfg, ("bunny", "open3d"))
    warm = pairs[-1]
    ev._run("spectrageo", warm, cfg["reg_seed"])
    ev._run("o3d_ransac_fpfh_icp", warm, cfg["reg_seed"])
    rows = []
    for p in pairs:
        ours = ev._run("spectrageo", p, cfg["reg_seed"])
        o3d = ev._run("o3d_ransac_fpfh_icp", p, cfg["reg_seed"])
        rows.append((p["data"], p["pair"], ours["seconds"], o3d["seconds"], ours["recall"],
                     o3d["recall"]))  # fmt: skip
    # one prepared target, every bunny source registered onto it
    by_target: dict[str, list[dict]] = {}
    for p in pairs:
        if p["data"] == "bunny":
            by_target.setdefault(p["pair"].split("->")[1], []).append(p)
    name, group = max(by_target.items(), key=lambda kv: len(kv[1]))
    t0 = time.perf_counter()
    pt = prepare_target(group[0]["target"])
    t_prep = time.perf_counter() - t0
    t0 = time.perf_counter()
    for p in group:
        register(p["source"], pt, rng=cfg["reg_seed"])
    t_reuse = (time.perf_counter() - t0) / len(group)
    cli, inproc = _cli_overhead(data)
    ours_t = np.array([r[2] for r in rows])
    o3d_t = np.array([r[3] for r in rows])
    lines = [
        "## Registration speed against Open3D, real pairs (issue 50)",
        "",
        f"`python benchmarks/register_speed.py --split {args.split}`; time per pair of one "
        "process, runs alternating with Open3D RANSAC on FPFH + ICP after a warm-up.",
        "",
        f"Split: {args.split} (real scan pairs of `spectrageo evaluate register`). {machine_line()}",
        "",
        "| data | pair | spectrageo s | Open3D s | ratio | recall (ours / Open3D) |",
        "|---|---|---|---|---|---|",
    ]
    for d, pair, a, b, ra, rb in rows:
        lines.append(f"| {d} | {pair} | {a:.2f} | {b:.2f} | {a / b:.2f} | {int(ra)} / {int(rb)} |")
    lines += [
        "",
        f"- sum of times: spectrageo {ours_t.sum():.1f} s, Open3D {o3d_t.sum():.1f} s, ratio "
        f"{ours_t.sum() / o3d_t.sum():.2f}; median per-pair ratio {np.median(ours_t / o3d_t):.2f}",
        f"- prepared target ({name}, {len(group)} sources): prepare {t_prep:.2f} s once, then "
        f"{t_reuse:.2f} s per source",
        f"- CLI (`spectrageo register` on the fragment pair): {cli:.2f} s against {inproc:.2f} s "
        f"in process (read + register); overhead {cli - inproc:.2f} s",
    ]
    write_section("register_speed", "\n".join(lines))


if __name__ == "__main__":
    main()
