"""The vertex order shared by the static predictive coder and ``pca-pred``
(docs/decisions.md#anim-pred2-traversal)."""

from __future__ import annotations

import numpy as np

from spectrageo.compress import _pca_pred
from spectrageo.compress._predictive_kernel import traversal_order

from conftest import icosphere


def test_order_is_a_permutation_that_grows_through_decoded_faces():
    """Every vertex once (isolated ones last, in index order); on a closed surface each vertex
    after the first two has a decoded neighbour, and from the fourth on most have a face whose
    two other corners are decoded (the gate the traversal prefers)."""
    V, F = icosphere(3)
    n = V.shape[0]
    order = traversal_order(np.ascontiguousarray(F, np.int64), n + 2)
    assert np.array_equal(np.sort(order), np.arange(n + 2))
    assert list(order[-2:]) == [n, n + 1]
    pos = np.empty(n + 2, np.int64)
    pos[order] = np.arange(n + 2)
    gated = 0
    for v in order[3:n]:
        faces = F[(F == v).any(axis=1)]
        others = faces[faces != v].reshape(-1, 2)
        assert (pos[others] < pos[v]).any()
        gated += bool((pos[others] < pos[v]).all(axis=1).any())
    assert gated == n - 3


def test_pca_pred_codes_in_the_shared_order():
    V, F = icosphere(2)
    plan = _pca_pred.make_plan(F, V.shape[0])
    assert np.array_equal(plan[1], traversal_order(plan[0], V.shape[0]))
