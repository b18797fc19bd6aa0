"""The viewer's local web server on ``127.0.0.1``: a JSON API, and bulk data for the page
(``static/``, three.js) as raw little-endian arrays (float32 positions, uint32 faces, uint8 RGB).

API (every JSON answer is an object; errors are ``{"error": message}`` with status 4xx/5xx):

========================================  =====================================================
``GET  /api/state``                       loaded models, denoisers, outlier methods, formats
``POST /api/upload?name=FILE``            body: the file bytes; reads it with :func:`spectrageo.io.read`
``POST /api/field-upload?model=ID&name=``  body: ``.npy``/``.txt``/``.csv`` scalars (per vertex or face)
``GET  /api/model/ID``                    model information
``GET  /api/model/ID/positions?frame=T``  float32 (n, 3) of frame ``T``
``GET  /api/model/ID/faces``              uint32 (m, 3) (empty for point clouds)
``GET  /api/model/ID/array/KEY``          a computed array (dtype in the ``X-Dtype`` header)
``GET  /api/model/ID/lod?max_faces=N``     level-of-detail proxy (``reps``/``faces`` array keys)
``GET  /api/model/ID/download?format=.ply`` the model written with :func:`spectrageo.io.write`
``POST /api/model/ID/features``           ``{"patch": 15, "frame": 0}`` -> job
``POST /api/model/ID/curves``             ``{"patch": 15, "frame": 0}`` -> job
``POST /api/model/ID/scalar``             ``{"field": "saliency" | "curvature" | "attr:NAME" ...}`` -> job
``POST /api/model/ID/denoise``            ``{"method": "tsgsp"}`` -> job, result is a new model
``POST /api/model/ID/outliers``           ``{"method": "rpca", "k": 10}`` -> job, result is a new model
``POST /api/model/ID/fill-holes``         ``{"method": "lsm", "max_hole": null, "density": 1}`` -> job, new model
``POST /api/compare``                     ``{"a": ID, "b": ID, "frame": 0}`` -> job (metrics table)
``GET  /api/job/JOB``                     ``{"state", "progress", "message", "elapsed", "result"|"error"}``
========================================  =====================================================

Security (docs/usage.md, "Viewer"; docs/decisions.md#viewer-security-model): only requests with
one well-formed loopback ``Host`` and a path as target are answered; every ``/api/`` request
needs the page's per-session token in the ``X-Spectrageo-Token`` header, and a foreign
``Origin``, a cross-site ``Sec-Fetch-Site`` or a CORS preflight gets 403 before the body is read.
Upload names are data (:func:`clean_name`); bodies, uploads, jobs, models and connections are
bounded by :class:`ViewerLimits`.
"""

from __future__ import annotations

import atexit
import functools
import secrets
import shutil
import threading
import time
from dataclasses import replace

from ._files import _make_temp_dir, clean_name, content_disposition, remove_stale_temp_dirs
from ._http import TOKEN_HEADER, _Handler, _HTTPServer
from ._jobs import Job, ViewerBusyError
from ._limits import ViewerLimits
from ._session import Model, ViewerSession, colorbar


class ViewerServer:
    """The viewer's HTTP server on ``127.0.0.1``.

    Parameters
    ----------
    paths : list of path-like
        Files (or frame folders) to load at start.
    port : int
        TCP port; 0 picks a free one.
    verbose : bool
        Log every request on stderr.
    limits : ViewerLimits, optional
        Resource limits; by default :meth:`ViewerLimits.from_env` with ``**overrides`` (its fields).

    Attributes
    ----------
    token : str
        The per-session token; API clients send it as :attr:`api_headers`.
    tmp_dir : Path
        Private ``spectrageo-view-<PID>-*`` folder, removed by :meth:`stop`, at exit or later.

    Examples
    --------
    >>> srv = ViewerServer(["fandisk.off"], port=0).start()   # doctest: +SKIP
    >>> srv.url                                                # doctest: +SKIP
    'http://127.0.0.1:40123/'
    >>> srv.stop()                                             # doctest: +SKIP
    """

    def __init__(
        self,
        paths=(),
        *,
        port: int = 0,
        verbose: bool = False,
        limits: ViewerLimits | None = None,
        **overrides,
    ):
        self.limits = ViewerLimits.from_env(**overrides) if limits is None else limits
        if limits is not None and overrides:
            self.limits = replace(limits, **overrides)
        self.removed_stale = remove_stale_temp_dirs()
        self.tmp_dir = _make_temp_dir()
        self._atexit = functools.partial(shutil.rmtree, self.tmp_dir, ignore_errors=True)
        atexit.register(self._atexit)
        self._serving = False
        self._closed = False
        self._clean = True
        self.httpd = None
        try:
            self.session = ViewerSession(self.limits, tmp_dir=self.tmp_dir)
            for p in paths:
                self.session.load_path(p)
            self.token = secrets.token_urlsafe(32)
            handler = type(
                "Handler",
                (_Handler,),
                {
                    "session": self.session,
                    "quiet": not verbose,
                    "token": self.token,
                    "limits": self.limits,
                    "timeout": float(self.limits.request_timeout),
                    "tmp_dir": self.tmp_dir,
                    "upload_slots": threading.BoundedSemaphore(self.limits.max_uploads),
                },
            )
            self.httpd = _HTTPServer(
                ("127.0.0.1", int(port)), handler, max_connections=self.limits.max_connections
            )
        except BaseException:
            self.stop()
            raise
        self._thread: threading.Thread | None = None

    @property
    def port(self) -> int:
        return int(self.httpd.server_address[1])

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}/"

    @property
    def api_headers(self) -> dict[str, str]:
        """Headers an API client (a script, a test) needs: the session token."""
        return {TOKEN_HEADER: self.token}

    def start(self) -> ViewerServer:
        """Serve in a background thread (returns self)."""
        self._serving = True
        self._thread = threading.Thread(target=self._serve, daemon=True, name="spectrageo-view")
        self._thread.start()
        return self

    def _serve(self) -> None:
        self._serving = True
        try:
            self.httpd.serve_forever()
        finally:
            self._serving = False

    def serve_forever(self) -> None:
        self._serve()

    def stop(self, timeout: float = 5.0) -> bool:
        """Stop accepting, cancel the jobs, close the connections and remove the temporary folder,
        waiting up to ``timeout`` seconds for the job and connection threads.

        Returns
        -------
        bool
            Whether every such thread ended. A computation inside a library call ends only with
            it; a process exiting while one runs native code can abort, so the CLI then leaves
            with ``os._exit``.
        """
        if self._closed:
            return self._clean
        self._closed = True
        end = time.monotonic() + timeout
        if self.httpd is not None:
            # shutdown() waits for serve_forever() to return; when it ran in this thread (the CLI,
            # interrupted by Ctrl+C or SIGTERM) it has already stopped -- possibly before it
            # entered its loop, when the wait would never end -- so only a server thread is asked
            if self._serving and self._thread is not None and self._thread.is_alive():
                if self._thread is not threading.current_thread():
                    self.httpd.shutdown()
            self.httpd.server_close()
        clean = True
        session = getattr(self, "session", None)
        if session is not None:
            clean = session.close(timeout)
        if self.httpd is not None:
            clean = self.httpd.close_connections(max(end - time.monotonic(), 0.0)) and clean
        shutil.rmtree(self.tmp_dir, ignore_errors=True)
        atexit.unregister(self._atexit)
        self._clean = clean
        return clean

    close = stop

    def __enter__(self) -> ViewerServer:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


__all__ = [
    "Job",
    "Model",
    "ViewerBusyError",
    "ViewerLimits",
    "ViewerServer",
    "ViewerSession",
    "clean_name",
    "colorbar",
    "content_disposition",
    "remove_stale_temp_dirs",
]
