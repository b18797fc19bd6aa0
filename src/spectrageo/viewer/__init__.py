"""Browser viewer (thesis Appendix C): models with their feature vertices, heatmaps, comparisons,
animation playback, denoising and outlier removal, served on ``127.0.0.1``.

Start it with ``spectrageo view [FILE ...]`` or from Python::

    from spectrageo.viewer import ViewerServer
    srv = ViewerServer(["model.ply"], port=0).start()
    print(srv.url)

The page renders with three.js (vendored under ``static/vendor``, MIT licence); the core library
never imports this package. It redraws on demand only. Models above 150,000 faces (300,000 points)
get a level-of-detail proxy (vertex clustering to at most 100,000 faces / 150,000 points, see
``_lod``) drawn while the camera moves; the full model is drawn once the motion stops. Page URL
options: ``?lod=0`` (always full detail), ``lod_faces=``, ``lod_points=``, ``lod_budget=``,
``lod_point_budget=``, ``lod_settle_ms=`` (thresholds, budgets, delay before the full redraw) and
``aa=0|1`` (multisampling; by default on for GPUs, off for software renderers such as SwiftShader).

Security: the server answers on the loopback interface only, to its own origin only, and every API
request must carry the per-session token written into the page (scripts use
``srv.api_headers``); uploads, jobs, loaded models, connections and timeouts are bounded by
:class:`ViewerLimits` (``spectrageo view --max-upload/--max-models/--max-memory`` or
``SPECTRAGEO_VIEW_*`` environment variables). See :mod:`spectrageo.viewer.server`.
"""

from .server import ViewerLimits, ViewerServer, ViewerSession, colorbar

__all__ = ["ViewerLimits", "ViewerServer", "ViewerSession", "colorbar"]
