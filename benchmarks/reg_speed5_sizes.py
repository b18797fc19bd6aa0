"""Narrow-phase target size of :func:`spectrageo.register.register` (``_api.TARGET_POINTS``).

Registers every tuning pair of ``spectrageo evaluate register`` (the 13 tuning bunny pairs, the
fragment pair, the 2 generated armadillo pairs, the 2 fragment crops; seed of the split) with
each value of ``TARGET_POINTS`` in turn, the values alternating within a pair and their order
reversed every repeat, and reports per value the CPU time per pair (process time, median of the
repeats), recall, ``converged``, and the pose change against the first value (rotation in
degrees, translation in target diagonals). ``--seeds N`` adds, per value, recall and
``converged`` counted over the broad-phase seeds ``reg_seed + 1 .. reg_seed + N - 1`` as well
(other broad poses, hence other ICP starts; one run each). ``--open3d`` also times Open3D's
RANSAC+FPFH+ICP (``spectrageo evaluate register``'s peer) once per repeat, after the values.

    OMP_NUM_THREADS=1 python benchmarks/reg_speed5_sizes.py [--values 2.0 1.5 1.0] [--repeats 2]
        [--seeds 1] [--open3d]

Writes ``benchmarks/_out/reg_speed5_sizes.md``.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import ALL_PAIRS, machine_line, register_tuning_pairs, write_section  # noqa: E402


def _pose_change(A: np.ndarray, B: np.ndarray, diag: float) -> tuple[float, float]:
    R = A[:3, :3].T @ B[:3, :3]
    ang = float(np.degrees(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))
    return ang, float(np.linalg.norm(A[:3, 3] - B[:3, 3]) / diag)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--values", type=float, nargs="+", default=[2.0, 1.5, 1.0])
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--open3d", action="store_true", help="also time Open3D RANSAC+FPFH+ICP")
    args = ap.parse_args()
    from spectrageo.metrics import registration as rm
    from spectrageo.register import _api, register
    from spectrageo.register._common import bbox_diagonal

    warnings.simplefilter("ignore")
    ev, pairs, seed = register_tuning_pairs(ALL_PAIRS)
    values = list(args.values)
    register(pairs[0]["source"], pairs[0]["target"], rng=seed)  # warm-up
    # per value: list over pairs of (cpu median, recall, converged, T, rot err)
    res: dict[float, list] = {v: [] for v in values}
    o3d_cpu: dict[str, list] = {}
    o3d_ok: dict[str, bool] = {}
    if args.open3d:
        ev._run("o3d_ransac_fpfh_icp", pairs[0], seed)  # warm-up
    for p in pairs:
        cpu: dict[float, list] = {v: [] for v in values}
        out: dict[float, object] = {}
        for r in range(args.repeats):
            for v in values if r % 2 == 0 else values[::-1]:
                _api.TARGET_POINTS = v
                c0 = time.process_time()
                o = register(p["source"], p["target"], rng=seed)
                cpu[v].append(time.process_time() - c0)
                out[v] = o
            if args.open3d:
                c0 = time.process_time()
                o3d_ok[p["pair"]] = ev._run("o3d_ransac_fpfh_icp", p, seed)["recall"]
                o3d_cpu.setdefault(p["pair"], []).append(time.process_time() - c0)
        for v in values:
            o = out[v]
            T = np.asarray(o.transformation)
            re = rm.rotation_error_deg(T, p["T_gt"])
            te = rm.translation_error(T, p["T_gt"]) / bbox_diagonal(p["target"])
            rec = bool(re < ev.RECALL_ROT_DEG and te < ev.RECALL_TRANS)
            res[v].append((float(np.median(cpu[v])), rec, bool(o.converged), T, re,
                           int(o.n_iter), float(o.info["tight_share"]),
                           float(o.info["constraint"])))  # fmt: skip
    # per value: runs, recall, converged, the (pair, seed) not converged or missed
    extra: dict[float, list] = {v: [0, 0, 0, []] for v in values}
    for s in range(1, args.seeds):
        for p in pairs:
            for v in values if s % 2 == 0 else values[::-1]:
                _api.TARGET_POINTS = v
                o = register(p["source"], p["target"], rng=seed + s)
                T = np.asarray(o.transformation)
                re = rm.rotation_error_deg(T, p["T_gt"])
                te = rm.translation_error(T, p["T_gt"]) / bbox_diagonal(p["target"])
                extra[v][0] += 1
                extra[v][1] += int(re < ev.RECALL_ROT_DEG and te < ev.RECALL_TRANS)
                extra[v][2] += int(o.converged)
                rec = re < ev.RECALL_ROT_DEG and te < ev.RECALL_TRANS
                if not (o.converged and rec):
                    extra[v][3].append(f"{p['pair']}@{seed + s}{'' if rec else ' miss'}")
    _api.TARGET_POINTS = values[0]
    diags = [bbox_diagonal(p["target"]) for p in pairs]
    lines = [
        "## Narrow-phase target size `TARGET_POINTS` (issue 50)",
        "",
        f"`OMP_NUM_THREADS=1 python benchmarks/reg_speed5_sizes.py --values "
        f"{' '.join(str(v) for v in values)} --repeats {args.repeats} --seeds {args.seeds}"
        f"{' --open3d' if args.open3d else ''}`; CPU: process time, "
        "median of alternating runs; pose change against the first value.",
        "",
        f"Split: tuning (18 pairs). {machine_line()}",
        "",
        "| TARGET_POINTS | CPU s per pair (mean) | bunny CPU s (mean) | recall | converged | "
        "max pose change deg | max pose change diag | rot err median / max deg | "
        "min tight share | min constraint | max n_iter |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    base = res[values[0]]
    for v in values:
        rows = res[v]
        cpu = np.array([r[0] for r in rows])
        bun = np.array([r[0] for r, p in zip(rows, pairs) if p["data"] == "bunny"])
        ch = [_pose_change(b[3], r[3], d) for b, r, d in zip(base, rows, diags)]
        lines.append(
            f"| {v:g} | {cpu.mean():.3f} | {bun.mean():.3f} | {sum(r[1] for r in rows)}/"
            f"{len(rows)} | {sum(r[2] for r in rows)}/{len(rows)} | "
            f"{max(c[0] for c in ch):.3f} | {max(c[1] for c in ch):.1e} | "
            f"{np.median([r[4] for r in rows]):.3f} / {max(r[4] for r in rows):.3f} | "
            f"{min(r[6] for r in rows):.3f} | {min(r[7] for r in rows):.2e} | "
            f"{max(r[5] for r in rows)} |"
        )
    if args.seeds > 1:
        lines += [
            "",
            f"Other broad-phase seeds (reg_seed + 1 .. + {args.seeds - 1}), one run each:",
            "",
            "| TARGET_POINTS | runs | recall | converged | not converged or missed |",
            "|---|---|---|---|---|",
        ]
        lines += [
            f"| {v:g} | {e[0]} | {e[1]} | {e[2]} | {', '.join(e[3])} |" for v, e in extra.items()
        ]
    if args.open3d:
        o3 = np.array([float(np.median(o3d_cpu[p["pair"]])) for p in pairs])
        isb = np.array([p["data"] == "bunny" for p in pairs])
        lines += ["", "Open3D RANSAC+FPFH+ICP, run after the values in every repeat:", "",
                  "| TARGET_POINTS | ours CPU s per pair | Open3D CPU s per pair | ratio of sums | "
                  "pairs at most Open3D's CPU | bunny pairs at most Open3D's CPU |",
                  "|---|---|---|---|---|---|"]  # fmt: skip
        for v in values:
            oc = np.array([r[0] for r in res[v]])
            lines.append(f"| {v:g} | {oc.mean():.3f} | {o3.mean():.3f} | {oc.sum() / o3.sum():.2f}"
                         f" | {int((oc <= o3).sum())}/{len(oc)} | {int((oc <= o3)[isb].sum())}/"
                         f"{int(isb.sum())} |")  # fmt: skip
        lines.append(f"\nOpen3D recall: {sum(o3d_ok.values())}/{len(o3d_ok)}")
    lines += ["", "Per pair (CPU s, converged, n_iter):", "",
              "| pair | " + " | ".join(f"{v:g}" for v in values) + " |"
              + (" Open3D |" if args.open3d else ""),
              "|---|" + "---|" * (len(values) + bool(args.open3d))]  # fmt: skip
    for i, p in enumerate(pairs):
        cells = [f"{res[v][i][0]:.2f} {'c' if res[v][i][2] else 'NC'} {res[v][i][5]}"
                 + ("" if res[v][i][1] else " MISS") for v in values]  # fmt: skip
        if args.open3d:
            cells.append(f"{np.median(o3d_cpu[p['pair']]):.2f}"
                         + ("" if o3d_ok[p["pair"]] else " MISS"))  # fmt: skip
        lines.append(f"| {p['data']} {p['pair']} | " + " | ".join(cells) + " |")
    write_section("reg_speed5_sizes", "\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
