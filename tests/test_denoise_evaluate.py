"""The denoising evaluation harness on the shared pairs (`spectrageo evaluate denoise`)."""

import csv

import pytest

from spectrageo._errors import InvalidInputError
from spectrageo.evaluate.denoise import COLUMNS, evaluate_denoise, format_markdown


def test_evaluate_on_shared_pair(shared_data, tmp_path):
    rows = evaluate_denoise(
        shared_data,
        methods=["taubin", "bnf+coarse"],
        pairs=["Twelve0.5Impulsive"],
        out=tmp_path / "den.md",
        hausdorff_distance=False,
    )
    assert [r["method"] for r in rows] == ["noisy", "taubin", "bnf+coarse"]
    noisy, taubin, bnf = rows
    assert noisy["theta_deg"] > 25  # the shared pair's input error
    assert taubin["theta_deg"] < noisy["theta_deg"] and bnf["theta_deg"] < noisy["theta_deg"]
    assert all(r["n_vertices"] == 4610 for r in rows)
    md = (tmp_path / "den.md").read_text()
    assert "| Twelve0.5Impulsive | taubin |" in md and "**" in md
    with open(tmp_path / "den.csv") as fh:
        got = list(csv.DictReader(fh))
    assert list(got[0]) == list(COLUMNS) and len(got) == 3
    assert float(got[1]["theta_deg"]) == pytest.approx(taubin["theta_deg"])
    assert format_markdown(rows).count("\n") == len(rows) + 1


def test_evaluate_validation(shared_data, tmp_path):
    with pytest.raises(InvalidInputError, match="must be a folder"):
        evaluate_denoise(tmp_path / "missing")
    with pytest.raises(InvalidInputError, match="no noisy/original pairs"):
        evaluate_denoise(tmp_path)
    with pytest.raises(InvalidInputError, match="unknown pairs"):
        evaluate_denoise(shared_data, pairs=["Nope"])
    with pytest.raises(InvalidInputError, match="unknown denoising method"):
        evaluate_denoise(shared_data, methods=["nope"], pairs=["Twelve0.5Impulsive"])


def test_summary_pairs_tsgsp_with_gnf_and_thesis_values():
    from spectrageo.evaluate.denoise import THESIS_THETA, format_summary

    def row(pair, method, theta, t):
        return {"pair": pair, "method": method, "theta_deg": theta, "time_s": t}

    rows = [
        row("Block0.4", "noisy", 33.7, 0.0),
        row("Block0.4", "gnf", 4.0, 1.0),
        row("Block0.4", "tsgsp", 3.5, 0.25),
        row("Bunny0.2", "gnf", 6.6, 2.0),
        row("Bunny0.2", "tsgsp", 5.8, 1.0),
        row("Fandisk0.3", "taubin", 9.9, 0.1),  # no tsgsp/gnf: not summarised
    ]
    lines = format_summary(rows).splitlines()
    assert len(lines) == 4
    assert lines[2] == (
        f"| Block0.4 | 3.50 | 4.00 | 0.25 | {THESIS_THETA['Block0.4'][1]:.2f} | "
        f"{THESIS_THETA['Block0.4'][0]:.2f} |"
    )
    assert lines[3] == "| Bunny0.2 | 5.80 | 6.60 | 0.50 | - | - |"
    assert format_summary(rows[-1:]) == ""


def test_warm_up_runs_each_method_on_a_reindexed_piece(monkeypatch):
    import numpy as np

    from spectrageo.datasets import fandisk
    from spectrageo.denoise import _registry

    m = fandisk()
    calls = []
    pieces = []

    def spy(V, F, *, method):
        calls.append((method, V.shape[0], F.shape[0], int(F.max())))
        pieces.append(F)
        if method == "bad":
            raise RuntimeError("fails")
        return V

    monkeypatch.setattr(_registry, "denoise", spy)
    # faces shuffled: the first 300 of the file are scattered, the piece must still be connected
    F = m.faces[np.random.default_rng(0).permutation(m.faces.shape[0])]
    _registry.warm_up(["bad", "taubin"], m.vertices, F, n_faces=300)
    assert [c[0] for c in calls] == ["bad", "taubin"]  # a failing method does not stop the rest
    for _, nv, nf, fmax in calls:
        assert nf == 300 and fmax == nv - 1  # every kept vertex is used, indices re-numbered
    from scipy.sparse.csgraph import connected_components

    from spectrageo.graph import face_adjacency

    assert connected_components(face_adjacency(pieces[0]), directed=False)[0] == 1
    _registry.warm_up(["taubin"], m.vertices, np.zeros((0, 3), dtype=int))  # nothing to run
