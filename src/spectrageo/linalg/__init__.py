"""Low-rank and sparse solvers (thesis Sections 4.5-4.7, 5.1.2, 5.2.4, 5.3): :func:`rpca`,
:func:`complete_matrix`, :func:`isvd_update`, :func:`lasso`, :func:`laplacian_interpolation`, and
:func:`update_vertices` re-exported from :mod:`spectrageo.geometry`.

Names are imported from their submodules on first use, except :func:`lasso` and :func:`rpca`,
which share their module's name and are therefore bound at import.
"""

from .._plugins import lazy_exports
from .lasso import LassoResult, lasso
from .rpca import RPCAResult, RPCASolverOptions, rpca

_EXPORTS = {
    "CompletionResult": ".completion",
    "complete_matrix": ".completion",
    "IncrementalSVD": ".isvd",
    "isvd_update": ".isvd",
    "laplacian_interpolation": ".interpolation",
    "update_vertices": "..geometry.update",
}

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
__getattr__, __dir__ = lazy_exports(
    __name__, _EXPORTS, ("LassoResult", "RPCAResult", "RPCASolverOptions", "lasso", "rpca")
)
