"""Split registry, saliency and the learned denoisers."""

from __future__ import annotations

from ._split_denoise import _T, DENOISE_VALIDATION_CONSULTED
from ._split_types import Case, _c, _group

_S = "spectrageo.saliency."
SALIENCY_CONSULTED = (
    _S + "SaliencyOptions.sparse_norm",
    _S + "geometric.geometric_face_values.sparse_norm",
)


# ========================================================================== saliency, learn
def _saliency_cases() -> list[Case]:
    # split fixed by a rule before the re-choice of sparse_norm: the four maps in alphabetical
    # order, the first two tuning (see docs/decisions.md#saliency-sparse-norm)
    return [
        _c(
            "saliency",
            f"saliency/{m}.obj",
            split,
            "cad",
            "rotation, decimation, noise",
            name=m,
            sources=(f"saliency/{m}_saliencyValues_of_centroids.csv",),
            consulted_by=SALIENCY_CONSULTED if split == "validation" else (),
            note=(
                "sparse_norm re-chosen on block and cad"
                if split == "tuning"
                else "patch scores seen before the split was fixed; not held out for sparse_norm"
            ),
        )
        for m, split in (
            ("block", "tuning"),
            ("cad", "tuning"),
            ("casting", "validation"),
            ("fandisk", "validation"),
        )
    ]


#: training meshes of the shipped learned weights (relative to the shared data folder)
LEARN_TRAIN_MESHES = (
    "saliency/casting.obj",
    "saliency/cad.obj",
    "meshes/rocker-arm.obj",
    "meshes/spot.obj",
    "meshes/knot2.off",
)
#: mesh whose noisy versions give the validation theta of the training report
LEARN_REPORT_MESH = "holes/mech-holes-shark.off"


def _learn_cases() -> list[Case]:
    out = [
        _c("learn-train", rel, "tuning", _group(rel), "gaussian-normal 0.1-0.7")
        for rel in LEARN_TRAIN_MESHES
    ]
    out.append(
        _c("learn-train", LEARN_REPORT_MESH, "validation", "cad", "gaussian-normal 0.3, 0.5")
    )
    for rel in ("meshes/ChineseDragon-10kv.off", "meshes/armadillo.off", "cad/joint.obj"):
        out.append(
            _c(
                "learn",
                rel,
                "validation",
                _group(rel),
                "gaussian-normal 0.3, 0.5",
                consulted_by=DENOISE_VALIDATION_CONSULTED,
                note="a slice of the denoising protocol's validation split",
            )
        )
    for a in ("crane", "horse-gallop", "chickenCrossing"):
        out.append(
            _c(
                "learn",
                f"animations/{a}.npz",
                "validation",
                "animation",
                "gaussian 0.3",
                name=a,
                consulted_by=(_T + "CURVED_FINISH",),
                note="its first frame tuned TSGSP's curved finish",
            )
        )
    return out
