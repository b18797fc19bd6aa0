"""Split registry, compression: static meshes, animations, the DOI codec, connectivity."""

from __future__ import annotations

from ._split_denoise import DENOISE_PAIRS
from ._split_types import Case, _c, _group

# ============================================================================== compression
_COMPRESS = {
    # the two elephants: organic tuning meshes of the predictive codec (no registry holds them
    # out; holes/elephant.off has the same bytes as meshes/elephant.off, which other tasks
    # validate on)
    "tuning": (
        "meshes/fandisk.off",
        "cad/partLp.obj",
        "holes/elephant.off",
        "holes/elephant-with-holes.off",
    ),
    "validation": (
        "meshes/stanford-bunny.obj",
        "meshes/armadillo.off",
        "cad/joint.obj",
        "cad/screwdriver.obj",
        "meshes/dragon_vrip_res2.ply.gz",
        "cad/featuretype.STL",
        "cad/plate_holes.STL",
        "cad/angle_block.STL",
        "cad/abc_00000050.stl",
        "cad/octagonal_pocket.stl",
        "cad/cycloidal.ply",
    ),
}
#: meshes of the compression evaluation run only with ``large=True`` (validation data)
COMPRESS_LARGE = ("meshes/dragon_vrip.ply.gz",)
_C = "spectrageo.compress._conn_traverse."
_CONN_CONSULTED = (_C + "WALK", _C + "N_CTX")


def _compress_cases() -> list[Case]:
    out = [_c("compress", rel, "tuning", _group(rel), "rate points") for rel in _COMPRESS["tuning"]]
    out += [
        _c(
            "compress",
            rel,
            "validation",
            _group(rel),
            "rate points",
            consulted_by=_CONN_CONSULTED,
            note="a tuning mesh of benchmarks/connectivity.py",
        )
        for rel in _COMPRESS["validation"]
    ]
    out += [
        _c(
            "compress",
            rel,
            "validation",
            "large",
            "rate points",
            note="runs only with large=True (its rows are labelled 'large')",
        )
        for rel in COMPRESS_LARGE
    ]
    anims = (
        "horse-gallop",
        "crane",
        "horse-collapse",
        "chickenCrossing",
        "cat-poses",
        "lion-poses",
    )
    for a in anims:
        out.append(
            _c(
                "compress-animation",
                f"animations/{a}.npz",
                "tuning" if a == "horse-gallop" else "validation",
                "animation",
                "rate points",
                name=a,
            )
        )
    out += [
        _c("doi-codec", rel, split, _group(rel), "rate points")
        for split, rel in (
            ("tuning", "meshes/fandisk.off"),
            ("validation", "meshes/stanford-bunny.obj"),
            ("validation", "meshes/dragon_vrip_res2.ply.gz"),
            ("validation", "meshes/dragon_vrip.ply.gz"),
        )
    ]
    return out


#: the meshes of ``benchmarks/connectivity.py`` in its order: the coder was designed while
#: looking at the tuning ones
_CONNECTIVITY = {
    "tuning": (
        "meshes/ChineseDragon-10kv.off",
        "meshes/anchor_dense.off",
        "meshes/armadillo.off",
        "meshes/bear.off",
        "meshes/blade.off",
        "meshes/bull.off",
        "meshes/camel.off",
        "meshes/cheese.off",
        "meshes/cow.off",
        "meshes/cube-meshed.off",
        "meshes/dino.off",
        "meshes/diplodocus.off",
        "meshes/elephant.off",
        "meshes/fandisk.off",
        "meshes/fandisk_large.off",
        "meshes/joint.off",
        "meshes/knot2.off",
        "meshes/lion.off",
        "meshes/man.off",
        "meshes/mushroom.off",
        "meshes/octahedron.off",
        "meshes/rotor.off",
        "meshes/turbine.off",
        "meshes/rocker-arm.obj",
        "meshes/spot.obj",
        "meshes/stanford-bunny.obj",
        "cad/joint.obj",
        "cad/partLp.obj",
        "cad/screwdriver.obj",
        "cad/angle_block.STL",
        "cad/featuretype.STL",
        "cad/plate_holes.STL",
        "cad/abc_00000050.stl",
        "cad/octagonal_pocket.stl",
        "cad/cycloidal.ply",
        "holes/elephant-with-holes.off",
        "holes/elephant.off",
        "holes/holes.off",
        "holes/mech-holes-shark.off",
        "meshes/dragon_vrip_res2.ply.gz",
    ),
    "validation": (
        "animations/cat-poses.npz",
        "animations/chickenCrossing.npz",
        "animations/crane.npz",
        "animations/horse-collapse.npz",
        "animations/horse-gallop.npz",
        "animations/lion-poses.npz",
        *(f"denoise/{p}/Original.obj" for p, _ in DENOISE_PAIRS),
        "saliency/block.obj",
        "saliency/cad.obj",
        "saliency/casting.obj",
        "saliency/fandisk.obj",
        "denoise/real_scans/angel.obj",
        "denoise/real_scans/iron.ply",
        "denoise/real_scans/rabbit.obj",
        "scans/rangemap/face000.ply",
        "scans/registration/uwa/parasaurolophus_6700.ply",
        "scans/registration/uwa/parasaurolophus_low_normals2.ply",
        "meshes/dragon_vrip_res3.ply.gz",
        "meshes/dragon_vrip.ply.gz",
    ),
}


def _connectivity_cases() -> list[Case]:
    out = []
    for split, rels in _CONNECTIVITY.items():
        for rel in rels:
            name = rel[: -len("/Original.obj")] if rel.endswith("/Original.obj") else rel
            grp = "animation" if rel.startswith("animations/") else _group(rel)
            if rel.startswith("denoise/"):
                grp = dict(DENOISE_PAIRS).get(name.split("/")[1], "organic")
            out.append(_c("connectivity", rel, split, grp, "order kept", name=name))
    return out
