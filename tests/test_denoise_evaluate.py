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
