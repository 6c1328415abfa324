import os

import numpy as np
import pytest

#: Tests that need a working OpenCL device carry ``@pytest.mark.requires_opencl``
#: (module-wide ``pytestmark`` where every test does; any test using the ``rt``
#: fixture is marked automatically). Where no device works they fail in CI
#: (``CI=true``) with one message saying why, and skip with it elsewhere.
_STATUS: list = []


def opencl_status():
    """(device, None) for the device the tests run on, or (None, why)."""
    if not _STATUS:
        from ocl_tonemap.backends.opencl.runtime import device_status
        try:
            dev, why = device_status()
        except Exception as exc:            # noqa: BLE001 -- reported, not hidden
            dev, why = None, exc
        _STATUS.append((dev, None if dev is not None else str(why)))
    return _STATUS[0]


def _in_ci() -> bool:
    return os.environ.get("CI", "").strip().lower() not in ("", "0", "false", "no")


def pytest_configure(config):
    config.addinivalue_line("markers", "requires_opencl: needs a working OpenCL device "
                            "(fails in CI, skips elsewhere, where none works)")
    config.addinivalue_line("markers", "slow: left out of the README's test command "
                            "(pyproject addopts -m 'not slow'); CI runs them after it "
                            "with python -m pytest -q -m slow")


def _device_line() -> str:
    from ocl_tonemap.backends.opencl.runtime import describe_device
    dev, why = opencl_status()
    if dev is None:
        return f"OpenCL: no working device ({why})"
    return f"OpenCL device: {describe_device(dev)}, driver {dev.driver_version.strip()}"


def pytest_report_header(config):
    return _device_line()


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    """The device the OpenCL tests ran on, in the log even under -q (CI)."""
    if _STATUS:
        terminalreporter.write_line(_device_line())


def pytest_collection_modifyitems(config, items):
    for item in items:
        if "rt" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.requires_opencl)


def pytest_runtest_setup(item):
    if item.get_closest_marker("requires_opencl") is None:
        return
    dev, why = opencl_status()
    if dev is None:
        msg = f"requires_opencl: {why}"
        if _in_ci():
            pytest.fail(msg, pytrace=False)
        pytest.skip(msg)


@pytest.fixture(scope="session")
def rt():
    """The OpenCL runtime (the first working device). Tests need a real one."""
    from ocl_tonemap.backends.opencl.runtime import get_runtime
    return get_runtime()


@pytest.fixture(scope="session")
def tunnel_frames():
    """A short, small tunnel drive as arrays (cd/m^2): 3 s at 10 fps, 64x36."""
    from ocl_tonemap.io.sample import render_frame
    return [render_frame(i / 10.0, 64, 36, 3.0) for i in range(30)]


@pytest.fixture(scope="session")
def sample_dir(tmp_path_factory):
    """The built-in sample on disk: 1.5 s at 30 fps, 48x27 (EXR, cd/m^2)."""
    from ocl_tonemap.io.sample import write_tunnel_sequence
    d = tmp_path_factory.mktemp("sample")
    pattern, frames = write_tunnel_sequence(str(d), 48, 27, 30.0, 1.5)
    return pattern, frames


def hdr_image(h, w, seed=0, lo=-4.0, hi=5.0):
    rng = np.random.default_rng(seed)
    lum = 10.0 ** rng.uniform(lo, hi, (h, w, 1))
    return (lum * rng.uniform(0.05, 1.0, (h, w, 3))).astype(np.float32)


#: The line the kernel builds print once they have taken a second
#: (``backends/opencl/runtime._building_notice``): without a kernel cache
#: (PYOPENCL_NO_CACHE) on a busy machine it can come before a refusal.
BUILDING_NOTE = "ocl-tonemap NOTE: building the OpenCL kernels"
#: ... and the machine's own news where no OpenCL device works (the float64 reference
#: runs instead: CI under a broken driver without a second runtime).
FALLBACK_NOTE = "ocl-tonemap WARNING: no working OpenCL device"


def said(stderr: str) -> list:
    """A command's stderr lines, without the kernels' building notice and the
    no-device fallback's line (news of the machine, not of the command)."""
    return [ln for ln in stderr.strip().splitlines()
            if not ln.startswith((BUILDING_NOTE, FALLBACK_NOTE))]
