"""The second pass of the RPCA outlier removal (``RPCAOptions.rescore_share``)."""

from __future__ import annotations

import numpy as np
import pytest

from spectrageo import noise
from spectrageo._errors import InvalidInputError
from spectrageo.outliers import OrganizedGrid, RPCAOptions, detect_outliers


def _wavy_sheet(n_side: int = 90, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A jittered grid on a gently curved sheet (spacing 1) and its normals."""
    rng = np.random.default_rng(seed)
    u, v = np.meshgrid(np.arange(n_side, dtype=float), np.arange(n_side, dtype=float))
    u = u.ravel() + rng.uniform(-0.2, 0.2, u.size)
    v = v.ravel() + rng.uniform(-0.2, 0.2, v.size)
    a = 2 * np.pi / n_side
    z = 3.0 * np.sin(a * u) * np.cos(a * v)
    dzu = 3.0 * a * np.cos(a * u) * np.cos(a * v)
    dzv = -3.0 * a * np.sin(a * u) * np.sin(a * v)
    N = np.stack([-dzu, -dzv, np.ones_like(u)], axis=1)
    return np.stack([u, v, z], axis=1), N / np.linalg.norm(N, axis=1, keepdims=True)


def _contaminate(P, N, fraction, seed=0):
    """Half uniform in the padded box, half 5-15 spacings along the normals (the scan-type mix)."""
    Qf, lf = noise.add_outliers(P, fraction=fraction / 2, kind="far", rng=seed)
    Qn, ln = noise.add_outliers(
        P, fraction=fraction / 2, kind="near", normals=N, distance=(5.0, 15.0), rng=seed + 1
    )
    Q = np.concatenate([P, Qf[lf], Qn[ln]])
    lab = np.concatenate([np.zeros(P.shape[0], bool), np.ones(int(lf.sum() + ln.sum()), bool)])
    return Q, lab


def _f1(removed, lab):
    tp = np.count_nonzero(removed & lab)
    return 2 * tp / (np.count_nonzero(removed) + np.count_nonzero(lab))


def test_second_pass_finds_the_near_shell_at_30_percent(monkeypatch):
    import spectrageo.outliers._local_density as ld

    monkeypatch.setattr(ld, "LOCAL_FACTOR", None)  # the second pass's own gain
    P, N = _wavy_sheet()
    Q, lab = _contaminate(P, N, 0.3)
    one = detect_outliers(Q, options=RPCAOptions(rescore_share=None))
    two = detect_outliers(Q)
    assert "rescore" not in one.info and two.info["rescore"]["n_removed"] > 0
    assert two.info["rescore_spread"] < 1.5  # an evenly sampled sheet
    # the second pass only removes more points; scores and threshold are the first pass's
    assert not (two.keep & ~one.keep).any()
    np.testing.assert_array_equal(two.scores, one.scores)
    assert two.threshold == one.threshold
    recall = np.count_nonzero(~two.keep & lab) / lab.sum()
    assert recall > np.count_nonzero(~one.keep & lab) / lab.sum() + 0.02
    assert _f1(~two.keep, lab) > _f1(~one.keep, lab)
    assert np.count_nonzero(~two.keep & ~lab) <= 0.01 * P.shape[0]


@pytest.mark.parametrize("fraction", [0.0, 0.05])
def test_no_second_pass_below_the_share(fraction):
    P, N = _wavy_sheet(60)
    Q, lab = _contaminate(P, N, fraction) if fraction else (P, np.zeros(P.shape[0], bool))
    r = detect_outliers(Q)
    off = detect_outliers(Q, options=RPCAOptions(rescore_share=None))
    assert "rescore" not in r.info
    np.testing.assert_array_equal(r.keep, off.keep)


def test_second_pass_with_a_grid_and_a_given_threshold():
    """The grid stage runs once on the whole frame; a given threshold holds in both passes."""
    h, w = 60, 80
    v, u = np.mgrid[0:h, 0:w]
    z = 1.0 + 0.001 * np.sin(u / 7.0)
    P = np.stack([(u - w / 2) / 100 * z, (v - h / 2) / 100 * z, z], axis=-1).reshape(-1, 3)
    Q, lab = noise.add_outliers(P, fraction=0.3, kind="far", rng=2)
    index = np.concatenate([np.arange(P.shape[0]), np.full(Q.shape[0] - P.shape[0], -1)])
    opts = RPCAOptions(grid=OrganizedGrid((h, w), index), rescore_share=0.05)
    r = detect_outliers(Q, options=opts, threshold=1.0)
    assert r.threshold == 1.0 and r.info["rescore"]["threshold"] == 1.0
    off = detect_outliers(Q, options=RPCAOptions(grid=opts.grid), threshold=1.0)
    assert r.keep[~lab].mean() >= 0.99 and not (r.keep & ~off.keep).any()
    assert r.info["n_flying"] == off.info["n_flying"]


def test_no_second_pass_on_a_cloud_of_uneven_spacing():
    """Two planes, one sampled 3x more sparsely (a frame without its range model): the kept
    points' spacing spread exceeds RESCORE_SPREAD, so the second pass removes only locally sparse
    points (RESCORE_LOCAL): a few more outliers, no point of either plane."""
    from spectrageo.outliers.static import RESCORE_SPREAD

    rng = np.random.default_rng(3)
    u, v = np.meshgrid(np.arange(60.0), np.arange(60.0))
    near = np.stack([u.ravel(), v.ravel(), np.zeros(u.size)], axis=1)
    u, v = np.meshgrid(np.arange(0.0, 150.0, 3.0), np.arange(0.0, 90.0, 3.0))
    far = np.stack([u.ravel() + 70.0, v.ravel(), np.full(u.size, 5.0)], axis=1)
    P = np.concatenate([near, far]) + rng.uniform(-0.1, 0.1, (near.shape[0] + far.shape[0], 3))
    Q, lab = noise.add_outliers(P, fraction=0.3, kind="far", rng=4)
    r = detect_outliers(Q)
    assert r.info["rescore_spread"] > RESCORE_SPREAD and r.info["rescore"]["local"]
    off = detect_outliers(Q, options=RPCAOptions(rescore_share=None))
    np.testing.assert_array_equal(r.keep[~lab], off.keep[~lab])
    assert not (r.keep & ~off.keep).any() and np.count_nonzero(off.keep & ~r.keep) >= 1


@pytest.mark.parametrize("bad", [0, -0.1, 1.5, float("nan"), "a", True])
def test_rescore_share_checks(bad):
    with pytest.raises(InvalidInputError, match="rescore_share"):
        RPCAOptions(rescore_share=bad)
