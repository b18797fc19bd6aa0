"""Browser viewer (thesis Appendix C): models with their feature vertices, heatmaps, comparisons,
animation playback, denoising and outlier removal, served on ``127.0.0.1``.

Start it with ``spectrageo view [FILE ...]`` or ``ViewerServer(["model.ply"], port=0).start()``
(its ``url`` is the page). Models above 150,000 faces (300,000 points) are drawn as a
level-of-detail proxy while the camera moves (``_lod``). Page URL options: ``?lod=0`` (always full
detail), ``lod_faces=``, ``lod_points=``, ``lod_budget=``, ``lod_point_budget=``,
``lod_settle_ms=`` and ``aa=0|1`` (multisampling; off for software renderers by default).
Routes, limits (:class:`ViewerLimits`) and security: :mod:`spectrageo.viewer.server`.
"""

from .server import ViewerLimits, ViewerServer, ViewerSession, colorbar

__all__ = ["ViewerLimits", "ViewerServer", "ViewerSession", "colorbar"]
