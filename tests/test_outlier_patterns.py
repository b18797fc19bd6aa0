"""Outlier patterns of :func:`spectrageo.noise.corrupt_outliers` and the split benchmark."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from spectrageo._errors import InvalidInputError
from spectrageo.noise import OUTLIER_PATTERNS, add_outliers, corrupt_outliers
from spectrageo.noise._core import mean_spacing
from spectrageo.outliers import detect_outliers, remove_outliers, sor_scores


def _plane(n_side=50, seed=0):
    rng = np.random.default_rng(seed)
    g = np.linspace(0.0, 1.0, n_side)
    X, Y = np.meshgrid(g, g)
    P = np.c_[X.ravel(), Y.ravel(), np.zeros(X.size)]
    P[:, :2] += rng.normal(0.0, 1e-3, (P.shape[0], 2))
    return P


def _f1(removed, labels):
    tp = np.count_nonzero(removed & labels)
    p = tp / max(np.count_nonzero(removed), 1)
    r = tp / max(np.count_nonzero(labels), 1)
    return 2 * p * r / (p + r) if p + r else 0.0


@pytest.mark.parametrize("pattern", OUTLIER_PATTERNS)
@pytest.mark.parametrize("fraction", [0.05, 0.1, 0.2, 0.3])
def test_labels_fractions_determinism(pattern, fraction):
    P = _plane(30)
    Q, lab = corrupt_outliers(P, pattern=pattern, fraction=fraction, rng=3)
    m = int(round(fraction * P.shape[0]))
    assert Q.shape == (P.shape[0] + m, 3) and lab.shape == (Q.shape[0],)
    assert lab.dtype == bool and lab.sum() == m
    # the inliers are the input rows, permuted
    assert np.array_equal(np.sort(Q[~lab], axis=0), np.sort(P, axis=0))
    Q2, lab2 = corrupt_outliers(P, pattern=pattern, fraction=fraction, rng=3)
    assert np.array_equal(Q, Q2) and np.array_equal(lab, lab2)
    Q3, _ = corrupt_outliers(P, pattern=pattern, fraction=fraction, rng=4)
    assert not np.array_equal(Q, Q3)
    A, la = corrupt_outliers(P, pattern=pattern, fraction=fraction, rng=3, shuffle=False)
    assert np.array_equal(A[: P.shape[0]], P) and not la[: P.shape[0]].any()


def test_uniform_and_halo_geometry():
    P = _plane()
    s = mean_spacing(P, None)
    lo, hi = P.min(axis=0), P.max(axis=0)
    pad = 0.1 * np.linalg.norm(hi - lo)
    Q, lab = corrupt_outliers(P, pattern="uniform", fraction=0.2, rng=0)
    assert np.all(Q[lab] >= lo - pad - 1e-12) and np.all(Q[lab] <= hi + pad + 1e-12)
    Q, lab = corrupt_outliers(P, pattern="halo", fraction=0.2, rng=0)
    d, _ = cKDTree(P).query(Q[lab])
    assert d.max() <= 20 * s + 1e-9  # within 20 spacings of the inlier it was moved from
    assert np.median(np.abs(Q[lab, 2])) > 2 * s  # mostly off the surface
    # mixed: first half uniform (appended order), second half a 5-15 spacing halo
    Q, lab = corrupt_outliers(P, pattern="mixed", fraction=0.2, rng=0, shuffle=False)
    out = Q[lab]
    d, _ = cKDTree(P).query(out[out.shape[0] // 2 :])
    assert d.max() <= 15 * s + 1e-9
    assert np.median(np.abs(out[out.shape[0] // 2 :, 2])) > 2.5 * s


def test_blobs_are_clustered():
    P = _plane()
    s = mean_spacing(P, None)
    Qb, lb = corrupt_outliers(P, pattern="blobs", fraction=0.2, rng=0, shuffle=False)
    Qu, lu = corrupt_outliers(P, pattern="uniform", fraction=0.2, rng=0, shuffle=False)
    # every cluster but the last has >= 10 points: the first 10 outliers share one centre
    # (standard deviation <= 5 spacings); uniform outliers spread over the whole box
    first = Qb[lb][:10]
    assert np.linalg.norm(first - first.mean(axis=0), axis=1).max() <= 25 * s
    spread = Qu[lu][:10]
    assert np.linalg.norm(spread - spread.mean(axis=0), axis=1).max() > 30 * s

    def nn(X):
        return np.median(cKDTree(X).query(X, k=2)[0][:, 1])

    assert nn(Qb[lb]) < nn(Qu[lu])


def test_flying_pixels_lie_on_sensor_rays():
    P = _plane()
    s = mean_spacing(P, None)
    vp = np.array([0.5, 0.5, 10.0])
    Q, lab = corrupt_outliers(P, pattern="flying", fraction=0.2, rng=0, viewpoint=vp)
    q = Q[lab]
    # where the ray from the viewpoint through q meets the plane z = 0: the inlier it came from
    t = vp[2] / (vp[2] - q[:, 2])
    x = vp + (q - vp) * t[:, None]
    d, _ = cKDTree(P).query(x)
    assert d.max() < 1e-9
    r = np.linalg.norm(q - x, axis=1)
    assert r.min() >= 2 * s - 1e-9 and r.max() <= 30 * s + 1e-9
    assert (q[:, 2] > 0).any() and (q[:, 2] < 0).any()  # both in front and behind


def test_lidar_multipath_behind_and_scatter_in_front():
    P = _plane()
    s = mean_spacing(P, None)
    vp = np.array([0.5, 0.5, 10.0])
    Q, lab = corrupt_outliers(P, pattern="lidar", fraction=0.2, rng=0, viewpoint=vp)
    z = Q[lab, 2]
    m = int(lab.sum())
    assert np.count_nonzero(z < 0) == m // 2  # multipath: behind the surface seen from vp
    assert np.count_nonzero(z > 0) == m - m // 2  # vegetation: on the sensor side
    assert z[z > 0].max() <= 10 * s + 1e-9
    assert -z[z < 0].max() >= 5 * s * 0.99 and -z.min() <= 50 * s + 1e-9


def test_default_viewpoint_and_errors():
    P = _plane(20)
    Q, lab = corrupt_outliers(P, pattern="flying", fraction=0.1)  # default viewpoint, seed 0
    assert lab.sum() == 40 and np.isfinite(Q).all()
    with pytest.raises(InvalidInputError, match="pattern"):
        corrupt_outliers(P, pattern="gaussian")
    with pytest.raises(InvalidInputError, match="fraction"):
        corrupt_outliers(P, fraction=-0.1)
    with pytest.raises(InvalidInputError, match="fraction"):
        corrupt_outliers(P, fraction="a lot")
    with pytest.raises(InvalidInputError, match="viewpoint"):
        corrupt_outliers(P, pattern="lidar", viewpoint=[0.0, 1.0])
    with pytest.raises(InvalidInputError, match="at least 11"):
        corrupt_outliers(P[:5])
    # the older generator is unchanged
    A, la = add_outliers(P, fraction=0.1, kind="far", rng=0)
    assert la.sum() == 40 and np.array_equal(A[:400], P)


# F1 of the default RPCA filter on a plane, seed 0 (measured 0.96-0.995, blobs 0.83, lidar 0.68:
# clustered and near-surface structured outliers are the hard cases).
_PLANE_F1 = {
    "uniform": 0.9,
    "halo": 0.9,
    "blobs": 0.7,
    "flying": 0.9,
    "lidar": 0.6,
    "mixed": 0.9,
}


@pytest.mark.parametrize("rule", ["density", "valley"])
@pytest.mark.parametrize("pattern", OUTLIER_PATTERNS)
def test_remove_outliers_rules_on_patterns(pattern, rule):
    P = _plane(55)
    Q, lab = corrupt_outliers(P, pattern=pattern, fraction=0.1, rng=0)
    r = detect_outliers(Q, threshold_rule=rule)
    assert _f1(~r.keep, lab) >= _PLANE_F1[pattern]


def test_evaluate_splits_on_real_scan(shared_data, monkeypatch):
    from spectrageo.evaluate import outliers as ev

    monkeypatch.setitem(
        ev.SPLITS,
        "validation",
        {
            "patterns": ("mixed",),
            "scans": (("fragment cloud_bin_1", "scans/registration/open3d/cloud_bin_1.pcd"),),
        },
    )
    rows = ev.evaluate_splits(shared_data, splits=("validation",), fractions=(0.1,))
    by = {(r["kind"], r["method"]): r for r in rows}
    for m in ("rpca", "sor", "radius"):
        assert ("clean", m) in by and 0.0 <= by["clean", m]["flagged"] <= 0.2
        assert by["mixed", f"{m}-oracle"]["f1"] >= by["mixed", m]["f1"]
    assert by["mixed", "rpca-oracle"]["f1"] >= 0.8
    # the PCL-style peer is statistical removal with 50 neighbours and std_ratio 1, exactly
    from spectrageo import io

    P = io.read(shared_data / "scans/registration/open3d/cloud_bin_1.pcd", kind="points").points
    Q, lab = corrupt_outliers(P, pattern="mixed", fraction=0.1, rng=0)
    removed = sor_scores(Q, 50) > 1.0
    assert by["mixed", "pcl-sor"]["f1"] == pytest.approx(_f1(removed, lab), abs=5e-5)  # 4 digits
    assert ("clean", "pcl-sor") in by
    md = ev.format_markdown(rows)
    assert "validation split" in md and "| mixed | 10% | fragment cloud_bin_1 |" in md
    with pytest.raises(InvalidInputError, match="split"):
        ev.evaluate_splits(shared_data, splits=("test",))


def _two_populations(c, seed, n=20000):
    """Inliers: half exact zeros, half log-normal around 0.03 spacings; outliers: log-uniform
    over 0.5-30 spacings (overlapping the inlier tail)."""
    rng = np.random.default_rng(seed)
    m = int(round(c * n))
    inl = 10 ** rng.normal(-1.5, 0.4, n - m)
    inl[rng.random(n - m) < 0.5] = 0.0
    out = 10 ** rng.uniform(-0.3, 1.5, m)
    return rng.permutation(np.r_[inl, out])


@pytest.mark.parametrize("c", [0.05, 0.1, 0.2, 0.3])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_valley_threshold_recovers_contamination(c, seed):
    from spectrageo.outliers import auto_threshold, valley_threshold

    s = _two_populations(c, seed)
    t, info = valley_threshold(s, minimum=0.0)
    assert abs(info["contamination"] - c) <= 0.02  # stated tolerance: 2 points of contamination
    assert info["valley"] is not None and 0.2 <= t <= 0.6  # between the two modes
    assert info["contamination"] == pytest.approx(np.mean(s >= t))
    assert auto_threshold(s, rule="valley") == pytest.approx(t)
    t_min, _ = valley_threshold(s, minimum=5.0)
    assert t_min == 5.0


def test_valley_threshold_single_population_and_degenerate():
    from spectrageo.outliers import auto_threshold, valley_threshold
    from spectrageo.outliers._thresholds import RPCA_MIN_TAU as floor

    rng = np.random.default_rng(0)
    s = 10 ** rng.normal(-1.5, 0.4, 20000)
    t, info = valley_threshold(s)
    assert info["valley"] is None  # no second population: the density rule, floored
    assert t == pytest.approx(max(auto_threshold(s, minimum=floor, rule="density"), floor))
    assert info["contamination"] < 0.01
    assert valley_threshold(np.array([np.inf, np.nan]))[0] == floor
    assert valley_threshold(np.zeros(50))[1]["valley"] is None


def test_remove_outliers_reports_contamination_and_rule():
    P = _plane(40)
    Q, lab = corrupt_outliers(P, pattern="mixed", fraction=0.2, rng=0)
    r = detect_outliers(Q, threshold_rule="valley")
    assert r.info["threshold_rule"] == "valley"
    assert abs(r.info["contamination"] - lab.mean()) <= 0.03
    default = detect_outliers(Q)  # the default rule is the valley
    assert default.info["threshold_rule"] == "valley" and default.threshold == r.threshold
    old = detect_outliers(Q, threshold_rule="density")
    assert old.info["threshold_rule"] == "density" and np.array_equal(old.scores, r.scores)
    given = detect_outliers(Q, threshold=1.0)
    assert given.info["threshold_rule"] == "given" and given.threshold == 1.0
    with pytest.raises(InvalidInputError, match="threshold_rule"):
        remove_outliers(Q, threshold_rule="median")
