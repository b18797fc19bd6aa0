"""Viewer server and its JSON/binary API, without a browser (see test_viewer_e2e.py for Chromium)."""

from __future__ import annotations

import json
import time
import urllib.error
import urllib.request

import numpy as np
import pytest

from spectrageo import io, metrics
from spectrageo._colormap import jet
from spectrageo._errors import InvalidInputError
from spectrageo.geometry import Mesh, MeshAnimation, PointCloud, mean_curvature
from spectrageo.geometry.features import classify_vertices
from spectrageo.viewer import ViewerServer, ViewerSession, _analysis, colorbar
from spectrageo.viewer._session import _as_int

from conftest import cube, grid


# --------------------------------------------------------------------------- helpers
@pytest.fixture(scope="module")
def server(tmp_path_factory):
    d = tmp_path_factory.mktemp("viewer")
    V, F = cube(3)
    io.write(d / "cube.ply", Mesh(V, F))
    rng = np.random.default_rng(0)
    frames = np.stack([V * (1 + 0.1 * t) for t in range(4)])
    io.write(d / "anim.npz", MeshAnimation(frames, F))
    noisy = V + 0.01 * rng.standard_normal(V.shape)
    io.write(d / "noisy.ply", Mesh(noisy, F))
    srv = ViewerServer([d / "cube.ply", d / "anim.npz", d / "noisy.ply"], port=0).start()
    srv.files = {"V": V, "F": F, "frames": frames, "noisy": noisy, "dir": d}
    yield srv
    srv.stop()


def _get(srv, path):
    req = urllib.request.Request(srv.url + path, headers=srv.api_headers)
    with urllib.request.urlopen(req, timeout=30) as r:
        return r.read(), dict(r.headers)


def _json(srv, path, body=None, data=None):
    if body is not None:
        data = json.dumps(body).encode()
    req = urllib.request.Request(
        srv.url + path, data=data, method="POST" if data else "GET", headers=srv.api_headers
    )
    try:
        with urllib.request.urlopen(req, timeout=60) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read())


def _wait(srv, job_id, timeout=60):
    t0 = time.time()
    while time.time() - t0 < timeout:
        _, j = _json(srv, f"api/job/{job_id}")
        if j["state"] != "running":
            return j
        time.sleep(0.02)
    raise AssertionError("job did not finish")


def _run(srv, path, body):
    status, r = _json(srv, path, body)
    assert status == 200, r
    return _wait(srv, r["job"])


# --------------------------------------------------------------------------- analysis
def _lib_mask(V, F, patch):
    """Feature vertices straight from the library (Section 6.1.1, else Section 4.4)."""
    from spectrageo import saliency

    if hasattr(saliency, "feature_vertices"):
        return saliency.feature_vertices(V, F, patch=patch).mask
    return classify_vertices(V, F, patch=patch).is_feature


def test_feature_vertices_match_library():
    V, F = cube(4)
    mask, method = _analysis.feature_vertices(V, F, patch=15)
    assert "Eq. 4.14" in method or "Section 6.1.1" in method
    np.testing.assert_array_equal(mask, _lib_mask(V, F, 15))
    # the cube's 8 corners are features; a flat face centre is not
    corners = np.flatnonzero(np.all(np.isclose(np.abs(V), 1.0), axis=1))
    assert len(corners) == 8 and mask[corners].all()
    centre = np.argmin(np.linalg.norm(V - [0, 0, 1], axis=1))
    assert not mask[centre]


def test_feature_vertices_point_cloud_uses_normals():
    V, F = cube(4)
    from spectrageo.geometry import vertex_normals

    N = vertex_normals(V, F, weighting="area")
    mask, _ = _analysis.feature_vertices(V, None, patch=15, normals=N)
    ref = classify_vertices(V, None, patch=15, normals=N).is_feature
    np.testing.assert_array_equal(mask, ref)


def test_feature_curves_fallback_clusters_curvature():
    V, F = cube(4)
    mask = classify_vertices(V, F, patch=15).is_feature
    lab = _analysis._curves_fallback(V, F, mask)
    assert lab.shape == (len(V),)
    assert (lab[~mask] == -1).all() and (lab[mask] >= 0).all()
    k = lab.max() + 1
    assert 2 <= k <= 5
    # clusters are ordered by curvature: mean curvature of each cluster increases with its label
    mc = mean_curvature(V, F)
    means = [mc[lab == c].mean() for c in range(k)]
    assert np.all(np.diff(means) > 0)
    # no feature vertices -> all -1
    assert (_analysis._curves_fallback(V, F, np.zeros(len(V), bool)) == -1).all()
    # point clouds always use the fallback
    np.testing.assert_array_equal(
        _analysis.feature_curves(V, None, mask), _analysis._curves_fallback(V, None, mask)
    )


def test_feature_curves_mesh_match_library():
    from spectrageo import saliency

    V, F = cube(4)
    mask, _ = _analysis.feature_vertices(V, F, patch=15)
    lab = _analysis.feature_curves(V, F, mask, patch=15)
    ref = saliency.feature_curves(V, F, patch=15)
    np.testing.assert_array_equal(lab, ref.labels)
    np.testing.assert_array_equal(lab >= 0, mask)  # curves cover exactly the feature vertices


def test_curvature_point_cloud_surface_variation():
    V, F = grid(12, 12)
    sv = _analysis.curvature(V, None)
    np.testing.assert_allclose(sv, 0.0, atol=1e-12)  # a plane has no variation
    Vs, Fs = cube(4)
    assert _analysis.curvature(Vs, None).max() > 0.05  # corners of the cube do


def test_vertex_field_per_face_mean_and_errors():
    V, F = grid(3, 3)
    vals = np.arange(len(F), dtype=float)
    out = _analysis.vertex_field(vals, len(V), F)
    for i in range(len(V)):
        inc = np.flatnonzero((F == i).any(axis=1))
        assert out[i] == pytest.approx(vals[inc].mean())
    np.testing.assert_array_equal(_analysis.vertex_field(np.ones(len(V)), len(V), F), 1.0)
    with pytest.raises(InvalidInputError, match="expected one per vertex"):
        _analysis.vertex_field(np.ones(5), len(V), F)


def test_colorbar_is_jet_64():
    cb = np.array(colorbar())
    assert cb.shape == (64, 3)
    np.testing.assert_array_equal(cb, jet(np.arange(64), n_classes=64, vmin=0, vmax=63))
    assert tuple(cb[0]) == (0, 0, 128) and tuple(cb[-1]) == (128, 0, 0)
    assert len({tuple(c) for c in cb}) == 64


def test_as_int_validation():
    assert _as_int("15", "patch", 3) == 15
    with pytest.raises(InvalidInputError, match="`patch` must be an integer"):
        _as_int("abc", "patch", 3)
    with pytest.raises(InvalidInputError, match="`patch` must be an integer"):
        _as_int(2.5, "patch", 3)
    with pytest.raises(InvalidInputError, match="`patch` must be an integer"):
        _as_int(True, "patch", 3)
    with pytest.raises(InvalidInputError, match="`patch` must be >= 3"):
        _as_int(2, "patch", 3)


# --------------------------------------------------------------------------- session
def test_session_errors():
    s = ViewerSession()
    with pytest.raises(InvalidInputError, match="unknown model"):
        s.get("m9")
    with pytest.raises(InvalidInputError, match="unknown job"):
        s.job("nope")
    with pytest.raises(InvalidInputError, match="could not read broken.ply"):
        s.load_bytes(b"ply\nformat nonsense 9\nend_header\n\x00\x01", "broken.ply")
    with pytest.raises(InvalidInputError, match=r"could not read x\.xyz2"):
        s.load_bytes(b"1 2 3\n", "x.xyz2")
    V, F = cube(2)
    m = s.add(Mesh(V, F), "c.ply")
    with pytest.raises(InvalidInputError, match=r"`frame` must be in \[0, 0\]"):
        m.geometry(3)
    with pytest.raises(InvalidInputError, match="`frame` must be an integer"):
        m.geometry("x")
    with pytest.raises(InvalidInputError, match="unknown scalar field"):
        s.scalar(m, "nope", 0)
    with pytest.raises(InvalidInputError, match="unknown attribute"):
        s.scalar(m, "attr:nope", 0)
    with pytest.raises(InvalidInputError, match="unknown face attribute"):
        s.scalar(m, "face:nope", 0)
    with pytest.raises(InvalidInputError, match="unknown field"):
        s.scalar(m, "field:nope", 0)
    with pytest.raises(InvalidInputError, match="cannot write a mesh as .xyz9"):
        s.download(m, "xyz9")
    with pytest.raises(InvalidInputError, match="could not read scalar file"):
        s.attach_field(m, b"1 2 x", "f.txt")
    with pytest.raises(InvalidInputError, match="expected one per vertex"):
        s.attach_field(m, b"1 2 3", "f.txt")
    pc = s.add(PointCloud(V), "p.xyz")
    with pytest.raises(InvalidInputError, match="saliency needs a mesh"):
        s.scalar(pc, "saliency", 0)
    with pytest.raises(InvalidInputError, match="denoising needs a mesh"):
        s.denoise(pc, "laplacian", _Job())
    anim = s.add(MeshAnimation(np.stack([V, V]), F), "a.npz")
    with pytest.raises(InvalidInputError, match="outlier removal works on one point cloud"):
        s.outliers(anim, "rpca", 10, _Job())
    other = s.add(Mesh(*cube(3)), "big.ply")
    with pytest.raises(InvalidInputError, match="cannot compare"):
        s.compare(m, other, 0)
    F2 = F.copy()
    F2[0] = F2[0, [0, 2, 1]]
    m2 = s.add(Mesh(V, F2), "flipped.ply")
    with pytest.raises(InvalidInputError, match="different faces"):
        s.compare(m, m2, 0)


class _Job:
    def update(self, *a, **k):
        pass


def test_attach_field_text_and_npy():
    s = ViewerSession()
    V, F = cube(2)
    m = s.add(Mesh(V, F), "c.ply")
    name = s.attach_field(m, ",".join(map(str, range(len(V)))).encode(), "idx.csv")
    assert name == "field:idx.csv" and name in m.info()["fields"]
    r = s.scalar(m, name, 0)
    assert (r["vmin"], r["vmax"]) == (0.0, len(V) - 1)
    np.testing.assert_array_equal(m.arrays[r["colors"]], jet(np.arange(len(V)), n_classes=64))
    import io as _io

    buf = _io.BytesIO()
    np.save(buf, np.arange(len(F), dtype=float))
    name = s.attach_field(m, buf.getvalue(), "faces.npy")
    r = s.scalar(m, name, 0)
    np.testing.assert_allclose(
        m.arrays[r["values"]], _analysis.vertex_field(np.arange(len(F)), len(V), F), rtol=1e-6
    )


# --------------------------------------------------------------------------- HTTP
def test_state_and_binary_geometry(server):
    status, st = _json(server, "api/state")
    assert status == 200
    names = [m["name"] for m in st["models"]]
    assert names == ["cube.ply", "anim.npz", "noisy.ply"]
    cube_info = st["models"][0]
    V, F = server.files["V"], server.files["F"]
    assert (cube_info["n_vertices"], cube_info["n_faces"]) == (len(V), len(F))
    assert st["models"][1]["n_frames"] == 4 and st["models"][1]["kind"] == "animation"
    assert ".ply" in st["formats"]["read"]
    body, hdr = _get(server, "api/model/m1/positions")
    assert hdr["X-Dtype"] == "float32"
    np.testing.assert_allclose(np.frombuffer(body, "<f4").reshape(-1, 3), V, rtol=1e-6)
    body, hdr = _get(server, "api/model/m1/faces")
    np.testing.assert_array_equal(np.frombuffer(body, "<u4").reshape(-1, 3), F)
    body, _ = _get(server, "api/model/m2/positions?frame=3")
    np.testing.assert_allclose(
        np.frombuffer(body, "<f4").reshape(-1, 3), server.files["frames"][3], rtol=1e-6
    )
    html, hdr = _get(server, "")
    assert b"Mesh Information" in html and b"Show feature curves" in html
    js, hdr = _get(server, "static/vendor/three.module.js")
    assert hdr["Content-Type"] == "text/javascript" and b"REVISION" in js


def test_http_errors_keep_server_up(server):
    assert _json(server, "api/model/m9")[0] == 400
    assert _json(server, "api/nothing")[0] == 404
    assert _json(server, "static/../server.py")[0] == 404
    st, r = _json(server, "api/model/m2/positions?frame=99")
    assert st == 400 and "`frame` must be in [0, 3]" in r["error"]
    st, r = _json(server, "api/upload?name=broken.ply", data=b"ply\nformat ascii 1.0\nelement v")
    assert st == 400 and r["error"].startswith("could not read broken.ply")
    st, r = _json(server, "api/model/m1/features", data=b"{not json")
    assert st == 400 and "not JSON" in r["error"]
    st, r = _json(server, "api/model/m1/features", data=b"[1]")
    assert st == 400 and "JSON object" in r["error"]
    j = _run(server, "api/model/m1/features", {"patch": 2})
    assert j["state"] == "error" and "`patch` must be >= 3" in j["error"]
    # still serving
    assert _json(server, "api/state")[0] == 200
    # a foreign Host header is refused (DNS-rebinding guard)
    req = urllib.request.Request(server.url + "api/state", headers={"Host": "evil.example:80"})
    with pytest.raises(urllib.error.HTTPError) as ei:
        urllib.request.urlopen(req, timeout=10)
    assert ei.value.code == 403


def test_upload_and_features_change_with_patch(server, tmp_path):
    V, F = cube(4)
    io.write(tmp_path / "c4.off", Mesh(V, F))
    st, r = _json(server, "api/upload?name=c4.off", data=(tmp_path / "c4.off").read_bytes())
    assert st == 200
    info = r["model"]
    assert (info["name"], info["n_vertices"], info["n_faces"]) == ("c4.off", len(V), len(F))
    counts = {}
    for patch in (5, 15, 45):
        j = _run(server, f"api/model/{info['id']}/features", {"patch": patch})
        assert j["state"] == "done", j
        res = j["result"]
        ref = _lib_mask(V, F, patch)
        body, _ = _get(server, f"api/model/{info['id']}/array/{res['key']}")
        np.testing.assert_array_equal(np.frombuffer(body, np.uint8).astype(bool), ref)
        assert res["n_features"] == int(ref.sum())
        counts[patch] = res["n_features"]
    assert len(set(counts.values())) > 1  # the patch size changes the feature count
    j = _run(server, f"api/model/{info['id']}/curves", {"patch": 15})
    assert j["state"] == "done"
    body, _ = _get(server, f"api/model/{info['id']}/array/{j['result']['key']}")
    lab = np.frombuffer(body, np.int8)
    ref = _analysis.feature_curves(V, F, _lib_mask(V, F, 15), patch=15)
    np.testing.assert_array_equal(lab, ref)
    assert j["result"]["n_curves"] == ref.max() + 1


def test_scalar_heatmap_matches_library(server):
    V, F = server.files["V"], server.files["F"]
    j = _run(server, "api/model/m1/scalar", {"field": "curvature"})
    res = j["result"]
    mc = mean_curvature(V, F)
    assert res["vmin"] == pytest.approx(mc.min()) and res["vmax"] == pytest.approx(mc.max())
    body, _ = _get(server, f"api/model/m1/array/{res['colors']}")
    np.testing.assert_array_equal(np.frombuffer(body, np.uint8).reshape(-1, 3), jet(mc))
    assert len(res["colorbar"]) == 64
    j = _run(server, "api/model/m1/scalar", {"field": "feature-class"})
    body, _ = _get(server, f"api/model/m1/array/{j['result']['values']}")
    np.testing.assert_array_equal(
        np.frombuffer(body, np.float32), classify_vertices(V, F, patch=15).labels
    )


def test_compare_metrics_table(server):
    V, F, noisy = server.files["V"], server.files["F"], server.files["noisy"]
    j = _run(server, "api/compare", {"a": "m1", "b": "m3"})
    assert j["state"] == "done", j
    ref = metrics.compare(noisy.astype(np.float64), V, F)
    got = j["result"]["metrics"]
    assert set(got) == set(ref)
    for k in ref:
        assert got[k] == pytest.approx(ref[k], rel=1e-5, abs=1e-12), k
    body, _ = _get(server, f"api/model/m3/array/{j['result']['heat']['values']}")
    d = np.linalg.norm(noisy - V, axis=1)
    np.testing.assert_allclose(np.frombuffer(body, np.float32), d, rtol=1e-5)


def test_denoise_outliers_and_download(server):
    from spectrageo import denoise

    noisy, F = server.files["noisy"], server.files["F"]
    j = _run(server, "api/model/m3/denoise", {"method": "laplacian"})
    assert j["state"] == "done", j
    new = j["result"]["model"]
    body, _ = _get(server, f"api/model/{new['id']}/positions")
    ref = denoise.denoise(noisy, F, method="laplacian")
    np.testing.assert_allclose(np.frombuffer(body, "<f4").reshape(-1, 3), ref, rtol=1e-5, atol=1e-6)
    data, hdr = _get(server, f"api/model/{new['id']}/download?format=.ply")
    assert "attachment" in hdr["Content-Disposition"]
    p = server.files["dir"] / "dl.ply"
    p.write_bytes(data)
    back = io.read(p)
    np.testing.assert_allclose(back.vertices, ref, rtol=1e-6)
    np.testing.assert_array_equal(back.faces, F)
    j = _run(server, "api/model/m3/denoise", {"method": "no-such"})
    assert j["state"] == "error" and "unknown denoising method" in j["error"]
    # outlier removal on a point cloud with 20 far points
    rng = np.random.default_rng(1)
    P = rng.uniform(-1, 1, (400, 3)) * [1, 1, 0.01]
    P = np.r_[P, rng.uniform(-1, 1, (20, 3)) + [0, 0, 3]]
    io.write(server.files["dir"] / "pts.xyz", PointCloud(P))
    st, r = _json(
        server, "api/upload?name=pts.xyz", data=(server.files["dir"] / "pts.xyz").read_bytes()
    )
    j = _run(server, f"api/model/{r['model']['id']}/outliers", {"method": "rpca", "k": 10})
    assert j["state"] == "done", j
    kept = j["result"]["model"]["n_vertices"]
    assert kept + j["result"]["n_removed"] == 420
    body, _ = _get(server, f"api/model/{j['result']['model']['id']}/positions")
    K = np.frombuffer(body, "<f4").reshape(-1, 3)
    far_kept = int((K[:, 2] > 1.5).sum())
    plane_kept = int((K[:, 2] < 0.5).sum())
    assert far_kept <= 10 and plane_kept >= 395  # most far points go, the plane stays


def test_fill_holes_api_matches_library(server):
    """``POST model/ID/fill-holes`` gives the library's result as a new model; a mesh without
    holes, a point cloud and an unknown method are clear job errors."""
    from spectrageo.complete import fill_holes
    from spectrageo.geometry import boundary_edges

    V, F = server.files["V"], server.files["F"]
    Fh = F[1:]  # one face off: a triangular hole
    Fh = np.r_[Fh[:10], Fh[12:]]  # and a larger one
    io.write(server.files["dir"] / "holed.ply", Mesh(V, Fh))
    st, r = _json(
        server, "api/upload?name=holed.ply", data=(server.files["dir"] / "holed.ply").read_bytes()
    )
    assert st == 200, r
    mid = r["model"]["id"]
    j = _run(server, f"api/model/{mid}/fill-holes", {"method": "lsm"})
    assert j["state"] == "done", j
    res = j["result"]
    V2, F2 = fill_holes(V, Fh, method="lsm")
    assert res["model"]["n_vertices"] == len(V2) and res["n_faces_added"] == len(F2) - len(Fh)
    assert res["n_loops"] >= 1
    body, _ = _get(server, f"api/model/{res['model']['id']}/positions")
    np.testing.assert_allclose(np.frombuffer(body, "<f4").reshape(-1, 3), V2, rtol=1e-5, atol=1e-6)
    body, _ = _get(server, f"api/model/{res['model']['id']}/faces")
    F_back = np.frombuffer(body, "<u4").reshape(-1, 3)
    assert boundary_edges(F_back).shape[0] == 0
    j = _run(server, "api/model/m1/fill-holes", {})  # the closed cube
    assert j["state"] == "error" and "no hole" in j["error"]
    j = _run(server, f"api/model/{mid}/fill-holes", {"method": "no-such"})
    assert j["state"] == "error" and "`method` must be one of" in j["error"]
    j = _run(server, f"api/model/{mid}/fill-holes", {"density": -1})
    assert j["state"] == "error" and "`density` must be > 0" in j["error"]
    j = _run(server, f"api/model/{mid}/fill-holes", {"density": 0.5})
    assert j["state"] == "done", j
    assert j["result"]["model"]["n_vertices"] == len(fill_holes(V, Fh, density=0.5)[0])
    _, st = _json(server, "api/state")
    assert st["hole_methods"][0] == "lsm"


def test_cli_parses_view(monkeypatch):
    from spectrageo.cli import main as cli_main
    from spectrageo.cli import view_cmd

    p = cli_main.build_parser()
    args = p.parse_args(["view", "a.ply", "b.off", "--port", "0", "--no-browser"])
    assert args.files == ["a.ply", "b.off"] and args.port == 0 and args.no_browser
    assert args.func is view_cmd.cmd_view
    assert cli_main.main(["view", "--port", "70000", "--no-browser"]) == 2
    assert cli_main.main(["view", "missing-file.ply", "--port", "0", "--no-browser"]) == 2


def test_cli_serves_until_interrupted(monkeypatch, capsys):
    from spectrageo.cli import view_cmd
    from spectrageo.viewer import server as srvmod

    seen = {}

    def fake_serve(self):
        seen["url"] = self.url
        self.start()  # serve from a thread so that this one can query it
        req = urllib.request.Request(self.url + "api/state", headers=self.api_headers)
        body = urllib.request.urlopen(req, timeout=10).read()
        seen["state"] = json.loads(body)
        self.httpd.shutdown()
        raise KeyboardInterrupt

    monkeypatch.setattr(srvmod.ViewerServer, "serve_forever", fake_serve)
    from spectrageo.cli import main as cli_main

    assert view_cmd.DEFAULT_PORT > 0
    rc = cli_main.main(["view", "--port", "0", "--no-browser"])
    assert rc == 0
    assert seen["url"].startswith("http://127.0.0.1:") and seen["state"]["models"] == []
    assert "spectrageo viewer on http://127.0.0.1:" in capsys.readouterr().err


# --------------------------------------------------------------------------- level of detail
def _cells_of(V, h):
    """Independent cell coordinates of every vertex (cubic cells of size h from the bbox corner)."""
    lo, ext = V.min(axis=0), V.max(axis=0) - V.min(axis=0)
    top = np.maximum(np.ceil(ext / h).astype(int), 1) - 1
    return [tuple(c) for c in np.minimum(np.floor((V - lo) / h).astype(int), top)]


def test_vertex_clustering_is_a_clustering_within_budget():
    from spectrageo.viewer._lod import vertex_clustering

    V, F = grid(60, 40)
    rng = np.random.default_rng(3)
    V = V + np.c_[np.zeros((len(V), 2)), 0.01 * rng.standard_normal(len(V))]
    p = vertex_clustering(V, F, max_faces=800)
    assert 0.8 * 800 < len(p.faces) <= 800  # close to the budget, never above
    assert p.resolution > 1 and p.cell_size > 0
    reps, faces = p.reps, p.faces
    assert np.all(np.diff(reps) > 0) and reps.min() >= 0 and reps.max() < len(V)
    assert faces.min() >= 0 and faces.max() < len(reps)
    # one representative per occupied cell: the vertex nearest the mean of its cell's vertices
    cells = _cells_of(V, p.cell_size)
    members = {}
    for i, c in enumerate(cells):
        members.setdefault(c, []).append(i)
    assert len(members) == len(reps)
    rep_of = {}
    for idx in members.values():
        d = ((V[idx] - V[idx].mean(axis=0)) ** 2).sum(axis=1)
        rep_of[cells[idx[0]]] = idx[int(np.argmin(d))]
    assert sorted(rep_of.values()) == reps.tolist()
    # faces: the input faces mapped to representatives, without collapsed or repeated ones
    ref = set()
    for f in F:
        t = tuple(rep_of[cells[v]] for v in f)
        if len(set(t)) == 3:
            ref.add(frozenset(t))
    got = [frozenset(reps[f]) for f in faces]
    assert len(got) == len(set(got)) and set(got) == ref
    # orientation kept: the grid faces +z, so do the proxy faces (clustering may fold a few and
    # flatten a few to collinear representatives)
    P = V[reps]
    nz = np.cross(P[faces[:, 1]] - P[faces[:, 0]], P[faces[:, 2]] - P[faces[:, 0]])[:, 2]
    assert (nz > 0).mean() > 0.95 and (nz < 0).mean() < 0.02


def test_vertex_clustering_small_models_and_point_clouds():
    from spectrageo.viewer._lod import vertex_clustering

    V, F = cube(3)
    p = vertex_clustering(V, F, max_faces=len(F))  # fits: the model is its own proxy
    assert p.resolution == 0
    np.testing.assert_array_equal(p.reps, np.arange(len(V)))
    np.testing.assert_array_equal(p.faces, F)
    P = np.random.default_rng(0).random((5000, 3))
    q = vertex_clustering(P, max_points=400)
    assert q.faces is None and 0.5 * 400 < len(q.reps) <= 400
    assert len(set(_cells_of(P, q.cell_size))) == len(q.reps)
    assert len(vertex_clustering(P, max_points=5000).reps) == 5000
    for bad in (0, -3, 1.5, True, "10"):
        with pytest.raises(InvalidInputError, match="`max_faces` must be a positive integer"):
            vertex_clustering(V, F, max_faces=bad)
    with pytest.raises(InvalidInputError, match="`max_points` must be a positive integer"):
        vertex_clustering(P, max_points=0)
    with pytest.raises(InvalidInputError, match="`F` must have shape"):
        vertex_clustering(V, F[:, :2])


def test_lod_api_matches_library(server):
    from spectrageo.viewer._lod import vertex_clustering

    V, F = server.files["V"], server.files["F"]
    status, r = _json(server, "api/model/m1/lod?max_faces=40")
    assert status == 200, r
    ref = vertex_clustering(V, F, max_faces=40)
    reps, h = _get(server, f"api/model/m1/array/{r['reps']}")
    assert h["X-Dtype"] == "uint32"
    np.testing.assert_array_equal(np.frombuffer(reps, np.uint32), ref.reps)
    faces, _ = _get(server, f"api/model/m1/array/{r['faces']}")
    np.testing.assert_array_equal(np.frombuffer(faces, np.uint32).reshape(-1, 3), ref.faces)
    assert (r["n_vertices"], r["n_faces"]) == (len(ref.reps), len(ref.faces))
    assert r["n_faces"] <= 40 and r["resolution"] == ref.resolution
    status, r = _json(server, "api/model/m1/lod?max_faces=zero")
    assert status == 400 and "`max_faces` must be an integer" in r["error"]
