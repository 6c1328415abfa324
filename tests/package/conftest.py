"""The example plugins (examples/) installed as a user installs them: with pip, into a
folder of their own, seen by a Python through PYTHONPATH."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def installed_example(name: str, target: Path) -> dict:
    """pip install (no build isolation, no dependencies) ``examples/<name>`` into
    ``target``; the environment whose Python sees it."""
    r = subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps",
                        "--no-build-isolation", "--target", str(target), str(EXAMPLES / name)],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(target), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep))


@pytest.fixture(scope="module")
def install_example(tmp_path_factory):
    """``install_example(name)``: :func:`installed_example` into a fresh folder."""
    return lambda name: installed_example(name, tmp_path_factory.mktemp("plugin"))
