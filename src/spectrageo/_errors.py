"""Exception and warning hierarchy; every deliberate error is a :class:`SpectrageoError`."""

from __future__ import annotations

from typing import Any


class SpectrageoError(Exception):
    """Base class of every error raised on purpose by spectrageo."""


class InvalidInputError(SpectrageoError, ValueError):
    """An argument, array or file content is not acceptable (wrong shape, NaN, bad index...)."""


class UnsupportedFormatError(InvalidInputError):
    """A file extension or format variant that spectrageo cannot read or write."""


class ConvergenceError(SpectrageoError, RuntimeError):
    """An iterative solver did not converge; ``partial`` holds the last iterate's result."""

    def __init__(self, message: str, partial: Any = None) -> None:
        super().__init__(message)
        self.partial = partial


class ConvergenceWarning(UserWarning):
    """An iterative solver stopped at ``max_iter`` before meeting its tolerance."""


class RepairWarning(UserWarning):
    """Input was repaired according to a documented policy (e.g. degenerate faces dropped)."""
