"""``compress.encode(method="auto")``: the smaller of predictive and spectral at a target."""

from __future__ import annotations

import json

import numpy as np
import pytest

from spectrageo import compress, datasets
from spectrageo._errors import InvalidInputError
from spectrageo.cli.main import main


@pytest.fixture(scope="module")
def fandisk():
    m = datasets.fandisk()
    return m.vertices, m.faces


def _geometry_bpv(data: bytes) -> float:
    d = compress.info(data)
    return d["geometry_bpv"]


def _max_dev(V, V2) -> float:
    diag = float(np.linalg.norm(V.max(0) - V.min(0)))
    return float(np.sqrt(np.max(np.sum((V2 - V) ** 2, axis=1)))) / diag


@pytest.mark.parametrize("bound", [2e-2, 1e-4])
def test_max_error_keeps_the_smaller_file(fandisk, bound):
    V, F = fandisk
    auto = compress.encode(V, F, max_error=bound)
    pred = compress.encode(V, F, method="predictive", max_error=bound)
    V2, F2 = compress.decode(auto)
    assert np.array_equal(F2, F)
    assert _max_dev(V, V2) <= bound * (1 + 1e-9)
    if _geometry_bpv(pred) <= compress.AUTO_SPECTRAL_BPV:
        spec = compress.encode(V, F, method="spectral", max_error=bound)
        assert len(auto) == min(len(pred), len(spec))
        assert auto in (pred, spec)
    else:  # spectral is not tried at this rate: the predictive file itself
        assert auto == pred


def test_gate_is_crossed_on_fandisk(fandisk):
    """Both branches of the gate occur at the two bounds above (guards the test's meaning)."""
    V, F = fandisk
    coarse = compress.encode(V, F, method="predictive", max_error=2e-2)
    fine = compress.encode(V, F, method="predictive", max_error=1e-4)
    assert _geometry_bpv(coarse) <= compress.AUTO_SPECTRAL_BPV < _geometry_bpv(fine)


def test_coarse_bound_picks_spectral_where_it_is_smaller(fandisk):
    # fandisk, reordered, at max_error 2e-2: spectral is the smaller file (tuning figure 0.87x)
    V, F = fandisk
    auto = compress.encode(V, F, max_error=2e-2, reorder=True)
    assert compress.info(auto)["method"] == "spectral"
    pred = compress.encode(V, F, method="predictive", max_error=2e-2, reorder=True)
    assert len(auto) < len(pred)


def test_error_target_is_met(fandisk):
    V, F = fandisk
    auto = compress.encode(V, F, error=1e-3)
    V2, _ = compress.decode(auto)
    diag = float(np.linalg.norm(V.max(0) - V.min(0)))
    rms = float(np.sqrt(np.mean(np.sum((V2 - V) ** 2, axis=1)))) / diag
    assert abs(rms - 1e-3) <= compress.RATE_TOLERANCE * 1e-3
    sizes = [len(compress.encode(V, F, method=m, error=1e-3)) for m in ("predictive", "spectral")]
    assert len(auto) == min(sizes)


def test_bpv_keeps_the_smaller_rms(fandisk):
    V, F = fandisk
    target = 24.0  # order kept: the connectivity is about 16 bpv, so spectral is tried too

    def rms(data):
        V2, _ = compress.decode(data)
        return float(np.sqrt(np.mean(np.sum((V2 - V) ** 2, axis=1))))

    auto = compress.encode(V, F, bpv=target)
    both = [compress.encode(V, F, method=m, bpv=target) for m in ("predictive", "spectral")]
    assert auto in both
    assert rms(auto) == min(rms(b) for b in both)


def test_without_target_is_spectral(fandisk):
    V, F = fandisk
    assert compress.encode(V, F) == compress.encode(V, F, method="spectral")
    assert compress.encode(V, F, step=3e-3) == compress.encode(V, F, method="spectral", step=3e-3)
    # method options with "auto" are spectral's
    assert compress.encode(V, F, error=2e-3, submesh_size=200) == compress.encode(
        V, F, method="spectral", error=2e-3, submesh_size=200
    )


def test_unreachable_targets_are_refused(fandisk):
    V, F = fandisk
    with pytest.raises(InvalidInputError, match="connectivity and header alone"):
        compress.encode(V, F, bpv=1.0)
    with pytest.raises(InvalidInputError, match="method"):
        compress.encode(V, F, method="nope", max_error=1e-3)


def test_cli_names_the_method_chosen(tmp_path, capsys):
    src = datasets.fandisk_path()
    out = tmp_path / "f.sgc"
    assert main(["compress", str(src), str(out), "--max-error", "2e-2", "--reorder"]) == 0
    assert "spectral (chosen by auto)" in capsys.readouterr().err
    assert main(["info", str(out), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["method"] == "spectral"
    assert main(["compress", str(src), str(out), "--max-error", "1e-4", "--method", "auto"]) == 0
    assert "predictive (chosen by auto)" in capsys.readouterr().err


@pytest.mark.parametrize("wiggle", [0.0, 0.08, 0.2])
@pytest.mark.parametrize("start", [1e-4, 3e-3, 0.05])
def test_max_error_search_ends_on_a_passing_step_next_to_a_failing_one(wiggle, start):
    # a deviation that grows linearly with the step, with the non-monotone ripple of rounding
    from spectrageo.compress import MAX_ERROR_STEP_TOL, _ladder_step
    from spectrageo.compress._rate import STEP_MIN

    bound = 1e-2
    seen = []

    def worst(s):
        seen.append(s)
        return 0.9 * s * (1.0 + wiggle * np.sin(400.0 * s))

    s = _ladder_step(worst, bound, start)
    tried = sorted(set(seen))
    assert len(tried) < 40
    assert STEP_MIN <= s and worst(s) <= bound
    above = [t for t in tried if s < t <= s * (1 + MAX_ERROR_STEP_TOL) * 1.0001]
    assert any(worst(t) > bound for t in above), "the search ends next to a failing step"


def test_max_error_search_returns_the_largest_step_when_every_step_passes():
    from spectrageo.compress import _ladder_step
    from spectrageo.compress._rate import STEP_MAX

    assert _ladder_step(lambda s: 0.0, 1e-3, 1e-2) == STEP_MAX
