import numpy as np
import pytest


@pytest.fixture(scope="session")
def rt():
    """The OpenCL runtime (PoCL in CI). Tests need a real OpenCL device."""
    from ocl_tonemap.backends.opencl.runtime import get_runtime
    return get_runtime()


@pytest.fixture(scope="session")
def tunnel_frames():
    """A short, small tunnel drive as arrays (cd/m^2): 3 s at 10 fps, 64x36."""
    from ocl_tonemap.sample import render_frame
    return [render_frame(i / 10.0, 64, 36, 3.0) for i in range(30)]


@pytest.fixture(scope="session")
def sample_dir(tmp_path_factory):
    """The built-in sample on disk: 1.5 s at 30 fps, 48x27 (EXR, cd/m^2)."""
    from ocl_tonemap.sample import write_tunnel_sequence
    d = tmp_path_factory.mktemp("sample")
    pattern, frames = write_tunnel_sequence(str(d), 48, 27, 30.0, 1.5)
    return pattern, frames


def hdr_image(h, w, seed=0, lo=-4.0, hi=5.0):
    rng = np.random.default_rng(seed)
    lum = 10.0 ** rng.uniform(lo, hi, (h, w, 1))
    return (lum * rng.uniform(0.05, 1.0, (h, w, 3))).astype(np.float32)
