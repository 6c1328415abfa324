"""A separately installed package adds an operator (examples/exposure_operator): the
registry finds it through its entry point, the command line lists it and its options,
and it runs on both backends, its kernel within float32 of its reference."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

@pytest.fixture(scope="module")
def plugin_env(install_example):
    return install_example("exposure_operator")


def _py(env, code: str):
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert r.returncode == 0, r.stderr
    return r.stdout


@pytest.mark.requires_opencl
def test_plugin_operator_through_the_api(plugin_env):
    out = _py(plugin_env, """
import json, numpy as np
from ocl_tonemap import Tonemapper
from ocl_tonemap.operators import registry
assert "exposure" in registry()
rng = np.random.default_rng(0)
img = (np.exp(rng.normal(0, 1.5, (24, 32, 3))) * 20).astype(np.float32)
res = {}
for be in ("opencl", "reference"):
    tm = Tonemapper("exposure", be, options={"key": 0.2, "tau": 0.5}, model="none")
    a = tm.process(img)
    b = tm.process(img * 100, dt=0.5)              # one time constant after a 100x step
    res[be] = [a.tolist(), b.tolist(), tm.state.values["A"], tm.last.G_cone]
print(json.dumps(res))
""")
    res = json.loads(out)
    for be in ("opencl", "reference"):
        a, b, A, G = np.array(res[be][0]), np.array(res[be][1]), res[be][2], res[be][3]
        # exact exponential: one tau covers 1 - 1/e of the way (in cd/m^2)
        G0 = G / 100.0
        assert A == pytest.approx(G0 + (G - G0) * (1 - np.exp(-1.0)), rel=1e-4)
        assert b.mean() > a.mean()                     # not yet adapted: brighter
    np.testing.assert_allclose(res["opencl"][0], res["reference"][0], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(res["opencl"][1], res["reference"][1], rtol=1e-5, atol=1e-6)


def test_plugin_operator_on_the_command_line(plugin_env, tmp_path):
    cmd = [sys.executable, "-m", "ocl_tonemap"]
    h = subprocess.run(cmd + ["run", "--help"], capture_output=True, text=True, env=plugin_env)
    assert h.returncode == 0 and "exposure" in h.stdout and "--exposure-key" in h.stdout
    _py(plugin_env, f"""
from ocl_tonemap.io.sample import write_tunnel_sequence
write_tunnel_sequence({str(tmp_path / 'in')!r}, 64, 36, 30.0, 0.2)
""")
    (tmp_path / "out").mkdir()
    r = subprocess.run(cmd + ["run", str(tmp_path / "in" / "tunnel.####.exr"),
                              str(tmp_path / "out" / "o.####.png"), "--operator", "exposure",
                              "--exposure-key", "0.25", "-q"],
                       capture_output=True, text=True, env=plugin_env)
    assert r.returncode == 0, r.stderr
    n_in = len(list((tmp_path / "in").glob("tunnel.*.exr")))
    assert n_in > 1 and len(list((tmp_path / "out").glob("o.*.png"))) == n_in
    bad = subprocess.run(cmd + ["run", str(tmp_path / "in" / "tunnel.0001.exr"),
                                str(tmp_path / "bad.png"), "--operator", "exposure",
                                "--exposure-key", "-1"], capture_output=True, text=True,
                         env=plugin_env)
    assert bad.returncode == 2 and "--exposure-key must be > 0 and at most 1" in bad.stderr
    assert "Traceback" not in bad.stderr
