"""Frame blocks of Algorithm 3 (gft-rpca): per-block generators, setup + one block, Dask blocks.

Skipped when dask/distributed are absent (they are the optional ``dist`` extra). Clusters are small
(threads of this process, or 2 workers) and always closed.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("dask")
pytest.importorskip("distributed")

from spectrageo import distributed, io, noise  # noqa: E402
from spectrageo._errors import InvalidInputError  # noqa: E402
from spectrageo.cli.main import main  # noqa: E402
from spectrageo.denoise import dynamic as dyn  # noqa: E402
from spectrageo.distributed import _frames  # noqa: E402
from spectrageo.geometry import Mesh, MeshAnimation  # noqa: E402
from test_denoise_dynamic import waving_grid  # noqa: E402

KW = {"submesh_size": 80}  # 256 vertices: 4 overlapped submeshes


@pytest.fixture(scope="module")
def noisy():
    A, F = waving_grid(T=23, n=16)
    return noise.animation_noise(A, F, kind="gaussian", level=0.3, rng=1), F


# ----------------------------------------------------------------------------- serial blocks
@pytest.mark.parametrize("basis", ["partitioned", "exact"])
def test_block_alone_equals_its_slice_of_full_run(noisy, basis):
    An, F = noisy
    full = dyn.gft_rpca(An, F, block_size=10, rng=7, options=dyn.GFTRPCAOptions(basis=basis, **KW))
    assert full.n_high.shape == (full.n_submeshes, 3)
    assert full.n_submeshes == (1 if basis == "exact" else 4)
    setup = dyn.gft_rpca_setup(F, An.shape[1], rng=7, options=dyn.GFTRPCAOptions(basis=basis, **KW))
    assert setup.n_parts == full.n_submeshes and setup.nbytes > 0
    # blocks in reverse order, each alone: the same bits as the block's slice of the full run
    for b, s in reversed(list(enumerate(range(0, 23, 10)))):
        blk = dyn.gft_rpca_block(setup, An[s : s + 10], b)
        np.testing.assert_array_equal(blk.frames, full.frames[s : s + 10])
        np.testing.assert_array_equal(blk.n_high, full.n_high[:, b])
        assert blk.n_iter <= full.n_iter and blk.residual <= full.residual
    # the last block run as a short animation of its own gets other generators, same quality
    alone = dyn.gft_rpca(An[20:], F, rng=7, options=dyn.GFTRPCAOptions(basis=basis, **KW))
    assert alone.frames.shape == (3, *An.shape[1:])


def test_result_depends_on_seed_not_on_generator_state(noisy):
    An, F = noisy
    a = dyn.gft_rpca(An, F, block_size=10, rng=3, options=dyn.GFTRPCAOptions(**KW))
    b = dyn.gft_rpca(
        An, F, block_size=10, rng=np.random.default_rng(3), options=dyn.GFTRPCAOptions(**KW)
    )
    np.testing.assert_array_equal(a.frames, b.frames)
    c = dyn.gft_rpca(An, F, block_size=10, rng=4, options=dyn.GFTRPCAOptions(**KW))
    assert not np.array_equal(a.frames, c.frames)  # the seed reaches the RPCA starts


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda An, F, s: dyn.gft_rpca_block("setup", An), "setup"),
        (lambda An, F, s: dyn.gft_rpca_block(s, An[:, :-1]), "vertices per frame"),
        (lambda An, F, s: dyn.gft_rpca_block(s, An, -1), "block_index"),
        (lambda An, F, s: dyn.gft_rpca_block(s, An, 1.0), "block_index"),
        (lambda An, F, s: dyn.gft_rpca_setup(F, 2.5), "n_vertices"),
        (lambda An, F, s: dyn.gft_rpca_setup(F, 0), "n_vertices"),
        (lambda An, F, s: dyn.gft_rpca_setup(F, 10), "F"),
        (
            lambda An, F, s: dyn.gft_rpca_setup(
                F, An.shape[1], options=dyn.GFTRPCAOptions(energy=2.0)
            ),
            "energy",
        ),
    ],
)
def test_setup_and_block_validation(noisy, call, match):
    An, F = noisy
    setup = dyn.gft_rpca_setup(F, An.shape[1], options=dyn.GFTRPCAOptions(basis="exact"))
    with pytest.raises(InvalidInputError, match=match):
        call(An[:4], F, setup)


# ----------------------------------------------------------------------------- Dask blocks
@pytest.mark.parametrize("basis", ["partitioned", "exact"])
def test_dask_blocks_equal_serial_threads(noisy, basis):
    An, F = noisy
    ser = dyn.gft_rpca(An, F, block_size=10, rng=7, options=dyn.GFTRPCAOptions(basis=basis, **KW))
    res = distributed.gft_rpca_blocks(
        An, F, block_size=10, rng=7, basis=basis, workers=2, processes=False, **KW
    )
    np.testing.assert_array_equal(res.frames, ser.frames)  # bitwise
    np.testing.assert_array_equal(res.n_high, ser.n_high)
    assert (res.basis, res.n_submeshes) == (ser.basis, ser.n_submeshes)
    assert (res.n_iter, res.converged, res.residual) == (ser.n_iter, ser.converged, ser.residual)


def test_dask_blocks_equal_serial_worker_processes(noisy):
    """Setup and blocks pickled to two worker processes: still the serial bits."""
    An, F = noisy
    A = MeshAnimation(An, F)
    ser = dyn.gft_rpca(A, block_size=8, rng=11, options=dyn.GFTRPCAOptions(**KW))
    res = distributed.gft_rpca_blocks(A, block_size=8, rng=11, workers=2, **KW)
    np.testing.assert_array_equal(res.frames, ser.frames)
    np.testing.assert_array_equal(res.n_high, ser.n_high)


def test_dask_blocks_equal_serial_shared_animation(shared_data):
    anim = io.read_animation(shared_data / "animations" / "chickenCrossing.npz")
    A = np.asarray(anim.frames[:12], dtype=np.float64)
    An = noise.animation_noise(A, anim.faces, kind="gaussian", level=0.2, rng=0)
    ser = dyn.gft_rpca(An, anim.faces, block_size=5, rng=2)
    res = distributed.gft_rpca_blocks(
        An, anim.faces, block_size=5, rng=2, workers=2, processes=False
    )
    assert res.n_high.shape == (ser.n_submeshes, 3) and ser.n_submeshes > 1
    np.testing.assert_array_equal(res.frames, ser.frames)


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"block_size": None}, "block_size"),
        ({"block_size": 0}, "block_size"),
        ({"block_size": 4, "preset": "x"}, "unknown option"),
        ({"block_size": 4, "energy": 0.0}, "energy"),
        ({"block_size": 4, "rng": "seed"}, "rng"),
    ],
)
def test_gft_rpca_blocks_validation(noisy, kw, match):
    An, F = noisy
    with pytest.raises(InvalidInputError, match=match):  # before any cluster starts
        distributed.gft_rpca_blocks(An, F, processes=False, **kw)


# ----------------------------------------------------------------------------- batch and CLI
def test_batch_animation_block_size_equals_cli(noisy, tmp_path, monkeypatch):
    An, F = noisy
    src = tmp_path / "anim.npz"
    io.write(src, MeshAnimation(An[:12], F))
    cli_out = tmp_path / "cli.npz"
    args = ["--method", "gft-rpca", "--block-size", "5"]
    assert main(["denoise", str(src), str(cli_out), *args]) == 0
    calls = []
    run_blocks = _frames._run_blocks

    def counting(client, A, bs, setup, progress, n_threads):
        calls.append((A.shape[0], bs))
        return run_blocks(client, A, bs, setup, progress, n_threads)

    monkeypatch.setattr(_frames, "_run_blocks", counting)
    recs = distributed.batch(
        "denoise", [src], tmp_path / "out", workers=2, processes=False,
        method="gft-rpca", block_size=5,
    )  # fmt: skip
    assert [r["status"] for r in recs] == ["ok"], recs
    assert calls == [(12, 5)]  # the file's frame blocks ran as Dask tasks (3 blocks)
    assert recs[0]["info"]["n_frames"] == 12
    a, b = io.read(cli_out), io.read(tmp_path / "out" / "anim.npz")
    np.testing.assert_array_equal(a.frames, b.frames)
    np.testing.assert_array_equal(a.faces, b.faces)
    ref = dyn.gft_rpca(An[:12], F, block_size=5)
    np.testing.assert_array_equal(a.frames, ref.frames)


def test_cli_block_size_errors(noisy, tmp_path, capsys):
    An, F = noisy
    src = tmp_path / "anim.npz"
    io.write(src, MeshAnimation(An[:4], F))
    mesh = tmp_path / "m.obj"
    io.write(mesh, Mesh(An[0], F))
    out = tmp_path / "o.npz"
    assert main(["denoise", str(src), str(out), "--method", "bnf", "--block-size", "2"]) != 0
    assert "--block-size applies to --method gft-rpca" in capsys.readouterr().err
    assert main(["denoise", str(src), str(out), "--method", "gft-rpca", "--block-size", "0"]) != 0
    assert "--block-size must be >= 1" in capsys.readouterr().err
    args = ["--method", "gft-rpca", "--block-size", "2"]
    assert main(["denoise", str(mesh), str(tmp_path / "o.obj"), *args]) != 0
    assert "not to a mesh" in capsys.readouterr().err
    assert not out.exists() and not (tmp_path / "o.obj").exists()
