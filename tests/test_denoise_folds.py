"""Folded meshes (Eq. N10 of spectrageo.denoise._guard): noise that flips triangles."""

from __future__ import annotations

import numpy as np
import pytest

from spectrageo import InvalidInputError, io
from spectrageo.denoise import denoise
from spectrageo.denoise._guard import FOLD_SHARE, FOLD_STOP, fold_share, unfold
from spectrageo.denoise.tsgsp import GateMeasures, fine, tsgsp
from spectrageo.metrics import theta_deg
from spectrageo.noise.generator import generate


def _rim_cylinder(sections=96, height=1.5):
    """A CAD-style cylinder sampled on its two rims only, caps fanned from their centres."""
    import trimesh

    m = trimesh.creation.cylinder(radius=1.0, height=height, sections=sections)
    return np.asarray(m.vertices, float), np.asarray(m.faces)


def test_fold_share_counts_turned_pairs_only():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.0]])
    flat = np.array([[0, 1, 2], [1, 3, 2]])
    assert fold_share(V, flat) == 0.0
    folded = np.array([[0, 1, 2], [1, 2, 3]])  # the second face's normal points the other way
    assert fold_share(V, folded) == 1.0
    W = V.copy()
    W[3] = [0.2, 0.2, 0.05]  # the second face turned back over the shared edge by ~165 deg
    assert fold_share(W, flat) == 1.0
    degenerate = np.array([[0, 1, 2], [1, 1, 2]])
    assert fold_share(V, degenerate) == 0.0
    with pytest.raises(InvalidInputError):
        fold_share(V, flat, angle=0)


def test_noise_that_flips_triangles_is_smoothed_not_kept():
    V, F = _rim_cylinder()
    Vn = generate(V, F, kind="gaussian-normal", level=0.3, rng=1).vertices
    assert fold_share(V, F) == 0.0 and fold_share(Vn, F) >= FOLD_SHARE
    t_in = theta_deg(Vn, V, F)
    t_out = theta_deg(denoise(Vn, F), V, F)
    # before the rule the gate called this mesh clean (detail test) and returned the input
    assert t_out < 0.6 * t_in
    X, share = unfold(Vn, F, return_share=True)
    assert share == fold_share(X, F) and np.array_equal(X, unfold(Vn, F))
    assert fold_share(X, F) < fold_share(Vn, F) / 4
    assert np.array_equal(tsgsp(Vn, F, unfold_fine=False), X)
    assert not np.array_equal(tsgsp(Vn, F, folds=False), X)
    # the folds are gone (share below FOLD_STOP), so the fine step runs on the unfolded mesh
    assert fold_share(X, F) < FOLD_STOP
    Y = tsgsp(Vn, F)
    assert np.array_equal(Y, fine(X, F))
    assert theta_deg(Y, V, F) < theta_deg(X, V, F) - 10  # 34.8 -> 13.6 degrees
    with pytest.raises(InvalidInputError, match="folds"):
        tsgsp(Vn, F, folds="yes")
    with pytest.raises(InvalidInputError, match="unfold_fine"):
        tsgsp(Vn, F, unfold_fine=1)


def test_folds_left_after_unfolding_skip_the_fine_step():
    """Where the unfold's blocks end with folds left (a steep cone: its clean rim already turns
    by more than 120 degrees), the unfolded mesh is returned as it is."""
    import trimesh

    m = trimesh.creation.cone(radius=1.0, height=3.0, sections=48)
    V, F = np.asarray(m.vertices, float), np.asarray(m.faces)
    Vn = generate(V, F, kind="gaussian-normal", level=0.3, rng=1).vertices
    X = unfold(Vn, F)
    assert fold_share(X, F) >= FOLD_STOP
    assert np.array_equal(tsgsp(Vn, F, measured=GateMeasures(folded=True)), X)


def test_fine_step_after_unfolding_an_organic_mesh(shared_data):
    """Tuning case of the rule (benchmarks/unfold_fine.py): rocker-arm with Gaussian noise in
    random directions at 0.5 folds; the fine step halves what the unfold left."""
    m = io.read_mesh(shared_data / "meshes" / "rocker-arm.obj")
    V, F = m.vertices, m.faces
    Vn = generate(V, F, kind="gaussian-random", level=0.5, rng=1).vertices
    X = unfold(Vn, F)
    Y = denoise(Vn, F)
    assert theta_deg(Y, V, F) < 0.7 * theta_deg(X, V, F)  # 18.4 -> 9.6 degrees


def test_clean_meshes_are_far_from_the_fold_rule(shared_data):
    worst = 0.0
    for sub in ("meshes", "cad"):
        for p in sorted((shared_data / sub).iterdir()):
            if p.suffix.lower() not in (".off", ".obj", ".ply", ".stl", ".gz"):
                continue
            m = io.read_mesh(p)
            if m.n_vertices > 120_000:
                continue
            worst = max(worst, fold_share(m.vertices, m.faces))
    # largest share among them: 0.070 (dragon_vrip_res3, a VRIP reconstruction)
    assert worst < FOLD_SHARE / 1.5


def test_cli_says_when_the_folded_path_ran(tmp_path, capsys):
    from spectrageo.cli.main import main
    from spectrageo.geometry import Mesh

    V, F = _rim_cylinder()
    Vn = generate(V, F, kind="gaussian-normal", level=0.3, rng=1).vertices
    src = tmp_path / "noisy.ply"
    io.write(src, Mesh(Vn, F))
    capsys.readouterr()
    assert main(["denoise", str(src), str(tmp_path / "out.ply")]) == 0
    assert "flipped triangles" in capsys.readouterr().err
    assert np.allclose(io.read(tmp_path / "out.ply").vertices, denoise(Vn, F))
    io.write(src, Mesh(V, F))
    assert main(["denoise", str(src), str(tmp_path / "out.ply")]) == 0
    assert "flipped triangles" not in capsys.readouterr().err


def test_the_gate_decision_reaches_tsgsp_once(monkeypatch):
    """denoise() measures the folds once and hands its decision to tsgsp (like sigma_z)."""
    import spectrageo.denoise._guard as guard

    V, F = _rim_cylinder()
    Vn = generate(V, F, kind="gaussian-normal", level=0.3, rng=1).vertices
    calls = []
    real = guard.fold_share

    def counting(*a, **k):
        calls.append(1)
        return real(*a, **k)

    monkeypatch.setattr(guard, "fold_share", counting)
    X = denoise(Vn, F)
    in_denoise = len(calls)
    calls.clear()
    U = unfold(Vn, F)
    in_unfold = len(calls)  # unfold measures once per block of pairs
    assert np.array_equal(X, fine(U, F))
    assert in_unfold >= 1
    # the gate's measurement only: tsgsp neither measures the folded decision again nor the
    # unfolded mesh (unfold_fine uses the share unfold measured after its last block)
    assert in_denoise == in_unfold + 1
    calls.clear()
    tsgsp(Vn, F, measured=GateMeasures(folded=False))
    assert not calls  # the given decision is used as it is
    with pytest.raises(InvalidInputError, match="folded"):
        tsgsp(Vn, F, measured=GateMeasures(folded="no"))
