"""Broad-phase preparation of registration: voxel down-sampling, shape properties, density.

Pairs: the real scan pairs of the tuning split of ``spectrageo evaluate register`` (the 13 tuning
bunny pairs and the RGB-D fragment pair; ``--all`` adds the generated and fragment-crop pairs).

For every pair :func:`spectrageo.register.register` (defaults, seed of the split) runs with the
working tree's down-sampling (``voxel_downsample``, ``downsample_to``, ``bbox_diagonal``) and
broad-phase preparation (``shape_properties``, ``density``), and with those functions of the git
revision ``--ref`` (default ``HEAD``) patched in, alternating, after a warm-up, ``--repeats``
times. Reported: the medians of the CPU time (process time) of the whole call and of each
preparation stage, and whether both give the same result bit for bit (transformation, fitness,
inlier rmse, iterations, convergence and every ``info`` value except times) and the largest
entry-wise difference of the two poses. Run it with one thread (``OMP_NUM_THREADS=1
OPENBLAS_NUM_THREADS=1``) for CPU times that do not depend on the thread count.

    python benchmarks/reg_speed4_prep.py [--all] [--repeats 3] [--ref HEAD]

Writes ``benchmarks/_out/reg_speed4_prep.md``.
"""

from __future__ import annotations

import argparse
import importlib.util
import subprocess
import sys
import tempfile
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

ROOT = Path(__file__).resolve().parent.parent
STAGES = {"voxel": ("voxel_downsample", "downsample_to"), "shape": ("shape_properties",),
          "density": ("density",)}  # fmt: skip


def _load_ref(rev: str, tmp: Path):
    """``(common, broad)`` modules of ``src/spectrageo/register/_common.py`` and ``_broad.py`` at
    git revision ``rev``, loaded beside the installed package."""
    mods = []
    for name in ("_common", "_broad"):
        text = subprocess.run(["git", "show", f"{rev}:src/spectrageo/register/{name}.py"],
                              cwd=ROOT, check=True, capture_output=True, text=True).stdout  # fmt: skip
        text = text.replace("from ._common import", "from ._common_ref import")
        path = tmp / f"{name}_ref.py"
        path.write_text(text)
        full = f"spectrageo.register.{name}_ref"
        spec = importlib.util.spec_from_file_location(full, path)
        mod = importlib.util.module_from_spec(spec)
        mod.__package__ = "spectrageo.register"
        sys.modules[full] = mod
        spec.loader.exec_module(mod)
        mods.append(mod)
    return tuple(mods)


class _Impl:
    """Switches the registration modules between the tree's and the reference's functions and
    times the preparation stages (CPU)."""

    def __init__(self, ref_common, ref_broad) -> None:
        from spectrageo.register import _api, _broad, _common, _narrow

        self.mods = (_api, _broad, _narrow)
        self.names = ("voxel_downsample", "downsample_to", "bbox_diagonal", "shape_properties",
                      "density")  # fmt: skip
        self.impl = {"tree": {}, "ref": {}}
        for n in self.names:
            src_new = _broad if n in ("shape_properties", "density") else _common
            src_ref = ref_broad if src_new is _broad else ref_common
            self.impl["tree"][n] = self._timed(getattr(src_new, n), n)
            self.impl["ref"][n] = self._timed(getattr(src_ref, n), n)
        self.t = dict.fromkeys(STAGES, 0.0)

    def _timed(self, fn, name):
        key = next((k for k, v in STAGES.items() if name in v), None)
        if key is None:
            return fn

        def inner(*a, **k):
            t0 = time.process_time()
            try:
                return fn(*a, **k)
            finally:
                self.t[key] += time.process_time() - t0

        return inner

    def use(self, which: str) -> None:
        for m in self.mods:
            for n in self.names:
                if hasattr(m, n):
                    setattr(m, n, self.impl[which][n])

    def take(self) -> dict[str, float]:
        out = dict(self.t)
        self.t = dict.fromkeys(STAGES, 0.0)
        return out


def _same(a, b) -> bool:
    """Whether two registration results agree bit for bit (times left out)."""
    if not (np.array_equal(a.transformation, b.transformation) and a.fitness == b.fitness
            and a.inlier_rmse == b.inlier_rmse and a.n_iter == b.n_iter
            and a.converged == b.converged):  # fmt: skip
        return False
    keys = {k for k in a.info if not k.endswith("time_s")}
    if keys != {k for k in b.info if not k.endswith("time_s")}:
        return False
    for k in keys:
        x, y = a.info[k], b.info[k]
        if isinstance(x, list):
            if len(x) != len(y) or not all(np.array_equal(u, v) for u, v in zip(x, y)):
                return False
        elif not np.array_equal(np.asarray(x), np.asarray(y)):
            return False
    return True


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--all", action="store_true", help="also the generated and crop pairs")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--ref", default="HEAD", help="git revision of the reference functions")
    args = ap.parse_args()
    from spectrageo.register import register

    warnings.simplefilter("ignore")
    _, pairs, seed = register_tuning_pairs(ALL_PAIRS if args.all else REAL_PAIRS)
    with tempfile.TemporaryDirectory() as tmp:
        impl = _Impl(*_load_ref(args.ref, Path(tmp)))
        for which in ("ref", "tree"):
            impl.use(which)
            register(pairs[-1]["source"], pairs[-1]["target"], rng=seed)
        impl.take()
        rows = []
        for p in pairs:
            cpu = {"ref": [], "tree": []}
            wall = {"ref": [], "tree": []}
            st = {"ref": [], "tree": []}
            out = {}
            for r in range(args.repeats):
                for which in ("ref", "tree") if r % 2 == 0 else ("tree", "ref"):
                    impl.use(which)
                    c0, w0 = time.process_time(), time.perf_counter()
                    out[which] = register(p["source"], p["target"], rng=seed)
                    cpu[which].append(time.process_time() - c0)
                    wall[which].append(time.perf_counter() - w0)
                    st[which].append(impl.take())
            med = {w: {k: float(np.median([s[k] for s in st[w]])) for k in STAGES} for w in st}
            dT = float(np.abs(out["ref"].transformation - out["tree"].transformation).max())
            rows.append((p["data"], p["pair"], float(np.median(cpu["ref"])),
                         float(np.median(cpu["tree"])), med, _same(out["ref"], out["tree"]), dT,
                         float(np.median(wall["ref"])), float(np.median(wall["tree"]))))  # fmt: skip
        impl.use("tree")
    lines = [
        "## Broad-phase preparation: down-sampling, shape properties, density (issue 50)",
        "",
        f"`python benchmarks/reg_speed4_prep.py{' --all' if args.all else ''} --repeats "
        f"{args.repeats} --ref {args.ref}`; medians of alternating runs after a warm-up, CPU "
        "(process time) of `register(source, target)` and of its preparation stages, ref: the "
        f"functions of `{args.ref}`, tree: the working tree's.",
        "",
        f"Split: tuning. {machine_line()}",
        "",
        "| data | pair | ref CPU s | tree CPU s | voxel ref / tree ms | shape ref / tree ms | "
        "density ref / tree ms | same result | max abs pose difference |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for d, pair, a, b, med, same, dT, _, _ in rows:
        cells = " | ".join(
            f"{1e3 * med['ref'][k]:.1f} / {1e3 * med['tree'][k]:.1f}" for k in STAGES
        )
        lines.append(f"| {d} | {pair} | {a:.3f} | {b:.3f} | {cells} | {same} | {dT:.1e} |")
    a = np.array([r[2] for r in rows])
    b = np.array([r[3] for r in rows])
    stage = {k: (np.mean([r[4]["ref"][k] for r in rows]), np.mean([r[4]["tree"][k] for r in rows]))
             for k in STAGES}  # fmt: skip
    lines += [
        "",
        f"- CPU per pair: ref {a.mean():.3f} s, tree {b.mean():.3f} s (ratio of sums "
        f"{b.sum() / a.sum():.3f}); wall per pair: ref {np.mean([r[7] for r in rows]):.3f} s, "
        f"tree {np.mean([r[8] for r in rows]):.3f} s; stages per pair (CPU ms, ref -> tree): "
        + ", ".join(f"{k} {1e3 * x:.1f} -> {1e3 * y:.1f}" for k, (x, y) in stage.items()),
        f"- same result bit for bit: {sum(r[5] for r in rows)} of {len(rows)} pairs; largest "
        f"entry-wise difference of the (4, 4) poses {max(r[6] for r in rows):.1e}",
    ]
    write_section("reg_speed4_prep", "\n".join(lines))


if __name__ == "__main__":
    main()
