"""The OpenCL path against the float64 reference, on real sequences and at the extremes.

Stated tolerance (docs/models.md): |opencl - reference| <= 1e-3 * max(1, |reference|)
in display-linear output (1.0 = display white unit), i.e. 1e-3 absolute where an
SDR display shows it and 1e-3 relative above.
"""

import numpy as np
import pytest

from ocl_tonemap.pipeline import Tonemapper
from conftest import hdr_image

TOL = 1e-3


def assert_close(ocl, ref):
    err = np.abs(ocl.astype(np.float64) - ref) / np.maximum(1.0, np.abs(ref))
    assert np.isfinite(ocl).all()
    assert err.max() <= TOL, f"max scaled error {err.max():.3g}"


def run_both(frames, dt, **kw):
    a = Tonemapper(backend="reference", **kw)
    b = Tonemapper(backend="opencl", **kw)
    for f in frames:
        ra = a.process(f, dt=dt)
        rb = b.process(f, dt=dt)
        assert_close(rb, ra)
        assert a.last.params["rule"] == b.last.params["rule"] or \
            abs(a.last.G_cone / b.last.G_cone - 1) < 1e-5
    return a, b


@pytest.mark.requires_opencl
@pytest.mark.parametrize("metering", ["logmean", "mean", "max", "centre", "spot:0.5,0.7,0.05"])
def test_tunnel_sequence_agrees(tunnel_frames, metering):
    a, b = run_both(tunnel_frames, 0.1, metering=metering)
    for k in ("A_rod", "A_cone", "B_rod", "B_cone"):
        assert b.state.values[k] == pytest.approx(a.state.values[k], rel=1e-4)


@pytest.mark.requires_opencl
def test_percentile_metering_within_one_bin(tunnel_frames):
    from ocl_tonemap.models.metering import HIST_BINS, HIST_HI, HIST_LO
    bin_decades = (HIST_HI - HIST_LO) / HIST_BINS
    a = Tonemapper(backend="reference", metering="percentile:60", model="none")
    b = Tonemapper(backend="opencl", metering="percentile:60", model="none")
    for f in tunnel_frames[::5]:
        a.process(f, dt=0.5)
        b.process(f, dt=0.5)
        for g in ("G_cone", "G_rod"):
            ga, gb = getattr(a.last, g), getattr(b.last, g)
            assert abs(np.log10(gb) - np.log10(ga)) <= bin_decades


@pytest.mark.requires_opencl
@pytest.mark.parametrize("display", ["sdr", "pq", "crt"])
def test_displays_agree(display):
    from ocl_tonemap.models.display import DisplaySpec
    spec = {"sdr": DisplaySpec.from_white("sRGB - Display", 100.0),
            "pq": DisplaySpec.from_white("Rec.2100-PQ - Display", 1000.0, hdr=True),
            "crt": DisplaySpec.crt_2000()}[display]
    frames = [hdr_image(20, 30, s, lo, hi) for s, (lo, hi) in
              enumerate([(-5, -1), (-2, 2), (1, 5), (3, 8)])]
    run_both(frames, 0.25, display=spec)


@pytest.mark.requires_opencl
@pytest.mark.parametrize("shape", [(1, 1), (3, 7), pytest.param((4099, 3), marks=pytest.mark.slow),
                                   pytest.param((3, 4099), marks=pytest.mark.slow)])
def test_odd_sizes(shape):
    img = hdr_image(*shape, seed=3)
    run_both([img, img * 0.01], 0.05)


def test_bands_equal_single_pass():
    img = hdr_image(37, 53, seed=5)
    one = Tonemapper(model="none")
    banded = Tonemapper(max_band_pixels=200, model="none")      # 3 rows per band, 13 bands
    for k in range(3):
        f = img * (10.0 ** (2 * k - 2))
        r1 = one.process(f, dt=0.1)
        r2 = banded.process(f, dt=0.1)
        np.testing.assert_allclose(r2, r1, rtol=2e-5, atol=1e-6)
        assert banded.last.G_cone == pytest.approx(one.last.G_cone, rel=1e-5)


BAD = np.array([np.nan, np.inf, -np.inf, -3.0, 1e-41, 5.0, 1e12, 0.0, -0.0], np.float32)


@pytest.mark.requires_opencl
@pytest.mark.parametrize("backend", ["reference", "opencl"])
def test_bad_values_repaired_and_counted(backend):
    rng = np.random.default_rng(7)
    img = hdr_image(9, 11, seed=7)
    flat = img.reshape(-1)
    idx = rng.choice(flat.size, 40, replace=False)
    flat[idx] = np.resize(BAD, 40)
    tm = Tonemapper(backend=backend, model="none")
    out = tm.process(img)
    assert np.isfinite(out).all() and out.min() >= 0
    rep = tm.last.repairs
    vals = np.resize(BAD, 40)
    assert rep.nan == int(np.isnan(vals).sum())
    assert rep.pos_inf == int(np.isposinf(vals).sum())
    assert rep.neg_inf == int(np.isneginf(vals).sum())
    assert rep.negative == int(((vals < 0) & np.isfinite(vals)).sum())
    assert rep.denormal == int(((vals > 0) & (vals < np.finfo(np.float32).tiny)).sum())
    assert rep.over_max == int((vals == np.float32(1e12)).sum())


@pytest.mark.requires_opencl
def test_bad_values_same_output_both_backends():
    img = hdr_image(6, 6, seed=9)
    flat = img.reshape(-1)
    flat[::5] = np.resize(BAD, flat[::5].size)
    a = Tonemapper(backend="reference", model="none").process(img)
    b = Tonemapper(backend="opencl", model="none").process(img)
    assert_close(b, a)


@pytest.mark.requires_opencl
@pytest.mark.parametrize("level", [0.0, 1e-6, 1e-3, 1.0, 1e4, 1e8])
def test_uniform_extreme_scenes(level):
    img = np.full((4, 5, 3), level, np.float32)
    for backend in ("reference", "opencl"):
        tm = Tonemapper(backend=backend, model="none")
        for dt in (1e-3, 1 / 30, 3600.0):
            out = tm.process(img, dt=dt)
            assert np.isfinite(out).all() and out.min() >= 0 and out.max() <= 100.0


def test_all_zero_then_bright_no_nan():
    tm = Tonemapper(model="none")
    tm.process(np.zeros((8, 8, 3), np.float32))
    out = tm.process(np.full((8, 8, 3), 1e8, np.float32), dt=1e-3)
    assert np.isfinite(out).all()


def test_alpha_passed_through():
    img = np.concatenate([hdr_image(5, 6, seed=1), np.linspace(0, 1, 30, dtype=np.float32).reshape(5, 6, 1)], 2)
    out = Tonemapper(model="none").process(img)
    assert out.shape == (5, 6, 4)
    np.testing.assert_array_equal(out[..., 3], img[..., 3])


def test_time_must_not_go_backwards():
    tm = Tonemapper(model="none")
    img = hdr_image(4, 4)
    tm.process(img, time_s=1.0)
    with pytest.raises(ValueError, match="backwards"):
        tm.process(img, time_s=0.5)


def test_adaptation_dims_after_entering_dark():
    # Response compression on entering a tunnel: the first dark frame shows the
    # tunnel much darker than it looks once adapted (Fig. 7).
    tm = Tonemapper(model="none")
    bright = np.full((8, 8, 3), 5000.0, np.float32)
    dark = np.full((8, 8, 3), 5.0, np.float32)
    tm.process(bright)
    first = tm.process(dark, dt=1 / 30)[0, 0, 1]
    for _ in range(60):
        later = tm.process(dark, dt=1 / 30)[0, 0, 1]
    assert first < 0.2 * later


@pytest.mark.parametrize("n", [1, 3, 4, 5, 8, 9, 15, 1023])
def test_vector_kernel_equals_scalar_kernel(rt, n):
    """pattanaik00_map8 (eight pixels per work-item, the scalar tail) against the scalar
    kernel."""
    import pyopencl as cl
    from ocl_tonemap.models import pattanaik2000 as P
    tm = Tonemapper(model="none")
    img = hdr_image(1, n, seed=n)
    tm.process(img)
    b = tm.backend.bufs
    p = P.frame_params(tm.scalar_state(), tm.display)
    outs = []
    for vector in (True, False):
        tm.backend.run_pointwise(tm.op.kernel_call(p, vector=vector), b["rgb"], b["Y"],
                                 b["Ys"], b["out"], n)
        o = np.empty((n, 3), np.float32)
        cl.enqueue_copy(rt.queue, o, b["out"])
        outs.append(o)
    np.testing.assert_allclose(outs[0], outs[1], rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize("channels", [3, 4])
@pytest.mark.parametrize("n", [1, 5, 64, 1027])
def test_colour_stage_quads_equal_scalar(rt, channels, n):
    """scene_to_working4 (four pixels per work-item, the scalar policy for any quad with
    a bad value) gives the scalar kernel's values bit for bit, and the same counts."""
    import pyopencl as cl
    from ocl_tonemap.backends.opencl.runtime import round_up
    rng = np.random.default_rng(n)
    src = (10.0 ** rng.uniform(-8, 9, (n, channels))).astype(np.float32)
    hit = rng.choice(src.size, min(src.size, 25), replace=False)
    src.reshape(-1)[hit] = np.resize(np.append(BAD, [1e-39, 3e-38]), hit.size)
    mf = cl.mem_flags
    sbuf = cl.Buffer(rt.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=src)
    got = []
    for name, items in (("scene_to_working", n), ("scene_to_working4", rt.pixel_items(n, 4))):
        bufs = [cl.Buffer(rt.context, mf.READ_WRITE, n * k * 4) for k in (3, 1, 1)]
        counts = cl.Buffer(rt.context, mf.READ_WRITE | mf.COPY_HOST_PTR,
                           hostbuf=np.zeros(8, np.int32))
        rt.kernel("colour.cl", name)(rt.queue, (round_up(items, 64),), (64,), sbuf,
                                     np.int32(channels), np.int32(n), np.float32(1e3),
                                     *bufs, counts, np.int32(0), np.int32(n))
        host = [np.empty(n * k, np.float32) for k in (3, 1, 1)] + [np.empty(8, np.int32)]
        for h, d in zip(host, bufs + [counts]):
            cl.enqueue_copy(rt.queue, h, d)
        got.append(host)
    for a, b in zip(*got):
        np.testing.assert_array_equal(a.view(np.uint32), b.view(np.uint32))
    assert got[0][3][:6].sum() > 0                          # repairs were made and counted


@pytest.mark.parametrize("n", [1, 3, 4, 5, 1023])
def test_durand00_float4_kernel_equals_scalar_kernel(rt, n):
    import dataclasses
    import pyopencl as cl
    tm = Tonemapper("durand00", model="none")
    img = hdr_image(1, n, seed=n, lo=-3, hi=6)              # highlights over the knee
    tm.process(img)
    b = tm.backend.bufs
    call = tm.op.kernel_call(tm.op.params(tm.scalar_state(), None))
    assert call.kernel == "durand00_map4" and dict(call.params)["knee"] > 0
    outs = []
    for c in (call, dataclasses.replace(call, kernel="durand00_map", pixels_per_item=1)):
        tm.backend.run_pointwise(c, b["rgb"], b["Y"], b["Ys"], b["out"], n)
        o = np.empty((n, 3), np.float32)
        cl.enqueue_copy(rt.queue, o, b["out"])
        outs.append(o)
    np.testing.assert_allclose(outs[0], outs[1], rtol=1e-6, atol=1e-7)


@pytest.mark.requires_opencl
def test_profiling_hook_times_every_kernel_launched(tmp_path):
    """OCLTM_PROFILE=1 (the benchmarks' per-kernel tables): each operator's frame
    records its kernels with positive device times; without it nothing is kept."""
    import json
    import subprocess
    import sys
    code = (
        "import json, numpy as np\n"
        "from ocl_tonemap.pipeline import Tonemapper\n"
        "from ocl_tonemap.backends.opencl.runtime import kernel_times\n"
        "img = (10.0 ** np.random.default_rng(1).uniform(-2, 3, (37, 53, 3))).astype(np.float32)\n"
        "out = {}\n"
        "for op in ('pattanaik00', 'durand00', 'ledda04', 'kirk11'):\n"
        "    tm = Tonemapper(operator=op, backend='opencl')\n"
        "    tm.process(img, 0.0); tm.process(img, 0.04)\n"
        "    out[op] = kernel_times()\n"
        "print(json.dumps(out))\n")
    for env, on in (({"OCLTM_PROFILE": "1"}, True), ({"OCLTM_PROFILE": "0"}, False)):
        p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                           env={**__import__("os").environ, **env})
        assert p.returncode == 0, p.stderr
        times = json.loads(p.stdout.strip().splitlines()[-1])
        for op, kt in times.items():
            if not on:
                assert kt == {}, op
                continue
            assert kt, op
            assert all(ms >= 0 and n >= 1 for ms, n in kt.values()), (op, kt)
            assert sum(ms for ms, _ in kt.values()) > 0, op
        if on:
            assert any(k.startswith("ledda04") for k in times["ledda04"])
            assert "bilateral_exact" in times["ledda04"] and "kirk11_shift" in times["kirk11"]


_LANES_SCRIPT = r"""
import sys, numpy as np
from ocl_tonemap.pipeline import Tonemapper
from ocl_tonemap.backends.opencl.runtime import get_runtime
img = np.load(sys.argv[1])
out = {"vector": np.array(get_runtime().vector_pixels)}
for op in ("pattanaik00", "durand00", "ledda04", "kirk11"):
    tm = Tonemapper(op, "opencl", model="none")      # the operators alone
    for k, dt in enumerate((None, 0.5)):           # fresh, then a time step
        out[f"{op}{k}"] = tm.process(img * (1.0 + 9.0 * k), dt=dt)
np.savez(sys.argv[2], **out)
"""


@pytest.mark.requires_opencl
def test_one_pixel_a_work_item_equals_the_vector_path(tmp_path):
    """The per-pixel kernels as GPUs run them (one pixel a work-item, scalar code:
    OCLTM_VECTOR_PIXELS=0, in a process of its own) on this CPU device give every
    operator's output of the vector path (several pixels a work-item), fresh and after
    a time step, on a frame whose width leaves tails and holds bad values. The two
    round each formula in their own order (float4 bodies), so within 2e-6."""
    import os
    import subprocess
    import sys
    img = hdr_image(29, 37, seed=5, lo=-6.0, hi=7.0)
    img[3, 4] = (np.nan, np.inf, -1.0)
    img[7, 36] = (1e-40, 0.0, 1e9)
    np.save(tmp_path / "in.npy", img)
    got = {}
    for flag in ("0", "1"):
        env = dict(os.environ, OCLTM_VECTOR_PIXELS=flag)
        r = subprocess.run([sys.executable, "-c", _LANES_SCRIPT, str(tmp_path / "in.npy"),
                            str(tmp_path / f"out{flag}.npz")], env=env, capture_output=True,
                           text=True, timeout=600)
        assert r.returncode == 0, r.stderr[-2000:]
        got[flag] = dict(np.load(tmp_path / f"out{flag}.npz"))
    assert not got["0"].pop("vector") and got["1"].pop("vector")
    assert got["0"].keys() == got["1"].keys() and len(got["0"]) == 8
    for key, a in got["0"].items():
        b = got["1"][key]
        assert np.isfinite(a).all(), key
        np.testing.assert_allclose(a, b, rtol=2e-6, atol=1e-7, err_msg=key)


def test_inline_log2_within_float32_rounding_of_log2(rt):
    """common.h log2_positive4 (metering's log-average; PoCL calls its own log2 out of
    line): within what the OpenCL specification allows the device's float32 arithmetic
    of max(1, |log2 x|), from metering's floor (1e-6 cd/m^2) to 1e10, the mantissa's
    fold at sqrt(2), powers of two and values just beside them. The bound: the one
    division t = (m - 1)/(m + 1) may be off by 2.5 ulp (OpenCL C 1.2+, 7.4: x / y, full
    profile; a CPU driver rounds it correctly, NVIDIA's does not: 1.33e-7 on the H100),
    and the series' four multiply-adds and the final add by half an ulp each, of a
    result within [-0.5, 0.5] (e = 0) or added to e exactly: 4.5 ulp of 1, 2.7e-7."""
    import pyopencl as cl
    from ocl_tonemap.backends.opencl.runtime import build_options, kernel_dir
    src = (kernel_dir() / "common.h").read_text() + """
__kernel void log2_test(__global const float *x, __global float *y)
{ const int i = get_global_id(0); vstore4(log2_positive4(vload4(i, x)), i, y); }"""
    prog = cl.Program(rt.context, src).build(options=build_options(rt.device))
    r2 = np.float32(np.sqrt(2.0))
    special = np.array([1e-6, 1.0, 2.0, 0.5, 1e10, r2, np.nextafter(r2, 2), np.nextafter(r2, 0),
                        np.nextafter(np.float32(1), 0), np.nextafter(np.float32(2), 0)], np.float32)
    x = np.concatenate([np.geomspace(1e-6, 1e10, 400_000).astype(np.float32), special,
                        np.ones(2, np.float32)])
    d_x = cl.Buffer(rt.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=x)
    d_y = cl.Buffer(rt.context, cl.mem_flags.WRITE_ONLY, x.nbytes)
    cl.Kernel(prog, "log2_test")(rt.queue, (x.size // 4,), None, d_x, d_y)
    y = np.empty_like(x)
    cl.enqueue_copy(rt.queue, y, d_y)
    ref = np.log2(x.astype(np.float64))
    divide_ulp, rounding_ulp = 2.5, 4 * 0.5
    bound = (divide_ulp + rounding_ulp) * 2.0 ** -24
    assert np.max(np.abs(y - ref) / np.maximum(np.abs(ref), 1.0)) < bound
    assert y[np.flatnonzero(x == 1.0)].tolist() == [0.0] * 3 and y[x == 2.0][0] == 1.0
