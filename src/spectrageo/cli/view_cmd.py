"""``spectrageo view [FILE ...] [--port P] [--no-browser] [--max-upload MB]``: the browser viewer
(Appendix C)."""

from __future__ import annotations

import os
import signal
import sys
import threading
import webbrowser

from .._errors import InvalidInputError
from ._common import apply_help

DEFAULT_PORT = 8765

HELP = {
    "view": (
        "Serve a local web viewer on 127.0.0.1 and open it in the browser. Files given here are\n"
        "loaded at start; more can be loaded from the page.",
        "spectrageo view model.ply noisy.ply",
    ),
}


def _limits(args) -> dict:
    """Limits given on the command line (the rest come from SPECTRAGEO_VIEW_* or the defaults)."""
    out = {}
    for opt, key in (
        ("max_upload", "max_upload_mb"),
        ("max_models", "max_models"),
        ("max_memory", "max_memory_mb"),
    ):
        v = getattr(args, opt, None)
        if v is None:
            continue
        if not v > 0:
            raise InvalidInputError(f"`--{opt.replace('_', '-')}` must be > 0; got {v}.")
        out[key] = v
    return out


def _on_terminate(signum, frame):  # SIGTERM / SIGHUP: stop like Ctrl+C, cleaning up on the way
    raise KeyboardInterrupt


def cmd_view(args) -> int:
    from ..viewer import ViewerServer

    if args.port is not None and not 0 <= args.port <= 65535:
        raise InvalidInputError(f"`--port` must be in [0, 65535]; got {args.port}.")
    port = DEFAULT_PORT if args.port is None else args.port
    limits = _limits(args)
    try:
        srv = ViewerServer(args.files, port=port, verbose=args.verbose, **limits)
    except OSError as exc:
        if args.port is not None:
            raise InvalidInputError(f"cannot listen on 127.0.0.1:{port}: {exc.strerror}") from exc
        srv = ViewerServer(args.files, port=0, verbose=args.verbose, **limits)  # default port busy
    old = {}
    if threading.current_thread() is threading.main_thread():
        for name in ("SIGTERM", "SIGHUP"):
            sig = getattr(signal, name, None)
            if sig is not None:
                old[sig] = signal.signal(sig, _on_terminate)
    try:
        lim = srv.limits
        print(
            f"spectrageo viewer on {srv.url}  (Ctrl+C to stop; uploads up to "
            f"{lim.max_upload_mb:g} MB, {lim.max_models} models / {lim.max_memory_mb:g} MB kept)",
            file=sys.stderr,
            flush=True,
        )
        if not args.no_browser:
            webbrowser.open(srv.url)
        srv.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        for sig, handler in old.items():  # a second SIGTERM while stopping ends the process
            signal.signal(sig, handler)
        clean = srv.stop()  # cancels the jobs, closes the sockets, removes the temporary folder
    if not clean:  # a job is still inside a library call: leave without the interpreter's
        # shutdown, which can abort the process under a thread running native code
        print("spectrageo view: stopped while a computation was running.", file=sys.stderr)
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(0)
    return 0


def register(sub) -> None:
    p = sub.add_parser(
        "view",
        help="open the browser viewer (features, heatmaps, comparisons, animations)",
        description="Serve a local web viewer on 127.0.0.1 and open it in the browser. "
        "Files given here are loaded at start; more can be loaded from the page. Limits can also "
        "be set with SPECTRAGEO_VIEW_MAX_UPLOAD_MB, SPECTRAGEO_VIEW_MAX_MODELS and "
        "SPECTRAGEO_VIEW_MAX_MEMORY_MB (and SPECTRAGEO_VIEW_MAX_JOBS, _MAX_QUEUED, _MAX_UPLOADS, "
        "_REQUEST_TIMEOUT, _MAX_CONNECTIONS).",
    )
    p.add_argument("files", nargs="*", metavar="FILE", help="geometry files or frame folders")
    p.add_argument(
        "--port",
        type=int,
        default=None,
        help=f"TCP port (default {DEFAULT_PORT}, or a free one if it is taken; 0 = any free port)",
    )
    p.add_argument("--no-browser", action="store_true", help="do not open a browser window")
    p.add_argument("--verbose", action="store_true", help="log every HTTP request")
    p.add_argument(
        "--max-upload",
        type=float,
        default=None,
        metavar="MB",
        help="largest accepted upload in MiB (default 256, or SPECTRAGEO_VIEW_MAX_UPLOAD_MB)",
    )
    p.add_argument(
        "--max-models",
        type=int,
        default=None,
        metavar="N",
        help="models kept loaded; the least recently used beyond it are unloaded (default 32)",
    )
    p.add_argument(
        "--max-memory",
        type=float,
        default=None,
        metavar="MB",
        help="memory budget of the loaded models in MiB; least recently used ones beyond it "
        "are unloaded (default 2048)",
    )
    p.set_defaults(func=cmd_view)
    apply_help(sub, HELP)
