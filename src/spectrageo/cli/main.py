"""``spectrageo`` command line: argument parsing, dispatch and error reporting.

User mistakes (bad files, bad options) print one line on stderr and exit with status 2; unexpected
failures print one line and exit with status 1 (set ``SPECTRAGEO_DEBUG=1`` for the traceback).
"""

from __future__ import annotations

import argparse
import functools
import importlib
import os
import re
import sys
import traceback
import warnings

from .._errors import SpectrageoError
from ._common import set_quiet

#: The command groups in ``spectrageo --help`` order, with the sub-commands each module's
#: ``register(sub)`` adds. A command line that names one of them builds that group's parser only,
#: so a command does not import the packages of the others (``tests/test_cli.py`` checks the
#: names against what the modules register).
COMMAND_GROUPS = {
    "file_cmds": ("info", "convert", "noise", "metrics"),
    "denoise_cmds": ("denoise", "outliers", "robot"),
    "evaluate_cmds": ("evaluate", "demo"),
    "saliency_cmds": ("saliency", "features", "curves", "simplify", "inspect"),
    "view_cmd": ("view",),
    "compress_cmds": ("compress", "decompress"),
    "complete_cmds": ("complete",),
    "batch_cmds": ("batch",),
    "register_cmds": ("register",),
    "identify_cmds": ("identify",),
    "learn_cmds": ("train",),
}


def _group(name: str):
    return importlib.import_module(f"{__package__}.{name}")


class _Formatter(argparse.RawDescriptionHelpFormatter, argparse.ArgumentDefaultsHelpFormatter):
    """Keeps the line breaks of descriptions and examples and shows every option's default."""

    def _get_help_string(self, action):  # no "(default: None)" / "(default: False)" noise
        if action.default in (None, False) or action.default is argparse.SUPPRESS:
            return action.help
        if action.help and "default" in action.help:
            return action.help
        return super()._get_help_string(action)


class _Parser(argparse.ArgumentParser):
    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", _Formatter)
        super().__init__(*args, **kwargs)

    def error(self, message: str):  # one line, exit 2, like every other user mistake
        self.exit(2, f"{self.prog}: error: {message}\n")


class _SummaryParser(_Parser):
    """A parser for ``spectrageo --help`` and ``--version``: its sub-commands' options skip the
    help texts and choices that functions compute (``add_schema_options``;
    docs/decisions.md#register-cli-startup)."""

    summary = True


#: first words after which argparse prints and exits before any sub-command parses
_TOP_ONLY = ("-h", "--help", "--version")


def build_parser(command: str | None = None, *, summary: bool = False) -> argparse.ArgumentParser:
    """The ``spectrageo`` parser: every command, or only the group of ``command`` when it names
    one (the parser a command line needs). ``summary=True`` builds every command for the
    top-level help only (see :class:`_SummaryParser`)."""
    groups = [g for g, names in COMMAND_GROUPS.items() if command in names] or list(COMMAND_GROUPS)
    cls = _SummaryParser if summary else _Parser
    p = cls(
        prog="spectrageo",
        description="Spectral processing of static and dynamic 3D geometry.",
        epilog="Run 'spectrageo COMMAND --help' for a command's options and an example.",
    )
    p.add_argument("--version", action="version", version=_version())
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=cls)
    for g in groups:
        _group(g).register(sub)
    for sp in sub.choices.values():
        if not any("--quiet" in a.option_strings for a in sp._actions):
            sp.add_argument(
                "-q",
                "--quiet",
                action="store_true",
                help="no progress display and no status lines on stderr (errors still print)",
            )
    return p


def _option_names(parser: argparse.ArgumentParser, command: str) -> dict[str, str]:
    """``dest -> --option`` of a sub-command, to word library messages in CLI terms."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction) and command in action.choices:
            sp = action.choices[command]
            out = {}
            for a in sp._actions:
                if isinstance(a, argparse._SubParsersAction):  # `batch denoise`, ...: theirs too
                    for sub in a.choices.values():
                        out.update(
                            {
                                b.dest: max(b.option_strings, key=len)
                                for b in sub._actions
                                if b.option_strings
                            }
                        )
            out.update(
                {a.dest: max(a.option_strings, key=len) for a in sp._actions if a.option_strings}
            )
            return out
    return {}


_BACKTICKED = re.compile(r"`([A-Za-z_][A-Za-z0-9_]*)`")


def cli_message(message: str, options: dict[str, str]) -> str:
    """Replace a Python argument name in backticks with the command's option (`patch` -> --patch).

    Names the command has no option for are left as they are. The reader's advice to pass
    ``nan_points='drop'`` (a Python argument no command has) becomes advice a command line can
    follow.
    """
    message = message.replace(
        "pass nan_points='drop' to drop them.",
        "this command needs every row; remove those rows first (`spectrageo outliers`, "
        "`register` and `identify` leave them out).",
    )
    return _BACKTICKED.sub(
        lambda m: options[m.group(1)] if m.group(1) in options else m.group(0), message
    )


def _version() -> str:
    from .. import __version__

    return f"spectrageo {__version__}"


def main(argv: list[str] | None = None) -> int:
    args_in = sys.argv[1:] if argv is None else list(argv)
    first = args_in[0] if args_in else None
    parser = build_parser(first, summary=first is None or first in _TOP_ONLY)
    args = parser.parse_args(args_in)
    if not getattr(args, "command", None):
        parser.print_help(sys.stderr)
        return 2
    from .. import _progress

    quiet = bool(getattr(args, "quiet", False))
    _progress.QUIET = quiet
    set_quiet(quiet)
    with warnings.catch_warnings():
        # warnings are one line each, like errors: "spectrageo CMD: warning: ..."
        warnings.showwarning = functools.partial(_show_warning, args.command)
        return _run(parser, args)


def _show_warning(command, message, category, filename, lineno, file=None, line=None):
    from .. import _errors

    ours = issubclass(category, _errors.RepairWarning | _errors.ConvergenceWarning)
    kind = "warning" if ours else f"warning ({category.__name__})"
    text = " ".join(str(message).split())
    print(f"spectrageo {command}: {kind}: {text}", file=sys.stderr)


def _run(parser: argparse.ArgumentParser, args) -> int:
    try:
        return int(args.func(args) or 0)
    except SpectrageoError as exc:
        msg = cli_message(str(exc), _option_names(parser, args.command))
        print(f"spectrageo {args.command}: error: {msg}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # `spectrageo info --json | head`: the reader went away, not an error
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        except OSError:
            pass
        return 0
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
