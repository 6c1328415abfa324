"""The layout's rules (docs/architecture.md), checked on the source: models are pure,
imports go one way without cycles, no module takes another's private names, the
models' doctests hold, and operators are found through one registry."""

from __future__ import annotations

import ast
import doctest
import importlib
from pathlib import Path

import pytest

import ocl_tonemap

PKG = Path(ocl_tonemap.__file__).resolve().parent


def _modules():
    for p in sorted(PKG.rglob("*.py")):
        rel = p.relative_to(PKG.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        yield ".".join(parts), p


def _type_checking_blocks(tree) -> set:
    """The nodes inside ``if TYPE_CHECKING:`` blocks (annotations only, never run)."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and getattr(node.test, "id", None) == "TYPE_CHECKING":
            for child in node.body:
                out.update(id(n) for n in ast.walk(child))
    return out


def _imports(name: str, path: Path, top_level_only: bool = False):
    """(imported module, names, line) of every import in a module, those inside
    functions included (``top_level_only``: the module's own statements only);
    ``if TYPE_CHECKING:`` imports are left out (they never run)."""
    tree = ast.parse(path.read_text())
    is_pkg = path.name == "__init__.py"
    skip = _type_checking_blocks(tree)
    nodes = tree.body if top_level_only else ast.walk(tree)
    for node in nodes:
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            for a in node.names:
                yield a.name, [], node.lineno
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".")
                base = base[:len(base) - node.level + (1 if is_pkg else 0)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            yield mod, [a.name for a in node.names], node.lineno


def _resolve(mod: str, names) -> list[str]:
    """Package-internal modules an import refers to (``from pkg import module``)."""
    known = {m for m, _ in _modules()}
    out = []
    if mod in known:
        out.append(mod)
    for n in names:
        if f"{mod}.{n}" in known:
            out.append(f"{mod}.{n}")
    return out


def test_models_are_pure_numpy():
    """models/ imports nothing else from the package, and no OpenCL, OIIO or OCIO."""
    bad = []
    for name, path in _modules():
        if not name.startswith("ocl_tonemap.models"):
            continue
        for mod, _, line in _imports(name, path):
            if mod.startswith("ocl_tonemap") and not mod.startswith("ocl_tonemap.models"):
                bad.append(f"{path.name}:{line} imports {mod}")
            if mod.split(".")[0] in ("pyopencl", "OpenImageIO", "PyOpenColorIO"):
                bad.append(f"{path.name}:{line} imports {mod}")
    assert not bad, bad


def test_no_import_cycles():
    """The module graph has no cycle, imports inside functions counted (a package's
    ``__init__`` importing its own submodules is not a cycle)."""
    graph = {}
    for name, path in _modules():
        deps = set()
        for mod, names, _ in _imports(name, path):
            deps.update(d for d in _resolve(mod, names) if d != name)
        graph[name] = deps
    # strongly connected components (Tarjan): every module of a cycle, all cycles at once
    index, low, stack, on, comps = {}, {}, [], set(), []

    def strong(n):
        index[n] = low[n] = len(index)
        stack.append(n)
        on.add(n)
        for d in graph.get(n, ()):
            if d.startswith(n + "."):
                continue               # a package importing its own submodules
            if d not in index:
                strong(d)
                low[n] = min(low[n], low[d])
            elif d in on:
                low[n] = min(low[n], index[d])
        if low[n] == index[n]:
            comp = []
            while True:
                m = stack.pop()
                on.discard(m)
                comp.append(m)
                if m == n:
                    break
            if len(comp) > 1:
                comps.append(sorted(comp))
    for n in sorted(graph):
        if n not in index:
            strong(n)
    assert not comps, comps


def test_no_private_names_across_modules():
    bad = []
    for name, path in _modules():
        for mod, names, line in _imports(name, path):
            if mod.startswith("ocl_tonemap") and any(n.startswith("_") and not n.startswith("__") for n in names):
                bad.append(f"{name}:{line} from {mod} import {names}")
    assert not bad, bad


@pytest.mark.parametrize("module", sorted(m for m, _ in _modules() if ".models." in m))
def test_models_doctests(module):
    mod = importlib.import_module(module)
    res = doctest.testmod(mod, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert res.failed == 0
    if module.rsplit(".", 1)[-1] not in ("__init__",):
        assert res.attempted > 0 or module.endswith(("numerics", "photometry", "lmsr",
                                                     "metering", "convolution", "bilateral",
                                                     "display")), \
            f"{module} has no doctest"


def test_registry_has_the_four_operators_with_one_protocol():
    from ocl_tonemap.operators import registry
    from ocl_tonemap.operators.base import STAGE_KINDS, Operator
    reg = registry()
    assert {"pattanaik00", "ledda04", "durand00", "kirk11"} <= set(reg)
    for name, cls in reg.items():
        assert issubclass(cls, Operator) and cls.name == name and cls.stages
        assert all(s.kind in STAGE_KINDS for s in cls.stages)
        assert any(o.name == "mode" for o in cls.options)
    assert reg["ledda04"].state.planes and not reg["pattanaik00"].state.planes


#: The size a module may reach before it is split (issue 29: one room, one job).
MAX_MODULE_LINES = 700


def test_no_module_over_the_size_limit():
    big = [f"{p.relative_to(PKG.parent)}: {n} lines" for p in sorted(PKG.rglob("*.py"))
           if (n := len(p.read_text().splitlines())) > MAX_MODULE_LINES]
    assert not big, big


def test_the_job_asks_backends_nothing_by_probing():
    """Backends and schedules are known through backends/base.py's protocols: at most
    three ``hasattr`` / ``getattr(..., default)`` probes on a backend, schedule or
    runtime object in the package (probes of OCIO's or OIIO's version are fine)."""
    import re
    target = re.compile(r"\b(backend|be|schedule|rt|runtime|_blur|device)\b")
    probes = []
    for name, path in _modules():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call) and getattr(node.func, "id", None) in ("hasattr",
                                                                                "getattr"):
                if node.func.id == "getattr" and len(node.args) < 3:
                    continue                      # getattr(obj, name): no probe
                if target.search(ast.unparse(node.args[0])):
                    probes.append(f"{name}:{node.lineno} {ast.unparse(node)}")
    assert len(probes) <= 3, probes


def test_no_sys_path_edits_in_tests_or_benchmarks():
    root = PKG.parent
    bad = [f"{p.relative_to(root)}" for d in ("tests", "benchmarks") if (root / d).is_dir()
           for p in sorted((root / d).rglob("*.py")) if "sys.path.insert" in p.read_text()
           and p.name != "test_architecture.py"]
    assert not bad, bad
