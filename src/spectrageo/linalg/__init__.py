"""Low-rank and sparse solvers (thesis Sections 4.5-4.7, 5.1.2, 5.2.4, 5.3): :func:`rpca`,
:func:`complete_matrix`, :func:`isvd_update`, :func:`lasso`, :func:`laplacian_interpolation`, and
:func:`update_vertices` re-exported from :mod:`spectrageo.geometry`.
"""

from ..geometry.update import update_vertices
from .completion import CompletionResult, complete_matrix
from .interpolation import laplacian_interpolation
from .isvd import IncrementalSVD, isvd_update
from .lasso import LassoResult, lasso
from .rpca import RPCAResult, RPCASolverOptions, rpca

__all__ = [
    "CompletionResult",
    "IncrementalSVD",
    "LassoResult",
    "RPCAResult",
    "RPCASolverOptions",
    "complete_matrix",
    "isvd_update",
    "laplacian_interpolation",
    "lasso",
    "rpca",
    "update_vertices",
]
