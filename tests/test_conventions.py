"""The package's conventions (docs/conventions.md), checked on the code itself.

Each test reads the package (its source with ``ast``, or its public callables with
``inspect``) and fails naming every place that breaks a convention, so a new module
is held to the same rules as the old ones.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import pathlib
import pkgutil
import re
import sys
import types
from collections.abc import Callable, Iterator, Sequence

import pytest

import manifold_sph
from manifold_sph.results import Result

ROOT = pathlib.Path(manifold_sph.__file__).resolve().parent
REPO = ROOT.parent
SOURCES = sorted(p for p in ROOT.rglob("*.py") if "__pycache__" not in p.parts)

#: The core follows the pipeline and never imports the periphery at module level.
PERIPHERY = ("manifold_sph.viz", "manifold_sph.cli", "manifold_sph.spem", "manifold_sph.distributed",
             "manifold_sph.mpi")
CORE = ("manifold_sph.pointcloud", "manifold_sph.neighbors", "manifold_sph.frames", "manifold_sph.kernels",
        "manifold_sph.schemes", "manifold_sph.assembly", "manifold_sph.area", "manifold_sph.voronoi",
        "manifold_sph.operators", "manifold_sph.surface", "manifold_sph.domain", "manifold_sph.normals",
        "manifold_sph.solvers", "manifold_sph.pde", "manifold_sph.geometry")

#: Words that tell the history of the code instead of what it does (that belongs in CHANGELOG.md,
#: docs/ or a commit message).
HISTORY = re.compile(r"\bformerly\b|\bwas \d|\(was\b|\bissues? #?\d+\b|\bsince 0\.\d|\buntil 0\.\d|\bdeprecated\b",
                     re.IGNORECASE)

#: Longest module, in lines (one concept a module; a table or one class may run longer, never this long).
MAX_LINES = 1000


def _module_name(path: pathlib.Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _resolve(module: str, is_package: bool, node: ast.ImportFrom) -> str:
    if not node.level:
        return node.module or ""
    base = module.split(".")
    base = base if is_package else base[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _module_level_imports(path: pathlib.Path) -> set[str]:
    """Modules imported at module level (not inside functions, not under ``if TYPE_CHECKING``)."""
    module = _module_name(path)
    tree = ast.parse(path.read_text(encoding="utf-8"))
    out: set[str] = set()

    def visit(body):
        for node in body:
            if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
                continue
            if isinstance(node, (ast.If, ast.Try)):
                visit(node.body)
                visit(getattr(node, "orelse", []))
                for h in getattr(node, "handlers", []):
                    visit(h.body)
                continue
            if isinstance(node, ast.Import):
                out.update(a.name for a in node.names)
            elif isinstance(node, ast.ImportFrom):
                target = _resolve(module, path.name == "__init__.py", node)
                out.add(target)
                # "from . import x" names submodules
                out.update(f"{target}.{a.name}" for a in node.names)

    visit(tree.body)
    return {m for m in out if m.startswith("manifold_sph")}


def _graph() -> dict[str, set[str]]:
    modules = {_module_name(p): p for p in SOURCES}
    graph = {}
    for name, path in modules.items():
        graph[name] = {m for m in _module_level_imports(path) if m in modules and m != name}
    return graph


def test_the_import_graph_has_no_cycles():
    graph = _graph()
    # a package's __init__ importing its own modules is not a cycle with them
    edges = {a: {b for b in bs if not a == b.rsplit(".", 1)[0] and not b.startswith(a + ".")} for a, bs in graph.items()}
    index, low, stack, on, cycles, counter = {}, {}, [], set(), [], [0]

    def strong(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges[v]:
            if w not in index:
                strong(w)
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
                cycles.append(sorted(comp))

    for v in edges:
        if v not in index:
            strong(v)
    assert cycles == [], f"import cycles at module level: {cycles}"


def test_the_core_does_not_import_the_periphery():
    bad = []
    for name, deps in _graph().items():
        if name.startswith(CORE):
            bad += [f"{name} -> {d}" for d in deps if d.startswith(PERIPHERY)]
    assert bad == [], bad


def test_no_private_name_is_imported_from_another_module():
    """A name two modules use is public in one of them (benchmarks and examples included)."""
    files = SOURCES + sorted((REPO / "benchmarks").glob("*.py")) + sorted((REPO / "examples").glob("*.py"))
    bad = []
    for path in files:
        tree = ast.parse(path.read_text(encoding="utf-8"))
        module = _module_name(path) if path.is_relative_to(ROOT) else ""
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                target = _resolve(module, path.name == "__init__.py", node) if module else (node.module or "")
                if not target.startswith("manifold_sph") and not node.level:
                    continue
                for a in node.names:
                    submodule = REPO.joinpath(*f"{target}.{a.name}".split("."))
                    if submodule.with_suffix(".py").exists() or submodule.is_dir():
                        continue  # a private module imported whole (an implementation module of the package)
                    if a.name.startswith("_") and not a.name.startswith("__"):
                        bad.append(f"{path.relative_to(REPO)}:{node.lineno} imports {a.name} from {target}")
    assert bad == [], "\n".join(bad)


def test_modules_are_short_and_tell_no_history():
    long_ = [f"{p.relative_to(REPO)}: {n} lines" for p in SOURCES
             if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_LINES]
    history = [f"{p.relative_to(REPO)}:{i}: {line.strip()[:100]}" for p in SOURCES
               for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1) if HISTORY.search(line)]
    assert long_ == [], long_
    assert history == [], "\n".join(history)


def _public_callables():
    """(qualified name, callable) of every public function and method of every public module."""
    seen = set()
    for info in pkgutil.walk_packages(manifold_sph.__path__, "manifold_sph."):
        if any(part.startswith("_") for part in info.name.split(".")) or ".cli" in info.name:
            continue
        mod = importlib.import_module(info.name)
        for name, obj in vars(mod).items():
            if name.startswith("_") or getattr(obj, "__module__", None) != mod.__name__:
                continue
            if isinstance(obj, types.FunctionType):
                if obj not in seen:
                    seen.add(obj)
                    yield f"{mod.__name__}.{name}", obj
            elif isinstance(obj, type):
                for mname, m in vars(obj).items():
                    if mname.startswith("_") and mname != "__init__":
                        continue
                    if isinstance(m, (staticmethod, classmethod)):
                        m = m.__func__
                    if isinstance(m, types.FunctionType) and m not in seen:
                        seen.add(m)
                        yield f"{mod.__name__}.{name}.{mname}", m


@pytest.fixture(scope="module")
def public_callables():
    return list(_public_callables())


def test_k_is_only_ever_a_count(public_callables):
    """``k`` counts neighbours or eigenpairs; a diffusivity is ``diffusivity=``, a speed ``c=``."""
    bad = []
    for qual, fn in public_callables:
        p = inspect.signature(fn).parameters.get("k")
        if p is None:
            continue
        ann = str(p.annotation)
        if "int" not in ann or "float" in ann:
            bad.append(f"{qual}: k: {ann}")
    assert bad == [], bad


def test_one_keyword_for_snapshots_and_one_for_probes(public_callables):
    bad = []
    for qual, fn in public_callables:
        names = set(inspect.signature(fn).parameters)
        bad += [f"{qual}({n}=)" for n in names & {"snapshot_every", "frames", "save_every", "probe"}]
    assert bad == [], f"use every= for snapshots and probes= for probes: {bad}"


def test_every_to_dict_comes_from_the_result_base(public_callables):
    bad = [qual for qual, fn in public_callables
           if qual.endswith(".to_dict") and not qual.startswith("manifold_sph.results.")]
    assert bad == [], f"results derive from manifold_sph.results.Result instead of writing to_dict: {bad}"
    for info in pkgutil.walk_packages(manifold_sph.__path__, "manifold_sph."):
        if ".cli" in info.name or info.name.endswith("__main__"):
            continue
        mod = importlib.import_module(info.name)
        for name, obj in vars(mod).items():
            if isinstance(obj, type) and name.endswith("Result") and getattr(obj, "__module__", "") == mod.__name__:
                assert issubclass(obj, Result), f"{mod.__name__}.{name} does not derive from results.Result"


def _entry_points():
    """The everyday entry points (README's tasks): data first, options keyword-only."""
    from manifold_sph import geometry, pde
    from manifold_sph.normals import estimate_normals
    from manifold_sph.viz import render

    S = manifold_sph.Surface
    out = {"Surface": S, "Domain2D": manifold_sph.Domain2D, "as_cloud": manifold_sph.as_cloud, "read": manifold_sph.read,
           "write": manifold_sph.write, "estimate_normals": estimate_normals, "render_field": render.render_field,
           "animate": render.animate, "show": render.show}
    for name in ("laplacian", "laplacian_matrix", "gradient", "divergence", "eigs", "mean_curvature",
                 "principal_curvatures", "geodesic_distance", "smooth", "transport", "log_map", "report"):
        out[f"Surface.{name}"] = getattr(S, name)
    for mod in (pde, geometry):
        for name in getattr(mod, "__all__", []):
            obj = getattr(mod, name)
            if inspect.isfunction(obj) or (inspect.isclass(obj) and not issubclass(obj, Result)):  # results: built by us
                out[f"{mod.__name__}.{name}"] = obj
    return out


def test_entry_points_take_options_by_keyword():
    """At most one optional argument by position (``normals``, ``k``, ``field``, ``form``): the rest keyword-only,
    so that options can be added and reordered without breaking a call."""
    bad = []
    for name, fn in _entry_points().items():
        params = [p for p in inspect.signature(fn).parameters.values() if p.name not in ("self", "cls")]
        pos = [p.name for p in params if p.kind == p.POSITIONAL_OR_KEYWORD and p.default is not p.empty]
        if len(pos) > 1:
            bad.append(f"{name}({', '.join(pos)})")
    assert len(_entry_points()) > 30 and bad == [], bad


# ----------------------------------------------------------------------------- annotations
# The package ships ``py.typed``, so type checkers trust its signatures: a public function with a
# missing parameter or return annotation reads as ``Any`` to users. mypy cannot hold that rule
# (``disallow_incomplete_defs`` also flags private helpers), so this walks every module with
# :mod:`inspect` (no evaluation of the annotations: names imported under ``TYPE_CHECKING`` are
# fine) and names every unannotated parameter or return.

#: Modules of compiled (numba) kernels, left out: numba ignores annotations and compiles one
#: specialisation per argument type, and the kernels are the compiled twins of typed numpy
#: functions, called only from the package's typed functions.
COMPILED = ("manifold_sph._jit", "manifold_sph.spem.compiled")

#: Module-level dunders that are part of a module's interface (PEP 562).
MODULE_DUNDERS = {"__getattr__", "__dir__"}


def _is_dunder(name: str) -> bool:
    return len(name) > 4 and name.startswith("__") and name.endswith("__")


def _is_public(name: str) -> bool:
    """Public names, and the special methods (``__init__``, ``__call__``, ``__repr__``, ...)."""
    return not name.startswith("_") or _is_dunder(name)


def _defined_here(obj: object, module: str) -> bool:
    return getattr(obj, "__module__", None) == module


def _class_callables(cls: type, module: str) -> Iterator[tuple[str, Callable[..., object], bool]]:
    """(qualified name, function, is_method) for the callables a class defines itself."""
    for name, attr in vars(cls).items():
        if not _is_public(name):
            continue
        qual = f"{cls.__module__}.{cls.__qualname__}.{name}"
        if isinstance(attr, property):
            for role, fn in (("fget", attr.fget), ("fset", attr.fset), ("fdel", attr.fdel)):
                if fn is not None and _defined_here(fn, module):
                    yield (qual if role == "fget" else f"{qual}.{role}"), fn, True
        elif isinstance(attr, staticmethod):
            fn = attr.__func__
            if _defined_here(fn, module):
                yield qual, fn, False
        elif isinstance(attr, classmethod):
            fn = attr.__func__
            if _defined_here(fn, module):
                yield qual, fn, True
        elif inspect.isfunction(attr):
            # skip methods generated by dataclasses/NamedTuple (no source in this module)
            if not _defined_here(attr, module):
                continue
            if _is_dunder(name) and _generated(attr):
                continue
            yield qual, attr, True
        elif inspect.isclass(attr) and _defined_here(attr, module) and not name.startswith("_"):
            yield from _class_callables(attr, module)


def _generated(fn: Callable[..., object]) -> bool:
    """True for functions created by exec (dataclass __init__, NamedTuple __new__)."""
    try:
        inspect.getsourcefile(fn)
        inspect.getsourcelines(fn)
    except (OSError, TypeError):
        return True
    code = getattr(fn, "__code__", None)
    return code is not None and not code.co_filename.endswith(".py")


def module_public_callables(module_name: str) -> Iterator[tuple[str, Callable[..., object], bool]]:
    """(qualified name, function, is_method) for the public callables defined in a module."""
    module = importlib.import_module(module_name)
    for name, obj in vars(module).items():
        if name in MODULE_DUNDERS and inspect.isfunction(obj):
            yield f"{module_name}.{name}", obj, False
            continue
        if name.startswith("_") or not _defined_here(obj, module_name):
            continue
        if inspect.isclass(obj):
            yield from _class_callables(obj, module_name)
        elif inspect.isfunction(obj):
            # a decorator's wrapper (contextmanager, functools.wraps): the signature checkers see is the wrapped one
            wrapped = getattr(obj, "__wrapped__", None)
            yield f"{module_name}.{name}", wrapped if inspect.isfunction(wrapped) else obj, False
        elif callable(obj) and inspect.isfunction(getattr(obj, "__wrapped__", None)):
            yield f"{module_name}.{name}", obj.__wrapped__, False


def missing_annotations(qual: str, fn: Callable[..., object], is_method: bool) -> list[str]:
    """The unannotated parts of fn, as 'qual(param)' / 'qual -> return'."""
    sig = inspect.signature(fn, follow_wrapped=False)
    out = []
    params = list(sig.parameters.values())
    if is_method and params and params[0].name in ("self", "cls"):
        params = params[1:]
    for p in params:
        if p.annotation is inspect.Parameter.empty:
            out.append(f"{qual}({p.name})")
    if sig.return_annotation is inspect.Signature.empty:
        out.append(f"{qual} -> return")
    return out


def walk(modules: Sequence[str]) -> tuple[int, int, list[str]]:
    """(number of public callables, number fully annotated, list of missing parts)."""
    total = complete = 0
    missing: list[str] = []
    seen: set[int] = set()
    for module_name in modules:
        for qual, fn, is_method in module_public_callables(module_name):
            if id(fn) in seen:
                continue
            seen.add(id(fn))
            total += 1
            gaps = missing_annotations(qual, fn, is_method)
            complete += not gaps
            missing.extend(gaps)
    return total, complete, missing


def annotated_modules() -> list[str]:
    """Every module of the package but the compiled kernels and the ``__main__`` scripts."""
    return [info.name for info in pkgutil.walk_packages(manifold_sph.__path__, "manifold_sph.")
            if not info.name.endswith("__main__") and not any(info.name == c or info.name.startswith(c + ".") for c in COMPILED)]


def test_public_callables_are_annotated() -> None:
    modules = annotated_modules()
    # the walk reaches the subpackages (a short module list would pass vacuously)
    assert {"manifold_sph.surface", "manifold_sph.distributed.surface", "manifold_sph.spem.tmz", "manifold_sph.cli.app"} <= set(modules)
    total, complete, missing = walk(modules)
    assert not missing, (f"{len(missing)} unannotated parameters/returns ({complete}/{total} public callables complete):\n  "
                         + "\n  ".join(missing))


def test_walker_reports_missing_annotations(tmp_path: pathlib.Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The walker itself: unannotated parameters and returns are found, self and private names are not."""
    (tmp_path / "fake_annotations_module.py").write_text(
        "from __future__ import annotations\n"
        "from contextlib import contextmanager\n"
        "from dataclasses import dataclass\n"
        "def good(x: int, *args: int, **kw: str) -> int: ...\n"
        "def bad(x, y: int = 0): ...\n"
        "def _private(x): ...\n"
        "@contextmanager\n"
        "def cm(n): yield\n"
        "class C:\n"
        "    def __init__(self, a): ...\n"
        "    def m(self) -> None: ...\n"
        "    @property\n"
        "    def p(self): ...\n"
        "    @staticmethod\n"
        "    def s(z) -> int: ...\n"
        "@dataclass\n"
        "class D:\n"
        "    a: int\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    try:
        total, complete, missing = walk(["fake_annotations_module"])
    finally:
        sys.modules.pop("fake_annotations_module", None)
    assert (total, complete) == (7, 2)  # D's generated __init__, __repr__, __eq__ are not counted
    assert sorted(missing) == sorted([
        "fake_annotations_module.bad(x)",
        "fake_annotations_module.bad -> return",
        "fake_annotations_module.C.__init__(a)",
        "fake_annotations_module.C.__init__ -> return",
        "fake_annotations_module.C.p -> return",
        "fake_annotations_module.C.s(z)",
        "fake_annotations_module.cm(n)",  # through the contextmanager wrapper's (*args, **kwds)
        "fake_annotations_module.cm -> return",
    ])
