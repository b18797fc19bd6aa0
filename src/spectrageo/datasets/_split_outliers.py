"""Split registry, outlier removal: the pattern splits, the injected scans, sequences."""

from __future__ import annotations

from ._split_types import Case, _c

_O = "spectrageo.outliers."
#: outlier defaults justified on the seven shared scans with far / near outliers
#: (``spectrageo evaluate outliers``), validation scans included
OUTLIER_SCANS_CONSULTED = (
    _O + "RPCAOptions.rho",
    _O + "RPCAOptions.tol",
    _O + "RPCAOptions.refine",
    _O + "rpca.REFINE_MIN_TAU",
    _O + "RPCAOptions.tangent_weight",
)
#: the cluster rule's lower bound was set after LiDAR autzen and face000 (validation scans) were
#: seen on the far-outlier benchmark; the valley rule's density cap and noise-scaled significance
#: were added after the validation results had been looked at
_OUTLIER_VALIDATION_CONSULTED = (
    *OUTLIER_SCANS_CONSULTED,
    _O + "_clusters.CLUSTER_MIN",
    _O + "static.DEFAULT_THRESHOLD_RULE",
)

# ================================================================================= outliers
#: the outlier patterns of each split of ``spectrageo evaluate outliers``
OUTLIER_PATTERNS_BY_SPLIT = {
    "tuning": ("uniform", "halo", "blobs"),
    "validation": ("blobs", "flying", "lidar", "mixed"),
}
_OUTLIER_SCANS = {  # label, path, split (in the order of the pattern splits)
    "tuning": (
        ("bunny bun000", "scans/bunny/bun000.ply.gz"),
        ("kinect milk", "scans/pcl/milk.pcd"),
        ("fragment cloud_bin_0", "scans/registration/open3d/cloud_bin_0.pcd"),
        ("kinect table_scene_mug", "scans/pcl/table_scene_mug_stereo_textured.pcd"),
    ),
    "validation": (
        ("bunny top2", "scans/bunny/top2.ply.gz"),
        ("fragment cloud_bin_1", "scans/registration/open3d/cloud_bin_1.pcd"),
        ("lidar autzen", "scans/lidar/autzen_trim.laz"),
        ("rangemap face000", "scans/rangemap/face000.ply"),
        ("b9", "scans/b9.ply"),
    ),
}
#: the scans of the far / near benchmark, in its order
_OUTLIER_INJECTED = (
    "scans/bunny/bun000.ply.gz",
    "scans/bunny/top2.ply.gz",
    "scans/lidar/autzen_trim.laz",
    "scans/pcl/milk.pcd",
    "scans/pcl/table_scene_mug_stereo_textured.pcd",
    "scans/registration/open3d/cloud_bin_0.pcd",
    "scans/registration/open3d/cloud_bin_1.pcd",
)


def _outlier_cases() -> list[Case]:
    out = []
    for split in ("tuning", "validation"):
        pats = ",".join(OUTLIER_PATTERNS_BY_SPLIT[split])
        for label, rel in _OUTLIER_SCANS[split]:
            cons = _OUTLIER_VALIDATION_CONSULTED if split == "validation" else ()
            out.append(
                _c(
                    "outliers",
                    rel,
                    split,
                    "scan",
                    f"patterns {pats}",
                    name=label,
                    consulted_by=cons,
                )
            )
    where = {rel: (label, sp) for sp, rows in _OUTLIER_SCANS.items() for label, rel in rows}
    for rel in _OUTLIER_INJECTED:
        label, split = where[rel]
        cons = OUTLIER_SCANS_CONSULTED if split == "validation" else ()
        out.append(
            _c(
                "outliers-injected",
                rel,
                split,
                "scan",
                "far, near",
                name=label,
                consulted_by=cons,
                note="rho, tol, the refinement and tangent_weight were justified on these seven "
                "scans"
                if cons
                else "",
            )
        )
    out.append(
        _c(
            "outliers-sequence",
            "animations/horse-gallop.npz",
            "tuning",
            "animation",
            "displaced 10-30 %",
            name="horse-gallop",
            note="clean_sequence's choices were measured on it (20 % outliers)",
        )
    )
    for label, rel, step in (
        ("horse-gallop", "animations/horse-gallop.npz", 1),
        ("crane (every 4th frame)", "animations/crane.npz", 4),
        ("Kinect grabber frames", "scans/pcl/grabber_sequence", 1),
    ):
        split = "tuning" if "horse-gallop" in rel else "validation"
        out.append(
            _c(
                "outliers-sequence-patterns",
                rel,
                split,
                "animation",
                f"patterns, step {step}",
                name=label,
            )
        )
    return out
