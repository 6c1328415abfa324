"""The bundled config loads on every OCIO from 2.1 (VFX Reference Platform CY2022) to
the wheel's 2.6: it declares profile version 2.1, its Display P3 display is written
with transforms 2.1 has and equals 2.3's built-in, and both OCIO 2.1's ``ociocheck``
(Debian's opencolorio-tools, installed by .ci/ocio21.sh) and the wheel's pass it."""

import os
import re
import shutil
import subprocess
import sys

import numpy as np
import PyOpenColorIO as ocio
import pytest

from ocl_tonemap.colour import bundled_config_path

DEBIAN_OCIOCHECK = "/usr/bin/ociocheck"


def _ociocheck_version(exe) -> tuple:
    out = subprocess.run([exe], capture_output=True, text=True).stdout
    m = re.search(r"Library Version:\s*(\d+)\.(\d+)", out)
    return (int(m.group(1)), int(m.group(2))) if m else ()


def _check(exe, path):
    r = subprocess.run([exe, "--iconfig", str(path)], capture_output=True, text=True)
    out = r.stdout + r.stderr
    assert r.returncode == 0 and "passed" in out and "ERROR" not in out, out
    return out


def test_bundled_config_declares_2_1_and_loads():
    cfg = ocio.Config.CreateFromFile(str(bundled_config_path()))
    cfg.validate()
    assert (cfg.getMajorVersion(), cfg.getMinorVersion()) == (2, 1)


def test_display_p3_equals_the_2_3_builtin():
    """Our matrix + mirrored sRGB curve against DISPLAY - CIE-XYZ-D65_to_DisplayP3 over
    in- and out-of-gamut colours: within 1 10-bit code (measured: 0)."""
    cfg = ocio.Config.CreateFromFile(str(bundled_config_path()))
    ours = cfg.getProcessor("CIE-XYZ-D65", "Display P3 - Display").getDefaultCPUProcessor()
    raw = ocio.Config.CreateRaw()
    builtin = raw.getProcessor(ocio.BuiltinTransform("DISPLAY - CIE-XYZ-D65_to_DisplayP3"))
    builtin = builtin.getDefaultCPUProcessor()
    rng = np.random.default_rng(1)
    xyz = rng.uniform(-0.3, 1.5, (100000, 3)).astype(np.float32)
    a, b = xyz.copy(), xyz.copy()
    ours.applyRGB(a)
    builtin.applyRGB(b)
    assert np.abs(a - b).max() * 1023 <= 1.0


def test_the_wheels_ociocheck_passes():
    exe = shutil.which("ociocheck", path=os.path.dirname(sys.executable))
    if exe is None:
        pytest.skip("the OCIO wheel's tools are not installed")
    _check(exe, bundled_config_path())


def test_ocio_2_1_ociocheck_passes():
    if not os.path.exists(DEBIAN_OCIOCHECK):
        if os.environ.get("CI"):
            pytest.fail("OCIO 2.1's ociocheck is missing: .ci/ocio21.sh installs Debian's "
                        "opencolorio-tools")
        pytest.skip("no system ociocheck (Debian: apt-get install opencolorio-tools)")
    if _ociocheck_version(DEBIAN_OCIOCHECK)[:2] >= (2, 3):
        pytest.skip("the system ociocheck is not an older OCIO")
    _check(DEBIAN_OCIOCHECK, bundled_config_path())
