"""Narrow phase against Open3D's ICP on the shared scan fragments, from the same starts.

Pairs: the Stanford bunny scan pairs of ``spectrageo evaluate register`` (overlap > 0.3, the
``bun.conf`` ground truth) and the Open3D fragment pair ``cloud_bin_0 -> cloud_bin_1``. Every
pair is started from the ground truth moved by a random rigid perturbation: a rotation of 5, 10 or
15 degrees about a uniform random axis and a translation of 2 % of the target's bounding-box
diagonal in a uniform random direction (one draw per angle and pair, seed 7; the registration
evaluation's motions use seeds 0 and 1). Peers run at the settings below. Two defaults of our
narrow phase were decided by runs of this benchmark, which has no held-out part: the step
tolerance (``tol`` 1e-5 instead of 1e-6: the same errors in 27 % less time) and keeping the
approximate neighbours of the coarse stage (``eps=1``: ~10 % less time, the same errors); the
coarse stage's stride and switch point follow from the point spacing and were not searched. Its
table is therefore not a held-out measurement of our accuracy or speed; ``spectrageo evaluate
register`` (other starts, through the broad phase) was run after these choices.

Methods (all get the full clouds as read; time = wall clock of the whole call, target index,
normals and any down-sampling included):

- ``ours p2plane``: :func:`spectrageo.register.narrow_phase` at its defaults (Tukey-weighted
  point-to-plane ICP, Eq. 6.39-6.41, source voxel-thinned to <= 20,000 points).
- ``ours p2point``: the same with ``method="point_to_point"`` (the literal weighted Eq. 6.39).
- ``o3d p2plane d``: Open3D ``registration_icp`` with ``TransformationEstimationPointToPlane``,
  target normals estimated by Open3D (hybrid search, radius 2 % of the diagonal, 30 neighbours),
  correspondence distance ``d`` = 1, 2.5 or 5 % of the diagonal, at most 100 iterations.
- ``o3d p2point d``: the same with ``TransformationEstimationPointToPoint``.

Each call is timed ``--repeat`` times (default 3) and the best time is kept, as in the
outlier throughput benchmark, so that one-off stalls of a shared machine do not decide a ratio.

Accuracy: rotation error in degrees and translation error as a fraction of the target's
diagonal against the ground truth; "accurate" = within 0.5 degrees and 0.5 % of the diagonal.
"At equal accuracy" compares the times of two methods over the starts that both make accurate.

    python benchmarks/narrow_phase.py

Writes ``benchmarks/_out/narrow_phase.md`` and the per-call rows to ``narrow_phase.csv``.
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import OUT, machine_line, write_section  # noqa: E402

ANGLES = (5.0, 10.0, 15.0)
SHIFT = 0.02
SEED = 7
ROT_OK = 0.5
TRANS_OK = 0.005
DISTANCES = (0.01, 0.025, 0.05)


def _pairs(data: Path) -> list[dict]:
    from spectrageo.datasets.splits import cases
    from spectrageo.evaluate.register import bunny_pairs, fragment_pairs

    # the split registry's ``register-narrow`` cases (the bunny scans, the fragment pair); the
    # evaluation's pairs carry a large random motion; only the clouds and the ground truth are
    # used here (the start is the ground truth perturbed, below)
    make = {"bunny": bunny_pairs, "open3d": fragment_pairs}
    out = []
    for c in cases("register-narrow"):
        out += [{**p, "split": c.split} for p in make[c.name](data, 0)]
    return out


def _perturb(T_gt: np.ndarray, angle_deg: float, shift: float, rng) -> np.ndarray:
    from spectrageo.register._common import make_transform, rotvec_to_matrix

    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    t = rng.normal(size=3)
    t *= shift / np.linalg.norm(t)
    D = make_transform(rotvec_to_matrix(axis * np.deg2rad(angle_deg)), t)
    return D @ T_gt


def _ours(S, T, T0, method):
    from spectrageo.register import narrow_phase

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return np.asarray(narrow_phase(S, T, T0, method=method).transformation)


def _o3d(S, T, T0, method, dist):
    import open3d as o3d

    reg = o3d.pipelines.registration
    src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(S))
    tgt = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(T))
    diag = float(np.linalg.norm(np.ptp(T, axis=0)))
    if method == "p2plane":
        tgt.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.02 * diag, max_nn=30))
        est = reg.TransformationEstimationPointToPlane()
    else:
        est = reg.TransformationEstimationPointToPoint()
    r = reg.registration_icp(src, tgt, dist * diag, T0, est,
                             reg.ICPConvergenceCriteria(max_iteration=100))  # fmt: skip
    return np.asarray(r.transformation)


def run(peers: bool = True, repeat: int = 1) -> list[dict]:
    from spectrageo.datasets import data_dir
    from spectrageo.metrics import registration as rm
    from spectrageo.register._common import bbox_diagonal

    data = Path(data_dir(required=True))
    pairs = _pairs(data)
    rng = np.random.default_rng(SEED)
    methods = [("ours p2plane", lambda S, T, T0: _ours(S, T, T0, "point_to_plane")),
               ("ours p2point", lambda S, T, T0: _ours(S, T, T0, "point_to_point"))]  # fmt: skip
    try:
        if not peers:
            raise ImportError
        import open3d  # noqa: F401

        for m in ("p2plane", "p2point"):
            for d in DISTANCES:
                methods.append((f"o3d {m} {d:g}", lambda S, T, T0, m=m, d=d: _o3d(S, T, T0, m, d)))
    except ImportError:
        print("open3d not importable: peers skipped", file=sys.stderr)
    # warm-up (numba compilation, thread pools)
    p = pairs[0]
    for _, fn in methods:
        fn(p["source"], p["target"], p["T_gt"])
    rows = []
    for p in pairs:
        diag = bbox_diagonal(p["target"])
        for angle in ANGLES:
            T0 = _perturb(p["T_gt"], angle, SHIFT * diag, rng)
            for name, fn in methods:
                sec = np.inf
                for _ in range(repeat):  # best of `repeat` (every call returns the same pose)
                    t0 = time.perf_counter()
                    Th = fn(p["source"], p["target"], T0)
                    sec = min(sec, time.perf_counter() - t0)
                re = rm.rotation_error_deg(Th, p["T_gt"])
                te = rm.translation_error(Th, p["T_gt"]) / diag
                rows.append({"pair": f"{p['data']}:{p['pair']}", "overlap": p["overlap"],
                             "angle": angle, "method": name, "rot": re, "trans": te,
                             "ok": bool(re <= ROT_OK and te <= TRANS_OK), "seconds": sec,
                             "split": p["split"]})  # fmt: skip
        print(f"{p['data']}:{p['pair']} done", file=sys.stderr)
    return rows


def _table(rows: list[dict]) -> list[str]:
    names = list(dict.fromkeys(r["method"] for r in rows))
    ref = "ours p2plane"
    by = {(r["pair"], r["angle"], r["method"]): r for r in rows}
    starts = sorted({(r["pair"], r["angle"]) for r in rows})
    lines = [
        "| method | accurate starts | median rot. error (deg) | median trans. error (diag) "
        "| median time (s) | both accurate with ours p2plane | median time ratio ours p2plane / this |",
        "|---|---|---|---|---|---|---|",
    ]
    for name in names:
        rs = [by[s + (name,)] for s in starts]
        both = [s for s in starts if by[s + (ref,)]["ok"] and by[s + (name,)]["ok"]]
        ratio = (
            f"{np.median([by[s + (ref,)]['seconds'] / by[s + (name,)]['seconds'] for s in both]):.2f}"
            if both and name != ref
            else "-"
        )
        lines.append(
            f"| {name} | {sum(r['ok'] for r in rs)}/{len(rs)} "
            f"| {np.median([r['rot'] for r in rs]):.3g} | {np.median([r['trans'] for r in rs]):.2g} "
            f"| {np.median([r['seconds'] for r in rs]):.3f} | {len(both)} | {ratio} |"
        )
    lines += ["", "By starting angle (accurate starts / median time in s):", ""]
    lines.append("| method | " + " | ".join(f"{a:g} deg" for a in ANGLES) + " |")
    lines.append("|---|" + "---|" * len(ANGLES))
    for name in names:
        cells = []
        for a in ANGLES:
            rs = [by[s + (name,)] for s in starts if s[1] == a]
            cells.append(
                f"{sum(r['ok'] for r in rs)}/{len(rs)}, {np.median([r['seconds'] for r in rs]):.3f}"
            )
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return lines


def main() -> None:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=3, help="time each call N times, keep the best")
    args = ap.parse_args()
    rows = run(repeat=max(1, args.repeat))
    n_pairs = len({r["pair"] for r in rows})
    lines = [
        "## Narrow phase against Open3D ICP (Section 6.2.4)",
        "",
        f"Machine: {machine_line()}. Produced by `python benchmarks/narrow_phase.py`: {n_pairs} "
        "scan pairs (the bunny pairs with overlap > 0.3 and the Open3D fragment pair), each "
        "started from its ground truth moved by 5, 10 and 15 degrees and 2 % of the diagonal "
        "(random axes and directions, seed 7). Accurate = within 0.5 degrees and 0.5 % of the "
        "diagonal. Open3D's ICP at three correspondence distances (fractions of the diagonal). "
        "Times are whole calls (target normals and down-sampling included), after a warm-up, "
        "the best of 3 calls of each method on each start (`--repeat`). Not held out for our "
        "narrow phase: its step tolerance and the coarse stage's approximate neighbours were "
        "decided by runs of this benchmark.",
        "",
        *_table(rows),
        "",
        _target_line(rows),
    ]
    write_section("narrow_phase", "\n".join(lines))
    _write_csv(rows)


def _target_line(rows: list[dict]) -> str:
    """Issue 19's narrow-phase target, read off the rows: our default against the Open3D setting
    that is accurate on the most starts, on the starts both get right."""
    ref = "ours p2plane"
    peers = [m for m in dict.fromkeys(r["method"] for r in rows) if m.startswith("o3d")]
    if not peers:
        return "Open3D was not importable: no comparison."
    ok = {m: sum(r["ok"] for r in rows if r["method"] == m) for m in peers + [ref]}
    best = max(peers, key=lambda m: ok[m])
    by = {(r["pair"], r["angle"], r["method"]): r for r in rows}
    both = [k[:2] for k in by if k[2] == ref and by[k]["ok"] and by[k[:2] + (best,)]["ok"]]
    ratio = np.median([by[s + (ref,)]["seconds"] / by[s + (best,)]["seconds"] for s in both])
    verdict = "met" if ratio < 1 else "not met"
    return (
        f"Target of the registration issue: the narrow phase faster than Open3D's ICP at equal "
        f"accuracy. Open3D's most accurate setting here is `{best}` ({ok[best]} accurate "
        f"starts, ours {ok[ref]}); on the {len(both)} starts both get right the median ratio of "
        f"our time to its time is {ratio:.2f}: {verdict}."
    )


def _write_csv(rows: list[dict]) -> None:
    import csv
    import os

    path = OUT / "narrow_phase.csv"
    tmp = path.with_suffix(".csv.tmp")
    with open(tmp, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    os.replace(tmp, path)


if __name__ == "__main__":
    main()
