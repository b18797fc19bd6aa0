"""Split registry, completion: inpainting, real and cut holes, animations, sequences."""

from __future__ import annotations

from ._split_types import Case, _c, _group

# =============================================================================== completion
_X = "spectrageo.complete."
_INPAINT = (_X + "inpaint.method", _X + "inpaint.tol", _X + "inpaint.max_iter", _X + "inpaint.rho")
HOLE_TUNING = (
    "meshes/bear.off",
    "meshes/bull.off",
    "meshes/camel.off",
    "meshes/cow.off",
    "meshes/dino.off",
    "meshes/fandisk.off",
    "meshes/knot2.off",
    "meshes/man.off",
    "meshes/rocker-arm.obj",
    "meshes/spot.obj",
    "meshes/turbine.off",
    "cad/abc_00000050.stl",
    "cad/cycloidal.ply",
    "cad/partLp.obj",
    "cad/screwdriver.obj",
)
HOLE_VALIDATION = (
    "meshes/armadillo.off",
    "meshes/diplodocus.off",
    "meshes/cheese.off",
    "meshes/anchor_dense.off",
    "meshes/rotor.off",
    "meshes/cube-meshed.off",
    "cad/featuretype.STL",
    "cad/joint.obj",
    "cad/octagonal_pocket.stl",
    "cad/plate_holes.STL",
    "cad/angle_block.STL",
    "saliency/casting.obj",
    "saliency/block.obj",
    "saliency/cad.obj",
)
_SWITCH = (_X + "dynamic.SWITCH_SCREEN", _X + "dynamic.SWITCH_STRIDE", _X + "dynamic.SWITCH_FOLDS")


def _completion_cases() -> list[Case]:
    out = [
        _c(
            "completion",
            "meshes/fandisk.off",
            "tuning",
            "cad",
            "random, region",
            seed=1,
            name="fandisk",
        )
    ]
    for name in ("fandisk", "elephant", "joint", "armadillo"):
        rel = f"meshes/{name}.off"
        same = name == "fandisk"
        out.append(
            _c(
                "completion",
                rel,
                "validation",
                _group(rel),
                "random, region",
                seed=0,
                name=name,
                consulted_by=_INPAINT if same else (),
                note="the tuning mesh with another seed" if same else "",
            )
        )
    out.append(
        _c(
            "completion-holes",
            "holes/elephant-with-holes.off",
            "tuning",
            "organic",
            "real holes",
            name="elephant-with-holes",
            sources=("holes/elephant.off",),
        )
    )
    for name in ("holes", "mech-holes-shark"):
        rel = f"holes/{name}.off"
        out.append(
            _c(
                "completion-holes",
                rel,
                "validation",
                _group(rel),
                "real holes",
                name=name,
                note="no reference; no documented choice used it",
            )
        )
    for split, rels in (("tuning", HOLE_TUNING), ("validation", HOLE_VALIDATION)):
        for rel in rels:
            out.append(
                _c(
                    "completion-holes-cut",
                    rel,
                    split,
                    _group(rel),
                    "six holes cut",
                    note="a welding bug was found on it and fixed"
                    if rel == "meshes/diplodocus.off"
                    else "",
                )
            )
    out.append(
        _c(
            "completion-animation",
            "animations/horse-gallop.npz",
            "tuning",
            "animation",
            "30 % known",
            seed=1,
            name="horse-gallop",
            note="25 frames; chose MOTION_SWEEPS, GMC_TAU and the switch",
        )
    )
    out.append(
        _c(
            "completion-animation",
            "animations/cat-poses.npz",
            "tuning",
            "animation",
            "30 % known",
            seed=1,
            name="cat-poses",
            note="screened the per-frame switch",
        )
    )
    anim_notes = {
        "horse-gallop": (
            (_X + "dynamic.MOTION_SWEEPS", _X + "dynamic.GMC_TAU", *_SWITCH),
            "the tuning animation with another seed",
        ),
        "cat-poses": (_SWITCH, "looked at with seed 0 when the switch was designed"),
        "lion-poses": (_SWITCH, "looked at with seed 0 before the switch's folds were chosen"),
    }
    for a in (
        "horse-gallop",
        "crane",
        "chickenCrossing",
        "horse-collapse",
        "cat-poses",
        "lion-poses",
    ):
        cons, note = anim_notes.get(a, ((), ""))
        out.append(
            _c(
                "completion-animation",
                f"animations/{a}.npz",
                "validation",
                "animation",
                "30 % known",
                seed=0,
                name=a,
                consulted_by=cons,
                note=note,
            )
        )
    out.append(
        _c(
            "completion-sequence",
            "scans/pcl/grabber_sequence",
            "validation",
            "animation",
            "30 % known",
            seed=0,
            name="pcl-grabber",
        )
    )
    return out
