"""Registration on real pairs: rival poses, the split of the bunny pairs, the 3DMatch recall."""

from __future__ import annotations

import warnings

import numpy as np

from spectrageo.metrics import registration as rm
from spectrageo.register import RegistrationResult, register
from spectrageo.register._broad import _rival
from spectrageo.register._common import make_transform, rotvec_to_matrix

from conftest import shared_file


def _res(T: np.ndarray, fit: float) -> RegistrationResult:
    return RegistrationResult(transformation=T, fitness=fit, inlier_rmse=0.0, n_iter=1,
                              converged=True)  # fmt: skip


def test_rival_is_a_nearly_as_fit_other_pose():
    best = _res(np.eye(4), 0.65)
    flip = make_transform(rotvec_to_matrix(np.array([0.0, 0.0, np.pi])), np.zeros(3))
    assert _rival(_res(flip, 0.62), best, 0.01)
    assert not _rival(_res(flip, 0.50), best, 0.01)  # clearly less fit
    near = make_transform(rotvec_to_matrix(np.radians([0.0, 0.0, 3.0])), [0.005, 0.0, 0.0])
    assert not _rival(_res(near, 0.64), best, 0.01)  # the same pose
    assert _rival(_res(make_transform(np.eye(3), [0.1, 0.0, 0.0]), 0.64), best, 0.01)


def test_real_rgbd_crops_turned_room_is_not_chosen(shared_data):
    """Tuning crop pair of the real RGB-D fragment where the room turned by 180 degrees fits
    best at the voxel scale; the refined rivals decide at one spacing."""
    from spectrageo.evaluate.register import crop_pairs

    shared_file(shared_data, "scans", "registration", "open3d", "fragment.pcd")
    p = crop_pairs(shared_data, 1, 2)[1]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = register(p["source"], p["target"], rng=1)
    assert res.info["n_rivals"] >= 1
    assert rm.rotation_error_deg(res.transformation, p["T_gt"]) < 2.0
    assert res.converged


def test_bunny_pairs_are_split_between_tuning_and_validation(shared_data):
    from spectrageo.datasets._split_register import BUNNY_PAIRS
    from spectrageo.evaluate.register import TUNING, VALIDATION, bunny_pairs

    shared_file(shared_data, "scans", "bunny", "bun.conf")
    tun, val = set(BUNNY_PAIRS["tuning"]), set(BUNNY_PAIRS["validation"])
    assert not tun & val and len(tun) == 13 and len(val) == 12
    assert TUNING["bunny_pairs"] == BUNNY_PAIRS["tuning"]
    got = [p["pair"] for p in bunny_pairs(shared_data, 0, VALIDATION["bunny_pairs"])]
    assert got == list(BUNNY_PAIRS["validation"])


def test_summary_reports_the_3dmatch_recall():
    from spectrageo.evaluate.register import summary

    rows = [
        {"data": "bunny", "overlap": 0.6, "method": "m", "rot_err_deg": r, "trans_err": t,
         "success": r < 5 and t < 0.05, "recall": r < 15 and t < 0.1, "seconds": 1.0}
        for r, t in ((1.0, 0.01), (10.0, 0.08), (40.0, 0.5), (2.0, 0.2))
    ]  # fmt: skip
    allrow = next(s for s in summary(rows) if s["data"] == "all")
    assert allrow["rate"] == 0.25 and allrow["recall"] == 0.5
    assert allrow["med_seconds"] == 1.0 and allrow["p90_rot_err_deg"] > 10.0
