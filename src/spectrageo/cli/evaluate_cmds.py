"""``spectrageo evaluate | demo``: the benchmark harness over the shared data, and a seeded demo on
the embedded fandisk."""

from __future__ import annotations

from pathlib import Path

from ._argtypes import seed_type
from ._common import apply_help, err

HELP = {
    "evaluate": (
        "Run methods and peers over the shared benchmark data; prints markdown tables and, with\n"
        "--out FILE, writes FILE.md and FILE.csv.",
        "spectrageo evaluate denoise --out results/denoise",
    ),
    "demo": (
        "Seeded Gaussian noise on the embedded fandisk, every denoiser, a metrics table and\n"
        "meshes plus an error heatmap in the output folder.",
        "spectrageo demo --out spectrageo-demo --level 0.3",
    ),
}


EVALUATIONS = (
    "denoise",
    "denoise-dynamic",
    "outliers",
    "saliency",
    "compress",
    "complete",
    "compress-animation",
    "register",
    "identify",
)


def cmd_evaluate(args) -> int:
    from ..datasets import data_dir

    data = Path(args.data) if args.data else data_dir(required=True)
    if not data.is_dir():
        raise err(f"`--data` must be a folder; got {data}.")
    methods = args.methods.split(",") if args.methods else None
    protocol = _generality_options(args)
    if args.what == "denoise" and protocol is not None:
        from ..evaluate import denoise as ev

        res = ev.evaluate_generality(
            data, **protocol, **({"methods": methods} if methods else {}), out=args.out
        )
        print(ev.format_generality(res))
        return 0
    before = _outputs(args.out)
    if args.what == "denoise":
        from ..evaluate import denoise as ev

        rows = ev.evaluate_denoise(data, methods=methods, out=args.out)
    elif args.what == "outliers":
        from ..evaluate import outliers as ev

        rows = ev.evaluate_outliers(
            data, **({"methods": tuple(methods)} if methods else {}), out=args.out
        )
    else:
        import importlib

        try:
            mod = {"complete": "completion"}.get(args.what, args.what.replace("-", "_"))
            ev = importlib.import_module(f"spectrageo.evaluate.{mod}")
        except ModuleNotFoundError as exc:
            raise err(f"no evaluation named {args.what!r}.") from exc
        kw = {}
        if args.what == "compress" and args.split is not None:
            kw["splits"] = ("tuning", "validation") if args.split == "both" else (args.split,)
        rows = ev.evaluate(data, methods=methods, out=args.out, **kw)
    if not rows:  # nothing of this area under --data: empty tables help no one
        for f in _outputs(args.out) - before:
            f.unlink(missing_ok=True)
        raise err(
            f"no {args.what} benchmark data found under {data} (its models and scans are "
            "read from the shared data folder's layout; see the README, Data and licences)."
        )
    print(ev.format_markdown(rows))
    return 0


def _outputs(out) -> set:
    """The files an evaluation writes for ``--out`` (``.md``, ``.csv``, ``.png``) that exist."""
    if not out:
        return set()
    base = Path(out)
    base = base.with_suffix("") if base.suffix in (".md", ".csv", ".png") else base
    return {f for f in (base.with_suffix(x) for x in (".md", ".csv", ".png")) if f.exists()}


def _generality_options(args) -> dict | None:
    """Keyword arguments of ``evaluate_generality`` from ``evaluate denoise --split ...``; None
    when no protocol option is given (then the pairs evaluation runs)."""
    given = {
        "--levels": args.levels,
        "--max-vertices": args.max_vertices,
        "--models": args.models,
        "--cli-timing": args.cli_timing or None,
        "--repeat": args.repeat,
    }
    if args.split is None:
        used = [k for k, v in given.items() if v is not None]
        if used:
            raise err(f"`{used[0]}` needs `--split tuning|validation|both` (evaluate denoise).")
        return None
    if args.what == "compress":  # the registry splits of the compress task
        used = [k for k, v in given.items() if v is not None]
        if used:
            raise err(f"`{used[0]}` applies to `evaluate denoise --split` only.")
        return None
    if args.what != "denoise":
        raise err(
            f"`--split` applies to `evaluate denoise` and `compress` only; got {args.what!r}."
        )
    opts: dict = {"split": args.split, "cli_timing": bool(args.cli_timing)}
    if args.repeat is not None:
        opts["repeat"] = args.repeat  # checked by evaluate_generality
    if args.levels:
        try:
            opts["levels"] = [float(x) for x in args.levels.split(",")]
        except ValueError as exc:
            raise err(f"`--levels` must be comma-separated numbers; got {args.levels!r}.") from exc
    if args.max_vertices is not None:
        opts["max_vertices"] = args.max_vertices
    if args.models:
        opts["models"] = args.models.split(",")
    return opts


def cmd_demo(args) -> int:
    from ..noise._core import check_level
    from .demo import run_demo

    check_level(args.level)  # before the output folder is created
    if args.methods:
        from .. import denoise

        for m in args.methods.split(","):
            denoise.get(m)

    run_demo(
        out_dir=Path(args.out),
        level=args.level,
        seed=args.seed,
        methods=args.methods.split(",") if args.methods else None,
    )
    return 0


def register(sub) -> None:
    """Add ``evaluate`` and ``demo``."""
    p = sub.add_parser("evaluate", help="run methods on the shared benchmark data and print tables")
    p.add_argument("what", choices=EVALUATIONS, metavar="AREA", help=" | ".join(EVALUATIONS))
    p.add_argument(
        "--data", default=None, help="data folder (default: $SPECTRAGEO_DATA or ../shared/data)"
    )
    p.add_argument("--methods", default=None, help="comma-separated method names")
    p.add_argument("--out", default=None, help="write FILE.md and FILE.csv")
    g = p.add_argument_group("denoise generality protocol (evaluate denoise only)")
    g.add_argument(
        "--split",
        default=None,
        choices=("tuning", "validation", "both"),
        help="denoise: run the protocol on this split instead of the shared pairs (also writes "
        "FILE_grid.csv and FILE.png); compress: only this split's models",
    )
    g.add_argument("--levels", default=None, help="noise levels, e.g. 0.1,0.3,0.5 (the default)")
    g.add_argument("--max-vertices", type=int, default=None, help="skip models with more vertices")
    g.add_argument("--models", default=None, help="comma-separated models, e.g. partLp,cad/joint")
    g.add_argument(
        "--cli-timing",
        action="store_true",
        help="also time `spectrageo denoise` processes for the package's methods",
    )
    g.add_argument(
        "--repeat",
        type=int,
        default=None,
        help="report the best of N timings of the package's methods (default 1)",
    )
    p.set_defaults(func=cmd_evaluate)

    p = sub.add_parser("demo", help="noise + every denoiser on the embedded fandisk, with metrics")
    p.add_argument(
        "--out", default="spectrageo-demo", help="output folder (default ./spectrageo-demo)"
    )
    p.add_argument(
        "--level", type=float, default=0.3, help="noise level relative to the mean edge length"
    )
    p.add_argument("--seed", type=seed_type, default=0)
    if getattr(p, "summary", False):  # `spectrageo --help` shows no option: no denoiser list
        static = []
    else:
        from .. import denoise

        static = denoise.available()
    p.add_argument("--methods", default=None, help=f"comma-separated subset of {', '.join(static)}")
    p.set_defaults(func=cmd_demo)
    apply_help(sub, HELP)
