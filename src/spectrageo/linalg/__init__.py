"""Low-rank and sparse numerical solvers (thesis Sections 4.5-4.7, 5.1.2, 5.2.4, 5.3).

- :func:`rpca`: robust PCA, ``M = E + S (+ G)`` by inexact ALM (PCP, Eq. 4.18-4.23) or by the
  bilateral factorisation with QR updates (GoDec, Eq. 5.29-5.35); row-chunked for tall matrices.
- :func:`complete_matrix`: low-rank matrix completion by ALM (Eq. 5.80-5.89).
- :func:`isvd_update`, :class:`IncrementalSVD`: SVD updating by appended columns (Eq. 5.69-5.71).
- :func:`lasso`: LASSO by ADMM (Eq. 5.96).
- :func:`laplacian_interpolation`: least-squares Laplacian interpolation (Eq. 4.24-4.27).
- :func:`update_vertices`: vertex positions from target face normals (Eq. 4.28-4.29), re-exported
  from :mod:`spectrageo.geometry`.
"""

from ..geometry.update import update_vertices
from .completion import CompletionResult, complete_matrix
from .interpolation import laplacian_interpolation
from .isvd import IncrementalSVD, isvd_update
from .lasso import LassoResult, lasso
from .rpca import RPCAResult, rpca

__all__ = [
    "CompletionResult",
    "IncrementalSVD",
    "LassoResult",
    "RPCAResult",
    "complete_matrix",
    "isvd_update",
    "laplacian_interpolation",
    "lasso",
    "rpca",
    "update_vertices",
]
