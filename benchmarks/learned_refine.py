"""Can the block-matching 3D CNN of Section 5.1.4 refine TSGSP's output? (issue 20)

The shipped ``bm3d-cnn`` weights filter the noisy mesh (Algorithm 5) and stay above TSGSP on
every benchmark pair. This script trains the same network and cascade
(:func:`spectrageo.learn.train.train_bm3d_cnn`, same training meshes, noise levels, epochs and
seed as the shipped weights) with TSGSP's result as the input of stage 1 (``start``), and
compares, on the shared denoising pairs (never trained on), TSGSP alone with TSGSP followed by
1, 2 and 3 trained stages, and with the shipped weights on the noisy input.

    python benchmarks/learned_refine.py [--data DIR] [--out FILE.md]    # about 3 minutes; needs torch
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _util import data_out_args, machine_line, write_section  # noqa: E402
from spectrageo import io  # noqa: E402
from spectrageo.datasets import denoise_pairs  # noqa: E402
from spectrageo.denoise import denoise  # noqa: E402
from spectrageo.denoise._normals import fast_update_vertices  # noqa: E402
from spectrageo.geometry import face_normals  # noqa: E402
from spectrageo.learn.bm3d_cnn import BM3DCNNModel, bm3d_cnn  # noqa: E402
from spectrageo.learn.train import TRAIN_MESHES, BM3DCNNTrainOptions, train_bm3d_cnn  # noqa: E402
from spectrageo.metrics import theta_deg  # noqa: E402


def tsgsp(V, F):
    """TSGSP with default settings, through the package's gate (as users run it)."""
    return denoise(V, F, method="tsgsp")


def main() -> None:
    args = data_out_args()
    data, out = Path(args.data), args.out
    with tempfile.TemporaryDirectory() as tmp:
        w = Path(tmp) / "refine.npz"
        t0 = time.perf_counter()
        train_bm3d_cnn(data, w, BM3DCNNTrainOptions(start=tsgsp, report=False), log=None)
        train_s = time.perf_counter() - t0
        model = BM3DCNNModel.load(w)
    rows = []
    for name, noisy_path, orig_path in denoise_pairs(data):
        noisy, orig = io.read_mesh(noisy_path), io.read_mesh(orig_path)
        V, V0, F = noisy.vertices, orig.vertices, orig.faces
        X = tsgsp(V, F)
        r = {"pair": name, "input": theta_deg(V, V0, F), "tsgsp": theta_deg(X, V0, F)}
        # control: the stages' vertex update (Eq. 4.28) fed TSGSP's own face normals
        Y = fast_update_vertices(X, F, face_normals(X, F), int(model.meta.get("vertex_iter", 20)))
        r["update"] = theta_deg(Y, V0, F)
        for s in range(1, model.n_stages + 1):
            r[f"+{s}"] = theta_deg(bm3d_cnn(X, F, weights=model, n_iter=s), V0, F)
        r["shipped"] = theta_deg(denoise(V, F, method="bm3d-cnn"), V0, F)
        rows.append(r)
        print(r, file=sys.stderr, flush=True)
    keys = [k for k in rows[0] if k != "pair"]
    head = {
        "input": "noisy input",
        "tsgsp": "tsgsp",
        "update": "tsgsp + vertex update on its own normals",
        "shipped": "bm3d-cnn (shipped, on the noisy input)",
    }
    lines = [
        "## Learned refinement of TSGSP (issue 20)",
        "",
        f"`python benchmarks/learned_refine.py`. Machine: {machine_line()}. Training "
        f"{train_s:.0f} s on {', '.join(TRAIN_MESHES)} (the shipped weights' meshes, levels, "
        "epochs and seed), with TSGSP's result as the input of the first stage. Mean face-normal "
        "angle to the clean mesh (degrees) on the shared denoising pairs, which no training "
        "used; `tsgsp +s`: TSGSP followed by the first `s` trained stages (each: the network's "
        "filtered normals, then the vertex update of Eq. 4.28); the control column runs that "
        "vertex update on TSGSP's own normals, so a loss comes from the filtered normals.",
        "",
        "| pair | " + " | ".join(head.get(k, f"tsgsp {k}") for k in keys) + " |",
        "|---|" + "---:|" * len(keys),
    ]
    for r in rows:
        lines.append(f"| {r['pair']} | " + " | ".join(f"{r[k]:.2f}" for k in keys) + " |")
    lines.append(
        "| mean | " + " | ".join(f"{np.mean([r[k] for r in rows]):.2f}" for k in keys) + " |"
    )
    worse = sum(r["+1"] > r["tsgsp"] for r in rows)
    lines += [
        "",
        f"- one trained stage after TSGSP is worse than TSGSP alone on {worse} of {len(rows)} pairs",
    ]
    md = "\n".join(lines) + "\n"
    if out:
        Path(out).write_text(md)
    else:
        write_section("learned_refine", md)
    print(md)


if __name__ == "__main__":
    main()
