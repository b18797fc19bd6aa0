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
    assert {r["model"] for r in rows} == {"fandisk", "partLp"}
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
