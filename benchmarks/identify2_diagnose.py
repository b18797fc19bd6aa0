"""Identification on the generated tuning scenes, with every refined pose recorded.

For each scene (``make_scene(lib, n_objects=3 + seed % 4, rng=seed)``, the 10-model library,
every model searched, with the viewpoint) this writes one JSON line: the decisions, and for each
model every refined pose ``(h, v, rotation error, translation error)`` that the pose search
tried, so a miss can be classified (no right hypothesis / right pose with ``h >= zeta`` / right
pose in free space / wrong pose preferred). Only tuning seeds are accepted.

    python benchmarks/identify2_diagnose.py --seeds 31-40 --out /tmp/id2/a.jsonl
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))


def run_scene(lib, seed: int) -> dict:
    from spectrageo.evaluate.identify import pose_errors
    from spectrageo.metrics.registration import rotation_error_deg, translation_error
    from spectrageo.register import _identify, identify, make_scene

    sc = make_scene(lib, n_objects=3 + seed % 4, rng=seed)
    names = list(lib)
    tried: dict[int, list] = {}
    order: list[int] = []
    original = _identify._search_segment

    def spy(model, seg, voxel, o, g, rays, hyp=None):
        out = original(model, seg, voxel, o, g, rays, hyp)
        if id(model) not in order:
            order.append(id(model))
        k = names[order.index(id(model))]
        for h, v, T in out:
            rec = {"h": float(h), "v": float(v), "piece": hyp is not None,
                   "seg_points": int(seg.P.shape[0])}  # fmt: skip
            if k in sc.names:
                Tg = sc.poses[sc.names.index(k)]
                rec["rot"] = float(rotation_error_deg(T[:3, :3], Tg[:3, :3]))
                rec["trans"] = float(translation_error(T[:3, 3], Tg[:3, 3]))
            tried.setdefault(k, []).append(rec)
        return out

    _identify._search_segment = spy
    try:
        t0 = time.perf_counter()
        res = identify(sc.points, lib, rng=0, viewpoint=sc.viewpoint)
        sec = time.perf_counter() - t0
    finally:
        _identify._search_segment = original
    rows = []
    for m in res:
        row = {"model": m.model, "present": m.model in sc.names, "found": m.found,
               "h": m.dissimilarity, "tried": tried.get(m.model, [])}  # fmt: skip
        if row["present"]:
            row.update(pose_errors(m, sc))
        rows.append(row)
    return {"seed": seed, "seconds": sec, "n_points": int(len(sc.points)), "rows": rows}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="1-10,31-50", help="e.g. 1-10,31-50 (tuning seeds only)")
    ap.add_argument("--out", required=True, help="JSON-lines file (appended)")
    ap.add_argument("--data", default=None)
    a = ap.parse_args(argv)
    from spectrageo.datasets import data_dir
    from spectrageo.datasets.splits import cases
    from spectrageo.evaluate.identify import load_library, parse_seeds

    tuning = {c.seed for c in cases("identify", "tuning") if c.file is None}
    seeds = parse_seeds(a.seeds)
    bad = sorted(set(seeds) - tuning)
    if bad:
        raise SystemExit(f"not tuning seeds of the split registry: {bad}")
    lib = load_library(Path(a.data) if a.data else data_dir(required=True))
    for seed in seeds:
        rec = run_scene(lib, seed)
        with open(a.out, "a") as f:
            f.write(json.dumps(rec) + "\n")
        miss = [r["model"] for r in rec["rows"] if r["present"] != r["found"]]
        print(f"seed {seed}: {rec['seconds']:.1f} s, misses {miss}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
