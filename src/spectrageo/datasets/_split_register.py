"""Split registry, registration and identification."""

from __future__ import annotations

from ._split_types import Case, _c

# ============================================================================= registration
_R = "spectrageo.register."
_REGISTER_CONSULTED = (
    _R + "_broad.broad_phase_points.n_samples",
    _R + "_broad.broad_phase_points.n_matches",
    _R + "_broad.broad_phase_points.n_peaks",
    _R + "narrow_phase.tol",
    _R + "_narrow.COARSE_EPS",
)
#: the library of the identification scenes: name -> path
IDENTIFY_LIBRARY = {
    "bunny": "meshes/stanford-bunny.obj",
    "armadillo": "meshes/armadillo.off",
    "cow": "meshes/cow.off",
    "elephant": "meshes/elephant.off",
    "camel": "meshes/camel.off",
    "fandisk": "meshes/fandisk.off",
    "rocker-arm": "meshes/rocker-arm.obj",
    "spot": "meshes/spot.obj",
    "dragon": "meshes/ChineseDragon-10kv.off",
    "parasaurolophus": "scans/registration/uwa/parasaurolophus_6700.ply",
}
_IDENTIFY_CONSULTED = (
    "rule: identify's ICP restricted to the segment points near the placed model",
    "rule: identify's normal check in the RANSAC re-ranking",
)


def _register_cases() -> list[Case]:
    out = []
    bunny, frag = "scans/bunny/bun.conf", "scans/registration/open3d/cloud_bin_0.pcd"
    frag_src = ("scans/registration/open3d/cloud_bin_1.pcd",)
    for split, seed, gen in (
        ("tuning", 1, ("armadillo",)),
        ("validation", 0, ("elephant", "camel", "cow", "dino", "bull")),
    ):
        cons = _REGISTER_CONSULTED if split == "validation" else ()
        note = "the tuning scans moved by other motions" if cons else ""
        out.append(
            _c(
                "register",
                bunny,
                split,
                "scan",
                "motion",
                seed,
                "bunny",
                consulted_by=cons,
                note=note,
            )
        )
        out.append(
            _c(
                "register",
                frag,
                split,
                "scan",
                "motion",
                seed,
                "open3d",
                frag_src,
                consulted_by=cons,
                note=note,
            )
        )
        out += [
            _c(
                "register",
                f"meshes/{g}.off",
                split,
                "organic",
                "two partial views, motion",
                seed,
                g,
            )
            for g in gen
        ]
    out.append(
        _c(
            "register-narrow",
            bunny,
            "tuning",
            "scan",
            "perturbed 5-15 deg",
            7,
            "bunny",
            note="benchmarks/narrow_phase.py has no held-out part",
        )
    )
    out.append(
        _c("register-narrow", frag, "tuning", "scan", "perturbed 5-15 deg", 7, "open3d", frag_src)
    )
    lib = tuple(IDENTIFY_LIBRARY.values())
    for seed in (1, 2, 3):
        out.append(
            _c(
                "identify",
                None,
                "tuning",
                "synthetic",
                "scene",
                seed,
                f"scene {seed}",
                lib,
                note="seeds 1-6 chose the defaults; 1-3 are reported",
            )
        )
    for seed in range(11, 19):
        out.append(
            _c(
                "identify",
                None,
                "validation",
                "synthetic",
                "scene",
                seed,
                f"scene {seed}",
                lib,
                consulted_by=_IDENTIFY_CONSULTED,
                note="run once before the last two changes, failures inspected",
            )
        )
    out.append(
        _c(
            "identify",
            "scans/pcl/milk_cartoon_all_small_clorox.pcd",
            "validation",
            "scan",
            "as given, moved",
            7,
            "milk",
            ("scans/pcl/milk.pcd",),
            note="real Kinect scene; no documented choice used it",
        )
    )
    return out
