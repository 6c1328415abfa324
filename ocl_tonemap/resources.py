"""Where the package's data folders are (kernels, OCIO configs), installed or in a
source tree."""

from __future__ import annotations

from pathlib import Path


def package_data_dir(name: str, probe: str) -> Path:
    """``ocl_tonemap/<name>`` in an installed wheel (where pyproject maps the
    top-level folder), else ``<name>`` beside the package in a source tree."""
    here = Path(__file__).resolve().parent      # ocl_tonemap/
    for p in (here / name, here.parent / name):
        if (p / probe).is_file():
            return p
    raise FileNotFoundError(f"{name}/{probe} not found in the installed package or the source tree")


