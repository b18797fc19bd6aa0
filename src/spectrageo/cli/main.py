"""``spectrageo`` command line: argument parsing, dispatch and error reporting.

User mistakes (bad files, bad options) print one line on stderr and exit with status 2; unexpected
failures print one line and exit with status 1 (set ``SPECTRAGEO_DEBUG=1`` for the traceback).
"""

from __future__ import annotations

import argparse
import os
import sys
import traceback

from .._errors import SpectrageoError


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, exit 2, like every other user mistake
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    from . import commands

    p = _Parser(
        prog="spectrageo", description="Spectral processing of static and dynamic 3D geometry."
    )
    p.add_argument("--version", action="version", version=_version())
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    commands.register_all(sub)
    return p


def _version() -> str:
    from .. import __version__

    return f"spectrageo {__version__}"


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "command", None):
        parser.print_help(sys.stderr)
        return 2
    try:
        return int(args.func(args) or 0)
    except SpectrageoError as exc:
        print(f"spectrageo {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except FileNotFoundError as exc:
        print(
            f"spectrageo {args.command}: error: file not found: {exc.filename or exc}",
            file=sys.stderr,
        )
        return 2
    except (PermissionError, IsADirectoryError, NotADirectoryError) as exc:
        print(
            f"spectrageo {args.command}: error: {exc.strerror or exc}: {exc.filename}",
            file=sys.stderr,
        )
        return 2
    except KeyboardInterrupt:
        print("spectrageo: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - last-resort reporting for the CLI only
        if os.environ.get("SPECTRAGEO_DEBUG"):
            traceback.print_exc()
        print(
            f"spectrageo {args.command}: internal error: {type(exc).__name__}: {exc} "
            "(set SPECTRAGEO_DEBUG=1 for the traceback)",
            file=sys.stderr,
        )
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
