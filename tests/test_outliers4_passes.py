"""Further passes after the second (``static.RESCORE_FOUND``, ``static.RESCORE_LIFT``,
``static.RESCORE_PASSES``; docs/decisions.md#outliers4-rescore-passes): after a pass that removed
at least ``RESCORE_FOUND`` of the cloud a further pass is tried, which stands only when it
removes that share with a median score of at least ``RESCORE_LIFT`` times its threshold."""

from __future__ import annotations

import numpy as np
import pytest

import spectrageo.outliers._local_density as ld
import spectrageo.outliers.static as st
from spectrageo.outliers import RPCAOptions, detect_outliers
from test_outliers_rescore import _contaminate, _f1, _wavy_sheet  # noqa: E402

from conftest import shared_file  # noqa: E402


@pytest.fixture(scope="module")
def sheet_30():
    P, N = _wavy_sheet()
    return _contaminate(P, N, 0.3)


def test_pass_constants():
    assert 0.0 < st.RESCORE_FOUND < RPCAOptions().rescore_share
    assert st.RESCORE_LIFT > 1.0 and st.RESCORE_PASSES >= 2


def test_clean_and_lightly_contaminated_clouds_take_no_further_pass():
    P, N = _wavy_sheet(60)
    for Q in (P, _contaminate(P, N, 0.05)[0]):
        r = detect_outliers(Q)
        off = detect_outliers(Q, options=RPCAOptions(rescore_share=None))
        assert "rescore" not in r.info and "rescore_dropped" not in r.info
        np.testing.assert_array_equal(r.keep, off.keep)


def test_two_passes_are_the_second_pass(sheet_30, monkeypatch):
    """RESCORE_PASSES = 2: the second pass of docs/decisions.md#outliers-rescore alone."""
    Q, lab = sheet_30
    monkeypatch.setattr(st, "RESCORE_PASSES", 2)
    r = detect_outliers(Q)
    assert r.info["rescore"]["n_passes"] == 2 and "rescore_dropped" not in r.info
    assert r.info["rescore"]["n_removed"] > 0


def test_further_passes_only_remove_more(sheet_30, monkeypatch):
    """Every tried pass standing (RESCORE_FOUND = RESCORE_LIFT = 0): RESCORE_PASSES passes,
    only more points removed each time; scores and threshold stay the first pass's."""
    Q, lab = sheet_30
    monkeypatch.setattr(ld, "LOCAL_FACTOR", None)  # the passes' own removals
    two = detect_outliers(Q, options=RPCAOptions())
    monkeypatch.setattr(st, "RESCORE_FOUND", 0.0)
    monkeypatch.setattr(st, "RESCORE_LIFT", 0.0)
    monkeypatch.setattr(st, "RESCORE_PASSES", 3)
    r = detect_outliers(Q)
    assert r.info["rescore"]["n_passes"] == 3 and "rescore_dropped" not in r.info
    monkeypatch.setattr(st, "RESCORE_PASSES", 2)
    second = detect_outliers(Q)
    assert not (r.keep & ~second.keep).any()
    removed = np.count_nonzero(~r.keep) - np.count_nonzero(~detect_outliers(
        Q, options=RPCAOptions(rescore_share=None)).keep)  # fmt: skip
    assert removed == r.info["rescore"]["n_removed"]
    np.testing.assert_array_equal(r.scores, two.scores)
    assert r.threshold == two.threshold


def test_a_pass_near_its_threshold_is_dropped(sheet_30, monkeypatch):
    """A tried pass whose removed points' median score is under RESCORE_LIFT times its
    threshold (the clean tail just above it) is dropped, whatever it found."""
    Q, _ = sheet_30
    monkeypatch.setattr(st, "RESCORE_FOUND", 0.0)
    monkeypatch.setattr(st, "RESCORE_LIFT", np.inf)
    r = detect_outliers(Q)
    monkeypatch.setattr(st, "RESCORE_PASSES", 2)
    second = detect_outliers(Q)
    dropped = r.info["rescore_dropped"]
    assert dropped["pass"] == 3 and dropped["lift"] < np.inf
    assert r.info["rescore"]["n_passes"] == 2
    np.testing.assert_array_equal(r.keep, second.keep)


def test_rescore_share_none_turns_every_pass_off(sheet_30):
    Q, _ = sheet_30
    r = detect_outliers(Q, options=RPCAOptions(rescore_share=None))
    assert "rescore" not in r.info and "rescore_dropped" not in r.info


def test_rgbd_fragment_at_30_percent(shared_data, monkeypatch):
    """The RGB-D tuning fragment at 30 % injected (far + near 5-15): a third pass stands and F1
    rises over the second pass alone; the clean fragment takes no further pass."""
    from spectrageo import io
    from spectrageo.evaluate._outliers_scans import _inject
    from spectrageo.geometry import pca_normals

    path = shared_file(shared_data, "scans", "registration", "open3d", "cloud_bin_0.pcd")
    P = io.read(path, kind="points").points
    Q, lab, _, _ = _inject(P, pca_normals(P, 10, orient="none"), 0.3, 0)
    r = detect_outliers(Q)
    clean = detect_outliers(P)
    monkeypatch.setattr(st, "RESCORE_PASSES", 2)
    second = detect_outliers(Q)
    assert r.info["rescore"]["n_passes"] >= 3
    assert _f1(~r.keep, lab) > _f1(~second.keep, lab) + 0.01
    assert "rescore" not in clean.info and 1.0 - clean.keep.mean() <= 0.01
