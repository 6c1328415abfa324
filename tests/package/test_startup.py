"""What a warm start reuses: program binaries, baked flare fits and the parser of one
sub-command give the same results as building everything afresh."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import OpenImageIO as oiio
import pytest

from ocl_tonemap.cli import table as cli
from ocl_tonemap.effects import flare as flare_effect
from ocl_tonemap.models import spencer1995 as fl


def test_parser_of_one_command_parses_as_the_whole_parser():
    argv = ["run", "in.exr", "out.png", "--operator", "durand00", "--flare", "on", "--fov",
            "60", "--lut", "256", "-v", "--quality", "draft"]
    assert vars(cli.build_parser("run").parse_args(argv)) == \
        vars(cli.build_parser().parse_args(argv))
    assert cli._command_of(["-v", "simulate", "a", "b"]) == "simulate"
    assert cli._command_of(["--version"]) is None


def test_stored_flare_fit_is_the_fit(tmp_path, monkeypatch):
    monkeypatch.setenv("OCLTM_CACHE_DIR", str(tmp_path))
    args = ((90, 160), 50.0 / 160, 1)
    fresh = fl.fit_gaussians(*args)
    for _ in range(2):                       # computed and stored, then read back
        got = flare_effect.stored_fit(*args)
        assert got.sigmas == fresh.sigmas and got.l2_error == fresh.l2_error
        assert got.weights.keys() == fresh.weights.keys()
        for k in fresh.weights:
            assert np.array_equal(got.weights[k], fresh.weights[k])
    assert len(list((tmp_path / "flare-fits").glob("*.json"))) == 1
    flare_effect.stored_fit((90, 161), 50.0 / 161, 1)
    assert len(list((tmp_path / "flare-fits").glob("*.json"))) == 2


@pytest.mark.requires_opencl
def test_program_binaries_cached_give_the_same_frames(tmp_path, sample_dir):
    pattern, frames = sample_dir
    src = pattern.replace("####", f"{frames[3]:04d}")
    env = {k: v for k, v in os.environ.items() if k != "PYOPENCL_NO_CACHE"}
    env["OCLTM_CACHE_DIR"] = str(tmp_path / "cache")
    outs = []
    for i in range(2):
        out = tmp_path / f"o{i}.exr"
        r = subprocess.run([sys.executable, "-m", "ocl_tonemap", "run", src, str(out),
                            "--operator", "durand00", "--flare", "on", "--out-bits", "float",
                            "-q"], env=env, capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr
        if i == 0:
            bins = sorted((tmp_path / "cache" / "programs").glob("*.bin"))
            assert bins and all(p.stat().st_size > 0 for p in bins)
            assert list((tmp_path / "cache" / "display-tables").glob("*.npz"))
            # the kernels the run asked for, listed for the next run's start
            assert len(list((tmp_path / "cache" / "programs").glob("run-*.json"))) == 1
        outs.append(oiio.ImageBuf(str(out)).get_pixels(oiio.FLOAT))
    assert np.isfinite(outs[0]).all() and np.array_equal(outs[0], outs[1])
    # PYOPENCL_NO_CACHE: no binaries kept or read
    env = {**env, "PYOPENCL_NO_CACHE": "1", "OCLTM_CACHE_DIR": str(tmp_path / "cache2")}
    r = subprocess.run([sys.executable, "-m", "ocl_tonemap", "run", src,
                        str(tmp_path / "o2.exr"), "-q"], env=env, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert not (tmp_path / "cache2" / "programs").exists()


@pytest.mark.requires_opencl
def test_kernels_of_the_last_run_are_loaded_from_the_cache_and_never_compiled(tmp_path,
                                                                              monkeypatch):
    """``Runtime.remember_kernels`` lists the kernels a run asked for; the next run's
    ``warm_kernels`` (while its first frame is read) makes them again from the cached
    binaries, stops when told to, and compiles nothing: a program whose binary is not
    in the cache is left to its first use."""
    monkeypatch.setenv("OCLTM_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("PYOPENCL_NO_CACHE", raising=False)
    from ocl_tonemap.backends.opencl import runtime as R
    rt = R.get_runtime()
    asked = dict(R._ASKED)
    try:
        R._build.cache_clear()
        R._kernel.cache_clear()
        R._ASKED.clear()
        rt.kernel("colour.cl", "apply_gains")     # compiled; its binary kept in tmp_path
        rt.remember_kernels("k")
        assert len(list((tmp_path / "programs").glob("run-*.json"))) == 1
        R._build.cache_clear()
        R._kernel.cache_clear()
        assert rt.warm_kernels("k", lambda: True) == 0        # told to stop at once
        assert R._build.cache_info().currsize == 0
        assert rt.warm_kernels("k", lambda: False) == 1
        assert R._kernel.cache_info().currsize == 1
        # a kernel whose program was never built here: listed, not compiled by the warm-up
        R._ASKED[("colour.cl", "apply_gains", (("OCLTM_TEST_UNBUILT", 1),))] = None
        rt.remember_kernels("k")
        R._build.cache_clear()
        R._kernel.cache_clear()
        assert rt.warm_kernels("k", lambda: False) == 1
        assert R._build.cache_info().currsize == 1
        assert rt.warm_kernels("another run", lambda: False) == 0
    finally:
        R._ASKED.clear()
        R._ASKED.update(asked)
