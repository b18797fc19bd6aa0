"""spectrageo.compress: .sgc round trips, rate control, progressive prefixes, hostile input, CLI."""

from __future__ import annotations

import json
import struct
import zlib

import numpy as np
import pytest

from spectrageo import InvalidInputError, compress, datasets, io, metrics
from spectrageo.cli.main import main
from spectrageo.compress import _container

from conftest import grid, icosphere


def _rms(V, W):
    diag = np.linalg.norm(V.max(0) - V.min(0))
    return float(np.sqrt(np.mean(np.sum((V - W) ** 2, axis=1))) / diag)


@pytest.fixture(scope="module")
def fandisk():
    m = datasets.fandisk()
    return m.vertices, m.faces


@pytest.fixture(scope="module")
def fandisk_sgc(fandisk):
    V, F = fandisk
    return compress.encode(V, F)


# ----------------------------------------------------------------------------- round trips
@pytest.mark.parametrize("method", compress.METHODS)
def test_round_trip_keeps_order_and_connectivity(method):
    V, F = icosphere(3)
    rng = np.random.default_rng(0)
    perm = rng.permutation(V.shape[0])  # a scrambled order must survive too
    inv = np.empty_like(perm)
    inv[perm] = np.arange(perm.size)
    V, F = V[perm], inv[F][rng.permutation(F.shape[0])]
    data = compress.encode(V, F, method=method, step=1e-4)
    V2, F2 = compress.decode(data)
    assert F2.dtype == np.int64 and np.array_equal(F2, F)
    assert V2.shape == V.shape
    # vertex i decodes near vertex i (order kept)
    assert _rms(V, V2) < 0.01
    d = compress.info(data)
    assert d["method"] == method and d["n_vertices"] == V.shape[0] and not d["reordered"]


def test_fandisk_round_trip_exact_faces(fandisk, fandisk_sgc):
    V, F = fandisk
    V2, F2 = compress.decode(fandisk_sgc)
    assert np.array_equal(F2, F)
    assert _rms(V, V2) < 1e-3
    # same bytes decode to the same mesh (the decoder is deterministic)
    V3, _ = compress.decode(fandisk_sgc)
    assert np.array_equal(V2, V3)


def test_reorder_is_reported_and_same_surface(fandisk):
    V, F = fandisk
    data = compress.encode(V, F, reorder=True, step=1e-4)
    assert compress.info(data)["reordered"] is True
    V2, F2 = compress.decode(data)
    assert F2.shape == F.shape and V2.shape == V.shape
    # same faces up to renumbering: match vertices by position
    from scipy.spatial import cKDTree

    d, idx = cKDTree(V).query(V2)
    assert d.max() < 1e-3 * np.linalg.norm(np.ptp(V, axis=0))
    a = np.sort(np.sort(idx[F2], axis=1), axis=0)
    b = np.sort(np.sort(F, axis=1), axis=0)
    assert np.array_equal(np.unique(a, axis=0), np.unique(b, axis=0))


def test_unreferenced_vertices_and_tiny_meshes():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 5.0]])
    F = np.array([[0, 1, 2]])
    for method in ("spectral", "feature"):
        V2, F2 = compress.decode(compress.encode(V, F, method=method, step=1e-5))
        assert np.array_equal(F2, F)
        assert np.abs(V2 - V).max() < 1e-3


def test_flat_and_degenerate_geometry():
    V, F = grid(6, 6)  # z = 0 everywhere
    V2, F2 = compress.decode(compress.encode(V, F, step=1e-5))
    assert np.array_equal(F2, F) and np.abs(V2 - V).max() < 1e-3
    Vp = np.zeros_like(V)  # all vertices at one point: zero bounding box
    V3, _ = compress.decode(compress.encode(Vp, F))
    assert np.allclose(V3, 0.0)


# ----------------------------------------------------------------------------- rate
def test_error_decreases_with_rate(fandisk):
    V, F = fandisk
    sizes, errs = [], []
    for step in (3e-3, 1e-3, 3e-4, 1e-4):
        data = compress.encode(V, F, step=step)
        sizes.append(len(data))
        errs.append(_rms(V, compress.decode(data)[0]))
    assert np.all(np.diff(sizes) > 0)
    assert np.all(np.diff(errs) < 0)


@pytest.mark.parametrize("bpv", [12.0, 20.0])
def test_rate_control_bpv_within_5_percent(fandisk, bpv):
    V, F = fandisk
    data = compress.encode(V, F, bpv=bpv)
    got = 8 * len(data) / V.shape[0]
    assert abs(got - bpv) <= 0.05 * bpv
    assert compress.info(data)["bpv"] == pytest.approx(got)


@pytest.mark.parametrize(
    "method,error", [("spectral", 1e-3), ("spectral", 2e-4), ("feature", 2e-3)]
)
def test_rate_control_error_within_5_percent(fandisk, method, error):
    V, F = fandisk
    V2, _ = compress.decode(compress.encode(V, F, method=method, error=error))
    assert abs(_rms(V, V2) - error) <= 0.05 * error


def test_rate_control_on_shared_mesh(shared_data):
    m = io.read_mesh(shared_data / "cad" / "partLp.obj")
    V, F = m.vertices, m.faces
    data = compress.encode(V, F, error=5e-4)
    V2, F2 = compress.decode(data)
    assert np.array_equal(F2, F)
    assert abs(_rms(V, V2) - 5e-4) <= 0.05 * 5e-4
    data = compress.encode(V, F, bpv=1.3 * compress.info(data)["connectivity_bpv"] + 8)
    assert abs(8 * len(data) / V.shape[0] - (1.3 * compress.info(data)["connectivity_bpv"] + 8)) < (
        0.05 * (1.3 * compress.info(data)["connectivity_bpv"] + 8)
    )


def test_unreachable_rate_is_a_clear_error(fandisk):
    V, F = fandisk
    with pytest.raises(InvalidInputError, match="connectivity and header alone"):
        compress.encode(V, F, bpv=1.0)
    with pytest.raises(InvalidInputError, match="below what method"):
        compress.encode(V, F, error=1e-3, k=20)


def test_feature_mask_beats_zero_deltas(fandisk):
    """Algorithm 9: sending the feature deltas improves on anchors alone (Eq. 5.53)."""
    V, F = fandisk
    a = compress.decode(compress.encode(V, F, method="feature", step=1e-3, ratio=0.0))[0]
    b = compress.decode(compress.encode(V, F, method="feature", step=1e-3))[0]
    assert _rms(V, b) < _rms(V, a)


@pytest.mark.parametrize("method", ["feature", "saliency"])
def test_delta_codecs_factorise_only_for_rate_control(monkeypatch, method):
    """The normal equations of Eq. (5.54) are factorised only when the encoder reconstructs
    (rate control), and then once for all the levels of detail it tries; a file coded at a given
    step decodes to the same mesh as before."""
    from spectrageo.compress import _feature

    V, F = icosphere(3)
    V = V + 0.01 * np.random.default_rng(1).standard_normal(V.shape)
    before = compress.encode(V, F, method=method)
    made = []
    real = _feature._Solver

    def counting(*a, **k):
        made.append(1)
        return real(*a, **k)

    monkeypatch.setattr(_feature, "_Solver", counting)
    data = compress.encode(V, F, method=method)
    assert made == [] and data == before
    W = compress.decode(data)[0]
    assert len(made) == 1 and _rms(V, W) < 0.05
    made.clear()
    compress.encode(V, F, method=method, error=2 * _rms(V, W))
    assert len(made) == 1


@pytest.mark.parametrize("method", ["feature", "saliency"])
def test_files_with_the_first_anchor_scheme_decode_as_before(method):
    """Files coded before the anchor-scheme byte existed (METIS, one part per anchor) keep
    decoding to what they decoded to then, up to rounding; new files record scheme 1 and
    round trip."""
    from pathlib import Path

    here = Path(__file__).parent / "data" / "sgc"
    old = (here / f"{method}_anchors_v0.sgc").read_bytes()
    want = np.load(here / f"{method}_anchors_v0_decoded.npy")
    info = compress.info(old)
    assert info["parameters"]["anchor_scheme"] == 0
    # The golden arrays were decoded by SuperLU and BLAS; the decoder now solves Eq. (5.54)
    # with the fixed-order Cholesky. Both solve the same system, exact up to rounding, so the
    # coordinates differ by rounding noise amplified by the conditioning of L^T L (about 1e-9
    # of the step here), whereas a change in what is decoded (anchors, mask, dequantisation)
    # moves them by the order of the quantisation step (a fraction of the bounding-box
    # diagonal). A millionth of the step tells the two apart.
    diag = float(np.linalg.norm(want.max(axis=0) - want.min(axis=0)))
    atol = 1e-6 * info["parameters"]["step"] * diag
    np.testing.assert_allclose(compress.decode(old)[0], want, rtol=0, atol=atol)
    V, F = icosphere(3)
    V = V + 0.01 * np.random.default_rng(1).standard_normal(V.shape)  # the fixtures' mesh
    new = compress.encode(V, F, method=method)
    assert compress.info(new)["parameters"]["anchor_scheme"] == 1
    W, F2 = compress.decode(new)
    np.testing.assert_array_equal(F2, F)
    assert _rms(V, W) < 2 * _rms(V, want) + 1e-4


def test_anchor_scheme_1_spreads_anchors_over_every_component():
    """Scheme 1: about ``fraction * n`` anchors, deterministic, one in every connected
    component, and no vertex far (in hops) from an anchor on a regular grid."""
    from scipy.sparse.csgraph import shortest_path

    from spectrageo.compress._feature import anchors
    from spectrageo.graph import adjacency_matrix

    V, F = grid(40)
    V2, F2 = icosphere(2)
    Vb = np.r_[V, V2 + 5.0]
    Fb = np.r_[F, F2 + V.shape[0]]
    n = Vb.shape[0]
    for frac in (0.005, 0.05, 0.3):
        a = anchors(Fb, n, frac, 0, 1)
        np.testing.assert_array_equal(a, anchors(Fb, n, frac, 0, 1))
        assert abs(a.size - frac * n) <= 0.1 * frac * n + 2
        assert (a < V.shape[0]).any() and (a >= V.shape[0]).any()  # both components
    a = anchors(F, V.shape[0], 0.05, 0, 1)
    C = adjacency_matrix(F, V.shape[0])
    hops = shortest_path(C, unweighted=True, indices=a).min(axis=0)
    # 80 anchors on a 40 x 40 grid: one per 20 vertices, a disc of radius ~3 hops each
    assert hops.max() <= 8
    assert anchors(F, V.shape[0], 1.0, 0, 1).size == V.shape[0]


def test_farthest_point_anchors_on_a_path_and_across_components():
    """Scheme 1 is farthest-point sampling in hops from one seed per component: on a path
    0-1-...-8 seeded at 0 the next anchors are 8, then 4; with a second path seeded at 9 the
    two ends tie at 8 hops and the smaller index goes first."""
    from spectrageo.compress._feature import _farthest_points
    from spectrageo.graph import adjacency_matrix

    i64 = np.int64
    path = np.array([[i, i + 1, i + 1] for i in range(8)])  # degenerate faces = the path's edges
    C = adjacency_matrix(path, 9).tocsr()
    out = np.empty(2, i64)
    k = _farthest_points(C.indptr.astype(i64), C.indices.astype(i64), np.array([0], i64), 2, out)
    np.testing.assert_array_equal(out[:k], [8, 4])
    C = adjacency_matrix(np.r_[path, path + 9], 18).tocsr()
    out = np.empty(3, i64)
    seeds = np.array([0, 9], i64)
    k = _farthest_points(C.indptr.astype(i64), C.indices.astype(i64), seeds, 3, out)
    np.testing.assert_array_equal(out[:k], [8, 17, 4])


def test_unused_vertices_do_not_take_the_surface_anchors():
    """Scans hold many unused vertices and tiny pieces (the Stanford bunny: 1113 of its 1114
    components are single vertices). Each needs an anchor of its own; the surface keeps its
    share of ``fraction * n`` and the codec's error on it stays what it is without them."""
    from spectrageo.compress._feature import anchors

    V, F = icosphere(3)
    V = V + 0.01 * np.random.default_rng(3).standard_normal(V.shape)
    n0 = V.shape[0]
    extra = np.random.default_rng(4).random((300, 3))
    Vx = np.r_[V, extra]
    a = anchors(F, Vx.shape[0], 0.05, 0, 1)
    assert (a < n0).sum() >= int(round(0.05 * Vx.shape[0] * n0 / Vx.shape[0])) - 1
    assert (a >= n0).sum() == 300
    plain = compress.decode(compress.encode(V, F, method="feature"))[0]
    mixed = compress.decode(compress.encode(Vx, F, method="feature"))[0]
    assert _rms(V, mixed[:n0]) <= 1.5 * _rms(V, plain) + 1e-5


def test_feature_parameters_from_a_newer_anchor_scheme_are_refused():
    from spectrageo.compress import _feature

    V, F = icosphere(2)
    data = compress.encode(V, F, method="feature")
    p = _feature._P1.pack(0.01, 4.0, 4e-4, 0, 7)
    with pytest.raises(InvalidInputError, match="anchor scheme 7"):
        _feature._unpack(p)
    with pytest.raises(InvalidInputError, match="parameters expected"):
        _feature._unpack(p[:-2])
    assert compress.decode(data)[0].shape == V.shape


def test_feature_rate_control_chooses_the_level_of_detail(fandisk):
    """Algorithm 9 step 5 under ``bpv=``: at a few geometry bits per vertex, sending the salient
    deltas and zeroing the rest (Eq. 5.53) beats quantising every delta coarsely; at a high rate
    the codec sends every delta, i.e. it falls back to uniform quantisation."""
    V, F = fandisk
    uni = {"feature_fraction": 1.0, "ratio": 1.0}
    conn = compress.info(compress.encode(V, F, method="feature", step=1.0, **uni))[
        "connectivity_bpv"
    ]
    low = conn + 3.0
    a = compress.encode(V, F, method="feature", bpv=low)
    b = compress.encode(V, F, method="feature", bpv=low, **uni)
    for d in (a, b):
        assert abs(8 * len(d) / V.shape[0] - low) <= 0.05 * low
    share = compress.info(a)["parameters"]["sent_share"]
    assert 0.05 < share < 1.0
    assert compress.info(b)["parameters"]["sent_share"] == 1.0
    Va, Vb = compress.decode(a)[0], compress.decode(b)[0]
    assert _rms(V, Va) < 0.9 * _rms(V, Vb)
    assert metrics.theta_deg(Va, V, F) < 0.9 * metrics.theta_deg(Vb, V, F)
    high = conn + 16.0
    c = compress.encode(V, F, method="feature", bpv=high)
    assert compress.info(c)["parameters"]["sent_share"] == 1.0
    assert c == compress.encode(V, F, method="feature", bpv=high, **uni)
    # an explicit level is kept as given
    d = compress.encode(V, F, method="feature", bpv=low, feature_fraction=0.2, ratio=0.0)
    assert abs(compress.info(d)["parameters"]["sent_share"] - 0.2) < 1e-3


# ----------------------------------------------------------------------------- progressive
def test_prefix_decodes_to_coarser_level(fandisk, fandisk_sgc):
    V, F = fandisk
    data = fandisk_sgc
    c = _container.parse(data)
    assert len(c.chunks) == 4  # connectivity + 3 frequency layers
    errs = []
    # cut right after the k-th chunk
    ends = [r.end for r in _container.layout(data)[2]]
    for end in ends[1:]:
        V2, F2 = compress.decode(data[:end], partial=True)
        assert np.array_equal(F2, F)
        errs.append(_rms(V, V2))
    assert errs[0] > errs[1] > errs[2]
    with pytest.raises(InvalidInputError, match="truncated"):
        compress.decode(data[: ends[1]])


# ----------------------------------------------------------------------------- hostile input
def test_truncated_and_corrupted_streams(fandisk_sgc):
    data = fandisk_sgc
    for cut in (0, 3, 10, 40, 60, len(data) // 2, len(data) - 1):
        with pytest.raises(InvalidInputError):
            compress.decode(data[:cut])
    rng = np.random.default_rng(1)
    for _ in range(40):
        b = bytearray(data)
        i = int(rng.integers(0, len(b)))
        b[i] ^= 1 << int(rng.integers(0, 8))
        with pytest.raises(InvalidInputError):
            compress.decode(bytes(b))
    with pytest.raises(InvalidInputError, match="trailing"):
        compress.decode(data + b"\0")


def test_foreign_and_wrong_version():
    with pytest.raises(InvalidInputError, match="magic"):
        compress.decode(b"ply\nformat binary_little_endian 1.0\n")
    with pytest.raises(InvalidInputError, match="bytes"):
        compress.decode("SGC")
    V, F = icosphere(1)
    data = bytearray(compress.encode(V, F))
    data[4] = 99
    (plen,) = struct.unpack_from("<H", data, 48)
    end = 50 + plen
    data[end : end + 4] = struct.pack("<I", zlib.crc32(bytes(data[:end])))
    with pytest.raises(InvalidInputError, match="version 99"):
        compress.decode(bytes(data))


def test_fuzz_decoder_never_crashes():
    """Random payloads behind a valid header and checksums: only InvalidInputError."""
    V, F = icosphere(2)
    for method in compress.METHODS:
        c = _container.parse(compress.encode(V, F, method=method))
        rng = np.random.default_rng(2)
        for _ in range(25):
            j = int(rng.integers(0, len(c.chunks)))
            chunks = list(c.chunks)
            tag, payload = chunks[j]
            junk = rng.integers(0, 256, size=int(rng.integers(0, 2 * len(payload) + 8)))
            chunks[j] = (tag, bytes(junk.astype(np.uint8)))
            c2 = _container.Container(
                c.method, c.n_vertices, c.n_faces, c.origin, c.scale, c.params, False, chunks
            )
            try:
                V2, F2 = compress.decode(c2.to_bytes())
            except InvalidInputError:
                continue
            assert np.isfinite(V2).all() and F2.min() >= 0 and F2.max() < c.n_vertices


def test_bad_arguments():
    V, F = icosphere(1)
    with pytest.raises(InvalidInputError, match="method"):
        compress.encode(V, F, method="draco")
    with pytest.raises(InvalidInputError, match="at most one"):
        compress.encode(V, F, bpv=10, error=0.01)
    with pytest.raises(InvalidInputError, match="`bpv` must be a positive"):
        compress.encode(V, F, bpv=-1)
    with pytest.raises(InvalidInputError, match="`error` must be a positive"):
        compress.encode(V, F, error=float("nan"))
    with pytest.raises(InvalidInputError, match="unknown option"):
        compress.encode(V, F, submeshes=3)
    with pytest.raises(InvalidInputError, match="`k` must be at most"):
        compress.encode(V, F, k=400, submesh_size=300)
    with pytest.raises(InvalidInputError, match="`F` is empty"):
        compress.encode(V, np.zeros((0, 3), int))
    with pytest.raises(InvalidInputError, match="`V` is empty"):
        compress.encode(np.zeros((0, 3)), F)
    with pytest.raises(InvalidInputError, match="NaN"):
        compress.encode(np.full_like(V, np.nan), F)
    with pytest.raises(InvalidInputError, match="out of range"):
        compress.encode(V, F + V.shape[0])


# ----------------------------------------------------------------------------- CLI
def test_cli_round_trip(tmp_path, capsys):
    src = datasets.fandisk_path()
    out = tmp_path / "f.sgc"
    assert main(["compress", str(src), str(out), "--bpv", "16"]) == 0
    err = capsys.readouterr().err
    # the default method "auto" keeps predictive here (the smaller RMS error at 16 bpv)
    assert "order kept" in err and "predictive (chosen by auto)" in err
    assert main(["info", str(out), "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["method"] == "predictive" and d["n_vertices"] == 6475
    assert abs(d["bpv"] - 16) <= 0.8
    ply = tmp_path / "f.ply"
    assert main(["decompress", str(out), str(ply)]) == 0
    m, ref = io.read_mesh(ply), datasets.fandisk()
    assert np.array_equal(m.faces, ref.faces)
    assert _rms(ref.vertices, m.vertices) < 2e-3
    # --reorder says so
    assert main(["compress", str(src), str(tmp_path / "r.sgc"), "--reorder", "-q"]) == 0
    assert main(["info", str(tmp_path / "r.sgc"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["reordered"] is True
    # the feature codec says which level of detail its rate control chose
    assert main(["compress", str(src), str(tmp_path / "h.sgc"), "--method", "feature"]
                + ["--bpv", "6"]) == 0  # fmt: skip
    err = capsys.readouterr().err
    assert "feature (deltas of" in err and "% of the vertices sent)" in err
    assert main(["info", str(tmp_path / "h.sgc"), "--json"]) == 0
    assert 0 < json.loads(capsys.readouterr().out)["parameters"]["sent_share"] < 1


def test_cli_errors(tmp_path, capsys):
    bad = tmp_path / "bad.sgc"
    bad.write_bytes(b"SGC\x1a" + b"\0" * 20)
    assert main(["decompress", str(bad), str(tmp_path / "x.ply")]) == 2
    assert "truncated" in capsys.readouterr().err
    assert not (tmp_path / "x.ply").exists()
    src = datasets.fandisk_path()
    assert main(["compress", str(src), str(tmp_path / "f.bin")]) == 2
    assert ".sgc" in capsys.readouterr().err
    assert main(["compress", str(src), str(tmp_path / "f.sgc"), "--bpv", "1"]) == 2
    assert "cannot be reached" in capsys.readouterr().err
    assert not (tmp_path / "f.sgc").exists()


def test_saliency_rate_control_scales_the_class_shares(fandisk):
    """Algorithm 10 under ``bpv=``: the share of deltas sent follows the rate (the per-class
    ratios scaled to it), and a high rate is no longer held at the fixed shares' error floor."""
    V, F = fandisk
    fixed = {"class_keep": [0.1, 0.4, 0.7, 1.0]}
    shares, errs = [], []
    for bpv in (6.0, 20.0):
        a = compress.encode(V, F, method="saliency", bpv=bpv)
        b = compress.encode(V, F, method="saliency", bpv=bpv, **fixed)
        assert abs(8 * len(a) / V.shape[0] - bpv) <= 0.05 * bpv
        shares.append(compress.info(a)["parameters"]["sent_share"])
        errs.append((_rms(V, compress.decode(a)[0]), _rms(V, compress.decode(b)[0])))
        assert abs(compress.info(b)["parameters"]["sent_share"] - 0.55) < 0.01
    assert shares[0] < shares[1]
    assert errs[0][0] < errs[0][1] and errs[1][0] < 0.5 * errs[1][1]


def test_entropy_groups_round_trip_at_the_shift_boundaries():
    """Large magnitudes are split into a Laplace-coded high part and raw low bits; a negative
    value's arithmetic shift floors (-32767 >> 3 == -4096), which once made the encoder write a
    high part the decoder refuses. Every magnitude up to the coder's limit must round-trip."""
    from spectrageo.compress._entropy import MAX_ABS, decode_groups, encode_groups

    rng = np.random.default_rng(0)
    for R in (1, 4095, 4096, 8191, 32767, 32768, 2**20 - 1, 2**33 + 5, MAX_ABS):
        vals = np.r_[-R, R, -R + 1, rng.integers(-R, R + 1, 200)].astype(np.int64)
        groups = np.arange(vals.size) % 3
        out = decode_groups(encode_groups(vals, groups, 3), groups, 3, "test")
        assert np.array_equal(out, vals), R


def test_entropy_groups_round_trip_when_the_coder_seals_into_no_words():
    """constriction seals a coder state that holds little information into an empty word list
    (one symbol -4 of a Laplace model of scale 4); the decoder once took that for missing data
    and refused a file the encoder had just written (a one-vertex layer of the layered codec,
    anchor trajectories of pca-q at a low rate)."""
    from spectrageo.compress._entropy import decode_groups, encode_groups

    rng = np.random.default_rng(1)
    cases = [np.array([0, 0, -4])] + [rng.integers(-6, 7, rng.integers(1, 4)) for _ in range(400)]
    empty = 0
    for vals in cases:
        vals = vals.astype(np.int64)
        groups = np.arange(vals.size) % 3
        data = encode_groups(vals, groups, 3)
        empty += len(data) == 12  # three group heads and no coder words
        assert np.array_equal(decode_groups(data, groups, 3, "test"), vals), vals
    assert empty >= 1


def test_info_on_a_damaged_sgc_speaks_of_a_mesh_file(tmp_path, capsys):
    """`info` tries the mesh header, then the animation one; a file that is neither was
    reported with the animation reader's message (".sga data ...")."""
    for data in (b"", b"garbage bytes, not a bitstream" * 4):
        bad = tmp_path / "bad.sgc"
        bad.write_bytes(data)
        assert main(["info", str(bad)]) == 2
        err = capsys.readouterr().err
        assert ".sgc" in err and ".sga" not in err, err
