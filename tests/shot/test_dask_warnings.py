"""Warnings of a shot on Dask come once a run, with the command line's prefix, as in
the serial run (issue 65): the tasks bring their log records back with their
results, the client says each once through the ``ocl_tonemap`` logger, and the
workers' own stderr says nothing. A real local cluster (one worker), the real
command line in a subprocess."""

import subprocess
import sys

import numpy as np
import OpenImageIO as oiio
import pytest

pytest.importorskip("distributed")


def _untagged(d, frames=2):
    """EXR frames with no colour tag and no chromaticities: the input colour is
    assumed (a WARNING in every task that reads one)."""
    d.mkdir()
    rng = np.random.default_rng(5)
    for f in range(1, frames + 1):
        spec = oiio.ImageSpec(32, 18, 3, oiio.HALF)
        spec.attribute("whiteLuminance", 1.0)
        buf = oiio.ImageBuf(spec)
        buf.set_pixels(oiio.ROI(0, 32, 0, 18, 0, 1, 0, 3),
                       rng.uniform(1.0, 200.0, (18, 32, 3)).astype(np.float32))
        assert buf.write(str(d / f"s.{f:04d}.exr"))
    return str(d / "s.####.exr")


def _stderr(args):
    p = subprocess.run([sys.executable, "-m", "ocl_tonemap", *args], capture_output=True,
                       text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    return p.stderr


@pytest.mark.requires_opencl
def test_a_dask_runs_warnings_come_once_with_the_prefix(tmp_path):
    pattern = _untagged(tmp_path / "in")
    common = ["--backend", "reference", "--no-checkpoint"]
    serial = [ln for ln in _stderr(["run", pattern, str(tmp_path / "s" / "o.####.png"),
                                    *common]).splitlines() if "input colour" in ln]
    assert len(serial) == 1 and serial[0].startswith("ocl-tonemap WARNING: input colour: ")
    # four tasks (two measure, two apply) in one worker, each reading an untagged frame
    err = _stderr(["run", pattern, str(tmp_path / "d" / "o.####.png"), *common,
                   "--scheduler", "dask", "--workers", "1", "--chunk-frames", "1"])
    said = [ln for ln in err.splitlines() if "input colour" in ln]
    assert said == serial, err
