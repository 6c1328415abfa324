"""Adrian 1989's threshold luminance difference and CIE 146's disability glare
(models/adrian1989.py, models/cie146.py; issue 48's first step): the model's pieces
where its fits meet, its factors at the ages and polarities the literature quotes,
and the behaviour a road-lighting designer relies on. (Adrian's published values
and the CIE 88 portal are the issue's next steps.)"""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from ocl_tonemap.models import adrian1989 as ad
from ocl_tonemap.models import cie146


@pytest.mark.parametrize("v", [ad.ADRIAN_1989, ad.RP8], ids=["1989", "rp8"])
@pytest.mark.parametrize("L", [ad.L_LOW, ad.L_HIGH])
def test_the_fits_meet_where_their_ranges_do(L, v):
    """Adrian's three fits of sqrt(Phi) and sqrt(L) meet within 1.1 % at 0.00418 and
    0.6 cd/m^2 with the chosen constants (D1: RP-8's 4.2841; the printed 4.1925 left
    sqrt(Phi) 1.04 % and a 1' target's dL_th 2.0 % apart at 0.6), and so does the
    threshold of a positive target of 1 to 60 arcmin (a break would be a step in a
    visibility map). A negative target's steps more (F_cp takes dL_pos: up to 1.6 %
    at 60-80'; docs/models.md)."""
    for f in (lambda x: ad.sqrt_phi(x, v), ad.sqrt_weber):
        below, above = float(f(L * (1 - 1e-9))), float(f(L * (1 + 1e-9)))
        assert above == pytest.approx(below, rel=0.011)
    for alpha in np.logspace(0, np.log10(60), 25):
        below, above = (float(ad.threshold_of(L * (1 + e), alpha, 25, 0.2, False, 2.6, v))
                        for e in (-1e-9, 1e-9))
        assert above == pytest.approx(below, rel=0.011), alpha
    printed = ad.Variant(**{**v.as_dict(), "ricco_high": 4.1925})
    assert float(ad.sqrt_phi(0.6 * (1 + 1e-9), printed)) < 0.99 * float(ad.sqrt_phi(0.6 * (1 - 1e-9), printed))


def test_the_threshold_falls_with_the_background_and_the_size():
    """Threshold contrast falls as the background brightens and the target grows
    (van Bommel 2015, Fig. 3.1 from Adrian 1989: 4, 7 and 9 arcmin at 0.1 .. 10 cd/m^2,
    0.2 s, age 30); the threshold luminance difference rises with the background
    (Weber's law above ~1 cd/m^2: dL_th / L_b tends to a constant). Over the range of
    road and tunnel lighting, 0.01 .. 100 cd/m^2 (beyond, the small targets' fits turn
    up slightly: daylight is not the model's domain)."""
    Ls = np.logspace(-2, 2, 21)
    for size in (4.0, 7.0, 9.0, 20.0):
        C = [ad.threshold(L, size, 30, 0.2).contrast for L in Ls]
        dL = [ad.threshold(L, size, 30, 0.2).dL_th for L in Ls]
        assert np.all(np.diff(C) < 0) and np.all(np.diff(dL) > 0)
    for L in (0.1, 1.0, 10.0):
        c = [ad.threshold(L, s, 30, 0.2).contrast for s in (4.0, 7.0, 9.0)]
        assert c[0] > c[1] > c[2]
    weber = [ad.threshold(L, 60.0, 23, math.inf).contrast for L in (1e3, 1e4)]
    assert weber[1] == pytest.approx(weber[0], rel=0.3)


def test_the_age_factor_is_adrians():
    """AF of both fits; D5: the upper fit's centre 56.5 and its start above 64 (RP-8's:
    a 0.7 % step at 64, against 1.4 % with TU Berlin's 56.6 from 64 on)."""
    assert float(ad.age_factor(23)) == pytest.approx((23 - 19) ** 2 / 2160 + 0.99)
    assert float(ad.age_factor(60)) == pytest.approx(41 ** 2 / 2160 + 0.99)      # 1.768
    assert float(ad.age_factor(64)) == pytest.approx(45 ** 2 / 2160 + 0.99)      # 1.9275
    assert float(ad.age_factor(70)) == pytest.approx(13.5 ** 2 / 116.3 + 1.43)   # 2.997
    step = float(ad.age_factor(64 + 1e-9)) / float(ad.age_factor(64)) - 1
    assert -0.008 < step < 0
    assert float(ad.age_factor(10)) == float(ad.age_factor(23))                 # held
    a60, a23 = (ad.threshold(1.0, 10, A, 2.0) for A in (60, 23))
    assert a60.dL_th / a23.dL_th == pytest.approx(a60.age_factor / a23.age_factor)


def test_a_long_look_and_a_short_one():
    """(a + t)/t: 1 for a long look, larger the shorter the look; a(alpha, L_b) is a
    fraction of a second."""
    th = [ad.threshold(1.0, 10, 23, t) for t in (0.1, 0.2, 2.0, math.inf)]
    f = [x.time_factor for x in th]
    assert f[0] > f[1] > f[2] > f[3] == 1.0
    assert 0.05 < float(ad.time_constant(1.0, 10.0)) < 0.5


def test_a_dark_target_needs_less_difference_than_a_bright_one():
    """F_cp < 1: at road levels a target darker than its background is seen at a
    smaller difference than a brighter one (Adrian's negative contrast)."""
    for L in (0.1, 1.0, 10.0):
        pos, neg = (ad.threshold(L, 10, 23, 0.2, p) for p in ("positive", "negative"))
        assert 0 < neg.F_cp < 1 and neg.dL_th < pos.dL_th


def test_visibility_level_is_the_difference_over_the_threshold():
    th = ad.threshold(1.0, 10, 60, 0.2)
    assert ad.visibility_level(5 * th.dL_th, th) == pytest.approx(5.0)
    with pytest.raises(ValueError, match="background"):
        ad.threshold(0.0)
    with pytest.raises(ValueError, match="size"):
        ad.threshold(1.0, 0.0)


def test_cie146_glare():
    """The general equation against the age-adjusted Stiles-Holladay one where both
    hold (CIE 146: 'adequate accuracy within their domains'): within a factor 1.6 at
    2-20 degrees, the same fall with angle, and the older eye veiled more by
    (1 + (A/62.5)^4)."""
    th = np.array([2.0, 5.0, 10.0, 20.0])
    for A in (25, 70):
        g, s = cie146.veil_per_lux(th, A), cie146.stiles_holladay(th, A)
        assert np.all(g / s > 1 / 1.6) and np.all(g / s < 1.6)
        assert np.all(np.diff(g) < 0)
    young, old = cie146.veil_per_lux(10.0, 25, 0.0), cie146.veil_per_lux(10.0, 70, 0.0)
    core = 10 / 1e3
    assert (old - core) / (young - core) == pytest.approx(
        float(cie146.age_glare_factor(70) / cie146.age_glare_factor(25)))


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "ocl_tonemap", "visibility", *args],
                          capture_output=True, text=True)


def test_the_calculator_prints_each_term_and_vl():
    r = _cli("--background", "1", "--size", "10", "--age", "60", "--time", "0.2",
             "--target", "1.5", "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    th = ad.threshold(1.0, 10, 60, 0.2)
    assert d["dL_th"] == pytest.approx(th.dL_th) and d["age_factor"] == pytest.approx(1.7683,
                                                                                       abs=1e-4)
    assert d["VL"] == pytest.approx(0.5 / th.dL_th)
    r = _cli("--background", "1", "--target", "0.2")
    assert r.returncode == 0 and "negative" in r.stdout and "visibility level VL" in r.stdout


@pytest.mark.parametrize("args, why", [
    (["--background", "1", "--size", "0"], "--size must be 0.1..600 arcmin"),
    (["--background", "1", "--size", "1e6"], "--size must be 0.1..600 arcmin"),
    (["--background", "1", "--age", "120"], "--age must be 1..100 years"),
    (["--background", "0"], "--background must be 1e-06..1e+08 cd/m^2"),
    (["--background", "1e9"], "--background must be 1e-06..1e+08 cd/m^2"),
    (["--background", "1e300"], "--background must be 1e-06..1e+08 cd/m^2"),
    (["--background", "nan"], "--background must be 1e-06..1e+08 cd/m^2"),
    (["--background", "1", "--k", "-1"], "--k must be > 0 and at most 100"),
    (["--background", "1", "--k", "0", "--target", "12"], "--k must be > 0"),
    (["--background", "1", "--k", "nan"], "--k must be > 0"),
    (["--background", "1", "--veil", "-1"], "--veil must be 0..1e+08 cd/m^2"),
    (["--background", "1", "--target", "inf"], "--target must be 1e-06..1e+08"),
    (["--background", "1", "--adapted-to", "1e12"], "--adapted-to must be 1e-06..1e+08"),
    (["--background", "1", "--adapted-to", "5", "--after", "1e9"], "--after must be T1,T2,..., each 0..1e+07 s"),
    (["--background", "1", "--time", "0"], "--time must be 0.001..1e+07 s (or inf)"),
    (["--background", "1", "--after", "1,2"], "--after needs --adapted-to"),
    (["--background", "10", "--negative", "--target", "20"],
     "--negative: the target (20 cd/m^2) is not darker than the background"),
    (["--background", "1", "--adrian", "1990"], "invalid choice: '1990'"),
])
def test_the_calculator_refuses_bad_input_in_one_line(args, why):
    """Every input checked from its declaration (visibility.INPUTS): one line, exit 2,
    the flag and its range named; nothing computed with an impossible value."""
    r = _cli(*args)
    assert r.returncode == 2 and why in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not r.stdout


def test_the_calculators_json_is_strict_and_operator_needs_a_step():
    r = _cli("--background", "10", "--time", "inf", "--json")
    assert r.returncode == 0
    d = json.loads(r.stdout, parse_constant=lambda c: pytest.fail(f"non-JSON {c}"))
    assert d["time_s"] == "inf" and d["time_factor"] == 1.0
    r = _cli("--background", "10", "--operator", "ledda04")
    assert r.returncode == 2 and "--operator needs --adapted-to" in r.stderr


def test_the_calculator_honours_negative_and_warns_beyond_adrians_data():
    r = _cli("--background", "10", "--negative", "--json")
    assert r.returncode == 0 and json.loads(r.stdout)["polarity"] == "negative"
    r = _cli("--background", "10", "--negative", "--target", "5", "--json")
    assert r.returncode == 0 and json.loads(r.stdout)["polarity"] == "negative"
    r = _cli("--background", "10", "--size", "0.5")
    assert r.returncode == 0 and "--size 0.5 arcmin is beyond" in r.stderr \
        and "extrapolated" in r.stderr


@pytest.mark.parametrize("age", [25.0, 70.0])
def test_the_flares_veil_is_cie146s_at_the_observers_age(age):
    """benchmarks/glare_cie146.py puts the flare's PSF in the CIE's units, per
    steradian: it carries the whole of a source's light (the bases' unit energy), and
    its smooth scatter (f1, f2) is CIE 146's veil at the observer's age within 10 % at
    2-20 degrees for daylight, dusk and night pupils (issue 48 asks 25 %); Spencer's
    lenticular halo adds its ring at ~3 degrees only."""
    from benchmarks.glare_cie146 import agreement, spencer_psf
    from ocl_tonemap.models import spencer1995 as fl
    th = np.concatenate([np.linspace(0, 0.2, 20001)[:-1],
                         np.linspace(0.2, fl.THETA_MAX, 400001)])
    r = np.radians(th)
    for L in (1000.0, 1.0, 0.01):
        assert np.trapezoid(spencer_psf(th, L, age) * 2 * np.pi * r, r) == \
            pytest.approx(1.0, rel=1e-4)
        lo, hi = agreement(L, age, ring=False)
        assert 0.9 < lo and hi < 1.1, (L, lo, hi)
        assert agreement(L, age, ring=True)[1] > hi          # the ring, where it is
        away = np.array([5.0, 7.0, 10.0, 15.0, 20.0])        # and not beyond it
        ratio = spencer_psf(away, L, age) / cie146.veil_per_lux(away, age)
        assert np.all(np.abs(ratio - 1) < 0.25), (L, ratio)


@pytest.mark.requires_opencl
def test_the_default_observer_is_25_and_spencer_keeps_eq_8(tmp_path):
    """Without --age the flare is a 25-year-old's (issue 48); ``--age spencer`` keeps
    Eq. 8 as Spencer et al. print it with Moon & Spencer's pupil. (``spencer`` is a
    value of its own: None would be taken as "not given" and become 25.) Through the
    API on both backends, and through the command line."""
    from ocl_tonemap.models import spencer1995 as fl
    from ocl_tonemap.pipeline import Tonemapper
    from ocl_tonemap.io.sample import render_frame
    rgb = render_frame(3.0, 96, 54, 8.0, ss=1).astype(np.float32)
    for b in ("opencl", "reference"):
        young = Tonemapper("durand00", backend=b)
        young.process(rgb)
        lit = Tonemapper("durand00", backend=b, age="spencer")
        lit.process(rgb)
        fy, fs = young.last.effects["flare"], lit.last.effects["flare"]
        assert fy["weights"] == pytest.approx(fl.flare_weights(fy["pupil_mm"], 25.0))
        assert fs["weights"] == pytest.approx(fl.spencer_weights(fs["pupil_mm"]))
        assert fs["weights"][1] > 1.2 * fy["weights"][1]          # Eq. 8 scatters more
        assert not np.allclose(young.last_output, lit.last_output)
    exr = tmp_path / "f.exr"
    import OpenImageIO as oiio
    buf = oiio.ImageBuf(oiio.ImageSpec(96, 54, 3, oiio.FLOAT))
    buf.set_pixels(oiio.ROI(), rgb)
    assert buf.write(str(exr))
    outs = []
    for extra in ([], ["--age", "spencer"], ["--age", "25"]):
        out = tmp_path / f"o{len(outs)}.exr"
        r = subprocess.run([sys.executable, "-m", "ocl_tonemap", "run", str(exr), str(out),
                            "--operator", "durand00", "--luminance-scale", "1", *extra],
                           capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
        outs.append(oiio.ImageBuf(str(out)).get_pixels(oiio.FLOAT))
    assert np.array_equal(outs[0], outs[2]) and not np.array_equal(outs[0], outs[1])


def test_an_older_eye_has_a_smaller_pupil_and_more_glare():
    from ocl_tonemap.models import spencer1995 as fl
    from ocl_tonemap.models import watson2012 as wy
    for L in (0.01, 1.0, 100.0):
        assert wy.pupil_diameter(L, 1400.0, 70) < wy.pupil_diameter(L, 1400.0, 25)
    w25, w70 = fl.flare_weights(4.0, 25.0), fl.flare_weights(4.0, 70.0)
    assert w70[1] + w70[2] > w25[1] + w25[2] and w70[0] < w25[0]
    assert fl.flare_weights(4.0) == fl.spencer_weights(4.0)      # no age: Eq. 8
    assert sum(fl.flare_weights(4.0, 100.0)) == pytest.approx(1.0)
    assert min(fl.flare_weights(7.0, 100.0)) >= 0.0


# --- transient adaptation: each operator's own time course (issue 48) ---------------------

from ocl_tonemap.operators import get_operator  # noqa: E402
from ocl_tonemap.effects.visibility import Viewing, trace  # noqa: E402

OPS = ("pattanaik00", "durand00", "ledda04", "kirk11")


@pytest.mark.parametrize("op", OPS)
def test_a_step_down_raises_the_threshold_then_it_falls_to_steady(op):
    """5000 -> 5 cd/m^2: dL_th at 0.5, 2 and 10 s is at or above the steady value at
    5 cd/m^2, above it at 0.5 s, never rising, and steady after an hour (within 0.5 %:
    the shared pigment course's rods, bleached by the approach, regenerate at a
    limited rate and still count in a mesopic 5 cd/m^2)."""
    o = get_operator(op)({})
    view = Viewing(10.0, 23.0, 2.0)
    steady = float(view.steady(5.0))
    ts = [0.05 * i for i in range(401)]
    pts = trace(o, 5000.0, None, 5.0, ts + [3600.0], view)
    d = [p.dL_th for p in pts]
    assert all(b <= a * (1 + 1e-12) for a, b in zip(d, d[1:]))
    at = {p.t: p for p in pts}
    # ledda04's pixels adapt at once by default (the pigment course's early neural
    # phase alone: 1.4 % at 0.5 s; its paper's hold gives the lag: --mode paper)
    assert at[0.5].dL_th > (1.01 if op == "ledda04" else 1.2) * steady
    assert all(at[t].dL_th >= steady for t in (0.5, 2.0, 10.0))
    assert at[3600.0].dL_th == pytest.approx(steady, rel=5e-3)


@pytest.mark.parametrize("op", OPS)
def test_an_adapted_observer_has_no_transient(op):
    o = get_operator(op)({})
    for L in (0.01, 1.0, 300.0, 1e5):
        obs = o.observer_preadapted(L, None)
        s = float(o.observer_steady_slope(L))
        assert float(ad.transient_factor(s, o.observer_slope(obs, L))) == \
            pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize("op", OPS)
def test_an_older_observer_adapted_to_the_background_has_no_transient(op):
    """A 70-year-old's state holds the light behind the media (0.84 of the scene's):
    adapted to L_b, the calculator's TAF is 1 and La is L_b in scene cd/m^2. (Read at
    the scene's L_b instead, the state would look dazzled: TAF > 1.)"""
    o = get_operator(op)({})
    view = Viewing(10.0, 70.0, 2.0)
    assert view.media_gain == pytest.approx(0.838, abs=2e-3)
    for L in (0.01, 1.0, 300.0):
        (p,) = trace(o, L, None, L, (0.0,), view)
        assert p.TAF == pytest.approx(1.0, abs=1e-4) and p.L_a == pytest.approx(L, rel=1e-3)
        assert p.dL_th == pytest.approx(float(view.steady(L)), rel=1e-4)


def test_ledda04_keeps_the_longest_memory_of_the_approach():
    """With ``--mode paper`` Ledda's cones wait a second, then recover over seconds to
    minutes; the light-adaptation models (Pattanaik's neural 80 ms, Durand's 0.1 s)
    within ~2 s. By default every operator has the shared pigment course's: its
    early neural phase (8 s) and its cones' and rods' pigment still raise the threshold
    at 10 s, less than at 0.5 s, and little after an hour."""
    view = Viewing(10.0, 25.0, 2.0)
    taf = {n: {p.t: p.TAF for p in trace(get_operator(n)({"mode": "paper"}), 5000.0, None,
                                          5.0, (0.5, 10.0), view)} for n in OPS}
    assert taf["ledda04"][10.0] > 1.05 > taf["pattanaik00"][10.0]
    assert taf["durand00"][10.0] < 1.0001
    for n in OPS:
        t = {p.t: p.TAF for p in trace(get_operator(n)({}), 5000.0, None, 5.0,
                                       (0.5, 10.0, 3600.0), view)}
        assert t[0.5] > t[10.0] > 1.0 and t[3600.0] < 1.005, (n, t)


def test_transient_factor_never_below_one_and_bounded():
    assert ad.transient_factor(1.0, 2.0) == 1.0
    assert ad.transient_factor(1.0, 0.0) == ad.TAF_MAX
    assert np.isfinite(ad.transient_factor(np.inf, 1.0))


@pytest.mark.parametrize("op", ["pattanaik00", "durand00", "kirk11", "ledda04"])
def test_the_devices_tables_are_the_model(op):
    """The device reads log2 dL_th from tables over log2 L_b (visibility.threshold_tables:
    Adrian's steady threshold x a global observer's TAF; for ledda04 the steady part
    and the steady gain, TAF per pixel): linear between nodes within 5e-4 of the model
    at 300 000 backgrounds from 1e-6 to 1e9 cd/m^2, both polarities, exact at Adrian's
    joins and at the steps of an operator's steady gain (durand00's TVI joins: 2.7 %
    there before the tables split at them)."""
    from ocl_tonemap.models.threshold_tables import table_lookup, threshold_tables
    from ocl_tonemap.models.visibility_map import transient
    o = get_operator(op)({})
    view = Viewing(10.0, 25.0, 0.2)
    for L0 in (0.01, 40.0, 5000.0):
        obs = o.observer_advance(o.observer_preadapted(L0, None), 3.0, 0.5)
        seg, T = threshold_tables(o, None if o.observer_per_pixel else obs, view)
        Lb = np.concatenate([np.logspace(-6, 9, 300_000),
                             [ad.L_LOW, ad.L_HIGH, 0.1, 0.004]])
        for neg in (False, True):
            want = view.steady(Lb, neg)
            if not o.observer_per_pixel:
                want = want * transient(o, obs, Lb, view.media_gain)
            got = 2.0 ** table_lookup(T[int(neg)].astype(np.float64), seg, Lb)
            assert np.max(np.abs(got / want - 1.0)) < 5e-4, (L0, neg)
        if o.observer_per_pixel:
            ss = 2.0 ** table_lookup(T[2].astype(np.float64), seg, Lb)
            np.testing.assert_allclose(ss, o.observer_steady_slope(Lb), rtol=5e-4)


def _vis(*args):
    return subprocess.run([sys.executable, "-m", "ocl_tonemap", "visibility", *map(str, args)],
                          capture_output=True, text=True)


def test_calculator_step_json_and_plot(tmp_path):
    png = tmp_path / "step.png"
    r = _vis("--background", "5", "--adapted-to", "5000", "--after", "0.5,2,10",
             "--operator", "ledda04", "--target", "6", "--plot", png, "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    pts = out["step"]["points"]
    assert [p["t"] for p in pts] == [0.5, 2.0, 10.0]
    assert pts[0]["dL_th"] > pts[1]["dL_th"] > pts[2]["dL_th"] > out["step"]["steady_dL_th"]
    assert pts[0]["VL"] < pts[2]["VL"]
    assert png.stat().st_size > 1000


@pytest.mark.parametrize("args,says", [
    (("--for", "3"), "needs --adapted-to"),
    (("--plot", "x.png"), "needs --adapted-to"),
    (("--adapted-to", "5000", "--after", "x"), "(its value 1 is x;"),
    (("--adapted-to", "5000", "--after", "-1"), "--after must be T1,T2,..., each 0..1e+07 s"),
    (("--adapted-to", "5000", "--after", "1,,2"), "(its value 2 is ;"),
    (("--adapted-to", "-1"), "--adapted-to must be"),
    (("--adapted-to", "5000", "--for", "0"), "--for must be > 0"),
    (("--adapted-to", "5000", "--operator", "nope"), "unknown operator"),
])
def test_calculator_step_refusals(args, says):
    r = _vis("--background", "5", *args)
    assert r.returncode != 0
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and says in lines[0], r.stderr


@pytest.mark.parametrize("shape", [(1, 1), (5, 300), (37, 53), (64, 96)])
@pytest.mark.parametrize("s", [2, 4, 8])
def test_block_means_and_their_bilinear_return(shape, s):
    """The maps' coarse grids (visibility.block_mean, upsample): each block's mean,
    the edge blocks of what pixels they have; back by bilinear interpolation between
    block centres, held at the edges. Against a direct evaluation of both."""
    from ocl_tonemap.models.visibility_map import block_mean, upsample
    rng = np.random.default_rng(4)
    Y = (rng.random(shape) * 100).astype(np.float32)
    h, w = shape
    B = block_mean(Y, s)
    ref = np.array([[Y[i:i + s, j:j + s].mean(dtype=np.float64) for j in range(0, w, s)]
                    for i in range(0, h, s)])
    np.testing.assert_allclose(B, ref, rtol=1e-6)

    def centre(n, m):                  # source cells and weights of each output
        c = (np.arange(n) + 0.5) / s - 0.5
        i0 = np.clip(np.floor(c).astype(int), 0, m - 1)
        return i0, np.minimum(i0 + 1, m - 1), np.clip(c - i0, 0.0, 1.0)
    y0, y1, fy = centre(h, B.shape[0])
    x0, x1, fx = centre(w, B.shape[1])
    B64 = B.astype(np.float64)
    r = B64[y0] * (1 - fy)[:, None] + B64[y1] * fy[:, None]
    want = r[:, x0] * (1 - fx) + r[:, x1] * fx
    np.testing.assert_allclose(upsample(B, shape, s), want, rtol=1e-6)
