"""The .sga animation codec (Section 5.2.2) with one Dask task per frame block: the same bytes as
the serial encoder for every supported method and rate mode, and the refusals.

Skipped when dask/distributed are absent (they are the optional ``dist`` extra). Clusters are small
(threads of this process, or 2 worker processes) and always closed.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("dask")
pytest.importorskip("distributed")

from spectrageo import compress, distributed, io  # noqa: E402
from spectrageo._errors import InvalidInputError  # noqa: E402
from spectrageo.geometry import MeshAnimation  # noqa: E402
from spectrageo.metrics import kg_error  # noqa: E402
from test_compress_animation import _synthetic  # noqa: E402

from conftest import shared_file

THREADS = {"workers": 2, "processes": False, "progress": False}


@pytest.fixture(scope="module")
def anim():
    return _synthetic(T=20, seed=3)


def _same_as_serial(A, F, **kw):
    ser = compress.encode_animation(A, F, **kw)
    par = distributed.encode_animation_blocks(A, F, **kw, **THREADS)
    assert par == ser
    return par


@pytest.mark.parametrize(
    ("method", "opts"),
    [
        ("blocks", {"block": 6}),  # 4 blocks, the last one short; OI chain
        ("blocks", {"block": 6, "basis": "exact"}),
        ("blocks", {"block": 8, "n_iter": 5, "anchors": 0.05}),
        ("pca", {}),
        ("pca-q", {}),
        ("pca-qs", {}),
        ("pca-qp", {"step": 5e-4}),
    ],
)
def test_fixed_step_equals_serial_and_decodes(anim, method, opts):
    A, F = anim
    data = _same_as_serial(A, F, method=method, **opts)
    R, F2 = compress.decode_animation(data)
    assert R.shape == A.shape and np.array_equal(F2, F)
    assert kg_error(R, A) < 5.0
    d = compress.info_animation(data)
    expect = -(-A.shape[0] // opts["block"]) if method == "blocks" else 1
    assert d["n_blocks"] == expect and d["frame_index"]


def test_oi_chain_matters(anim):
    """The OI warm start changes the bytes: every block coded with its own exact basis differs, so
    the chain that carries the previous block's basis is what makes the Dask file the serial one."""
    A, F = anim
    oi = compress.encode_animation(A, F, method="blocks", block=5, n_iter=1)
    exact = compress.encode_animation(A, F, method="blocks", block=5, basis="exact")
    assert oi != exact
    assert distributed.encode_animation_blocks(A, F, block=5, n_iter=1, **THREADS) == oi


@pytest.mark.parametrize(
    ("method", "target"),
    [("blocks", {"bpvf": 3.0}), ("pca", {"bpvf": 5.0}), ("pca-q", {"error": 1.0})],
)
def test_rate_control_equals_serial(anim, method, target):
    A, F = anim
    opts = {"block": 6} if method == "blocks" else {}
    data = _same_as_serial(A, F, method=method, **target, **opts)
    if "bpvf" in target:
        assert abs(compress.info_animation(data)["bpvf"] / target["bpvf"] - 1) <= 0.05
    else:
        assert abs(kg_error(compress.decode_animation(data)[0], A) / target["error"] - 1) <= 0.05


def test_worker_processes_and_atomic_file(anim, tmp_path):
    """Frames and L pickled to two worker processes: still the serial bytes, written to ``path``."""
    A, F = anim
    ser = compress.encode_animation(A, F, method="blocks", block=6)
    out = tmp_path / "a.sga"
    data = distributed.encode_animation_blocks(
        MeshAnimation(A, F), F, out, block=6, workers=2, progress=False
    )
    assert data == ser and out.read_bytes() == ser
    assert [p.name for p in tmp_path.iterdir()] == ["a.sga"]  # no temporary left


def test_real_animation_equals_serial(shared_data):
    path = shared_file(shared_data, "animations", "horse-gallop.npz")
    a = io.read_animation(path)
    A, F = a.frames[:20], a.faces
    data = _same_as_serial(A, F, method="blocks", block=8)
    assert compress.decode_animation(data)[0].shape == A.shape


def test_refusals(anim, tmp_path):
    A, F = anim
    with pytest.raises(InvalidInputError, match="'layered' cannot be split into frame blocks"):
        distributed.encode_animation_blocks(A, F, tmp_path / "x.sga", method="layered", **THREADS)
    with pytest.raises(InvalidInputError, match="`method` must be one of"):
        distributed.encode_animation_blocks(A, F, method="gft", **THREADS)
    with pytest.raises(InvalidInputError, match="at most one of `bpvf` and `error`"):
        distributed.encode_animation_blocks(A, F, bpvf=2.0, error=1.0, **THREADS)
    with pytest.raises(InvalidInputError, match="`bpvf` must be a positive number"):
        distributed.encode_animation_blocks(A, F, bpvf=-1.0, **THREADS)
    with pytest.raises(InvalidInputError, match="`step` cannot be combined"):
        distributed.encode_animation_blocks(A, F, step=1e-3, bpvf=2.0, **THREADS)
    with pytest.raises(InvalidInputError, match="`step` must be in"):
        distributed.encode_animation_blocks(A, F, step=10.0, **THREADS)
    with pytest.raises(InvalidInputError, match="kept-coefficient count"):
        distributed.encode_animation_blocks(A, F, method="pca", step=0, **THREADS)
    with pytest.raises(InvalidInputError, match="unknown option"):
        distributed.encode_animation_blocks(A, F, layer=0.1, **THREADS)
    with pytest.raises(InvalidInputError, match="`block` must be an integer"):
        distributed.encode_animation_blocks(A, F, block=1, **THREADS)
    with pytest.raises(InvalidInputError, match="`F` must"):
        distributed.encode_animation_blocks(A, F[:, :2], **THREADS)
    with pytest.raises(InvalidInputError, match="`path`: the folder of"):
        distributed.encode_animation_blocks(A, F, tmp_path / "no" / "a.sga", **THREADS)
    assert not list(tmp_path.iterdir())
