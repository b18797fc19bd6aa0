"""Identification speed at the issue's operating point: a scene of ~150k points, 5 models.

Three generated single-view scenes (:func:`spectrageo.register.make_scene`, seeds 21-23, outside
the tuning and validation seeds of ``spectrageo evaluate identify``), each holding 4 objects of a
5-model library (the first or the second half of
:data:`spectrageo.evaluate.identify.LIBRARY`), at 560 x 420 pixels (about 150k points).
``identify(scene, library)`` is timed wall-clock after one warm-up call (numba compilation);
the decisions (found / not found) are checked against the ground truth.

    python benchmarks/identify_speed.py
    python benchmarks/identify_speed.py --screen-ab   # grid screen of hypotheses on / off
    python benchmarks/identify_speed.py --pieces-ab   # pieces of wide segments on / off

Writes ``benchmarks/_out/identify_speed.md``. ``--screen-ab`` instead times the tuning scenes 1-3
of ``spectrageo evaluate identify`` (10 models, with the viewpoint) with the grid screen of pose
hypotheses off and on, alternating in one process (docs/decisions.md#identify-screening);
``--pieces-ab`` times tuning scenes 1-10 with and without the pieces of wide segments
(docs/decisions.md#identify-pieces).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import machine_line, write_section  # noqa: E402

SEEDS = (21, 22, 23)


def main() -> None:
    from spectrageo.datasets import data_dir
    from spectrageo.evaluate.identify import load_library
    from spectrageo.register import identify, make_scene

    lib = load_library(Path(data_dir(required=True)))
    names = list(lib)
    warm = make_scene(lib, n_objects=3, rng=0)
    identify(warm.points[:20000], {names[0]: lib[names[0]]}, rng=0)
    rows = []
    for seed in SEEDS:
        half = (seed % 2) * 5
        lib5 = {k: lib[k] for k in names[half : half + 5]}
        sc = make_scene(lib5, n_objects=4, image_size=(560, 420), rng=seed)
        t0 = time.perf_counter()
        matches = identify(sc.points, lib5, rng=0)
        sec = time.perf_counter() - t0
        present = set(sc.names)
        right = sum(m.found == (m.model in present) for m in matches)
        found = sum(m.found and m.model in present for m in matches)
        rows.append((seed, len(sc.points), ", ".join(lib5), sec, right, found, len(present)))
    lines = [
        "## Identification speed: 150k points, 5 models",
        "",
        f"Machine: {machine_line()}. Produced by `python benchmarks/identify_speed.py`: generated "
        "scenes (seeds 21-23, not used by the tuning or validation split), 4 objects of a "
        "5-model library, 560 x 420 pixels; wall-clock time of `identify(scene, library)` after "
        "a warm-up call. Target of the identification issue: <= 10 s.",
        "",
        "| scene | points | library | time (s) | correct decisions | present found |",
        "|---|---|---|---|---|---|",
    ]
    for seed, n, lib_names, sec, right, found, n_present in rows:
        lines.append(
            f"| {seed} | {n:,} | {lib_names} | {sec:.2f} | {right}/5 | {found}/{n_present} |"
        )
    worst = max(r[3] for r in rows)
    lines += ["", f"Slowest scene: {worst:.2f} s."]
    write_section("identify_speed", "\n".join(lines))


def ab(attr: str, off, seeds=(1, 2, 3)) -> None:
    """Time tuning scenes with ``_identify.<attr>`` at ``off`` and at its default, alternating."""
    from spectrageo.datasets import data_dir
    from spectrageo.evaluate.identify import load_library
    from spectrageo.register import _identify, identify, make_scene

    lib = load_library(Path(data_dir(required=True)))
    identify(make_scene(lib, n_objects=3, rng=0).points[:20000], lib, rng=0)  # warm-up
    default = getattr(_identify, attr)
    lines = [f"| scene | {attr} off (s) | on (s) | ratio | found off | found on |",
             "|---|---|---|---|---|---|"]  # fmt: skip
    tot = [0.0, 0.0]
    try:
        for seed in seeds:
            sc = make_scene(lib, n_objects=3 + seed % 4, rng=seed)
            cell = []
            for k, n in enumerate((off, default)):
                setattr(_identify, attr, n)
                t0 = time.perf_counter()
                res = identify(sc.points, lib, rng=0, viewpoint=sc.viewpoint)
                cell.append((time.perf_counter() - t0, sum(m.found for m in res)))
                tot[k] += cell[-1][0]
            (a, fa), (b, fb) = cell
            lines.append(f"| {seed} | {a:.1f} | {b:.1f} | {b / a:.2f} | {fa} | {fb} |")
            print(lines[-1], flush=True)
    finally:
        setattr(_identify, attr, default)
    print(f"all: {tot[0]:.1f} / {tot[1]:.1f} s, ratio {tot[1] / tot[0]:.2f}")
    print(f"Machine: {machine_line()}")


if __name__ == "__main__":
    if "--screen-ab" in sys.argv:
        ab("N_SCREEN", 0)
    elif "--pieces-ab" in sys.argv:  # tuning scenes 1-10 (docs/decisions.md#identify-pieces)
        ab("SPLIT_DIAG", float("inf"), seeds=tuple(range(1, 11)))
    else:
        main()
