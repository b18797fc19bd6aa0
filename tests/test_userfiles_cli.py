"""Files as users have them: welded soups, seams, NaN rows, and a command line that explains itself.

Every file is built by the test (small soups with float32 jitter, seam copies, an organized PCD
with NaN rows), so the cases run without the shared data.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import numpy as np
import pytest

from spectrageo import Mesh, denoise, io, noise
from spectrageo.cli.main import build_parser, main
from spectrageo.geometry import face_areas, weld

from conftest import cube, icosphere


def run_cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def soup_stl_bytes(V, F, *, jitter=0.0, rng=0) -> bytes:
    """Binary STL of (V, F): three float32 corners per facet, each corner jittered independently
    (as CAD exporters that recompute corners per triangle do)."""
    gen = np.random.default_rng(rng)
    tri = V[F].astype(np.float64)
    diag = np.linalg.norm(V.max(0) - V.min(0))
    tri = tri + gen.uniform(-1, 1, tri.shape) * jitter * diag
    rec = np.zeros(len(F), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    rec["v"] = tri.astype(np.float32)
    return b"\0" * 80 + np.uint32(len(F)).tobytes() + rec.tobytes()


def seam_mesh(V, F):
    """Split the faces on the +x side off: their vertices on the cut get copies (a UV seam)."""
    side = V[F].mean(1)[:, 0] > 0.05
    shared = np.intersect1d(np.unique(F[side]), np.unique(F[~side]))
    copies = np.arange(len(V), len(V) + len(shared))
    remap = np.arange(len(V))
    remap[shared] = copies
    F2 = F.copy()
    F2[side] = remap[F[side]]
    return np.vstack([V, V[shared]]), F2, shared, copies


# ------------------------------------------------------------------------------- welding
def test_stl_soup_is_welded_with_tolerance(tmp_path):
    V, F = icosphere(2)
    p = tmp_path / "part.stl"
    p.write_bytes(soup_stl_bytes(V, F, jitter=1e-8))
    # exact welding leaves cracks: the jittered copies differ in their float32 bits
    raw = io.read(p, weld=False)
    assert raw.n_vertices == 3 * len(F)
    assert np.unique(raw.vertices, axis=0).shape[0] > len(V)
    m, rep = io.read_with_report(p)
    assert m.n_vertices == len(V) and m.n_faces == len(F)
    assert rep.welded and rep.n_merged_vertices == 3 * len(F) - len(V)
    # distinct vertices far closer than any edge but above the tolerance are kept apart
    assert weld(V, F, tol=1e-6).n_merged == 0


def test_soup_in_other_formats_is_welded_but_shared_meshes_are_not(tmp_path):
    V, F = icosphere(1)
    Vs = V[F].reshape(-1, 3)
    Fs = np.arange(len(Vs)).reshape(-1, 3)
    io.write(tmp_path / "soup.ply", Mesh(Vs, Fs))
    assert io.read(tmp_path / "soup.ply").n_vertices == len(V)
    assert io.read(tmp_path / "soup.ply", weld=False).n_vertices == len(Vs)
    # a mesh with a duplicated (seam) vertex keeps its count and order on read
    V2, F2, _, _ = seam_mesh(V, F)
    io.write(tmp_path / "seam.obj", Mesh(V2, F2))
    back = io.read(tmp_path / "seam.obj")
    assert back.n_vertices == len(V2)
    np.testing.assert_allclose(back.vertices, V2)


def test_weld_drops_collapsed_faces_and_expands():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1e-9, 0, 0], [1, 1, 0.0]])
    F = np.array([[0, 1, 2], [0, 3, 1], [1, 4, 2]])
    w = weld(V, F)
    assert w.n_merged == 1 and w.n_dropped_faces == 1
    np.testing.assert_array_equal(w.face_kept, [True, False, True])
    np.testing.assert_array_equal(w.index_map, [0, 1, 2, 0, 3])
    out = w.expand(w.vertices + 1.0)
    assert out.shape == V.shape
    np.testing.assert_allclose(out[3], out[0])


def test_cli_denoise_stl_keeps_the_part(tmp_path, capsys):
    V, F = cube(4)
    p = tmp_path / "box.stl"
    p.write_bytes(soup_stl_bytes(V, F, jitter=1e-8))
    area0 = face_areas(V, F).sum()
    for method in ("taubin", "laplacian", "gnf", "tsgsp"):
        out = tmp_path / f"box_{method}.ply"
        code, _, err = run_cli(capsys, "denoise", p, out, "--method", method)
        assert code == 0, err
        assert "welded" in err
        m = io.read(out)
        assert m.n_vertices == len(V)
        ratio = face_areas(m.vertices, m.faces).sum() / area0
        assert ratio > 0.5, (method, ratio)  # a soup collapsed to points scored 0.000
    # --no-weld keeps the soup: every triangle is isolated and shrinks to its centroid
    code, _, _ = run_cli(
        capsys, "denoise", p, tmp_path / "raw.ply", "--method", "laplacian", "--no-weld"
    )
    raw = io.read(tmp_path / "raw.ply", weld=False)
    assert code == 0 and raw.n_vertices == 3 * len(F)


def test_info_reports_merged_vertices(tmp_path, capsys):
    V, F = icosphere(1)
    p = tmp_path / "s.stl"
    p.write_bytes(soup_stl_bytes(V, F))
    code, out, _ = run_cli(capsys, "info", p, "--json")
    d = json.loads(out)
    assert code == 0
    assert d["n_vertices"] == len(V) and d["n_input_rows"] == 3 * len(F)
    assert d["merged_vertices"] == 3 * len(F) - len(V)
    assert d["topology"]["is_closed"] is True
    code, out, _ = run_cli(capsys, "info", p, "--json", "--no-weld")
    d = json.loads(out)
    assert d["n_vertices"] == 3 * len(F) and d["merged_vertices"] == 0


# ------------------------------------------------------------------------------- seams
@pytest.mark.parametrize("method", ["tsgsp", "gnf", "bnf", "bilateral", "taubin", "laplacian"])
def test_seams_stay_closed(method):
    V, F = cube(4)
    Vn = noise.apply(V, F, kind="gaussian", level=0.3, rng=1)
    V2, F2, shared, copies = seam_mesh(Vn, F)
    out = denoise.denoise(V2, F2, method=method)
    assert out.shape == V2.shape
    np.testing.assert_array_equal(out[shared], out[copies])
    # and the seam does change: the copies are denoised, not frozen
    assert np.abs(out[shared] - V2[shared]).max() > 0
    # processed as stored, the seam opens: the check above can fail
    opened = denoise.denoise(V2, F2, method=method, weld=False)
    assert np.abs(opened[shared] - opened[copies]).max() > 1e-6


def test_cli_denoise_seam_obj_writes_input_order(tmp_path, capsys):
    V, F = cube(3)
    Vn = noise.apply(V, F, kind="gaussian", level=0.3, rng=2)
    V2, F2, shared, copies = seam_mesh(Vn, F)
    io.write(tmp_path / "seam.obj", Mesh(V2, F2))
    code, _, err = run_cli(
        capsys, "denoise", tmp_path / "seam.obj", tmp_path / "out.obj", "--method", "gnf"
    )
    assert code == 0, err
    out = io.read(tmp_path / "out.obj")
    assert out.n_vertices == len(V2)
    np.testing.assert_array_equal(out.faces, F2)
    np.testing.assert_allclose(out.vertices[shared], out.vertices[copies])


# ------------------------------------------------------------------------------- NaN rows
def organized_pcd(tmp_path, n_side=40, nan_every=3):
    x, y = np.meshgrid(np.linspace(0, 1, n_side), np.linspace(0, 1, n_side))
    P = np.c_[x.ravel(), y.ravel(), 0.05 * np.sin(6 * x.ravel())]
    nan_rows = np.arange(0, len(P), nan_every)
    P[nan_rows] = np.nan
    lines = [
        "# .PCD v0.7",
        "VERSION 0.7",
        "FIELDS x y z",
        "SIZE 4 4 4",
        "TYPE F F F",
        "COUNT 1 1 1",
        f"WIDTH {n_side}",
        f"HEIGHT {n_side}",
        "VIEWPOINT 0 0 0 1 0 0 0",
        f"POINTS {len(P)}",
        "DATA ascii",
    ]
    lines += [" ".join("nan" if np.isnan(c) else f"{c:.6f}" for c in row) for row in P]
    path = tmp_path / "organized.pcd"
    path.write_text("\n".join(lines) + "\n")
    return path, P, nan_rows


def test_outliers_masks_cover_every_input_row(tmp_path, capsys):
    path, P, nan_rows = organized_pcd(tmp_path)
    code, _, err = run_cli(
        capsys,
        "outliers",
        path,
        tmp_path / "o.ply",
        "--mask",
        tmp_path / "m.npy",
        "--scores",
        tmp_path / "s.npy",
    )
    assert code == 0, err
    assert f"{len(nan_rows)} of {len(P)} rows" in err
    mask, scores = np.load(tmp_path / "m.npy"), np.load(tmp_path / "s.npy")
    assert mask.shape == (len(P),) and scores.shape == (len(P),)
    assert not mask[nan_rows].any() and np.isinf(scores[nan_rows]).all()
    finite = np.setdiff1d(np.arange(len(P)), nan_rows)
    assert np.isfinite(scores[finite]).all() and not np.isnan(scores).any()
    # in input order: the kept points written are exactly the masked input rows, in order
    kept = io.read(tmp_path / "o.ply").points
    np.testing.assert_allclose(kept, P[mask], atol=1e-6)


def test_outliers_on_a_mesh_keeps_faces(tmp_path, capsys):
    V, F = icosphere(3)
    Vo = np.vstack([V, [[5.0, 5.0, 5.0]]])  # one far outlier vertex, unreferenced
    io.write(tmp_path / "m.ply", Mesh(Vo, F))
    code, _, err = run_cli(capsys, "outliers", tmp_path / "m.ply", tmp_path / "o.ply")
    assert code == 0, err
    out = io.read(tmp_path / "o.ply")
    assert isinstance(out, Mesh) and out.n_faces > 0.9 * len(F)
    assert "faces kept" in err
    assert np.linalg.norm(out.vertices, axis=1).max() < 1.5


# ------------------------------------------------------------------------------- the CLI
def test_output_over_input_is_refused(tmp_path, capsys):
    V, F = icosphere(2)
    p = tmp_path / "in.ply"
    io.write(p, Mesh(V, F))
    before = p.read_bytes()
    for argv in (
        ("denoise", p, p, "--method", "taubin"),
        ("convert", p, p),
        ("noise", p, p),
        ("outliers", p, tmp_path / "o.ply", "--mask", p),
    ):
        code, _, err = run_cli(capsys, *argv)
        assert code == 2 and "is the input file" in err, argv
    assert p.read_bytes() == before


def test_errors_speak_in_cli_terms(tmp_path, capsys):
    V, F = icosphere(2)
    p = tmp_path / "in.ply"
    io.write(p, Mesh(V, F))
    code, _, err = run_cli(capsys, "features", p, "--out", tmp_path / "x.npy", "--patch", "0")
    assert code == 2 and "--patch" in err and "`patch`" not in err
    code, _, err = run_cli(capsys, "convert", p, tmp_path / "x.xyz")
    assert code == 2 and "--kind points" in err and "PointCloud(" not in err
    with pytest.raises(SystemExit) as exc:  # argparse's own one-line error, exit 2
        main(["evaluate", "nonsense"])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "invalid choice" in err and "denoise" in err
    np.save(tmp_path / "pts.npy", V)
    code, _, err = run_cli(capsys, "denoise", tmp_path / "pts.npy", tmp_path / "o.ply")
    assert code == 2 and "point cloud" in err and "outliers" in err


def test_folder_error_names_what_it_found(tmp_path, capsys):
    d = tmp_path / "anims"
    d.mkdir()
    V, F = icosphere(1)
    from spectrageo import MeshAnimation

    io.write(d / "a.npz", MeshAnimation(np.stack([V, V]), F))
    code, _, err = run_cli(capsys, "denoise", d, tmp_path / "o.ply")
    assert code == 2 and "a.npz" in err and "pass one of them" in err


def test_demo_bad_level_leaves_no_folder(tmp_path, capsys):
    out = tmp_path / "demo"
    code, _, err = run_cli(capsys, "demo", "--out", out, "--level", "-1")
    assert code == 2 and "--level" in err
    assert not out.exists()


def test_every_subcommand_help_has_description_defaults_example():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    assert set(sub.choices) >= {"info", "convert", "denoise", "outliers", "evaluate", "demo"}
    for name, sp in sub.choices.items():
        text = sp.format_help()
        assert sp.description, name
        assert "example:" in text and f"spectrageo {name}" in text, name
        # argparse's repetition marks are fine; a "..." elsewhere is an unfinished text
        repeats = ("[FILE ...]", "COMMAND ...", "[MODEL ...]")
        for r in repeats:
            text = text.replace(r, "")
        assert "..." not in text, name
    text = sub.choices["denoise"].format_help()
    for m in denoise.available() + denoise.dynamic_methods():
        assert m in text
    assert "(default: tsgsp)" in " ".join(text.split())  # argparse may wrap the line


def test_quiet_and_status_lines(tmp_path, capsys):
    V, F = icosphere(2)
    io.write(tmp_path / "in.ply", Mesh(V, F))
    code, _, err = run_cli(
        capsys, "denoise", tmp_path / "in.ply", tmp_path / "o.ply", "--method", "taubin"
    )
    assert code == 0 and "wrote" in err
    code, _, err = run_cli(
        capsys, "denoise", tmp_path / "in.ply", tmp_path / "o2.ply", "--method", "taubin", "--quiet"
    )
    assert code == 0 and err == ""


def test_activity_display_on_terminal_only(monkeypatch, capsys):
    from spectrageo import _progress

    monkeypatch.setenv("SPECTRAGEO_PROGRESS", "1")
    monkeypatch.setattr(_progress, "QUIET", False)
    with _progress.activity("busy", interval=0.05, delay=0.0):
        time.sleep(0.3)
    assert "busy:" in capsys.readouterr().err
    monkeypatch.setattr(_progress, "QUIET", True)
    with _progress.activity("busy", interval=0.05, delay=0.0):
        time.sleep(0.2)
    assert capsys.readouterr().err == ""


def test_outliers_and_saliency_commands_show_their_activity(tmp_path, monkeypatch, capsys):
    """Long commands say what runs (on a terminal), as `denoise` does."""
    import contextlib

    from spectrageo import PointCloud, _progress

    shown = []

    @contextlib.contextmanager
    def record(desc, **kw):
        shown.append(desc)
        yield

    monkeypatch.setattr(_progress, "activity", record)
    rng = np.random.default_rng(0)
    io.write(tmp_path / "c.ply", PointCloud(rng.random((400, 3))))
    V, F = icosphere(2)
    io.write(tmp_path / "m.ply", Mesh(V, F))
    code, _, _ = run_cli(capsys, "outliers", tmp_path / "c.ply", tmp_path / "o.ply")
    assert code == 0
    code, _, _ = run_cli(capsys, "saliency", tmp_path / "m.ply", "--out", tmp_path / "s.npy")
    assert code == 0
    assert shown[0] == "outliers rpca (400 points)"
    assert shown[1].startswith("saliency ") and shown[1].endswith(f"({V.shape[0]} vertices)")


def test_info_piped_into_head_is_not_an_error(tmp_path):
    # a sequence of 30,000 one-point frames: its JSON (the per-frame counts) outgrows a pipe buffer
    n = 30_000
    np.savez(
        tmp_path / "seq.npz",
        points=np.random.default_rng(0).random((n, 3)),
        counts=np.ones(n, dtype=np.int64),
    )
    cmd = f"{sys.executable} -m spectrageo.cli.main info {tmp_path / 'seq.npz'} --json | head -c 1"
    r = subprocess.run(
        cmd, shell=True, capture_output=True, text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"}
    )
    assert "internal error" not in r.stderr and "Traceback" not in r.stderr


# ------------------------------------------------------------------- odd files from real collections
def test_gltf_with_separate_buffer_file(tmp_path, capsys):
    import trimesh

    files = trimesh.creation.box().export(
        file_type="gltf"
    )  # {"model.gltf": ..., "gltf_buffer_...bin": ...}
    for fname, data in files.items():
        (tmp_path / fname).write_bytes(data)
    gltf = tmp_path / "model.gltf"
    m = io.read(gltf)
    assert isinstance(m, Mesh) and m.n_faces == 12
    # without its buffer file: one clear line, exit 2
    for fname in files:
        if fname != "model.gltf":
            (tmp_path / fname).unlink()
    code, _, err = run_cli(capsys, "info", gltf)
    assert code == 2 and "not found" in err and len(err.strip().splitlines()) == 1


def test_obj_with_broken_texture_indices_keeps_geometry(tmp_path, capsys):
    V, F = icosphere(1)
    lines = [f"v {x} {y} {z}" for x, y, z in V] + ["vn 0 0 1"]
    lines += [f"f {a + 1}/{a + 1}/1 {b + 1}/{b + 1}/1 {c + 1}/{c + 1}/1" for a, b, c in F]
    (tmp_path / "t.obj").write_text("\n".join(lines) + "\n")  # vt indices, but no 'vt' lines
    with pytest.warns(UserWarning, match="texture index 1 is out of range"):
        m = io.read(tmp_path / "t.obj")
    assert m.n_vertices == len(V) and m.n_faces == len(F) and "texcoord" not in m.face_attributes
    code, out, err = run_cli(capsys, "info", tmp_path / "t.obj", "--json")
    assert code == 0 and json.loads(out)["n_faces"] == len(F)
    warn_lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(warn_lines) == 1 and warn_lines[0].startswith("spectrageo info: warning: t.obj:")


def test_obj_faces_with_two_corners_are_skipped(tmp_path):
    (tmp_path / "l.obj").write_text(
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1// 2//\nf 1 2 3\nf 1 3 4\n"
    )
    with pytest.warns(UserWarning, match="1 OBJ 'f' line"):
        m = io.read(tmp_path / "l.obj")
    np.testing.assert_array_equal(m.faces, [[0, 1, 2], [0, 2, 3]])


def test_tsgsp_on_tiny_meshes():
    import trimesh

    box = trimesh.creation.box()  # 8 vertices, 12 faces: the default patch (18) is capped
    V, F = np.asarray(box.vertices, float), np.asarray(box.faces)
    Vn = V + np.random.default_rng(0).normal(0, 0.01, V.shape)
    out = denoise.denoise(Vn, F, method="tsgsp")
    # 8 vertices of a coarse shape: the coarse-mesh test of the gate cannot tell this noise from
    # shape, and filtering such boxes made them worse on the tuning split, so they are left alone
    np.testing.assert_array_equal(out, Vn)
    tet = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    Ft = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    out = denoise.denoise(tet, Ft, method="tsgsp")  # 4 vertices: noise cannot be told from shape
    np.testing.assert_array_equal(out, tet)


def test_isolated_triangles_give_a_plain_cause(tmp_path, capsys):
    """Separate triangles have nothing to filter: written unchanged, with the reason."""
    tri = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]])
    V = np.vstack([tri, tri + 5, tri + 10])
    F = np.arange(9).reshape(3, 3)
    io.write(tmp_path / "s.ply", Mesh(V, F))
    code, _, err = run_cli(capsys, "denoise", tmp_path / "s.ply", tmp_path / "o.ply")
    assert code == 0 and "separate triangles" in err and "unchanged" in err
    np.testing.assert_array_equal(io.read_mesh(tmp_path / "o.ply", weld=False).V, V)


def test_point_rows_without_coordinates_in_register_and_elsewhere(tmp_path, capsys):
    """A scan saved as .xyz with NaN rows (no measurement): register leaves them out and says
    so, and so does convert (one policy for every command on point clouds)."""
    V, _F = icosphere(3)
    rows = np.r_[V, [[np.nan, np.nan, np.nan]], V[:5] * 1.01]
    scan = tmp_path / "scan.xyz"
    np.savetxt(scan, rows)
    target = tmp_path / "target.xyz"
    np.savetxt(target, V)
    code, _, err = run_cli(capsys, "register", scan, target, "--out", tmp_path / "T.json")
    assert code == 0, err
    assert "1 of" in err and "left out" in err
    assert json.loads((tmp_path / "T.json").read_text())
    code, _, err = run_cli(capsys, "convert", scan, tmp_path / "o.ply")
    assert code == 0 and "1 of" in err and "left out" in err and "nan_points" not in err
    assert io.read(tmp_path / "o.ply").n_points == rows.shape[0] - 1


@pytest.mark.parametrize("area", ["compress", "compress-animation", "outliers", "complete"])
def test_evaluate_on_a_folder_without_its_data_is_an_error(tmp_path, capsys, area):
    """Several areas wrote empty tables and exited 0 when `--data` held none of their files."""
    empty = tmp_path / "empty"
    empty.mkdir()
    out = tmp_path / "ev"
    code, _, err = run_cli(capsys, "evaluate", area, "--data", empty, "--out", out)
    assert code == 2 and "no " in err and "benchmark data found" in err
    assert not list(tmp_path.glob("ev.*"))  # no empty tables left behind


def test_batch_errors_name_the_batch_options(tmp_path, capsys):
    """`batch CMD` has its options one parser down; its errors said `suffix`, not --suffix."""
    pytest.importorskip("dask")
    V, F = icosphere(1)
    p = tmp_path / "in.ply"
    io.write(p, Mesh(V, F))
    code, _, err = run_cli(capsys, "batch", "convert", p, "--out", tmp_path / "o")
    assert code == 2 and "--suffix" in err and "`suffix`" not in err
