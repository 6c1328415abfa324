"""Ledda, Santos & Chalmers 2004 (ledda04) and the shared bilateral filters."""

import math

import numpy as np
import pytest

from conftest import hdr_image
from ocl_tonemap.models import ledda2004 as L
from ocl_tonemap.io.state_files import load_state, save_state
from ocl_tonemap.backends.opencl.bilateral import DeviceBilateral
from ocl_tonemap.models.bilateral import LEDDA_RANGE, RangeKernel, bilateral_reference
from ocl_tonemap.pipeline import Tonemapper

#: Stated tolerance of the device exact path against float64 (relative).
TOL_EXACT = 1e-5
#: Recorded bound of the grid (q_s = q_r = 2) against exact on white-noise HDR
#: (the worst case; natural scenes are far better, see benchmarks/results).
FAST_MAX_LOG10 = 0.02
#: Operator output, device vs float64 reference, scaled as in the foundation.
TOL_OP = 1e-3
#: Over a shot, a pixel whose goal lands within float32 rounding of one of the time
#: course's thresholds (ledda2004.step_reference) may take the other branch on the
#: device: at most this share of the pixels beyond TOL_OP, by at most BRANCH_DIFF
#: (measured on the 240-frame tunnel drive at 160x90: 0.11 %, 0.047).
RARE_BRANCHES, BRANCH_DIFF = 0.003, 0.1


#: ledda04's paper course (Eqs. 14-17), which the course tests test: by default the
#: slow course is the shared pigment model's (issue 66).
PAPER = {"mode": "paper"}


@pytest.fixture(scope="module")
def filt(rt):
    return DeviceBilateral(rt)


def piecewise_scene(h=40, w=60):
    """A 1e4:1 step with gentle gradients and texture on each side (cd/m^2)."""
    x = np.linspace(0, 1, w)[None, :]
    y = np.linspace(0, 1, h)[:, None]
    lum = np.where(x < 0.5, 0.01 * (1 + 0.3 * y), 100.0 * (1 + 0.3 * x)) * np.ones((h, w))
    return lum


# --- bilateral ---------------------------------------------------------------------

@pytest.mark.parametrize("sigma", [1.0, 2.5])
def test_exact_bilateral_matches_float64(filt, sigma):
    v = hdr_image(30, 41, seed=5)[..., 1]
    ref = bilateral_reference(v, sigma, LEDDA_RANGE)
    dev = filt.filter(v, sigma, LEDDA_RANGE, "exact")
    assert np.max(np.abs(dev / ref - 1)) < TOL_EXACT
    rk = RangeKernel("difference", 0.4 * math.log(10))
    lv = np.log(v + 1e-3)
    ref = bilateral_reference(lv, sigma, rk)
    assert np.max(np.abs(filt.filter(lv, sigma, rk, "exact") - ref)) < 1e-4


def test_exact_bilateral_wider_than_the_image(filt):
    """A spatial sigma far wider than the frame (1e5 px on 41 x 30: the declared
    --sigma-spatial allows it) takes the time of the frame, not of 6e5 offsets per
    pixel (offsets past the image add nothing; it ran for minutes past SIGTERM), and
    equals the float64 brute force written over every pixel pair."""
    v = hdr_image(30, 41, seed=7)[..., 1]
    sigma = 1e5
    ref = bilateral_reference(v, sigma, LEDDA_RANGE)
    vv = np.maximum(v.astype(np.float64), 1e-12).ravel()
    ys, xs = np.divmod(np.arange(v.size), v.shape[1])
    d2 = (ys[:, None] - ys[None, :]) ** 2 + (xs[:, None] - xs[None, :]) ** 2
    t = vv[None, :] / vv[:, None] - 1.0
    wgt = np.exp(-0.5 * d2 / sigma ** 2) * np.exp(-LEDDA_RANGE.k * t * t)
    direct = (wgt @ vv) / wgt.sum(axis=1)
    assert np.allclose(ref.ravel(), direct, rtol=1e-12)
    dev = filt.filter(v, sigma, LEDDA_RANGE, "exact")
    assert np.max(np.abs(dev / ref - 1)) < TOL_EXACT


def test_fast_bilateral_within_recorded_bound(filt):
    v = hdr_image(48, 64, seed=6)[..., 1].astype(np.float64)
    ex = filt.filter(v, 3.0, LEDDA_RANGE, "exact")
    fa = filt.filter(v, 3.0, LEDDA_RANGE, "fast", 2.0, 2.0)
    err = np.abs(np.log10(fa) - np.log10(ex))
    assert err.max() < FAST_MAX_LOG10
    coarse = np.abs(np.log10(filt.filter(v, 3.0, LEDDA_RANGE, "fast", 1.0, 1.0)) - np.log10(ex))
    assert coarse.mean() > err.mean()          # the knob does what it says


@pytest.mark.parametrize("method", ["exact", "fast"])
def test_bilateral_constant_and_edge(filt, method):
    const = np.full((20, 30), 7.5)
    assert np.allclose(filt.filter(const, 3.0, LEDDA_RANGE, method), 7.5, rtol=1e-5)
    lum = piecewise_scene()
    out = filt.filter(lum, 4.0, LEDDA_RANGE, method)
    # the edge stops the filter: the dark side is not lifted by the bright one
    assert np.all(out[:, :29] < 0.02) and np.all(out[:, 31:] > 90)


def test_range_kernel_is_a_function_of_log_ratio():
    # Eq. 10 with sigma_g = 0.15 I_s depends on I_p / I_s only.
    rk = LEDDA_RANGE
    for Is in (1e-4, 1.0, 1e6):
        Ip = Is * np.array([0.8, 1.0, 1.1, 1.3])
        direct = np.exp(-(Ip - Is) ** 2 / (2 * (0.15 * Is) ** 2))
        assert np.allclose(rk.weight_of_dz(np.log(Ip / Is)), direct)


# --- the static operator -------------------------------------------------------------

def test_mesopic_factor_range_and_monotonic():
    I = np.logspace(-6, 8, 500)
    m = L.mesopic_factor_ledda2004(I)
    assert m.min() == 0.0 and m.max() == 1.0 and np.all(np.diff(m) >= 0)
    assert L.mesopic_factor_ledda2004(0.01) == 0.0 and L.mesopic_factor_ledda2004(10 ** 0.6) == 1.0
    assert 0 < L.mesopic_factor_ledda2004(0.1) < 1


def test_inverse_identity():
    # (R/(1-R))^(1/n) sigma_disp == Y sigma_disp / sigma, used for stability.
    Y = np.logspace(-3, 3, 13)
    s = L.sigma_of(2.0, L.BETA_CONE)
    R = L.response(Y, s)
    assert np.allclose(L.inverse_response(R, 1.0), Y / s, rtol=1e-9)


def test_photopic_cone_only_scotopic_rod_only():
    tm = Tonemapper("ledda04", "reference", model="none")
    bright = np.ones((12, 12, 3)) * np.array([150.0, 100.0, 60.0])   # warm, photopic
    out = tm.process(bright * 0.5)               # (below the highlight shoulder)
    # cones only: chromaticity kept (channel ratios of the input)
    assert np.allclose(out[6, 6] / out[6, 6, 1], [1.5, 1.0, 0.6], rtol=1e-6)
    dark = bright * 1e-5
    out = Tonemapper("ledda04", "reference", model="none").process(dark)
    assert np.allclose(out[6, 6], out[6, 6, 0], rtol=1e-6)           # rods only: grey
    assert out[6, 6, 0] > 0
    meso = bright * 1e-3                                             # I_A ~ 0.1 cd/m^2
    out = Tonemapper("ledda04", "reference", model="none").process(meso)
    r = out[6, 6] / out[6, 6, 1]
    assert 1.0 < r[0] < 1.5 and 0.6 < r[2] < 1.0                    # both: desaturated


@pytest.mark.requires_opencl
def test_no_halo_across_a_step():
    lum = piecewise_scene()
    img = np.repeat(lum[..., None], 3, axis=2)
    for method in ("exact", "fast"):
        out = Tonemapper("ledda04", "opencl", options={"bilateral": method,
                                                       "sigma_spatial": 4.0}, model="none").process(img)
        row = out[20, :, 1]
        assert np.all(np.diff(row) >= -1e-7), method          # monotonic, no reversal


@pytest.mark.requires_opencl
@pytest.mark.parametrize("method", ["exact", "fast"])
def test_opencl_matches_reference_over_time(method):
    img = hdr_image(24, 36, seed=7, lo=-4, hi=4)
    opts = {"rods": "always", "sigma_spatial": 2.5}
    a = Tonemapper("ledda04", "opencl", options=dict(opts, bilateral=method), model="none")
    b = Tonemapper("ledda04", "reference", options=opts, model="none")
    tol = TOL_OP if method == "exact" else 0.05
    for t, k in ((0, 1.0), (0.5, 1e-3), (3, 1e-3), (700, 1e-3), (4000, 1e-3), (4010, 10.0)):
        oa = a.process(img * k, time_s=t)
        ob = b.process(img * k, time_s=t)
        assert np.max(np.abs(oa - ob) / np.maximum(1.0, np.abs(ob))) < tol, (method, t)


# --- time course -----------------------------------------------------------------------

def test_dark_curve_endpoints_and_energy():
    t = np.array([0.1, 1.0, 2.0, 10.0, 60.0, 599.0, 600.0, 1e4])
    for K in (L.K_MIN, 9.0, L.K_MAX):
        f = L.dark_fraction(t, K, L.TAU_CONE)
        assert f[0] == 1.0 and f[1] == pytest.approx(1.0) and f[-2] == 0.0 and f[-1] == 0.0
        assert np.all(np.diff(f) <= 0)
    # larger energy -> smaller K -> slower recovery (Eq. 17)
    assert L.K_of_energy(0) == 12.0 and L.K_of_energy(1e9) == pytest.approx(L.K_MIN)
    assert L.dark_fraction(60.0, L.K_of_energy(8000), 600) > L.dark_fraction(60.0, L.K_of_energy(100), 600)


def test_light_curve_and_rod_lag():
    assert L.light_fraction(1.0, 20) == 1.0 and L.light_fraction(20.0, 20) == 0.0
    assert L.light_fraction(np.sqrt(20.0), 20) == pytest.approx(0.5)
    # in the dark, rods hold sigma_in until tau_cone has passed
    s = L.sigma_at(100.0, 1.0, np.array([0.0, 300.0, 600.0, 660.0, 3100.0]), 8.0, "rod")
    assert s[0] == s[1] == s[2] == 100.0 and 1.0 < s[3] < 100.0 and s[4] == 1.0
    c = L.sigma_at(100.0, 1.0, np.array([0.0, 60.0, 600.0]), 8.0, "cone")
    assert c[0] == 100.0 and 1.0 < c[1] < 100.0 and c[2] == 1.0


@pytest.mark.requires_opencl
def test_long_dark_reaches_static_result():
    img = hdr_image(16, 20, seed=8, lo=-3, hi=1)
    # (the paper's course, Eqs. 14-17: the default's is the shared pigment's)
    tm = Tonemapper("ledda04", "opencl", preadapt=(500.0, 60.0), model="none", options=PAPER)
    tm.process(img, time_s=0)
    first = tm.last_output.copy()
    out = tm.process(img, time_s=3 * 3600.0)
    static = Tonemapper("ledda04", "opencl", model="none", options=PAPER).process(img)
    assert np.allclose(out, static, rtol=1e-5, atol=1e-7)
    assert first.mean() < 0.2 * static.mean()      # temporarily blind at the switch


@pytest.mark.requires_opencl
def test_small_changes_continue_the_course():
    img = hdr_image(10, 10, seed=9, lo=0, hi=1)
    tm = Tonemapper("ledda04", "opencl", model="none", options=PAPER)
    tm.process(img, time_s=0)
    tm.process(img * 1.05, time_s=0.1)        # 0.015 log10 in sigma: below the threshold
    assert tm.last.params["restarted_fraction"] == 0.0
    tm.process(img * 10, time_s=0.2)          # a jump after the course was done: a new one
    assert tm.last.params["restarted_fraction"] == 1.0


def test_course_clock_inverts_the_curves():
    """course_clock finds the time at which a curve (Eqs. 14-15) passes a sigma: dark
    and light, cones and rods (tau_cone later in the dark); in the hold the clock runs
    on, at most to the hold's end; near the end the course counts as finished."""
    for receptor in ("cone", "rod"):
        for s_in, goal in ((100.0, 1.0), (1.0, 100.0)):
            lag = L.TAU_CONE if (receptor == "rod" and goal < s_in) else 0.0
            t = lag + np.array([1.05, 1.5, 3.0, 8.0, 15.0])
            for K in (L.K_MIN, L.K_MAX):
                now = L.sigma_at(s_in, goal, t, K, receptor)
                keep = np.abs(goal - now) > L.COURSE_DONE * goal
                got = L.course_clock(s_in, goal, now, K, 0.0, receptor)
                np.testing.assert_allclose(got[keep], t[keep], rtol=1e-6)
                assert np.all(got[~keep] == L.T_DONE)
            held = L.course_clock(s_in, goal, s_in, 9.0, np.array([0.3, 5e3]), receptor)
            np.testing.assert_allclose(held, [0.3, lag + L.T_HOLD])


@pytest.mark.requires_opencl
@pytest.mark.parametrize("backend", ["opencl", "reference"])
def test_a_drifting_goal_is_followed_not_frozen(backend):
    """A field that dims (or brightens) by 0.02 log10 a frame for 5 s at 30 fps: each
    frame re-aims the running course at the new goal, so sigma follows at the curve's
    pace. Before, a goal that kept moving past the restart threshold restarted the
    course every few frames and each restart held sigma_in for the curve's first
    second: sigma stayed where the drift began (94x the goal after the dimming). Now
    3.5x, and 1/5 of it after the brightening (Eq. 15's light curve is slow)."""
    for sign, Y0, bound in ((-1, 1000.0, (1.0, 5.0)), (1, 1.0, (0.1, 1.0))):
        tm = Tonemapper("ledda04", backend, options=PAPER)
        ratios = []
        for k in range(151):
            tm.process(np.full((8, 8, 3), Y0 * 10 ** (sign * 0.02 * k), np.float32), dt=1 / 30)
            st = tm.schedule.pixel_state()
            sc, _ = L.current_sigmas({n: np.asarray(v, np.float64) for n, v in st.items()})
            ratios.append(float(np.mean(sc / np.asarray(st["sigma_fin_cone"], np.float64))))
        assert bound[0] < ratios[-1] < bound[1], (sign, ratios[-1])
        r = np.asarray(ratios) if sign < 0 else 1.0 / np.asarray(ratios)
        assert np.all(np.diff(r) > -1e-4)           # the lag grows smoothly, no sawtooth


@pytest.mark.requires_opencl
def test_figure_11_trend():
    from benchmarks.lib.validation import dark_adaptation_thresholds
    times = np.geomspace(0.5, 2700, 40)
    lo_E = dark_adaptation_thresholds(5.0, times, options=PAPER)      # E = 1000
    hi_E = dark_adaptation_thresholds(120.0, times, options=PAPER)    # E beyond 10567
    for th in (lo_E, hi_E):
        assert np.all(np.diff(th) <= 0)                 # thresholds only fall
        assert th[-1] < th[0] / 100
    assert np.all(hi_E >= lo_E) and np.any(hi_E > lo_E)  # more energy: slower


# --- extremes, state, bands ----------------------------------------------------------

@pytest.mark.requires_opencl
@pytest.mark.parametrize("backend", ["opencl", "reference"])
def test_extremes_never_nan(backend):
    img = hdr_image(9, 11, seed=10)
    img[0, 0] = [np.nan, np.inf, -np.inf]
    img[1, 1] = [-3.0, 1e-42, 0.0]
    img[2] = 1e8
    img[3] = 1e-6
    img[4] = 0.0
    tm = Tonemapper("ledda04", backend, model="none")
    for t in (0.0, 0.001, 0.002, 3600.0, 7200.0 + 0.001):
        out = tm.process(img, time_s=t)
        assert np.all(np.isfinite(out)) and out.min() >= 0
    assert tm.last.repairs.nan == 1
    one = Tonemapper("ledda04", backend, model="none").process(np.full((1, 1, 3), 5.0))
    assert np.all(np.isfinite(one)) and one.shape == (1, 1, 3)
    zero = Tonemapper("ledda04", backend, model="none").process(np.zeros((4, 4, 3)))
    assert np.all(zero == 0)


@pytest.mark.requires_opencl
@pytest.mark.parametrize("method", ["exact", "fast"])
def test_bands_equal_one_pass(method):
    img = hdr_image(45, 50, seed=11, lo=-3, hi=3)
    opts = {"bilateral": method, "sigma_spatial": 3.0}
    a = Tonemapper("ledda04", "opencl", options=opts, model="none")
    b = Tonemapper("ledda04", "opencl", options=opts, max_band_pixels=50 * 11, model="none")
    for t, k in ((0, 1.0), (2, 0.01), (50, 0.01)):
        # equal but for the float32 order of the frame's global log-average sums
        np.testing.assert_allclose(a.process(img * k, time_s=t), b.process(img * k, time_s=t),
                                   rtol=2e-5, atol=1e-8)
        assert a.last.repairs.as_dict() == b.last.repairs.as_dict()
    # the paper's fully local mode has no global sum: bit for bit
    opts["mode"] = "paper"
    a = Tonemapper("ledda04", "opencl", options=opts, model="none")
    b = Tonemapper("ledda04", "opencl", options=opts, max_band_pixels=50 * 11, model="none")
    for t, k in ((0, 1.0), (2, 0.01), (50, 0.01)):
        assert np.array_equal(a.process(img * k, time_s=t), b.process(img * k, time_s=t))


@pytest.mark.requires_opencl
def test_state_side_file_roundtrip(tmp_path):
    img = hdr_image(20, 30, seed=12)
    one = Tonemapper("ledda04", "opencl", model="none")
    for t, k in ((0, 1.0), (1, 1e-3)):
        one.process(img * k, time_s=t)
    save_state(one.state, tmp_path / "s.json")
    assert (tmp_path / "s.pixels.exr").exists()
    final = one.process(img * 1e-3, time_s=30)
    st = load_state(tmp_path / "s.json")
    assert set(st.pixels) == set(L.STATE_CHANNELS)
    two = Tonemapper("ledda04", "opencl", state=st, model="none")
    assert np.array_equal(two.process(img * 1e-3, time_s=30), final)
    with pytest.raises(ValueError, match="one image size"):
        Tonemapper("ledda04", "opencl", state=st, model="none").process(img[:10], time_s=31)
    # a state saved before each receptor had its own clock: refused, saying why
    old = load_state(tmp_path / "s.json")
    old.pixels = {("t_course" if k == "t_cone" else k): v for k, v in old.pixels.items()
                  if k != "t_rod"}
    with pytest.raises(ValueError, match="lacks t_cone, t_rod: .*t_course.*start"):
        Tonemapper("ledda04", "opencl", state=old, model="none").process(img, time_s=31)


def test_grid_fits_device_memory_and_tiny_images(filt):
    # a grid that would not fit is coarsened, not an allocation failure
    g = filt.fit_geometry(7680, 4320, -20.0, 20.0, 4.0, LEDDA_RANGE, 2.0, 2.0)
    assert g.nbytes <= filt.grid_limit_bytes() and g.s_s > 2.0
    with pytest.raises(ValueError, match="use the exact filter"):
        filt.fit_geometry(10 ** 6, 10 ** 6, -20.0, 20.0, 4.0, LEDDA_RANGE, 2.0, 2.0)
    for shape in ((1, 1), (1, 7), (5, 1)):
        v = np.full(shape, 3.0)
        assert np.allclose(filt.filter(v, 3.0, LEDDA_RANGE, "fast"), 3.0, rtol=1e-5)


@pytest.mark.requires_opencl
@pytest.mark.parametrize("mode", ["default", "paper"])
@pytest.mark.parametrize("shape", [(9, 11), (16, 24)])
def test_map_float4_kernel_equals_scalar_kernel(mode, shape):
    """ledda04_map4 (four pixels per work-item, both branches of the time course
    selected per pixel) gives the scalar kernel's output through light adaptation,
    dark adaptation and restarts, on sizes with and without a tail."""
    img = hdr_image(*shape, seed=11, lo=-3, hi=5)
    img[:, : shape[1] // 2] *= 1e-3                      # half the frame mesopic/scotopic
    tms = []
    for vector in (True, False):
        tm = Tonemapper("ledda04", options={"mode": mode, "bilateral": "exact"}, model="none")
        tm.schedule.set_map_kernel(vector=vector)
        tms.append(tm)
    for k, (scale, dt) in enumerate([(1.0, 0.0), (1e-4, 0.5), (1e-4, 20.0), (1e2, 0.2),
                                     (1e2, 3.0)]):
        a, b = (tm.process(img * scale, dt=dt if k else None) for tm in tms)
        np.testing.assert_allclose(a, b, rtol=2e-6, atol=1e-7)
        assert a.max() > 0


@pytest.mark.requires_opencl
@pytest.mark.parametrize("mode", ["default", "paper"])
@pytest.mark.parametrize("shape", [(9, 11), (16, 24)])
def test_step_float4_kernel_equals_scalar_kernel(mode, shape):
    """ledda04_step4 (four pixels per work-item, the restart branch selected per lane)
    leaves the scalar kernel's per-pixel state and restart count through light
    adaptation, dark adaptation and restarts of part of the frame, with and without a
    tail."""
    img = hdr_image(*shape, seed=12, lo=-3, hi=5)
    tms = []
    for vector in (True, False):
        tm = Tonemapper("ledda04", options={"mode": mode, "bilateral": "exact"}, model="none")
        tm.schedule.set_step_kernel(vector=vector)
        tms.append(tm)
    part = np.ones_like(img)
    part[:, : shape[1] // 3] = 1e-3                  # only some pixels' goals move
    steps = [(img, None), (img * 1e-4, 0.5), (img * 1e-4, 20.0), (img, 0.2),
             (img * part, 3.0), (img * part, 0.04)]
    restarts = []
    pigment = mode == "default"          # each pixel at once at its level: no course
    for frame, dt in steps:
        a, b = (tm.process(frame, dt=dt) for tm in tms)
        np.testing.assert_allclose(a, b, rtol=2e-6, atol=1e-7)
        sa, sb = (tm.schedule.pixel_state() for tm in tms)
        for k in sa:
            np.testing.assert_allclose(sa[k], sb[k], rtol=2e-6, atol=1e-30, err_msg=k)
        ra, rb = (tm.last.params["restarted_fraction"] for tm in tms)
        assert ra == rb
        restarts.append(ra)
    if pigment:
        assert restarts == [0.0] * len(steps)
        return
    assert restarts[1] == 1.0 and restarts[2] == 0.0 and restarts[-1] == 0.0
    if mode == "paper":           # purely local levels: only the darkened third restarts
        assert 0.0 < restarts[4] < 1.0


@pytest.mark.requires_opencl
def test_no_stepped_rings_on_the_tunnel_drive_with_the_defaults():
    """The tunnel drive of the built-in sample (160x90) with ledda04's defaults, as a
    user gets them (a 25-year-old's glare), on the device and on the float64 reference
    (``--quality reference``): the display shows few steps that the scene does not
    have (``appearance_metrics.step_artefacts`` on frames 60-150: the tunnel's mouth,
    lamps, the exit as it nears) and the two backends agree on every frame; inside,
    the walls brighten as the eye adapts. Measured 0.2-2.3 % (1.2 % on average; the
    wall-road line and the exit's rim, which the scene's own edge finder misses, and
    arcs where the goals turn from dark to light as the exit nears). Issue 45's rings
    (each pixel's course restarting on its own frame as its level drifted, then held)
    were 4.6 % at worst with Eq. 8's veil; with a 25-year-old's veil the same rule drew
    7.4 %, and its walls stayed at the sunlit approach's level (frame 90 darker than
    frame 60). The reference once decided "rods or not" on the blended levels and the
    device on the local ones: the rod goals then differed by the neutral-ratio
    stand-in, the restarts fell on other frames and the reference drew rings the
    device did not."""
    from benchmarks.lib.appearance_metrics import step_artefacts
    from ocl_tonemap.colour import ColourPipeline, load_config
    from ocl_tonemap.io.sample import render_frame
    cp = ColourPipeline(load_config("ocl-tonemap"), "sRGB - Display")
    tms = {b: Tonemapper("ledda04", backend=b) for b in ("opencl", "reference")}
    found = {b: [] for b in tms}
    wall = {b: {} for b in tms}
    for k in range(151):
        rgb = render_frame(k / 30.0, 160, 90, 8.0, ss=1).astype(np.float32)
        out = {b: tm.process(rgb, dt=1 / 30) for b, tm in tms.items()}
        diff = np.abs(out["opencl"] - out["reference"]).max(axis=2)
        assert np.mean(diff > TOL_OP) <= RARE_BRANCHES and diff.max() < BRANCH_DIFF, k
        if k >= 60 and k % 5 == 0:
            for b, o in out.items():
                codes = np.round(np.clip(cp.encode(np.ascontiguousarray(np.clip(o, 0, 1))),
                                         0, 1) * 255)
                found[b].append((step_artefacts(codes, rgb), k))
                wall[b][k] = codes[45, 20].mean()
    for b in tms:
        assert max(found[b])[0] < 0.03, (b, max(found[b]))
        assert np.mean([f for f, _ in found[b]]) < 0.015, b
        assert wall[b][90] > 1.5 * wall[b][60], (b, wall[b])
