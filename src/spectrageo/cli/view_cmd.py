"""``spectrageo view [FILE ...] [--port P] [--no-browser]``: the browser viewer (Appendix C)."""

from __future__ import annotations

import sys
import webbrowser

from .._errors import InvalidInputError

DEFAULT_PORT = 8765


def cmd_view(args) -> int:
    from ..viewer import ViewerServer

    if args.port is not None and not 0 <= args.port <= 65535:
        raise InvalidInputError(f"`--port` must be in [0, 65535]; got {args.port}.")
    port = DEFAULT_PORT if args.port is None else args.port
    try:
        srv = ViewerServer(args.files, port=port, verbose=args.verbose)
    except OSError as exc:
        if args.port is not None:
            raise InvalidInputError(f"cannot listen on 127.0.0.1:{port}: {exc.strerror}") from exc
        srv = ViewerServer(args.files, port=0, verbose=args.verbose)  # default port busy
    print(f"spectrageo viewer on {srv.url}  (Ctrl+C to stop)", file=sys.stderr, flush=True)
    if not args.no_browser:
        webbrowser.open(srv.url)
    try:
        srv.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        srv.httpd.server_close()
    return 0


def register(sub) -> None:
    p = sub.add_parser(
        "view",
        help="open the browser viewer (features, heatmaps, comparisons, animations)",
        description="Serve a local web viewer on 127.0.0.1 and open it in the browser. "
        "Files given here are loaded at start; more can be loaded from the page.",
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
    p.set_defaults(func=cmd_view)
