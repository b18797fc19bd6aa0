"""The package's architecture, checked from its source.

Every import between files of ``src/spectrageo`` (module-level and function-level alike) must run
downward through the layers below, and no two files may import each other, directly or through
others. Modules stay below 900 lines, public functions take at most 12 parameters, and docstrings
stay at most 12 % of the source lines.

Layers, lowest first (a package may import only packages of a strictly lower rank; files inside one
package may import each other as long as they form no cycle)::

    0  _errors                                                  the error hierarchy
    0.5 _validation, _progress, _device, _colormap, _plugins,   base helpers
        _threads
    1  geometry                                                 data types, primitives, kNN
    1.5 spectrageo (the package root: errors and data types)
    2  graph, io                                                graphs and Laplacians; format registry
    3  linalg, datasets                                          solvers; shipped and shared data
    4  spectral, metrics, noise                                  GFT and filters; measures; corruption
    5  denoise, outliers, complete                               application areas
    6  saliency                                                  saliency and TSGSP's saliency variant
    7  compress, register                                        codecs (registered into io); registration
    8  evaluate                                                  the harness
    9  learn                                                     models, training, shipped weights
    10 distributed                                               Dask mapping of library tasks
    10.5 viewer, 11 cli                                          shells over the API (cli may
                                                                 start the viewer; nothing else
                                                                 imports either)
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
PKG = SRC / "spectrageo"

RANK = {
    "_errors": 0,
    "_validation": 0.5,
    "_progress": 0.5,
    "_threads": 0.5,
    "_device": 0.5,
    "_colormap": 0.5,
    "_plugins": 0.5,
    "geometry": 1,
    "": 1.5,
    "graph": 2,
    "io": 2,
    "linalg": 3,
    "datasets": 3,
    "spectral": 4,
    "metrics": 4,
    "noise": 4,
    "denoise": 5,
    "outliers": 5,
    "complete": 5,
    "saliency": 6,
    "compress": 7,
    "register": 7,
    "evaluate": 8,
    "learn": 9,
    "distributed": 10,
    "viewer": 10.5,
    "cli": 11,
}

MAX_LINES = 900
MAX_PARAMS = 12
MAX_DOC_SHARE = 0.12


def _modules() -> dict[str, Path]:
    mods = {}
    for path in sorted(PKG.rglob("*.py")):
        parts = list(path.relative_to(SRC).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        mods[".".join(parts)] = path
    return mods


MODULES = _modules()


def _resolve(name: str) -> str | None:
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def _imports(module: str, path: Path) -> set[str]:
    """Every ``spectrageo`` module that ``module`` imports, wherever the import statement sits."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    is_pkg = path.name == "__init__.py"
    found = set()
    for node in ast.walk(tree):
        names = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".")
                if not is_pkg:
                    base = base[:-1]
                base = base[: len(base) - (node.level - 1)]
                stem = ".".join(base + ([node.module] if node.module else []))
            else:
                stem = node.module or ""
            for alias in node.names:
                full = f"{stem}.{alias.name}"
                names.append(full if full in MODULES else stem)
        for name in names:
            if name.split(".")[0] != "spectrageo":
                continue
            target = _resolve(name)
            if target and target != module:
                found.add(target)
    return found


GRAPH = {m: _imports(m, p) for m, p in MODULES.items()}


def _package(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def _cycles() -> list[list[str]]:
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in GRAPH[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(GRAPH):
        if v not in index:
            visit(v)
    return out


def test_every_package_has_a_rank():
    missing = sorted({_package(m) for m in MODULES} - set(RANK))
    assert not missing, f"packages without a layer rank in tests/test_layers.py: {missing}"


def test_no_import_cycles_between_files():
    cycles = _cycles()
    assert not cycles, "import cycles:\n" + "\n".join(" <-> ".join(c) for c in cycles)


def test_imports_run_down_the_layers():
    upward = []
    for source, targets in GRAPH.items():
        for target in targets:
            a, b = _package(source), _package(target)
            if a != b and RANK[a] <= RANK[b]:
                upward.append(f"{source} (rank {RANK[a]}) imports {target} (rank {RANK[b]})")
    assert not upward, "imports that do not run downward:\n" + "\n".join(sorted(upward))


def test_modules_stay_small():
    big = {}
    for module, path in MODULES.items():
        n = len(path.read_text(encoding="utf-8").splitlines())
        if n > MAX_LINES:
            big[module] = n
    assert not big, f"modules over {MAX_LINES} lines: {big}"


def _exported_names() -> set[tuple[str, str]]:
    """(package, name) for every name a package ``__init__`` imports from its own modules."""
    out = set()
    for module, path in MODULES.items():
        if path.name != "__init__.py":
            continue
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            if isinstance(node, ast.ImportFrom) and node.level:
                out.update((module, alias.asname or alias.name) for alias in node.names)
    return out


def _public_functions():
    """Functions a user can reach: public names in public modules, and names a package exports."""
    exported = {name for _, name in _exported_names()}
    for module, path in MODULES.items():
        private_module = any(part.startswith("_") for part in module.split(".")[1:])
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if not isinstance(
                node, (ast.FunctionDef, ast.AsyncFunctionDef)
            ) or node.name.startswith("_"):
                continue
            if not private_module or node.name in exported:
                yield module, node


def test_public_functions_take_few_parameters():
    wide = []
    for module, node in _public_functions():
        a = node.args
        params = [
            p.arg for p in a.posonlyargs + a.args + a.kwonlyargs if p.arg not in ("self", "cls")
        ]
        if len(params) > MAX_PARAMS:
            wide.append(f"{module}.{node.name}: {len(params)}")
    assert not wide, f"public functions with more than {MAX_PARAMS} parameters: {wide}"


def _docstring_lines(path: Path) -> tuple[int, int]:
    text = path.read_text(encoding="utf-8")
    tree = ast.parse(text)
    doc = 0
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                if isinstance(body[0].value.value, str):
                    doc += body[0].end_lineno - body[0].lineno + 1
    return doc, len(text.splitlines())


def test_docstrings_document_without_dominating():
    doc = total = 0
    for path in MODULES.values():
        d, n = _docstring_lines(path)
        doc += d
        total += n
    share = doc / total
    assert share <= MAX_DOC_SHARE, f"docstrings are {share:.1%} of src lines ({doc}/{total})"


@pytest.mark.parametrize("module", ["spectrageo.cli", "spectrageo.viewer"])
def test_library_never_imports_the_shells(module):
    importers = sorted(
        s
        for s, t in GRAPH.items()
        if any(x == module or x.startswith(module + ".") for x in t)
        and not (s == module or s.startswith(module + "."))
    )
    allowed = {"spectrageo.__main__"} | (
        {"spectrageo.cli"} if module == "spectrageo.viewer" else set()
    )
    outside = [s for s in importers if not any(s == a or s.startswith(a + ".") for a in allowed)]
    assert not outside, f"{module} imported by {outside}"
