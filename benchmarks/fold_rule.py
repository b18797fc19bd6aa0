"""Tuning data of the folded-mesh rule (Eq. N10 of :mod:`spectrageo.denoise._guard`): the share
of face pairs turned by more than 120 degrees (``fold_share``) of every tuning case, TSGSP with and
without the rule, and the mean normal error for other thresholds.

    python benchmarks/fold_rule.py [--data DIR] [--out FILE.md]    # about 1 minute

Tuning cases (no validation mesh of the denoising protocol): the shared denoising pairs, the
tuning meshes of ``spectrageo evaluate denoise`` (rocker-arm, knot2, spot, casting), seven
trimesh test models (``tests/data/trimesh``) and the synthetic CAD-like shapes of
``benchmarks/planar_rule.py``, each generated mesh with the five kinds at levels 0.1, 0.3 and
0.5 (seed 1). "Without the rule" disables it in the gate and in TSGSP (``FOLD_SHARE`` set out of
reach); with a threshold ``T`` a case takes :func:`~spectrageo.denoise._guard.unfold` when its
share is at least ``T`` and the result without the rule otherwise (every model here has at least
the rule's 50 vertices). Also the largest share of a clean mesh of ``meshes/`` and ``cad/``.
The threshold was chosen with the unfold alone, which is what this script still measures; the
fine step TSGSP now runs after a successful unfold (``unfold_fine``) is measured by
``benchmarks/unfold_fine.py``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import data_out_args  # noqa: E402
from planar_rule import TRIMESH, TRIMESH_TUNING, synthetic  # noqa: E402
from spectrageo import io  # noqa: E402
from spectrageo.denoise import _guard, denoise  # noqa: E402
from spectrageo.evaluate.denoise import TUNING_MESHES, TUNING_PAIRS  # noqa: E402
from spectrageo.metrics import theta_deg  # noqa: E402
from spectrageo.noise.generator import GENERATOR_KINDS, generate  # noqa: E402

LEVELS = (0.1, 0.3, 0.5)
THRESHOLDS = (0.05, 0.06, 0.08, 0.1, 0.12, 0.14, 0.16, 0.2, 0.25)


def cases(data: Path):
    """``(name, clean V, F, noisy V)`` of every tuning case."""
    models = [(f"trimesh/{n}", io.read_mesh(TRIMESH / n)) for n in TRIMESH_TUNING]
    models = [(n, m.vertices, m.faces) for n, m in models] + list(synthetic())
    for rel in TUNING_MESHES:
        m = io.read_mesh(data / rel)
        models.append((rel, m.vertices, m.faces))
    for kind in GENERATOR_KINDS:
        for level in LEVELS:
            for name, V, F in models:
                yield (
                    f"{name}:{kind}@{level:g}",
                    V,
                    F,
                    generate(V, F, kind=kind, level=level, rng=1).vertices,
                )
    for p in TUNING_PAIRS:
        noisy = io.read_mesh(data / "denoise" / p / "Noisy.obj")
        orig = io.read_mesh(data / "denoise" / p / "Original.obj")
        yield p, orig.vertices, orig.faces, noisy.vertices


def without_rule(Vn, F):
    keep = _guard.FOLD_SHARE
    _guard.FOLD_SHARE = np.inf
    try:
        return denoise(Vn, F, method="tsgsp")
    finally:
        _guard.FOLD_SHARE = keep


def main() -> None:
    a = data_out_args()
    data = Path(a.data)
    rows = []
    for name, V, F, Vn in cases(data):
        f = _guard.fold_share(Vn, F)
        old = theta_deg(without_rule(Vn, F), V, F)
        new = theta_deg(_guard.unfold(Vn, F), V, F) if f >= min(THRESHOLDS) else old
        rows.append((name, f, theta_deg(Vn, V, F), old, new))
    clean = []
    for sub in ("meshes", "cad"):
        for p in sorted((data / sub).iterdir()):
            if p.suffix.lower() in (".off", ".obj", ".ply", ".stl", ".gz"):
                m = io.read_mesh(p)
                if m.n_vertices <= 200_000:
                    clean.append((f"{sub}/{p.name}", _guard.fold_share(m.vertices, m.faces)))
    f = np.array([r[1] for r in rows])
    inp, old, new = (np.array([r[i] for r in rows]) for i in (2, 3, 4))
    lines = [
        "## Folded-mesh rule of the denoising gate and TSGSP (Eq. N10)",
        "",
        f"`python benchmarks/fold_rule.py` (tuning data only; see the script's docstring). "
        f"{len(rows)} cases; theta = mean normal error in degrees. A case above the threshold "
        "counts with the unfold alone, as the threshold was chosen (TSGSP now also runs its "
        "fine step when the unfold leaves no folds: `benchmarks/unfold_fine.py`).",
        "",
        f"- largest share of a clean mesh of `meshes/` and `cad/`: "
        f"{max(c[1] for c in clean):.3f} ({max(clean, key=lambda c: c[1])[0]})",
        f"- largest share of a shared pair: {max(r[1] for r in rows if r[0] in TUNING_PAIRS):.3f}",
        f"- mean theta: noisy {inp.mean():.2f}, tsgsp without the rule {old.mean():.2f}; "
        f"`FOLD_SHARE` = {_guard.FOLD_SHARE:g}",
        "",
        "| threshold | cases smoothed | mean theta | cases above the noisy input |",
        "|---:|---:|---:|---:|",
    ]
    for t in THRESHOLDS:
        v = np.where(f >= t, new, old)
        lines.append(f"| {t:g} | {int(np.sum(f >= t))} | {v.mean():.2f} | {int(np.sum(v > inp))} |")
    lines.append(f"| off | 0 | {old.mean():.2f} | {int(np.sum(old > inp))} |")
    text = "\n".join(lines) + "\n"
    print(text)
    if a.out:
        Path(a.out).write_text(text)


if __name__ == "__main__":
    main()
