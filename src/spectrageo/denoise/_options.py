"""Old keyword arguments of :func:`~spectrageo.denoise.tsgsp.tsgsp` mapped onto its options."""

from __future__ import annotations

import dataclasses
import warnings


def take_fields(cls, options, legacy: dict, func: str, param: str):
    """``options`` (a ``cls`` or None) with the fields of ``cls`` found in ``legacy`` (popped)
    replaced; a DeprecationWarning names ``param=cls(...)``."""
    names = {f.name for f in dataclasses.fields(cls)}
    given = {k: legacy.pop(k) for k in list(legacy) if k in names}
    if not given:
        return options
    warnings.warn(
        f"{func}(..., {', '.join(f'{k}=' for k in given)}) is deprecated; pass "
        f"{param}={cls.__name__}({', '.join(f'{k}=...' for k in given)}) instead.",
        DeprecationWarning,
        stacklevel=4,
    )
    return dataclasses.replace(options or cls(), **given)
