"""spectrageo.distributed: batch over files and tiled (out-of-core) outlier removal on Dask.

Skipped when dask/distributed are absent (they are the optional ``dist`` extra). Clusters are small
(threads of this process, or 2 workers) and always closed.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("dask")
pytest.importorskip("distributed")

from spectrageo import distributed, io, outliers  # noqa: E402
from spectrageo._errors import InvalidInputError  # noqa: E402
from spectrageo.cli.main import main  # noqa: E402
from spectrageo.geometry import Mesh, PointCloud  # noqa: E402

from conftest import outlier_recall_precision  # noqa: E402


def _grid_mesh(n=12, seed=0):
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    V = np.c_[x.ravel(), y.ravel(), 0.01 * rng.standard_normal(n * n)]
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = (
        idx[:-1, :-1].ravel(),
        idx[:-1, 1:].ravel(),
        idx[1:, :-1].ravel(),
        idx[1:, 1:].ravel(),
    )
    F = np.r_[np.c_[a, b, d], np.c_[a, d, c]]
    return Mesh(V, F)


@pytest.fixture
def three_files(tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    io.write(src / "a.obj", _grid_mesh(seed=1))
    io.write(src / "b.ply", _grid_mesh(seed=2))
    (src / "broken.obj").write_text("this is not an OBJ file\n")
    return src


def _cloud(n=6000, n_out=200, seed=0):
    rng = np.random.default_rng(seed)
    u = rng.uniform(0, 1, (n, 2))
    P = np.c_[u, 0.05 * np.sin(6 * u[:, 0]) + 0.002 * rng.standard_normal(n)]
    O = rng.uniform([0, 0, -0.3], [1, 1, 0.3], (n_out, 3))
    return np.r_[P, O]


def _labels(X, n_out):
    """Injected outliers (the last ``n_out`` rows of :func:`_cloud`) and those of them farther
    than 0.02 (10 sigma of the surface noise) from the surface: the others (about 5 %, uniform
    heights in [-0.3, 0.3]) lie on the surface and no filter can tell them apart."""
    injected = np.zeros(len(X), dtype=bool)
    injected[len(X) - n_out :] = True
    off = np.abs(X[:, 2] - 0.05 * np.sin(6 * X[:, 0]))
    return injected, injected & (off > 0.02)


# ----------------------------------------------------------------------------- batch
def test_batch_reports_failures_and_names_outputs(three_files, tmp_path):
    out = tmp_path / "out"
    recs = distributed.batch(
        "denoise", three_files, out, workers=2, processes=False, method="bilateral"
    )
    status = {r["input"].rsplit("/", 1)[1]: r["status"] for r in recs}
    assert status == {"a.obj": "ok", "b.ply": "ok", "broken.obj": "failed"}
    assert (out / "a.obj").exists() and (out / "b.ply").exists()
    assert not (out / "broken.obj").exists()
    summary = json.loads((out / "batch-summary.json").read_text())
    assert (summary["n_ok"], summary["n_failed"], summary["n_skipped"]) == (2, 1, 0)
    failed = [r for r in summary["files"] if r["status"] == "failed"][0]
    assert "OBJ" in failed["error"] and failed["time_s"] >= 0
    ok = [r for r in summary["files"] if r["status"] == "ok"][0]
    assert ok["info"]["n_vertices"] == 144 and ok["time_s"] >= 0


def test_batch_output_equals_single_file_run(three_files, tmp_path):
    out = tmp_path / "out"
    distributed.batch("denoise", [three_files / "a.obj"], out, workers=1, processes=False)
    assert main(["denoise", str(three_files / "a.obj"), str(tmp_path / "single.obj"), "-q"]) == 0
    np.testing.assert_array_equal(
        io.read(out / "a.obj").vertices, io.read(tmp_path / "single.obj").vertices
    )


def test_batch_resume_skips_finished(three_files, tmp_path):
    out = tmp_path / "out"
    globbed = str(three_files / "*.obj")
    distributed.batch("denoise", [globbed], out, workers=1, processes=False)
    stamp = (out / "a.obj").stat().st_mtime_ns
    recs = distributed.batch("denoise", [globbed], out, workers=1, processes=False, resume=True)
    by = {r["input"].rsplit("/", 1)[1]: r for r in recs}
    assert by["a.obj"]["status"] == "skipped" and by["broken.obj"]["status"] == "failed"
    assert by["a.obj"]["info"]["n_vertices"] == 144  # carried over from the first summary
    assert (out / "a.obj").stat().st_mtime_ns == stamp


def test_batch_same_names_keep_folders(tmp_path):
    for d in ("x", "y"):
        (tmp_path / d).mkdir()
        io.write(tmp_path / d / "Noisy.obj", _grid_mesh())
    outs = distributed.output_paths(
        "compress", distributed.expand_inputs(str(tmp_path / "*" / "Noisy.obj")), tmp_path / "o"
    )
    assert [o.relative_to(tmp_path / "o").as_posix() for o in outs] == [
        "x/Noisy.sgc",
        "y/Noisy.sgc",
    ]


def test_batch_writes_compressed_inputs_decoded(tmp_path):
    from spectrageo import compress

    m = _grid_mesh()
    (tmp_path / "m.sgc").write_bytes(compress.encode(m.vertices, m.faces))
    outs = distributed.output_paths("denoise", [tmp_path / "m.sgc"], tmp_path / "o")
    assert [o.name for o in outs] == ["m.ply"]
    assert distributed.output_paths("compress", [tmp_path / "m.sgc"], tmp_path / "c")[0].name == (
        "m.sgc"
    )
    assert distributed.output_paths("denoise", [tmp_path / "a.sga"], tmp_path / "o")[0].name == (
        "a.npz"
    )
    recs = distributed.batch("denoise", [tmp_path / "m.sgc"], tmp_path / "o", processes=False)
    assert recs[0]["status"] == "ok", recs[0]
    assert io.read(tmp_path / "o" / "m.ply").n_vertices == m.n_vertices


def test_batch_outliers_and_saliency(tmp_path):
    io.write(tmp_path / "c.ply", PointCloud(_cloud(1500, 50)))
    recs = distributed.batch("outliers", [tmp_path / "c.ply"], tmp_path / "o", processes=False)
    assert recs[0]["status"] == "ok" and recs[0]["info"]["n_points"] == 1550
    assert 1400 < recs[0]["info"]["n_kept"] < 1550
    io.write(tmp_path / "m.obj", _grid_mesh())
    recs = distributed.batch("saliency", [tmp_path / "m.obj"], tmp_path / "s", processes=False)
    assert recs[0]["status"] == "ok", recs[0]
    assert np.load(tmp_path / "s" / "m.npy").shape == (144,)


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"command": "explode"}, "`command` must be one of"),
        ({"inputs": ["/nonexistent/x.obj"]}, "does not exist"),
        ({"inputs": ["/nonexistent/*.obj"]}, "no file matches"),
        ({"inputs": []}, "`inputs` is empty"),
        ({"bogus": 1}, "has no option 'bogus'"),
        ({"command": "outliers", "mask": "m.npy"}, "names one file per run"),
        ({"command": "convert"}, "`suffix` is required"),
    ],
)
def test_batch_bad_input(three_files, tmp_path, kw, match):
    args = {"command": "denoise", "inputs": [three_files / "a.obj"], **kw}
    with pytest.raises(InvalidInputError, match=match):
        distributed.batch(args.pop("command"), args.pop("inputs"), tmp_path / "o", **args)


def test_batch_refuses_overwriting_inputs(three_files):
    with pytest.raises(InvalidInputError, match="overwrite its input"):
        distributed.batch("denoise", [three_files / "a.obj"], three_files)


def test_cli_batch_round_trip(three_files, tmp_path, capsys):
    out = tmp_path / "out"
    argv = ["batch", "convert", str(three_files), "--out", str(out), "--suffix", ".off",
            "--workers", "2"]  # fmt: skip
    assert main(argv) == 1  # one file failed
    err = capsys.readouterr().err
    assert "2 ok, 1 failed" in err and "broken.obj" in err
    assert io.read(out / "a.off").n_vertices == 144
    assert main([*argv, "--resume", "-q"]) == 1
    summary = json.loads((out / "batch-summary.json").read_text())
    assert summary["n_skipped"] == 2 and summary["workers"] == 2


def test_cli_batch_option_errors(three_files, tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:  # --mask is per file: not an option of batch outliers
        main(["batch", "outliers", str(three_files), "--out", str(tmp_path), "--mask", "x"])
    assert exc.value.code == 2
    assert main(["batch", "denoise", "/nonexistent.obj", "--out", str(tmp_path)]) == 2
    assert "does not exist" in capsys.readouterr().err


# ----------------------------------------------------------------------------- tiled outliers
@pytest.mark.parametrize("method", ["sor", "radius"])
def test_tiled_equals_untiled_knn_methods(tmp_path, method):
    X = _cloud()
    np.save(tmp_path / "c.npy", X)
    ref = outliers.remove_outliers(X, method=method, k=10)
    r = distributed.remove_outliers_tiled(
        tmp_path / "c.npy", tmp_path / "o.npy",
        distributed.TileOptions(800, chunk=1000, processes=False, workers=2),
        method=method, return_arrays=True,
    )  # fmt: skip
    assert r.n_tiles == 8
    np.testing.assert_array_equal(r.keep, ref.keep)
    np.testing.assert_allclose(r.scores, ref.scores, rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(np.load(tmp_path / "o.npy"), X[ref.keep])


def test_tiled_rpca_one_tile_equals_untiled(tmp_path):
    X = _cloud(3000, 100)
    np.save(tmp_path / "c.npy", X)
    ref = outliers.remove_outliers(X, k=10)
    r = distributed.remove_outliers_tiled(
        tmp_path / "c.npy", tmp_path / "o.npy",
        distributed.TileOptions(10_000, chunk=700, processes=False, workers=1), return_arrays=True,
    )  # fmt: skip
    assert r.n_tiles == 1
    np.testing.assert_array_equal(r.keep, ref.keep)
    np.testing.assert_array_equal(r.scores, ref.scores)


@pytest.mark.parametrize("tile", [1500, 5000])
def test_tiled_rpca_many_tiles_equal_untiled(tmp_path, tile):
    # above block_size the untiled method is these tiles (partition="tiles"); a larger --tile
    # is cut down to block_size, so both runs score the same regions bit for bit
    X = _cloud()
    np.save(tmp_path / "c.npy", X)
    opts = outliers.RPCAOptions(block_size=1500)
    ref = outliers.remove_outliers(X, k=10, options=opts)
    r = distributed.remove_outliers_tiled(
        tmp_path / "c.npy", tmp_path / "o.npy",
        distributed.TileOptions(tile, chunk=900, processes=False, workers=2),
        options=opts, return_arrays=True,
    )  # fmt: skip
    assert r.n_tiles == 8
    np.testing.assert_array_equal(r.scores, ref.scores)
    np.testing.assert_array_equal(r.keep, ref.keep)
    np.testing.assert_array_equal(np.load(tmp_path / "o.npy"), X[ref.keep])
    recall, precision = outlier_recall_precision(r.keep, *_labels(X, 200))  # not vacuous
    assert recall >= 0.95 and precision >= 0.9, (recall, precision)


def test_tiled_rpca_smaller_tiles_close_to_untiled(tmp_path):
    # tiles below block_size are separate RPCA problems: an approximation
    X = _cloud()
    np.save(tmp_path / "c.npy", X)
    ref = outliers.remove_outliers(X, k=10)
    r = distributed.remove_outliers_tiled(
        tmp_path / "c.npy", tmp_path / "o.npy",
        distributed.TileOptions(1500, processes=False, workers=2), return_arrays=True,
    )  # fmt: skip
    assert r.n_tiles == 8
    # both runs find the outliers: measured on _cloud(seed=0..19) recall 0.97-1.0 of the
    # detectable outliers (tiled and untiled), precision 0.93-1.0; keeping every outlier gives
    # recall 0, removing surface points instead lowers the precision
    injected, detectable = _labels(X, 200)
    for keep in (ref.keep, r.keep):
        recall, precision = outlier_recall_precision(keep, injected, detectable)
        assert recall >= 0.95 and precision >= 0.9, (recall, precision)
    # and mostly the same points: 0-16 of the 6200 masks' entries differ (20 seeds), against
    # about 200 if one run kept the outliers
    assert np.count_nonzero(r.keep != ref.keep) <= 0.15 * 200


def test_tiled_ply_keeps_properties_and_cli(tmp_path):
    X = _cloud(3000, 100)
    col = np.random.default_rng(1).integers(0, 255, (X.shape[0], 3), dtype=np.uint8)
    io.write(tmp_path / "c.ply", PointCloud(X, colors=col))
    rc = main(["outliers", str(tmp_path / "c.ply"), str(tmp_path / "o.ply"), "--tile", "1000",
               "--method", "sor", "--workers", "2", "--mask", str(tmp_path / "k.npy"), "-q"])  # fmt: skip
    assert rc == 0
    keep = np.load(tmp_path / "k.npy")
    ref = outliers.remove_outliers(X, method="sor", k=10)
    np.testing.assert_array_equal(keep, ref.keep)
    out = io.read(tmp_path / "o.ply")
    np.testing.assert_allclose(out.points, X[keep])
    np.testing.assert_array_equal(out.colors, col[keep])


def test_tiled_las_round_trip(tmp_path):
    pytest.importorskip("laspy")
    X = _cloud(3000, 100) * 100.0
    io.write(tmp_path / "c.las", PointCloud(X))
    src = io.read(tmp_path / "c.las").points
    r = distributed.remove_outliers_tiled(
        tmp_path / "c.las", tmp_path / "o.las",
        distributed.TileOptions(1000, chunk=500, processes=False, workers=2),
        method="radius", return_arrays=True,
    )  # fmt: skip
    ref = outliers.remove_outliers(src, method="radius", k=10)
    np.testing.assert_array_equal(r.keep, ref.keep)
    np.testing.assert_allclose(io.read(tmp_path / "o.las").points, src[r.keep])


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"tile": 0}, "`tile` must be"),
        ({"tile": 5}, "`tile` must be >= 2 k"),
        ({"method": "magic"}, "`method` must be one of"),
        ({"method": "sor", "options": {"lam": 0.1}}, "apply to method='rpca' only"),
    ],
)
def test_tiled_bad_input(tmp_path, kw, match):
    np.save(tmp_path / "c.npy", _cloud(200, 0))
    args = {"tile": 100, **kw}
    with pytest.raises(InvalidInputError, match=match):
        if "options" in args:
            args["options"] = outliers.RPCAOptions(**args["options"])
        tiling = distributed.TileOptions(args.pop("tile"))
        distributed.remove_outliers_tiled(tmp_path / "c.npy", tmp_path / "o.npy", tiling, **args)


def test_tiled_rejects_meshes_and_nan(tmp_path):
    io.write(tmp_path / "m.ply", _grid_mesh())
    with pytest.raises(InvalidInputError, match="has faces"):
        distributed.remove_outliers_tiled(
            tmp_path / "m.ply", tmp_path / "o.ply", distributed.TileOptions(100)
        )
    X = _cloud(200, 0)
    X[5] = np.nan
    np.save(tmp_path / "n.npy", X)
    with pytest.raises(InvalidInputError, match="NaN"):
        distributed.remove_outliers_tiled(
            tmp_path / "n.npy", tmp_path / "o.npy", distributed.TileOptions(100)
        )


def test_missing_dask_message(monkeypatch):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda m, *a: None if m == "distributed" else real(m, *a)
    )
    with pytest.raises(distributed.DaskMissingError, match=r"spectrageo\[dist\]"):
        distributed.require_dask()


_THREADS = {"processes": False, "workers": 2}


def _tiles(tile: int, **kw):
    return distributed.TileOptions(tile, **_THREADS, **kw)


def test_tiled_outliers_on_arrays(tmp_path):
    # the Python API takes an (n, 3) numpy or dask array: same scores as the file, no output file
    # unless asked (then .npy), and a clear error for other output formats
    import dask.array as da

    X = _cloud()
    np.save(tmp_path / "c.npy", X)
    ref = distributed.remove_outliers_tiled(
        tmp_path / "c.npy", tmp_path / "o.npy", _tiles(1500), return_arrays=True
    )
    lazy = da.from_array(X, chunks=(1000, 3))
    r = distributed.remove_outliers_tiled(lazy, None, _tiles(1500, chunk=700))
    np.testing.assert_array_equal(r.scores, ref.scores)
    np.testing.assert_array_equal(r.keep, ref.keep)
    r2 = distributed.remove_outliers_tiled(X, tmp_path / "k.npy", _tiles(1500))
    assert r2.keep is None and r2.n_kept == ref.n_kept
    np.testing.assert_array_equal(np.load(tmp_path / "k.npy"), X[ref.keep])
    with pytest.raises(InvalidInputError, match=r"written as \.npy"):
        distributed.remove_outliers_tiled(X, tmp_path / "k.ply", _tiles(1500))
    with pytest.raises(InvalidInputError, match="expected an"):
        distributed.remove_outliers_tiled(X[:, :2], None, _tiles(1500))


def test_tiled_rpca_with_an_empty_tile_equals_untiled(tmp_path):
    rng = np.random.default_rng(0)
    X = np.r_[
        rng.random((1000, 3)) * [10.0, 1.0, 1.0], np.c_[np.full(3000, 5.0), rng.random((3000, 2))]
    ]
    np.save(tmp_path / "c.npy", X)
    opts = outliers.RPCAOptions(block_size=1000)
    ref = outliers.rpca_scores(X, 10, opts)
    r = distributed.remove_outliers_tiled(tmp_path / "c.npy", None, _tiles(1000), options=opts)
    assert r.n_tiles == 4
    np.testing.assert_array_equal(r.scores, ref.scores)


def test_tiled_rpca_mostly_copies_is_a_clear_error(tmp_path):
    # more than half of the points are one position: no global spacing (was NaN scores)
    rng = np.random.default_rng(0)
    X = np.r_[rng.random((2000, 3)), np.zeros((3000, 3)) + 0.5]
    np.save(tmp_path / "c.npy", X)
    with pytest.raises(InvalidInputError, match="exact copies"):
        distributed.remove_outliers_tiled(tmp_path / "c.npy", None, _tiles(1300))


def test_tiled_functions_are_imported_on_first_use():
    """``import spectrageo.distributed`` (which every CLI command pays for) does not import the
    tiled module and its outlier kernels; its names resolve on first use."""
    import subprocess
    import sys

    code = (
        "import sys, spectrageo.distributed as d\n"
        "assert 'spectrageo.distributed._tiled' not in sys.modules\n"
        "assert 'spectrageo.outliers' not in sys.modules\n"
        "f = d.remove_outliers_tiled\n"
        "assert 'spectrageo.distributed._tiled' in sys.modules\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
    from spectrageo import distributed
    from spectrageo.distributed import _tiled

    assert distributed._TILED == tuple(_tiled.__all__)
    assert set(distributed._TILED) <= set(distributed.__all__)
    with pytest.raises(AttributeError):
        _ = distributed.no_such_function


def test_denoise_does_not_import_scipy_stats():
    """The gate's chi-square quantile comes from scipy.special: scipy.stats (0.25 s of import)
    stays out of every command that denoises."""
    import subprocess
    import sys

    code = (
        "import sys, spectrageo.denoise, spectrageo.cli.main\n"
        "assert 'scipy.stats' not in sys.modules, 'scipy.stats imported'\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
