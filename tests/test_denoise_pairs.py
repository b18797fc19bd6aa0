"""TSGSP against GNF on the shared pairs of the thesis's Table 5.4 (issue 14).

Table 5.4 ranks TSGSP ahead of GNF on Block, Fandisk (0.7), SharpSphere and Twelve (impulsive).
The shared pairs are the same models with the benchmark's own noise realisations, so the values
are not the thesis's; the ranking must hold and TSGSP's mean normal error must stay within a
quarter of the thesis's value (measured: 3.46 / 6.40 / 7.18 / 2.79 degrees against the thesis's
3.30 / 6.07 / 6.24 / 2.65; GNF 4.09 / 8.43 / 8.17 / 3.18). Both methods run through
:func:`spectrageo.denoise.denoise` with their defaults, as a user calls them.
"""

from __future__ import annotations

import pytest

from spectrageo import denoise, io
from spectrageo.evaluate.denoise import THESIS_THETA
from spectrageo.metrics import theta_deg

from conftest import shared_file


@pytest.mark.parametrize("pair", sorted(THESIS_THETA))
def test_tsgsp_ranks_ahead_of_gnf_as_in_table_5_4(shared_data, pair):
    d = shared_file(shared_data, "denoise", pair, "Noisy.obj").parent
    noisy = io.read_mesh(d / "Noisy.obj")
    clean = io.read_mesh(d / "Original.obj")
    V0, F = clean.vertices, clean.faces
    th = {
        m: theta_deg(denoise.denoise(noisy.vertices, noisy.faces, method=m), V0, F)
        for m in ("tsgsp", "gnf")
    }
    thesis_gnf, thesis_tsgsp = THESIS_THETA[pair]
    assert thesis_tsgsp < thesis_gnf  # the ranking the test holds us to
    assert th["tsgsp"] < th["gnf"], th
    assert th["tsgsp"] < 1.25 * thesis_tsgsp, th
    assert th["tsgsp"] < 0.25 * theta_deg(noisy.vertices, V0, F), th
