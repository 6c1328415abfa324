"""Every source path and module the README and docs/*.md name exists where they say
(issue 68: the layout moved; a page naming ``cli_options.py`` or
``ocl_tonemap.imageio`` after the move is stale):

* inline code ending in ``.py`` (``io/imageio.py``, ``ocl_tonemap/cli/table.py``,
  ``tests/job/test_radiance.py``, optionally ``:name``): a file of the repository whose
  path ends so (from the repository, the package or ``tests/``, ``benchmarks/``,
  ``examples/``);
* a dotted ``ocl_tonemap.x.y`` anywhere: its longest module prefix is a module of the
  package at its new path (not one of ``ocl_tonemap.moved``'s old paths), the rest
  names in it.

A section headed "Old import paths" names the old paths on purpose, and is left out.
"""

from __future__ import annotations

import importlib
import re
from functools import lru_cache

import pytest

from ocl_tonemap.moved import new_name

import mdscan  # tests/docs/mdscan.py (pytest puts this folder on sys.path)

ROOT = mdscan.ROOT
PAGES = mdscan.PAGES + sorted(ROOT.glob("examples/*/README.md"))
PY_RE = re.compile(r"`([\w./-]+\.py)(?::[\w.]+)?`")
MOD_RE = re.compile(r"\bocl_tonemap(?:\.\w+)+")
#: Files the docs name that are not in this repository (other projects' sources).
ELSEWHERE = {"setup.py"}


def _text(page) -> str:
    """The page without its "Old import paths" section (up to the next heading)."""
    return re.sub(r"(?ms)^#+ Old import paths\n.*?(?=^#)", "", page.read_text())


@lru_cache(maxsize=1)
def _sources() -> tuple[str, ...]:
    return tuple(p.relative_to(ROOT).as_posix() for p in ROOT.rglob("*.py")
                 if not {".venv", "build", ".git"} & set(p.relative_to(ROOT).parts))


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_named_source_files_exist(page):
    files = _sources()
    missing = []
    for m in PY_RE.finditer(_text(page)):
        name = m.group(1).lstrip("./")
        if name in ELSEWHERE:
            continue
        if not any(f == name or f.endswith("/" + name) for f in files):
            missing.append(name)
    assert not missing, f"{page.name} names files that are not there: {sorted(set(missing))}"


def _resolves(dotted: str) -> bool:
    parts = dotted.split(".")
    for k in range(len(parts), 0, -1):
        mod = ".".join(parts[:k])
        if new_name(mod) is not None:
            return False                  # an old path (it works, with a warning: stale)
        try:
            m = importlib.import_module(mod)
        except ImportError:
            continue
        for attr in parts[k:]:
            if not hasattr(m, attr):
                return False
            m = getattr(m, attr)
        return True
    return False


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_named_modules_are_at_their_paths(page):
    text = _text(page)
    bad = sorted({d.rstrip(".") for d in MOD_RE.findall(text) if not _resolves(d.rstrip("."))})
    assert not bad, f"{page.name} names modules that are not there: {bad}"
