"""The wheel carries kernels/ and ocio_configs/ and runs outside the source tree."""

import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_wheel_contains_kernels_and_config(tmp_path):
    # the same isolated PEP 517 build that `pip install .` does
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w",
                        str(tmp_path), str(ROOT)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    whl = next(tmp_path.glob("ocl_tonemap-*.whl"))
    names = set(zipfile.ZipFile(whl).namelist())
    for k in (ROOT / "kernels").iterdir():
        if k.suffix in (".cl", ".h"):
            assert f"ocl_tonemap/kernels/{k.name}" in names
    assert "ocl_tonemap/ocio_configs/ocl_tonemap.ocio" in names
    assert "ocl_tonemap/data/rgb_to_lmsr.json" in names
    # evaluation code stays in the source tree (benchmarks/lib), out of the wheel
    assert not [n for n in names if n.startswith("benchmarks/")]
    for gone in ("appearance_metrics", "appearance_scenes", "validation", "fit_lmsr"):
        assert f"ocl_tonemap/{gone}.py" not in names
    # run from the unpacked wheel, away from the source tree
    site = tmp_path / "site"
    zipfile.ZipFile(whl).extractall(site)
    code = ("import numpy as np; from ocl_tonemap import Tonemapper; "
            "from ocl_tonemap.colour import load_config; load_config('ocl-tonemap'); "
            "print(Tonemapper().process(np.full((2,2,3),10,np.float32)).shape); "
            "print(Tonemapper('kirk11').process(np.full((2,2,3),1,np.float32)).shape)")
    r = subprocess.run([sys.executable, "-c", code], cwd=str(tmp_path), capture_output=True,
                       text=True, env={"PYTHONPATH": str(site), "PATH": "/usr/bin:/bin"})
    assert r.returncode == 0, r.stderr
    assert "(2, 2, 3)" in r.stdout


def test_every_package_of_the_tree_is_declared_for_the_wheel():
    """pyproject's explicit package list names every folder of ocl_tonemap/ with an
    __init__.py (a package left out installs without it, and only CI would notice)."""
    import tomllib
    declared = set(tomllib.loads((ROOT / "pyproject.toml").read_text())
                   ["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(ROOT).parts)
             for p in (ROOT / "ocl_tonemap").rglob("__init__.py")}
    assert found <= declared, sorted(found - declared)
