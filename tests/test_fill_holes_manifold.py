"""`fill_holes` keeps the input's faces, never makes the mesh less manifold, and reports each loop
it leaves open (issue 53)."""

from __future__ import annotations

import numpy as np
import pytest

from spectrageo.complete import FilledMesh, fill_holes
from spectrageo.complete.holes import (
    OPEN_DUPLICATE,
    OPEN_MAX_HOLE,
    OPEN_NON_ORIENTABLE,
    OPEN_NOT_CLOSED,
)
from spectrageo.geometry import boundary_edges, weld


def _defects(F: np.ndarray) -> tuple[int, int]:
    """(edges with more than two faces, faces repeating another face's vertices)."""
    E = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    _, ce = np.unique(E, axis=0, return_counts=True)
    _, cf = np.unique(np.sort(F, axis=1), axis=0, return_counts=True)
    return int((ce > 2).sum()), int((cf - 1).sum())


def _welded(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    g = weld(V, F).index_map
    Fw = g[F]
    return Fw[(Fw[:, 0] != Fw[:, 1]) & (Fw[:, 1] != Fw[:, 2]) & (Fw[:, 2] != Fw[:, 0])]


def _area(V: np.ndarray, F: np.ndarray) -> float:
    return 0.5 * float(
        np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1).sum()
    )


def _uv_sphere_with_seam(nu: int = 12, nv: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """A UV sphere whose column 0 is duplicated as column ``nu`` (a texture seam)."""
    th = np.linspace(0.0, np.pi, nv + 1)[1:-1]
    ph = 2.0 * np.pi * np.arange(nu + 1) / nu
    t, p = np.meshgrid(th, ph, indexing="ij")
    ring = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)
    ring[:, nu] = ring[:, 0]  # the seam copies are coincident
    V = np.concatenate([[[0.0, 0.0, 1.0]], ring.reshape(-1, 3), [[0.0, 0.0, -1.0]]])
    S = V.shape[0] - 1

    def idx(j, i):
        return 1 + j * (nu + 1) + i

    F = [(0, idx(0, i), idx(0, i + 1)) for i in range(nu)]
    for j in range(nv - 2):
        for i in range(nu):
            F += [(idx(j, i), idx(j + 1, i), idx(j + 1, i + 1))]
            F += [(idx(j, i), idx(j + 1, i + 1), idx(j, i + 1))]
    F += [(S, idx(nv - 2, i + 1), idx(nv - 2, i)) for i in range(nu)]
    return V, np.asarray(F, dtype=np.int64)


def _grid(k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A flat k x k grid of unit cells: vertices, faces, and each face's (row, col) cell."""
    x, y = np.meshgrid(np.arange(k + 1.0), np.arange(k + 1.0), indexing="ij")
    V = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    F, cell = [], []
    for r in range(k):
        for c in range(k):
            a, b = r * (k + 1) + c, (r + 1) * (k + 1) + c
            F += [(a, b, b + 1), (a, b + 1, a + 1)]
            cell += [(r, c), (r, c)]
    return V, np.asarray(F, dtype=np.int64), np.asarray(cell)


def _check_kept_and_manifold(V, F, res):
    V2, F2 = res
    assert isinstance(res, FilledMesh)
    np.testing.assert_array_equal(V2[: V.shape[0]], V)
    np.testing.assert_array_equal(F2[: F.shape[0]], F)  # input faces keep their indices
    assert _defects(F2) == _defects(F)
    assert _defects(_welded(V2, F2)) <= _defects(_welded(V, F))


def test_seam_through_a_hole_keeps_input_faces_and_closes_it():
    V, F = _uv_sphere_with_seam()
    nu = 12
    # remove 3 x 4 cells, two on each side of the seam: the hole's border crosses the seam
    bands = [
        nu + 2 * (j * nu + i) + s for j in (2, 3, 4) for i in (0, 1, nu - 2, nu - 1) for s in (0, 1)
    ]
    Fh = np.delete(F, bands, axis=0)
    assert boundary_edges(_welded(V, F)).shape[0] == 0  # the seam itself is no hole
    res = fill_holes(V, Fh)
    _check_kept_and_manifold(V, Fh, res)
    assert (res.n_loops, res.n_filled, res.open_loops) == (1, 1, ())
    V2, F2 = res
    assert boundary_edges(_welded(V2, F2)).shape[0] == 0  # closed, seams apart
    used = np.zeros(V2.shape[0], dtype=bool)
    used[F2.ravel()] = True
    assert used[np.unique(Fh)].all() and used[V.shape[0] :].all()
    assert (
        np.isfinite(V2).all() and np.abs(np.linalg.norm(V2[V.shape[0] :], axis=1) - 1).max() < 0.2
    )


def test_moebius_strip_is_left_open_without_new_vertices():
    N, w = 24, 0.3
    t = 2.0 * np.pi * np.arange(N) / N
    c = np.column_stack([np.cos(t), np.sin(t), np.zeros(N)])
    d = w * (np.cos(t / 2)[:, None] * c + np.sin(t / 2)[:, None] * np.array([0.0, 0.0, 1.0]))
    V = np.concatenate([c + d, c - d])  # a_k = k, b_k = N + k
    F = []
    for k in range(N):
        a, b = k, N + k
        a1, b1 = (k + 1, N + k + 1) if k < N - 1 else (N, 0)  # the half twist: a_N = b_0
        F += [(a, b, b1), (a, b1, a1)]
    F = np.asarray(F, dtype=np.int64)
    res = fill_holes(V, F)
    np.testing.assert_array_equal(res[0], V)
    np.testing.assert_array_equal(res[1], F)
    assert res.n_filled == 0 and res.n_loops >= 1
    assert [lp.reason for lp in res.open_loops] == [OPEN_NON_ORIENTABLE]
    assert sorted(res.open_loops[0].vertices.tolist()) == list(range(2 * N))  # its one border


def test_triangles_never_get_a_duplicated_face():
    V = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    one = np.array([[0, 1, 2]])
    res = fill_holes(V, one)
    np.testing.assert_array_equal(res[1], one)  # the only fill is the face itself, backwards
    assert [lp.reason for lp in res.open_loops] == [OPEN_DUPLICATE]
    assert res.open_loops[0].vertices.tolist() in ([0, 1, 2], [1, 2, 0], [2, 0, 1])
    pair = np.array([[0, 1, 2], [0, 2, 3]])  # one 4-loop around two triangles
    res = fill_holes(V, pair)
    _check_kept_and_manifold(V, pair, res)
    assert _defects(res[1]) == (0, 0) and res.open_loops == ()
    flipped = np.array([[0, 1, 2], [0, 3, 2]])  # wound against each other
    res = fill_holes(V, flipped)
    _check_kept_and_manifold(V, flipped, res)
    assert res.n_filled == 1 and boundary_edges(res[1]).shape[0] == 0


def test_concave_hole_is_filled_inside_its_border():
    V, F, cell = _grid(6)
    r, c = cell[:, 0], cell[:, 1]
    u = ((c == 1) | (c == 4)) & (r >= 1) & (r <= 4) | (r == 4) & (c >= 2) & (c <= 3)
    Fh = F[~u]
    res = fill_holes(V, Fh, max_hole=22)
    _check_kept_and_manifold(V, Fh, res)
    assert res.n_loops == 2 and res.n_filled == 1
    assert [lp.reason for lp in res.open_loops] == [OPEN_MAX_HOLE]  # the grid's 24-edge border
    assert res.open_loops[0].vertices.size == 24
    new = res[1][Fh.shape[0] :]
    assert _area(res[0], new) == pytest.approx(10.0, rel=1e-9)  # the U's 10 cells, no overlap
    assert np.abs(res[0][:, 2]).max() < 1e-9


def test_two_holes_sharing_a_vertex():
    V, F, cell = _grid(7)
    r, c = cell[:, 0], cell[:, 1]
    gone = (r >= 1) & (r <= 2) & (c >= 1) & (c <= 2) | (r >= 3) & (r <= 4) & (c >= 3) & (c <= 4)
    Fh = F[~gone]
    res = fill_holes(V, Fh, max_hole=20)
    _check_kept_and_manifold(V, Fh, res)
    assert (res.n_loops, res.n_filled) == (3, 2)
    assert [lp.reason for lp in res.open_loops] == [OPEN_MAX_HOLE]
    assert _area(res[0], res[1][Fh.shape[0] :]) == pytest.approx(8.0, rel=1e-9)
    inner = boundary_edges(res[1])
    assert np.isin(inner, res.open_loops[0].vertices).all()  # only the outer border is left
    Fx = Fh.copy()
    Fx[Fx.shape[0] // 2 :] = Fx[Fx.shape[0] // 2 :, ::-1]  # the second half wound the other way
    res = fill_holes(V, Fx, max_hole=20)
    _check_kept_and_manifold(V, Fx, res)
    assert res.n_filled == 0 and res[0].shape == V.shape
    why = sorted((lp.reason, lp.vertices.size) for lp in res.open_loops)
    assert why == [(OPEN_MAX_HOLE, 28), (OPEN_NOT_CLOSED, 15)]  # both holes, joined at the vertex


def _write_obj(path, V, F):
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in V.tolist()]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in F.tolist()]
    path.write_text("\n".join(lines) + "\n")


def test_cli_status_line_reports_open_loops(tmp_path, capsys):
    from spectrageo.cli.main import main

    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    src, out = tmp_path / "tri.obj", tmp_path / "out.obj"
    _write_obj(src, V, np.array([[0, 1, 2]]))
    assert main(["complete", str(src), str(out), "--fill-holes"]) == 0
    err = capsys.readouterr().err
    assert (
        "0 of 1 boundary loops closed" in err
        and "1 left open: 1 whose fill would duplicate a face" in err
    )
    Vg, Fg, cell = _grid(4)
    _write_obj(src, Vg, Fg[~((cell[:, 0] == 1) & (cell[:, 1] == 1))])
    assert main(["complete", str(src), str(out), "--fill-holes", "--max-hole", "8"]) == 0
    err = capsys.readouterr().err
    assert "1 of 2 boundary loops closed" in err and "1 longer than max_hole (--max-hole)" in err


def test_cli_all_faces_collapsing_is_a_clear_error(tmp_path, capsys):
    from spectrageo.cli.main import main

    src = tmp_path / "flat.obj"
    _write_obj(src, np.zeros((4, 3)), np.array([[0, 1, 2], [0, 2, 3]]))
    assert main(["complete", str(src), str(tmp_path / "o.obj"), "--fill-holes"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "`F`" not in err[0] and "every face of the mesh collapses" in err[0]


def test_fill_that_would_overload_an_edge_is_refused():
    """The check applied to every patch: an edge of the mesh that already has two faces cannot
    take a third; a face the mesh (or an earlier patch) has cannot be added again."""
    from spectrageo.complete.holes import OPEN_NON_MANIFOLD, OPEN_UNCOVERED, _Checker

    Fw = np.array([[0, 1, 2], [2, 1, 3], [2, 3, 4]])  # edges 1-2 and 2-3 have two faces
    check = _Checker(Fw, 5)
    loop = np.array([0, 1, 3, 4, 2])
    assert check.loop_closed(loop) and not check.loop_closed(np.array([0, 1, 2]))
    assert check.problem(loop, np.array([[1, 2, 5]])) == OPEN_NON_MANIFOLD
    assert check.problem(loop, np.array([[1, 0, 2]])) == OPEN_DUPLICATE
    check.add(np.array([[0, 4, 2]]))  # an accepted patch: edges 0-2 and 2-4 now have two faces
    assert check.problem(loop, np.array([[2, 4, 0]])) == OPEN_DUPLICATE
    assert check.problem(loop, np.array([[0, 2, 6]])) == OPEN_NON_MANIFOLD
    assert check.problem(loop, np.array([[1, 0, 6]])) == OPEN_UNCOVERED  # leaves 1-3-4-2 open
