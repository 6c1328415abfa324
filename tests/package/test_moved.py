"""The import paths of the modules that moved into layer folders (issue 68) keep working
for one release, each with a DeprecationWarning that names the new path and points at
the importing line; ``python -m`` of an old path runs the new module."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from ocl_tonemap.moved import MOVED

_CHECK = r"""
import importlib, json, sys, warnings
out = {}
for old, new in json.loads(sys.argv[1]).items():
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        m = importlib.import_module("ocl_tonemap." + old)
    n = importlib.import_module("ocl_tonemap." + new)
    dep = [x for x in w if issubclass(x.category, DeprecationWarning)]
    out[old] = [m is n, len(dep), str(dep[0].message) if dep else "", dep[0].filename if dep else ""]
print(json.dumps(out))
"""


def test_every_old_path_is_the_new_module_with_a_warning():
    """A fresh interpreter per run (an old path warns once, on its first import): each
    old module is the new module object itself, with one DeprecationWarning naming
    the new path, attributed to the importing file (here the script), not to the
    import machinery."""
    r = subprocess.run([sys.executable, "-c", _CHECK, json.dumps(MOVED)], capture_output=True,
                       text=True, check=True)
    got = json.loads(r.stdout)
    for old, new in MOVED.items():
        same, n, msg, where = got[old]
        assert same and n == 1, (old, got[old])
        assert f"ocl_tonemap.{new}" in msg and f"ocl_tonemap.{old} has moved" in msg
        assert where == "<string>", (old, where)


def test_an_old_from_import_and_the_cli_package_still_work():
    code = ("import warnings; warnings.simplefilter('error', DeprecationWarning)\n"
            "from ocl_tonemap.cli import build_parser, main\n"      # the package: no warning
            "from ocl_tonemap import Tonemapper, AdaptationState\n"
            "warnings.simplefilter('ignore', DeprecationWarning)\n"
            "from ocl_tonemap.quantities import Quantity\n"          # a plugin's old import
            "from ocl_tonemap.base.quantities import Quantity as Q\n"
            "assert Quantity is Q\n"
            "print(build_parser().prog)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "ocl-tonemap"


def test_python_m_of_the_old_cli_docs_path_runs_the_new_one():
    """The README's old ``python -m ocl_tonemap.cli_docs --check`` (docs/cli.md is what
    the parser gives) runs ``ocl_tonemap.cli.docs`` and says it moved, once."""
    new = subprocess.run([sys.executable, "-m", "ocl_tonemap.cli.docs", "--check"],
                         capture_output=True, text=True)
    old = subprocess.run([sys.executable, "-m", "ocl_tonemap.cli_docs", "--check"],
                         capture_output=True, text=True)
    assert new.returncode == old.returncode == 0, (new.stderr, old.stderr)
    assert "DeprecationWarning" not in new.stderr
    assert old.stderr.count("ocl_tonemap.cli_docs has moved to ocl_tonemap.cli.docs") == 1
    assert old.stdout == new.stdout


@pytest.mark.parametrize("old", ["imageio", "cli_options"])
def test_an_unknown_name_under_the_package_is_still_an_import_error(old):
    with pytest.raises(ImportError):
        __import__(f"ocl_tonemap.{old}_no_such_module")
