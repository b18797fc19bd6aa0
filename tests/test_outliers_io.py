"""Outlier removal through the CLI and the evaluation harness (real shared scans)."""

from __future__ import annotations

import numpy as np
import pytest

from spectrageo import io, noise
from spectrageo._errors import InvalidInputError
from spectrageo.cli.main import main
from spectrageo.geometry import PointCloud, PointCloudSequence


def _cloud(n=2000, seed=0):
    rng = np.random.default_rng(seed)
    P = rng.standard_normal((n, 3))
    P /= np.linalg.norm(P, axis=1, keepdims=True)
    Q, lab = noise.add_outliers(P, fraction=0.1, kind="far", rng=seed, shuffle=True)
    cols = rng.integers(0, 255, (Q.shape[0], 3)).astype(np.uint8)
    return PointCloud(Q, colors=cols), lab


@pytest.mark.parametrize("method", ["rpca", "sor", "radius"])
def test_cli_outliers_mask_scores_colours(tmp_path, capsys, method):
    pc, lab = _cloud()
    src, dst = tmp_path / "in.ply", tmp_path / "out.ply"
    io.write(src, pc)
    mask, scores = tmp_path / "keep.npy", tmp_path / "scores.npy"
    code = main(
        [
            "outliers",
            str(src),
            str(dst),
            "--method",
            method,
            "--mask",
            str(mask),
            "--scores",
            str(scores),
        ]
    )
    assert code == 0
    keep = np.load(mask)
    s = np.load(scores)
    assert keep.dtype == bool and keep.shape == lab.shape
    assert s.shape == lab.shape and np.isfinite(s).all()
    assert np.mean(~keep[lab]) > (0.6 if method == "radius" else 0.65)  # most outliers removed
    out = io.read(dst, kind="points")
    np.testing.assert_allclose(out.points, pc.points[keep])
    np.testing.assert_array_equal(out.colors[:, :3], pc.colors[keep])
    assert "kept" in capsys.readouterr().err


def test_cli_outliers_sequence(tmp_path):
    rng = np.random.default_rng(0)
    x, y = np.meshgrid(np.linspace(0, 1, 15), np.linspace(0, 1, 15))
    base = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    frames = []
    for t in range(6):
        V = base + [0.03 * t, 0, 0]
        V[:, 2] = 0.1 * np.sin(3 * V[:, 0])
        idx = rng.choice(V.shape[0], 20, replace=False)
        V[idx] += 0.2
        frames.append(PointCloud(V))
    src, dst, mask = tmp_path / "seq.npz", tmp_path / "clean.npz", tmp_path / "keep.npy"
    io.write(src, PointCloudSequence(frames))
    assert main(["outliers", str(src), str(dst), "--mask", str(mask)]) == 0
    keep = np.load(mask)
    assert keep.shape == (6, base.shape[0]) and keep.dtype == bool
    out = io.read(dst, kind="sequence")
    assert out.n_frames == 6 and out.n_points == [base.shape[0]] * 6  # refilled, all points
    assert main(["outliers", str(src), str(dst), "--method", "sor"]) == 2


def test_evaluate_outliers_on_real_scan(shared_data, tmp_path):
    from spectrageo.evaluate.outliers import evaluate_outliers, format_markdown

    rows = evaluate_outliers(
        shared_data,
        methods=("rpca", "sor", "sor-grid"),
        out=tmp_path / "o",
        fractions=(0.1,),
        kinds=("far",),
        scans=(("kinect milk", "scans/pcl/milk.pcd"),),
    )
    by = {r["method"]: r for r in rows}
    assert set(by) == {"rpca", "rpca-oracle", "sor", "sor-grid"}
    assert by["rpca"]["f1"] >= 0.85  # the target at 10 % outliers
    assert by["sor-grid"]["f1"] >= by["sor"]["f1"]  # the oracle grid contains std_ratio 1, k 10
    assert by["rpca-oracle"]["f1"] >= by["rpca"]["f1"]  # the best cut of the same scores
    md = (tmp_path / "o.md").read_text()
    assert "kinect milk" in md and "| rpca |" in md
    csv = (tmp_path / "o.csv").read_text().splitlines()
    assert csv[0].startswith("dataset,kind,fraction,method") and len(csv) == 5
    text = format_markdown(rows)
    assert "F1" in text
    # the summary line of the case repeats the table's F1 values
    summary = next(ln for ln in text.splitlines() if ln.startswith("| kinect milk | far |"))
    cells = [c.strip() for c in summary.strip("|").split("|")]
    assert cells[2] == f"{by['rpca']['f1']:.3f}" and cells[3] == f"{by['rpca-oracle']['f1']:.3f}"
    assert cells[4] == f"{by['sor-grid']['f1']:.3f}" and cells[5] == "-" and cells[6] == "-"
    with pytest.raises(InvalidInputError, match="unknown method"):
        evaluate_outliers(shared_data, methods=("lof",))
    with pytest.raises(InvalidInputError, match="folder"):
        evaluate_outliers(tmp_path / "missing")
