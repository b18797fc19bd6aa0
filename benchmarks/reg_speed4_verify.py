"""Registration time per pair, CPU and wall, against Open3D RANSAC+FPFH+ICP, with stage times.

Pairs: the real scan pairs of the tuning split of ``spectrageo evaluate register`` (the 13 tuning
bunny pairs and the RGB-D fragment pair; ``--all`` adds the generated and fragment-crop pairs).
Each pair runs :func:`spectrageo.register.register` (defaults, seed of the split) and Open3D's
global-registration pipeline (as in ``benchmarks/register_speed.py``), alternating, after one
warm-up of each, ``--repeats`` times; the median of each is reported. CPU time is the process
time (all threads of both libraries). Stage times of ours (CPU): the broad phase's verification
ICP, the narrow-phase ICP runs (with rivals, every start) and the robustification.

    python benchmarks/reg_speed4_verify.py [--all] [--repeats 2]

Writes ``benchmarks/_out/reg_speed4_verify.md``.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import (  # noqa: E402
    ALL_PAIRS,
    REAL_PAIRS,
    machine_line,
    register_tuning_pairs,
    write_section,
)


class _Stages:
    """CPU time spent in the wrapped functions of the registration modules."""

    def __init__(self) -> None:
        from spectrageo.register import _api, _broad

        self.t = {"verify": 0.0, "narrow": 0.0, "robustify": 0.0}
        for mod, name, key in ((_broad, "icp", "verify"), (_api, "run_narrow", "narrow"),
                               (_api, "_robustify", "robustify")):  # fmt: skip
            setattr(mod, name, self._wrap(getattr(mod, name), key))

    def _wrap(self, fn, key):
        def inner(*a, **k):
            t0 = time.process_time()
            try:
                return fn(*a, **k)
            finally:
                self.t[key] += time.process_time() - t0

        return inner

    def take(self) -> dict[str, float]:
        out = dict(self.t)
        for k in self.t:
            self.t[k] = 0.0
        return out


def _timed(fn, *a, **k):
    c0, w0 = time.process_time(), time.perf_counter()
    out = fn(*a, **k)
    return out, time.process_time() - c0, time.perf_counter() - w0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--all", action="store_true", help="also the generated and crop pairs")
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    ev, pairs, seed = register_tuning_pairs(ALL_PAIRS if args.all else REAL_PAIRS)
    stages = _Stages()
    ev._run("spectrageo", pairs[-1], seed)
    ev._run("o3d_ransac_fpfh_icp", pairs[-1], seed)
    stages.take()
    rows = []
    for p in pairs:
        ours, theirs, st = [], [], []
        for r in range(args.repeats):
            order = ("ours", "o3d") if r % 2 == 0 else ("o3d", "ours")
            for who in order:
                if who == "ours":
                    res, c, w = _timed(ev._run, "spectrageo", p, seed)
                    ours.append((c, w, res["recall"]))
                    st.append(stages.take())
                else:
                    res, c, w = _timed(ev._run, "o3d_ransac_fpfh_icp", p, seed)
                    theirs.append((c, w, res["recall"]))
        med = {k: float(np.median([s[k] for s in st])) for k in st[0]}
        rows.append((p["data"], p["pair"], float(np.median([o[0] for o in ours])),
                     float(np.median([o[1] for o in ours])),
                     float(np.median([o[0] for o in theirs])),
                     float(np.median([o[1] for o in theirs])), med,
                     int(ours[0][2]), int(theirs[0][2])))  # fmt: skip
    lines = [
        "## Registration time per pair, CPU and wall, with stage times (issue 50)",
        "",
        f"`python benchmarks/reg_speed4_verify.py{' --all' if args.all else ''} --repeats "
        f"{args.repeats}`; medians of alternating runs after a warm-up. CPU: process time, all "
        "threads. Stages: CPU of ours.",
        "",
        f"Split: tuning. {machine_line()}",
        "",
        "| data | pair | ours CPU s | ours wall s | Open3D CPU s | Open3D wall s | CPU ratio | "
        "verify s | narrow s | robustify s | recall (ours / Open3D) |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for d, pair, oc, ow, tc, tw, med, ra, rb in rows:
        lines.append(f"| {d} | {pair} | {oc:.2f} | {ow:.2f} | {tc:.2f} | {tw:.2f} | "
                     f"{oc / tc:.2f} | {med['verify']:.3f} | {med['narrow']:.3f} | "
                     f"{med['robustify']:.3f} | {ra} / {rb} |")  # fmt: skip
    oc = np.array([r[2] for r in rows])
    ow = np.array([r[3] for r in rows])
    tc = np.array([r[4] for r in rows])
    tw = np.array([r[5] for r in rows])
    lines += [
        "",
        f"- CPU per pair: ours {oc.mean():.2f} s, Open3D {tc.mean():.2f} s (ratio of sums "
        f"{oc.sum() / tc.sum():.2f}, median per-pair ratio {np.median(oc / tc):.2f}); wall: ours "
        f"{ow.mean():.2f} s, Open3D {tw.mean():.2f} s (median per-pair ratio "
        f"{np.median(ow / tw):.2f})",
        f"- pairs where ours takes at most Open3D's CPU time: {int((oc <= tc).sum())} of "
        f"{len(rows)}; wall: {int((ow <= tw).sum())}",
    ]
    write_section("reg_speed4_verify", "\n".join(lines))


if __name__ == "__main__":
    main()
