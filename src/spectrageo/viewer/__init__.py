"""Browser viewer (thesis Appendix C): models with their feature vertices, heatmaps, comparisons,
animation playback, denoising and outlier removal, served on ``127.0.0.1``.

Start it with ``spectrageo view [FILE ...]`` or from Python::

    from spectrageo.viewer import ViewerServer
    srv = ViewerServer(["model.ply"], port=0).start()
    print(srv.url)

The page renders with three.js (vendored under ``static/vendor``, MIT licence); the core library
never imports this package.
"""

from .server import ViewerServer, ViewerSession, colorbar

__all__ = ["ViewerServer", "ViewerSession", "colorbar"]
