"""Rate control of the animation codecs (:mod:`spectrageo.compress._rate_animation`) and the
unreachable targets of the static codecs (:func:`spectrageo.compress._rate.check_connectivity_floor`):
the trial error is the decoded error, targets are met within 5 % in a few trials, and targets out
of reach are refused before any search."""

from __future__ import annotations

import numpy as np
import pytest

from spectrageo import InvalidInputError, compress
from spectrageo.cli.main import main
from spectrageo.compress import _animation, _rate_animation
from spectrageo.compress._rate import check_connectivity_floor
from spectrageo.metrics import kg_error

from conftest import icosphere


def _anim(T: int = 24, seed: int = 1):
    V, F = icosphere(3)
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, T)[:, None, None]
    bulge = 1 + 0.15 * np.sin(3 * V[None, :, 1:2] + 5 * t + rng.uniform(0, 6))
    return V[None] * bulge + 0.2 * t * np.array([0.3, 1.0, 0.0]), F


@pytest.fixture(scope="module")
def anim():
    return _anim()


def _count_trials(monkeypatch):
    """Steps quantised by the search (one list entry per step: every block's first call)."""
    seen = []
    orig = _rate_animation.quantise_block

    def quantise(plan, method, step, *args):
        if plan.t0 == 0:
            seen.append(step)
        return orig(plan, method, step, *args)

    monkeypatch.setattr(_rate_animation, "quantise_block", quantise)
    return seen


@pytest.mark.parametrize("method", ["blocks", "pca-qp", "pca-qs", "pca-q"])
def test_trial_error_is_the_decoded_error(anim, method):
    A, F = anim
    enc = _animation.make_encoder(A, F, method, {"block": 8})
    tr = _rate_animation.Trials(enc, A)
    for s in (3e-4, 2e-3):
        e = tr.error(s)
        data = tr.build(s)
        assert data == enc.build(s)  # coding the trial's symbols is coding the step
        R, _F = compress.decode_animation(data)
        assert e == pytest.approx(kg_error(R, A), rel=1e-9)


@pytest.mark.parametrize("method", ["blocks", "pca-qp"])
def test_error_target_met_in_a_few_trials(anim, method, monkeypatch):
    A, F = anim
    seen = _count_trials(monkeypatch)
    for target in (0.05, 0.2):
        seen.clear()
        data = compress.encode_animation(A, F, method=method, error=target, block=8)
        R, _F = compress.decode_animation(data)
        assert abs(kg_error(R, A) - target) <= 0.05 * target
        assert len(seen) <= 5


@pytest.mark.parametrize("method", ["blocks", "pca-qp"])
def test_bpvf_target_met(anim, method, monkeypatch):
    A, F = anim
    seen = _count_trials(monkeypatch)
    T, n = A.shape[:2]
    for target in (3.0, 9.0):
        seen.clear()
        data = compress.encode_animation(A, F, method=method, bpvf=target, block=8)
        assert abs(8 * len(data) / (T * n) - target) <= 0.05 * target
        assert len(seen) <= 8


def test_model_bits_close_to_the_coded_size(anim):
    A, F = anim
    enc = _animation.make_encoder(A, F, "blocks", {"block": 8})
    tr = _rate_animation.Trials(enc, A)
    fixed = 8 * len(tr.build(4.0)) - tr.bits(4.0)
    for s in (2e-4, 1e-3, 5e-3):
        coded = 8 * len(tr.build(s))
        assert abs(fixed + tr.bits(s) - coded) <= 0.03 * coded


def test_laplace_entropy_matches_samples():
    rng = np.random.default_rng(0)
    x = rng.laplace(0.0, 1.0, 400_000)
    for a in (0.05, 0.5, 2.0, 8.0):
        _u, c = np.unique(np.rint(x / a), return_counts=True)
        p = c / c.sum()
        h = float(-(p * np.log2(p)).sum())
        assert _rate_animation.laplace_entropy(np.array([a]))[0] == pytest.approx(h, abs=0.02)
    assert _rate_animation.laplace_entropy(np.array([1e6]))[0] < 1e-100


def test_unreachable_animation_targets(anim):
    A, F = anim
    with pytest.raises(InvalidInputError, match=r"smallest file of this method is .* bpvf"):
        compress.encode_animation(A, F, method="blocks", bpvf=0.01)
    with pytest.raises(InvalidInputError, match="cannot be reached: the largest value"):
        compress.encode_animation(A, F, method="blocks", bpvf=5000.0)
    with pytest.raises(InvalidInputError, match="cannot be reached"):
        compress.encode_animation(A, F, method="pca-qp", error=1e5)


def test_connectivity_floor_answers_before_any_search(monkeypatch):
    V, F = icosphere(4)
    rng = np.random.default_rng(0)
    perm = rng.permutation(F.shape[0])  # a shuffled face order costs many bits to keep
    F = F[perm]

    def no_plan(*a, **k):
        raise AssertionError("the geometry was analysed")

    from spectrageo.compress import _spectral

    monkeypatch.setattr(_spectral, "make_plan", no_plan)
    with pytest.raises(InvalidInputError, match=r"reorder=True \(--reorder\)"):
        compress.encode(V, F, bpv=1.0)
    with pytest.raises(InvalidInputError) as exc:
        check_connectivity_floor(1.0, 1000, 100, True)
    assert "80.00 bpv" in str(exc.value) and "reorder" not in str(exc.value)
    check_connectivity_floor(80.0, 1000, 100, False)  # within 5 %: left to the search


def test_cli_unreachable_is_exit_2(tmp_path, capsys):
    from spectrageo import io
    from spectrageo.geometry import Mesh

    V, F = icosphere(4)
    src = tmp_path / "s.ply"
    io.write(src, Mesh(V, F))
    assert main(["compress", str(src), str(tmp_path / "s.sgc"), "--bpv", "0.5"]) == 2
    err = capsys.readouterr().err
    assert "cannot be reached" in err and "--reorder" in err
    assert not (tmp_path / "s.sgc").exists()
