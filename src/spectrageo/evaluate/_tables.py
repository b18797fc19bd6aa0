"""Output helpers shared by the evaluation harnesses: CSV text and atomic ``.md`` + ``.csv`` files."""

from __future__ import annotations

import csv
import io as _io
from collections.abc import Iterable, Sequence
from pathlib import Path


def rows_to_csv(rows: Iterable[dict], columns: Sequence[str]) -> str:
    """CSV text of ``rows`` restricted to ``columns`` (full precision; missing keys left empty)."""
    buf = _io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(columns), lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({c: r.get(c) for c in columns})
    return buf.getvalue()


def write_md_csv(out, markdown: str, csv_text: str) -> tuple[Path, Path]:
    """Write ``<out>.md`` and ``<out>.csv`` atomically (``out`` may end in .md or .csv).

    Creates the parent folder; returns both paths.
    """
    from ..io import atomic_write

    out = Path(out)
    if out.suffix in (".md", ".csv"):
        out = out.with_suffix("")
    out.parent.mkdir(parents=True, exist_ok=True)
    md, cs = out.with_name(out.name + ".md"), out.with_name(out.name + ".csv")
    with atomic_write(md) as tmp:
        Path(tmp).write_text(markdown.rstrip() + "\n", encoding="utf-8")
    with atomic_write(cs) as tmp:
        Path(tmp).write_text(csv_text, encoding="utf-8")
    return md, cs


def check_names(given, allowed: Sequence[str], what: str) -> tuple[str, ...]:
    """``given`` as a tuple, or an :class:`InvalidInputError` naming the unknown entries and the
    allowed ones (``what``: "method", "split", ...)."""
    from .._errors import InvalidInputError

    given = tuple(given)
    bad = [g for g in given if g not in allowed]
    if bad:
        raise InvalidInputError(f"unknown {what}(s) {bad}; choose from {list(allowed)}.")
    return given


def markdown_table(rows: Iterable[dict], columns: Sequence[str]) -> list[str]:
    """Lines of a markdown table of ``rows`` over ``columns`` (cells by :func:`fmt_cell`)."""
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    for r in rows:
        lines.append("| " + " | ".join(fmt_cell(r.get(c)) for c in columns) + " |")
    return lines


def write_rate_outputs(out, markdown: str, rows: list[dict], columns: Sequence[str], **plot):
    """``<out>.md`` + ``<out>.csv`` (:func:`write_md_csv`) and ``<out>.png`` with the rate curves
    of :func:`plot_rate_curves` (``plot``: its keyword arguments)."""
    md, _ = write_md_csv(out, markdown, rows_to_csv(rows, columns))
    plot_rate_curves(rows, md.with_suffix(".png"), **plot)
    return md


#: messages of a codec's rate control when a request lies outside what it can give
_UNMET = ("cannot be reached", "could not be met", "is below what method")


def unmet_request(exc: Exception) -> bool:
    """True when ``exc`` says a rate or error request cannot be met (a point to leave out of a
    rate curve); any other error, e.g. a file that does not decode, is a fault to report."""
    return any(m in str(exc) for m in _UNMET)


def rate_at_error(points, e: float) -> float:
    """Rate at error ``e`` on a rate curve ``[(rate, error)]``, linear in log-log (sorted by
    error); NaN outside the curve's range (no extrapolation) or with fewer than two usable
    points."""
    import numpy as np

    pts = sorted(
        (float(err), float(r))
        for r, err in points
        if r is not None and err is not None and np.isfinite(err) and err > 0
    )
    if len(pts) < 2 or not pts[0][0] <= e <= pts[-1][0]:
        return float("nan")
    le = np.log([p[0] for p in pts])
    lr = np.log([p[1] for p in pts])
    return float(np.exp(np.interp(np.log(e), le, lr)))


def have(module: str) -> bool:
    """True when ``module`` imports (optional peers and plotting)."""
    try:
        __import__(module)
    except Exception:  # noqa: BLE001 - any import failure means "not available"
        return False
    return True


def fmt_cell(v) -> str:
    """A table cell: yes/no for booleans, 3 significant digits for floats, '-' for NaN/inf."""
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        if v != v or v in (float("inf"), float("-inf")):
            return "-"
        return f"{v:.3g}" if abs(v) < 1e4 else f"{v:.0f}"
    return str(v)


def pyplot():
    """``matplotlib.pyplot`` on the non-interactive Agg backend, or None without matplotlib."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except Exception:  # noqa: BLE001 - plotting is optional
        return None
    return plt


def save_png(fig, png) -> Path:
    """Write ``fig`` atomically to ``png`` (110 dpi) and close it; returns the path."""
    from ..io import atomic_write

    plt = pyplot()
    with atomic_write(png) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)
    return Path(png)


def write_section(out, heading: str, intro: str, body: str, csv_text: str) -> tuple[Path, Path]:
    """``<out>.md`` (a BENCHMARKS.md section: ``## heading``, ``intro``, ``body``) and
    ``<out>.csv``, atomically (:func:`write_md_csv`)."""
    return write_md_csv(out, f"## {heading}\n\n{intro}\n\n{body}\n", csv_text)


def plot_rate_curves(rows: list[dict], png, *, x: str, y: str, xlabel: str, ylabel: str):
    """Log-log ``y`` vs ``x`` per model, one curve per method, written atomically to ``png``;
    returns the path, or None without matplotlib or rows."""
    plt = pyplot()
    if plt is None:
        return None

    models = list(dict.fromkeys(r["model"] for r in rows))
    if not models:
        return None
    cols = min(3, len(models))
    nrows = -(-len(models) // cols)
    fig, axes = plt.subplots(nrows, cols, figsize=(5 * cols, 4 * nrows), squeeze=False)
    for ax, model in zip(axes.ravel(), models):
        for m in dict.fromkeys(r["method"] for r in rows if r["model"] == model):
            pts = sorted((r[x], r[y]) for r in rows if r["model"] == model and r["method"] == m)
            ax.loglog(*zip(*pts), marker="o", label=m)
        ax.set_title(model)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    for ax in axes.ravel()[len(models) :]:
        ax.axis("off")
    fig.tight_layout()
    return save_png(fig, png)
