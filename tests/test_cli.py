"""Command-line interface: contracts of commands, options and JSON keys; one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from spectrageo import Mesh, MeshAnimation, io
from spectrageo.cli.main import main
from spectrageo.geometry import mean_edge_length

from conftest import icosphere

INFO_KEYS = {"kind", "n_vertices", "n_faces", "n_frames", "bbox", "mean_edge_length"}
METRIC_KEYS = {"theta_deg", "dmean", "dmax", "dist_n", "dmean_n", "nmsve", "hd_mean", "hd_max"}


@pytest.fixture
def sphere_file(tmp_path):
    V, F = icosphere(3)
    path = tmp_path / "sphere.ply"
    io.write(path, Mesh(V, F))
    return path, V, F


def run_cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_info_json_mesh(capsys, sphere_file):
    path, V, F = sphere_file
    code, out, _ = run_cli(capsys, "info", path, "--json")
    assert code == 0
    d = json.loads(out)
    assert INFO_KEYS <= set(d)
    assert (
        d["kind"] == "mesh"
        and d["n_vertices"] == len(V)
        and d["n_faces"] == len(F)
        and d["n_frames"] == 1
    )
    assert d["mean_edge_length"] == pytest.approx(mean_edge_length(V, F))
    np.testing.assert_allclose(d["bbox"], [V.min(0), V.max(0)])


def test_info_point_cloud_and_animation(capsys, tmp_path):
    P = np.random.default_rng(0).random((50, 3))
    np.save(tmp_path / "pts.npy", P)
    code, out, _ = run_cli(capsys, "info", tmp_path / "pts.npy", "--json")
    d = json.loads(out)
    assert code == 0 and d["kind"] == "point_cloud" and d["n_vertices"] == 50 and d["n_faces"] == 0
    V, F = icosphere(1)
    io.write(tmp_path / "anim.npz", MeshAnimation(np.stack([V, 1.1 * V, 1.2 * V]), F))
    code, out, _ = run_cli(capsys, "info", tmp_path / "anim.npz", "--json")
    d = json.loads(out)
    assert d["kind"] == "animation" and d["n_frames"] == 3 and d["n_vertices"] == len(V)
    code, out, _ = run_cli(capsys, "info", tmp_path / "anim.npz")
    assert code == 0 and "n_frames" in out


def test_noise_metrics_roundtrip(capsys, sphere_file, tmp_path):
    path, V, F = sphere_file
    noisy = tmp_path / "noisy.obj"
    code, _, err = run_cli(
        capsys, "noise", path, noisy, "--kind", "gaussian", "--level", "0.3", "--seed", "7"
    )
    assert code == 0, err
    m = io.read_mesh(noisy)
    assert m.n_vertices == len(V) and np.array_equal(m.faces, F)
    d = np.linalg.norm(m.vertices - V, axis=1)
    assert 0 < d.mean() < 0.3 * mean_edge_length(V, F) * 2
    # same seed -> same file content
    noisy2 = tmp_path / "noisy2.obj"
    run_cli(capsys, "noise", path, noisy2, "--kind", "gaussian", "--level", "0.3", "--seed", "7")
    np.testing.assert_array_equal(io.read_mesh(noisy2).vertices, m.vertices)
    code, out, _ = run_cli(capsys, "metrics", noisy, path, "--json")
    res = json.loads(out)
    assert code == 0 and METRIC_KEYS <= set(res)
    assert res["dmax"] == pytest.approx(d.max(), rel=1e-6)
    assert res["dmean"] == pytest.approx(d.mean(), rel=1e-6)
    assert res["theta_deg"] > 0 and res["hd_max"] <= res["dmax"] + 1e-12
    code, out, _ = run_cli(capsys, "metrics", path, path, "--json")
    assert json.loads(out)["theta_deg"] == pytest.approx(0.0, abs=1e-9)


def test_convert_preserves_order(capsys, sphere_file, tmp_path):
    path, V, F = sphere_file
    for ext in ("off", "obj", "ply", "stl"):
        out = tmp_path / f"c.{ext}"
        code, _, err = run_cli(capsys, "convert", path, out)
        assert code == 0, err
        if ext != "stl":
            m = io.read_mesh(out)
            np.testing.assert_allclose(m.vertices, V, atol=1e-6)
            np.testing.assert_array_equal(m.faces, F)


def test_denoise_mesh_and_animation_keep_layout(capsys, sphere_file, tmp_path):
    from spectrageo import denoise

    assert "taubin" in denoise.available()
    path, V, F = sphere_file
    out = tmp_path / "den.ply"
    code, _, err = run_cli(capsys, "denoise", path, out, "--method", "taubin")
    assert code == 0, err
    m = io.read_mesh(out)
    assert m.n_vertices == len(V) and np.array_equal(m.faces, F)
    anim = tmp_path / "a.npz"
    io.write(anim, MeshAnimation(np.stack([V, V * 1.01]), F))
    out = tmp_path / "a_out.npz"
    code, _, err = run_cli(capsys, "denoise", anim, out, "--method", "taubin")
    assert code == 0, err
    a = io.read_animation(out)
    assert a.n_frames == 2 and a.n_vertices == len(V) and np.array_equal(a.faces, F)


def test_denoise_says_when_the_gate_found_no_noise(capsys, sphere_file, tmp_path):
    """A clean sphere comes back unchanged from tsgsp's gate and the CLI says so; a noisy one
    is denoised without that message."""
    path, V, F = sphere_file
    out = tmp_path / "den.ply"
    code, out_s, err = run_cli(capsys, "denoise", path, out)
    assert code == 0, err
    assert "no noise found" in out_s + err
    assert np.allclose(io.read_mesh(out).vertices, V)
    rng = np.random.default_rng(0)
    noisy = tmp_path / "noisy.ply"
    io.write(noisy, Mesh(V + 0.01 * rng.standard_normal(V.shape), F))
    code, out_s, err = run_cli(capsys, "denoise", noisy, out)
    assert code == 0, err
    assert "no noise found" not in out_s + err


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["info", "/nonexistent/file.ply"], "not found"),
        (["info", "{tmp}/bad.xyzw"], "format|extension"),
        (["metrics", "{tmp}/a.ply", "{tmp}/b.ply", "--radius", "-1"], "radius"),
        (
            ["denoise", "{tmp}/a.ply", "{tmp}/o.ply", "--method", "nosuch"],
            "unknown denoising method",
        ),
        (["noise", "{tmp}/a.ply", "{tmp}/o.ply", "--kind", "nosuch"], "kind"),
        (["evaluate", "denoise", "--data", "{tmp}/missing"], "folder|not found"),
        (["demo", "--methods", "nosuch", "--out", "{tmp}/d"], "unknown denoising method"),
    ],
)
def test_user_mistakes_give_one_line(capsys, tmp_path, argv, match):
    V, F = icosphere(1)
    io.write(tmp_path / "a.ply", Mesh(V, F))
    V2, F2 = icosphere(2)
    io.write(tmp_path / "b.ply", Mesh(V2, F2))
    (tmp_path / "bad.xyzw").write_text("hello")
    code, out, err = run_cli(capsys, *[a.format(tmp=tmp_path) for a in argv])
    assert code == 2
    lines = [ln for ln in err.strip().splitlines() if ln]
    assert len(lines) == 1 and "Traceback" not in err
    import re

    assert re.search(match, lines[0], re.IGNORECASE), lines[0]


def test_bad_option_and_no_command(capsys):
    assert main([]) == 2
    with pytest.raises(SystemExit) as exc:
        main(["info"])
    assert exc.value.code == 2


def test_subprocess_no_traceback(tmp_path):
    bad = tmp_path / "broken.ply"
    bad.write_bytes(
        b"ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\nend_header\n\x00\x01"
    )
    proc = subprocess.run(
        [sys.executable, "-m", "spectrageo.cli.main", "info", str(bad)],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr and proc.stderr.count("\n") == 1


def test_demo_writes_outputs(capsys, tmp_path):
    from spectrageo import denoise

    methods = ["taubin", "laplacian"]
    assert set(methods) <= set(denoise.available())
    code, out, err = run_cli(
        capsys, "demo", "--out", tmp_path / "demo", "--methods", ",".join(methods)
    )
    assert code == 0, err
    assert "theta_deg" in out and "noisy" in out
    for name in [
        "fandisk_noisy.ply",
        "fandisk_error_heatmap.ply",
        *[f"fandisk_{m}.ply" for m in methods],
    ]:
        assert (tmp_path / "demo" / name).exists()
    heat = io.read_mesh(tmp_path / "demo" / "fandisk_error_heatmap.ply")
    assert heat.vertex_colors is not None and "error" in heat.vertex_attributes
    assert heat.n_vertices == 6475


def test_noise_outlier_kinds_take_their_fraction_and_refuse_a_level(capsys, tmp_path):
    from spectrageo import PointCloud

    P = np.random.default_rng(0).uniform(size=(300, 3))
    src = tmp_path / "p.xyz"
    io.write(src, PointCloud(P))
    out = tmp_path / "o.ply"
    for fraction, added in (("0", 0), ("0.2", 60), (None, 30)):
        opt = [] if fraction is None else ["--fraction", fraction]
        code, _, err = run_cli(capsys, "noise", src, out, "--kind", "outliers-near", *opt)
        assert code == 0, err
        assert io.read(out).points.shape[0] == 300 + added
    code, _, err = run_cli(capsys, "noise", src, out, "--kind", "outliers-far", "--level", "0.5")
    assert code == 2 and "--fraction" in err and "Traceback" not in err


@pytest.mark.parametrize("command", ["noise", "simplify", "register"])
def test_negative_seed_is_a_usage_error(capsys, tmp_path, command):
    V, F = icosphere(1)
    a = tmp_path / "a.ply"
    io.write(a, Mesh(V, F))
    argv = {
        "noise": ["noise", a, tmp_path / "o.ply"],
        "simplify": ["simplify", a, tmp_path / "o.ply"],
        "register": ["register", a, a, "--out", tmp_path / "t.json"],
    }[command]
    with pytest.raises(SystemExit) as exc:
        main([str(x) for x in argv] + ["--seed", "-1"])
    assert exc.value.code == 2
    assert "non-negative integer" in capsys.readouterr().err
    from spectrageo import InvalidInputError
    from spectrageo._validation import as_rng

    with pytest.raises(InvalidInputError, match="non-negative"):
        as_rng(-1)


def test_a_command_that_cannot_write_every_output_writes_none(capsys, tmp_path):
    """Output folders and the --apply format are checked before any work: nothing is left
    behind by a command that then fails."""
    from spectrageo import PointCloud

    P = np.random.default_rng(0).uniform(size=(200, 3))
    src = tmp_path / "p.xyz"
    io.write(src, PointCloud(P))
    out = tmp_path / "o.xyz"
    code, _, err = run_cli(capsys, "outliers", src, out, "--mask", tmp_path / "no" / "m.npy")
    assert code == 2 and "output folder does not exist" in err and not out.exists()
    V, F = icosphere(2)
    a = tmp_path / "a.ply"
    io.write(a, Mesh(V, F))
    t = tmp_path / "t.json"
    code, _, err = run_cli(capsys, "register", a, a, "--out", t, "--apply", tmp_path / "m.npz")
    assert code == 2 and "--apply" in err and not t.exists()
    code, _, err = run_cli(capsys, "register", a, a, "--out", tmp_path / "no" / "t.json")
    assert code == 2 and "output folder does not exist" in err


def test_point_cloud_saliency_has_one_value_per_input_row(capsys, tmp_path):
    """Rows without coordinates (NaN, as scanners write them) are left out of the computation
    and get NaN, so the map lines up with the file's rows, as the outlier masks do."""
    P = np.random.default_rng(1).normal(size=(120, 3))
    rows = [" ".join(f"{x:.9g}" for x in p) for p in P]
    rows[17] = "nan nan nan"
    src = tmp_path / "scan.xyz"
    src.write_text("\n".join(rows) + "\n")
    out = tmp_path / "s.npy"
    code, _, err = run_cli(capsys, "saliency", src, "--out", out)
    assert code == 0, err
    s = np.load(out)
    assert s.shape == (120,) and np.isnan(s[17]) and np.isfinite(np.delete(s, 17)).all()
    assert "1 rows without coordinates" in err
    code, _, err = run_cli(capsys, "saliency", src, "--out", tmp_path / "s.ply")
    assert code == 0, err
    assert io.read(tmp_path / "s.ply").points.shape[0] == 119
