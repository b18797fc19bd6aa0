"""Run the ``spectrageo`` command line in a subprocess under the limits of the hostile-input tests.

Each run gets ``RLIMIT_AS`` = 4 GiB (address space), no core dumps and a wall-clock timeout, so that
a native crash, a runaway allocation or a hang in a reader ends the child, never pytest. Outcomes
follow the contract of the issue "Hardening against hostile input": exit 0 (valid output), or exit
2 with exactly one line on stderr; never exit 1 (internal error), never a signal, never a timeout.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import time
from dataclasses import dataclass, field

LIMIT_AS = 4 * 1024**3
TIME_LIMIT = 20.0

_CLI = "import sys; from spectrageo.cli.main import main; sys.exit(main())"


def limit_resources() -> None:
    """``preexec_fn`` of the child: 4 GiB of address space and no core file."""
    resource.setrlimit(resource.RLIMIT_AS, (LIMIT_AS, LIMIT_AS))
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))


def child_env() -> dict[str, str]:
    env = dict(os.environ)
    env.pop("SPECTRAGEO_DEBUG", None)  # tracebacks would add stderr lines
    return env


@dataclass
class Outcome:
    """What one CLI run did: return code (negative = killed by that signal; None = timed out)."""

    code: int | str | None
    lines: list[str] = field(default_factory=list)
    stdout: str = ""
    seconds: float = 0.0

    def describe(self) -> str:
        first = self.lines[0][:160] if self.lines else ""
        return f"exit {self.code}, {len(self.lines)} stderr line(s), {self.seconds:.1f} s: {first}"


def run_cli(args: list[str], *, timeout: float = TIME_LIMIT, cwd=None) -> Outcome:
    """``spectrageo ARGS`` in a fresh interpreter under :func:`limit_resources`."""
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(
            [sys.executable, "-c", _CLI, *args],
            capture_output=True,
            timeout=timeout,
            preexec_fn=limit_resources,
            env=child_env(),
            cwd=cwd,
        )
    except subprocess.TimeoutExpired:
        return Outcome(None, ["timeout"], "", time.perf_counter() - t0)
    lines = [ln for ln in proc.stderr.decode("utf-8", "replace").splitlines() if ln.strip()]
    return Outcome(
        proc.returncode, lines, proc.stdout.decode("utf-8", "replace"), time.perf_counter() - t0
    )


def contract_violation(out: Outcome, *, json_expected: bool = True) -> str | None:
    """None when ``out`` keeps the contract, else a short description of the violation."""
    import json

    if out.code is None:
        return "timeout"
    if out.seconds > TIME_LIMIT:
        return f"took {out.seconds:.1f} s"
    if out.code == 0:
        if json_expected:
            try:
                json.loads(out.stdout)
            except ValueError:
                return "exit 0 with invalid JSON"
        return None
    if out.code == 2:
        return None if len(out.lines) == 1 else f"exit 2 with {len(out.lines)} stderr lines"
    if isinstance(out.code, int) and out.code < 0:
        return f"killed by signal {-out.code}"
    return f"exit {out.code}"
