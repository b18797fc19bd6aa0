"""Tuning data of TSGSP's curved-surface finish (reading choice (g) of
:func:`spectrageo.denoise.tsgsp.fine`): mean normal error of TSGSP with default settings
(through :func:`spectrageo.denoise.denoise`, so with its gate) for several numbers of Taubin
lambda|mu pairs run when the curved-surface gate stops the fine step.

    python benchmarks/curved_finish.py [--data DIR] [--out FILE.md]    # about 4 minutes

Tuning groups (no validation mesh of the denoising protocol): the shared denoising pairs; the
tuning meshes of ``spectrageo evaluate denoise`` (rocker-arm, knot2, spot, casting); the first
frame of four shared animations (cat-poses, chickenCrossing, crane, horse-gallop; organic
shapes in neither split of the static protocol); trimesh's seven CAD test models
(``tests/data/trimesh``) and the synthetic shapes of ``benchmarks/planar_rule.py``. Every
generated case: the five generator kinds at levels 0.1, 0.3 and 0.5, seed 1.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import data_out_args  # noqa: E402
from planar_rule import TRIMESH, TRIMESH_TUNING, synthetic  # noqa: E402
from spectrageo import io  # noqa: E402
from spectrageo.datasets.splits import cases as registry_cases  # noqa: E402
from spectrageo.denoise import denoise  # noqa: E402
from spectrageo.denoise.tsgsp import CURVED_FINISH, FineOptions  # noqa: E402
from spectrageo.evaluate.denoise import TUNING_MESHES, TUNING_PAIRS  # noqa: E402
from spectrageo.metrics import theta_deg  # noqa: E402
from spectrageo.noise.generator import GENERATOR_KINDS, generate  # noqa: E402

LEVELS = (0.1, 0.3, 0.5)
PAIRS = (0, 10, 15, 20, 30)
#: the animations whose first frames are the split registry's ``denoise-frames`` cases
ANIMATIONS = tuple(Path(c.file).stem for c in registry_cases("denoise-frames"))


def _generated(models):
    for name, V, F in models:
        for kind in GENERATOR_KINDS:
            for level in LEVELS:
                Vn = generate(V, F, kind=kind, level=level, rng=1).vertices
                yield f"{name}:{kind}@{level:g}", V, F, Vn


def groups(data: Path) -> dict[str, list]:
    """``{group: [(case, clean V, F, noisy V), ...]}``."""
    pairs = []
    for p in TUNING_PAIRS:
        noisy = io.read_mesh(data / "denoise" / p / "Noisy.obj")
        orig = io.read_mesh(data / "denoise" / p / "Original.obj")
        pairs.append((p, orig.vertices, orig.faces, noisy.vertices))
    tuning = []
    for rel in TUNING_MESHES:
        m = io.read_mesh(data / rel)
        tuning.append((rel, m.vertices, m.faces))
    frames = []
    for name in ANIMATIONS:
        with np.load(data / "animations" / f"{name}.npz") as z:
            V = np.asarray(z["vertices"][0], dtype=np.float64)
            F = np.asarray(z["faces"], dtype=np.int64)
        frames.append((f"animations/{name}[0]", V, F))
    cad = [(f"trimesh/{n}", io.read_mesh(TRIMESH / n)) for n in TRIMESH_TUNING]
    cad = [(n, m.vertices, m.faces) for n, m in cad] + list(synthetic())
    return {
        "shared pairs": pairs,
        "tuning meshes, generated": list(_generated(tuning)),
        "animation first frames, generated": list(_generated(frames)),
        "trimesh CAD + synthetic, generated": list(_generated(cad)),
    }


def main() -> None:
    a = data_out_args()
    lines = [
        "## Curved-surface finish of TSGSP (reading choice (g) of `tsgsp.fine`)",
        "",
        "`python benchmarks/curved_finish.py` (tuning data only; see the script's docstring). "
        "Mean theta (degrees) of TSGSP with default settings for each number of Taubin "
        f"lambda|mu pairs (0.33 / -0.34) run when the curved-surface gate stops the fine step "
        f"(default {CURVED_FINISH}; 0 = before), and the cases above the noisy input.",
        "",
        "| group | cases | noisy | " + " | ".join(f"{p} pairs" for p in PAIRS) + " |",
        "|---|---:|---:|" + "---:|" * len(PAIRS),
    ]
    above = []
    for group, cases in groups(Path(a.data)).items():
        inp = np.array([theta_deg(Vn, V, F) for _, V, F, Vn in cases])
        th = np.array(
            [
                [theta_deg(denoise(Vn, F, fine=FineOptions(curved_finish=p)), V, F) for p in PAIRS]
                for _, V, F, Vn in cases
            ]
        )
        cells = " | ".join(f"{x:.3f}" for x in th.mean(axis=0))
        lines.append(f"| {group} | {len(cases)} | {inp.mean():.2f} | {cells} |")
        counts = ", ".join(f"{p}: {int(np.sum(th[:, i] > inp))}" for i, p in enumerate(PAIRS))
        above.append(f"- {group}, cases above the noisy input: {counts}")
        print(lines[-1], flush=True)
    text = "\n".join(lines + [""] + above) + "\n"
    print(text)
    if a.out:
        Path(a.out).write_text(text)


if __name__ == "__main__":
    main()
