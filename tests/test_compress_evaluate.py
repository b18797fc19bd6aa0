"""``spectrageo evaluate compress`` on the tuning split (small: fandisk and partLp)."""

from __future__ import annotations

import numpy as np

from spectrageo.evaluate import compress as ev


def test_evaluate_compress_tuning(shared_data, tmp_path):
    rows = ev.evaluate(
        shared_data,
        methods=("spectral", "quant-zstd"),
        out=tmp_path / "rd",
        splits=("tuning",),
    )
    assert {r["model"] for r in rows} == {"fandisk", "partLp", "elephant", "elephant-with-holes"}
    for model in ("fandisk", "partLp"):
        sp = sorted(
            (r["bpv"], r["rms"]) for r in rows if r["model"] == model and r["method"] == "spectral"
        )
        assert len(sp) == len(ev.STEPS["spectral"])
        assert all(b[1] < a[1] for a, b in zip(sp, sp[1:]))  # more bits, less error
        assert all(r["order_kept"] for r in rows if r["model"] == model)
        assert all(np.isfinite(r["hausdorff"]) for r in rows if r["model"] == model)
    md = (tmp_path / "rd.md").read_text()
    assert md.startswith("## Static mesh compression") and "| split | model |" in md
    assert (tmp_path / "rd.csv").read_text().splitlines()[0].startswith("split,model")


def _point(method, setting, bpv, hd, th=float("nan"), share=float("nan")):
    """One rate point of mesh "m" in split "t"."""
    return {
        "split": "t",
        "model": "m",
        "method": method,
        "setting": setting,
        "bpv": bpv,
        "hausdorff": hd,
        "theta_deg": th,
        "sent_share": share,
    }


def test_equal_error_rows_interpolate_without_extrapolating():
    row = _point
    rows = [
        row("spectral", "a", 10.0, 1e-2),
        row("spectral", "b", 20.0, 1e-3),
        row("draco-ordered", "q=10", 100.0, 1e-3),  # on our curve: 20 bpv
        row("draco-ordered", "q=16", 130.0, 1e-5),  # below our curve's range
        row("spectral-reorder", "a", 4.0, 1e-2),
        row("spectral-reorder", "b", 16.0, 1e-4),
        row("draco", "q=8", 5.0, 1e-3),  # log-log midpoint: 8 bpv
    ]
    out = {r["peer"]: r for r in ev.equal_error_rows(rows)}
    assert abs(out["draco-ordered q=10"]["ours_bpv"] - 20.0) < 1e-9
    assert abs(out["draco-ordered q=10"]["ratio"] - 0.2) < 1e-12
    assert out["draco-ordered q=16"]["ours"] == "-"
    assert np.isnan(out["draco-ordered q=16"]["ratio"])
    assert abs(out["draco q=8"]["ours_bpv"] - 8.0) < 1e-9
    assert out["draco q=8"]["ours"] == "spectral-reorder"


def test_feature_rows_pair_the_same_rate_request():
    row = _point

    rows = [
        row("feature", "bpv=conn+2", 5.0, 0.01, 4.0, 0.3),
        row("uniform-delta", "bpv=conn+2", 5.1, 0.02, 8.0, 1.0),
        row("feature", "bpv=conn+4", 7.0, 0.01, 9.0, 0.5),
        row("uniform-delta", "bpv=conn+4", 7.0, 0.02, 8.0, 1.0),
        row("feature", "bpv=conn+8", 11.0, 0.005, 2.0, 1.0),
        row("uniform-delta", "bpv=conn+8", 11.0, 0.005, 2.0, 1.0),
        row("feature", "bpv=conn+12", 15.0, 0.003, 1.0, 0.75),
        row("uniform-delta", "bpv=conn+12", 15.0, 0.002, 0.9, 1.0),
        row("feature", "bpv=conn+16", 19.0, 0.001, 0.5, 1.0),  # no uniform point: left out
    ]
    out = {r["rate"]: r for r in ev.feature_rows(rows)}
    assert list(out) == ["conn+2", "conn+4", "conn+8", "conn+12"]
    assert out["conn+2"]["feature_better"] == "both"
    assert out["conn+4"]["feature_better"] == "hausdorff"
    assert out["conn+8"]["feature_better"] == "same"
    assert out["conn+12"]["feature_better"] == "neither"
    assert out["conn+2"]["sent_share"] == 0.3


def test_only_unmet_requests_are_left_out_of_a_rate_curve():
    from spectrageo import InvalidInputError
    from spectrageo.evaluate._tables import unmet_request

    assert unmet_request(InvalidInputError("`bpv` = 3 cannot be reached: the smallest value..."))
    assert unmet_request(InvalidInputError("`error` = 1e-05 is below what method 'feature'..."))
    assert not unmet_request(InvalidInputError(".sgc spectral layer has invalid parameters."))
