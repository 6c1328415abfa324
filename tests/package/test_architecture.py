"""The layout's rules (docs/architecture.md), checked on the source: models are pure,
imports follow the declared layers without cycles, imports inside functions say why,
no module takes another's private names, sizes stay small, the models' doctests
hold, and operators are found through one registry."""

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


#: The layers, lowest first (docs/architecture.md), each a list of the package's
#: folders (every module in a folder is in its layer, a new one too) and of the root
#: modules of :data:`ROOT_MODULES` ("" is the package's own ``__init__``, the API). A
#: module imports only from its own layer or those below, imports inside functions
#: included.
LAYERS = (
    ("base", ("base", "version", "moved")),
    ("models", ("models",)),
    ("operators", ("operators",)),
    ("backends", ("backends",)),
    ("effects", ("effects", "mechanisms")),
    ("pipeline", ("pipeline",)),
    ("colour and I/O", ("colour", "io")),
    ("job", ("job",)),
    ("shot", ("shot",)),
    ("cli", ("cli", "__main__", "")),
)
#: The only modules the package root holds besides its folders (docs/architecture.md,
#: "The package root"): the API's names, ``python -m ocl_tonemap``, the version, the
#: old import paths (one release).
ROOT_MODULES = ("__init__", "__main__", "version", "moved")


def test_the_root_holds_the_api_and_every_folder_is_a_layer():
    """At most four modules in the package root, each on the short list; every folder
    of the package is named in LAYERS (or is its data), and every LAYERS name is a
    folder or a root module of the list."""
    root = sorted(p.stem for p in PKG.glob("*.py"))
    assert set(root) <= set(ROOT_MODULES) and len(root) <= 4, root
    folders = sorted(p.parent.name for p in PKG.glob("*/__init__.py"))
    named = {n for _, names in LAYERS for n in names}
    assert set(folders) <= named, sorted(set(folders) - named)
    for n in named - {""}:
        assert (PKG / n / "__init__.py").is_file() or n in ROOT_MODULES, n
    # a module added to a folder is in that folder's layer without editing LAYERS
    assert LAYERS[_layer("ocl_tonemap.io.a_new_format")][0] == "colour and I/O"
    assert _layer("ocl_tonemap.a_loose_module") is None


def _layer(module: str) -> int | None:
    """The index in :data:`LAYERS` of a module (its longest declared prefix)."""
    best = None
    for i, (_, names) in enumerate(LAYERS):
        for n in names:
            full = "ocl_tonemap" + (f".{n}" if n else "")
            if module == full or (n and module.startswith(full + ".")):
                if best is None or len(full) > best[1]:
                    best = (i, len(full))
    return None if best is None else best[0]


def _edges(name: str, mod: str, names) -> set:
    """The modules an import runs: ``from pkg import submodule`` the submodule (and
    the package only for the names its ``__init__`` defines), ``import pkg.mod`` the
    module; a package's ``__init__`` is a module like the others."""
    known = {m for m, _ in _modules()}
    subs = {f"{mod}.{n}" for n in names if f"{mod}.{n}" in known}
    out = set(subs)
    if mod in known and (len(subs) < len(names) or not names):
        out.add(mod)
    out.discard(name)
    return out


def _graph() -> dict:
    return {name: set().union(*[_edges(name, mod, names) for mod, names, _ in
                                _imports(name, path)] or [set()])
            for name, path in _modules()}


def test_every_module_is_in_a_declared_layer():
    loose = [m for m, _ in _modules() if _layer(m) is None]
    assert not loose, f"declare these in LAYERS (and docs/architecture.md): {loose}"


def test_no_import_runs_back_up_a_layer():
    """models -> operators -> backends -> effects/mechanisms -> pipeline -> colour/IO ->
    job -> shot -> cli: nothing imports from a layer above its own, imports inside
    functions and packages' ``__init__`` included."""
    up = []
    for name, path in _modules():
        for mod, names, line in _imports(name, path):
            for dep in _edges(name, mod, names):
                if _layer(dep) is not None and _layer(dep) > _layer(name):
                    up.append(f"{path.relative_to(PKG.parent)}:{line} ({LAYERS[_layer(name)][0]})"
                              f" imports {dep} ({LAYERS[_layer(dep)][0]})")
    assert not up, up


def test_no_import_cycles():
    """The module graph has no cycle, imports inside functions counted and a
    package's ``__init__`` a module of its own (a package importing its submodule
    and that submodule importing a name of the package is a cycle)."""
    graph = _graph()
    # strongly connected components (Tarjan): every module of a cycle, all cycles at once
    index, low, stack, on, comps = {}, {}, [], set(), []

    def strong(n):
        index[n] = low[n] = len(index)
        stack.append(n)
        on.add(n)
        for d in graph.get(n, ()):
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


def test_imports_inside_functions_say_why():
    """An import of the package's own modules inside a function is there for start-up
    (``--help`` without NumPy, a command loading only its own layers, OIIO or OpenCL
    only when used), and says so in a ``# lazy:`` comment on its line or the one
    before; any other belongs at the top of the module."""
    silent = []
    for name, path in _modules():
        tree = ast.parse(path.read_text())
        lines = path.read_text().splitlines()
        skip = _type_checking_blocks(tree)
        top = {id(n) for n in tree.body}
        for node in ast.walk(tree):
            if id(node) in skip or id(node) in top or \
                    not isinstance(node, (ast.Import, ast.ImportFrom)):
                continue
            own = (isinstance(node, ast.ImportFrom) and node.level > 0) or any(
                a.name.startswith("ocl_tonemap") for a in getattr(node, "names", [])
                if isinstance(node, ast.Import)) or (isinstance(node, ast.ImportFrom) and
                                                     (node.module or "").startswith("ocl_tonemap"))
            if not own:
                continue
            here = lines[node.lineno - 1] + (lines[node.lineno - 2] if node.lineno > 1 else "")
            if "# lazy:" not in here:
                silent.append(f"{path.relative_to(PKG.parent)}:{node.lineno}: "
                              f"{lines[node.lineno - 1].strip()}")
    assert not silent, silent


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


#: The size a module may reach before it is split (issue 46: split, not squeezed), a
#: class's, and the facade's.
MAX_MODULE_LINES = 500
MAX_CLASS_LINES = 300
MAX_TONEMAPPER_LINES = 250
MAX_CLI_LINES = 400


def test_no_module_over_the_size_limit():
    big = [f"{p.relative_to(PKG.parent)}: {n} lines" for p in sorted(PKG.rglob("*.py"))
           if (n := len(p.read_text().splitlines())) > MAX_MODULE_LINES]
    assert not big, big


def test_no_class_over_the_size_limit():
    big = []
    for name, path in _modules():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ClassDef):
                n = node.end_lineno - node.lineno + 1
                cap = MAX_TONEMAPPER_LINES if node.name == "Tonemapper" else MAX_CLASS_LINES
                if n > cap:
                    big.append(f"{name}.{node.name}: {n} lines (at most {cap})")
    assert not big, big


def test_the_command_line_names_no_effect():
    """cli/table.py is a table of sub-commands: the effects' flags come from their
    declarations (cli/options.py reads them), so it names none."""
    import re
    text = (PKG / "cli" / "table.py").read_text()
    assert len(text.splitlines()) <= MAX_CLI_LINES
    named = sorted(set(re.findall(r"(?i)flare|acuity|purkinje|chromatic", text)))
    assert not named, named


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
